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
//!
//! One idea a file: `settings.rs` (the parameters, their checks and errors), `frequency_plan.rs`
//! (the frequencies and the length of every record), `sine_fit.rs` (the correlator sums and
//! the response and its standard errors), `settling_check.rs` and `precision_control.rs`
//! (when the measurement starts and how long the records run), `prbs.rs` (the PRBS mode),
//! `acquisition.rs` (the samples the drive streams), `measure.rs` (what U and Y are: the
//! loop's signals, or the motor torque and the machine-end acceleration); this file holds the results and the
//! runner, [`PhaseShiftedSweep`], which steps through records and frequencies tick by tick.

mod acquisition;
mod frequency_plan;
mod half_block_spread;
mod measure;
mod prbs;
mod precision_control;
mod settings;
mod settling_check;
mod sine_fit;
#[cfg(test)]
mod tests;

pub use acquisition::AcquisitionSample;
pub use frequency_plan::{FrequencyPlan, NO_EXTRA};
pub use measure::SweepMeasure;
pub use settings::{SweepError, SweepParams, MAX_EXTENSIONS, MAX_SWEEP_DITHER};
pub use sine_fit::ResponseError;

use crate::excitation::{phase_angle, InjectionPoint, SineGenerator};
use crate::m_sequence::MSequence;
use crate::trigonometry::ReducedAngle;
use crate::TAU;
use core::mem::MaybeUninit;
use half_block_spread::HalfBlockSpread;
use settling_check::{TrackedRing, MIN_CHECKED_SAMPLES};
use sine_fit::SineFitSums;

pub const MAX_SWEEP_POINTS: usize = 128;

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

#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SweepStatus {
    pub state: SweepState,
    pub point: u32,
    pub record: u32,
    pub frequency: f32,
    pub done_points: u32,
    pub last: SweepResult,
    /// The share (0..1) of `last`'s samples whose acquisition period saw the drive's output
    /// limited (the voltage circle; see [`PhaseShiftedSweep::end_tick`]; a stepped sine's
    /// results only: the PRBS mode has none, its caller checks its own data). Above 0 the loop was
    /// not linear for part of the measurement and `last` can be off by tenths of a decibel
    /// and degrees (how much depends on how deep the circle cut, which the share does not
    /// tell).
    pub last_limited: f32,
    pub sample: AcquisitionSample,
}

/// The dither runs from the threshold up, and from this frequency up where the threshold is
/// higher (a faster loop: 4 kHz at 32 kHz). There the response is a few encoder counts
/// whether or not the samples are period means, and the count pattern locks to the excitation
/// all the same: at a 32 kHz loop, undithered, 3 kHz was 0.28–0.31 dB and 1.5–3.1° off the
/// oracle, also with records three times longer; dithered, within 0.07 dB and 0.3°. At the
/// default 16 kHz the threshold is this frequency: nothing changes there.
const DITHER_FROM_HZ: f32 = 2000.0;

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
    /// Half blocks (half a base measurement each) added to each record of the present
    /// frequency (see `SweepParams::precision_db`), predicted once the first record's base
    /// block is in (0 until then, and when none are needed); below the threshold the half
    /// blocks' spread may add more or end the record before they are in (see
    /// [`Self::next_half_block`]).
    extensions: u32,
    acc: SineFitSums,
    /// Settling check of the present frequency's first record (see [`Self::settled`]): the
    /// sums at the start of the present half block, the response of the previous half block,
    /// the half blocks discarded so far, and whether the check still runs.
    half_start: SineFitSums,
    previous_half: Option<((f32, f32), f32)>,
    discarded_halves: u32,
    /// The last comparison's difference of the two half blocks' responses (see
    /// [`Self::settled`]), whether it was above the noise, and its size over its limit.
    previous_difference: (f32, f32),
    previous_above_noise: bool,
    previous_excess: f32,
    /// The previous comparison's ratio of successive differences (NaN when it had none; see
    /// [`Self::settled`]).
    previous_ratio: (f32, f32),
    /// The ring the settling check's ratios told, if any.
    ring: TrackedRing,
    checking_settling: bool,
    /// The half-block responses of the present frequency's record once it has settled, below
    /// the threshold (one record; see [`Self::next_half_block`]; none measured otherwise).
    spread: HalfBlockSpread,
    /// Index of the present half block (see [`AcquisitionSample::half_block`]; at most
    /// `1 +` [`SweepParams::half_block_cap`], below `1 + 4·MAX_EXTENSIONS`), and the samples'
    /// word of record and half block (found when either changes, not on every sample: the
    /// Cortex-M4's tick budget).
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
    /// The present frequency is done and the sine runs on to its next peak, where the next
    /// frequency starts (see [`Self::next_frequency`]).
    aligning: bool,
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
    /// The time budget's base ticks less the longest every frequency can take, found when the
    /// sweep is built (see [`Self::extension_cap`]; [`NO_BUDGET`] without a budget); and while
    /// it runs, the budget's ticks left after the stages begun so far and the longest of the
    /// frequencies after the present one: what the present one may take in all (see
    /// `SweepParams::time_budget_s`). 32-bit: the budget and the sum are kept below 2³⁰ ticks
    /// (18 h at 16 kHz), so that neither can overflow; a 64-bit field would also align the
    /// sweep to 8 bytes, and the axis's layout moves the tick's instruction count by tens
    /// (see `SweepParams::shifts`; not measured for this field alone).
    budget_over_longest: i32,
    budget_left: i32,
    /// With a budget: what the frequencies can take beyond their shortest (no half block added
    /// or discarded), summed over all of them when the sweep is built, and while it runs over
    /// those after the present one. `budget_left` plus the latter is what the present frequency
    /// may take with every later one at its shortest: the bound that keeps the sweep within
    /// its budget where the frequencies before took long (see [`Self::budget_bound`]). 0
    /// without a budget; -1 (and no bound) with one the shortest schedule does not fit.
    slack_over_shortest: i32,
    slack_later: i32,
}

