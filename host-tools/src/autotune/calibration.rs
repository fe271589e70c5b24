//! The machine's mechanics fitted to a measured plant response: the torque point of a sweep
//! measures `P = D·M` (torque command → velocity estimate), where the drive's part `D` is
//! known from its parameters (`drive_dynamics`) and `M` is the two-inertia machine
//! (`mechanics`). The fit finds the motor and load inertias, the shaft's stiffness and its
//! damping ratio by least squares on the complex logarithm of `P_measured / P_model` (gain in
//! nepers and phase in radians, alike), from a ladder of starting resonances and inertia
//! ratios, each refined by Levenberg–Marquardt; each value comes with its standard error
//! from the fit's residual and Jacobian.
//!
//! **An absorber.** A second mode on the load (a third inertia on its own spring) leaves a
//! resonance and anti-resonance pair the two-inertia fit cannot follow. The fit is then run
//! again with the absorber's inertia, stiffness and damping ratio, from the two-inertia fit
//! and a ladder of absorber frequencies across the band and inertia shares; the absorber is
//! tried where the two-inertia fit misses the response ([`ABSORBER_MISFIT_DB`]) and kept
//! where it explains it: its residual a quarter of the two-inertia fit's or less
//! ([`ABSORBER_GAIN`]), its mode inside the measured band, and its inertias and stiffnesses
//! determined within [`ABSORBER_DETERMINED`].

use num_complex::Complex64;
use serde::Serialize;

use super::drive_dynamics::DriveDynamics;
use super::mechanics::{AbsorberMechanics, Mechanics};

/// One measured point of the plant: frequency (Hz) and `P` (rad/s per N·m).
#[derive(Clone, Copy, Debug)]
pub struct PlantPoint {
    pub hz: f64,
    pub response: Complex64,
}

/// The fitted machine, with standard errors (relative: 0.01 is 1 %) of its inertias,
/// stiffness and damping, and the fit's worst residual (dB and degrees).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Calibration {
    pub mechanics: Mechanics,
    pub relative_errors: [f64; 4],
    /// The absorber's inertia, stiffness and damping ratio, where one was fitted.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub absorber_relative_errors: Option<[f64; 3]>,
    pub worst_gain_db: f64,
    pub worst_phase_deg: f64,
    /// The shaft's resonance lies above the measured band: the machine is rigid there and
    /// the split of its inertia and the stiffness are not determined (only bounds).
    pub rigid: bool,
    /// The fitted parameters and their covariance, where the fit determines every one.
    #[serde(skip)]
    pub uncertainty: Option<Uncertainty>,
}

/// The fit's log parameters θ and their covariance `σ²·(JᵀJ)⁻¹`: the models the measurement
/// cannot tell from the fitted one lie in the ellipsoid it spans around θ.
#[derive(Clone, Copy, Debug)]
pub struct Uncertainty {
    theta: [f64; 7],
    len: usize,
    covariance: [[f64; 7]; 7],
}

impl Uncertainty {
    fn of(theta: &[f64], covariance: &nalgebra::DMatrix<f64>) -> Option<Self> {
        let len = theta.len();
        if len > 7 || covariance.nrows() != len || covariance.iter().any(|v| !v.is_finite()) {
            return None;
        }
        let mut u = Self { theta: [0.0; 7], len, covariance: [[0.0; 7]; 7] };
        u.theta[..len].copy_from_slice(theta);
        for i in 0..len {
            for j in 0..len {
                u.covariance[i][j] = covariance[(i, j)];
            }
        }
        Some(u)
    }

