//! Standard error of a sweep result, gain (dB) and phase (deg), from the acquisition samples
//! its fit keeps: the error the noise left in it, so that a user knows which points to distrust.
//!
//! The fit (`measurement.rs`, the README's formula) is linear in the samples: with the centred
//! phases `c'_k = cos θ_k − mean`, `s'_k = sin θ_k − mean` and the normal matrix
//! `A = [[S_cc, S_cs], [S_cs, S_ss]]`, a residual r_k of x moves its complex amplitude by
//! `r_k·v_k`, `v_k = p_k − j·q_k`, `(p_k, q_k) = A⁻¹·(c'_k, s'_k)`. The response's relative
//! error `δG/G = δY/Y − δU/U` (real part: the gain's, relative; imaginary: the phase's, rad)
//! is then the sum over the samples of `z_k = (r_y,k/Y − r_u,k/U)·v_k`. Its variance is taken
//! two ways:
//! - **model**: the noise as the drive's precision control sees it, white or correlated with
//!   the previous sample only (the variance of Σz from the products of z_k with itself and its
//!   predecessor in the same record: exact for white noise and for the encoder's quantisation
//!   differentiated into a velocity, `(n/(n − 3))` for the three fitted parameters per signal);
//! - **batch means**: the kept samples of each record cut into contiguous batches
//!   ([`BATCHES`] in all), each batch's share of Σz summed on its own: the spread of those
//!   shares, `B/(B − 1)·Σ_b (Σ_{k∈b} z_k)²`, is the variance of their sum whatever the noise's
//!   spectrum, as long as a batch is longer than the noise's memory. It is each batch's own
//!   fit linearised about the full one (a batch's phases alone may not tell a sine: near the
//!   acquisition Nyquist frequency one record sees one phase and its opposite), and it also
//!   sees a transient that has not died out, which drifts from batch to batch.
//!
//! Colored noise (a lightly damped mode rung by current noise) hides from the model: its
//! spectrum at the excitation is not the one the residuals' variance and lag-one covariance
//! give. Batch means see it but, from a dozen batches, scatter themselves. The reported error
//! is the larger of the two (see [`ResponseStandardError`]). Neither sees a ring that stays at
//! the excitation frequency through all the kept samples: it looks like response (on the
//! light, soft axis of `servo bench sweep --detail` the default sweep was 0.02 dB and 0.6°
//! off at 43–50 Hz in every noise seed, 2–4 standard errors; with 0.5 s of settling the error
//! went away). The drive's settling check now waits out such a ring where its half blocks'
//! differences tell it (`control_core::phase_shifted_sweep`'s settling check); one they do
//! not tell stays unseen here too.

use std::f64::consts::LN_10;

use crate::sweep::measurement::MIN_QUALITY;

/// One acquisition sample a result's fit keeps: u, y, the excitation's phase (rad) and the
/// record (phase-shifted repeat) it belongs to. In time order.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FitSample {
    pub u: f64,
    pub y: f64,
    pub phase: f64,
    pub record: i64,
}

/// Batches a result's samples are cut into for the batch-means error: enough for the spread
/// of their shares to tell (B − 1 degrees of freedom), few enough that a batch outlasts the
/// noise's memory. Over 10 seeds × 41 frequencies of `servo bench sweep --detail`'s
/// calibration (defaults), RMS of error/standard error, gain / phase, the reported error's
/// (batch means' alone): 4 batches 0.99 / 1.15 (1.72 / 1.84), 8: 1.01 / 1.12 (1.21 / 1.34),
/// 12: 1.02 / 1.07 (1.13 / 1.24), 16: 1.01 / 1.07 (1.12 / 1.21); on the narrowband noise of
/// the tests (memory about 50 samples, batches of 160–270) the reported gain error was
/// 0.97, 0.94 and 0.90 of the Monte-Carlo spread with 8, 12 and 16.
pub const BATCHES: usize = 12;

/// Standard errors of one result. `gain_db` and `phase_deg` are the reported ones: the larger
/// of the model's and the batch means' (each on its own scale): the model alone misses
/// colored noise and transients, the batch means alone scatter with their few degrees of
/// freedom, and one too small would make a user trust a point the noise moved.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct ResponseStandardError {
    pub gain_db: f64,
    pub phase_deg: f64,
    pub model_gain_db: f64,
    pub model_phase_deg: f64,
    pub batch_gain_db: f64,
    pub batch_phase_deg: f64,
    /// Batches the batch-means error had (0 where the samples cannot tell).
    pub batches: usize,
}