/// [`PhaseShiftedSweep::budget_over_longest`] without a time budget: no budget
/// (`time_budget_s` 0, no precision control, the PRBS mode), or a budget or a sweep of
/// 2³⁰ ticks or more.
const NO_BUDGET: i32 = i32::MIN;

/// The most ticks a time budget, or the longest the sweep can take with one, may count.
pub(crate) const MAX_BUDGET_TICKS: u64 = 1 << 30;

impl PhaseShiftedSweep {
    #[allow(unsafe_code)]
    pub fn new(params: SweepParams, base_rate_hz: f32) -> Self {
        let mut slot = MaybeUninit::uninit();
        // SAFETY: `init` writes every field.
        unsafe {
            Self::init(slot.as_mut_ptr(), params, base_rate_hz);
            slot.assume_init()
        }
    }

    /// [`Self::new`] written at `sweep`, field by field (the result table, 2 KiB, where it
    /// is: the drive's axis is built in place).
    ///
    /// # Safety
    /// `sweep` is valid for writes and aligned.
    #[allow(unsafe_code)]
    pub(crate) unsafe fn init(sweep: *mut Self, params: SweepParams, base_rate_hz: f32) {
        let plan = params.plan();
        let (budget_over_longest, slack_over_shortest) = Self::budget_over_longest(&params, &plan, base_rate_hz);
        // SAFETY: the caller's; every field is written once.
        unsafe {
            let results = core::ptr::addr_of_mut!((*sweep).results).cast::<SweepResult>();
            for i in 0..MAX_SWEEP_POINTS {
                results.add(i).write(SweepResult::default());
            }
            write_fields!(sweep, PhaseShiftedSweep {
                plan: plan,
                budget_over_longest: budget_over_longest,
                budget_left: NO_BUDGET,
                slack_over_shortest: slack_over_shortest,
                slack_later: 0,
                params: params,
                base_rate_hz: base_rate_hz,
                status: SweepStatus::default(),
                generator: SineGenerator::default(),
                left: 0,
                left_high: 0,
                extensions: 0,
                acc: SineFitSums::default(),
                half_start: SineFitSums::default(),
                previous_half: None,
                discarded_halves: 0,
                previous_difference: (0.0, 0.0),
                previous_above_noise: false,
                previous_excess: 0.0,
                previous_ratio: (f32::NAN, f32::NAN),
                ring: TrackedRing::default(),
                checking_settling: false,
                spread: HalfBlockSpread::default(),
                half_block: 0,
                segment: 0,
                period_sums: (0.0, 0.0, 0.0),
                averaging: false,
                dither_state: DITHER_SEED,
                dither: 0.0,
                dithering: false,
                aligning: false,
                // Validated with the parameters; the fallback only keeps this constructor total.
                sequence: MSequence::new(params.prbs_degree).unwrap_or(MSequence::DEGREE_15),
                chip: 0.0,
                value: 0.0,
                phase_word: 0,
                angle: ReducedAngle::default(),
                ; results
            });
        }
    }