    /// The machines at the ends of the ellipsoid's principal axes, `sigmas` standard
    /// deviations out from the fit (two per parameter); `None` where the covariance is not
    /// positive semi-definite (a value the fit does not determine).
    pub fn principal_extremes(&self, sigmas: f64) -> Option<Vec<Mechanics>> {
        let n = self.len;
        let c = nalgebra::DMatrix::from_fn(n, n, |i, j| 0.5 * (self.covariance[i][j] + self.covariance[j][i]));
        let eigen = nalgebra::SymmetricEigen::new(c);
        let mut extremes = Vec::with_capacity(2 * n);
        for (k, &lambda) in eigen.eigenvalues.iter().enumerate() {
            if !(lambda.is_finite() && lambda >= -1e-12 * eigen.eigenvalues.amax()) {
                return None;
            }
            let reach = sigmas * lambda.max(0.0).sqrt();
            for sign in [-1.0, 1.0] {
                let theta: Vec<f64> =
                    (0..n).map(|i| self.theta[i] + sign * reach * eigen.eigenvectors[(i, k)]).collect();
                extremes.push(mechanics_of(&theta, 0.0));
            }
        }
        Some(extremes)
    }

    /// The same fit with independent relative errors `sigma` on every parameter.
    #[cfg(test)]
    pub fn with_relative_errors(mut self, sigma: f64) -> Self {
        self.covariance = [[0.0; 7]; 7];
        for i in 0..self.len {
            self.covariance[i][i] = sigma * sigma;
        }
        self
    }
}

/// The absorber is kept where its fit's residual (sum of squares) is at most this share of
/// the two-inertia fit's.
pub const ABSORBER_GAIN: f64 = 0.25;

/// The absorber is kept where every value of its fit (the shaft's and the absorber's inertia
/// and stiffness) has a standard error below this (relative).
pub const ABSORBER_DETERMINED: f64 = 0.05;

/// The absorber is tried where the two-inertia fit misses a point by more than this (dB) or
/// ten times as many degrees: a mode the motor feels misses by several decibels, a good
/// two-inertia fit on a noisy sweep by a few tenths.
pub const ABSORBER_MISFIT_DB: f64 = 1.0;

/// θ = (ln J_M, ln J_L, ln k, ln ζ), ζ the shaft's damping ratio at the load's own frequency;
/// with an absorber, then (ln J_a, ln k_a, ln ζ_a), ζ_a its own damping ratio.
fn mechanics_of(theta: &[f64], viscous: f64) -> Mechanics {
    let (jm, jl, k, zeta) = (theta[0].exp(), theta[1].exp(), theta[2].exp(), theta[3].exp());
    let absorber = (theta.len() == 7).then(|| {
        let (ja, ka, zeta_a) = (theta[4].exp(), theta[5].exp(), theta[6].exp());
        AbsorberMechanics { inertia: ja, stiffness: ka, damping: 2.0 * zeta_a * (ka * ja).sqrt() }
    });
    Mechanics {
        motor_inertia: jm,
        load_inertia: jl,
        shaft_stiffness: k,
        shaft_damping: 2.0 * zeta * (k * jl).sqrt(),
        motor_viscous: viscous,
        load_viscous: 0.0,
        absorber,
    }
}

fn residuals(points: &[PlantPoint], drive: &DriveDynamics, theta: &[f64]) -> Vec<f64> {
    let m = mechanics_of(theta, 0.0);
    let mut r = Vec::with_capacity(2 * points.len());
    for p in points {
        let model = super::plant_response(drive, &m, p.hz);
        let e = (p.response / model).ln();
        r.push(e.re);
        r.push(e.im);
    }
    r
}

fn cost(r: &[f64]) -> f64 {
    r.iter().map(|x| x * x).sum()
}