impl ResponseStandardError {
    /// A result whose samples cannot tell its error (too few, phases that cannot tell a sine,
    /// no response): infinite.
    pub fn unknown() -> Self {
        let inf = f64::INFINITY;
        Self {
            gain_db: inf,
            phase_deg: inf,
            model_gain_db: inf,
            model_phase_deg: inf,
            batch_gain_db: inf,
            batch_phase_deg: inf,
            batches: 0,
        }
    }

    /// The gain's standard error and the phase's in the gain's terms (dB: the phase's relative
    /// size, `deg·π/180`, as a gain ratio), whichever is larger.
    pub fn larger_db(&self) -> f64 {
        self.gain_db.max(phase_deg_as_db(self.phase_deg))
    }
}

/// dB of a relative size (`20/ln 10` per unit).
const DB_PER_UNIT: f64 = 20.0 / LN_10;

/// A phase error (deg) as the gain error of the same relative size (dB): 0.2° ≈ 0.03 dB.
pub fn phase_deg_as_db(deg: f64) -> f64 {
    deg.to_radians() * DB_PER_UNIT
}

/// The standard errors of the result fitted to `samples` (in time order), in [`BATCHES`]
/// batches.
pub fn response_standard_error(samples: &[FitSample]) -> ResponseStandardError {
    response_standard_error_in(samples, BATCHES)
}

/// As [`response_standard_error`] with `batches` batches (at least 2).
pub fn response_standard_error_in(samples: &[FitSample], batches: usize) -> ResponseStandardError {
    let Some(z) = error_shares(samples) else { return ResponseStandardError::unknown() };
    let n = z.len() as f64;
    // Model: Σz_k² plus twice the products with the previous sample of the same record.
    let (mut re, mut im) = (0.0, 0.0);
    for k in 0..z.len() {
        re += z[k].0 * z[k].0;
        im += z[k].1 * z[k].1;
        if k > 0 && samples[k].record == samples[k - 1].record {
            re += 2.0 * z[k].0 * z[k - 1].0;
            im += 2.0 * z[k].1 * z[k - 1].1;
        }
    }
    let dof = n / (n - 3.0);
    let model = ((re * dof).max(0.0).sqrt(), (im * dof).max(0.0).sqrt());
    let cuts = batch_bounds(samples, batches.max(2));
    let (mut bre, mut bim) = (0.0, 0.0);
    for w in cuts.windows(2) {
        let (sr, si) = z[w[0]..w[1]].iter().fold((0.0, 0.0), |(a, b), &(r, i)| (a + r, b + i));
        bre += sr * sr;
        bim += si * si;
    }
    let b = (cuts.len() - 1) as f64;
    let batch = if b >= 2.0 { ((bre * b / (b - 1.0)).sqrt(), (bim * b / (b - 1.0)).sqrt()) } else { (0.0, 0.0) };
    ResponseStandardError {
        gain_db: DB_PER_UNIT * model.0.max(batch.0),
        phase_deg: model.1.max(batch.1).to_degrees(),
        model_gain_db: DB_PER_UNIT * model.0,
        model_phase_deg: model.1.to_degrees(),
        batch_gain_db: DB_PER_UNIT * batch.0,
        batch_phase_deg: batch.1.to_degrees(),
        batches: cuts.len() - 1,
    }
}

/// Each sample's share `z_k` of the response's relative error (real: gain, imaginary: phase;
/// see the module's documentation). None when the samples cannot tell a response.
fn error_shares(samples: &[FitSample]) -> Option<Vec<(f64, f64)>> {
    let n = samples.len() as f64;
    if samples.len() < 8 {
        return None;
    }
    let (sc, ss) = samples.iter().fold((0.0, 0.0), |(c, s), x| (c + x.phase.cos(), s + x.phase.sin()));
    let (mc, ms) = (sc / n, ss / n);
    let centred: Vec<(f64, f64)> = samples.iter().map(|x| (x.phase.cos() - mc, x.phase.sin() - ms)).collect();
    let (mut scc, mut sss, mut scs) = (0.0, 0.0, 0.0);
    for &(c, s) in &centred {
        scc += c * c;
        sss += s * s;
        scs += c * s;
    }
    let det = scc * sss - scs * scs;
    // Phases that cannot tell a sine (the fit's quality, det/(n²/4), under the threshold of
    // `unmeasurable`).
    if !(det > MIN_QUALITY * 0.25 * n * n) {
        return None;
    }
    // (p_k, q_k) = A⁻¹·(c'_k, s'_k).
    let weights: Vec<(f64, f64)> =
        centred.iter().map(|&(c, s)| ((sss * c - scs * s) / det, (scc * s - scs * c) / det)).collect();
    // Fitted amplitude (b, c) of x, its mean and complex amplitude b − j·c.
    let fit = |x: &dyn Fn(&FitSample) -> f64| {
        let mean = samples.iter().map(x).sum::<f64>() / n;
        let (b, c) = samples.iter().zip(&weights).fold((0.0, 0.0), |(b, c), (v, &(p, q))| {
            let d = x(v) - mean;
            (b + d * p, c + d * q)
        });
        (mean, b, c)
    };
    let (u_mean, ub, uc) = fit(&|v| v.u);
    let (y_mean, yb, yc) = fit(&|v| v.y);
    let (au, ay) = (ub * ub + uc * uc, yb * yb + yc * yc);
    if !(au > 0.0 && ay > 0.0) {
        return None;
    }
    Some(
        samples
            .iter()
            .zip(&centred)
            .zip(&weights)
            .map(|((v, &(c, s)), &(p, q))| {
                let ru = v.u - u_mean - ub * c - uc * s;
                let ry = v.y - y_mean - yb * c - yc * s;
                // δX = r·(p − j·q); δX/X with X = b − j·c: (r/|X|²)·(p − j·q)·(b + j·c).
                let share = |r: f64, b: f64, c: f64, a: f64| {
                    let k = r / a;
                    (k * (p * b + q * c), k * (p * c - q * b))
                };
                let (yr, yi) = share(ry, yb, yc, ay);
                let (ur, ui) = share(ru, ub, uc, au);
                (yr - ur, yi - ui)
            })
            .collect(),
    )
}

