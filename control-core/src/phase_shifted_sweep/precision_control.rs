//! Precision control: how many half blocks every record of a frequency adds for its
//! response to meet `precision_db` (see [`PhaseShiftedSweep::halves_needed`]), and, below the
//! threshold, the check of that prediction against the half blocks' own spread (see
//! [`PhaseShiftedSweep::next_half_block`]).

#[cfg(doc)]
use super::HalfBlockSpread;
use super::PhaseShiftedSweep;
use crate::TAU;

/// The half blocks' spread extends a record when it puts the error above the precision by
/// more than this factor: from three half blocks on its estimate of the error is itself
/// uncertain (by about ±40 % at three), and extending on every chance excess would cost
/// measurement time for nothing.
const SPREAD_MARGIN: f32 = 1.25;

/// The record ends before the predicted half blocks are in when at least so many put the
/// spread's error at most 1/`EARLY_MARGIN` of the precision. The prediction's first-order
/// noise spectrum over-estimates where the noise is a band above the excitation (current
/// noise through the velocity loop, seen at 10–30 Hz): there it asked for records of up to
/// 1.5 s for errors of about 0.01 dB. With six half blocks that told a response (ten degrees
/// of freedom) an error at the precision reads below half of it with a probability of about
/// 1 %, somewhat more over the repeated looks (one per half block), and more again because
/// the first two are the settled pair, kept because their difference was small (the spread
/// reads low with few half blocks: the early end asks for half the precision, the extension
/// for 1.25 times it). Measured on the benches, not only argued: see the book's sweep page. The
/// settling check's ring rule counts at most this many half blocks in a record below the
/// threshold, which the early end can stop there.
pub(super) const EARLY_HALF_BLOCKS: u32 = 6;
const EARLY_MARGIN: f32 = 2.0;

/// Where the time budget has room, a record extended for precision runs on until its
/// predicted standard errors are 1/`BUDGET_MARGIN` of the precision: 0.024 dB for 0.03 (the
/// prediction's target; the half blocks' spread below the threshold still asks for the
/// precision itself). The goal against the oracle, 0.1 dB, is then 4.2 standard errors
/// instead of 3.3: at 3.3 about one result in a thousand misses it, and the grids of
/// `servo bench sweep` met 4 such misses in about 8 800 results from 2 kHz up, each at the
/// precision.
const BUDGET_MARGIN: f32 = 1.25;

impl PhaseShiftedSweep {
    /// Extra half blocks per record for the standard errors of the response, gain's and
    /// phase's, to reach `precision_db` (the phase's: the same relative size,
    /// `precision_db·ln10/20` rad, 0.2° at 0.03 dB) over all `records`, predicted from the
    /// first base block (error ∝ 1/√samples), at most the cap of `max_extensions` or `grant`,
    /// the time budget's room ([`Self::budget_grant`]; 0 for none, or for a prediction that
    /// must not count on the budget), where that is more; or, where more, those for
    /// 1/[`BUDGET_MARGIN`] of the precision, at most `grant`.
    // Once per record or frequency, and at the settling check's comparisons while a ring is
    // told or followed (`record_half_blocks`): kept out of line so that the every-tick path
    // stays small.
    #[inline(never)]
    pub(super) fn halves_needed(&self, records: u32, grant: u32) -> u32 {
        let p = &self.params;
        if !(p.precision_db > 0.0) || p.max_extensions == 0 {
            return 0;
        }
        let turns = self.status.frequency * p.acquisition_divider as f32 / self.base_rate_hz;
        let step = TAU * (turns - libm::floorf(turns));
        let Some(error) = self.acc.response_error(step) else { return 0 };
        let target = p.relative_precision();
        let ratio = error.gain.max(error.phase) / target;
        // Half blocks per record (the base block is two).
        let halves = |ratio: f32, cap: u32| {
            let halves = libm::ceilf(2.0 * ratio * ratio / records as f32);
            // Compared as floats: a huge ratio must not wrap in the conversion.
            if halves <= 2.0 {
                0
            } else if halves > (cap + 2) as f32 {
                cap
            } else {
                halves as u32 - 2
            }
        };
        let cap = p.half_block_cap(self.status.frequency, self.base_rate_hz).max(grant);
        halves(ratio, cap).max(halves(ratio * BUDGET_MARGIN, grant)).min(self.budget_bound(records))
    }

