//! Frequency-response measurement on the drive (seed 000): a stepped sine whose repeats are
//! phase shifted, so the response stays measurable above the acquisition's Nyquist frequency.
//!
//! The loop runs faster than the acquisition. A sine of frequency f is injected at the loop
//! rate; U and Y are acquired every `acquisition_divider` base ticks, each sample with the
//! excitation's phase θ at that instant. The response is `G = Y/U`, the complex amplitudes
//! of sines fitted to y and u at those phases: the phase, not the sample time, is the time
//! base, so records with different initial phases add up as one equivalent-time record. At
//! and above `threshold_hz` (default: the acquisition Nyquist frequency) each frequency is
//! measured `repeats` times with initial phases `r·2π/shifts` (claims 5 and 6); below, once,
//! unshifted. A single record sampled at exactly fs/2 sees the sine at one phase and its
//! opposite only: cos θ and sin θ are collinear and the sine cannot be told apart from its
//! phase. Records shifted by 2π/3 spread the phases over the circle.
//!
//! What U and Y are, per injection point (the sine s is added there):
//! - velocity command: U = velocity reference + s, Y = velocity estimate → closed velocity
//!   loop T = CP/(1 + CP);
//! - torque command: U = torque command + s, Y = velocity estimate → plant P (torque to motor
//!   velocity, measured inside the running loop);
//! - velocity feedback (the seed's figure): the controller sees estimate + s; U = estimate + s,
//!   Y = estimate → `−Y/U` is the open loop L = CP (the sign is applied in the result).
//!
//! Below the threshold an acquisition sample is the mean of u and of y over the loop ticks of
//! its acquisition period (the same average on both cancels in Y/U; it keeps the encoder's
//! differentiated quantisation noise from folding down to low frequencies); from the
//! threshold up it is the instantaneous value, as equivalent-time sampling needs.
//!
//! The sine is phase continuous across frequencies (a new frequency starts at the phase the
//! old one reached), so a step does not jolt the loop. The measurement starts when the loop
//! has settled, judged from the response itself, not from a number of periods: the first
//! record of a frequency is measured in half blocks, and the earlier of two half blocks is
//! discarded while their responses disagree beyond the precision (or their residuals still
//! decay; see [`PhaseShiftedSweep::settled`]). Each sample carries its half-block index, so
//! that a host fitting the stream keeps the same samples. Precision control then lengthens a
//! frequency's records by half blocks until the predicted standard errors of G, gain and
//! phase, meet `precision_db` (see [`SineFitSums::response_error`]).
//!
//! The on-line correlator keeps the sums of a three-parameter sine fit per frequency (no
//! sample buffers; see [`SineFitSums`]); results
//! for up to [`MAX_SWEEP_POINTS`] frequencies are kept. A PRBS mode (an M-sequence of configurable
//! degree and chip rate: seed 001's identification excitation) feeds the same acquisition.

use core::fmt;

use crate::excitation::{phase_angle, InjectionPoint, SineGenerator};
use crate::m_sequence::MSequence;
use crate::trigonometry::ReducedAngle;
use crate::TAU;

pub const MAX_SWEEP_POINTS: usize = 128;
const MAX_SHIFTS: u32 = 16;
/// Upper bound of `SweepParams::max_extensions`.
pub const MAX_EXTENSIONS: u32 = 64;
/// Upper bound of `SweepParams::dither` (N·m).
pub const MAX_SWEEP_DITHER: f32 = 1000.0;

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SweepSignal {
    #[default]
    SteppedSine,
    /// Maximum-length binary sequence, ±amplitude.
    Prbs,
}

impl SweepSignal {
    /// The signal of a `sweep.signal` code: 0 stepped sine, 1 PRBS.
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(Self::SteppedSine),
            1 => Some(Self::Prbs),
            _ => None,
        }
    }

    /// The inverse of [`Self::from_code`].
    pub fn code(self) -> i32 {
        match self {
            Self::SteppedSine => 0,
            Self::Prbs => 1,
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SweepParams {
    pub point: InjectionPoint,
    pub signal: SweepSignal,
    /// Sine or PRBS amplitude (rad/s or Nm, as the point).
    pub amplitude: f32,
    pub start_hz: f32,
    pub stop_hz: f32,
    /// Frequencies between start and stop, both included (≥ 2).
    pub points: u32,
    pub logarithmic: bool,
    /// One more frequency inserted in order (0: none), for example the acquisition Nyquist.
    pub extra_hz: f32,
    /// Settling before each record: the longer of so many cycles and `min_settle_s`.
    pub settle_cycles: f32,
    pub min_settle_s: f32,
    /// Measurement of each record: the longer of so many cycles and `min_measure_s`.
    pub measure_cycles: f32,
    pub min_measure_s: f32,
    /// Phase step 2π/shifts between repeats.
    pub shifts: u32,
    /// Records per frequency at and above the threshold.
    pub repeats: u32,
    /// Phase shifting from this frequency up (0: the acquisition Nyquist frequency).
    pub threshold_hz: f32,
    /// Base ticks per acquisition sample (a multiple of the velocity divider).
    pub acquisition_divider: u32,
    /// PRBS: M-sequence degree (period 2^n − 1 chips), base ticks per chip, and the measured
    /// duration after `min_settle_s`.
    pub prbs_degree: u32,
    pub prbs_divider: u32,
    pub prbs_seconds: f32,
    /// Stepped sine: lengthen a frequency's records by whole blocks so that the standard
    /// error of its gain (predicted from the fit's residual after the first block: mostly
    /// encoder quantisation) is at most this (dB; 0: fixed records). At low-gain points (a
    /// deep anti-resonance, the top of the sweep) the response is a few encoder counts and
    /// the base record leaves about 0.1 dB of error whose size depends on the fine detail of
    /// the motion; the well-measured points are not lengthened.
    pub precision_db: f32,
    /// At most so many extra blocks (each as long as one record's base measurement) per
    /// record of a frequency, and at most twice as many half blocks discarded while its first
    /// record settles.
    pub max_extensions: u32,
    /// Stepped sine: a pseudo-random ±dither (N·m) added to the torque command on every base
    /// tick of the frequencies at and above the threshold (0: none). At constant speed and
    /// without sensor noise the encoder's count pattern is periodic and can lock to the
    /// excitation: at the top of the sweep, where the response is a few counts, a
    /// quantisation error that longer records do not remove (0.24 dB at 3 kHz on the default
    /// axis). A dither of a few milli-newton-metres moves the axis by enough counts to break
    /// the lock; the fit sees it as noise. Below the threshold the samples are period means
    /// (see [`PhaseShiftedSweep::end_tick`]) and need none.
    pub dither: f32,
}

impl Default for SweepParams {
    /// Velocity-command injection, 10 Hz to 3 kHz in 40 log steps plus 2 kHz, 1 settle and
    /// 3 measure cycles (at least 10 ms of settling and 40 ms of measurement), 3 records
    /// shifted by 2π/3 from the acquisition Nyquist frequency up, acquisition every 4 ticks
    /// (4 kHz at 16 kHz). The base records are short: the settling check lengthens the wait
    /// where the loop rings (see `PhaseShiftedSweep::settled`), the precision control the
    /// records where the response is noisy (near 3 kHz it is a few encoder counts per
    /// velocity period).
    fn default() -> Self {
        Self {
            point: InjectionPoint::VelocityCommand,
            signal: SweepSignal::SteppedSine,
            amplitude: 2.0,
            start_hz: 10.0,
            stop_hz: 3000.0,
            points: 40,
            logarithmic: true,
            extra_hz: 2000.0,
            settle_cycles: 1.0,
            min_settle_s: 0.01,
            measure_cycles: 3.0,
            min_measure_s: 0.04,
            shifts: 3,
            repeats: 3,
            threshold_hz: 0.0,
            acquisition_divider: 4,
            prbs_degree: 15,
            prbs_divider: 1,
            prbs_seconds: 5.0,
            precision_db: 0.03,
            max_extensions: 8,
            dither: 0.003,
        }
    }
}

/// Why sweep settings or a start were refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SweepError {
    /// A value outside its range: the field and the value.
    Setting { field: &'static str, value: f32 },
    /// A value outside `[min, max]`.
    Range { field: &'static str, value: f32, min: f32, max: f32 },
    /// A frequency at or above the loop's Nyquist frequency, where the injected sine aliases.
    AboveLoopNyquist { frequency: f32, nyquist: f32 },
    /// More frequencies than the result table holds.
    TooManyPoints(u32),
    /// The acquisition divider is not a multiple of the velocity divider.
    AcquisitionDivider { acquisition: u32, velocity: u32 },
    /// Injection point off, or a velocity-loop point while the velocity loop does not run.
    PointUnusable,
    /// A sweep is already running.
    Busy,
}

impl fmt::Display for SweepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Setting { field, value } => write!(f, "sweep {field} = {value} is out of range"),
            Self::Range { field, value, min, max } => write!(f, "sweep {field} = {value} is outside [{min}, {max}]"),
            Self::AboveLoopNyquist { frequency, nyquist } => {
                write!(f, "sweep frequency {frequency} Hz is at or above the loop's Nyquist frequency {nyquist} Hz")
            }
            Self::TooManyPoints(n) => write!(f, "{n} sweep frequencies: at most {MAX_SWEEP_POINTS}"),
            Self::AcquisitionDivider { acquisition, velocity } => write!(
                f,
                "acquisition every {acquisition} ticks is not a multiple of the velocity loop's {velocity} ticks"
            ),
            Self::PointUnusable => write!(
                f,
                "the sweep needs an injection point, and velocity-command or feedback injection needs the velocity loop (velocity, position or sequence mode)"
            ),
            Self::Busy => write!(f, "a sweep is already running"),
        }
    }
}

