//! The physical range of every set-point that enters the drive, checked where it enters
//! (the link's request handler, [`crate::Commands::validate`]) and again by [`crate::Axis::step`]
//! (an out-of-range command latches [`crate::Faults::COMMAND_RANGE`] and never reaches the
//! integer command path).
//!
//! The bounds are chosen so that no integer sum in the core can come near overflow for an
//! accepted value:
//! - positions (streamed positions, move targets, stop-sequence targets, soft limits) within
//!   ±2⁵³ counts (every count exact in an f64; 1.7·10⁹ revolutions at 2²² counts per
//!   revolution): a difference or sum of two positions stays below 2⁵⁴, 512 times short of
//!   `i64::MAX`;
//! - speeds (move speed, jog velocity, velocity command) within ±100 000 rad/s (about
//!   955 000 rpm, the ceiling of `position.velocity_limit`): at most 2.7·10¹¹ counts per
//!   position tick (2²⁴ counts per revolution, a position tick of at most one second);
//! - torque within ±100 000 Nm (the ceiling of `velocity.torque_limit`);
//! - loop dividers at most 1 000 base ticks, acquisition and PRBS dividers at most 10⁶, sweep
//!   durations at most 10⁴ s and 10⁴ cycles from 1 mHz (see `Params::validate`): tick
//!   counts stay below 2⁴⁸.
//!
//! Integer arithmetic on values that accumulate without a bound the core can prove (encoder
//! position, interpolated position over a long jog, pulses in a filter) saturates.

use core::fmt;

/// Largest magnitude of a position (counts).
pub const MAX_POSITION_COUNTS: i64 = 1 << 53;
/// Largest magnitude of a speed set-point (rad/s).
pub const MAX_SPEED: f32 = 100_000.0;
/// Largest magnitude of a torque set-point (Nm).
pub const MAX_TORQUE: f32 = 100_000.0;
/// Largest velocity or position divider (base ticks).
pub const MAX_LOOP_DIVIDER: u32 = 1_000;
/// Largest acquisition or PRBS-chip divider (base ticks).
pub const MAX_SWEEP_DIVIDER: u32 = 1_000_000;
/// Longest sweep duration setting (s) and most cycles per record.
pub const MAX_SWEEP_SECONDS: f32 = 10_000.0;
pub const MAX_SWEEP_CYCLES: f32 = 10_000.0;
/// Lowest sweep frequency (Hz).
pub const MIN_SWEEP_HZ: f32 = 0.001;
/// Lowest Butterworth acc/dec cut-off (Hz): acc/dec time constants of machine tools reach
/// 300 ms (0.5 Hz).
pub const MIN_ACC_DEC_CUTOFF_HZ: f32 = 0.5;
/// Lowest Butterworth acc/dec cut-off × position-loop period: below, the poles are too close to
/// `z = 1` for the drive's integer filter to stay within a count of its design (0.5 Hz at a
/// 0.125 ms period is 6.25·10⁻⁵).
pub const MIN_ACC_DEC_CUTOFF_TIMES_PERIOD: f32 = 6.0e-5;

/// A set-point the link or the loop checks against its range.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Quantity {
    /// `Commands::position` (counts).
    Position,
    /// `Commands::move_speed` (rad/s).
    MoveSpeed,
    /// `Commands::jog_velocity` (rad/s).
    JogVelocity,
    /// `Commands::velocity` (rad/s).
    Velocity,
    /// `Commands::torque` (Nm).
    Torque,
    /// The target of a stop-sequence `MoveTo` event (counts).
    MoveTarget,
}

impl Quantity {
    pub fn name(self) -> &'static str {
        match self {
            Self::Position => "commands.position",
            Self::MoveSpeed => "commands.move_speed",
            Self::JogVelocity => "commands.jog_velocity",
            Self::Velocity => "commands.velocity",
            Self::Torque => "commands.torque",
            Self::MoveTarget => "sequence MoveTo target",
        }
    }

    pub fn unit(self) -> &'static str {
        match self {
            Self::Position | Self::MoveTarget => "counts",
            Self::MoveSpeed | Self::JogVelocity | Self::Velocity => "rad/s",
            Self::Torque => "Nm",
        }
    }

    /// The closed interval `[min, max]` the value must lie in.
    pub fn range(self) -> (f64, f64) {
        let m = match self {
            Self::Position | Self::MoveTarget => MAX_POSITION_COUNTS as f64,
            Self::MoveSpeed | Self::JogVelocity | Self::Velocity => MAX_SPEED as f64,
            Self::Torque => MAX_TORQUE as f64,
        };
        (-m, m)
    }
}

/// A set-point outside its range (or not a number): which one and its value.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct RangeError {
    pub quantity: Quantity,
    pub value: f64,
}

impl fmt::Display for RangeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let (min, max) = self.quantity.range();
        let unit = self.quantity.unit();
        write!(f, "{} = {} {unit} is outside [{min}, {max}] {unit}", self.quantity.name(), self.value)
    }
}

/// A speed or torque set-point in range (NaN and infinities are not).
#[inline]
pub fn check_f32(quantity: Quantity, value: f32) -> Result<(), RangeError> {
    let (_, max) = quantity.range();
    if value.abs() <= max as f32 {
        Ok(())
    } else {
        Err(RangeError { quantity, value: value as f64 })
    }
}

/// A position in range.
#[inline]
pub fn check_position(quantity: Quantity, value: i64) -> Result<(), RangeError> {
    if value.unsigned_abs() <= MAX_POSITION_COUNTS as u64 {
        Ok(())
    } else {
        Err(RangeError { quantity, value: value as f64 })
    }
}
