//! The settling check: the first record of a frequency is measured in half blocks, and the
//! earlier of two is discarded while they disagree, or while a ring their differences told
//! would leave more than the precision in the result (see [`PhaseShiftedSweep::settled`]).

use super::precision_control::EARLY_HALF_BLOCKS;
use super::{AcquisitionSample, HalfBlockSpread, PhaseShiftedSweep};
use crate::TAU;

/// Half blocks agree within so many standard deviations of their difference (see
/// `PhaseShiftedSweep::settled`).
const SETTLING_NOISE_SIGMAS: f32 = 1.5;

/// After a discarded half block, the previous comparison's difference was at most so many
/// times its limit.
const SETTLED_TREND: f32 = 2.0;

/// Two successive ratios of half-block differences (`d_k/d_{k−1}`, complex) that differ by at
/// most this are one decaying mode's, not noise's. Noise alone gives ratios that scatter
/// around −1/2 (successive differences share a half block with opposite signs) by about as
/// much again, and two successive ones agree this closely in about 2 % of comparisons (each
/// then costs a half block or so; complex Gaussian half blocks, simulated); a ring's ratio is
/// its decay and beat over a half block. On a 0.3:1, 53 Hz axis (velocity feedback, 50 Hz,
/// no current noise) the ratios before the check ended were 0.68∠−37°, 0.66∠−29°,
/// 0.55∠−38°: the residuals' model read the encoder's noise at the excitation as about 0.011
/// (three times the precision; the check emulated on the stream), the last difference,
/// 0.006, passed within it and left −0.62° in the result.
const RING_RATIO_AGREEMENT: f32 = 0.25;

/// A ring told by its ratios is waited for until what it is predicted to leave in the result
/// is at most this share of the precision (its standard error's goal: the ring then takes no
/// more of the 0.1 dB budget than the noise's standard error does). Lower shares cost
/// measurement time on soft axes: with a wait fixed when the ring was told, at 0.3
/// `servo bench sweep`'s 5:1, 50 Hz velocity-feedback rows took 9.9–10.2 s, at 1.0 9.1–9.3 s
/// (9.3 s before rings were told; 9.4–9.5 s as the check follows them now; one noise seed,
/// the test command's; over six seeds the noisy one's longest is 9.9 s).
const RING_LEFT: f32 = 1.0;

/// Base blocks shorter than this (samples) are not checked for settling: a half block would
/// be too short to fit a sine and estimate its noise.
pub(super) const MIN_CHECKED_SAMPLES: u64 = 32;

