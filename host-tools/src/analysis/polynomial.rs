//! Polynomial roots for the model checks (python-control poles, identified zeros).

use nalgebra::DMatrix;

use num_complex::Complex64;

/// Roots of a real polynomial `c[0] + c[1]·x + … + c[n]·x^n`: the eigenvalues of its
/// companion matrix (nalgebra's real Schur decomposition, as numpy's `roots`). Leading zero
/// coefficients are dropped (a lower degree); a zero polynomial has no roots.
pub fn roots(c: &[f64]) -> Vec<Complex64> {
    let Some(top) = c.iter().rposition(|&x| x != 0.0) else { return Vec::new() };
    let n = top;
    if n == 0 {
        return Vec::new();
    }
    let lead = c[top];
    // x^n = −Σ c_i/c_n x^i: ones on the subdiagonal, the coefficients in the last column.
    let companion = DMatrix::from_fn(n, n, |i, j| {
        if j == n - 1 {
            -c[i] / lead
        } else if i == j + 1 {
            1.0
        } else {
            0.0
        }
    });
    companion.complex_eigenvalues().iter().copied().collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sorted(mut r: Vec<Complex64>) -> Vec<Complex64> {
        r.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        r
    }

    #[test]
    fn roots_of_a_known_cubic() {
        // (x − 2)(x² + 2x + 5): roots 2 and −1 ± 2j.
        let r = sorted(roots(&[-10.0, 1.0, 0.0, 1.0]));
        let expect = [Complex64::new(-1.0, -2.0), Complex64::new(-1.0, 2.0), Complex64::new(2.0, 0.0)];
        assert_eq!(r.len(), 3);
        for (a, b) in r.iter().zip(expect) {
            assert!((a - b).norm() < 1e-9, "{a:?} vs {b:?}");
        }
    }

    #[test]
    fn widely_spread_roots_of_a_sixth_degree_polynomial() {
        // Roots from 1e-2 to 1e3 (a Butterworth-like spread): the product's coefficients span
        // fifteen decades; each root comes back within 1e-7 relative.
        let truth = [0.01, -0.5, 3.0, -40.0, 200.0, -1000.0];
        let mut c = vec![1.0];
        for r in truth {
            // multiply by (x − r)
            let mut next = vec![0.0; c.len() + 1];
            for (i, &ci) in c.iter().enumerate() {
                next[i] -= r * ci;
                next[i + 1] += ci;
            }
            c = next;
        }
        let mut got: Vec<f64> = roots(&c).iter().map(|z| z.re).collect();
        got.sort_by(f64::total_cmp);
        let mut want = truth.to_vec();
        want.sort_by(f64::total_cmp);
        for (g, w) in got.iter().zip(&want) {
            assert!((g - w).abs() <= 1e-7 * w.abs(), "{g} vs {w}");
        }
    }

    #[test]
    fn leading_zeros_lower_the_degree() {
        let r = roots(&[-6.0, 1.0, 0.0, 0.0]);
        assert_eq!(r.len(), 1);
        assert!((r[0] - Complex64::new(6.0, 0.0)).norm() < 1e-12);
        assert!(roots(&[0.0, 0.0]).is_empty());
        assert!(roots(&[3.0]).is_empty());
    }
}
