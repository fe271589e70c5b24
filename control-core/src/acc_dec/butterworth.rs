//! Butterworth low-pass acc/dec filter discretised by pole-zero matching (seed 003).
//!
//! Design: the `N` analogue poles `p = ωc·e^{jθ}` map to `z = e^{p·T}`; the gain makes
//! `G(1) = 1`. The `N` zeros at infinity are placed by [`ZeroPlacement`]: the seed maps
//! `N − 1` of them to `z = −1` and keeps one as a one-sample delay
//! (`K·z⁻¹(1 + z⁻¹)^{N−1}/A(z)`: the output reacts one tick after the input and the Nyquist
//! frequency is nulled), python-control's `sample_system(method='matched')` keeps every one as
//! a delay (`K·z⁻ᴺ/A(z)`: same poles, `N` ticks of dead time, no null at Nyquist).
//!
//! Realisation: cascaded second-order sections (one first-order section for odd orders) in
//! transposed direct form II. A direct form with one delay line, as the seed draws it,
//! has the same transfer function but in f32 its pole positions are far more sensitive to
//! coefficient rounding when the cut-off is low against the sample rate (poles near z = 1);
//! [`ButterworthDesign::denominator`] still gives the direct-form coefficients to print and
//! compare.
//!
//! Whole pulses: each tick the filter's *pending output* (what it would still emit if the
//! input stopped now: a linear function of its state) is rounded, and the output is what
//! makes the integer stock of pulses inside the filter equal to it. The rounding error is
//! carried to the next tick (the seed's claim 10) and the sum of the output equals the sum of
//! the input exactly once the filter has settled, whatever the floating-point error.

use super::AccDecError;
use crate::biquad::Biquad;

pub const MAX_ORDER: u32 = 6;
const MAX_BIQUADS: usize = (MAX_ORDER as usize) / 2;

/// `y(k) = b1·u(k−1) − a1·y(k−1)`: a real pole with the kept one-sample delay.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirstOrderSection {
    pub b1: f32,
    pub a1: f32,
    s: f32,
}

impl FirstOrderSection {
    fn process(&mut self, u: f32) -> f32 {
        let y = self.s;
        self.s = self.b1 * u - self.a1 * y;
        y
    }