impl PhaseShiftedSweep {
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
    /// two half blocks, one base block. A ring whose differences decay geometrically (two
    /// successive ratios agree) is, besides, waited for until what it is predicted to leave in
    /// the result is within the precision, whatever the noise's allowance. At most
    /// `SweepParams::half_block_cap` half blocks are discarded (`2·max_extensions` of the full
    /// block).
    // Once per half block: kept out of line so that the every-tick path stays small.
    #[inline(never)]
    pub(super) fn settled(&mut self) -> Option<u64> {
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
            if first {
                self.half_block = 1;
                self.segment = AcquisitionSample::segment_of(self.status.record, 1);
            }
            // Else the check ends on a half block that tells nothing (also while a ring is
            // tracked: nothing tells what it still leaves): the base block is the last two
            // (indices k − 1 and k) and the samples after it keep index k, so that a host
            // fitting from the last index minus one up keeps what the drive keeps.
            return first.then_some(samples - samples / 2);
        };
        let target = p.relative_precision();
        // The log of the ratio of two noise variances of n samples each has a spread of about
        // 2/√n: three of those bound how far two half blocks' noise can differ.
        let n = half.n;
        let variance_ratio = libm::expf(6.0 / crate::square_root::sqrt(n));
        // The responses differ beyond the precision and beyond `SETTLING_NOISE_SIGMAS` times
        // the size of a difference of two half blocks under the noise (twice one's variance).
        // At the first comparison this half block's variance counts only up to the square of
        // that ratio over the earlier one's: a half block whose residual grew beyond what noise
        // does (a mode building up, or an input swung through zero) says nothing about
        // settling and must not widen the allowance. On a 0.576:1, 59.3 Hz axis at 57.8 Hz the
        // torque command of the second half block was a twenty-fifth of the first's; its
        // relative noise (62 times the first's) let a difference of 100 % pass at the first
        // comparison and left 0.6 dB and 3.6° in the result. From the second comparison on a
        // pass needs besides the previous comparison within `SETTLED_TREND` of its limit (and,
        // where that one's difference was above the noise, the tail it predicts within the
        // limit), which a build-up that had just swung the input through zero is not likely to
        // meet; a noisier half block after a calm comparison can still pass there, as before.
        // Squared, and the first comparison only, because quantisation and noise through
        // lightly damped modes vary between half blocks more than Gaussian noise does: the
        // ratio itself at every comparison held `servo bench sweep`'s 30 rows (one noise seed)
        // 3.5 % longer in all (2.1 % squared; 0.3 % squared at the first comparison only, with
        // the fs/2 record's fix of `response_error`), and the time it took from the top's
        // precision showed as results over 0.1 dB at 1.9–2.6 kHz on the other grids. An
        // earlier half block whose noise reads 0 (its spectrum's estimate clamped) caps
        // nothing: it tells no noise to compare with.
        let most = variance_ratio * variance_ratio * spread0;
        let counted = if spread <= most || spread0 <= 0.0 || self.discarded_halves > 0 { spread } else { most };
        let noise = SETTLING_NOISE_SIGMAS * crate::square_root::sqrt(2.0 * counted);
        let (dre, dim) = (re - re0, im - im0);
        let difference = crate::square_root::sqrt((dre * dre + dim * dim) / (re * re + im * im));
        // Or the earlier half's residual is larger than the noise's variance ratio allows (a
        // decaying transient, which can bias both halves alike when it rings near the
        // excitation: the responses then agree before the loop has settled) and large
        // enough to matter: its relative size `√(spread·n/2)` above the precision.
        let decaying = spread0 > variance_ratio * spread && spread0 * 0.5 * n > target * target;
        // A transient seen above the noise in the previous comparison must, besides, have left
        // the base block within the limit (see `tail_over_difference`), and the previous
        // comparison must not have been far outside the limit: two half blocks can agree by
        // chance while a larger ring, under noise, has not decayed.
        let excess = difference / target.max(noise);
        let ratio = if self.discarded_halves == 0 {
            (f32::NAN, f32::NAN)
        } else {
            ratio_of_differences((dre, dim), self.previous_difference)
        };
        let tail = tail_over_difference(ratio);
        // The larger of this and the previous ratio's tail: one ratio spoiled by a second mode
        // or by noise under-estimates it. A NaN of this ratio (no decay told) stays NaN and
        // refuses; the previous one's (or none) is passed over.
        let previous_tail = tail_over_difference(self.previous_ratio);
        let worst_tail = if tail <= previous_tail { previous_tail } else { tail };
        // Two successive ratios that agree, of differences above the noise, the last one below
        // 1 in size, are one mode's decay, not noise (see `RING_RATIO_AGREEMENT`; noise gives
        // ratios above 1 in size as often as not, and a pair of those that agreed by chance
        // held a record of the 0.2:1, 50 Hz axis's torque command to the cap at 77.5 Hz). Told
        // while the ring is still above the noise, it is followed on by its ratio, whatever the
        // later, noisier comparisons say, and the record settles only once what the ring is
        // predicted to leave in the result is at most `RING_LEFT` of the precision (see
        // `TrackedRing::left_in_result`). Of two rings told, the slower is followed, scaled to
        // what the other leaves now where that is more (see `TrackedRing::or`).
        let (are, aim) = (ratio.0 - self.previous_ratio.0, ratio.1 - self.previous_ratio.1);
        let told = are * are + aim * aim <= RING_RATIO_AGREEMENT * RING_RATIO_AGREEMENT
            && ratio.0 * ratio.0 + ratio.1 * ratio.1 < 1.0
            && difference.is_finite()
            && difference > noise
            && self.previous_above_noise;
        let ring_left = if told || self.ring.difference > 0.0 {
            let halves = self.record_half_blocks();
            let tracked =
                if self.ring.difference > 0.0 { self.ring.left_in_result(self.half_block, halves) } else { 0.0 };
            if told {
                let now = TrackedRing { difference, ratio, at: self.half_block };
                let left = now.left_in_result(self.half_block, halves);
                self.ring = if self.ring.difference > 0.0 { self.ring.or(now, left, tracked) } else { now };
                left.max(tracked)
            } else {
                tracked
            }
        } else {
            0.0
        };
        let settled = excess <= 1.0
            && !decaying
            && (self.discarded_halves == 0
                || self.previous_excess <= SETTLED_TREND && (!self.previous_above_noise || excess * worst_tail <= 1.0))
            && ring_left <= RING_LEFT * target;
        self.previous_ratio = ratio;
        self.previous_difference = (dre, dim);
        self.previous_above_noise = difference > noise;
        self.previous_excess = excess;
        let cap = p.half_block_cap(self.status.frequency, self.base_rate_hz);
        if settled || self.discarded_halves >= cap || self.budget_discards_left() == 0 {
            self.checking_settling = false;
            if settled && self.averaging {
                // Below the threshold the frequency has this one record: its extension is
                // measured in half blocks too, whose spread checks the predicted error (see
                // `next_half_block`).
                self.spread = HalfBlockSpread::default();
                self.spread.close(Some((re0, im0)));
                self.spread.close(Some((re, im)));
                self.half_start = self.acc;
            }
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

    /// The half blocks the present frequency's result will average if the record settles
    /// now: its base block and the extension predicted from it, of every record; below the
    /// threshold at most [`EARLY_HALF_BLOCKS`], after which the half blocks' spread can end
    /// the record (see [`Self::next_half_block`]). From the threshold up the later records
    /// are counted as if they followed on without a gap, though each starts after a settling
    /// gap and a phase step of 2π/shifts: there the figure is the model's, not a bound.
    fn record_half_blocks(&self) -> u32 {
        let records = self.params.records(self.status.frequency, self.base_rate_hz);
        // Without the budget's room (grant 0): fewer half blocks dilute a ring less, so the
        // wait for it stays on the safe side whatever the budget grants later.
        let per_record = 2 + self.halves_needed(records, 0);
        let per_record = if self.averaging { per_record.min(EARLY_HALF_BLOCKS) } else { per_record };
        records.saturating_mul(per_record).max(2)
    }
}

/// A ring told by the settling check (two successive ratios of half-block differences that
/// agree): the last difference's size relative to |G|, their ratio, and the half block it was
/// told at. `difference` 0: none told.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct TrackedRing {
    difference: f32,
    ratio: (f32, f32),
    at: u32,
}