/// Where the extra frequency sits among the planned ones, found once: both the count and the
/// position take every base frequency (a power each, about 20 000 instructions for 128 points
/// on a Cortex-M4), which the runner must not compute inside a control tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrequencyPlan {
    /// Number of frequencies (with the extra one; at most `MAX_SWEEP_POINTS`).
    pub count: u16,
    /// Index of the extra frequency (`NO_EXTRA`: none, or it is one of the base frequencies).
    pub extra_at: u16,
}

/// [`FrequencyPlan::extra_at`] when there is no extra frequency.
pub const NO_EXTRA: u16 = u16::MAX;

impl SweepParams {
    /// Number of frequencies (with the extra one).
    pub fn count(&self) -> usize {
        let extra = self.extra_hz > 0.0 && !(0..self.points as usize).any(|i| self.base(i) == self.extra_hz);
        self.points as usize + extra as usize
    }

    /// The count and the extra frequency's place (see [`FrequencyPlan`]).
    /// Settings that passed [`Self::validate`] have at most `MAX_SWEEP_POINTS`; larger counts
    /// saturate (a sweep is never built from them).
    pub fn plan(&self) -> FrequencyPlan {
        let count = u16::try_from(self.count()).unwrap_or(u16::MAX);
        if count as u32 == self.points {
            return FrequencyPlan { count, extra_at: NO_EXTRA };
        }
        let at = (0..self.points as usize).filter(|&j| self.base(j) < self.extra_hz).count();
        FrequencyPlan { count, extra_at: u16::try_from(at).unwrap_or(NO_EXTRA - 1) }
    }

    fn base(&self, i: usize) -> f32 {
        let x = i as f32 / (self.points - 1) as f32;
        if self.logarithmic {
            self.start_hz * libm::powf(self.stop_hz / self.start_hz, x)
        } else {
            self.start_hz + (self.stop_hz - self.start_hz) * x
        }
    }

    /// The i-th frequency in ascending order.
    pub fn frequency(&self, i: usize) -> f32 {
        self.frequency_in(&self.plan(), i)
    }

    /// The i-th frequency of `plan` (this parameter set's [`Self::plan`]): one power at most.
    pub fn frequency_in(&self, plan: &FrequencyPlan, i: usize) -> f32 {
        if plan.extra_at == NO_EXTRA {
            return self.base(i);
        }
        let at = plan.extra_at as usize;
        match i.cmp(&at) {
            core::cmp::Ordering::Less => self.base(i),
            core::cmp::Ordering::Equal => self.extra_hz,
            core::cmp::Ordering::Greater => self.base(i - 1),
        }
    }

    /// Phase shifting from this frequency up.
    pub fn threshold(&self, base_rate_hz: f32) -> f32 {
        if self.threshold_hz > 0.0 {
            self.threshold_hz
        } else {
            0.5 * base_rate_hz / self.acquisition_divider as f32
        }
    }

    /// Records at frequency f.
    pub fn records(&self, f: f32, base_rate_hz: f32) -> u32 {
        if f >= self.threshold(base_rate_hz) {
            self.repeats
        } else {
            1
        }
    }

    /// Settling ticks (a whole number of acquisition periods) and measured samples of one
    /// record at f.
    pub fn record_length(&self, f: f32, base_rate_hz: f32) -> (u64, u64) {
        let d = self.acquisition_divider as f32;
        let settle = libm::ceilf(self.min_settle_s.max(self.settle_cycles / f) * base_rate_hz / d) as u64;
        let samples = (libm::roundf(self.min_measure_s.max(self.measure_cycles / f) * base_rate_hz / d) as u64).max(1);
        (settle.saturating_mul(self.acquisition_divider as u64), samples)
    }

    /// Base ticks from the start to the end of the sweep when no frequency is extended (the
    /// sweep's length when `precision_db` is 0 or every point meets it at once).
    pub fn total_ticks(&self, base_rate_hz: f32) -> u64 {
        self.ticks_with_extensions(base_rate_hz, 0)
    }

    /// Base ticks of the sweep when every frequency takes all `max_extensions` blocks and
    /// discards `2·max_extensions` half blocks while settling: the longest it can run.
    pub fn max_total_ticks(&self, base_rate_hz: f32) -> u64 {
        let extensions = if self.precision_db > 0.0 { self.max_extensions } else { 0 };
        self.ticks_with_extensions(base_rate_hz, extensions)
    }

    /// `extensions` blocks per record, and as many blocks of half blocks discarded while the
    /// first record settles (see `PhaseShiftedSweep::settled`).
    fn ticks_with_extensions(&self, base_rate_hz: f32, extensions: u32) -> u64 {
        let d = self.acquisition_divider as u64;
        match self.signal {
            SweepSignal::Prbs => {
                let settle = (libm::ceilf(self.min_settle_s * base_rate_hz / d as f32) as u64).saturating_mul(d);
                settle.saturating_add(
                    (libm::roundf(self.prbs_seconds * base_rate_hz / d as f32) as u64).saturating_mul(d),
                )
            }
            SweepSignal::SteppedSine => (0..self.count())
                .map(|i| {
                    let f = self.frequency(i);
                    let (settle, samples) = self.record_length(f, base_rate_hz);
                    let added = (samples / 2).saturating_mul(2 * extensions as u64);
                    let measure = samples.saturating_add(added).saturating_mul(d);
                    let discarded = (samples / 2).saturating_mul(d).saturating_mul(2 * extensions as u64);
                    (self.records(f, base_rate_hz) as u64)
                        .saturating_mul(settle.saturating_add(measure))
                        .saturating_add(discarded)
                })
                .fold(0u64, u64::saturating_add),
        }
    }

