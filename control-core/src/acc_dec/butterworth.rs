//! Butterworth low-pass acc/dec filter discretised by pole-zero matching (seed 003): the design.
//!
//! Design: the `N` analogue poles `p = ωc·e^{jθ}` map to `z = e^{p·T}`; the gain makes
//! `G(1) = 1`. The `N` zeros at infinity are placed by [`ZeroPlacement`]: the seed maps
//! `N − 1` of them to `z = −1` and keeps one as a one-sample delay
//! (`K·z⁻¹(1 + z⁻¹)^{N−1}/A(z)`: the output reacts one tick after the input and the Nyquist
//! frequency is nulled), python-control's `sample_system(method='matched')` keeps every one as
//! a delay (`K·z⁻ᴺ/A(z)`: same poles, `N` ticks of dead time, no null at Nyquist).
//!
//! The design is computed once, in f64, in the form the drive runs (see
//! [`super::ButterworthPulseFilter`]): for each pole pair `r·e^{±jφ}` the values `1 + a1 + a2 =
//! |1 − z|² = (1 − r)² + 4r·sin²(φ/2)` and `1 − a2 = 1 − r²`, and for the real pole `1 − p`, each
//! built from `expm1` and `sin` of small arguments, so none of them is a difference of nearly
//! equal numbers. With poles near `z = 1` (a cut-off of 0.5 Hz at 8 kHz: `ωc·T = 3.9·10⁻⁴`),
//! `1 + a1 + a2 ≈ (ωc·T)² = 1.5·10⁻⁷` computed from `a1 ≈ −2`, `a2 ≈ 1` would keep only 3 of
//! f32's 24 bits, and the filter would not be the one designed. f64 here is design-time only
//! (a few thousand soft-float instructions on the Cortex-M4F when the parameters change, none
//! per tick); `libm`'s f64 functions and IEEE f64 arithmetic give the same bits on the host and
//! on the target.
//!
//! [`ButterworthDesign::denominator`] and [`ButterworthDesign::numerator`] give the direct-form
//! polynomials to print and compare (python-control, the seed's digits).

use super::AccDecError;

pub const MAX_ORDER: u32 = 6;
pub(super) const MAX_PAIRS: usize = (MAX_ORDER as usize) / 2;

/// The smallest cut-off (Hz) the filter takes, and the smallest cut-off × sample period: below
/// either, the poles come so close to `z = 1` that the drive's integer states can no longer
/// keep the commanded position within a count of the designed filter (see
/// [`super::ButterworthPulseFilter`]). `servo bench accdec` checks the corner (0.5 Hz at
/// 0.125 ms).
pub const MIN_CUTOFF_HZ: f32 = crate::ranges::MIN_ACC_DEC_CUTOFF_HZ;
pub const MIN_CUTOFF_TIMES_PERIOD: f32 = crate::ranges::MIN_ACC_DEC_CUTOFF_TIMES_PERIOD;

/// A pair of complex poles `z = r·e^{±jφ}`: the factor `1 + a1·z⁻¹ + a2·z⁻²` of `A(z)`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolePair {
    /// `r = e^{σT}` and `φ = ω_d·T` of the pole `e^{(σ + jω_d)·T}`.
    pub radius: f64,
    pub angle: f64,
    /// `a1 = −2r·cos φ`, `a2 = r²`.
    pub a1: f64,
    pub a2: f64,
    /// `1 + a1 + a2 = |1 − z|²`, without cancellation: the section's DC value.
    pub dc: f64,
    /// `1 − a2 = 1 − r²`, without cancellation.
    pub one_minus_a2: f64,
}

/// The real pole `p = e^{−ωc·T}` of an odd order: the factor `1 − p·z⁻¹`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RealPole {
    pub pole: f64,
    /// `1 − p`, without cancellation.
    pub one_minus_pole: f64,
}

/// Where the `N` zeros at infinity of the analogue Butterworth go in `z`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum ZeroPlacement {
    /// `N − 1` at `z = −1`, one kept as a one-sample delay (seed 003's worked example).
    #[default]
    Seed,
    /// All `N` kept as delays (python-control's `matched`).
    AllDelays,
}

/// A designed filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ButterworthDesign {
    pub order: u32,
    pub zeros: ZeroPlacement,
    pub cutoff_hz: f32,
    pub sample_period: f32,
    /// Overall gain `K` of `G(z) = K·z⁻¹·(1 + z⁻¹)^{N−1} / A(z)` (or `K·z⁻ᴺ / A(z)`).
    pub gain: f64,
    pairs: [PolePair; MAX_PAIRS],
    pair_count: usize,
    real_pole: Option<RealPole>,
}

impl ButterworthDesign {
    /// The seed's design: [`ZeroPlacement::Seed`].
    pub fn new(order: u32, cutoff_hz: f32, sample_period: f32) -> Result<Self, AccDecError> {
        Self::with_zeros(order, cutoff_hz, sample_period, ZeroPlacement::Seed)
    }

