//! The torque ceiling: the torque command from which one of the drive's two clamps may be
//! cutting an experiment's excitation, and which clamp that is.
//!
//! The drive's torque path, on every base tick (`Axis::velocity_tick`, `Axis::inner_loop`):
//!
//! ```text
//! velocity PI + friction compensation → filters → clamp ±velocity.torque_limit   (the loop's clamp)
//!   + torque-command injection + the sweep's dither                               (added after it)
//!   → torque / kt → clamp ±current.max_current                                    (the current clamp)
//! ```
//!
//! The drive's `torque_command` (the FMU's `torque_command_out`) is the torque after the
//! loop's clamp and the additions, before the current clamp. So an excitation injected in
//! front of the loop (position or velocity command, velocity feedback; a circle; a streamed
//! multisine) meets whichever clamp is lower, the loop's seen through the dither (a sample at
//! the clamp reads `torque_limit − dither` at least); a torque-command injection is added
//! after the loop's clamp, which cannot cut it, and meets the current clamp only, at
//! `kt·max_current`.
//!
//! Four experiments ask whether their excitation stays below the ceiling. Each takes it from
//! [`TorqueCeiling::of`] with its own parts — where its excitation enters, the dither added
//! after the loop's clamp — and keeps its own observable, margin and comparison, for the
//! reasons given:
//!
//! - **The sweep** (`Params::validate_sweep`, on the drive when a sweep starts or parameters are
//!   set; `host-tools/src/sweep/torque_limit.rs` on the FMU's trace). Before: a torque-command
//!   amplitude was refused when `amplitude + dither ≥ kt·max_current` and the dither when it
//!   exceeded `torque_limit`; the trace counted a sample as limited at `|torque| ≥
//!   kt·max_current` or, for the points in front of the loop, `≥ torque_limit − dither` (each
//!   less 10⁻⁵ for the f32 rounding). After: the same amplitude and trace rules from the
//!   ceiling (the dither enters as the part added after the loop's clamp). The dither's own
//!   rule was wrong where the current binds: it is added after the loop's clamp, so with
//!   `kt·max_current < torque_limit` a dither between the two was accepted and cut by the
//!   current clamp on every sample; it is now held to the lower of the two (at or below: a
//!   dither at the clamp on its own is not cut). The trace's warning now names the clamp.
//! - **The circle** (`host-tools/src/fmu/circle.rs`, `fmu/axis_health.rs`): no injection, no
//!   dither: `min(torque_limit, kt·max_current)`, a sample at it within one f32 epsilon (the
//!   core clamps exactly). Unchanged; it now also names the clamp.
//! - **Identification's PRBS** (`host-tools/src/ident/identification.rs`): an M-sequence on
//!   the torque command. Before: refused when the mean electromagnetic torque reached 0.999 of
//!   `torque_limit` — the wrong clamp: the PRBS is added after the loop's clamp, so with
//!   `kt·max_current < torque_limit` the current clamp cut it unseen, and with `torque_limit <
//!   kt·max_current` a loop torque plus PRBS above `torque_limit` (cut by nothing) was refused.
//!   After: the torque command against the torque-command ceiling (`kt·max_current`), as the
//!   sweep's trace at the same point. (On one such axis — 0.6 A, 0.01 N·m of Coulomb friction,
//!   a 40 Hz absorber — the data refused now gave the anti-resonance at 40.000 Hz before, rms
//!   fit error 0.2 % against 0.1 % unclamped: the identification divides the measured torque
//!   out. The refusal keeps the old rule's intent, data measured through a clamp are not used.)
//! - **Tune's multisine** (`host-tools/src/ident/tuning.rs`, and the machine-end sweep's twin in
//!   `ident/device_machine_end.rs`): a streamed position multisine. Before: refused when the
//!   measured q current reached 0.9 of `max_current` — the wrong clamp where the torque limit
//!   binds (`torque_limit < kt·max_current`: the loop's clamp pins the torque and the current
//!   never nears `max_current`). After: 0.9 of the ceiling's current (the measured current
//!   overshoots the clamped reference, hence the margin), the same where the current binds.
//!
//! Not on the tick: nothing here runs in `Axis::step`, which watches neither clamp (each would
//! cost the Cortex-M4 about 20 instructions per tick).

