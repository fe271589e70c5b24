//! The settling check: the first record of a frequency is measured in half blocks, and the
//! earlier of two is discarded while they disagree (see [`PhaseShiftedSweep::settled`]).

use super::{AcquisitionSample, PhaseShiftedSweep};
use crate::TAU;

/// Half blocks agree within so many standard deviations of their difference (see
/// `PhaseShiftedSweep::settled`).
const SETTLING_NOISE_SIGMAS: f32 = 1.5;

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
    /// two half blocks, one base block. At most `2·max_extensions` half blocks are discarded.
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
}