/// The mechanics that best explain `points` through `drive`; an error when there are too few
/// points or no fit converges.
pub fn calibrate(points: &[PlantPoint], drive: &DriveDynamics) -> anyhow::Result<Calibration> {
    let points: Vec<PlantPoint> = points
        .iter()
        .copied()
        .filter(|p| p.hz.is_finite() && p.hz > 0.0 && p.response.norm().is_finite() && p.response.norm() > 0.0)
        .collect();
    if points.len() < 8 {
        anyhow::bail!("{} usable points of the plant's response: the fit needs at least 8", points.len());
    }
    let low = points.iter().map(|p| p.hz).fold(f64::INFINITY, f64::min);
    let high = points.iter().map(|p| p.hz).fold(0.0, f64::max);
    // The rigid body's inertia from the lowest points (a start: the back-EMF path left out,
    // under 0.1 % there with the decoupling, up to about a tenth without it; the fit has it).
    let mut lowest: Vec<&PlantPoint> = points.iter().collect();
    lowest.sort_by(|a, b| a.hz.total_cmp(&b.hz));
    let j: f64 = {
        let take = lowest.len().min(3);
        lowest[..take]
            .iter()
            .map(|p| {
                1.0 / (std::f64::consts::TAU
                    * p.hz
                    * (p.response / drive.around_machine(p.hz, Complex64::new(0.0, 0.0))).norm())
            })
            .sum::<f64>()
            / take as f64
    };
    if !(j.is_finite() && j > 0.0) {
        anyhow::bail!("the lowest points give no inertia");
    }
    // Starting points: a ladder of resonances across (and past) the band and of ratios.
    let mut starts: Vec<Vec<f64>> = Vec::new();
    for k in 0..16 {
        let fr = 0.5 * low * (4.0 * high / low).powf(k as f64 / 15.0);
        for ratio in [0.2, 0.5, 1.0, 2.0, 5.0] {
            let jm = j / (1.0 + ratio);
            let jl = jm * ratio;
            let w = std::f64::consts::TAU * fr;
            let stiffness = w * w / (1.0 / jm + 1.0 / jl);
            starts.push(vec![jm.ln(), jl.ln(), stiffness.ln(), 0.05f64.ln()]);
        }
    }
    // Every start refined (a narrow resonance a start misses by a little has phase errors of
    // half a turn, and ranks below a rigid body before its refinement).
    let (theta, c) = best_fit(&points, drive, starts).ok_or_else(|| {
        anyhow::anyhow!("no start of the fit gave a finite residual: the measured response is not a machine's")
    })?;
    let two_inertia = (theta, c);
    let (misfit_db, misfit_deg) = worst_misfit(&residuals(&points, drive, &two_inertia.0));
    // The absorber: starts from the two-inertia fit, its own mode on a ladder across the band
    // and a few inertia shares of the load, lightly damped.
    let mut starts: Vec<Vec<f64>> = Vec::new();
    let jl = two_inertia.0[1].exp();
    for k in 0..16 {
        let fa = low * (high / low).powf((k as f64 + 0.5) / 16.0);
        for share in [0.05, 0.2, 0.5] {
            let ja = share * jl;
            let ka = ja * (std::f64::consts::TAU * fa).powi(2);
            let mut t = two_inertia.0.clone();
            t.extend([ja.ln(), ka.ln(), 0.03f64.ln()]);
            starts.push(t);
        }
    }
    let missed = misfit_db > ABSORBER_MISFIT_DB || misfit_deg > 10.0 * ABSORBER_MISFIT_DB;
    let absorber = if missed { best_fit(&points, drive, starts) } else { None };
    let (theta, c) = match absorber {
        Some((t, ca)) if ca <= ABSORBER_GAIN * c && absorber_holds(&points, drive, &t, ca, (low, high)) => (t, ca),
        _ => two_inertia,
    };
    let mechanics = mechanics_of(&theta, 0.0);
    let (worst_gain_db, worst_phase_deg) = worst_misfit(&residuals(&points, drive, &theta));
    // Standard errors: σ²·(JᵀJ)⁻¹ on the log parameters are relative errors.
    let covariance = covariance(&points, drive, &theta, c);
    let errors = standard_errors_of(covariance.as_ref(), theta.len());
    let relative_errors = [errors[0], errors[1], errors[2], errors[3]];
    let absorber_relative_errors = (theta.len() == 7).then(|| [errors[4], errors[5], errors[6]]);
    let fr = mechanics.highest_resonance_hz();
    Ok(Calibration {
        mechanics,
        relative_errors,
        absorber_relative_errors,
        worst_gain_db,
        worst_phase_deg,
        rigid: fr > high,
        uncertainty: covariance.as_ref().and_then(|cov| Uncertainty::of(&theta, cov)),
    })
}

