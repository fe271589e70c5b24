//! Response-correction filter (seed 001) in front of the position loop: every axis's command
//! is multiplied by the OTHER axes' anti-resonance numerators and a common low-pass,
//! `G_rc,x(s) = F(s)·N_y(s)·N_z(s)…`, so that all axes' command → machine-end transfer
//! functions share every numerator and contours are not distorted.
//!
//! The filter is a cascade of up to [`MAX_SECTIONS`] second-order sections, each
//! `N(s)/F_i(s)` with `N(s) = s²/ωz² + 2ζz·s/ωz + 1` (or 1) and
//! `F_i(s) = s²/ωf² + 2ζf·s/ωf + 1`, discretised by pole-zero matching at the position-loop
//! period with unit DC gain (a section without zeros puts its two zeros at z = −1, as the
//! seed-003 filter does). It runs on the command's pulses per position tick with whole-pulse
//! output (the rounded pending output stays inside), so the corrected command ends exactly
//! where the uncorrected one does. Coefficients can be loaded while running, but only when the
//! filter is at rest: loading mid-motion would lose or invent command pulses.

use core::fmt;

use crate::biquad::Biquad;
use crate::TAU;

pub const MAX_SECTIONS: usize = 4;

/// A second-order factor `s²/ω² + 2ζ·s/ω + 1` (frequency in Hz).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SecondOrder {
    pub hz: f32,
    pub damping: f32,
}

/// One section: optional zeros (an anti-resonance numerator), poles (a low-pass factor).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CorrectionSection {
    pub zeros: Option<SecondOrder>,
    pub poles: SecondOrder,
}

impl Default for CorrectionSection {
    /// No zeros; a critically damped 100 Hz pole pair (unused until counted in).
    fn default() -> Self {
        Self { zeros: None, poles: SecondOrder { hz: 100.0, damping: 1.0 } }
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CorrectionParams {
    pub sections: [CorrectionSection; MAX_SECTIONS],
    /// Sections in use (0: no correction).
    pub count: usize,
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CorrectionError {
    Count(usize),
    /// A frequency not positive and finite, or at/above the Nyquist frequency.
    Frequency { section: usize, hz: f32 },
    /// A damping not finite or ≤ 0 for poles (< 0 for zeros).
    Damping { section: usize, damping: f32 },
    /// New coefficients while command pulses are still inside the filter.
    InMotion,
}

impl fmt::Display for CorrectionError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Count(n) => write!(f, "{n} correction sections: use 0..={MAX_SECTIONS}"),
            Self::Frequency { section, hz } => {
                write!(f, "correction section {section}: {hz} Hz must be positive and below the position loop's Nyquist frequency")
            }
            Self::Damping { section, damping } => {
                write!(f, "correction section {section}: damping {damping} must be finite (> 0 for poles, >= 0 for zeros)")
            }
            Self::InMotion => write!(f, "correction coefficients can only be loaded while no command is in motion"),
        }
    }
}

/// `1 + a1·z⁻¹ + a2·z⁻²` with roots `e^{sT}` of `s²/ω² + 2ζs/ω + 1`.
fn matched(f: SecondOrder, period: f32) -> (f32, f32) {
    let w = TAU * f.hz;
    let z = f.damping;
    if z < 1.0 {
        let r = libm::expf(-z * w * period);
        let wd = w * libm::sqrtf(1.0 - z * z);
        (-2.0 * r * libm::cosf(wd * period), r * r)
    } else {
        // Two real roots −ω(ζ ± √(ζ² − 1)).
        let d = libm::sqrtf(z * z - 1.0);
        let (p1, p2) = (libm::expf(-w * (z - d) * period), libm::expf(-w * (z + d) * period));
        (-(p1 + p2), p1 * p2)
    }
}

