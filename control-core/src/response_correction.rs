//! Response-correction filter (seed 001) in front of the position loop: every axis's command
//! is multiplied by the OTHER axes' dynamics so that all axes' command → machine-end transfer
//! functions become the same product and contours are not distorted. The seed multiplies the
//! others' anti-resonance numerators over a common low-pass, `G_rc,x(s) = F(s)·N_y(s)·N_z(s)…`;
//! `servo tune` by default multiplies the others' whole measured command → machine-end
//! models. Both are cascades of second-order factors, which is all this filter knows.
//!
//! The filter is a cascade of up to [`MAX_SECTIONS`] second-order sections, each
//! `N(s)/F_i(s)` with `N(s) = s²/ωz² + 2ζz·s/ωz + 1` (or 1) and
//! `F_i(s) = s²/ωf² + 2ζf·s/ωf + 1`, discretised by the bilinear transform at the
//! position-loop period with unit DC gain (a section without zeros gets its two zeros at
//! z = −1). It runs on the command's pulses per position tick with whole-pulse
//! output (the rounded pending output stays inside), so the corrected command ends exactly
//! where the uncorrected one does. Coefficients can be loaded while running, but only when the
//! filter is at rest: loading mid-motion would lose or invent command pulses.

use core::fmt;

use crate::biquad::Biquad;
use crate::TAU;

/// Enough for three axes whose measured models have three sections each, or five axes with
/// two (the other axes' sections are multiplied in).
pub const MAX_SECTIONS: usize = 8;

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
    Frequency {
        section: usize,
        hz: f32,
    },
    /// A damping not finite or ≤ 0 for poles (< 0 for zeros).
    Damping {
        section: usize,
        damping: f32,
    },
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
                write!(
                    f,
                    "correction section {section}: damping {damping} must be finite (> 0 for poles, >= 0 for zeros)"
                )
            }
            Self::InMotion => write!(f, "correction coefficients can only be loaded while no command is in motion"),
        }
    }
}

/// `1 + c1·z⁻¹ + c2·z⁻²` ∝ `(1 + z⁻¹)²·(s²/ω² + 2ζs/ω + 1)` with the bilinear substitution
/// `s = (2/T)·(1 − z⁻¹)/(1 + z⁻¹)`. Both factors of a section carry the same `(1 + z⁻¹)²`, so
/// it cancels in a section with zeros and puts a section's missing zeros at z = −1.
///
/// Bilinear, not pole-zero matching: the correction must reproduce a measured continuous
/// model inside the position-loop band, where the bilinear map's error is of order
/// (ωT)²·(ω/ω_section) and matching leaves a phase error a hundred times larger (0.04° against
/// 0.001° at 20 Hz for a 33 Hz, ζ 0.1 pole pair at 4 kHz), which is what sets the residual
/// difference between corrected axes.
fn bilinear(f: SecondOrder, period: f32) -> (f32, f32) {
    let k = 2.0 / (TAU * f.hz * period);
    let (kk, dk) = (k * k, 2.0 * f.damping * k);
    let c0 = kk + dk + 1.0;
    ((2.0 - 2.0 * kk) / c0, (kk - dk + 1.0) / c0)
}