/// Every start refined (a narrow resonance a start misses by a little has phase errors of
/// half a turn, and ranks below a rigid body before its refinement); the best fit and its cost.
fn best_fit(points: &[PlantPoint], drive: &DriveDynamics, starts: Vec<Vec<f64>>) -> Option<(Vec<f64>, f64)> {
    let mut best: Option<(Vec<f64>, f64)> = None;
    for theta in starts {
        let (theta, c) = levenberg_marquardt(points, drive, theta);
        if c.is_finite() && best.as_ref().is_none_or(|b| c < b.1) {
            best = Some((theta, c));
        }
    }
    best
}

/// The worst of `residuals` (pairs of nepers and radians) in dB and degrees.
fn worst_misfit(residuals: &[f64]) -> (f64, f64) {
    let (mut worst_gain_db, mut worst_phase_deg) = (0.0f64, 0.0f64);
    for pair in residuals.chunks(2) {
        worst_gain_db = worst_gain_db.max((pair[0] * 20.0 / std::f64::consts::LN_10).abs());
        worst_phase_deg = worst_phase_deg.max(pair[1].to_degrees().abs());
    }
    (worst_gain_db, worst_phase_deg)
}

/// An absorber fit explains the response: its own mode and the chain's resonances inside the
/// measured band (`low`, `high` Hz) and every inertia and stiffness determined.
fn absorber_holds(
    points: &[PlantPoint],
    drive: &DriveDynamics,
    theta: &[f64],
    c: f64,
    (low, high): (f64, f64),
) -> bool {
    let mechanics = mechanics_of(theta, 0.0);
    let Some(a) = mechanics.absorber else { return false };
    let (fa, _) = a.own_mode();
    let inside = |f: f64| f > low && f < high;
    let errors = standard_errors(points, drive, theta, c);
    inside(fa)
        && inside(mechanics.highest_resonance_hz())
        && [0, 1, 2, 4, 5].iter().all(|&i| errors[i] < ABSORBER_DETERMINED)
}

/// Standard errors: σ²·(JᵀJ)⁻¹ on the log parameters are relative errors (infinite where a
/// value is undetermined).
fn standard_errors(points: &[PlantPoint], drive: &DriveDynamics, theta: &[f64], c: f64) -> Vec<f64> {
    standard_errors_of(covariance(points, drive, theta, c).as_ref(), theta.len())
}

/// The covariance of the log parameters, `σ²·(JᵀJ)⁻¹` (`None` where `JᵀJ` is singular).
fn covariance(points: &[PlantPoint], drive: &DriveDynamics, theta: &[f64], c: f64) -> Option<nalgebra::DMatrix<f64>> {
    let jac = jacobian(points, drive, theta);
    let dof = (2.0 * points.len() as f64 - theta.len() as f64).max(1.0);
    let jtj = jac.transpose() * &jac;
    jtj.try_inverse().map(|inv| inv * (c / dof))
}

/// The square roots of the covariance's diagonal; infinite where it is not a finite
/// non-negative number (the value is undetermined), every one without a covariance.
fn standard_errors_of(covariance: Option<&nalgebra::DMatrix<f64>>, n: usize) -> Vec<f64> {
    match covariance {
        Some(cov) => (0..n)
            .map(|i| {
                let v = cov[(i, i)];
                if v.is_finite() && v >= 0.0 {
                    v.sqrt()
                } else {
                    f64::INFINITY
                }
            })
            .collect(),
        None => vec![f64::INFINITY; n],
    }
}

fn jacobian(points: &[PlantPoint], drive: &DriveDynamics, theta: &[f64]) -> nalgebra::DMatrix<f64> {
    let r0 = residuals(points, drive, theta);
    let n = theta.len();
    let mut j = nalgebra::DMatrix::zeros(r0.len(), n);
    for c in 0..n {
        let mut t = theta.to_vec();
        let h = 1e-6;
        t[c] += h;
        let r1 = residuals(points, drive, &t);
        for i in 0..r0.len() {
            j[(i, c)] = (r1[i] - r0[i]) / h;
        }
    }
    j
}