    pub fn validate(&self, base_rate_hz: f32, velocity_divider: u32) -> Result<(), SweepError> {
        let finite_positive = |field, value: f32| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(SweepError::Setting { field, value })
            }
        };
        let finite_non_negative = |field, value: f32| {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(SweepError::Setting { field, value })
            }
        };
        finite_positive("amplitude", self.amplitude)?;
        finite_positive("start_hz", self.start_hz)?;
        finite_positive("stop_hz", self.stop_hz)?;
        if self.stop_hz <= self.start_hz {
            return Err(SweepError::Setting { field: "stop_hz (must exceed start_hz)", value: self.stop_hz });
        }
        finite_non_negative("extra_hz", self.extra_hz)?;
        if self.points < 2 {
            return Err(SweepError::Setting { field: "points", value: self.points as f32 });
        }
        if self.points as usize + 1 > MAX_SWEEP_POINTS {
            return Err(SweepError::TooManyPoints(self.points));
        }
        finite_non_negative("settle_cycles", self.settle_cycles)?;
        finite_non_negative("min_settle_s", self.min_settle_s)?;
        finite_positive("measure_cycles", self.measure_cycles)?;
        finite_non_negative("min_measure_s", self.min_measure_s)?;
        if !(1..=MAX_SHIFTS).contains(&self.shifts) {
            return Err(SweepError::Setting { field: "shifts", value: self.shifts as f32 });
        }
        if !(1..=MAX_SHIFTS).contains(&self.repeats) {
            return Err(SweepError::Setting { field: "repeats", value: self.repeats as f32 });
        }
        finite_non_negative("threshold_hz", self.threshold_hz)?;
        if self.acquisition_divider == 0 || !self.acquisition_divider.is_multiple_of(velocity_divider) {
            return Err(SweepError::AcquisitionDivider {
                acquisition: self.acquisition_divider,
                velocity: velocity_divider,
            });
        }
        if MSequence::new(self.prbs_degree).is_err() {
            return Err(SweepError::Setting { field: "prbs_degree (2 to 20)", value: self.prbs_degree as f32 });
        }
        if self.prbs_divider == 0 {
            return Err(SweepError::Setting { field: "prbs_divider", value: 0.0 });
        }
        finite_positive("prbs_seconds", self.prbs_seconds)?;
        finite_non_negative("precision_db", self.precision_db)?;
        finite_non_negative("dither", self.dither)?;
        if self.max_extensions > MAX_EXTENSIONS {
            return Err(SweepError::Setting {
                field: "max_extensions (at most 64)",
                value: self.max_extensions as f32,
            });
        }
        // Bounds that keep every tick count far from overflow (`crate::ranges`): at most
        // 10⁴ s or 10⁴ cycles from 1 mHz per record, 2·10¹² ticks at 200 kHz.
        let range = |field, value: f32, min: f32, max: f32| {
            if value >= min && value <= max {
                Ok(())
            } else {
                Err(SweepError::Range { field, value, min, max })
            }
        };
        use crate::ranges::{MAX_SWEEP_CYCLES, MAX_SWEEP_DIVIDER, MAX_SWEEP_SECONDS, MIN_SWEEP_HZ};
        range("start_hz", self.start_hz, MIN_SWEEP_HZ, f32::MAX)?;
        if self.extra_hz != 0.0 {
            range("extra_hz (0 or above)", self.extra_hz, MIN_SWEEP_HZ, f32::MAX)?;
        }
        range("settle_cycles", self.settle_cycles, 0.0, MAX_SWEEP_CYCLES)?;
        range("measure_cycles", self.measure_cycles, 0.0, MAX_SWEEP_CYCLES)?;
        range("min_settle_s", self.min_settle_s, 0.0, MAX_SWEEP_SECONDS)?;
        range("min_measure_s", self.min_measure_s, 0.0, MAX_SWEEP_SECONDS)?;
        range("prbs_seconds", self.prbs_seconds, 0.0, MAX_SWEEP_SECONDS)?;
        range("dither", self.dither, 0.0, MAX_SWEEP_DITHER)?;
        range("acquisition_divider", self.acquisition_divider as f32, 1.0, MAX_SWEEP_DIVIDER as f32)?;
        range("prbs_divider", self.prbs_divider as f32, 1.0, MAX_SWEEP_DIVIDER as f32)?;
        // The sine is updated at the velocity-loop rate for velocity-loop points.
        let loop_rate = if self.point == InjectionPoint::TorqueCommand {
            base_rate_hz
        } else {
            base_rate_hz / velocity_divider as f32
        };
        let top = self.stop_hz.max(self.extra_hz);
        if top >= 0.5 * loop_rate {
            return Err(SweepError::AboveLoopNyquist { frequency: top, nyquist: 0.5 * loop_rate });
        }
        Ok(())
    }
}

/// One measured frequency.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SweepResult {
    pub frequency: f32,
    /// G = Y/U (−Y/U for feedback injection).
    pub re: f32,
    pub im: f32,
    /// How well the samples' phases determine a sine, 0..1: 1 when they spread over the
    /// circle, 0 when they sit at one phase and its opposite (a single record at exactly fs/2).
    pub quality: f32,
}

impl SweepResult {
    pub fn gain_db(&self) -> f32 {
        20.0 * libm::log10f(libm::hypotf(self.re, self.im))
    }
    pub fn phase_deg(&self) -> f32 {
        libm::atan2f(self.im, self.re) * (360.0 / TAU)
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SweepState {
    #[default]
    Idle,
    Settling,
    Measuring,
    Done,
}

impl SweepState {
    /// The state of a `sweep_state` output code: 0 idle, 1 settling, 2 measuring, 3 done.
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(Self::Idle),
            1 => Some(Self::Settling),
            2 => Some(Self::Measuring),
            3 => Some(Self::Done),
            _ => None,
        }
    }

    /// The inverse of [`Self::from_code`].
    pub fn code(self) -> i32 {
        match self {
            Self::Idle => 0,
            Self::Settling => 1,
            Self::Measuring => 2,
            Self::Done => 3,
        }
    }
}

/// The last acquisition sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AcquisitionSample {
    /// Base tick of the sample.
    pub tick: u64,
    pub u: f32,
    pub y: f32,
    /// Excitation phase at the sample (rad, [0, 2π)); 0 in PRBS mode.
    pub phase: f32,
    /// The sample belongs to a measured record.
    pub measuring: bool,
    pub point: u32,
    /// The record (phase-shifted repeat, low 16 bits) and the half block (high 16 bits) the
    /// sample belongs to: see [`Self::record`] and [`Self::half_block`]. One word, as the
    /// record alone was: the sample stays as it was on the tick and on the link.
    pub segment: u32,
}

impl AcquisitionSample {
    /// The word of [`Self::segment`].
    pub fn segment_of(record: u32, half_block: u32) -> u32 {
        (record & 0xFFFF) | (half_block.min(0xFFFF) << 16)
    }

    /// Record (phase-shifted repeat) the sample belongs to.
    pub fn record(&self) -> u32 {
        self.segment & 0xFFFF
    }

    /// Half block of the frequency's first record the sample belongs to (see
    /// `PhaseShiftedSweep::settled`; later samples keep the last index). The response is
    /// fitted to the samples from the frequency's last index minus one up.
    pub fn half_block(&self) -> u32 {
        self.segment >> 16
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SweepStatus {
    pub state: SweepState,
    pub point: u32,
    pub record: u32,
    pub frequency: f32,
    pub done_points: u32,
    pub last: SweepResult,
    pub sample: AcquisitionSample,
}

/// Sums of a three-parameter sine fit (IEEE 1057 with known frequency) of u and y:
/// `x ≈ x̄ + b·cos θ + c·sin θ`, the complex amplitude `X = b − j·c`. Unlike a plain
/// correlation it leaks neither the constant speed the sweep rides on nor the image at
/// fs − f when a record is not a whole number of cycles; and it tells how well the sample
/// phases determine the sine: the determinant of the (cos, sin) covariance, 0 when all
/// samples sit at one phase and its opposite (a single record at exactly fs/2).
///
/// u and y are summed about their first samples (`u0`, `y0`): the constant speed the sweep
/// rides on would otherwise swamp the f32 sums, in particular the squares, which give the
/// residuals. The squares and the cross product of u and y, and those of their differences
/// between consecutive samples of a record, give the noise of U and Y at the excitation
/// frequency (see [`SineFitSums::response_error`]).
#[derive(Clone, Copy, Debug, Default)]
struct SineFitSums {
    u0: f32,
    y0: f32,
    uu: f32,
    yy: f32,
    uy: f32,
    n: f32,
    c: f32,
    s: f32,
    cc: f32,
    ss: f32,
    cs: f32,
    u: f32,
    uc: f32,
    us: f32,
    y: f32,
    yc: f32,
    ys: f32,
    /// Differences between consecutive samples of one record: their count, squares and
    /// cross product, and the previous sample (`None` at a record's start).
    dn: f32,
    duu: f32,
    dyy: f32,
    duy: f32,
    previous: (f32, f32),
    has_previous: bool,
    /// Σcos², Σsin², Σcos·sin of the records' first samples (which start no difference).
    first_cc: f32,
    first_ss: f32,
    first_cs: f32,
}

/// Standard errors of a measured response `G = Y/U`, relative to |G|: the gain's (radial) and
/// the phase's (tangential, rad).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResponseError {
    pub gain: f32,
    pub phase: f32,
}

impl ResponseError {
    /// The gain's standard error in dB.
    pub fn gain_db(&self) -> f32 {
        20.0 / core::f32::consts::LN_10 * self.gain
    }
}

impl SineFitSums {
    /// One sample with the sine and cosine of its phase.
    fn add(&mut self, u: f32, y: f32, (s, c): (f32, f32)) {
        if self.n == 0.0 {
            self.u0 = u;
            self.y0 = y;
        }
        let u = u - self.u0;
        let y = y - self.y0;
        if self.has_previous {
            let (du, dy) = (u - self.previous.0, y - self.previous.1);
            self.dn += 1.0;
            self.duu += du * du;
            self.dyy += dy * dy;
            self.duy += du * dy;
        } else {
            self.first_cc += c * c;
            self.first_ss += s * s;
            self.first_cs += c * s;
        }
        self.previous = (u, y);
        self.has_previous = true;
        self.uu += u * u;
        self.yy += y * y;
        self.uy += u * y;
        self.n += 1.0;
        self.c += c;
        self.s += s;
        self.cc += c * c;
        self.ss += s * s;
        self.cs += c * s;
        self.u += u;
        self.uc += u * c;
        self.us += u * s;
        self.y += y;
        self.yc += y * c;
        self.ys += y * s;
    }

