//! Polynomial roots for the model checks (python-control poles, identified zeros).

use crate::analysis::spectral::Complex;

/// Roots of a real polynomial `c[0] + c[1]·x + … + c[n]·x^n` (Durand–Kerner).
pub fn roots(c: &[f64]) -> Vec<Complex> {
    let n = c.len() - 1;
    let lead = c[n];
    let mut z: Vec<Complex> = (0..n)
        .map(|k| {
            let a = 0.4 + std::f64::consts::TAU * k as f64 / n as f64;
            Complex::new(0.9 * a.cos(), 0.9 * a.sin())
        })
        .collect();
    let eval =
        |x: Complex| c.iter().rev().fold(Complex::default(), |acc, &ci| acc.mul(x).add(Complex::new(ci / lead, 0.0)));
    for _ in 0..2000 {
        for i in 0..n {
            let mut den = Complex::new(1.0, 0.0);
            for j in (0..n).filter(|&j| j != i) {
                den = den.mul(z[i].sub(z[j]));
            }
            z[i] = z[i].sub(eval(z[i]).div(den));
        }
    }
    z
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn roots_of_a_known_cubic() {
        // (x − 2)(x² + 2x + 5): roots 2 and −1 ± 2j.
        let mut r = roots(&[-10.0, 1.0, 0.0, 1.0]);
        r.sort_by(|a, b| a.re.total_cmp(&b.re).then(a.im.total_cmp(&b.im)));
        let expect = [Complex::new(-1.0, -2.0), Complex::new(-1.0, 2.0), Complex::new(2.0, 0.0)];
        for (a, b) in r.iter().zip(expect) {
            assert!(a.sub(b).abs() < 1e-9, "{a:?} vs {b:?}");
        }
    }
}
