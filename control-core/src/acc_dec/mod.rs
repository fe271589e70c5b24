//! Post-interpolation acceleration/deceleration (seed 003): the pulses per position tick that
//! the interpolator produces pass through a low-pass filter that shapes the velocity, and come
//! out as whole pulses again without losing or creating any.
//!
//! Two filters: the prior art's cascaded moving averages ([`MovingAverageCascade`], integer
//! arithmetic) and the seed's Butterworth low-pass discretised by pole-zero matching
//! ([`ButterworthDesign`], run on pulses by [`ButterworthPulseFilter`] in integer arithmetic;
//! [`reference::ReferenceFilter`] is the same filter in f64 for the checks).

mod butterworth;
mod fixed_point;
mod moving_average;
mod pulse_filter;
pub mod reference;

pub use butterworth::{
    ButterworthDesign, PolePair, RealPole, ZeroPlacement, MAX_ORDER, MIN_CUTOFF_HZ, MIN_CUTOFF_TIMES_PERIOD,
};
pub use moving_average::{MovingAverageCascade, MAX_MOVING_AVERAGE_LENGTH, MAX_MOVING_AVERAGE_STAGES};
pub use pulse_filter::{ButterworthPulseFilter, MAX_FILTERED_PULSES};

use core::fmt;
use core::mem::MaybeUninit;

/// Which acc/dec filter sits between the interpolator and the position loop.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum AccDecKind {
    /// Pulses pass unchanged.
    #[default]
    None,
    MovingAverage,
    Butterworth,
}

impl AccDecKind {
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(Self::None),
            1 => Some(Self::MovingAverage),
            2 => Some(Self::Butterworth),
            _ => None,
        }
    }

    /// The inverse of [`Self::from_code`].
    pub fn code(self) -> i32 {
        match self {
            Self::None => 0,
            Self::MovingAverage => 1,
            Self::Butterworth => 2,
        }
    }
}

/// Acc/dec settings (part of [`crate::Params`]).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AccDecParams {
    pub kind: AccDecKind,
    /// Butterworth order, 1 to 6.
    pub order: u32,
    /// Butterworth cut-off (Hz); at least [`MIN_CUTOFF_HZ`] (and [`MIN_CUTOFF_TIMES_PERIOD`]
    /// over the position-loop period), at most the position loop's Nyquist frequency.
    pub cutoff_hz: f32,
    /// Moving-average stages in use (1 to 3) and their lengths (position ticks).
    pub ma_stages: u32,
    pub ma_lengths: [u32; MAX_MOVING_AVERAGE_STAGES],
}

impl Default for AccDecParams {
    /// Off; when switched on: 3rd-order Butterworth at 40 Hz (twice the default position
    /// loop's 20 Hz bandwidth, the seed's rule), or three 16-tick moving averages.
    fn default() -> Self {
        Self { kind: AccDecKind::None, order: 3, cutoff_hz: 40.0, ma_stages: 3, ma_lengths: [16; 3] }
    }
}

/// The configured filter, running on pulses per position tick.
///
/// Sized for the largest variant (three 512-tick windows, 12 KB): without an allocator the
/// axis must hold room for any filter the parameters may select. Built where it lives with
/// [`Self::new_in`] (a drive's axis never holds one on a stack); `#[repr(u32)]` gives the
/// enum the layout that makes that possible (see `MovingAverageVariant`).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(u32)]
pub enum AccDecFilter {
    None,
    MovingAverage(MovingAverageCascade),
    Butterworth(ButterworthPulseFilter),
}

impl AccDecFilter {
    /// Build from settings at the position-loop period (s). Every setting is checked, also
    /// those of the kinds not selected, so that switching kind later cannot fail.
    #[allow(unsafe_code)]
    pub fn new(p: &AccDecParams, sample_period: f32) -> Result<Self, AccDecError> {
        let mut slot = MaybeUninit::uninit();
        Self::new_in(&mut slot, p, sample_period)?;
        // SAFETY: built above.
        Ok(unsafe { slot.assume_init() })
    }

