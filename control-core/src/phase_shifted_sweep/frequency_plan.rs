//! The frequency plan: the sweep's frequencies in ascending order (the extra one found in
//! its place once, [`FrequencyPlan`]), the threshold from which records are phase shifted,
//! and the length of every record and of the whole sweep.

use super::settling_check::MIN_CHECKED_SAMPLES;
use super::{SweepParams, SweepSignal};
use crate::excitation::{phase_angle, SineGenerator};
use crate::TAU;

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
        if self.points <= 1 {
            return self.start_hz;
        }
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
            self.repeats as u32
        } else {
            1
        }
    }

    /// Settling ticks (a whole number of acquisition periods) and measured samples of one
    /// record at f: the longer of `measure_cycles` and the shortest measurement, which is
    /// `min_measure_s` from half the threshold up and half of it below while precision control
    /// runs (see `min_measure_at`).
    // Once per stage, and per frequency where the time budget counts: out of line, one copy
    // for its callers (inlined into each, the drive image's flash went 2 KiB over its goal).
    #[inline(never)]
    pub fn record_length(&self, f: f32, base_rate_hz: f32) -> (u64, u64) {
        let d = self.acquisition_divider as f32;
        let settle = libm::ceilf(self.min_settle_s.max(self.settle_cycles / f) * base_rate_hz / d) as u64;
        let samples = self.block_samples(f, base_rate_hz, self.min_measure_at(f, base_rate_hz));
        (settle.saturating_mul(self.acquisition_divider as u64), samples)
    }

    /// Samples of a record's base block at f when its shortest measurement is `min_measure`.
    fn block_samples(&self, f: f32, base_rate_hz: f32, min_measure: f32) -> u64 {
        let d = self.acquisition_divider as f32;
        (libm::roundf(min_measure.max(self.measure_cycles / f) * base_rate_hz / d) as u64).max(1)
    }

    /// `precision_db` as a relative size of the response (the gain's error, and the phase's in
    /// radians): 0.03 dB is 0.0035, 0.2°.
    pub(super) fn relative_precision(&self) -> f32 {
        self.precision_db * (core::f32::consts::LN_10 / 20.0)
    }

    /// The most half blocks (of the record's own base block, see [`Self::record_length`]) that
    /// precision control adds to each record at f, and that the settling check discards:
    /// `2·max_extensions` half blocks of the block `min_measure_s` gives, the same time where
    /// the block is halved (twice as many of them then).
    pub fn half_block_cap(&self, f: f32, base_rate_hz: f32) -> u32 {
        self.half_blocks_of(self.max_extensions, f, base_rate_hz)
    }

    /// `2·extensions` half blocks of the full block at f, in half blocks of the record's own.
    fn half_blocks_of(&self, extensions: u32, f: f32, base_rate_hz: f32) -> u32 {
        let samples = self.record_length(f, base_rate_hz).1;
        self.half_blocks_in(extensions, samples, f, base_rate_hz)
    }

    /// [`Self::half_blocks_of`] for a record of `samples` at f: `2·extensions` where the block
    /// is the full one (no division: the longest sum takes it for every frequency, when the
    /// sweep is built), as many more as the block is shorter.
    pub(super) fn half_blocks_in(&self, extensions: u32, samples: u64, f: f32, base_rate_hz: f32) -> u32 {
        let full = self.block_samples(f, base_rate_hz, self.min_measure_s);
        if samples == full {
            return (2 * extensions as u64).min(u32::MAX as u64) as u32;
        }
        ((2 * extensions as u64).saturating_mul(full) / samples).min(u32::MAX as u64) as u32
    }

    /// Base ticks of the time budget (`time_budget_s`; 0 without one, or without a stepped
    /// sine's precision control, which alone uses it).
    pub fn budget_ticks(&self, base_rate_hz: f32) -> u64 {
        let precision_control = self.precision_db > 0.0 && self.max_extensions > 0;
        if self.signal == SweepSignal::SteppedSine && precision_control && self.time_budget_s > 0.0 {
            libm::floorf(self.time_budget_s * base_rate_hz) as u64
        } else {
            0
        }
    }

    /// The shortest measurement of a record at f: `min_measure_s`, and half of it below half
    /// the threshold while precision control runs (`precision_db` and `max_extensions` > 0),
    /// unless that half would leave the settling check fewer than
    /// [`MIN_CHECKED_SAMPLES`](super::settling_check::MIN_CHECKED_SAMPLES) samples.
    ///
    /// Down there the response is usually many encoder counts (a low-gain point, an
    /// anti-resonance, is lengthened by the precision control as before, up to the same time:
    /// see [`Self::half_block_cap`]), and a shorter block halves both the base measurement and
    /// the steps in which the settling check waits for the loop (its half blocks keep 40
    /// samples at the defaults). From half the threshold up the response falls to a few
    /// counts, and the full block carries the accuracy: precision control predicts the error
    /// from the first base block, and at the acquisition Nyquist frequency, where a single
    /// record's phases collapse to two and tell no error, the records are not lengthened at
    /// all. Measured on `servo bench sweep`'s grid (six noise seeds): the half block
    /// everywhere left the top (1.4–3 kHz) at 0.031 dB RMS against the oracle with 23 of 735
    /// results beyond 0.07 dB (0.026 dB and 6 with the full one); halved below half the
    /// threshold the top keeps 0.027 dB, and the longest row takes 9.7 s instead of 10.1 s.
    /// Fixed records (an oracle's) keep their length.
    fn min_measure_at(&self, f: f32, base_rate_hz: f32) -> f32 {
        let half = 0.5 * self.min_measure_s;
        let checked = half * base_rate_hz / self.acquisition_divider as f32 >= MIN_CHECKED_SAMPLES as f32;
        if self.precision_db > 0.0 && self.max_extensions > 0 && checked && f < 0.5 * self.threshold(base_rate_hz) {
            half
        } else {
            self.min_measure_s
        }
    }

    /// Base ticks from the start to the end of the sweep when no frequency is extended (the
    /// sweep's length when `precision_db` is 0 or every point meets it at once).
    pub fn total_ticks(&self, base_rate_hz: f32) -> u64 {
        self.ticks_with_extensions(base_rate_hz, false)
    }

    /// Base ticks of the sweep when every frequency's records take all the half blocks they
    /// can ([`Self::half_block_cap`]) and its first record discards as many while settling,
    /// or the time budget where that is longer (a record goes past its cap only while the
    /// sweep still ends within it: see `time_budget_s`): the longest it can run.
    pub fn max_total_ticks(&self, base_rate_hz: f32) -> u64 {
        self.ticks_with_extensions(base_rate_hz, self.precision_db > 0.0).max(self.budget_ticks(base_rate_hz))
    }

    /// The longest a frequency f can take (its records at their cap, as many half blocks
    /// discarded while the first settles, and the wait for the next frequency's peak unless it
    /// is the `last`): [`Self::max_total_ticks`]'s share of it, without the budget.
    pub fn longest_point_ticks(&self, f: f32, last: bool, base_rate_hz: f32) -> u64 {
        let d = self.acquisition_divider as u64;
        let (settle, samples) = self.record_length(f, base_rate_hz);
        // A stage lasts at least one tick (see `PhaseShiftedSweep::set_left`).
        let settle = settle.max(1);
        let halves = if self.precision_db > 0.0 {
            self.half_blocks_in(self.max_extensions, samples, f, base_rate_hz) as u64
        } else {
            0
        };
        let half = (samples / 2).saturating_mul(d);
        let record = settle.saturating_add(samples.saturating_mul(d)).saturating_add(half.saturating_mul(halves));
        let discarded = half.saturating_mul(halves);
        let wait = if last { 0 } else { self.peak_wait_bound(f, base_rate_hz) };
        record.saturating_mul(self.records(f, base_rate_hz) as u64).saturating_add(discarded).saturating_add(wait)
    }

    /// The shortest a frequency f can take: [`Self::longest_point_ticks`] without a half block
    /// added to its records or discarded while the first settles.
    pub fn shortest_point_ticks(&self, f: f32, last: bool, base_rate_hz: f32) -> u64 {
        let d = self.acquisition_divider as u64;
        let (settle, samples) = self.record_length(f, base_rate_hz);
        let record = settle.max(1).saturating_add(samples.saturating_mul(d));
        let wait = if last { 0 } else { self.peak_wait_bound(f, base_rate_hz) };
        record.saturating_mul(self.records(f, base_rate_hz) as u64).saturating_add(wait)
    }

    /// The sum of [`Self::shortest_point_ticks`] over the frequencies of `plan`.
    pub fn shortest_ticks(&self, plan: &FrequencyPlan, base_rate_hz: f32) -> u64 {
        let count = plan.count as usize;
        (0..count).fold(0u64, |total, i| {
            total.saturating_add(self.shortest_point_ticks(self.frequency_in(plan, i), i + 1 == count, base_rate_hz))
        })
    }

    /// The sum of [`Self::longest_point_ticks`] over the frequencies of `plan`.
    pub fn longest_ticks(&self, plan: &FrequencyPlan, base_rate_hz: f32) -> u64 {
        let count = plan.count as usize;
        (0..count).fold(0u64, |total, i| {
            total.saturating_add(self.longest_point_ticks(self.frequency_in(plan, i), i + 1 == count, base_rate_hz))
        })
    }

    /// A bound of the wait for the next frequency's start at the sine's next peak (see
    /// `PhaseShiftedSweep::next_frequency`): half a turn over the smallest increment the
    /// generator's rounding can give, at least one tick. Not `ceil(fs/2f) + 1`: the increment is
    /// rounded to an integer, and at 0.01 Hz and 16 kHz (2 684, rounded down from 2 684.35) the
    /// wait reaches 105 ticks more than that (a review's finding). In f32 and 32-bit integers,
    /// not the generator's f64 (software on the Cortex-M4, and taken for every frequency when
    /// a sweep is built): the estimate's rounding is taken off the increment first, so the
    /// bound holds against [`SineGenerator::longest_wait_to_peak`] (a unit test).
    pub(super) fn peak_wait_bound(&self, f: f32, base_rate_hz: f32) -> u64 {
        // The increment is round(f/fs·2³²) ≥ this (the f32 quotient is within 2⁻²⁴ of it).
        let increment = libm::floorf(f / base_rate_hz * 4_294_967_296.0 * (1.0 - 1.0 / 1_048_576.0) - 1.0);
        let increment = if increment >= 1.0 { increment.min(u32::MAX as f32) as u32 } else { 1 };
        ((1u32 << 31) / increment) as u64 + 1
    }

    /// With `longest`, every record lengthened by its cap of half blocks and as many half
    /// blocks discarded while the first record settles (see `PhaseShiftedSweep::settled`);
    /// without, none.
    fn ticks_with_extensions(&self, base_rate_hz: f32, longest: bool) -> u64 {
        let d = self.acquisition_divider as u64;
        let plan = self.plan();
        match self.signal {
            SweepSignal::Prbs => {
                self.prbs_settle_ticks(base_rate_hz).saturating_add(self.prbs_samples(base_rate_hz).saturating_mul(d))
            }
            SweepSignal::SteppedSine if longest => self.longest_ticks(&plan, base_rate_hz),
            SweepSignal::SteppedSine => {
                // The sine's phase is followed along the schedule as the runner builds each
                // record's generator, so that the wait for the next frequency's peak (see
                // `PhaseShiftedSweep::next_frequency`) is exact.
                let mut generator = SineGenerator::default();
                let mut total = 0u64;
                let count = plan.count as usize;
                for i in 0..count {
                    let f = self.frequency_in(&plan, i);
                    let (settle, samples) = self.record_length(f, base_rate_hz);
                    // A stage lasts at least one tick (see `PhaseShiftedSweep::set_left`).
                    let ticks = settle.max(1).saturating_add(samples.saturating_mul(d));
                    for record in 0..self.records(f, base_rate_hz) {
                        let shift = if record == 0 { 0.0 } else { TAU / self.shifts as f32 };
                        let start = phase_angle(generator.phase_word()) + shift;
                        generator = SineGenerator::new(1.0, f, base_rate_hz, start).advanced(ticks);
                        total = total.saturating_add(ticks);
                    }
                    if i + 1 < count {
                        let wait = generator.ticks_to_peak() as u64;
                        generator = generator.advanced(wait);
                        total = total.saturating_add(wait);
                    }
                }
                total
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

    /// The PRBS mode takes no time budget: its longest is its fixed length.
    #[test]
    fn the_prbs_mode_has_no_budget() {
        let p = SweepParams { signal: SweepSignal::Prbs, ..SweepParams::default() };
        assert!(p.time_budget_s > 0.0 && p.precision_db > 0.0);
        assert_eq!(p.budget_ticks(16_000.0), 0);
        assert_eq!(p.max_total_ticks(16_000.0), p.total_ticks(16_000.0));
    }

    /// The wait bound holds against the generator's own longest wait (exact, from its rounded
    /// increment) over frequencies from 1 mHz to just under the Nyquist frequency at the loop
    /// rates the drive takes, and stays within 0.1 % (and two ticks) of it where the increment
    /// is 10⁴ or more.
    #[test]
    fn the_peak_wait_bound_holds_against_the_generators_rounded_increment() {
        let p = SweepParams::default();
        let mut checked = 0;
        for rate in [4_000.0f32, 16_000.0, 32_000.0, 200_000.0] {
            let mut f = 0.001f32;
            while f < 0.5 * rate {
                let exact = SineGenerator::new(1.0, f, rate, 0.0).longest_wait_to_peak() as u64;
                let bound = p.peak_wait_bound(f, rate);
                assert!(bound >= exact, "{f} Hz at {rate} Hz: bound {bound} < {exact}");
                // One increment and a part in a million taken off: tight where the increment is
                // large (from 0.04 Hz at 16 kHz), loose only for mHz sines at fast loops.
                if f / rate * 4_294_967_296.0 >= 10_000.0 {
                    assert!(
                        bound as f64 <= exact as f64 * 1.001 + 2.0,
                        "{f} Hz at {rate} Hz: bound {bound} vs {exact}"
                    );
                }
                f *= 1.0173;
                checked += 1;
            }
        }
        // The review's case: 0.01 Hz at 16 kHz waits up to 800 106 ticks, past ceil(fs/2f) + 1.
        let exact = SineGenerator::new(1.0, 0.01, 16_000.0, 0.0).longest_wait_to_peak();
        assert!(exact as f32 > libm::ceilf(0.5 * 16_000.0 / 0.01) + 1.0, "{exact}");
        assert!(checked > 2000);
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
}
