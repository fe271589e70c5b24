//! Second-order IIR sections for the torque-command path: low-pass and notch.
//!
//! Designed by the bilinear transform with frequency pre-warping, so the cut-off or notch
//! centre lands exactly where asked. Realised in transposed direct form II (two states,
//! good numerical behaviour in f32 at these ratios of centre to sample frequency).

use crate::TAU;

/// Normalised coefficients: `H(z) = (b0 + b1 z⁻¹ + b2 z⁻²) / (1 + a1 z⁻¹ + a2 z⁻²)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Biquad {
    pub b0: f32,
    pub b1: f32,
    pub b2: f32,
    pub a1: f32,
    pub a2: f32,
    s1: f32,
    s2: f32,
}

impl Default for Biquad {
    fn default() -> Self {
        Self::identity()
    }
}

impl Biquad {
    /// A section with the given normalised coefficients and zero state.
    pub const fn new(b0: f32, b1: f32, b2: f32, a1: f32, a2: f32) -> Self {
        Self { b0, b1, b2, a1, a2, s1: 0.0, s2: 0.0 }
    }

    /// Take `other`'s coefficients and state, field by field (a struct copy of this size
    /// becomes a `memcpy` call on the Cortex-M4, some 40 instructions).
    #[inline(always)]
    pub fn copy_from(&mut self, other: &Self) {
        let Self { b0, b1, b2, a1, a2, s1, s2 } = *other;
        (self.b0, self.b1, self.b2, self.a1, self.a2, self.s1, self.s2) = (b0, b1, b2, a1, a2, s1, s2);
    }

    /// The transposed-direct-form-II state `(s1, s2)`.
    pub fn state(&self) -> (f32, f32) {
        (self.s1, self.s2)
    }

    /// Pass-through section.
    pub const fn identity() -> Self {
        Self { b0: 1.0, b1: 0.0, b2: 0.0, a1: 0.0, a2: 0.0, s1: 0.0, s2: 0.0 }
    }

    fn from_analog(num: [f32; 3], den: [f32; 3], w0: f32, sample_rate: f32) -> Self {
        // H(s) = (n2 s² + n1 w0 s + n0 w0²) / (d2 s² + d1 w0 s + d0 w0²) with
        // s = K (1 - z⁻¹)/(1 + z⁻¹), K = w0 / tan(w0 / (2 fs)) (pre-warped).
        let k = w0 / libm::tanf(w0 / (2.0 * sample_rate));
        let kk = k * k;
        let w2 = w0 * w0;
        let nb0 = num[2] * kk + num[1] * w0 * k + num[0] * w2;
        let nb1 = 2.0 * (num[0] * w2 - num[2] * kk);
        let nb2 = num[2] * kk - num[1] * w0 * k + num[0] * w2;
        let da0 = den[2] * kk + den[1] * w0 * k + den[0] * w2;
        let da1 = 2.0 * (den[0] * w2 - den[2] * kk);
        let da2 = den[2] * kk - den[1] * w0 * k + den[0] * w2;
        Self { b0: nb0 / da0, b1: nb1 / da0, b2: nb2 / da0, a1: da1 / da0, a2: da2 / da0, s1: 0.0, s2: 0.0 }
    }

    /// Second-order Butterworth low-pass (Q = 1/√2) at `cutoff_hz`.
    pub fn low_pass(cutoff_hz: f32, sample_rate: f32) -> Self {
        let w0 = TAU * cutoff_hz;
        Self::from_analog([1.0, 0.0, 0.0], [1.0, core::f32::consts::SQRT_2, 1.0], w0, sample_rate)
    }

    /// Notch `(s² + 2·d·ζ·w0·s + w0²)/(s² + 2·ζ·w0·s + w0²)` with `ζ = 1/(2Q)`:
    /// `depth` is the gain at the centre (0 = full notch, 1 = no notch).
    pub fn notch(centre_hz: f32, q: f32, depth: f32, sample_rate: f32) -> Self {
        let w0 = TAU * centre_hz;
        let zeta = 0.5 / q;
        Self::from_analog([1.0, 2.0 * zeta * depth, 1.0], [1.0, 2.0 * zeta, 1.0], w0, sample_rate)
    }

    pub fn reset(&mut self) {
        self.s1 = 0.0;
        self.s2 = 0.0;
    }

    /// Set the internal state to the steady state for a constant input `x` (bumpless start).
    pub fn preset(&mut self, x: f32) {
        let dc = (self.b0 + self.b1 + self.b2) / (1.0 + self.a1 + self.a2);
        let y = dc * x;
        self.s2 = self.b2 * x - self.a2 * y;
        self.s1 = y - self.b0 * x;
    }

    /// Sum of every future output if the input stopped now (whole-pulse filters keep this
    /// many pulses inside).
    pub fn pending_output(&self) -> f32 {
        (self.s1 + self.s2) / (1.0 + self.a1 + self.a2)
    }

    pub fn process(&mut self, x: f32) -> f32 {
        let y = self.b0 * x + self.s1;
        self.s1 = self.b1 * x - self.a1 * y + self.s2;
        self.s2 = self.b2 * x - self.a2 * y;
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn gain_at(bq: &Biquad, f: f32, fs: f32) -> f32 {
        // |H(e^{jωT})| evaluated directly from the coefficients.
        let w = TAU * f / fs;
        let (c1, s1, c2, s2) = (libm::cosf(w), libm::sinf(w), libm::cosf(2.0 * w), libm::sinf(2.0 * w));
        let nr = bq.b0 + bq.b1 * c1 + bq.b2 * c2;
        let ni = -(bq.b1 * s1 + bq.b2 * s2);
        let dr = 1.0 + bq.a1 * c1 + bq.a2 * c2;
        let di = -(bq.a1 * s1 + bq.a2 * s2);
        libm::sqrtf((nr * nr + ni * ni) / (dr * dr + di * di))
    }

    #[test]
    fn low_pass_is_minus_3db_at_cutoff_and_unity_at_dc() {
        let lp = Biquad::low_pass(1000.0, 8000.0);
        assert!((gain_at(&lp, 0.0, 8000.0) - 1.0).abs() < 1e-5);
        assert!((gain_at(&lp, 1000.0, 8000.0) - core::f32::consts::FRAC_1_SQRT_2).abs() < 1e-4);
    }

    #[test]
    fn notch_has_its_depth_at_the_centre() {
        let n = Biquad::notch(500.0, 2.0, 0.1, 8000.0);
        assert!((gain_at(&n, 500.0, 8000.0) - 0.1).abs() < 1e-4);
        assert!((gain_at(&n, 0.0, 8000.0) - 1.0).abs() < 1e-5);
    }

    #[test]
    fn preset_gives_constant_output_for_constant_input() {
        let mut lp = Biquad::low_pass(300.0, 8000.0);
        lp.preset(2.5);
        for _ in 0..10 {
            assert!((lp.process(2.5) - 2.5).abs() < 1e-5);
        }
    }
}
