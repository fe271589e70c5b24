//! Spectral estimation for the broadband baseline: the FFT (rustfft) and the H1 estimator
//! `S_uy / S_uu` with Welch averaging (Hann windows, 50 % overlap) and its coherence.
//!
//! Complex values are `num_complex::Complex64` (the type rustfft and nalgebra use); where one
//! goes into JSON it keeps the `{"re": .., "im": ..}` form through `analysis::complex_json`.

use anyhow::{bail, Result};
use num_complex::Complex64;

/// One DFT bin: `Σ x[i]·e^{−j2πki/N}` over the whole record (k may be any harmonic of the
/// record, for periodic excitations whose period is the record).
pub fn dft_bin(x: &[f64], k: f64) -> Complex64 {
    let w = -std::f64::consts::TAU * k / x.len() as f64;
    x.iter().enumerate().fold(Complex64::default(), |acc, (i, v)| {
        let a = w * i as f64;
        acc + Complex64::new(v * a.cos(), v * a.sin())
    })
}

/// In-place forward FFT `X[k] = Σ x[i]·e^{−j2πki/N}` (rustfft; any length).
pub fn fft(x: &mut [Complex64]) {
    rustfft::FftPlanner::new().plan_fft_forward(x.len()).process(x);
}

/// H1 and coherence at bins 0..=segment/2.
pub fn welch_h1(u: &[f64], y: &[f64], segment: usize) -> Result<(Vec<Complex64>, Vec<f64>)> {
    if !segment.is_power_of_two() || segment < 16 {
        bail!("Welch segment length {segment} must be a power of two >= 16");
    }
    if u.len() != y.len() || u.len() < segment {
        bail!("{} samples are too few for segments of {segment}", u.len());
    }
    let window: Vec<f64> =
        (0..segment).map(|i| 0.5 - 0.5 * (std::f64::consts::TAU * i as f64 / segment as f64).cos()).collect();
    let bins = segment / 2 + 1;
    let (mut suu, mut syy, mut suy) = (vec![0.0; bins], vec![0.0; bins], vec![Complex64::default(); bins]);
    let mut start = 0;
    while start + segment <= u.len() {
        let mean = |s: &[f64]| s.iter().sum::<f64>() / s.len() as f64;
        let (mu, my) = (mean(&u[start..start + segment]), mean(&y[start..start + segment]));
        let mut fu: Vec<Complex64> =
            (0..segment).map(|i| Complex64::new((u[start + i] - mu) * window[i], 0.0)).collect();
        let mut fy: Vec<Complex64> =
            (0..segment).map(|i| Complex64::new((y[start + i] - my) * window[i], 0.0)).collect();
        fft(&mut fu);
        fft(&mut fy);
        for k in 0..bins {
            suu[k] += fu[k].norm_sqr();
            syy[k] += fy[k].norm_sqr();
            suy[k] += fu[k].conj() * fy[k];
        }
        start += segment / 2;
    }
    let h = (0..bins).map(|k| suy[k] * (1.0 / suu[k])).collect();
    let coherence = (0..bins).map(|k| suy[k].norm_sqr() / (suu[k] * syy[k])).collect();
    Ok((h, coherence))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fft_of_a_cosine_has_two_bins() {
        let n = 64;
        let mut x: Vec<Complex64> =
            (0..n).map(|i| Complex64::new((std::f64::consts::TAU * 5.0 * i as f64 / n as f64).cos(), 0.0)).collect();
        fft(&mut x);
        for (k, v) in x.iter().enumerate() {
            let expect = if k == 5 || k == n - 5 { n as f64 / 2.0 } else { 0.0 };
            assert!((v.norm() - expect).abs() < 1e-9, "bin {k}: {v:?}");
        }
    }

    #[test]
    fn one_bin_equals_the_fft() {
        let x: Vec<f64> = (0..64).map(|i| ((i * 37 % 11) as f64 - 5.0) * 0.3).collect();
        let mut f: Vec<Complex64> = x.iter().map(|&v| Complex64::new(v, 0.0)).collect();
        fft(&mut f);
        for k in [0usize, 1, 7, 31] {
            assert!((dft_bin(&x, k as f64) - f[k]).norm() < 1e-9, "bin {k}");
        }
    }

    #[test]
    fn h1_recovers_a_known_filter() {
        // y(k) = 0.5·u(k) + 0.3·u(k−1): H(e^{jω}) = 0.5 + 0.3·e^{−jω}.
        let mut state = 12345u64;
        let u: Vec<f64> = (0..65536)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                if state & 1 == 1 {
                    1.0
                } else {
                    -1.0
                }
            })
            .collect();
        let y: Vec<f64> = (0..u.len()).map(|k| 0.5 * u[k] + if k > 0 { 0.3 * u[k - 1] } else { 0.0 }).collect();
        let (h, c) = welch_h1(&u, &y, 256).unwrap();
        for k in [1usize, 40, 100, 127] {
            let w = std::f64::consts::TAU * k as f64 / 256.0;
            let expect = Complex64::new(0.5 + 0.3 * w.cos(), -0.3 * w.sin());
            assert!((h[k] - expect).norm() < 2e-3, "bin {k}: {:?} vs {expect:?}", h[k]);
            assert!(c[k] > 0.999);
        }
    }
}