use core::fmt;

use crate::excitation::InjectionPoint;
use crate::params::Params;

/// One of the drive's two torque clamps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TorqueClamp {
    /// The velocity loop's output clamp, ±`velocity.torque_limit`.
    TorqueLimit,
    /// The current reference's clamp, ±`current.max_current`: a torque of kt·max_current.
    CurrentLimit,
}

impl TorqueClamp {
    /// The parameter that sets the clamp, as `Params` names it.
    pub fn parameter(self) -> &'static str {
        match self {
            Self::TorqueLimit => "velocity.torque_limit",
            Self::CurrentLimit => "current.max_current",
        }
    }
}

/// Where an experiment's excitation enters the torque path.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExcitationEntry {
    /// In front of the velocity loop (position or velocity command, velocity feedback), or no
    /// injection at all: both clamps act on it.
    BeforeTheLoopClamp,
    /// Added to the torque command after the loop's clamp: only the current clamp acts on it.
    AfterTheLoopClamp,
}

impl ExcitationEntry {
    /// Where a sweep injected at `point` enters.
    pub fn of(point: InjectionPoint) -> Self {
        match point {
            InjectionPoint::TorqueCommand => Self::AfterTheLoopClamp,
            _ => Self::BeforeTheLoopClamp,
        }
    }
}

/// The torque command (N·m, magnitude) from which a clamp may be cutting the excitation, the
/// same as a q current (A), and the clamp with what sets it (for a message: [`fmt::Display`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TorqueCeiling {
    /// N·m, as the drive's torque command reads it.
    pub torque: f32,
    /// A: `max_current` itself where the current clamp binds, else `torque / kt`.
    pub current: f32,
    pub clamp: TorqueClamp,
    /// The clamp's parameter: `velocity.torque_limit` (N·m) or `current.max_current` (A).
    pub setting: f32,
    /// The dither the loop's clamp is read through (N·m; 0 where the current clamp binds).
    pub dither: f32,
    /// The motor's torque constant (N·m/A).
    pub kt: f32,
}

impl TorqueCeiling {
    /// The ceiling of `params`' drive for an excitation entering at `entry`, with `dither`
    /// N·m (peak, ≥ 0) added after the loop's clamp beside it: before the loop, the lower of
    /// the loop's clamp as the torque command reads it (`torque_limit − dither`) and the
    /// current clamp (`kt·max_current`, which acts on the sum with the dither); after the
    /// loop, the current clamp. On a tie the current clamp is named (both cut there).
    pub fn of(params: &Params, entry: ExcitationEntry, dither: f32) -> Self {
        let kt = params.motor.torque_constant();
        let (torque_limit, max_current) = (params.velocity.torque_limit, params.current.max_current);
        let current_clamp = kt * max_current;
        let loop_clamp = torque_limit - dither;
        if entry == ExcitationEntry::BeforeTheLoopClamp && loop_clamp < current_clamp {
            let clamp = TorqueClamp::TorqueLimit;
            Self { torque: loop_clamp, current: loop_clamp / kt, clamp, setting: torque_limit, dither, kt }
        } else {
            let clamp = TorqueClamp::CurrentLimit;
            Self { torque: current_clamp, current: max_current, clamp, setting: max_current, dither: 0.0, kt }
        }
    }

    /// [`TorqueCeiling::current`] to six significant digits, for a message (0.2 A, not the
    /// f32's 0.19999997 of 0.02 N·m / 0.10000001 N·m/A).
    pub fn rounded_current(&self) -> f64 {
        six_digits(self.current)
    }

    /// The torque left to a peak excitation added after the loop's clamp with `dither` beside
    /// it: an excitation at or above this reaches the ceiling (N·m; may be ≤ 0).
    pub fn room_beside(&self, dither: f32) -> f32 {
        self.torque - dither
    }
}