impl TrackedRing {
    /// One ring standing for this one and `other`, told now, which leave `other_left` and
    /// `self_left` in the result now: the slower of the two (the larger |q|), its size raised
    /// to leave what the other leaves now where that is more. It then bounds both from here on
    /// (exactly for the same N; the slower one decays less per half block). Keeping whichever
    /// left more now could let a fast ring told later displace a slow one that still mattered
    /// one half block after the fast one had died out (a reviewer's example: q = 0.95 leaving
    /// 2× the precision, then q = 0.2 leaving 2.1×; not seen on the benches); a second ring
    /// per axis slot does not fit in the drive's RAM (24 bytes left).
    fn or(self, other: TrackedRing, other_left: f32, self_left: f32) -> TrackedRing {
        let size = |(re, im): (f32, f32)| re * re + im * im;
        let (mut slower, slower_left, faster_left) = if size(other.ratio) > size(self.ratio) {
            (other, other_left, self_left)
        } else {
            (self, self_left, other_left)
        };
        if faster_left > slower_left && slower_left > 0.0 {
            slower.difference *= faster_left / slower_left;
        }
        slower
    }

    /// What the ring is predicted to leave, relative to |G|, in a result that averages
    /// `halves` half blocks from the last two at `half_block` on: its difference decays by
    /// |q| per half block since it was told (see [`ring_left_in_result`]; a ring is told only
    /// when it decays, |q| < 1).
    fn left_in_result(&self, half_block: u32, halves: u32) -> f32 {
        let (pre, pim) = power(self.ratio, half_block.saturating_sub(self.at));
        let decayed = self.difference * crate::square_root::sqrt(pre * pre + pim * pim);
        ring_left_in_result(decayed, self.ratio, halves)
    }
}