    /// The sums of the samples added since `earlier` (a copy of these sums taken before):
    /// the same fit over that stretch only (same offsets, same last sample).
    fn since(&self, earlier: &Self) -> Self {
        Self {
            uu: self.uu - earlier.uu,
            yy: self.yy - earlier.yy,
            uy: self.uy - earlier.uy,
            n: self.n - earlier.n,
            c: self.c - earlier.c,
            s: self.s - earlier.s,
            cc: self.cc - earlier.cc,
            ss: self.ss - earlier.ss,
            cs: self.cs - earlier.cs,
            u: self.u - earlier.u,
            uc: self.uc - earlier.uc,
            us: self.us - earlier.us,
            y: self.y - earlier.y,
            yc: self.yc - earlier.yc,
            ys: self.ys - earlier.ys,
            dn: self.dn - earlier.dn,
            duu: self.duu - earlier.duu,
            dyy: self.dyy - earlier.dyy,
            duy: self.duy - earlier.duy,
            first_cc: self.first_cc - earlier.first_cc,
            first_ss: self.first_ss - earlier.first_ss,
            first_cs: self.first_cs - earlier.first_cs,
            ..*self
        }
    }

    /// `G = Y/U` of these sums (None when the phases or U cannot tell).
    fn response(&self) -> Option<(f32, f32)> {
        let ((u_re, u_im), (y_re, y_im), quality) = self.solve();
        let den = u_re * u_re + u_im * u_im;
        if den > 0.0 && quality > 0.0 {
            Some(((y_re * u_re + y_im * u_im) / den, (y_im * u_re - y_re * u_im) / den))
        } else {
            None
        }
    }

    /// A new record starts: its first sample has no predecessor.
    fn break_record(&mut self) {
        self.has_previous = false;
    }

    /// The centred (cos, sin) normal equations: `n` (at least 1), `Scc'`, `Sss'`, `Scs'` and
    /// their determinant.
    fn normal_equations(&self) -> NormalEquations {
        let n = self.n.max(1.0);
        let scc = self.cc - self.c * self.c / n;
        let sss = self.ss - self.s * self.s / n;
        let scs = self.cs - self.c * self.s / n;
        NormalEquations { n, scc, sss, scs, det: scc * sss - scs * scs }
    }

    /// `(b, c)` of `x ≈ x̄ + b·cos θ + c·sin θ` from x's sums, and the centred sums
    /// `(Sxc', Sxs')` they solve.
    fn coefficients(&self, e: &NormalEquations, x: f32, xc: f32, xs: f32) -> ((f32, f32), (f32, f32)) {
        let (pc, ps) = (xc - x * self.c / e.n, xs - x * self.s / e.n);
        (((e.sss * pc - e.scs * ps) / e.det, (e.scc * ps - e.scs * pc) / e.det), (pc, ps))
    }

    /// (U, Y) complex amplitudes and the conditioning of the phases (0..1).
    fn solve(&self) -> ((f32, f32), (f32, f32), f32) {
        let e = self.normal_equations();
        let amplitude = |x: f32, xc: f32, xs: f32| {
            let ((b, c), _) = self.coefficients(&e, x, xc, xs);
            (b, -c)
        };
        let conditioning = crate::limit(e.det / (0.25 * e.n * e.n), 0.0, 1.0);
        (amplitude(self.u, self.uc, self.us), amplitude(self.y, self.yc, self.ys), conditioning)
    }