/// Indices that cut the samples into about `batches` contiguous batches, none across a
/// record's start: each record gets its share of the batches by its share of the samples (at
/// least one). First index 0, last `samples.len()`.
fn batch_bounds(samples: &[FitSample], batches: usize) -> Vec<usize> {
    let mut records = Vec::new();
    let mut start = 0;
    for k in 1..=samples.len() {
        if k == samples.len() || samples[k].record != samples[k - 1].record {
            records.push((start, k));
            start = k;
        }
    }
    let n = samples.len() as f64;
    let mut cuts = vec![0];
    for (a, b) in records {
        let len = b - a;
        let count = ((batches as f64 * len as f64 / n).round() as usize).clamp(1, len);
        for i in 1..=count {
            cuts.push(a + (len * i) / count);
        }
    }
    cuts
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The phases of a record of `n` samples at `step` rad per sample from `start`.
    fn record(n: usize, step: f64, start: f64, record: i64) -> impl Iterator<Item = (f64, i64)> {
        (0..n).map(move |k| ((start + step * k as f64).rem_euclid(std::f64::consts::TAU), record))
    }

    /// A deterministic generator of standard normal numbers (xorshift + Box–Muller).
    struct Normal(u64);

    impl Normal {
        fn uniform(&mut self) -> f64 {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        }

        fn next(&mut self) -> f64 {
            let (a, b) = (self.uniform(), self.uniform());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        }
    }

    /// The response G = Y/U of `samples` (the same fit as `measurement.rs`).
    fn response(samples: &[FitSample]) -> num_complex::Complex64 {
        let mut fit = crate::sweep::measurement::SineFit::default();
        for s in samples {
            fit.add(s.u, s.y, s.phase);
        }
        let (u, y, _) = fit.solve();
        y / u
    }

    /// The experiment the errors must predict: samples of u = sin and y = g·sin shifted,
    /// each with its own realisation of `noise` (on u, on y), fitted many times. The spread of
    /// the fitted gain (dB) and phase (deg) over the realisations is the truth (Monte Carlo);
    /// returned with the root mean square of the reported standard errors, and of the
    /// model's alone.
    fn monte_carlo(
        phases: &[(f64, i64)],
        realisations: usize,
        mut noise: impl FnMut(&mut Normal, bool) -> (f64, f64),
    ) -> [(f64, f64); 3] {
        let mut rng = Normal(0x9E37_79B9_7F4A_7C15);
        let (gain, shift) = (0.5, 0.7);
        let (mut g, mut p) = (Vec::new(), Vec::new());
        let (mut reported, mut model) = ((0.0, 0.0), (0.0, 0.0));
        for _ in 0..realisations {
            let samples: Vec<FitSample> = phases
                .iter()
                .enumerate()
                .map(|(k, &(phase, record))| {
                    let (nu, ny) = noise(&mut rng, k == 0 || phases[k - 1].1 != record);
                    FitSample { u: phase.sin() + nu, y: gain * (phase - shift).sin() + ny, phase, record }
                })
                .collect();
            let r = response(&samples);
            g.push(20.0 * r.norm().log10());
            p.push(r.arg().to_degrees());
            let e = response_standard_error(&samples);
            reported.0 += e.gain_db * e.gain_db;
            reported.1 += e.phase_deg * e.phase_deg;
            model.0 += e.model_gain_db * e.model_gain_db;
            model.1 += e.model_phase_deg * e.model_phase_deg;
        }
        let spread = |v: &[f64]| {
            let m = v.iter().sum::<f64>() / v.len() as f64;
            (v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (v.len() - 1) as f64).sqrt()
        };
        let n = realisations as f64;
        let rms = |(a, b): (f64, f64)| ((a / n).sqrt(), (b / n).sqrt());
        [(spread(&g), spread(&p)), rms(reported), rms(model)]
    }

    /// White noise on U and on Y, partly the same with the opposite sign (as where U carries
    /// the loop's reaction to the noise of Y; the errors of Y and U then add): model and
    /// reported errors both match the Monte-Carlo spread (within 15 %; the reported one, the
    /// larger of two estimates, lies at or above it).
    #[test]
    fn under_white_noise_the_standard_error_is_the_monte_carlo_spread() {
        let phases: Vec<(f64, i64)> = record(600, 0.2, 0.0, 0).collect();
        let [truth, reported, model] = monte_carlo(&phases, 400, |rng, _| {
            let nu = 0.04 * rng.next();
            (nu, 0.03 * rng.next() - 0.5 * nu)
        });
        for (t, m) in [(truth.0, model.0), (truth.1, model.1)] {
            assert!((m / t - 1.0).abs() < 0.15, "model {m} vs spread {t}");
        }
        for (t, r) in [(truth.0, reported.0), (truth.1, reported.1)] {
            assert!(r / t > 0.95 && r / t < 1.3, "reported {r} vs spread {t}");
        }
    }

    /// Narrowband noise on Y at the excitation frequency (a lightly damped mode rung by white
    /// noise: AR(2) with its poles at radius 0.98 at the excitation's phase step) is far from
    /// the white/lag-one spectrum the model assumes: the model's error falls short of the
    /// Monte-Carlo spread (a quarter of it), the reported one (batch means) is within 25 % of
    /// it. Three phase-shifted records,
    /// the noise restarting (from rest) with each, as at and above the threshold.
    #[test]
    fn under_narrowband_noise_the_batch_means_find_the_spread_the_model_misses() {
        let step = 0.3;
        let phases: Vec<(f64, i64)> =
            (0..3).flat_map(|r| record(800, step, r as f64 * std::f64::consts::TAU / 3.0, r as i64)).collect();
        let (radius, mut state) = (0.98f64, (0.0, 0.0));
        let (a1, a2) = (2.0 * radius * step.cos(), -radius * radius);
        let [truth, reported, model] = monte_carlo(&phases, 400, |rng, restart| {
            if restart {
                // Started from its stationary state: run it in for a while.
                state = (0.0, 0.0);
                for _ in 0..400 {
                    state = (a1 * state.0 + a2 * state.1 + rng.next(), state.0);
                }
            }
            state = (a1 * state.0 + a2 * state.1 + rng.next(), state.0);
            (0.0, 0.002 * state.0)
        });
        for (t, r, m) in [(truth.0, reported.0, model.0), (truth.1, reported.1, model.1)] {
            assert!(m / t < 0.6, "the model {m} should miss the colored spread {t}");
            assert!(r / t > 0.75 && r / t < 1.25, "reported {r} vs spread {t}");
        }
    }

    /// Samples that cannot tell a response (all at one phase and its opposite) have an
    /// infinite error, not a number.
    #[test]
    fn phases_that_cannot_tell_a_sine_have_an_infinite_error() {
        let phases: Vec<FitSample> = record(100, std::f64::consts::PI, 0.3, 0)
            .map(|(phase, record)| FitSample { u: phase.sin(), y: phase.cos(), phase, record })
            .collect();
        let e = response_standard_error(&phases);
        assert!(e.gain_db.is_infinite() && e.phase_deg.is_infinite() && e.batches == 0);
    }

    /// Batches never cross a record's start and cover every sample once.
    #[test]
    fn batches_cover_the_records_without_crossing_them() {
        let samples: Vec<FitSample> = [(0, 500), (1, 170), (2, 170)]
            .iter()
            .flat_map(|&(r, n)| (0..n).map(move |_| FitSample { u: 0.0, y: 0.0, phase: 0.0, record: r }))
            .collect();
        let cuts = batch_bounds(&samples, 8);
        assert_eq!((cuts[0], *cuts.last().unwrap()), (0, samples.len()));
        assert!(cuts.contains(&500) && cuts.contains(&670));
        assert!(cuts.windows(2).all(|w| w[1] > w[0]));
        assert_eq!(cuts.len() - 1, 5 + 2 + 2);
    }
}
