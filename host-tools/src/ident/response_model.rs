//! Measured command → machine-end models of closed-loop axes, for the response correction
//! (seed 001 in its measured form).
//!
//! The seed multiplies every axis's command by the OTHER axes' anti-resonance numerators
//! N_j(s), which makes all axes' command → machine-end responses `F·ΠN/D(s)` alike on the
//! premise that every axis has the same closed-loop denominator D(s). On a drive whose loop
//! closes on the motor encoder that premise does not hold: the load's extra mode moves the
//! closed-loop poles, and the closed loop puts poles next to the anti-resonance zeros (the
//! motor feels the absorber too), so `ΠN_other` alone spreads the responses apart instead of
//! together (`servo bench ident` prints both).
//!
//! The measured form keeps the seed's structure and chooses its free low-pass F per axis: the
//! whole measured closed-loop response of every other axis, `M_j = N_j/D_j`, is multiplied
//! in, so every axis answers `ΠM_j` — identical whatever the denominators, with no inverse of
//! any axis's own dynamics (the seed's objection to 1/N) and only stable factors. The price is
//! the other axes' lag on every axis, alike for all.
//!
//! A model is a ratio of second-order factors with unit DC gain, fitted to the measured
//! response by Levy's linearised least squares with Sanathanan–Koerner reweighting and the
//! output error's minimisation from there ([`fit_rational`]); pairs of
//! real roots become factors with damping ≥ 1. The order is chosen from the candidates that
//! the correction filter can hold (stable poles, left-half-plane zeros, below the position
//! loop's Nyquist frequency) by the smallest worst-case error over the fit band.

use anyhow::{bail, Result};
use serde::{Deserialize, Serialize};

use crate::correction::Section;
use crate::ident::identification::{fit_rational, Factor, Measured};
use num_complex::Complex64;

/// Fitted command → machine-end model of one axis.
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct ResponseModel {
    pub axis: String,
    /// Numerator factors (each `s²/ω² + 2ζs/ω + 1`).
    pub zeros: Vec<Factor>,
    /// Denominator factors.
    pub poles: Vec<Factor>,
    /// Fit band (Hz).
    pub band: (f64, f64),
    /// Largest relative error |model − measured|/|measured| over the band.
    pub worst_error: f64,
}

impl ResponseModel {
    pub fn at(&self, f: f64) -> Complex64 {
        let one = Complex64::new(1.0, 0.0);
        let n = self.zeros.iter().fold(one, |acc, z| acc * z.at(f));
        let d = self.poles.iter().fold(one, |acc, p| acc * p.at(f));
        n / d
    }

    /// The model as correction sections: zeros paired with poles, the remaining poles alone.
    pub fn sections(&self) -> Vec<Section> {
        self.poles
            .iter()
            .enumerate()
            .map(|(i, p)| Section {
                zeros: self.zeros.get(i).map(|z| (z.hz, z.damping)),
                pole_hz: p.hz,
                pole_damping: p.damping,
            })
            .collect()
    }
}

/// Candidate (numerator, denominator) orders, simplest first.
const ORDERS: [(usize, usize); 5] = [(2, 2), (2, 4), (4, 4), (4, 6), (6, 6)];

/// Second-order factors of roots given as complex pairs and real roots (Hz, positive in the
/// left half plane), or why they cannot be a correction filter's.
fn as_factors(pairs: Vec<Factor>, mut real: Vec<f64>, what: &str, nyquist_hz: f64) -> Result<Vec<Factor>, String> {
    if let Some(r) = real.iter().find(|&&r| r <= 0.0) {
        return Err(format!("a real {what} in the right half plane ({:.1} Hz)", -r));
    }
    if real.len() % 2 == 1 {
        return Err(format!("an odd number of real {what}s"));
    }
    real.sort_by(f64::total_cmp);
    let mut out = pairs;
    for p in real.chunks(2) {
        let (a, b) = (p[0], p[1]);
        let hz = (a * b).sqrt();
        out.push(Factor { hz, damping: (a + b) / (2.0 * hz) });
    }
    if let Some(f) = out.iter().find(|f| !(f.damping.is_finite() && f.damping > 0.0)) {
        return Err(format!("{what}s at {:.1} Hz with damping {:.3} (not in the left half plane)", f.hz, f.damping));
    }
    if let Some(f) = out.iter().find(|f| !(f.hz.is_finite() && f.hz < nyquist_hz)) {
        return Err(format!("{what}s at {:.1} Hz, at or above the position loop's Nyquist frequency", f.hz));
    }
    out.sort_by(|a, b| a.hz.total_cmp(&b.hz));
    Ok(out)
}