    /// Standard errors of `G = Y/U` (gain and phase, relative), from the residuals of both
    /// fits. The noise of U and Y and their correlation (on the torque command U carries the
    /// loop's reaction to the noise of Y) enter as `δG/G = δY/Y − δU/U`. The noise at the
    /// excitation frequency, not its average over the band, decides: the residuals' variance
    /// γ₀ and lag-one covariance γ₁ (from the differences of consecutive samples) give the
    /// first-order noise spectrum `γ₀ + 2γ₁·cos(ω·Tₐ)` (`step`: ω·Tₐ, the excitation's
    /// phase step between samples). Encoder quantisation in a velocity averaged over the
    /// acquisition period has exactly this form (γ₁ = −γ₀/2: little noise at low
    /// frequencies, twice the average near the acquisition Nyquist frequency). None when the
    /// samples cannot tell (too few, phases degenerate, no response).
    fn response_error(&self, step: f32) -> Option<ResponseError> {
        if self.n < 8.0 || self.dn < 4.0 {
            return None;
        }
        let e = self.normal_equations();
        if !(e.det > 1e-6 * e.n * e.n) {
            return None;
        }
        let ((bu, cu), (pcu, psu)) = self.coefficients(&e, self.u, self.uc, self.us);
        let ((by, cy), (pcy, psy)) = self.coefficients(&e, self.y, self.yc, self.ys);
        let (au, ay) = (bu * bu + cu * cu, by * by + cy * cy);
        if !(au > 0.0 && ay > 0.0) {
            return None;
        }
        // Residual sums: Σr_u², Σr_y², Σr_u·r_y.
        let ruu = self.uu - self.u * self.u / e.n - (bu * pcu + cu * psu);
        let ryy = self.yy - self.y * self.y / e.n - (by * pcy + cy * psy);
        let ruy = self.uy - self.u * self.y / e.n - (by * pcu + cy * psu);
        // The fitted sine's difference between consecutive samples is the sine of
        // coefficients (b(1 − cos φ) + c·sin φ, c(1 − cos φ) − b·sin φ) at the later sample;
        // its sum of squares over the differences (the phase sums without the records' first
        // samples) comes off the differences'.
        let (sin_step, cos_step) = crate::trigonometry::sin_cos(step);
        let (pcc, pss, pcs) = (self.cc - self.first_cc, self.ss - self.first_ss, self.cs - self.first_cs);
        let rotated = |b: f32, c: f32| (b * (1.0 - cos_step) + c * sin_step, c * (1.0 - cos_step) - b * sin_step);
        let ((dbu, dcu), (dby, dcy)) = (rotated(bu, cu), rotated(by, cy));
        let quadratic = |b1: f32, c1: f32, b2: f32, c2: f32| b1 * b2 * pcc + c1 * c2 * pss + (b1 * c2 + c1 * b2) * pcs;
        let druu = self.duu - quadratic(dbu, dcu, dbu, dcu);
        let dryy = self.dyy - quadratic(dby, dcy, dby, dcy);
        let druy = self.duy - quadratic(dbu, dcu, dby, dcy);
        // Spectrum at the excitation: γ₀ + 2γ₁ cos φ with γ₁ = γ₀ − Σ(Δr)²/(2·dn).
        let dof = e.n - 3.0;
        let spectrum = |r: f32, dr: f32| {
            let g0 = r / dof;
            let g1 = g0 - dr / (2.0 * self.dn);
            g0 + 2.0 * g1 * cos_step
        };
        let (suu, syy) = (spectrum(ruu, druu).max(0.0), spectrum(ryy, dryy).max(0.0));
        let bound = crate::square_root::sqrt(suu * syy);
        let suy = crate::limit(spectrum(ruy, druy), -bound, bound);
        // (δb, δc) of any fit have the covariance σ²·[[Sss', −Scs'], [−Scs', Scc']]/det.
        let form = |(p1, q1): (f32, f32), (p2, q2): (f32, f32)| {
            (p1 * p2 * e.sss - (p1 * q2 + q1 * p2) * e.scs + q1 * q2 * e.scc) / e.det
        };
        // Re(δX/X) = (b·δb + c·δc)/|X|², Im(δX/X) = (c·δb − b·δc)/|X|².
        let variance = |wy: (f32, f32), wu: (f32, f32)| {
            (syy * form(wy, wy) + suu * form(wu, wu) - 2.0 * suy * form(wy, wu)).max(0.0)
        };
        let gain = variance((by / ay, cy / ay), (bu / au, cu / au));
        let phase = variance((cy / ay, -by / ay), (cu / au, -bu / au));
        Some(ResponseError { gain: crate::square_root::sqrt(gain), phase: crate::square_root::sqrt(phase) })
    }
}

/// See [`SineFitSums::normal_equations`].
struct NormalEquations {
    n: f32,
    scc: f32,
    sss: f32,
    scs: f32,
    det: f32,
}

/// Half blocks agree within so many standard deviations of their difference (see
/// `PhaseShiftedSweep::settled`).
const SETTLING_NOISE_SIGMAS: f32 = 1.5;

/// Base blocks shorter than this (samples) are not checked for settling: a half block would
/// be too short to fit a sine and estimate its noise.
const MIN_CHECKED_SAMPLES: u64 = 32;

/// Start of the dither's xorshift32 sequence (any non-zero value; the same for every sweep).
const DITHER_SEED: u32 = 0x2545_F491;

#[derive(Clone, Copy, Debug)]
pub struct PhaseShiftedSweep {
    params: SweepParams,
    base_rate_hz: f32,
    status: SweepStatus,
    generator: SineGenerator,
    /// Ticks left in the present stage after this one: `left + 1 + left_high·2³²` (see
    /// [`Self::set_left`]; a 32-bit countdown on the tick, the Cortex-M4 has no 64-bit
    /// arithmetic).
    left: u32,
    left_high: u32,
    /// Half blocks (half a base measurement each) added to each record of the present frequency (see
    /// `SweepParams::precision_db`), decided once the first record's base block is in (0
    /// until then, and when none are needed).
    extensions: u32,
    acc: SineFitSums,
    /// Settling check of the present frequency's first record (see [`Self::settled`]): the
    /// sums at the start of the present half block, the response of the previous half block,
    /// the half blocks discarded so far, and whether the check still runs.
    half_start: SineFitSums,
    previous_half: Option<((f32, f32), f32)>,
    discarded_halves: u32,
    checking_settling: bool,
    /// Index of the present half block (see [`AcquisitionSample::half_block`]; at most
    /// `1 + 2·MAX_EXTENSIONS`), and the samples' word of record and half block (found when
    /// either changes, not on every sample: the Cortex-M4's tick budget).
    half_block: u32,
    segment: u32,
    /// Sums of u and y over the loop ticks of the present acquisition period, and their count.
    period_sums: (f32, f32, f32),
    /// The present frequency's samples are period means (a stepped sine below the threshold).
    averaging: bool,
    /// xorshift32 state of the dither and the dither of the present tick (N·m).
    dither_state: u32,
    dither: f32,
    /// The present frequency is dithered (`dither` > 0, at or above the threshold).
    dithering: bool,
    sequence: MSequence,
    chip: f32,
    /// The excitation value and phase (the generator's accumulator word, converted on
    /// acquisition ticks only) of the present tick, and the phase reduced for its sine and
    /// cosine (evaluated on acquisition ticks only).
    value: f32,
    phase_word: u32,
    angle: ReducedAngle,
    results: [SweepResult; MAX_SWEEP_POINTS],
    /// The parameters' frequency plan, found when the sweep is built (outside the tick).
    plan: FrequencyPlan,
}

impl PhaseShiftedSweep {
    pub fn new(params: SweepParams, base_rate_hz: f32) -> Self {
        Self {
            plan: params.plan(),
            params,
            base_rate_hz,
            status: SweepStatus::default(),
            generator: SineGenerator::default(),
            left: 0,
            left_high: 0,
            extensions: 0,
            acc: SineFitSums::default(),
            half_start: SineFitSums::default(),
            previous_half: None,
            discarded_halves: 0,
            checking_settling: false,
            half_block: 0,
            segment: 0,
            period_sums: (0.0, 0.0, 0.0),
            averaging: false,
            dither_state: DITHER_SEED,
            dither: 0.0,
            dithering: false,
            // Validated with the parameters; the fallback only keeps this constructor total.
            sequence: MSequence::new(params.prbs_degree).unwrap_or(MSequence::DEGREE_15),
            chip: 0.0,
            value: 0.0,
            phase_word: 0,
            angle: ReducedAngle::default(),
            results: [SweepResult::default(); MAX_SWEEP_POINTS],
        }
    }

    /// The dither to add to the torque command on this tick (0 when no stepped sine runs: it
    /// is cleared when the sweep ends).
    pub fn torque_dither(&self) -> f32 {
        self.dither
    }

    pub fn params(&self) -> &SweepParams {
        &self.params
    }

    pub fn status(&self) -> &SweepStatus {
        &self.status
    }

    pub fn running(&self) -> bool {
        matches!(self.status.state, SweepState::Settling | SweepState::Measuring)
    }

    /// Results measured so far, in frequency order.
    pub fn results(&self) -> &[SweepResult] {
        &self.results[..self.status.done_points as usize]
    }

    /// Start from the first frequency (validated settings; refused while running).
    pub fn start(&mut self) -> Result<(), SweepError> {
        if self.running() {
            return Err(SweepError::Busy);
        }
        self.status = SweepStatus::default();
        self.generator = SineGenerator::default();
        self.sequence.restart();
        self.dither_state = DITHER_SEED;
        self.dither = 0.0;
        self.begin_record(0, 0);
        Ok(())
    }

    // Once per record or frequency: kept out of line so that the every-tick path stays small.
    #[inline(never)]
    fn begin_record(&mut self, point: u32, record: u32) {
        let p = &self.params;
        self.status.point = point;
        self.status.record = record;
        self.segment = AcquisitionSample::segment_of(record, 0);
        self.status.state = SweepState::Settling;
        if p.signal == SweepSignal::Prbs {
            let d = p.acquisition_divider as u64;
            let ticks = (libm::ceilf(p.min_settle_s * self.base_rate_hz / d as f32) as u64).saturating_mul(d);
            self.set_left(ticks);
            self.status.frequency = 0.0;
            self.averaging = false;
            self.dithering = false;
            return;
        }
        let f = p.frequency_in(&self.plan, point as usize);
        self.status.frequency = f;
        self.averaging = f < p.threshold(self.base_rate_hz);
        self.dithering = p.dither > 0.0 && !self.averaging;
        // Phase continuous: the new frequency (or record) starts at the phase the sine has
        // reached (0 at the start), so that the excitation does not jump: a restart at phase 0
        // steps the input by up to its amplitude and rings the loop's lightly damped modes
        // for many periods. A record after the first adds the shift 2π/shifts.
        let shift = if record == 0 { 0.0 } else { TAU / p.shifts as f32 };
        let initial = phase_angle(self.generator.phase_word()) + shift;
        self.generator = SineGenerator::new(p.amplitude, f, self.base_rate_hz, initial);
        let ticks = p.record_length(f, self.base_rate_hz).0;
        if record == 0 {
            self.acc = SineFitSums::default();
            self.extensions = 0;
            self.half_start = SineFitSums::default();
            self.previous_half = None;
            self.discarded_halves = 0;
            self.half_block = 0;
            self.checking_settling = p.precision_db > 0.0
                && p.max_extensions > 0
                && p.record_length(f, self.base_rate_hz).1 >= MIN_CHECKED_SAMPLES;
        } else {
            self.acc.break_record();
        }
        self.segment = AcquisitionSample::segment_of(record, self.half_block);
        self.set_left(ticks);
    }

    /// Excitation for this base tick (call once per tick, before the loops): the value to
    /// add at the injection point, or None when no sweep runs. `chip_due`: the tick is a
    /// multiple of `prbs_divider` (the caller counts ticks; a 64-bit modulo is software on a
    /// Cortex-M4). The phase's reduction is kept for the correlator on the same tick, which
    /// evaluates the cosine only when it acquires (one reduction, no cosine on other ticks). Rotating them on between acquisition ticks instead
    /// of evaluating every tick saved the Cortex-M4 about 20 instructions per tick, but changes
    /// what the loop computes (the golden vectors and the drive's own results): not done.
    pub fn excitation(&mut self, chip_due: bool) -> Option<(InjectionPoint, f32)> {
        if !self.running() {
            return None;
        }
        let p = &self.params;
        match p.signal {
            SweepSignal::SteppedSine => {
                self.phase_word = self.generator.phase_word();
                (self.value, self.angle) = self.generator.next_with_angle();
                self.dither = if self.dithering {
                    let mut x = self.dither_state;
                    x ^= x << 13;
                    x ^= x >> 17;
                    x ^= x << 5;
                    self.dither_state = x;
                    if x & 0x8000_0000 != 0 {
                        p.dither
                    } else {
                        -p.dither
                    }
                } else {
                    0.0
                };
            }
            SweepSignal::Prbs => {
                if chip_due {
                    self.chip = p.amplitude * self.sequence.next_chip() as f32;
                }
                self.value = self.chip;
                self.phase_word = 0;
            }
        }
        Some((p.point, self.value))
    }