    /// The end of a half block of a settled record below the threshold (measured on in half
    /// blocks, see [`HalfBlockSpread`]): true when another half block follows. The record runs
    /// the half blocks [`Self::halves_needed`] predicted; then, when the half blocks' spread
    /// says the error is still more than [`SPREAD_MARGIN`] times the precision, as many more as
    /// that spread asks for, up to the same cap, checked again at their end. The prediction
    /// models the noise as a first-order spectrum, which a lightly damped closed-loop mode
    /// driven by current noise is not: on a 0.3:1, 53 Hz axis, velocity-feedback point, 0.01 A,
    /// the result at 50 Hz scattered by 0.059 dB (12 noise seeds) for a predicted 0.03 dB.
    // Once per half block: kept out of line so that the every-tick path stays small.
    #[inline(never)]
    pub(super) fn next_half_block(&mut self) -> bool {
        self.spread.close(self.acc.since(&self.half_start).response());
        self.half_start = self.acc;
        // The base block's two and the extension's so far.
        let measured = self.spread.half_blocks;
        let target = self.params.relative_precision();
        let error = self.spread.relative_error();
        if measured < 2 + self.extensions {
            // Done early when enough half blocks put the error far below the precision.
            let done_early =
                self.spread.count >= EARLY_HALF_BLOCKS && error.is_some_and(|e| e * EARLY_MARGIN <= target);
            return !done_early;
        }
        let Some(error) = error else { return false };
        let cap = self.extension_cap(1);
        let ratio = error / target;
        if !(ratio > SPREAD_MARGIN) || self.extensions >= cap {
            return false;
        }
        // The error falls as 1/√(half blocks): so many in all for the precision.
        let wanted = libm::ceilf(measured as f32 * ratio * ratio);
        let more =
            if wanted > (cap + 2) as f32 { cap - self.extensions } else { (wanted as u32).saturating_sub(measured) };
        self.extensions = (self.extensions + more).min(cap);
        more > 0
    }
}

impl PhaseShiftedSweep {
    /// The most half blocks each of the present frequency's `records` may add: the cap of
    /// `max_extensions` ([`SweepParams::half_block_cap`](super::SweepParams::half_block_cap)),
    /// or more, up to the cap of [`MAX_EXTENSIONS`](super::MAX_EXTENSIONS), where the time
    /// budget has room for them: the frequency's remaining half blocks, its later records (at
    /// their base length, with their settling) and the wait for the next frequency's peak fit in
    /// what is left of the budget once every later frequency is given its own longest
    /// (`budget_left`). So a grant never costs a later frequency its cap, and a sweep that was
    /// granted anything (past a cap, or the finer target of [`BUDGET_MARGIN`]) ends within the
    /// budget. Called at the end of the first
    /// record's base block (`records` of them) and, below the threshold, at the end of each
    /// of its half blocks (one record; those already measured count as taken).
    pub(super) fn extension_cap(&self, records: u32) -> u32 {
        let cap = self.params.half_block_cap(self.status.frequency, self.base_rate_hz).max(self.budget_grant(records));
        cap.min(self.budget_bound(records))
    }