    /// [`Self::new`] built in `slot` (no filter value on the stack: the moving averages'
    /// windows, 12 KB, are zeroed where they live). Refused, writing nothing, as `new`.
    #[allow(unsafe_code)]
    pub fn new_in<'a>(
        slot: &'a mut MaybeUninit<Self>,
        p: &AccDecParams,
        sample_period: f32,
    ) -> Result<&'a mut Self, AccDecError> {
        let stages = moving_average_stages(p)?;
        MovingAverageCascade::check(&p.ma_lengths[..stages])?;
        let bw = ButterworthDesign::new(p.order, p.cutoff_hz, sample_period)?;
        match p.kind {
            AccDecKind::None => Ok(slot.write(Self::None)),
            AccDecKind::Butterworth => Ok(slot.write(Self::Butterworth(ButterworthPulseFilter::new(bw)))),
            AccDecKind::MovingAverage => {
                let variant = slot.as_mut_ptr().cast::<MovingAverageVariant>();
                // SAFETY: `#[repr(u32)]` lays the enum out as a union of `#[repr(C)]` structs,
                // each the tag followed by one variant's fields (the Rust reference, "Primitive
                // representation of enums with fields"): `MovingAverageVariant` is the
                // moving-average variant's, so writing its tag and building its cascade (the
                // lengths checked above) initialises `slot` as that variant.
                unsafe {
                    core::ptr::addr_of_mut!((*variant).tag).write(Tag::MovingAverage);
                    MovingAverageCascade::init(core::ptr::addr_of_mut!((*variant).cascade), &p.ma_lengths[..stages]);
                    Ok(slot.assume_init_mut())
                }
            }
        }
    }

    /// [`Self::new`]'s checks, in its order, without building the filter: a parameter check
    /// needs no room for one (12 KB, most of it moving-average windows; on the Cortex-M4 that
    /// room in `Params::validate`'s frame, under `Axis::new`'s, overflowed the stack).
    pub fn check(p: &AccDecParams, sample_period: f32) -> Result<(), AccDecError> {
        let stages = moving_average_stages(p)?;
        MovingAverageCascade::check(&p.ma_lengths[..stages])?;
        ButterworthDesign::new(p.order, p.cutoff_hz, sample_period)?;
        Ok(())
    }

    /// Empty the filter (as built; settings kept).
    pub fn reset(&mut self) {
        match self {
            Self::None => {}
            Self::MovingAverage(m) => m.reset(),
            Self::Butterworth(b) => b.reset(),
        }
    }

    /// One position tick: pulses in, whole pulses out.
    pub fn step(&mut self, pulses: i64) -> i64 {
        match self {
            Self::None => pulses,
            Self::MovingAverage(m) => m.step(pulses),
            Self::Butterworth(b) => b.step(pulses),
        }
    }
}

/// [`AccDecFilter`]'s tags under `#[repr(u32)]`: its variants' discriminants, in the order
/// they are declared.
#[allow(dead_code)] // only `MovingAverage` is written by name; the others keep the order
#[derive(Clone, Copy)]
#[repr(u32)]
enum Tag {
    None,
    MovingAverage,
    Butterworth,
}

/// The moving-average variant of [`AccDecFilter`] as `#[repr(u32)]` lays it out: its tag, then
/// its field.
#[repr(C)]
struct MovingAverageVariant {
    tag: Tag,
    cascade: MovingAverageCascade,
}

/// The number of moving-average stages, 1 to [`MAX_MOVING_AVERAGE_STAGES`].
fn moving_average_stages(p: &AccDecParams) -> Result<usize, AccDecError> {
    let stages = p.ma_stages as usize;
    if (1..=MAX_MOVING_AVERAGE_STAGES).contains(&stages) {
        Ok(stages)
    } else {
        Err(AccDecError::Stages(stages))
    }
}

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
    /// Cut-off below the lowest the filter keeps within a count of its design at this sample
    /// period ([`MIN_CUTOFF_HZ`], [`MIN_CUTOFF_TIMES_PERIOD`]).
    CutoffBelowMinimum { cutoff_hz: f32, minimum_hz: f32 },
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
            Self::CutoffAboveNyquist { cutoff_hz, nyquist_hz } => {
                write!(f, "cut-off {cutoff_hz} Hz is above the Nyquist frequency {nyquist_hz} Hz of the sample period")
            }
            Self::CutoffBelowMinimum { cutoff_hz, minimum_hz } => write!(
                f,
                "cut-off {cutoff_hz} Hz is below {minimum_hz} Hz, the lowest the filter keeps within a count of its \
                 design at this sample period (at least {MIN_CUTOFF_HZ} Hz and {MIN_CUTOFF_TIMES_PERIOD} / period)"
            ),
            Self::SamplePeriod(t) => write!(f, "sample period {t} s must be a positive finite time"),
            Self::Stages(n) => {
                write!(f, "{n} moving-average stages: use 1..={MAX_MOVING_AVERAGE_STAGES}")
            }
            Self::Length { stage, length } => {
                write!(f, "moving-average stage {stage} has length {length}: use 1..={MAX_MOVING_AVERAGE_LENGTH}")
            }
        }
    }
}

#[cfg(test)]
mod tests;