    /// End of a base tick: `u` and `y` as defined for the injection point. `loop_tick`: the
    /// velocity loop ran on this tick (u and y are new); `acquire`: the tick is a multiple of
    /// `acquisition_divider` (a loop tick too). A stepped sine's acquisition sample is the
    /// mean of u and of y over the loop ticks of the acquisition period (for y, the velocity
    /// estimate, that is the position's change over the period): the same average on both,
    /// so it cancels in Y/U, and it keeps the encoder's quantisation noise, which the
    /// estimate differentiates, out of the low frequencies where a single sample per period
    /// would fold it. PRBS samples are the values at the acquisition tick. Advances the
    /// schedule.
    #[inline(always)]
    pub fn end_tick(&mut self, tick: u64, loop_tick: bool, acquire: bool, u: f32, y: f32) {
        if !self.running() {
            return;
        }
        // One field, not the whole parameter set: this runs every tick while sweeping.
        let signal = self.params.signal;
        if loop_tick && self.averaging {
            self.period_sums.0 += u;
            self.period_sums.1 += y;
            self.period_sums.2 += 1.0;
        }
        if acquire {
            let (u, y) = match self.period_sums {
                (su, sy, n) if self.averaging && n > 0.0 => (su / n, sy / n),
                _ => (u, y),
            };
            self.period_sums = (0.0, 0.0, 0.0);
            let measuring = self.status.state == SweepState::Measuring;
            self.status.sample = AcquisitionSample {
                tick,
                u,
                y,
                phase: phase_angle(self.phase_word),
                measuring,
                point: self.status.point,
                segment: self.segment,
            };
            if measuring && signal == SweepSignal::SteppedSine {
                self.acc.add(u, y, self.angle.sin_cos());
            }
        }
        if self.left == 0 {
            self.next_stage();
        } else {
            self.left -= 1;
        }
    }

    /// The present stage lasts `ticks` more ticks, this one included (at least this one).
    fn set_left(&mut self, ticks: u64) {
        let rest = ticks.max(1) - 1;
        self.left = rest as u32;
        self.left_high = (rest >> 32) as u32;
    }

    /// The present stage (settling, a half block, a block, a record) is over: the next one,
    /// or the next frequency. Once per stage: kept out of line so that the every-tick path
    /// stays small.
    #[inline(never)]
    fn next_stage(&mut self) {
        if self.left_high > 0 {
            // Another 2³² ticks of the same stage.
            self.left_high -= 1;
            self.left = u32::MAX;
            return;
        }
        let (signal, divider) = (self.params.signal, self.params.acquisition_divider);
        match self.status.state {
            SweepState::Settling => {
                let p = &self.params;
                self.status.state = SweepState::Measuring;
                let ticks = match signal {
                    SweepSignal::Prbs => libm::roundf(p.prbs_seconds * self.base_rate_hz / divider as f32) as u64,
                    // Later records take the blocks the first one was given.
                    SweepSignal::SteppedSine => {
                        let samples = p.record_length(self.status.frequency, self.base_rate_hz).1;
                        if self.checking_settling {
                            // The first record's base block in two halves (see `settled`).
                            samples / 2
                        } else {
                            let extra = if self.status.record == 0 { 0 } else { self.extensions as u64 };
                            samples.saturating_add(extra.saturating_mul(samples / 2))
                        }
                    }
                }
                .saturating_mul(divider as u64);
                self.set_left(ticks);
            }
            SweepState::Measuring if signal == SweepSignal::Prbs => self.status.state = SweepState::Done,
            SweepState::Measuring => {
                let f = self.status.frequency;
                let records = self.params.records(f, self.base_rate_hz);
                // After the first record's base block: how many more blocks every record of
                // this frequency takes (the same for all, so that the phase-shifted records
                // stay balanced); the first one measures on at once, without settling. Its
                // end comes back here only when blocks were added, with `extensions` > 0.
                if self.status.record == 0 && self.extensions == 0 {
                    if self.checking_settling {
                        if let Some(samples) = self.settled() {
                            self.set_left(samples.saturating_mul(divider as u64));
                            return;
                        }
                    }
                    self.extensions = self.halves_needed(records);
                    if self.extensions > 0 {
                        let ticks = (self.extensions as u64)
                            .saturating_mul(self.params.record_length(f, self.base_rate_hz).1 / 2)
                            .saturating_mul(divider as u64);
                        self.set_left(ticks);
                        return;
                    }
                }
                if self.status.record + 1 < records {
                    self.begin_record(self.status.point, self.status.record + 1);
                    return;
                }
                self.finish_point();
                let next = self.status.point + 1;
                if next < self.plan.count as u32 {
                    self.begin_record(next, 0);
                } else {
                    self.status.state = SweepState::Done;
                    self.dither = 0.0;
                }
            }
            _ => {}
        }
    }

    /// The settling check, at the end of each half block of the first record: None when the
    /// record has settled (the response of the last half block agrees with the previous
    /// one's), else the samples of the next half block to measure. The closed loop's slowest
    /// transient, not a number of periods, decides when the measurement starts: a lightly
    /// damped mode near the excitation (an anti-resonance of a soft shaft inside a stiff
    /// velocity loop) rings for many periods after the frequency step and biases the fit by
    /// tenths of a decibel and degrees. Two successive half blocks agree when their responses
    /// differ, relative to |G|, by at most the precision (`precision_db` as a relative size,
    /// gain and phase together) or three standard deviations of the difference under the
    /// measured noise, whichever is larger. When they differ, the earlier half block is
    /// discarded and the last one is compared with a new one; the kept data is always the last
    /// two half blocks, one base block. At most `2·max_extensions` half blocks are discarded.
    // Once per half block: kept out of line so that the every-tick path stays small.
    #[inline(never)]
    fn settled(&mut self) -> Option<u64> {
        let p = &self.params;
        let samples = p.record_length(self.status.frequency, self.base_rate_hz).1;
        let half = self.acc.since(&self.half_start);
        let turns = self.status.frequency * p.acquisition_divider as f32 / self.base_rate_hz;
        let step = TAU * (turns - libm::floorf(turns));
        // This half block's response and the variance of its relative error (gain and phase).
        let this = match (half.response(), half.response_error(step)) {
            (Some(g), Some(e)) => Some((g, e.gain * e.gain + e.phase * e.phase)),
            _ => None,
        };
        let first = self.previous_half.is_none();
        let (Some(((re, im), spread)), Some(((re0, im0), spread0))) = (this, self.previous_half) else {
            // The first half block (or one that tells nothing): the second one completes the
            // base block, checked only when both tell.
            self.previous_half = this;
            self.half_start = self.acc;
            self.checking_settling = first && this.is_some();
            self.half_block = 1;
            self.segment = AcquisitionSample::segment_of(self.status.record, 1);
            return first.then_some(samples - samples / 2);
        };
        let target = p.precision_db * (core::f32::consts::LN_10 / 20.0);
        // The responses differ beyond the precision and beyond three standard deviations of a
        // difference of two half blocks (twice one's variance).
        let noise = SETTLING_NOISE_SIGMAS * crate::square_root::sqrt(2.0 * spread);
        let (dre, dim) = (re - re0, im - im0);
        let difference = crate::square_root::sqrt((dre * dre + dim * dim) / (re * re + im * im));
        // Or the earlier half's residual is larger than the noise's variance ratio allows (a
        // decaying transient, which can bias both halves alike when it rings near the
        // excitation: the responses then agree before the loop has settled) and large
        // enough to matter: its relative size `√(spread·n/2)` above the precision. The log
        // of the ratio of two noise variances of n samples each has a spread of about 2/√n:
        // three of those.
        let n = half.n;
        let ratio = libm::expf(6.0 / crate::square_root::sqrt(n));
        let decaying = spread0 > ratio * spread && spread0 * 0.5 * n > target * target;
        if !(difference > target.max(noise) || decaying) || self.discarded_halves >= 2 * p.max_extensions {
            self.checking_settling = false;
            return None;
        }
        // Keep the last half block only and compare it with the next one.
        self.acc = half;
        self.half_start = half;
        self.previous_half = this;
        self.discarded_halves += 1;
        self.half_block = self.half_block.saturating_add(1);
        self.segment = AcquisitionSample::segment_of(self.status.record, self.half_block);
        Some((samples / 2).max(1))
    }

