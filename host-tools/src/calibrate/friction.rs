//! Friction from constant-speed runs. At a constant speed the velocity loop's torque command
//! balances the friction (the shaft carries no torque of its own once both ends turn
//! together), so its mean over a window is
//! `T(ω) = T₀ + Fc·sign(ω) + B·ω`: a constant load torque `T₀` (gravity on an axis, a
//! spring), the Coulomb friction `Fc` and the viscous coefficient `B`, each the sum of the
//! motor's and the load's (at a constant speed the two sides are not told apart). Fitted by
//! least squares over runs at several speeds in both directions, with standard errors.

use serde::Serialize;

/// One constant-speed run: its mean velocity estimate (rad/s) and mean torque command (N·m).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct SpeedPoint {
    pub velocity: f64,
    pub torque: f64,
}

/// The fitted friction, each value with its standard error (same units).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Friction {
    /// Coulomb friction, motor and load together (N·m).
    pub coulomb: f64,
    pub coulomb_error: f64,
    /// Viscous coefficient, motor and load together (N·m·s/rad).
    pub viscous: f64,
    pub viscous_error: f64,
    /// A constant torque the axis holds whatever the direction (N·m; gravity, a spring).
    pub load_torque: f64,
    pub load_torque_error: f64,
    /// The largest residual of a run (N·m).
    pub worst_residual: f64,
}

impl Friction {
    /// The torque the fit predicts at `velocity` (rad/s).
    pub fn torque(&self, velocity: f64) -> f64 {
        self.load_torque + self.coulomb * velocity.signum() + self.viscous * velocity
    }
}

/// The friction that best explains `points`. Needs runs in both directions and at two or
/// more distinct speeds (else Coulomb and viscous cannot be told apart); refused with the
/// reason otherwise, when a point is not finite, when the fit does not determine Coulomb or
/// viscous friction (a standard error over half the value), and when either comes out
/// negative (a friction that drives the axis: the runs did not measure friction).
pub fn fit_friction(points: &[SpeedPoint]) -> anyhow::Result<Friction> {
    if let Some(p) = points.iter().find(|p| !(p.velocity.is_finite() && p.torque.is_finite())) {
        anyhow::bail!("a constant-speed run gave a non-finite mean ({} rad/s, {} N·m)", p.velocity, p.torque);
    }
    let forward = points.iter().filter(|p| p.velocity > 0.0).count();
    let backward = points.iter().filter(|p| p.velocity < 0.0).count();
    if forward == 0 || backward == 0 || forward + backward < 4 {
        anyhow::bail!(
            "friction needs runs in both directions and at least four in all ({forward} forward, {backward} backward)"
        );
    }
    let points: Vec<SpeedPoint> = points.iter().copied().filter(|p| p.velocity != 0.0).collect();
    let mut speeds: Vec<f64> = points.iter().map(|p| p.velocity.abs()).collect();
    speeds.sort_by(f64::total_cmp);
    speeds.dedup_by(|a, b| (*a - *b).abs() <= 1e-3 * b.abs());
    if speeds.len() < 2 {
        anyhow::bail!("friction needs runs at two or more distinct speeds (got {speeds:?} rad/s)");
    }
    // Columns: 1, sign(ω), ω (scaled by the largest speed so the normal matrix is balanced).
    let scale = points.iter().map(|p| p.velocity.abs()).fold(0.0, f64::max);
    let x = nalgebra::DMatrix::from_fn(points.len(), 3, |i, j| match j {
        0 => 1.0,
        1 => points[i].velocity.signum(),
        _ => points[i].velocity / scale,
    });
    let y = nalgebra::DVector::from_iterator(points.len(), points.iter().map(|p| p.torque));
    let xtx = x.transpose() * &x;
    let inverse = xtx
        .try_inverse()
        .ok_or_else(|| anyhow::anyhow!("the runs' speeds do not separate Coulomb from viscous friction"))?;
    let beta = &inverse * x.transpose() * &y;
    let residual = &y - &x * &beta;
    let dof = (points.len() as f64 - 3.0).max(1.0);
    let sigma2 = residual.norm_squared() / dof;
    let error = |i: usize| (sigma2 * inverse[(i, i)]).max(0.0).sqrt();
    let (coulomb, viscous) = (beta[1], beta[2] / scale);
    let (coulomb_error, viscous_error) = (error(1), error(2) / scale);
    for (name, v, e) in [("Coulomb", coulomb, coulomb_error), ("viscous", viscous, viscous_error)] {
        if v < 0.0 {
            anyhow::bail!(
                "the runs give a negative {name} friction ({v:.3e} ± {e:.1e}): the torque that holds each speed is not friction's (a load that drives the axis, or runs too short to settle)"
            );
        }
        if !(e <= 0.5 * v) {
            anyhow::bail!(
                "the runs do not determine the {name} friction ({v:.3e} ± {e:.1e}): too noisy, or the speeds too close together"
            );
        }
    }
    Ok(Friction {
        load_torque: beta[0],
        load_torque_error: error(0),
        coulomb,
        coulomb_error,
        viscous,
        viscous_error,
        worst_residual: residual.amax(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Points of a known friction with a constant load torque and small noise: each value
    /// within three standard errors, and the standard errors small beside the values; runs
    /// in one direction only are refused with the reason.
    #[test]
    fn coulomb_viscous_and_load_torque_are_recovered_with_their_errors() {
        let (t0, fc, b) = (0.004, 0.03, 3e-5);
        let mut seed = 3u64;
        let mut noise = || {
            seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((seed >> 11) as f64 / (1u64 << 53) as f64 - 0.5) * 2e-4
        };
        let points: Vec<SpeedPoint> = [20.0, 50.0, 100.0, 150.0, -20.0, -50.0, -100.0, -150.0]
            .into_iter()
            .map(|w: f64| SpeedPoint { velocity: w, torque: t0 + fc * w.signum() + b * w + noise() })
            .collect();
        let f = fit_friction(&points).unwrap();
        assert!((f.coulomb - fc).abs() < 3.0 * f.coulomb_error + 1e-12 && f.coulomb_error < 0.01 * fc, "{f:?}");
        assert!((f.viscous - b).abs() < 3.0 * f.viscous_error + 1e-15 && f.viscous_error < 0.1 * b, "{f:?}");
        assert!((f.load_torque - t0).abs() < 3.0 * f.load_torque_error + 1e-12, "{f:?}");
        assert!(f.load_torque_error < 0.05 * t0, "{f:?}");
        assert!((f.torque(80.0) - (t0 + fc + b * 80.0)).abs() < 3e-4);
        let one_way: Vec<SpeedPoint> = points.iter().copied().filter(|p| p.velocity > 0.0).collect();
        let e = fit_friction(&one_way).unwrap_err().to_string();
        assert!(e.contains("both directions"), "{e}");
        let same: Vec<SpeedPoint> = points.iter().copied().filter(|p| p.velocity.abs() == 50.0).collect();
        let doubled: Vec<SpeedPoint> = same.iter().chain(&same).copied().collect();
        assert!(fit_friction(&doubled).unwrap_err().to_string().contains("distinct speeds"));
        let driven: Vec<SpeedPoint> = points
            .iter()
            .map(|p| SpeedPoint { torque: t0 - fc * p.velocity.signum() + b * p.velocity, ..*p })
            .collect();
        assert!(fit_friction(&driven).unwrap_err().to_string().contains("negative Coulomb"));
        let mut bad = points.clone();
        bad[2].torque = f64::NAN;
        assert!(fit_friction(&bad).unwrap_err().to_string().contains("non-finite"));
    }
}