    /// Sum of every future output if the input stopped now: `Y = s − a1·Y`.
    fn pending(&self) -> f32 {
        self.s / (1.0 + self.a1)
    }
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

/// A designed filter: sections, and the direct-form polynomials for reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ButterworthDesign {
    pub order: u32,
    pub zeros: ZeroPlacement,
    pub cutoff_hz: f32,
    pub sample_period: f32,
    /// Overall gain `K` of `G(z) = K·z⁻¹·(1 + z⁻¹)^{N−1} / A(z)` (or `K·z⁻ᴺ / A(z)`).
    pub gain: f32,
    biquads: [Biquad; MAX_BIQUADS],
    biquad_count: usize,
    first_order: Option<FirstOrderSection>,
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
        let wc_t = crate::TAU * cutoff_hz * sample_period;
        let n = order as usize;
        let mut biquads = [Biquad::identity(); MAX_BIQUADS];
        // Poles in the left half plane at angles π(2k + N + 1)/(2N), k = 0..N/2 (the upper
        // half's conjugates pair with them).
        for (k, section) in biquads.iter_mut().enumerate().take(n / 2) {
            let theta = core::f32::consts::PI * (2 * k + n + 1) as f32 / (2 * n) as f32;
            let radius = libm::expf(wc_t * libm::cosf(theta));
            let a1 = -2.0 * radius * libm::cosf(wc_t * libm::sinf(theta));
            let a2 = radius * radius;
            let dc = 1.0 + a1 + a2;
            // (1 + z⁻¹)² has DC value 4; the section carrying the delay of an even order
            // has z⁻¹(1 + z⁻¹) with DC value 2; z⁻² has DC value 1.
            *section = if zeros == ZeroPlacement::AllDelays {
                Biquad::new(0.0, 0.0, dc, a1, a2)
            } else if n.is_multiple_of(2) && k == 0 {
                Biquad::new(0.0, dc / 2.0, dc / 2.0, a1, a2)
            } else {
                Biquad::new(dc / 4.0, dc / 2.0, dc / 4.0, a1, a2)
            };
        }
        let first_order = (n % 2 == 1).then(|| {
            let a1 = -libm::expf(-wc_t);
            FirstOrderSection { b1: 1.0 + a1, a1, s: 0.0 }
        });
        let mut design =
            Self { order, zeros, cutoff_hz, sample_period, gain: 0.0, biquads, biquad_count: n / 2, first_order };
        // G(1) = 1: K·2^{N−1} = A(1) (seed), K = A(1) (all delays). A(1) is the product of
        // the sections' DC values, each `1 + a1 + a2` (or `1 + a1`): with poles near z = 1
        // these sums are exact in f32 (Sterbenz), whereas summing the expanded direct-form
        // coefficients would cancel catastrophically at high orders and low cut-offs.
        let a_at_1 = design.biquads().iter().map(|b| 1.0 + b.a1 + b.a2).product::<f32>()
            * design.first_order.map_or(1.0, |f| 1.0 + f.a1);
        let numerator_dc = match zeros {
            ZeroPlacement::Seed => (1u32 << (n - 1)) as f32,
            ZeroPlacement::AllDelays => 1.0,
        };
        design.gain = a_at_1 / numerator_dc;
        Ok(design)
    }

    /// `[1, a1, …, aN, 0, …]`: `A(z) = 1 + a1·z⁻¹ + … + aN·z⁻ᴺ` of the direct form.
    pub fn denominator(&self) -> [f32; MAX_ORDER as usize + 1] {
        let mut poly = [0.0f32; MAX_ORDER as usize + 1];
        poly[0] = 1.0;
        let mut degree = 0;
        let mut multiply = |factor: &[f32]| {
            let mut out = [0.0f32; MAX_ORDER as usize + 1];
            for (i, p) in poly.iter().enumerate().take(degree + 1) {
                for (j, f) in factor.iter().enumerate() {
                    out[i + j] += p * f;
                }
            }
            poly = out;
            degree += factor.len() - 1;
        };
        for b in &self.biquads[..self.biquad_count] {
            multiply(&[1.0, b.a1, b.a2]);
        }
        if let Some(f) = &self.first_order {
            multiply(&[1.0, f.a1]);
        }
        poly
    }

    /// `[0, b1, …, bN, 0, …]`: `K·z⁻¹·(1 + z⁻¹)^{N−1}` (or `K·z⁻ᴺ`) of the direct form.
    pub fn numerator(&self) -> [f32; MAX_ORDER as usize + 1] {
        let mut poly = [0.0f32; MAX_ORDER as usize + 1];
        if self.zeros == ZeroPlacement::AllDelays {
            poly[self.order as usize] = self.gain;
            return poly;
        }
        // Binomial coefficients of (1 + z⁻¹)^{N−1}, shifted by the delay.
        let mut c = 1.0f32;
        let m = self.order - 1;
        for i in 0..=m {
            poly[i as usize + 1] = self.gain * c;
            c = c * (m - i) as f32 / (i + 1) as f32;
        }
        poly
    }

    /// Second-order sections in cascade order.
    pub fn biquads(&self) -> &[Biquad] {
        &self.biquads[..self.biquad_count]
    }

    pub fn first_order(&self) -> Option<&FirstOrderSection> {
        self.first_order.as_ref()
    }
}

/// The designed filter running on pulses per tick, with whole-pulse output.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ButterworthPulseFilter {
    design: ButterworthDesign,
    /// Pulses taken in and not yet given out (exact).
    stock: i64,
}

impl ButterworthPulseFilter {
    pub fn new(design: ButterworthDesign) -> Self {
        Self { design, stock: 0 }
    }

    pub fn design(&self) -> &ButterworthDesign {
        &self.design
    }

    /// Pulses inside the filter (taken in, not yet given out).
    pub fn stock(&self) -> i64 {
        self.stock
    }

    /// Empty the filter: zero state, no pulse inside.
    pub fn reset(&mut self) {
        for b in &mut self.design.biquads {
            b.reset();
        }
        if let Some(f) = &mut self.design.first_order {
            f.s = 0.0;
        }
        self.stock = 0;
    }

    /// One tick: `pulses` in, whole pulses out.
    pub fn step(&mut self, pulses: i64) -> i64 {
        let d = &mut self.design;
        let mut v = crate::counts_to_f32(pulses);
        let mut pending = 0.0;
        for b in &mut d.biquads[..d.biquad_count] {
            v = b.process(v);
            pending += b.pending_output();
        }
        if let Some(f) = &mut d.first_order {
            f.process(v);
            pending += f.pending();
        }
        crate::release_whole_pulses(&mut self.stock, pulses, pending)
    }
}