    pub fn with_zeros(
        order: u32,
        cutoff_hz: f32,
        sample_period: f32,
        zeros: ZeroPlacement,
    ) -> Result<Self, AccDecError> {
        if !(1..=MAX_ORDER).contains(&order) {
            return Err(AccDecError::Order(order));
        }
        if !(sample_period.is_finite() && sample_period > 0.0) {
            return Err(AccDecError::SamplePeriod(sample_period));
        }
        if !(cutoff_hz.is_finite() && cutoff_hz > 0.0) {
            return Err(AccDecError::Cutoff(cutoff_hz));
        }
        // Above Nyquist the pole angles ωc·T·sin θ can pass π and alias. Exactly at Nyquist
        // the mapping is still exact, and the seed's own worked example (1 kHz at 0.5 ms)
        // sits there, so it is allowed; the tolerance only absorbs f32 rounding of T.
        let nyquist_hz = 0.5 / sample_period;
        if 2.0 * cutoff_hz * sample_period > 1.0 + 1e-6 {
            return Err(AccDecError::CutoffAboveNyquist { cutoff_hz, nyquist_hz });
        }
        let minimum_hz = MIN_CUTOFF_HZ.max(MIN_CUTOFF_TIMES_PERIOD / sample_period);
        if cutoff_hz < minimum_hz {
            return Err(AccDecError::CutoffBelowMinimum { cutoff_hz, minimum_hz });
        }
        let wc_t = core::f64::consts::TAU * cutoff_hz as f64 * sample_period as f64;
        let n = order as usize;
        let unit = PolePair { radius: 0.0, angle: 0.0, a1: 0.0, a2: 0.0, dc: 1.0, one_minus_a2: 1.0 };
        let mut pairs = [unit; MAX_PAIRS];
        // Poles in the left half plane at angles θ = π(2k + N + 1)/(2N), k = 0..N/2 (the upper
        // half's conjugates pair with them): σT = ωc·T·cos θ < 0, ω_d·T = ωc·T·sin θ.
        for (k, pair) in pairs.iter_mut().enumerate().take(n / 2) {
            let theta = core::f64::consts::PI * (2 * k + n + 1) as f64 / (2 * n) as f64;
            let sigma_t = wc_t * libm::cos(theta);
            let angle = wc_t * libm::sin(theta);
            let radius = libm::exp(sigma_t);
            let one_minus_r = -libm::expm1(sigma_t);
            let half_angle_sine = libm::sin(0.5 * angle);
            *pair = PolePair {
                radius,
                angle,
                a1: -2.0 * radius * libm::cos(angle),
                a2: radius * radius,
                dc: one_minus_r * one_minus_r + 4.0 * radius * half_angle_sine * half_angle_sine,
                one_minus_a2: one_minus_r * (1.0 + radius),
            };
        }
        let real_pole = (n % 2 == 1).then(|| RealPole { pole: libm::exp(-wc_t), one_minus_pole: -libm::expm1(-wc_t) });
        // G(1) = 1: K·2^{N−1} = A(1) (seed), K = A(1) (all delays); A(1) is the product of the
        // sections' DC values.
        let a_at_1 = pairs[..n / 2].iter().map(|p| p.dc).product::<f64>() * real_pole.map_or(1.0, |r| r.one_minus_pole);
        let numerator_dc = match zeros {
            ZeroPlacement::Seed => (1u32 << (n - 1)) as f64,
            ZeroPlacement::AllDelays => 1.0,
        };
        Ok(Self {
            order,
            zeros,
            cutoff_hz,
            sample_period,
            gain: a_at_1 / numerator_dc,
            pairs,
            pair_count: n / 2,
            real_pole,
        })
    }

    /// `[1, a1, …, aN, 0, …]`: `A(z) = 1 + a1·z⁻¹ + … + aN·z⁻ᴺ` of the direct form.
    pub fn denominator(&self) -> [f64; MAX_ORDER as usize + 1] {
        let mut poly = [0.0f64; MAX_ORDER as usize + 1];
        poly[0] = 1.0;
        let mut degree = 0;
        let mut multiply = |factor: &[f64]| {
            let mut out = [0.0f64; MAX_ORDER as usize + 1];
            for (i, p) in poly.iter().enumerate().take(degree + 1) {
                for (j, f) in factor.iter().enumerate() {
                    out[i + j] += p * f;
                }
            }
            poly = out;
            degree += factor.len() - 1;
        };
        for p in self.pole_pairs() {
            multiply(&[1.0, p.a1, p.a2]);
        }
        if let Some(r) = &self.real_pole {
            multiply(&[1.0, -r.pole]);
        }
        poly
    }

    /// `[0, b1, …, bN, 0, …]`: `K·z⁻¹·(1 + z⁻¹)^{N−1}` (or `K·z⁻ᴺ`) of the direct form.
    pub fn numerator(&self) -> [f64; MAX_ORDER as usize + 1] {
        let mut poly = [0.0f64; MAX_ORDER as usize + 1];
        if self.zeros == ZeroPlacement::AllDelays {
            poly[self.order as usize] = self.gain;
            return poly;
        }
        // Binomial coefficients of (1 + z⁻¹)^{N−1}, shifted by the delay.
        let mut c = 1.0f64;
        let m = self.order - 1;
        for i in 0..=m {
            poly[i as usize + 1] = self.gain * c;
            c = c * (m - i) as f64 / (i + 1) as f64;
        }
        poly
    }

    /// The complex pole pairs, in cascade order.
    pub fn pole_pairs(&self) -> &[PolePair] {
        &self.pairs[..self.pair_count]
    }

    /// The real pole of an odd order.
    pub fn real_pole(&self) -> Option<&RealPole> {
        self.real_pole.as_ref()
    }

    /// Every pole `(re, im)` in `z`.
    pub fn poles(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        self.pole_pairs()
            .iter()
            .flat_map(|p| {
                let (re, im) = (p.radius * libm::cos(p.angle), p.radius * libm::sin(p.angle));
                [(re, im), (re, -im)]
            })
            .chain(self.real_pole.map(|r| (r.pole, 0.0)))
    }
}