/// The ratio `q = d_k/d_{k−1}` of the last two differences of half-block responses (NaN when
/// the earlier one is zero or not finite).
fn ratio_of_differences((dre, dim): (f32, f32), (pre, pim): (f32, f32)) -> (f32, f32) {
    let den = pre * pre + pim * pim;
    ((dre * pre + dim * pim) / den, (dim * pre - dre * pim) / den)
}

/// What one decaying mode still leaves in a result that averages `halves` half blocks from
/// the last two on, relative to |G|, from the last difference of half-block responses (its
/// size relative to |G|) and their ratio q: the mode's part of the half blocks is
/// `r·q^j` with `r = d/(q − 1)`, its mean over them `r·(1 − q^N)/((1 − q)·N)`. Over two half
/// blocks (the base block alone) this is [`tail_over_difference`] times |d|; a longer record
/// dilutes it.
fn ring_left_in_result(difference: f32, q: (f32, f32), halves: u32) -> f32 {
    let (pre, pim) = power(q, halves);
    let (qre, qim) = q;
    let distance = (1.0 - qre) * (1.0 - qre) + qim * qim;
    let (ore, oim) = (1.0 - pre, -pim);
    difference * crate::square_root::sqrt(ore * ore + oim * oim) / (distance * halves as f32)
}

/// `q^n` by repeated squaring (at most 32 steps of a few multiplications; with `powf`, `atan2f`
/// and a sine and cosine instead, the drive image was 1.6 KiB larger).
fn power((mut bre, mut bim): (f32, f32), mut n: u32) -> (f32, f32) {
    let (mut re, mut im) = (1.0f32, 0.0f32);
    while n > 0 {
        if n & 1 == 1 {
            (re, im) = (re * bre - im * bim, re * bim + im * bre);
        }
        (bre, bim) = (bre * bre - bim * bim, 2.0 * bre * bim);
        n >>= 1;
    }
    (re, im)
}

/// What a decaying transient still leaves in the base block (the last two half blocks), over
/// the last difference of half-block responses, if it decays as one mode: the differences
/// then form a geometric sequence `d_k = d_{k−1}·q` (q complex, [`ratio_of_differences`]: the
/// mode beats against the excitation), the half blocks carry `d_k·q/(q − 1)` and
/// `d_k/(q − 1)`, their mean `d_k·(1 + q)/(2(q − 1))`. A slow decay (q near 1) leaves several
/// times the last difference: a ring at 52 Hz with τ = 50 ms, measured at 50 Hz in half
/// blocks of 20 ms (q = 0.67∠14°), leaves 2.1 times it. Infinite or NaN when the ratio tells
/// no decay (NaN for a NaN ratio).
fn tail_over_difference((qre, qim): (f32, f32)) -> f32 {
    let plus = (1.0 + qre) * (1.0 + qre) + qim * qim;
    let minus = (1.0 - qre) * (1.0 - qre) + qim * qim;
    0.5 * crate::square_root::sqrt(plus / minus)
}

#[cfg(test)]
mod tests {
    use super::{ratio_of_differences, ring_left_in_result, tail_over_difference};

    /// Half-block responses `G + C·q^k` of one decaying mode: the function turns the last
    /// difference into the bias the last two half blocks' mean still has.
    #[test]
    fn the_tail_of_a_geometric_transient_is_what_the_base_block_still_carries() {
        let mul = |(a, b): (f32, f32), (c, d): (f32, f32)| (a * c - b * d, a * d + b * c);
        for &(q, c) in &[((0.67, 0.0), (0.3, 0.1)), ((0.4, -0.45), (-0.2, 0.5)), ((-0.3, 0.6), (1.0, -1.0))] {
            let g = (1.5, -0.4);
            let mut power = (1.0, 0.0);
            let mut halves = [(0.0, 0.0); 4];
            for h in halves.iter_mut() {
                let t = mul(c, power);
                *h = (g.0 + t.0, g.1 + t.1);
                power = mul(power, q);
            }
            let d = |k: usize| (halves[k].0 - halves[k - 1].0, halves[k].1 - halves[k - 1].1);
            let bias = ((halves[2].0 + halves[3].0) / 2.0 - g.0, (halves[2].1 + halves[3].1) / 2.0 - g.1);
            let last = d(3);
            let predicted = tail_over_difference(ratio_of_differences(last, d(2))) * libm::hypotf(last.0, last.1);
            let actual = libm::hypotf(bias.0, bias.1);
            assert!((predicted - actual).abs() < 1e-4 * actual.max(1e-3), "q {q:?}: {predicted} vs {actual}");
        }
    }

