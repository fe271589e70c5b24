//! The measured response from one M-sequence record, the same on the FMU and over a drive:
//! its last [`PERIODS`](super::identification::PERIODS) whole periods averaged into one, and
//! the DFT ratio `H = Y/U` at that period's harmonics inside the band. With a periodic
//! excitation the ratio has no leakage; the noise (the accelerometer's, the converters'
//! quantisation) only adds variance, which the averaging divides by the number of periods.

use anyhow::{bail, Result};

use num_complex::Complex64;

use crate::analysis::spectral::{dft_bin, fft};
use crate::ident::identification::Measured;

/// The record's samples: U and Y per acquisition period (means over it), in order, none
/// missing, and the acquisition rate (Hz).
pub struct Record<'a> {
    pub u: &'a [f64],
    pub y: &'a [f64],
    pub acquisition_hz: f64,
}

/// The DFT bins of a period (bin spacing `df`, Hz) from `f_min` to `f_max`, both included
/// where they fall on a bin, the mean (bin 0) left out.
pub fn bins(df: f64, (f_min, f_max): (f64, f64)) -> std::ops::RangeInclusive<usize> {
    ((f_min / df).ceil() as usize).max(1)..=(f_max / df).floor() as usize
}

/// The response between `band.0` and `band.1` (Hz) from the last `periods` periods of
/// `samples_per_period` samples each.
pub fn averaged_response(
    record: &Record,
    samples_per_period: usize,
    periods: usize,
    (f_min, f_max): (f64, f64),
) -> Result<Measured> {
    let (u_all, y_all) = (record.u, record.y);
    let n = samples_per_period;
    if u_all.len() != y_all.len() {
        bail!("{} torque samples but {} acceleration samples", u_all.len(), y_all.len());
    }
    if n == 0 || u_all.len() < n * periods {
        bail!("{} samples recorded, {} needed ({periods} periods of the M-sequence)", u_all.len(), n * periods);
    }
    if let Some(i) = u_all.iter().chain(y_all).position(|v| !v.is_finite()) {
        let which = if i < u_all.len() { "torque" } else { "acceleration" };
        bail!("a {which} sample is not a finite number (is the accelerometer connected?)");
    }
    let start = u_all.len() - n * periods;
    let mut u = vec![0.0; n];
    let mut y = vec![0.0; n];
    for j in 0..n * periods {
        u[j % n] += u_all[start + j] / periods as f64;
        y[j % n] += y_all[start + j] / periods as f64;
    }
    let u_rms = (u.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    if u_rms < 1e-9 {
        bail!("no excitation in the recorded torque");
    }
    let df = record.acquisition_hz / n as f64;
    let spectra = period_spectra(&u_all[start..], &y_all[start..], n);
    let mut frequencies = Vec::new();
    let mut response = Vec::new();
    let mut input_power = Vec::new();
    let mut standard_error = Vec::new();
    for k in bins(df, (f_min, f_max)) {
        let uk = dft_bin(&u, k as f64);
        let h = dft_bin(&y, k as f64) / uk;
        frequencies.push(k as f64 * df);
        response.push(h);
        input_power.push(uk.norm_sqr());
        standard_error.push(standard_error_of(&spectra, k, h, uk));
    }
    Ok(Measured { frequencies, response, input_power, standard_error })
}

/// Each period's spectra of u and y (FFT, the DFT's scaling).
fn period_spectra(u: &[f64], y: &[f64], n: usize) -> Vec<(Vec<Complex64>, Vec<Complex64>)> {
    let spectrum = |x: &[f64]| {
        let mut c: Vec<Complex64> = x.iter().map(|&v| Complex64::new(v, 0.0)).collect();
        fft(&mut c);
        c
    };
    u.chunks_exact(n).zip(y.chunks_exact(n)).map(|(u, y)| (spectrum(u), spectrum(y))).collect()
}

/// Standard error of `h` at bin `k`: the residuals `Y_p − h·U_p` of the periods scatter about
/// zero (their mean is `P·(Ȳ − h·Ū) = 0`); the mean residual's variance is their spread over
/// `P(P − 1)`, and `h`'s that over `|Ū|²`.
fn standard_error_of(spectra: &[(Vec<Complex64>, Vec<Complex64>)], k: usize, h: Complex64, u_mean: Complex64) -> f64 {
    let p = spectra.len() as f64;
    if p < 2.0 {
        return 0.0;
    }
    let spread: f64 = spectra.iter().map(|(u, y)| (y[k] - h * u[k]).norm_sqr()).sum();
    (spread / (p * (p - 1.0))).sqrt() / u_mean.norm()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_periodic_record_gives_the_ratio_of_its_harmonics_and_gaps_are_refused() {
        // y = 3·u delayed by one sample: H = 3·e^{−jωT} at every harmonic.
        let (n, periods, fs) = (64usize, 3usize, 1000.0);
        let one: Vec<f64> = (0..n).map(|i| if (i * 7919) % 13 < 6 { 1.0 } else { -1.0 }).collect();
        let u: Vec<f64> = (0..n * (periods + 1)).map(|i| one[i % n]).collect();
        let y: Vec<f64> = (0..u.len()).map(|i| 3.0 * one[(i + n - 1) % n]).collect();
        let m = averaged_response(&Record { u: &u, y: &y, acquisition_hz: fs }, n, periods, (1.0, 400.0)).unwrap();
        assert_eq!(m.frequencies.len(), 400 * n / 1000);
        for (f, h) in m.frequencies.iter().zip(&m.response) {
            let expected = Complex64::from_polar(3.0, -std::f64::consts::TAU * f / fs);
            assert!((h - expected).norm() < 1e-9, "{f} Hz: {h} vs {expected}");
        }
        // Noise-free and periodic: no scatter between the periods.
        assert!(m.standard_error.iter().all(|&e| e < 1e-9), "{:?}", &m.standard_error[..4]);
        let short =
            averaged_response(&Record { u: &u[..n * 2], y: &y[..n * 2], acquisition_hz: fs }, n, periods, (1.0, 400.0));
        assert!(short.unwrap_err().to_string().contains("needed"));
        let mut bad = y.clone();
        bad[5] = f64::NAN;
        let e =
            averaged_response(&Record { u: &u, y: &bad, acquisition_hz: fs }, n, periods, (1.0, 400.0)).unwrap_err();
        assert!(e.to_string().contains("accelerometer"), "{e}");
    }

    #[test]
    fn the_standard_error_follows_the_output_noise() {
        // y = u plus white noise of deviation s: each bin's H has the standard error
        // s·√(n/P)/|Ū|; the estimate from the periods' scatter must find it within its own
        // sampling error (P = 8 periods: about ±25 % per bin, averaged over the bins).
        let (n, periods) = (256usize, 8usize);
        let one: Vec<f64> = (0..n).map(|i| if (i * 7919) % 13 < 6 { 1.0 } else { -1.0 }).collect();
        let u: Vec<f64> = (0..n * periods).map(|i| one[i % n]).collect();
        let mut state = 0x1234_5678_u64;
        let mut gauss = || {
            let mut uniform = || {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 11) as f64 / (1u64 << 53) as f64
            };
            (-2.0 * uniform().max(1e-300).ln()).sqrt() * (std::f64::consts::TAU * uniform()).cos()
        };
        let s = 0.1;
        let y: Vec<f64> = u.iter().map(|&v| v + s * gauss()).collect();
        let m = averaged_response(&Record { u: &u, y: &y, acquisition_hz: 1000.0 }, n, periods, (1.0, 499.0)).unwrap();
        let ratio: f64 = m
            .frequencies
            .iter()
            .zip(&m.standard_error)
            .zip(&m.input_power)
            .map(|((_, &e), &p)| e / (s * (n as f64 / periods as f64).sqrt() / p.sqrt()))
            .sum::<f64>()
            / m.frequencies.len() as f64;
        assert!((ratio - 1.0).abs() < 0.1, "estimated / true standard error: {ratio}");
    }
}