/// Fit the model of `axis` from measured `(frequency, response)` points over `band`, with at
/// most `max_sections` second-order sections.
pub fn fit(
    axis: &str,
    points: &[(f64, Complex64)],
    band: (f64, f64),
    max_sections: usize,
    nyquist_hz: f64,
) -> Result<ResponseModel> {
    let measured = Measured {
        frequencies: points.iter().map(|p| p.0).collect(),
        response: points.iter().map(|p| p.1).collect(),
        input_power: vec![1.0; points.len()],
        standard_error: vec![0.0; points.len()],
    };
    if let Some((f, _)) =
        points.iter().find(|(f, h)| !(f.is_finite() && h.re.is_finite() && h.im.is_finite() && h.norm() > 0.0))
    {
        bail!("axis {axis}: the measured response at {f} Hz is not a finite, non-zero number: the axis did not follow its command");
    }
    let in_band: Vec<&(f64, Complex64)> = points.iter().filter(|(f, _)| *f >= band.0 && *f <= band.1).collect();
    let mut best: Option<ResponseModel> = None;
    let mut refused = Vec::new();
    for (nb, na) in ORDERS {
        if na / 2 > max_sections {
            continue;
        }
        let Ok(fit) = fit_rational(&measured, band, nb, na) else { continue };
        let (zp, zr) = fit.zeros();
        let (pp, pr) = fit.poles();
        let factors =
            as_factors(zp, zr, "zero", nyquist_hz).and_then(|z| as_factors(pp, pr, "pole", nyquist_hz).map(|p| (z, p)));
        let (zeros, poles) = match factors {
            Ok(f) => f,
            Err(why) => {
                refused.push(format!("order {nb}/{na}: {why}"));
                continue;
            }
        };
        let mut model = ResponseModel { axis: axis.into(), zeros, poles, band, worst_error: 0.0 };
        model.worst_error = in_band.iter().map(|(f, h)| (model.at(*f) - *h).norm() / h.norm()).fold(0.0, f64::max);
        if best.as_ref().is_none_or(|b| model.worst_error < b.worst_error) {
            best = Some(model);
        }
    }
    best.ok_or_else(|| {
        anyhow::anyhow!(
            "axis {axis}: no model of the command → machine-end response fits a correction filter of {max_sections} sections ({})",
            if refused.is_empty() { "too few measured frequencies".to_string() } else { refused.join("; ") }
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A known model is found again from its own exact response (an independent
    /// evaluation of the factors, not the fit's polynomials).
    #[test]
    fn a_fourth_order_model_is_recovered_from_its_response() {
        let truth = ResponseModel {
            axis: "x".into(),
            zeros: vec![Factor { hz: 18.0, damping: 0.9 }, Factor { hz: 60.0, damping: 0.2 }],
            poles: vec![Factor { hz: 25.0, damping: 0.6 }, Factor { hz: 45.0, damping: 0.15 }],
            band: (1.0, 40.0),
            worst_error: 0.0,
        };
        let points: Vec<(f64, Complex64)> = (1..=40).map(|f| (f as f64, truth.at(f as f64))).collect();
        let m = fit("x", &points, (1.0, 40.0), 2, 2000.0).expect("fits");
        assert!(m.worst_error < 1e-6, "worst error {}", m.worst_error);
        for (a, b) in m.poles.iter().zip(&truth.poles) {
            assert!((a.hz - b.hz).abs() < 1e-4 * b.hz && (a.damping - b.damping).abs() < 1e-4, "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn a_response_with_a_right_half_plane_zero_is_refused_with_the_reason() {
        // (1 − s/a)/(1 + s/b)²: a non-minimum-phase zero no section can hold.
        let (a, b) = (std::f64::consts::TAU * 30.0, std::f64::consts::TAU * 20.0);
        let points: Vec<(f64, Complex64)> = (1..=40)
            .map(|f| {
                let s = Complex64::new(0.0, std::f64::consts::TAU * f as f64);
                let n = 1.0 - s * (1.0 / a);
                let d = 1.0 + s * (1.0 / b);
                (f as f64, n / (d * d))
            })
            .collect();
        let e = fit("y", &points, (1.0, 40.0), 1, 2000.0).unwrap_err().to_string();
        assert!(e.contains("right half plane") || e.contains("odd number"), "{e}");
    }

    #[test]
    fn a_dead_axis_is_an_error_not_a_model() {
        let points: Vec<(f64, Complex64)> = (1..=40).map(|f| (f as f64, Complex64::new(0.0, 0.0))).collect();
        let e = fit("z", &points, (1.0, 40.0), 2, 2000.0).unwrap_err().to_string();
        assert!(e.contains("did not follow"), "{e}");
    }
}
