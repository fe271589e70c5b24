//! Position command path of the drive: interpolator, then acc/dec filter, then the position
//! loop (seed 003: acceleration/deceleration *after* interpolation).
//!
//! The interpolator turns a move into pulses (encoder counts) per position tick:
//! - **stream**: the increments of an externally streamed position input (the host or a CNC
//!   sends absolute positions; their differences are the pulses);
//! - **absolute** / **relative positioning**: a constant speed until the target, the last
//!   tick taking the remainder (a rectangular speed profile; the filter shapes it);
//! - **jog**: a constant speed until told otherwise.
//!
//! Fractional pulses of a speed are carried from tick to tick; the filter conserves whole
//! pulses; so the filtered command ends exactly on the target.
//!
//! Positions and speeds are bounded where they enter (`crate::ranges`); the sums here
//! saturate, so no input, accepted or not, can make them wrap.

use core::mem::MaybeUninit;

use crate::acc_dec::{AccDecError, AccDecFilter, AccDecParams};
use crate::response_correction::{CorrectionError, CorrectionParams, ResponseCorrection};

/// What the interpolator does this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Move {
    /// Follow the increments of the position input.
    Stream,
    /// Go to this position (counts) at this speed (counts per tick, > 0).
    Absolute { target: i64, speed: f32 },
    /// Jog at this signed speed (counts per tick).
    Jog(f32),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommandPath {
    /// Interpolated (unfiltered) position (counts).
    interpolated: i64,
    /// Last streamed input, for its increments.
    last_stream_input: i64,
    /// Fraction of a pulse carried by the speed moves.
    carry: f32,
    filter: AccDecFilter,
    /// Response correction after the acc/dec filter (seed 001).
    correction: ResponseCorrection,
    /// Filtered position command (counts) and the last tick's pulses.
    position: i64,
    pulses: i64,
}

impl CommandPath {
    pub fn new(filter: AccDecFilter) -> Self {
        Self::with_correction(filter, ResponseCorrection::default())
    }

    pub fn with_correction(filter: AccDecFilter, correction: ResponseCorrection) -> Self {
        Self { interpolated: 0, last_stream_input: 0, carry: 0.0, filter, correction, position: 0, pulses: 0 }
    }

    /// [`Self::with_correction`] built at `path`, its acc/dec filter of `acc_dec` at the
    /// position-loop `period` built in place (no filter value on any stack); refused, with
    /// nothing written, as [`AccDecFilter::new`].
    ///
    /// # Safety
    /// `path` is valid for writes and aligned.
    #[allow(unsafe_code)]
    pub unsafe fn init(
        path: *mut Self,
        acc_dec: &AccDecParams,
        period: f32,
        correction: &ResponseCorrection,
    ) -> Result<(), AccDecError> {
        use core::ptr::addr_of_mut;
        // SAFETY: the caller's; the filter's slot is a field of `path` (a `MaybeUninit` has
        // its type's layout), and every field is written once the filter is.
        unsafe {
            let filter = &mut *addr_of_mut!((*path).filter).cast::<MaybeUninit<AccDecFilter>>();
            AccDecFilter::new_in(filter, acc_dec, period)?;
            write_fields!(path, CommandPath {
                correction: *correction,
                interpolated: 0,
                last_stream_input: 0,
                carry: 0.0,
                position: 0,
                pulses: 0,
                ; filter
            });
        }
        Ok(())
    }

    /// Start from rest at `position` (counts): empty filter, no carry (field by field: the
    /// filter is kilobytes and stays where it is).
    pub fn reset(&mut self, position: i64) {
        self.filter.reset();
        self.correction.reset();
        self.interpolated = position;
        self.last_stream_input = position;
        self.position = position;
        self.carry = 0.0;
        self.pulses = 0;
    }

    /// Position the interpolator has reached, before the filter (counts).
    pub fn interpolated(&self) -> i64 {
        self.interpolated
    }

    /// Filtered position command (counts).
    pub fn position(&self) -> i64 {
        self.position
    }

    /// Load response-correction coefficients; refused while command pulses are in flight.
    pub fn load_correction(&mut self, p: &CorrectionParams, period: f32) -> Result<(), CorrectionError> {
        self.correction.load(p, period)
    }

