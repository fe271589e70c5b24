//! The settling check: the first record of a frequency is measured in half blocks, and the
//! earlier of two is discarded while they disagree (see [`PhaseShiftedSweep::settled`]).

use super::{AcquisitionSample, HalfBlockSpread, PhaseShiftedSweep};
use crate::TAU;

/// Half blocks agree within so many standard deviations of their difference (see
/// `PhaseShiftedSweep::settled`).
const SETTLING_NOISE_SIGMAS: f32 = 1.5;

/// After a discarded half block, the previous comparison's difference was at most so many
/// times its limit.
const SETTLED_TREND: f32 = 2.0;

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
    /// two half blocks, one base block. At most `SweepParams::half_block_cap` half blocks are
    /// discarded (`2·max_extensions` of the full block).
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
            // Else the check ends on a half block that tells nothing: the base block is the
            // last two (indices k − 1 and k) and the samples after it keep index k, so that a
            // host fitting from the last index minus one up keeps what the drive keeps.
            return first.then_some(samples - samples / 2);
        };
        let target = p.relative_precision();
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
        // A transient seen above the noise in the previous comparison must, besides, have left
        // the base block within the limit (see `tail_over_difference`), and the previous
        // comparison must not have been far outside the limit: two half blocks can agree by
        // chance while a larger ring, under noise, has not decayed.
        let excess = difference / target.max(noise);
        let tail =
            if self.discarded_halves == 0 { 0.0 } else { tail_over_difference((dre, dim), self.previous_difference) };
        // The larger of this and the previous ratio's tail: one ratio spoiled by a second mode
        // or by noise under-estimates it. A NaN of this ratio (no decay told) stays NaN and
        // refuses; the previous one's is passed over.
        let worst_tail = if tail <= self.previous_tail { self.previous_tail } else { tail };
        let settled = excess <= 1.0
            && !decaying
            && (self.discarded_halves == 0
                || self.previous_excess <= SETTLED_TREND && (!self.previous_above_noise || excess * worst_tail <= 1.0));
        self.previous_tail = tail;
        self.previous_difference = (dre, dim);
        self.previous_above_noise = difference > noise;
        self.previous_excess = excess;
        if settled || self.discarded_halves >= p.half_block_cap(self.status.frequency, self.base_rate_hz) {
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
}

/// What a decaying transient still leaves in the base block (the last two half blocks), over
/// the last difference of half-block responses, if it decays as one mode: the differences
/// then form a geometric sequence `d_k = d_{k−1}·q` (q complex: the mode beats against the
/// excitation), the half blocks carry `d_k·q/(q − 1)` and `d_k/(q − 1)`, their mean
/// `d_k·(1 + q)/(2(q − 1))`. A slow decay (q near 1) leaves several times the last
/// difference: a ring at 52 Hz with τ = 50 ms, measured at 50 Hz in half blocks of 20 ms,
/// leaves 2.5 times it. Infinite or NaN when the ratio tells no decay.
fn tail_over_difference((dre, dim): (f32, f32), (pre, pim): (f32, f32)) -> f32 {
    let den = pre * pre + pim * pim;
    let (qre, qim) = ((dre * pre + dim * pim) / den, (dim * pre - dre * pim) / den);
    let plus = (1.0 + qre) * (1.0 + qre) + qim * qim;
    let minus = (1.0 - qre) * (1.0 - qre) + qim * qim;
    0.5 * crate::square_root::sqrt(plus / minus)
}

#[cfg(test)]
mod tests {
    use super::tail_over_difference;

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
            let predicted = tail_over_difference(last, d(2)) * libm::hypotf(last.0, last.1);
            let actual = libm::hypotf(bias.0, bias.1);
            assert!((predicted - actual).abs() < 1e-4 * actual.max(1e-3), "q {q:?}: {predicted} vs {actual}");
        }
    }
}