    /// The half blocks per record (of `records`, as [`Self::budget_grant`] counts them) that
    /// still end the sweep within its time budget with every later frequency at its shortest
    /// (`slack_later` added to the room the grant sees): where the frequencies before took
    /// long (a noisy low end lengthened to its cap, a ringing loop's settling), the present
    /// one is cut short rather than the budget overrun. At least the half blocks already
    /// measured (they are paid for); `u32::MAX` without a budget, or with one the sweep's
    /// shortest schedule does not fit (nothing can hold it: the sweep runs as without it). It
    /// binds only where the budget would otherwise be overrun: a sweep that fits ends as it
    /// did before.
    pub(super) fn budget_bound(&self, records: u32) -> u32 {
        let Some((room, half, taken)) = self.budget_room(records) else { return u32::MAX };
        if room <= 0 {
            return taken as u32;
        }
        (room as u64 / (half * records.max(1) as u64)).max(taken).min(u32::MAX as u64) as u32
    }

    /// The half blocks the settling check may still discard from the present frequency's first
    /// record within the budget's bound: each lengthens that record alone (the discarded ones
    /// are already paid for). `u32::MAX` where [`Self::budget_bound`] has no bound.
    pub(super) fn budget_discards_left(&self) -> u32 {
        let records = self.params.records(self.status.frequency, self.base_rate_hz);
        let Some((room, half, _)) = self.budget_room(records) else { return u32::MAX };
        if room <= 0 {
            return 0;
        }
        (room as u64 / half).min(u32::MAX as u64) as u32
    }

    /// The ticks the present frequency may still take beyond its later records' base length
    /// with every later frequency at its shortest (the half blocks of its extension already
    /// measured counted back in), its half block's ticks and those half blocks; None without
    /// a bound (see [`Self::budget_bound`]).
    fn budget_room(&self, records: u32) -> Option<(i64, u64, u64)> {
        if self.budget_over_longest == super::NO_BUDGET || self.slack_over_shortest < 0 {
            return None;
        }
        let (room, half, taken, _) = self.room_with_later_at_longest(records);
        Some((room + self.slack_later as i64, half, taken))
    }

    /// What `budget_left` leaves the present frequency's `records` beyond their base length
    /// and the wait for the next frequency's peak, every later frequency at its longest (the
    /// half blocks of its extension already measured counted back in); with the half block's
    /// ticks, those half blocks and the record's samples. Only with a budget: every
    /// frequency's longest is then below 2³⁰ ticks (see `MAX_BUDGET_TICKS`), and with it each
    /// of the terms: 64-bit sums cannot overflow.
    fn room_with_later_at_longest(&self, records: u32) -> (i64, u64, u64, u64) {
        let p = &self.params;
        let (f, rate) = (self.status.frequency, self.base_rate_hz);
        let (settle, samples) = p.record_length(f, rate);
        let d = p.acquisition_divider as u64;
        let half = ((samples / 2) * d).max(1);
        let later_records = records.saturating_sub(1 + self.status.record) as u64;
        let last = self.status.point as usize + 1 >= self.plan.count as usize;
        let wait = if last { 0 } else { p.peak_wait_bound(f, rate) };
        let fixed = later_records * (settle.max(1) + samples * d) + wait;
        // Half blocks of this record's extension already measured (and paid for).
        let taken = self.spread.half_blocks.saturating_sub(2) as u64;
        let room = self.budget_left as i64 + (taken * half) as i64 - fixed as i64;
        (room, half, taken, samples)
    }

    /// The half blocks per record the time budget has room for (see [`Self::extension_cap`]),
    /// at most the cap of [`MAX_EXTENSIONS`](super::MAX_EXTENSIONS); 0 without a budget or
    /// room.
    pub(super) fn budget_grant(&self, records: u32) -> u32 {
        if self.budget_over_longest == super::NO_BUDGET || self.budget_left <= 0 {
            return 0;
        }
        let (room, half, _, samples) = self.room_with_later_at_longest(records);
        if room <= 0 {
            return 0;
        }
        let granted = room as u64 / (half * records.max(1) as u64);
        let (f, rate) = (self.status.frequency, self.base_rate_hz);
        let most = self.params.half_blocks_in(super::MAX_EXTENSIONS, samples, f, rate);
        granted.min(most as u64) as u32
    }
}