impl CorrectionParams {
    pub fn validate(&self, period: f32) -> Result<(), CorrectionError> {
        if self.count > MAX_SECTIONS {
            return Err(CorrectionError::Count(self.count));
        }
        let nyquist = 0.5 / period;
        let frequency = |section, f: SecondOrder| {
            if f.hz.is_finite() && f.hz > 0.0 && f.hz < nyquist { Ok(()) } else { Err(CorrectionError::Frequency { section, hz: f.hz }) }
        };
        for (i, s) in self.sections[..self.count].iter().enumerate() {
            frequency(i + 1, s.poles)?;
            if !(s.poles.damping.is_finite() && s.poles.damping > 0.0) {
                return Err(CorrectionError::Damping { section: i + 1, damping: s.poles.damping });
            }
            if let Some(zeros) = s.zeros {
                frequency(i + 1, zeros)?;
                if !(zeros.damping.is_finite() && zeros.damping >= 0.0) {
                    return Err(CorrectionError::Damping { section: i + 1, damping: zeros.damping });
                }
            }
        }
        Ok(())
    }

    /// The discrete sections (validated first).
    pub fn design(&self, period: f32) -> Result<([Biquad; MAX_SECTIONS], usize), CorrectionError> {
        self.validate(period)?;
        let mut out = [Biquad::identity(); MAX_SECTIONS];
        for (o, s) in out.iter_mut().zip(&self.sections[..self.count]) {
            let (a1, a2) = matched(s.poles, period);
            let (b0, b1, b2) = match s.zeros {
                Some(z) => {
                    let (c1, c2) = matched(z, period);
                    (1.0, c1, c2)
                }
                None => (1.0, 2.0, 1.0),
            };
            // Unit DC gain: B(1)·k = A(1).
            let k = (1.0 + a1 + a2) / (b0 + b1 + b2);
            *o = Biquad::new(b0 * k, b1 * k, b2 * k, a1, a2);
        }
        Ok((out, self.count))
    }
}

/// The running filter on pulses per position tick (default: no sections, pulses pass).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ResponseCorrection {
    sections: [Biquad; MAX_SECTIONS],
    count: usize,
    /// Pulses taken in and not yet given out.
    stock: i64,
}

impl ResponseCorrection {
    pub fn new(p: &CorrectionParams, period: f32) -> Result<Self, CorrectionError> {
        let (sections, count) = p.design(period)?;
        Ok(Self { sections, count, stock: 0 })
    }

    /// No pulse inside and the state at rest (within a thousandth of a pulse).
    pub fn at_rest(&self) -> bool {
        self.stock == 0 && self.sections[..self.count].iter().all(|b| {
            let (s1, s2) = b.state();
            s1.abs() < 1e-3 && s2.abs() < 1e-3
        })
    }

    /// New coefficients (from a tuning run): only at rest; refused otherwise, nothing changed.
    pub fn load(&mut self, p: &CorrectionParams, period: f32) -> Result<(), CorrectionError> {
        if !self.at_rest() {
            return Err(CorrectionError::InMotion);
        }
        *self = Self::new(p, period)?;
        Ok(())
    }

    pub fn reset(&mut self) {
        for b in &mut self.sections {
            b.reset();
        }
        self.stock = 0;
    }