/// The clamp by its parameter and value, and the torque it reads as: "velocity.torque_limit
/// = 0.5 N·m", "velocity.torque_limit = 2 N·m less the 0.003 N·m dither", "current.max_current
/// = 20 A, 2 N·m at kt = 0.1 N·m/A" (the product and kt to six significant digits: not the
/// f32's 0.060000006).
impl fmt::Display for TorqueCeiling {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let name = self.clamp.parameter();
        match self.clamp {
            TorqueClamp::TorqueLimit if self.dither > 0.0 => {
                write!(f, "{name} = {} N·m less the {} N·m dither", self.setting, self.dither)
            }
            TorqueClamp::TorqueLimit => write!(f, "{name} = {} N·m", self.setting),
            TorqueClamp::CurrentLimit => {
                let (torque, kt) = (six_digits(self.torque), six_digits(self.kt));
                write!(f, "{name} = {} A, {torque} N·m at kt = {kt} N·m/A", self.setting)
            }
        }
    }
}

/// `x` rounded to six significant digits (for a message).
fn six_digits(x: f32) -> f64 {
    let x = x as f64;
    if x == 0.0 || !x.is_finite() {
        return x;
    }
    let scale = libm::pow(10.0, 5.0 - libm::floor(libm::log10(libm::fabs(x))));
    libm::round(x * scale) / scale
}

#[cfg(test)]
mod tests {
    use super::*;

    fn params(torque_limit: f32, max_current: f32) -> Params {
        let mut p = Params::default();
        (p.velocity.torque_limit, p.current.max_current) = (torque_limit, max_current);
        p
    }

    /// Each clamp where it is the lower one, the dither lowering only the loop's clamp as the
    /// torque command reads it, and a torque-command injection meeting the current clamp only.
    #[test]
    fn the_lower_clamp_binds_and_the_dither_shows_only_through_the_loop_clamp() {
        let kt = Params::default().motor.torque_constant();
        let before = ExcitationEntry::BeforeTheLoopClamp;
        let after = ExcitationEntry::AfterTheLoopClamp;
        let low_torque = TorqueCeiling::of(&params(0.5, 20.0), before, 0.1);
        assert_eq!((low_torque.torque, low_torque.clamp), (0.5 - 0.1, TorqueClamp::TorqueLimit));
        assert_eq!(low_torque.current, (0.5 - 0.1) / kt);
        let low_current = TorqueCeiling::of(&params(2.0, 5.0), before, 0.1);
        assert_eq!((low_current.torque, low_current.current), (kt * 5.0, 5.0));
        assert_eq!(low_current.clamp.parameter(), "current.max_current");
        extern crate std;
        use std::string::ToString;
        assert_eq!(low_current.to_string(), "current.max_current = 5 A, 0.5 N·m at kt = 0.1 N·m/A");
        assert_eq!(low_torque.to_string(), "velocity.torque_limit = 0.5 N·m less the 0.1 N·m dither");
        // The f32 product 0.060000006 and kt 0.10000001 read as set.
        let small = TorqueCeiling::of(&params(2.0, 0.6), before, 0.0);
        assert_eq!(small.to_string(), "current.max_current = 0.6 A, 0.06 N·m at kt = 0.1 N·m/A");
        let torque_bound = TorqueCeiling::of(&params(0.02, 20.0), before, 0.0);
        assert_eq!((torque_bound.current == 0.2, torque_bound.rounded_current()), (false, 0.2));
        let undithered = TorqueCeiling::of(&params(0.5, 20.0), before, 0.0);
        assert_eq!(undithered.to_string(), "velocity.torque_limit = 0.5 N·m");
        let injected = TorqueCeiling::of(&params(0.5, 20.0), after, 0.1);
        assert_eq!((injected.torque, injected.clamp), (kt * 20.0, TorqueClamp::CurrentLimit));
        assert_eq!(injected.room_beside(0.1), kt * 20.0 - 0.1);
        assert_eq!(ExcitationEntry::of(InjectionPoint::TorqueCommand), after);
        for p in [InjectionPoint::Off, InjectionPoint::VelocityCommand, InjectionPoint::PositionCommand] {
            assert_eq!(ExcitationEntry::of(p), before);
        }
    }
}