/// Levenberg–Marquardt from `theta`: the refined parameters and their cost.
fn levenberg_marquardt(points: &[PlantPoint], drive: &DriveDynamics, mut theta: Vec<f64>) -> (Vec<f64>, f64) {
    let n = theta.len();
    let mut r = residuals(points, drive, &theta);
    let mut c = cost(&r);
    let mut lambda = 1e-3;
    for _ in 0..200 {
        let jac = jacobian(points, drive, &theta);
        let jtj = jac.transpose() * &jac;
        let g = jac.transpose() * nalgebra::DVector::from_vec(r.clone());
        let mut improved = false;
        for _ in 0..12 {
            let mut a = jtj.clone();
            for i in 0..n {
                a[(i, i)] *= 1.0 + lambda;
                a[(i, i)] += 1e-12;
            }
            let Some(step) = a.lu().solve(&(-&g)) else {
                lambda *= 10.0;
                continue;
            };
            let mut t = theta.clone();
            for i in 0..n {
                // Steps within a factor of e per iteration (the parameters are logarithms).
                t[i] += step[i].clamp(-1.0, 1.0);
            }
            // Damping ratios within 1e-4 to 2.
            t[3] = t[3].clamp(1e-4f64.ln(), 2.0f64.ln());
            if n == 7 {
                t[6] = t[6].clamp(1e-4f64.ln(), 2.0f64.ln());
            }
            let rt = residuals(points, drive, &t);
            let ct = cost(&rt);
            if ct.is_finite() && ct < c {
                let done = (c - ct) < 1e-12 * c.max(1e-30);
                (theta, r, c) = (t, rt, ct);
                lambda = (lambda * 0.3).max(1e-9);
                improved = !done;
                break;
            }
            lambda *= 10.0;
        }
        if !improved {
            break;
        }
    }
    (theta, c)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Uniform noise of ±0.5 % from a linear congruential generator seeded with `seed`.
    fn uniform_noise(mut seed: u64) -> impl FnMut() -> f64 {
        move || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 0.01
        }
    }

    /// `truth`'s plant through `drive` at 41 frequencies from 10 Hz to 3 kHz, each reading
    /// multiplied by `1 + noise() + j·noise()`.
    fn noisy_points(truth: &Mechanics, drive: &DriveDynamics, noise: &mut impl FnMut() -> f64) -> Vec<PlantPoint> {
        crate::autotune::margins::log_grid(10.0, 3000.0, 41)
            .into_iter()
            .map(|hz| PlantPoint {
                hz,
                response: crate::autotune::plant_response(drive, truth, hz) * Complex64::new(1.0 + noise(), noise()),
            })
            .collect()
    }

    /// Points of a known machine through the default drive, with 0.5 % multiplicative noise:
    /// the fit recovers its inertias and stiffness within 2 % and the damping within 20 %,
    /// from starting points that know nothing of it.
    #[test]
    fn a_two_inertia_machine_is_recovered_from_its_response() {
        let params = control_core::Params::default();
        let drive = DriveDynamics::as_configured(&params);
        let mut noise = uniform_noise(7);
        for (jl, fr, zeta) in [(3e-4, 120.0, 0.03), (5e-5, 400.0, 0.08), (7e-4, 60.0, 0.01)] {
            let jm = 1.5e-4;
            let truth = Mechanics::two_inertia(jm, jl, fr, zeta);
            let k = truth.shaft_stiffness;
            let points = noisy_points(&truth, &drive, &mut noise);
            let c = calibrate(&points, &drive).unwrap();
            let m = c.mechanics;
            let rel = |a: f64, b: f64| (a / b - 1.0).abs();
            assert!(rel(m.motor_inertia, jm) < 0.02 && rel(m.load_inertia, jl) < 0.02, "{c:?}");
            assert!(rel(m.shaft_stiffness, k) < 0.02, "{c:?}");
            assert!(rel(m.shaft_damping, truth.shaft_damping) < 0.2, "{c:?}");
            assert!(c.relative_errors.iter().all(|e| e.is_finite()), "{c:?}");
            assert!(!c.rigid);
            assert!(m.absorber.is_none() && c.absorber_relative_errors.is_none(), "no absorber: {c:?}");
        }
    }

    /// The machines the measurement cannot tell from the fit: every principal extreme lies
    /// `sigmas` standard deviations out (its Mahalanobis distance from the fit, under the
    /// fit's covariance, is `sigmas`), two per parameter, and the covariance's diagonal is the
    /// standard errors reported.
    #[test]
    fn the_principal_extremes_lie_on_the_fits_confidence_ellipsoid() {
        let params = control_core::Params::default();
        let drive = DriveDynamics::as_configured(&params);
        let mut noise = uniform_noise(3);
        let truth = Mechanics::two_inertia(1.5e-4, 3e-4, 120.0, 0.03);
        let c = calibrate(&noisy_points(&truth, &drive, &mut noise), &drive).unwrap();
        let u = c.uncertainty.expect("a determined fit");
        let log_params = |m: &Mechanics| {
            let zeta = m.shaft_damping / (2.0 * (m.shaft_stiffness * m.load_inertia).sqrt());
            nalgebra::DVector::from_vec(vec![
                m.motor_inertia.ln(),
                m.load_inertia.ln(),
                m.shaft_stiffness.ln(),
                zeta.ln(),
            ])
        };
        let cov = nalgebra::DMatrix::from_fn(4, 4, |i, j| u.covariance[i][j]);
        for i in 0..4 {
            assert!((cov[(i, i)].sqrt() / c.relative_errors[i] - 1.0).abs() < 1e-9, "{c:?}");
        }
        let inverse = cov.clone().try_inverse().unwrap();
        let fit = log_params(&c.mechanics);
        let extremes = u.principal_extremes(4.0).unwrap();
        assert_eq!(extremes.len(), 8);
        for m in &extremes {
            let d = log_params(m) - &fit;
            let distance = (d.transpose() * &inverse * &d)[(0, 0)].sqrt();
            assert!((distance - 4.0).abs() < 1e-6, "{distance}");
        }
    }

    /// A machine with an absorber on the load, through the default drive with 0.5 % noise:
    /// the fit with the absorber recovers the absorber's inertia and stiffness within 5 % (its own mode within 2 %) and
    /// the shaft's within 3 %, on three machines whose absorber the motor feels: below the
    /// shaft's resonance, just under it, and on a stiff shaft. (An absorber far above the
    /// shaft's resonance moves a load the shaft has already decoupled from the motor: the
    /// motor's response does not show it, and the two-inertia fit explains it.)
    #[test]
    fn an_absorber_on_the_load_is_found_and_fitted() {
        let params = control_core::Params::default();
        let drive = DriveDynamics::as_configured(&params);
        let mut noise = uniform_noise(11);
        for (jl, fr, fa, share) in [(3e-4, 150.0, 60.0, 0.3), (1e-4, 400.0, 250.0, 0.2), (2e-4, 1500.0, 300.0, 0.15)] {
            let jm = 1.5e-4;
            let w = std::f64::consts::TAU * fr;
            let k = w * w / (1.0 / jm + 1.0 / jl);
            let ja = share * jl;
            let ka = ja * (std::f64::consts::TAU * fa).powi(2);
            let truth = Mechanics {
                motor_inertia: jm,
                load_inertia: jl,
                shaft_stiffness: k,
                shaft_damping: 2.0 * 0.03 * (k * jl).sqrt(),
                motor_viscous: 0.0,
                load_viscous: 0.0,
                absorber: Some(AbsorberMechanics {
                    inertia: ja,
                    stiffness: ka,
                    damping: 2.0 * 0.02 * (ka * ja).sqrt(),
                }),
            };
            let points = noisy_points(&truth, &drive, &mut noise);
            let c = calibrate(&points, &drive).unwrap();
            let m = c.mechanics;
            let a = m.absorber.unwrap_or_else(|| panic!("no absorber found: {c:?}"));
            let rel = |x: f64, y: f64| (x / y - 1.0).abs();
            let t = truth.absorber.unwrap();
            assert!(rel(a.inertia, t.inertia) < 0.05 && rel(a.stiffness, t.stiffness) < 0.05, "{c:?}");
            assert!(rel(a.own_mode().0, fa) < 0.02, "{c:?}");
            assert!(rel(m.shaft_stiffness, k) < 0.03 && rel(m.load_inertia, jl) < 0.03, "{c:?}");
            assert!(c.worst_gain_db < 0.5, "{c:?}");
        }
    }
}
