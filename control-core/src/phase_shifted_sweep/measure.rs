//! What the sweep's acquisition relates: the loop's own signals (seed 000), or the machine-end
//! acceleration against the motor's torque (seed 001's identification over a drive) or against
//! the position command (the check of its correction over a drive).

/// The U and Y the acquisition records.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SweepMeasure {
    /// U and Y as the injection point defines them (see `phase_shifted_sweep`'s documentation).
    #[default]
    Loop,
    /// U = the drive's torque estimate from its measured q current (kt · iq), Y = the
    /// machine-end angular acceleration (`AxisInputs::load_acceleration`, rad/s²), each the
    /// mean over the base ticks of its acquisition period. Both are sampled at the same
    /// instant (the phase currents' and the accelerometer's conversions), so no delay lies
    /// between them; the torque is the motor's as the drive sees it, not the command (the
    /// current loop's lag stays out of the ratio). With position-command injection U is the
    /// injected position (rad) instead, Y the acceleration read with this tick's encoder count
    /// (`servo tune --device`'s machine-end check: command → machine-end position is Y/U
    /// over −ω²). Refused with the other injection points.
    MachineAcceleration,
}

impl SweepMeasure {
    /// The measure of a `sweep.measure` code: 0 the loop's signals, 1 torque → machine-end
    /// acceleration.
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(Self::Loop),
            1 => Some(Self::MachineAcceleration),
            _ => None,
        }
    }

    /// The inverse of [`Self::from_code`].
    pub fn code(self) -> i32 {
        match self {
            Self::Loop => 0,
            Self::MachineAcceleration => 1,
        }
    }
}
