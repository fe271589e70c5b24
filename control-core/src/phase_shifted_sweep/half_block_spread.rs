//! The spread of a record's half-block responses: an estimate of the response's standard
//! error that needs no model of the noise (see [`HalfBlockSpread::relative_error`]).

/// Responses `G_k = Y_k/U_k` of the successive half blocks of one record, summed about the
/// first (`reference`): the differences, not the responses, are summed, so that the f32 sums
/// of squares do not cancel when the half blocks agree to a few parts in 10⁴.
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct HalfBlockSpread {
    reference: (f32, f32),
    sum: (f32, f32),
    squares: f32,
    /// Responses summed (half blocks that told one).
    pub(super) count: u32,
    /// Half blocks measured, with or without a response (0: the record is not measured in
    /// half blocks).
    pub(super) half_blocks: u32,
}

impl HalfBlockSpread {
    /// A half block ended, with its response (None when its samples told none: it counts as
    /// measured, not in the spread).
    pub(super) fn close(&mut self, response: Option<(f32, f32)>) {
        self.half_blocks += 1;
        if let Some(g) = response {
            self.add(g);
        }
    }

    fn add(&mut self, (re, im): (f32, f32)) {
        if self.count == 0 {
            self.reference = (re, im);
        }
        let (dre, dim) = (re - self.reference.0, im - self.reference.1);
        self.sum.0 += dre;
        self.sum.1 += dim;
        self.squares += dre * dre + dim * dim;
        self.count += 1;
    }

    /// The standard error of the half blocks' mean response relative to its size, per
    /// component (the gain's and the phase's alike: half the complex variance each), from the
    /// half blocks' scatter: `√(Σ|G_k − Ḡ|² / (K(K − 1)) / 2) / |Ḡ|`. It holds whatever the
    /// noise's spectrum, where the model of [`SineFitSums::response_error`]
    /// (super::sine_fit::SineFitSums::response_error), a first-order spectrum fitted to the
    /// residuals, does not: a lightly damped closed-loop mode driven by current noise puts a
    /// narrow peak of noise next to the excitation, which that model, fitted to the residual's
    /// variance and its lag-one correlation, cannot see. None with fewer than three half
    /// blocks (one difference tells too little) or no response.
    pub(super) fn relative_error(&self) -> Option<f32> {
        if self.count < 3 {
            return None;
        }
        let k = self.count as f32;
        let (mre, mim) = (self.sum.0 / k, self.sum.1 / k);
        let scatter = (self.squares - k * (mre * mre + mim * mim)).max(0.0);
        let (gre, gim) = (self.reference.0 + mre, self.reference.1 + mim);
        let size = gre * gre + gim * gim;
        if !(size > 0.0) {
            return None;
        }
        Some(crate::square_root::sqrt(scatter / (k * (k - 1.0)) / (2.0 * size)))
    }
}

#[cfg(test)]
mod tests {
    use super::HalfBlockSpread;

    /// Against the textbook formula in f64 over the responses themselves, for a spread many
    /// orders of magnitude below the responses' size (where summing the responses' squares in
    /// f32 would cancel).
    #[test]
    fn the_relative_error_is_the_standard_error_of_the_mean_over_its_size() {
        for &(g, scale) in &[((1.5f64, -0.4f64), 1e-3f64), ((120.0, 35.0), 1e-4), ((-0.02, 0.007), 0.3)] {
            let offsets = [(0.3, -1.1), (-0.7, 0.2), (1.2, 0.9), (-0.4, -0.5), (0.1, 0.6)];
            let mut spread = HalfBlockSpread::default();
            let responses: [(f64, f64); 5] = offsets
                .map(|(a, b)| (g.0 + scale * a * g.0.abs().max(g.1.abs()), g.1 + scale * b * g.0.abs().max(g.1.abs())));
            for &(re, im) in &responses {
                spread.close(Some((re as f32, im as f32)));
            }
            let k = responses.len() as f64;
            let mean = (responses.iter().map(|r| r.0).sum::<f64>() / k, responses.iter().map(|r| r.1).sum::<f64>() / k);
            let ss: f64 = responses.iter().map(|r| (r.0 - mean.0).powi(2) + (r.1 - mean.1).powi(2)).sum();
            let expected = (ss / (k * (k - 1.0)) / 2.0).sqrt() / (mean.0 * mean.0 + mean.1 * mean.1).sqrt();
            let got = spread.relative_error().unwrap() as f64;
            assert!((got - expected).abs() < 1e-3 * expected, "{g:?}: {got} vs {expected}");
        }
    }

    #[test]
    fn fewer_than_three_half_blocks_or_no_response_tell_nothing() {
        let mut spread = HalfBlockSpread::default();
        assert_eq!(spread.relative_error(), None);
        spread.close(Some((1.0, 0.0)));
        spread.close(None);
        spread.close(Some((1.1, 0.0)));
        assert_eq!((spread.relative_error(), spread.half_blocks), (None, 3));
        let mut zero = HalfBlockSpread::default();
        for _ in 0..3 {
            zero.close(Some((0.0, 0.0)));
        }
        assert_eq!(zero.relative_error(), None);
    }
}