impl CorrectionParams {
    pub fn validate(&self, period: f32) -> Result<(), CorrectionError> {
        if self.count > MAX_SECTIONS {
            return Err(CorrectionError::Count(self.count));
        }
        let nyquist = 0.5 / period;
        let frequency = |section, f: SecondOrder| {
            if f.hz.is_finite() && f.hz > 0.0 && f.hz < nyquist {
                Ok(())
            } else {
                Err(CorrectionError::Frequency { section, hz: f.hz })
            }
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
            let (a1, a2) = bilinear(s.poles, period);
            let (b0, b1, b2) = match s.zeros {
                Some(z) => {
                    let (c1, c2) = bilinear(z, period);
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

/// The bits of the largest state magnitude a filter at rest may hold (below it).
const REST_BITS: u32 = 1e-3f32.to_bits();

/// `x.abs() < 1e-3` compared on the bits, as integers: for a non-negative threshold the order
/// of magnitudes is the order of their bits, and NaN's bits (exponent all ones, fraction not
/// zero) lie above every finite one, so the answer is the same for every `x` (NaN, ±0, ±∞
/// included); without two floating-point compares and their status transfers, which is what
/// the drive's check with interrupts off spent most of its time on.
#[inline(always)]
fn within_rest(x: f32) -> bool {
    (x.to_bits() & 0x7FFF_FFFF) < REST_BITS
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

    /// No pulse inside and the state at rest (within a thousandth of a pulse: `|s| < 1e-3`
    /// for both states of every section in use; a NaN state is not at rest).
    pub fn at_rest(&self) -> bool {
        self.stock == 0
            && self.sections[..self.count].iter().all(|b| {
                let (s1, s2) = b.state();
                within_rest(s1) && within_rest(s2)
            })
    }

    /// Take the sections of `built` (made by [`ResponseCorrection::new`]): only at rest;
    /// refused otherwise, nothing changed. Section by section, only those in use: the drive
    /// does this with interrupts off, where a whole-struct `memcpy` cost about 400
    /// instructions on the Cortex-M4. Never inlined: inlined into the drive's section, the
    /// filter sat some 13 KB into the axis, and every store of a field computed its address
    /// anew (three instructions a field: 375 instructions for eight sections against 256).
    #[inline(never)]
    pub fn install(&mut self, built: &Self) -> Result<(), CorrectionError> {
        if !self.at_rest() {
            return Err(CorrectionError::InMotion);
        }
        for (d, s) in self.sections.iter_mut().zip(&built.sections[..built.count]) {
            d.copy_from(s);
        }
        self.count = built.count;
        self.stock = 0;
        Ok(())
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
        let mut v = crate::counts_to_f32(pulses);
        let mut pending = 0.0;
        for b in &mut self.sections[..self.count] {
            v = b.process(v);
            pending += b.pending_output();
        }
        crate::release_whole_pulses(&mut self.stock, pulses, crate::round_to_counts(pending))
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

    /// The discrete section against the continuous `N(jω)/F(jω)` evaluated directly, inside
    /// the position-loop band, for a lightly damped pole pair (the hard case).
    #[test]
    fn a_section_reproduces_its_continuous_response_in_band() {
        let (zeros, poles) = (SecondOrder { hz: 40.0, damping: 0.05 }, SecondOrder { hz: 33.0, damping: 0.1 });
        let p = params(&[CorrectionSection { zeros: Some(zeros), poles }]);
        let (s, _) = p.design(T).unwrap();
        let b = s[0];
        for f in [1.0f64, 5.0, 10.0, 20.0] {
            let w = 2.0 * core::f64::consts::PI * f * T as f64;
            let (c1, s1, c2, s2) = (libm::cos(w), -libm::sin(w), libm::cos(2.0 * w), -libm::sin(2.0 * w));
            let (nr, ni) = (b.b0 as f64 + b.b1 as f64 * c1 + b.b2 as f64 * c2, b.b1 as f64 * s1 + b.b2 as f64 * s2);
            let (dr, di) = (1.0 + b.a1 as f64 * c1 + b.a2 as f64 * c2, b.a1 as f64 * s1 + b.a2 as f64 * s2);
            let factor = |q: SecondOrder| {
                let x = f / q.hz as f64;
                (1.0 - x * x, 2.0 * q.damping as f64 * x)
            };
            let ((zr, zi), (pr, pi)) = (factor(zeros), factor(poles));
            let discrete = (libm::hypot(nr, ni) / libm::hypot(dr, di), libm::atan2(ni, nr) - libm::atan2(di, dr));
            let continuous = (libm::hypot(zr, zi) / libm::hypot(pr, pi), libm::atan2(zi, zr) - libm::atan2(pi, pr));
            let db = 20.0 * libm::log10(discrete.0 / continuous.0);
            let deg = (discrete.1 - continuous.1).to_degrees();
            assert!(db.abs() < 2e-3 && deg.abs() < 5e-3, "{f} Hz: {db} dB, {deg}°");
        }
    }

    #[test]
    fn whole_pulses_in_and_out_and_loading_only_at_rest() {
        let p = params(&[
            CorrectionSection {
                zeros: Some(SecondOrder { hz: 55.0, damping: 0.05 }),
                poles: SecondOrder { hz: 80.0, damping: 1.0 },
            },
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

    /// `install` (what the drive does with interrupts off) as `load`: refused with the
    /// filter untouched while pulses are inside; at rest, the filter `new` designs, whatever
    /// the number of sections before and after.
    #[test]
    fn installing_a_built_correction_only_at_rest_and_as_designed() {
        let section = |hz| CorrectionSection {
            zeros: Some(SecondOrder { hz, damping: 0.05 }),
            poles: SecondOrder { hz: 1.5 * hz, damping: 1.0 },
        };
        let eight = params(&[30.0, 40.0, 50.0, 60.0, 70.0, 80.0, 90.0, 100.0].map(section));
        let two = params(&[45.0, 65.0].map(section));
        let mut f = ResponseCorrection::new(&eight, T).unwrap();
        let built = ResponseCorrection::new(&two, T).unwrap();
        let mut sum_out = 0;
        for _ in 0..50 {
            sum_out += f.step(300);
        }
        let in_motion = f;
        assert_eq!(f.install(&built), Err(CorrectionError::InMotion));
        assert_eq!(f, in_motion, "a refused install changes nothing");
        // Pulses still inside after the input stops: refused until the last has come out.
        let mut refusals = 0;
        while f.install(&built).is_err() {
            refusals += 1;
            sum_out += f.step(0);
            assert!(refusals < 100_000);
        }
        assert!(refusals > 10);
        assert_eq!(sum_out, 50 * 300, "installed only once every pulse was out");
        // Now the two-section filter: the same outputs as a fresh one.
        let mut fresh = built;
        for k in 0..400 {
            let x = if k < 100 { 77 } else { 0 };
            assert_eq!(f.step(x), fresh.step(x), "tick {k}");
        }
        // And back to eight sections from two.
        let mut g = built;
        assert_eq!(g.install(&ResponseCorrection::new(&eight, T).unwrap()), Ok(()));
        let mut fresh = ResponseCorrection::new(&eight, T).unwrap();
        for k in 0..400 {
            let x = if k < 100 { -55 } else { 0 };
            assert_eq!(g.step(x), fresh.step(x), "tick {k}");
        }
    }

    /// The rest check on the bits against the floating-point comparison it replaces: every
    /// special value, the bits around the threshold, and a spread over all 2³² patterns.
    #[test]
    fn the_rest_check_on_the_bits_is_the_magnitude_comparison() {
        let threshold = 1e-3f32.to_bits();
        let specials =
            [0.0, -0.0, 1e-3, -1e-3, f32::INFINITY, f32::NEG_INFINITY, f32::NAN, -f32::NAN, f32::MIN_POSITIVE];
        let near = (threshold - 4..threshold + 4).flat_map(|b| [b, b | 0x8000_0000]);
        let spread = (0..=u32::MAX / 65_521).map(|k| k * 65_521);
        let nans = [0x7F80_0001u32, 0xFFC0_0000, 0x7FFF_FFFF, 0xFF80_0001];
        let bits = specials.iter().map(|x: &f32| x.to_bits()).chain(near).chain(spread).chain(nans);
        let mut checked = 0;
        for b in bits {
            let x = f32::from_bits(b);
            assert_eq!(within_rest(x), x.abs() < 1e-3, "{x:e} ({b:#010x})");
            checked += 1;
        }
        assert!(checked > 65_000);
    }

    #[test]
    fn bad_sections_are_named() {
        let bad = |s: CorrectionSection| params(&[s]).validate(T);
        let ok = CorrectionSection { zeros: None, poles: SecondOrder { hz: 50.0, damping: 1.0 } };
        assert_eq!(bad(ok), Ok(()));
        assert!(matches!(
            bad(CorrectionSection { poles: SecondOrder { hz: 2500.0, damping: 1.0 }, ..ok }),
            Err(CorrectionError::Frequency { .. })
        ));
        assert!(matches!(
            bad(CorrectionSection { poles: SecondOrder { hz: 50.0, damping: 0.0 }, ..ok }),
            Err(CorrectionError::Damping { .. })
        ));
        assert!(matches!(
            bad(CorrectionSection { zeros: Some(SecondOrder { hz: f32::NAN, damping: 0.1 }), ..ok }),
            Err(CorrectionError::Frequency { .. })
        ));
        assert_eq!(CorrectionParams { count: 9, ..Default::default() }.validate(T), Err(CorrectionError::Count(9)));
    }
}