    /// Install a correction built ahead; refused while command pulses are in flight.
    pub fn install_correction(&mut self, built: &ResponseCorrection) -> Result<(), CorrectionError> {
        self.correction.install(built)
    }

    /// Filtered pulses of the last tick.
    pub fn pulses(&self) -> i64 {
        self.pulses
    }

    /// A relative move of `distance` counts from where the interpolator is now.
    pub fn relative(&self, distance: i64, speed: f32) -> Move {
        Move::Absolute { target: self.interpolated.saturating_add(distance), speed }
    }

    fn speed_pulses(&mut self, speed: f32) -> i64 {
        let total = self.carry + speed;
        let (whole, counts) = crate::floor_to_counts(total);
        self.carry = total - whole;
        counts
    }

    /// One position tick; returns the filtered position command (counts). `position_input`
    /// is the streamed absolute position (counts); its increments are followed only in
    /// [`Move::Stream`], but it is watched in every tick so that returning to streaming after
    /// a jog or a positioning move never jumps.
    pub fn step(&mut self, m: Move, position_input: i64) -> i64 {
        let increment = position_input.saturating_sub(self.last_stream_input);
        self.last_stream_input = position_input;
        let pulses = match m {
            Move::Stream => {
                self.carry = 0.0;
                increment
            }
            Move::Absolute { target, speed } => {
                let remaining = target.saturating_sub(self.interpolated);
                let step = self.speed_pulses(speed.abs());
                if step >= remaining.saturating_abs() {
                    self.carry = 0.0;
                    remaining
                } else {
                    step * remaining.signum()
                }
            }
            Move::Jog(speed) => {
                let step = self.speed_pulses(speed.abs());
                if speed < 0.0 {
                    step.saturating_neg()
                } else {
                    step
                }
            }
        };
        self.interpolated = self.interpolated.saturating_add(pulses);
        self.pulses = self.correction.step(self.filter.step(pulses));
        self.position = self.position.saturating_add(self.pulses);
        self.position
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::acc_dec::{AccDecKind, AccDecParams};

    fn path(kind: AccDecKind) -> CommandPath {
        let p = AccDecParams { kind, ..AccDecParams::default() };
        CommandPath::new(AccDecFilter::new(&p, 0.00025).unwrap())
    }

    #[test]
    fn absolute_move_ends_exactly_on_target_at_the_asked_speed() {
        for kind in [AccDecKind::None, AccDecKind::MovingAverage, AccDecKind::Butterworth] {
            let mut c = path(kind);
            c.reset(1000);
            let mut fastest = 0;
            for _ in 0..2000 {
                let before = c.interpolated();
                c.step(Move::Absolute { target: 1000 + 123_457, speed: 333.3 }, 0);
                fastest = fastest.max(c.interpolated() - before);
            }
            assert_eq!(c.interpolated(), 124_457);
            assert_eq!(c.position(), 124_457, "{kind:?}");
            // The interpolator never goes faster than asked (the carry rounds up to 334).
            assert_eq!(fastest, 334, "{kind:?}");
        }
    }

    #[test]
    fn jog_speed_is_exact_on_average_and_stops_without_a_jump() {
        let mut c = path(AccDecKind::Butterworth);
        c.reset(0);
        for _ in 0..4000 {
            c.step(Move::Jog(-12.25), 777);
        }
        assert_eq!(c.interpolated(), -49_000);
        // Jog released: stream from wherever the input is now; only increments move.
        for _ in 0..2000 {
            c.step(Move::Stream, 777);
        }
        assert_eq!(c.position(), -49_000);
    }

    #[test]
    fn stream_passes_increments_and_relative_moves_add_up() {
        let mut c = path(AccDecKind::MovingAverage);
        c.reset(50);
        for k in 0..100 {
            c.step(Move::Stream, 50 + 7 * k);
        }
        let m = c.relative(-1000, 10.0);
        for _ in 0..400 {
            c.step(m, 50 + 7 * 99);
        }
        assert_eq!(c.position(), 50 + 7 * 99 - 1000);
    }
}