    /// Extra half blocks per record (at most `2·max_extensions`) for the standard errors of the response, gain's and phase's,
    /// to reach `precision_db` (the phase's: the same relative size, `precision_db·ln10/20`
    /// rad, 0.2° at 0.03 dB) over all `records`, predicted from the first base block (error ∝
    /// 1/√samples).
    // Once per record or frequency: kept out of line so that the every-tick path stays small.
    #[inline(never)]
    fn halves_needed(&self, records: u32) -> u32 {
        let p = &self.params;
        if !(p.precision_db > 0.0) || p.max_extensions == 0 {
            return 0;
        }
        let turns = self.status.frequency * p.acquisition_divider as f32 / self.base_rate_hz;
        let step = TAU * (turns - libm::floorf(turns));
        let Some(error) = self.acc.response_error(step) else { return 0 };
        let target = p.precision_db * (core::f32::consts::LN_10 / 20.0);
        let ratio = error.gain.max(error.phase) / target;
        // Half blocks per record (the base block is two).
        let halves = libm::ceilf(2.0 * ratio * ratio / records as f32);
        // Compared as floats: a huge ratio must not wrap in the conversion.
        if halves <= 2.0 {
            0
        } else if halves > (2 * p.max_extensions + 2) as f32 {
            2 * p.max_extensions
        } else {
            halves as u32 - 2
        }
    }