    /// [`Self::budget_over_longest`] of these settings: the budget's ticks less the longest
    /// the sweep can take, or [`NO_BUDGET`]; and [`Self::slack_over_shortest`], the longest
    /// less the shortest (0 without a budget). Passes over the frequencies (a power and a
    /// record length each), when the sweep is built; out of line, so that the constructor
    /// (an axis of 20 KiB built in place) stays as it was.
    #[inline(never)]
    fn budget_over_longest(params: &SweepParams, plan: &FrequencyPlan, base_rate_hz: f32) -> (i32, i32) {
        let budget = params.budget_ticks(base_rate_hz);
        // `budget_ticks` is 0 for the PRBS mode and without precision control.
        if budget == 0 || budget >= MAX_BUDGET_TICKS {
            return (NO_BUDGET, 0);
        }
        let longest = params.longest_ticks(plan, base_rate_hz);
        if longest < MAX_BUDGET_TICKS {
            // The shortest is at most the longest, point by point. A budget the shortest does
            // not fit bounds nothing (-1: see `PhaseShiftedSweep::budget_bound`).
            let shortest = params.shortest_ticks(plan, base_rate_hz);
            let slack = if shortest <= budget { (longest - shortest) as i32 } else { -1 };
            (budget as i32 - longest as i32, slack)
        } else {
            (NO_BUDGET, 0)
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
        self.aligning = false;
        self.budget_left = self.budget_over_longest;
        self.slack_later = self.slack_over_shortest;
        self.begin_record(0, 0);
        Ok(())
    }

    /// [`Self::start`] with the first frequency `ticks` base ticks from now (0: at once): the
    /// sweep runs meanwhile (busy, settling) with a silent excitation and no measured sample.
    /// Out of line and cold: inlined, it shifted LTO's choices in the tick (+4 instructions
    /// per tick on the Cortex-M4, `servo bench firmware`).
    #[inline(never)]
    #[cold]
    pub fn start_after(&mut self, ticks: u32) -> Result<(), SweepError> {
        self.start()?;
        if ticks > 0 {
            self.status = SweepStatus { point: u32::MAX, state: SweepState::Settling, ..SweepStatus::default() };
            self.generator = SineGenerator::default();
            self.averaging = false;
            self.dithering = false;
            self.segment = 0;
            self.aligning = true;
            // The first frequency begins (and takes its longest from the budget) after the wait.
            self.budget_left = self.budget_over_longest;
            self.slack_later = self.slack_over_shortest;
            self.set_left(ticks as u64);
        }
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
            self.begin_prbs_record();
            return;
        }
        let f = p.frequency_in(&self.plan, point as usize);
        self.status.frequency = f;
        self.averaging = f < p.threshold(self.base_rate_hz);
        self.dithering = p.dither > 0.0 && (!self.averaging || f >= DITHER_FROM_HZ);
        // Phase continuous: the new frequency (or record) starts at the phase the sine has
        // reached (0 at the start), so that the excitation does not jump: a restart at phase 0
        // steps the input by up to its amplitude and rings the loop's lightly damped modes
        // for many periods. A record after the first adds the shift 2π/shifts.
        let shift = if record == 0 { 0.0 } else { TAU / p.shifts as f32 };
        let initial = phase_angle(self.generator.phase_word()) + shift;
        self.generator = SineGenerator::new(p.amplitude, f, self.base_rate_hz, initial);
        let ticks = p.record_length(f, self.base_rate_hz).0;
        if record == 0 {
            if self.budget_over_longest != NO_BUDGET {
                // The present frequency leaves the later ones: its own longest is now its to
                // take (below 2³⁰ ticks, as their sum).
                let last = point as usize + 1 >= self.plan.count as usize;
                let longest = p.longest_point_ticks(f, last, self.base_rate_hz);
                self.budget_left += longest as i32;
                self.slack_later -= (longest - p.shortest_point_ticks(f, last, self.base_rate_hz)) as i32;
            }
            self.acc = SineFitSums::default();
            self.extensions = 0;
            self.half_start = SineFitSums::default();
            self.previous_half = None;
            self.discarded_halves = 0;
            self.previous_above_noise = false;
            self.previous_excess = 0.0;
            self.previous_ratio = (f32::NAN, f32::NAN);
            self.ring = TrackedRing::default();
            self.half_block = 0;
            self.spread = HalfBlockSpread::default();
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
            SweepSignal::Prbs => self.prbs_excitation(chip_due),
        }
        Some((self.params.point, self.value))
    }