    /// One position tick: pulses in, whole pulses out (the sum out equals the sum in).
    pub fn step(&mut self, pulses: i64) -> i64 {
        if self.count == 0 {
            return pulses;
        }
        let mut v = pulses as f32;
        let mut pending = 0.0;
        for b in &mut self.sections[..self.count] {
            v = b.process(v);
            let (s1, s2) = b.state();
            pending += (s1 + s2) / (1.0 + b.a1 + b.a2);
        }
        let keep = libm::roundf(pending) as i64;
        let out = self.stock + pulses - keep;
        self.stock = keep;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const T: f32 = 0.00025;

    fn params(sections: &[CorrectionSection]) -> CorrectionParams {
        let mut p = CorrectionParams { count: sections.len(), ..Default::default() };
        p.sections[..sections.len()].copy_from_slice(sections);
        p
    }

    /// Gain of the designed cascade at f (Hz), from its coefficients.
    fn gain(p: &CorrectionParams, f: f32) -> f32 {
        let (s, n) = p.design(T).unwrap();
        let w = TAU * f * T;
        let (c1, s1, c2, s2) = (libm::cosf(w), -libm::sinf(w), libm::cosf(2.0 * w), -libm::sinf(2.0 * w));
        s[..n].iter().fold(1.0, |g, b| {
            let num = libm::hypotf(b.b0 + b.b1 * c1 + b.b2 * c2, b.b1 * s1 + b.b2 * s2);
            let den = libm::hypotf(1.0 + b.a1 * c1 + b.a2 * c2, b.a1 * s1 + b.a2 * s2);
            g * num / den
        })
    }

    #[test]
    fn a_section_has_its_notch_at_the_anti_resonance_and_unit_dc_gain() {
        let p = params(&[CorrectionSection {
            zeros: Some(SecondOrder { hz: 40.0, damping: 0.02 }),
            poles: SecondOrder { hz: 100.0, damping: 1.0 },
        }]);
        assert!((gain(&p, 0.0) - 1.0).abs() < 1e-5);
        // |N(j2π·40)| = 2ζ = 0.04 against |F| = 1/(1 + 0.16) at 40 Hz: about 0.0464.
        let expect = 0.04 / (1.0 + (40.0f32 / 100.0).powi(2));
        assert!((gain(&p, 40.0) - expect).abs() < 0.01, "{}", gain(&p, 40.0));
        assert!(gain(&p, 40.0) < 0.1 * gain(&p, 10.0));
    }

    #[test]
    fn whole_pulses_in_and_out_and_loading_only_at_rest() {
        let p = params(&[
            CorrectionSection { zeros: Some(SecondOrder { hz: 55.0, damping: 0.05 }), poles: SecondOrder { hz: 80.0, damping: 1.0 } },
            CorrectionSection { zeros: None, poles: SecondOrder { hz: 80.0, damping: 1.0 } },
        ]);
        let mut f = ResponseCorrection::new(&p, T).unwrap();
        let (mut sum_in, mut sum_out) = (0i64, 0i64);
        for k in 0..400 {
            let x = if k < 200 { 1234 } else { 0 };
            sum_in += x;
            sum_out += f.step(x);
            if k == 100 {
                assert_eq!(f.load(&p, T), Err(CorrectionError::InMotion));
            }
        }
        for _ in 0..4000 {
            sum_out += f.step(0);
        }
        assert_eq!(sum_in, sum_out);
        assert!(f.at_rest());
        assert_eq!(f.load(&CorrectionParams::default(), T), Ok(()));
        assert_eq!(f.step(77), 77, "no sections: pulses pass");
    }

    #[test]
    fn bad_sections_are_named() {
        let bad = |s: CorrectionSection| params(&[s]).validate(T);
        let ok = CorrectionSection { zeros: None, poles: SecondOrder { hz: 50.0, damping: 1.0 } };
        assert_eq!(bad(ok), Ok(()));
        assert!(matches!(bad(CorrectionSection { poles: SecondOrder { hz: 2500.0, damping: 1.0 }, ..ok }), Err(CorrectionError::Frequency { .. })));
        assert!(matches!(bad(CorrectionSection { poles: SecondOrder { hz: 50.0, damping: 0.0 }, ..ok }), Err(CorrectionError::Damping { .. })));
        assert!(matches!(bad(CorrectionSection { zeros: Some(SecondOrder { hz: f32::NAN, damping: 0.1 }), ..ok }), Err(CorrectionError::Frequency { .. })));
        assert_eq!(CorrectionParams { count: 5, ..Default::default() }.validate(T), Err(CorrectionError::Count(5)));
    }
}