    // Once per record or frequency: kept out of line so that the every-tick path stays small.
    #[inline(never)]
    fn finish_point(&mut self) {
        let ((u_re, u_im), (y_re, y_im), quality) = self.acc.solve();
        let den = u_re * u_re + u_im * u_im;
        let (mut re, mut im) = if den > 0.0 && quality > 0.0 {
            ((y_re * u_re + y_im * u_im) / den, (y_im * u_re - y_re * u_im) / den)
        } else {
            (f32::NAN, f32::NAN)
        };
        if self.params.point == InjectionPoint::VelocityFeedback {
            re = -re;
            im = -im;
        }
        let r = SweepResult { frequency: self.status.frequency, re, im, quality };
        self.results[self.status.point as usize] = r;
        self.status.last = r;
        self.status.done_points = self.status.point + 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweep_codes_round_trip() {
        for s in [SweepSignal::SteppedSine, SweepSignal::Prbs] {
            assert_eq!(SweepSignal::from_code(s.code()), Some(s));
        }
        for s in [SweepState::Idle, SweepState::Settling, SweepState::Measuring, SweepState::Done] {
            assert_eq!(SweepState::from_code(s.code()), Some(s));
        }
        assert_eq!(SweepState::Done.code(), 3);
        assert_eq!(SweepSignal::from_code(2), None);
        assert_eq!(SweepState::from_code(-1), None);
    }

    const FS: f32 = 16_000.0;

    /// Drive the sweep with a known linear response y = |G|·sin(θ + φ) (times A), u = the
    /// injected sine, sampled exactly as the axis would.
    fn measure(params: SweepParams, gain: f32, phase: f32) -> [SweepResult; 2] {
        let mut s = PhaseShiftedSweep::new(params, FS);
        s.start().unwrap();
        let mut tick = 0u64;
        while s.running() {
            let (_, u) = s.excitation(tick.is_multiple_of(params.prbs_divider as u64)).unwrap();
            let y = gain * params.amplitude * libm::sinf(phase_angle(s.phase_word) + phase);
            s.end_tick(tick, tick.is_multiple_of(2), tick.is_multiple_of(params.acquisition_divider as u64), u, y);
            tick += 1;
        }
        assert_eq!(tick, params.total_ticks(FS), "the schedule the host computes is the one the drive runs");
        [s.results()[0], *s.results().last().unwrap()]
    }

    fn at(f: f32, shifts: u32, repeats: u32) -> SweepParams {
        SweepParams {
            start_hz: f,
            stop_hz: f * 1.001,
            points: 2,
            extra_hz: 0.0,
            shifts,
            repeats,
            threshold_hz: 1000.0,
            ..Default::default()
        }
    }

    #[test]
    fn phase_shifted_records_measure_exactly_at_the_acquisition_nyquist_frequency() {
        // 2 kHz sampled at 4 kHz: one record sees the wave at two phases only.
        let [shifted, _] = measure(at(2000.0, 3, 3), 0.5, -1.0);
        assert!((shifted.gain_db() - 20.0 * libm::log10f(0.5)).abs() < 1e-3, "{shifted:?}");
        assert!((shifted.phase_deg() + 1.0f32.to_degrees()).abs() < 0.05, "{shifted:?}");
        assert!(shifted.quality > 0.99);
        let [single, _] = measure(at(2000.0, 1, 1), 0.5, -1.0);
        let gain_error = (single.gain_db() - 20.0 * libm::log10f(0.5)).abs();
        let phase_error = (single.phase_deg() + 1.0f32.to_degrees()).abs();
        assert!(
            gain_error > 3.0 || phase_error > 10.0 || !gain_error.is_finite(),
            "single phase must fail: {single:?}"
        );
    }

    #[test]
    fn below_the_threshold_one_record_measures_exactly() {
        let [r, _] = measure(at(123.0, 3, 3), 2.0, 0.7);
        assert!(
            (r.gain_db() - 20.0 * libm::log10f(2.0)).abs() < 1e-3 && (r.phase_deg() - 0.7f32.to_degrees()).abs() < 0.05,
            "{r:?}"
        );
    }

    #[test]
    fn below_the_threshold_a_sample_is_the_mean_over_the_loop_ticks_and_above_it_the_value() {
        for (f, averaged) in [(123.0, true), (2500.0, false)] {
            let p = at(f, 3, 3);
            let mut s = PhaseShiftedSweep::new(p, FS);
            s.start().unwrap();
            let mut ys = [0.0f32; 4];
            for tick in 0..400u64 {
                let (_, u) = s.excitation(true).unwrap();
                let y = (tick * tick % 97) as f32;
                ys[(tick % 4) as usize] = y;
                let acquire = tick % 4 == 3;
                s.end_tick(tick, tick % 2 == 1, acquire, u, y);
                if acquire && tick > 4 {
                    let expected = if averaged { 0.5 * (ys[1] + ys[3]) } else { y };
                    assert_eq!(s.status().sample.y, expected, "{f} Hz, tick {tick}");
                }
            }
        }
    }

    #[test]
    fn the_frequency_list_includes_the_extra_point_in_order() {
        let p = SweepParams::default();
        assert_eq!(p.count(), 41);
        let f: [f32; 41] = core::array::from_fn(|i| p.frequency(i));
        assert!(f.windows(2).all(|w| w[0] < w[1]));
        assert!(f.contains(&2000.0) && (f[0] - 10.0).abs() < 1e-4 && (f[40] - 3000.0).abs() < 0.1);
    }

    #[test]
    fn the_plan_found_once_gives_the_frequencies_of_a_sorted_list() {
        // Reference: the base frequencies, the extra one added unless already there, sorted.
        for (points, extra, logarithmic) in [
            (41, 2000.0, true),
            (41, 0.0, true),
            (5, 10.0, true),
            (5, 3000.0, true),
            (9, 777.0, false),
            (9, 1.0, false),
        ] {
            let p = SweepParams { points, extra_hz: extra, logarithmic, ..Default::default() };
            let mut list: heapless_list::List = heapless_list::List::new();
            for i in 0..points as usize {
                let x = i as f32 / (points - 1) as f32;
                list.push(if logarithmic {
                    p.start_hz * libm::powf(p.stop_hz / p.start_hz, x)
                } else {
                    p.start_hz + (p.stop_hz - p.start_hz) * x
                });
            }
            if extra > 0.0 && !list.as_slice().contains(&extra) {
                list.push(extra);
            }
            list.sort();
            let plan = p.plan();
            assert_eq!(plan.count as usize, list.len, "{points} {extra}");
            for (i, f) in list.as_slice().iter().enumerate() {
                assert_eq!(p.frequency_in(&plan, i), *f, "{points} {extra} #{i}");
            }
        }
    }

    /// A fixed-capacity list for the test (the core has no allocator).
    mod heapless_list {
        pub struct List {
            items: [f32; 64],
            pub len: usize,
        }
        impl List {
            pub fn new() -> Self {
                Self { items: [0.0; 64], len: 0 }
            }
            pub fn push(&mut self, x: f32) {
                self.items[self.len] = x;
                self.len += 1;
            }
            pub fn as_slice(&self) -> &[f32] {
                &self.items[..self.len]
            }
            pub fn sort(&mut self) {
                self.items[..self.len].sort_unstable_by(f32::total_cmp);
            }
        }
    }

    #[test]
    fn bad_settings_are_named() {
        let v = |p: SweepParams| p.validate(FS, 2);
        assert_eq!(
            v(SweepParams { stop_hz: 4000.0, ..Default::default() }),
            Err(SweepError::AboveLoopNyquist { frequency: 4000.0, nyquist: 4000.0 })
        );
        assert!(matches!(
            v(SweepParams { amplitude: f32::NAN, ..Default::default() }),
            Err(SweepError::Setting { field: "amplitude", .. })
        ));
        assert_eq!(
            v(SweepParams { acquisition_divider: 3, ..Default::default() }),
            Err(SweepError::AcquisitionDivider { acquisition: 3, velocity: 2 })
        );
        assert_eq!(v(SweepParams { points: 200, ..Default::default() }), Err(SweepError::TooManyPoints(200)));
        assert!(matches!(
            v(SweepParams { dither: f32::NAN, ..Default::default() }),
            Err(SweepError::Setting { field: "dither", .. })
        ));
        assert!(matches!(
            v(SweepParams { dither: 2000.0, ..Default::default() }),
            Err(SweepError::Range { field: "dither", .. })
        ));
        assert_eq!(v(SweepParams::default()), Ok(()));
    }

    /// Uniform in [−1, 1) from a xorshift32 state.
    fn uniform(state: &mut u32) -> f32 {
        *state ^= *state << 13;
        *state ^= *state >> 17;
        *state ^= *state << 5;
        (*state >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
    }

    /// A response of `gain` plus uniform noise of ±`noise` (a stand-in for encoder
    /// quantisation), two frequencies; returns (G of the first, ticks run).
    fn noisy(params: SweepParams, gain: f32, noise: f32, seed: u32) -> (SweepResult, u64) {
        let mut s = PhaseShiftedSweep::new(params, FS);
        s.start().unwrap();
        let (mut tick, mut state) = (0u64, seed | 1);
        while s.running() {
            let (_, u) = s.excitation(true).unwrap();
            let r = uniform(&mut state);
            let y = 50.0 + gain * params.amplitude * libm::sinf(phase_angle(s.phase_word) + 0.3) + noise * r;
            s.end_tick(tick, tick.is_multiple_of(2), tick.is_multiple_of(params.acquisition_divider as u64), u, y);
            tick += 1;
        }
        (s.results()[0], tick)
    }

    /// A response of gain 1.5 and phase −0.4 rad plus a lightly damped ring at 52 Hz that
    /// starts with the sweep (30 % of the response, τ = 50 ms), as a loop's mode rings after
    /// a frequency step; the first frequency's result and the ticks run.
    fn ringing(params: SweepParams) -> (SweepResult, u64, u32) {
        let mut s = PhaseShiftedSweep::new(params, FS);
        s.start().unwrap();
        let (mut tick, mut last_half) = (0u64, 0u32);
        while s.running() {
            let (_, u) = s.excitation(true).unwrap();
            let t = tick as f32 / FS;
            let ring = 0.3 * 1.5 * params.amplitude * libm::expf(-t / 0.05) * libm::sinf(TAU * 52.0 * t);
            let y = 1.5 * params.amplitude * libm::sinf(phase_angle(s.phase_word) - 0.4) + ring;
            s.end_tick(tick, tick.is_multiple_of(2), tick.is_multiple_of(params.acquisition_divider as u64), u, y);
            if s.status().sample.point == 0 {
                last_half = s.status().sample.half_block();
            }
            tick += 1;
        }
        (s.results()[0], tick, last_half)
    }

    #[test]
    fn a_ringing_loop_is_measured_once_it_has_settled() {
        let p = SweepParams { start_hz: 50.0, stop_hz: 50.05, points: 2, extra_hz: 0.0, ..Default::default() };
        let error = |r: SweepResult| (r.gain_db() - 20.0 * libm::log10f(1.5), r.phase_deg() + 0.4f32.to_degrees());
        // Without the check (fixed records) the ring is in the record.
        let (fixed, ticks, _) = ringing(SweepParams { precision_db: 0.0, ..p });
        let (db, deg) = error(fixed);
        assert_eq!(ticks, p.total_ticks(FS));
        assert!(db.abs() > 0.3 || deg.abs() > 3.0, "{db} dB {deg} deg");
        // With it, the half blocks measured while it rings are discarded.
        let (checked, ticks, last_half) = ringing(p);
        let (db, deg) = error(checked);
        assert!(db.abs() < 0.03 && deg.abs() < 0.2, "{db} dB {deg} deg");
        assert!(ticks > p.total_ticks(FS) && ticks <= p.max_total_ticks(FS), "{ticks}");
        assert!(last_half >= 3, "{last_half} half blocks");
    }

    #[test]
    fn an_acquisition_sample_stays_32_bytes() {
        // The acquisition stream buffers 256 of them.
        assert!(core::mem::size_of::<AcquisitionSample>() <= 32);
    }

    #[test]
    fn a_noisy_low_gain_point_is_lengthened_until_precise_and_a_clean_one_is_not() {
        // Base records of 80 ms (not the defaults: the test is about the extension).
        let p = SweepParams {
            start_hz: 300.0,
            stop_hz: 400.0,
            points: 2,
            extra_hz: 0.0,
            min_measure_s: 0.08,
            ..Default::default()
        };
        let off = SweepParams { precision_db: 0.0, ..p };
        // A clean response: no extension, the schedule the host computes.
        assert_eq!(noisy(p, 1.0, 0.0, 1).1, p.total_ticks(FS));
        // Gain 0.06 (−24 dB) under noise ±0.04: 0.1 dB-class error in a base record.
        let (mut before, mut after) = (0.0f32, 0.0f32);
        for seed in 1..=12 {
            let db = |r: SweepResult| (20.0 * libm::log10f(libm::hypotf(r.re, r.im) / 0.06)).abs();
            let (r_off, t_off) = noisy(off, 0.06, 0.04, seed);
            let (r_on, t_on) = noisy(p, 0.06, 0.04, seed);
            assert_eq!(t_off, off.total_ticks(FS));
            assert!(
                t_on > t_off && t_on <= p.max_total_ticks(FS),
                "{t_on} ticks vs {t_off}..{}",
                p.max_total_ticks(FS)
            );
            before = before.max(db(r_off));
            after = after.max(db(r_on));
        }
        assert!(after < 0.5 * before, "worst error {after} dB with extensions vs {before} dB without");
        // The standard errors the sweep computes are the spread it predicts, σ(f)·√(2/n)/A,
        // with σ(f)² the noise's spectrum at the excitation: white noise, and differenced
        // noise (the velocity estimate's quantisation), which is small at low frequencies.
        let step = 0.731f32;
        let n = 4000;
        let variance = 0.04 * 0.04 / 3.0;
        for (differenced, spectrum) in [(false, variance), (true, variance * 2.0 * (1.0 - libm::cosf(step)))] {
            let mut fit = SineFitSums::default();
            let (mut state, mut last) = (7u32, 0.0f32);
            for k in 0..n {
                let theta = k as f32 * step;
                let r = 0.04 * uniform(&mut state);
                let noise = if differenced { r - last } else { r };
                last = r;
                let (s, c) = libm::sincosf(theta);
                fit.add(1.0 * s, 50.0 + 0.12 * s + noise, (s, c));
            }
            let predicted = libm::sqrtf(spectrum) * libm::sqrtf(2.0 / n as f32) / 0.12;
            let got = fit.response_error(step).unwrap();
            for (what, value) in [("gain", got.gain), ("phase", got.phase)] {
                assert!(
                    (value / predicted - 1.0).abs() < 0.1,
                    "differenced {differenced}: {what} {value}, expected {predicted}"
                );
            }
        }
    }
}