    /// End of a base tick: `u` and `y` as defined for the injection point. `loop_tick`: the
    /// velocity loop ran on this tick (u and y are new); `acquire`: the tick is a multiple of
    /// `acquisition_divider` (a loop tick too). A stepped sine's acquisition sample is the
    /// mean of u and of y over the loop ticks of the acquisition period (for y, the velocity
    /// estimate, that is the position's change over the period): the same average on both,
    /// so it cancels in Y/U, and it keeps the encoder's quantisation noise, which the
    /// estimate differentiates, out of the low frequencies where a single sample per period
    /// would fold it. PRBS samples are the values at the acquisition tick, or period means
    /// for the machine-end acceleration measure, whose caller passes every base tick as a
    /// loop tick (its signals are sampled on every one). Advances the schedule.
    ///
    /// `limited` (read on acquisition ticks): the drive's output was limited on a tick of the
    /// acquisition period (the voltage circle cut what the current loop asked for; the axis
    /// keeps the flag between acquisition ticks). The loop is then not linear and a response
    /// measured meanwhile is not its frequency response (at 200 rad/s on the default axis,
    /// 0.2 N·m at 2–3 kHz needs more voltage than the 48 V bus leaves beside the back-EMF:
    /// 0.3–0.6 dB and 2–4° off). A result's share of such samples is
    /// [`SweepStatus::last_limited`].
    #[inline(always)]
    pub fn end_tick(&mut self, tick: u64, loop_tick: bool, acquire: bool, u: f32, y: f32, limited: bool) {
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
                limited,
                point: self.status.point,
                segment: self.segment,
            };
            if measuring && signal == SweepSignal::SteppedSine {
                self.acc.add(u, y, self.angle.sin_cos());
                self.acc.limited += limited as u32;
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
        let ticks = ticks.max(1);
        // Without a budget `budget_left` stays at its floor (a stage's ticks may reach 2⁴⁴).
        self.budget_left = self.budget_left.saturating_sub(ticks.min(i32::MAX as u64) as i32);
        let rest = ticks - 1;
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
        if self.aligning {
            self.aligning = false;
            // After a delayed start (`start_after`) the point is u32::MAX: the first is next.
            self.begin_record(self.status.point.wrapping_add(1), 0);
            return;
        }
        let (signal, divider) = (self.params.signal, self.params.acquisition_divider);
        match self.status.state {
            SweepState::Settling => {
                let p = &self.params;
                self.status.state = SweepState::Measuring;
                let ticks = match signal {
                    SweepSignal::Prbs => p.prbs_samples(self.base_rate_hz),
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
                // end comes back here when blocks were added, with `extensions` > 0 (below the
                // threshold after each half block of them, `next_half_block`).
                let half = self.params.record_length(f, self.base_rate_hz).1 / 2;
                if self.status.record == 0 && self.spread.half_blocks > 0 {
                    // A half block of the settled record's extension has ended.
                    if self.next_half_block() {
                        self.set_left(half.saturating_mul(divider as u64));
                        return;
                    }
                } else if self.status.record == 0 && self.extensions == 0 {
                    if self.checking_settling {
                        if let Some(samples) = self.settled() {
                            self.set_left(samples.saturating_mul(divider as u64));
                            return;
                        }
                    }
                    self.extensions = self.halves_needed(records, self.budget_grant(records));
                    if self.spread.half_blocks > 0 {
                        // Measured on in half blocks, each checked (see `next_half_block`).
                        if self.extensions > 0 {
                            self.set_left(half.saturating_mul(divider as u64));
                            return;
                        }
                    } else if self.extensions > 0 {
                        self.set_left((self.extensions as u64).saturating_mul(half).saturating_mul(divider as u64));
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
                    self.next_frequency();
                } else {
                    self.status.state = SweepState::Done;
                    self.dither = 0.0;
                }
            }
            _ => {}
        }
    }

    /// The present frequency is measured: the next one starts at the sine's next peak (the
    /// nearest tick to it), the sine running on meanwhile, unmeasured, for at most half a
    /// period. There the value and the slope of both sines agree (±amplitude, zero slope),
    /// so the change does not excite, to first order, the loop's modes away from the
    /// excitation frequency: a slow mode sees a continuous integral of the input, a fast one a
    /// continuous input. Changed at any other phase, the slope jumps and the mode rings; on a
    /// soft shaft (a closed-loop mode near 18 Hz with τ ≈ 70 ms on the 5:1, 50 Hz axis of
    /// `servo bench sweep`) the settling check then waits several half blocks for it.
    fn next_frequency(&mut self) {
        let ticks = self.generator.ticks_to_peak();
        if ticks == 0 {
            self.begin_record(self.status.point + 1, 0);
            return;
        }
        self.aligning = true;
        self.status.state = SweepState::Settling;
        self.set_left(ticks as u64);
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
        self.status.last_limited = if self.acc.n > 0.0 { self.acc.limited as f32 / self.acc.n } else { 0.0 };
        self.status.done_points = self.status.point + 1;
    }
}
