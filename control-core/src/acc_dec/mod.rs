//! Post-interpolation acceleration/deceleration (seed 003): the pulses per position tick that
//! the interpolator produces pass through a low-pass filter that shapes the velocity, and come
//! out as whole pulses again without losing or creating any.
//!
//! Two filters: the prior art's cascaded moving averages ([`MovingAverageCascade`], integer
//! arithmetic) and the seed's Butterworth low-pass discretised by pole-zero matching
//! ([`ButterworthDesign`], [`ButterworthPulseFilter`]).

mod butterworth;
mod moving_average;

pub use butterworth::{ButterworthDesign, ButterworthPulseFilter, FirstOrderSection, MAX_ORDER};
pub use moving_average::{MovingAverageCascade, MAX_MOVING_AVERAGE_LENGTH, MAX_MOVING_AVERAGE_STAGES};

use core::fmt;

/// Why an acc/dec filter cannot be built. Nothing is configured when one is returned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum AccDecError {
    /// Butterworth order outside 1..=6.
    Order(u32),
    /// Cut-off not a positive finite frequency (Hz).
    Cutoff(f32),
    /// Cut-off above the Nyquist frequency of the sample period (at Nyquist is allowed: the
    /// seed's own example sits there).
    CutoffAboveNyquist { cutoff_hz: f32, nyquist_hz: f32 },
    /// Sample period not a positive finite time (s).
    SamplePeriod(f32),
    /// Number of moving-average stages outside 1..=3.
    Stages(usize),
    /// A moving-average length of 0 or above the maximum.
    Length { stage: usize, length: u32 },
}

impl fmt::Display for AccDecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Order(n) => write!(f, "Butterworth order {n} is outside 1..={MAX_ORDER}"),
            Self::Cutoff(c) => write!(f, "cut-off {c} Hz must be a positive finite frequency"),
            Self::CutoffAboveNyquist { cutoff_hz, nyquist_hz } => write!(
                f,
                "cut-off {cutoff_hz} Hz is above the Nyquist frequency {nyquist_hz} Hz of the sample period"
            ),
            Self::SamplePeriod(t) => write!(f, "sample period {t} s must be a positive finite time"),
            Self::Stages(n) => {
                write!(f, "{n} moving-average stages: use 1..={MAX_MOVING_AVERAGE_STAGES}")
            }
            Self::Length { stage, length } => write!(
                f,
                "moving-average stage {stage} has length {length}: use 1..={MAX_MOVING_AVERAGE_LENGTH}"
            ),
        }
    }
}

#[cfg(test)]
mod tests;
