//! Least squares with an intercept over running sums: up to three regressors, their sums, the
//! sums of their products and with the response, solved from the centred normal equations
//! (covariances). Callers take their samples relative to a first one: f32 sums of raw values
//! would lose a small ripple on a large mean.

/// Least squares of `N` regressors and an intercept.
#[derive(Clone, Copy, Debug)]
pub struct Regression<const N: usize> {
    n: f32,
    sx: [f32; N],
    sy: f32,
    sxx: [[f32; N]; N],
    sxy: [f32; N],
}

impl<const N: usize> Default for Regression<N> {
    fn default() -> Self {
        Self { n: 0.0, sx: [0.0; N], sy: 0.0, sxx: [[0.0; N]; N], sxy: [0.0; N] }
    }
}

impl<const N: usize> Regression<N> {
    pub fn add(&mut self, x: [f32; N], y: f32) {
        self.n += 1.0;
        self.sy += y;
        for j in 0..N {
            self.sx[j] += x[j];
            self.sxy[j] += x[j] * y;
            for k in 0..N {
                self.sxx[j][k] += x[j] * x[k];
            }
        }
    }

    pub fn samples(&self) -> f32 {
        self.n
    }

    /// The coefficients of the first `terms` regressors (the rest 0); `None` when a regressor
    /// does not vary independently of the others (a pivot a millionth of its own variance).
    pub fn coefficients(&self, terms: usize) -> Option<[f32; N]> {
        self.coefficients_less(terms, [[0.0; N]; N], [0.0; N])
    }

    /// The coefficients with `noise_xx` taken off the regressors' covariances and `noise_xy`
    /// off their covariances with the response: what white sensor noise on the regressors
    /// and the response adds to them in expectation, which would otherwise bias the fit.
    pub fn coefficients_less(&self, terms: usize, noise_xx: [[f32; N]; N], noise_xy: [f32; N]) -> Option<[f32; N]> {
        let terms = terms.min(N);
        let n = self.n;
        let mean = |s: f32| s / n;
        let mut m = [[0.0f32; N]; N];
        let mut rhs = [0.0f32; N];
        for j in 0..terms {
            for k in 0..terms {
                m[j][k] = mean(self.sxx[j][k]) - mean(self.sx[j]) * mean(self.sx[k]) - noise_xx[j][k];
            }
            rhs[j] = mean(self.sxy[j]) - mean(self.sx[j]) * mean(self.sy) - noise_xy[j];
        }
        // A covariance matrix is symmetric and positive definite: elimination needs no pivots.
        // With noise taken off it may not be: a pivot that is not positive refuses the fit.
        let own: [f32; N] = core::array::from_fn(|j| m[j][j].abs());
        for col in 0..terms {
            if !(m[col][col] > 1e-6 * own[col]) {
                return None;
            }
            for row in col + 1..terms {
                let f = m[row][col] / m[col][col];
                for k in col..terms {
                    m[row][k] -= f * m[col][k];
                }
                rhs[row] -= f * rhs[col];
            }
        }
        let mut x = [0.0f32; N];
        for row in (0..terms).rev() {
            let tail: f32 = (row + 1..terms).map(|k| m[row][k] * x[k]).sum();
            x[row] = (rhs[row] - tail) / m[row][row];
        }
        Some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// y = 2 + 3·x0 − 0.5·x1 + 0.25·x2 over regressors that vary independently: recovered;
    /// a regressor that copies another: refused.
    #[test]
    fn a_linear_model_is_recovered_and_a_copied_regressor_refused() {
        let mut r = Regression::<3>::default();
        let mut copied = Regression::<3>::default();
        let mut s = 12345u32;
        let mut u = || {
            s = s.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
            (s >> 8) as f32 / (1u32 << 24) as f32 - 0.5
        };
        for _ in 0..1000 {
            let x = [u(), u(), u()];
            r.add(x, 2.0 + 3.0 * x[0] - 0.5 * x[1] + 0.25 * x[2]);
            copied.add([x[0], 2.0 * x[0], x[2]], x[0]);
        }
        let c = r.coefficients(3).unwrap();
        for (got, want) in c.iter().zip([3.0, -0.5, 0.25]) {
            assert!((got - want).abs() < 1e-4, "{c:?}");
        }
        assert_eq!(copied.coefficients(3), None);
        assert_eq!(copied.coefficients(1).map(|c| (c[0] * 1e4).round()), Some(1e4));
    }
}