    /// The same mode over a longer record: the mean of its part over the N half blocks from
    /// the last two on, summed directly, is what the closed form predicts from the last
    /// difference and the ratio.
    #[test]
    fn what_a_ring_leaves_in_a_longer_record_is_its_mean_over_it() {
        let mul = |(a, b): (f32, f32), (c, d): (f32, f32)| (a * c - b * d, a * d + b * c);
        for &(q, c) in &[((0.67, 0.0), (0.3, 0.1)), ((0.4, -0.45), (-0.2, 0.5)), ((0.55, -0.35), (1.0, -1.0))] {
            for halves in [2usize, 3, 6, 17] {
                // The mode's part of half blocks 0 (the one before the last two), 1, 2, … .
                let mut power = (1.0f32, 0.0f32);
                let mut parts = [(0.0f32, 0.0f32); 20];
                for part in parts.iter_mut() {
                    *part = mul(c, power);
                    power = mul(power, q);
                }
                let last = (parts[2].0 - parts[1].0, parts[2].1 - parts[1].1);
                let sum = parts[1..halves + 1].iter().fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
                let actual = libm::hypotf(sum.0, sum.1) / halves as f32;
                let predicted = ring_left_in_result(libm::hypotf(last.0, last.1), q, halves as u32);
                assert!(
                    (predicted - actual).abs() < 1e-4 * actual.max(1e-3),
                    "q {q:?}, {halves}: {predicted} vs {actual}"
                );
            }
        }
    }

    /// A ring told at an earlier half block: decayed by q per half block since, it leaves
    /// what the direct sum over the N half blocks from the last two at the present one on
    /// gives; and of two rings, the one kept bounds both from then on.
    #[test]
    fn a_followed_ring_decays_by_its_ratio_and_one_ring_bounds_two() {
        use super::TrackedRing;
        let mul = |(a, b): (f32, f32), (c, d): (f32, f32)| (a * c - b * d, a * d + b * c);
        // Half block k's part of a mode c·q^k (k = 0: the first of the pair it was told at).
        let part = |c: (f32, f32), q: (f32, f32), k: u32| (0..k).fold(c, |x, _| mul(x, q));
        let mean = |c: (f32, f32), q: (f32, f32), from: u32, halves: u32| {
            let sum = (from..from + halves).map(|k| part(c, q, k)).fold((0.0, 0.0), |a, p| (a.0 + p.0, a.1 + p.1));
            libm::hypotf(sum.0, sum.1) / halves as f32
        };
        let (q, c) = ((0.6f32, -0.3f32), (0.02f32, 0.01f32));
        let d = {
            let (a, b) = (part(c, q, 0), part(c, q, 1));
            libm::hypotf(b.0 - a.0, b.1 - a.1)
        };
        // Told at half block 7 from the pair (6, 7); five half blocks later the pair is (11, 12).
        let ring = TrackedRing { difference: d, ratio: q, at: 7 };
        for halves in [2u32, 5, 9] {
            let predicted = ring.left_in_result(12, halves);
            let actual = mean(c, q, 5, halves);
            assert!((predicted - actual).abs() < 1e-4 * actual, "{halves}: {predicted} vs {actual}");
        }
        // A slow ring and a fast one told later that leaves more now: the one kept is the slow
        // one, raised to what the fast one leaves now, and it bounds both afterwards.
        let slow = TrackedRing { difference: 0.004, ratio: (0.9, 0.2), at: 3 };
        let fast = TrackedRing { difference: 0.05, ratio: (0.2, 0.1), at: 6 };
        let (slow_left, fast_left) = (slow.left_in_result(6, 2), fast.left_in_result(6, 2));
        assert!(fast_left > slow_left, "{fast_left} {slow_left}");
        let kept = slow.or(fast, fast_left, slow_left);
        assert_eq!(kept.ratio, slow.ratio);
        for later in 6..20 {
            let left = kept.left_in_result(later, 2);
            let both = slow.left_in_result(later, 2).max(fast.left_in_result(later, 2));
            assert!(left >= 0.999 * both, "half block {later}: {left} below {both}");
        }
    }
}
