//! Identification of an axis's anti-resonance (seed 001) on the FMU.
//!
//! The drive adds an M-sequence to its torque command (degree 11: 2047 chips at 1 kHz, one
//! period = 2.05 s) while it holds a constant speed (friction stays on one side). After
//! 0.5 s for the transients, one full period of the motor torque u and the machine-end
//! acceleration y is recorded; with a periodic excitation the DFT ratio `H = Y/U` at the
//! period's harmonics has no leakage, and the accelerometer noise (not fed back: the loop
//! closes on the encoder) only adds variance.
//!
//! Then, as embodiment 4: the response, smoothed by a moving average over neighbouring
//! frequencies, is searched for a minimum (an anti-resonance); only if one is found is the
//! local model `H ≈ K·N(s)/P(s)`, `N = s²/ωz² + 2ζz·s/ωz + 1`, `P` likewise, fitted around it
//! by linear least squares in the frequency domain (Levy's method with Sanathanan–Koerner
//! reweighting); else N = 1.

use servo_axis::variables::name;
use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Result};
use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::{SweepParams, SweepSignal};
use serde::{Deserialize, Serialize};

use crate::analysis::polynomial::roots;
use crate::analysis::response_point::ResponsePoint;
use crate::analysis::spectral::{dft_bin, Complex};
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::SweepRun;

pub const DEGREE: u32 = 11;
/// Base ticks per acquisition sample (4 kHz) and per chip (1 kHz: the chips' spectrum has its
/// first null at 1 kHz and little power left above the acquisition Nyquist frequency to fold
/// back; chips at 4 kHz put 2 % of bias on the anti-resonance frequency).
pub const DIVIDER: u32 = 4;
pub const CHIP_DIVIDER: u32 = 16;
pub const SPEED: f64 = 20.0;
/// Excitation before the measured period, for the transients to die out (the response is
/// periodic after them; any window of one period is then a full period).
pub const TRANSIENT_S: f64 = 0.5;
/// The torque the identification relates the acceleration to: the motor's torque, as the
/// drive estimates it from its measured q current (the FMU gives it exactly). The torque
/// *command* would add the current loop's lag and delay, which the rational model has no
/// term for (+2 % on the anti-resonance frequency at 40 Hz).
pub const INPUT_SIGNAL: &str = "electromagnetic_torque";

/// A second-order factor `s²/ω² + 2ζs/ω + 1`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Factor {
    pub hz: f64,
    pub damping: f64,
}

impl Factor {
    pub fn at(&self, f: f64) -> Complex {
        let x = f / self.hz;
        Complex::new(1.0 - x * x, 2.0 * self.damping * x)
    }
}

/// The model an axis is tuned from: a file the user may edit (embodiment 5).
#[derive(Clone, Debug, Serialize, Deserialize, PartialEq)]
pub struct AxisModel {
    pub axis: String,
    /// Anti-resonance numerator N(s); None: a rigid axis, N = 1.
    pub anti_resonance: Option<Factor>,
    /// The pole pair fitted with it (the absorber's resonance).
    pub resonance: Option<Factor>,
    /// Gain of the model at low frequencies: torque → acceleration, 1/J (1/(kg·m²)).
    pub gain: f64,
    /// Band the model was fitted over (Hz).
    pub band: (f64, f64),
    /// RMS relative error of the fit over the band.
    pub fit_error: f64,
    /// The FMU parameters the axis was identified with (for `servo tune`'s check runs).
    #[serde(default)]
    pub fmu_parameters: BTreeMap<String, f64>,
}

impl AxisModel {
    /// Read a model file (`servo ident` writes them; the user may edit them).
    pub fn load(path: &std::path::Path) -> Result<Self> {
        use anyhow::Context;
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        serde_json::from_str(&text).with_context(|| format!("{} is not a model file", path.display()))
    }

    pub fn response(&self, f: f64) -> Complex {
        let n = self.anti_resonance.map_or(Complex::new(1.0, 0.0), |z| z.at(f));
        let p = self.resonance.map_or(Complex::new(1.0, 0.0), |z| z.at(f));
        n.div(p).scale(self.gain)
    }
}

/// A measured torque → acceleration response.
#[derive(Clone, Debug, Serialize)]
pub struct Measured {
    pub frequencies: Vec<f64>,
    pub response: Vec<Complex>,
    /// |U|² per frequency: the inverse variance of H under output noise (fit weights).
    pub input_power: Vec<f64>,
}

impl Measured {
    pub fn points(&self) -> Vec<ResponsePoint> {
        self.frequencies.iter().zip(&self.response).map(|(&f, &h)| ResponsePoint::from_complex(f, h, 1.0)).collect()
    }
}

/// The drive's M-sequence on the torque command for `seconds`, at constant speed.
fn excitation(parameters: &BTreeMap<String, Value>, amplitude: f64, seconds: f64) -> SweepRun {
    let settings = SweepParams {
        point: InjectionPoint::TorqueCommand,
        signal: SweepSignal::Prbs,
        amplitude: amplitude as f32,
        prbs_degree: DEGREE,
        prbs_divider: CHIP_DIVIDER,
        acquisition_divider: DIVIDER,
        prbs_seconds: seconds as f32,
        min_settle_s: 0.0,
        ..Default::default()
    };
    SweepRun { settings, parameters: parameters.clone(), velocity: SPEED }
}

/// Run the excitation on an axis with `parameters` and return the measured response between
/// `f_min` and `f_max`.
pub fn measure(
    fmu: &Fmu,
    parameters: &BTreeMap<String, Value>,
    amplitude: f64,
    f_min: f64,
    f_max: f64,
) -> Result<Measured> {
    let chips = (1u64 << DEGREE) - 1;
    let control = configuration(parameters)?.control;
    let fs = control.rates.current_loop_hz as f64;
    let period = chips as f64 * CHIP_DIVIDER as f64 / fs;
    let trace = excitation(parameters, amplitude, TRANSIENT_S + period).run(fmu, |_| {})?;
    let col = |n: &str| trace.column(n).ok_or_else(|| anyhow!("the FMU has no output {n}"));
    let (measuring, u_all, y_all, faults) =
        (col("acq_measuring")?, col(INPUT_SIGNAL)?, col("load_acceleration")?, col("faults")?);
    if faults.iter().any(|&f| f != 0.0) {
        bail!(
            "the axis tripped during the excitation (faults {}): lower the amplitude",
            faults.iter().cloned().fold(0.0, f64::max)
        );
    }
    let torque_limit = control.velocity.torque_limit as f64;
    if u_all.iter().any(|u| u.abs() >= 0.999 * torque_limit) {
        bail!("the torque command saturated at {torque_limit} N·m during the excitation: the data cannot be used (lower the amplitude)");
    }
    // Rows following a measuring step; the last full period of them.
    let rows: Vec<usize> = (1..measuring.len()).filter(|&i| measuring[i] != 0.0).collect();
    let n = (chips * (CHIP_DIVIDER / DIVIDER) as u64) as usize;
    if rows.len() < n {
        bail!("{} samples recorded, {} needed (a period of the M-sequence)", rows.len(), n);
    }
    let last = &rows[rows.len() - n..];
    let u: Vec<f64> = last.iter().map(|&i| u_all[i]).collect();
    let y: Vec<f64> = last.iter().map(|&i| y_all[i]).collect();
    let u_rms = (u.iter().map(|x| x * x).sum::<f64>() / n as f64).sqrt();
    if u_rms < 1e-9 {
        bail!("no excitation in the recorded torque command");
    }
    let fa = fs / DIVIDER as f64;
    let df = fa / n as f64;
    let (k0, k1) = ((f_min / df).ceil() as usize, (f_max / df).floor() as usize);
    let mut frequencies = Vec::new();
    let mut response = Vec::new();
    let mut input_power = Vec::new();
    for k in k0.max(1)..=k1 {
        let uk = dft_bin(&u, k as f64);
        frequencies.push(k as f64 * df);
        response.push(dft_bin(&y, k as f64).div(uk));
        input_power.push(uk.norm_sqr());
    }
    Ok(Measured { frequencies, response, input_power })
}

/// Noise-free run, to set the accelerometer noise for a signal-to-noise ratio.
pub fn acceleration_rms(fmu: &Fmu, parameters: &BTreeMap<String, Value>, amplitude: f64) -> Result<f64> {
    let trace = excitation(parameters, amplitude, 0.5).run(fmu, |_| {})?;
    let (m, a) =
        (trace.column("acq_measuring").unwrap_or_default(), trace.column("load_acceleration").unwrap_or_default());
    let v: Vec<f64> = (0..a.len()).filter(|&i| m[i] != 0.0).map(|i| a[i]).collect();
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    Ok((v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt())
}

/// Solve a small dense system by Gaussian elimination with partial pivoting.
fn solve(mut a: Vec<Vec<f64>>, mut b: Vec<f64>) -> Result<Vec<f64>> {
    let n = b.len();
    for c in 0..n {
        let p = (c..n).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs())).unwrap_or(c);
        if a[p][c].abs() < 1e-300 {
            bail!("the identification equations are singular (no usable excitation in the band)");
        }
        a.swap(c, p);
        b.swap(c, p);
        for r in c + 1..n {
            let f = a[r][c] / a[c][c];
            for k in c..n {
                a[r][k] -= f * a[c][k];
            }
            b[r] -= f * b[c];
        }
    }
    let mut x = vec![0.0; n];
    for r in (0..n).rev() {
        x[r] = (b[r] - (r + 1..n).map(|k| a[r][k] * x[k]).sum::<f64>()) / a[r][r];
    }
    Ok(x)
}

/// Moving average of the gain (dB) over ±`half` bins.
fn smoothed_db(m: &Measured, half: usize) -> Vec<f64> {
    let db: Vec<f64> = m.response.iter().map(|h| 20.0 * h.abs().log10()).collect();
    (0..db.len())
        .map(|i| {
            let (a, b) = (i.saturating_sub(half), (i + half + 1).min(db.len()));
            db[a..b].iter().sum::<f64>() / (b - a) as f64
        })
        .collect()
}

/// Embodiment 4: the anti-resonance, if the smoothed response has a minimum at least
/// `depth_db` below its surroundings (±40 % in frequency) inside the band.
pub fn find_anti_resonance(m: &Measured, depth_db: f64) -> Option<f64> {
    let half = (m.frequencies.len() / 200).max(2);
    let s = smoothed_db(m, half);
    let (i, &min) = s.iter().enumerate().min_by(|a, b| a.1.total_cmp(b.1))?;
    let f = m.frequencies[i];
    let around = |lo: f64, hi: f64| {
        m.frequencies
            .iter()
            .zip(&s)
            .filter(|(x, _)| **x >= lo && **x <= hi)
            .map(|(_, v)| *v)
            .fold(f64::NEG_INFINITY, f64::max)
    };
    let (left, right) = (around(0.6 * f, 0.8 * f), around(1.25 * f, 1.4 * f));
    (left.is_finite() && right.is_finite() && left - min >= depth_db && right - min >= depth_db).then_some(f)
}

/// Polynomial in s = jx at x.
fn poly_at(c: &[f64], x: f64) -> Complex {
    let s = Complex::new(0.0, x);
    c.iter().rev().fold(Complex::default(), |acc, &ci| acc.mul(s).add(Complex::new(ci, 0.0)))
}

/// A fitted rational model `B(s)/A(s)` (s normalised by `w0`), A(0) = 1.
#[derive(Clone, Debug)]
pub struct RationalFit {
    pub w0: f64,
    pub numerator: Vec<f64>,
    pub denominator: Vec<f64>,
    pub fit_error: f64,
}

impl RationalFit {
    pub fn at(&self, f: f64) -> Complex {
        let x = std::f64::consts::TAU * f / self.w0;
        poly_at(&self.numerator, x).div(poly_at(&self.denominator, x))
    }

    /// Complex-conjugate root pairs of a polynomial as factors (Hz, damping), and real roots
    /// (Hz, negative for the right half plane).
    fn factors(&self, c: &[f64]) -> (Vec<Factor>, Vec<f64>) {
        let mut pairs = Vec::new();
        let mut real = Vec::new();
        for r in roots(c) {
            let (re, im) = (r.re * self.w0, r.im * self.w0);
            if im > 1e-6 * re.abs().max(1.0) {
                let w = re.hypot(im);
                pairs.push(Factor { hz: w / std::f64::consts::TAU, damping: -re / w });
            } else if im.abs() <= 1e-6 * re.abs().max(1.0) {
                real.push(-re / std::f64::consts::TAU);
            }
        }
        pairs.sort_by(|a, b| a.hz.total_cmp(&b.hz));
        (pairs, real)
    }

    pub fn zeros(&self) -> (Vec<Factor>, Vec<f64>) {
        self.factors(&self.numerator)
    }

    pub fn poles(&self) -> (Vec<Factor>, Vec<f64>) {
        self.factors(&self.denominator)
    }
}

/// Fit `B(s)/A(s)` of orders (nb, na) over the band by Levy's linearised least squares with
/// Sanathanan–Koerner reweighting (s normalised by the band's centre).
pub fn fit_rational(m: &Measured, band: (f64, f64), nb: usize, na: usize) -> Result<RationalFit> {
    let selected: Vec<usize> =
        (0..m.frequencies.len()).filter(|&i| m.frequencies[i] >= band.0 && m.frequencies[i] <= band.1).collect();
    let pts: Vec<(f64, Complex)> = selected.iter().map(|&i| (m.frequencies[i], m.response[i])).collect();
    // Inverse-variance weights of H under accelerometer noise, normalised.
    let mean_power = selected.iter().map(|&i| m.input_power[i]).sum::<f64>() / selected.len().max(1) as f64;
    let confidence: Vec<f64> = selected.iter().map(|&i| m.input_power[i] / mean_power.max(1e-300)).collect();
    let unknowns = nb + 1 + na;
    if pts.len() < 2 * unknowns {
        bail!("{} frequencies in the fit band {:?} Hz: too few for {unknowns} coefficients (record longer or widen the band)", pts.len(), band);
    }
    let w0 = std::f64::consts::TAU * (band.0 * band.1).sqrt();
    // (jx)^i as (re, im).
    let power = |x: f64, i: usize| match i % 4 {
        0 => (x.powi(i as i32), 0.0),
        1 => (0.0, x.powi(i as i32)),
        2 => (-x.powi(i as i32), 0.0),
        _ => (0.0, -x.powi(i as i32)),
    };
    let mut weight = confidence.clone();
    let mut theta = vec![0.0; unknowns];
    for _ in 0..10 {
        let mut ata = vec![vec![0.0; unknowns]; unknowns];
        let mut atb = vec![0.0; unknowns];
        for ((f, h), w) in pts.iter().zip(&weight) {
            let x = std::f64::consts::TAU * f / w0;
            // Σ b_i (jx)^i − H·Σ_{i≥1} a_i (jx)^i = H
            let mut re = vec![0.0; unknowns];
            let mut im = vec![0.0; unknowns];
            for i in 0..=nb {
                let (pr, pi) = power(x, i);
                re[i] = pr;
                im[i] = pi;
            }
            for i in 1..=na {
                let (pr, pi) = power(x, i);
                let hp = h.mul(Complex::new(pr, pi));
                re[nb + i] = -hp.re;
                im[nb + i] = -hp.im;
            }
            for (row, rhs) in [(&re, h.re), (&im, h.im)] {
                for i in 0..unknowns {
                    for j in 0..unknowns {
                        ata[i][j] += w * row[i] * row[j];
                    }
                    atb[i] += w * row[i] * rhs;
                }
            }
        }
        theta = solve(ata, atb)?;
        let mut den = vec![1.0];
        den.extend_from_slice(&theta[nb + 1..]);
        for (((f, _), w), c) in pts.iter().zip(weight.iter_mut()).zip(&confidence) {
            *w = c / poly_at(&den, std::f64::consts::TAU * f / w0).norm_sqr();
        }
    }
    let numerator = theta[..=nb].to_vec();
    let mut denominator = vec![1.0];
    denominator.extend_from_slice(&theta[nb + 1..]);
    let mut fit = RationalFit { w0, numerator, denominator, fit_error: 0.0 };
    fit.fit_error =
        (pts.iter().map(|(f, h)| (fit.at(*f).sub(*h).abs() / h.abs()).powi(2)).sum::<f64>() / pts.len() as f64).sqrt();
    Ok(fit)
}

/// Identify one axis: measure, look for an anti-resonance, fit.
pub fn identify(axis: &str, m: &Measured) -> Result<AxisModel> {
    let low_gain = {
        let n = (m.response.len() / 20).max(1);
        m.response[..n].iter().map(|h| h.abs()).sum::<f64>() / n as f64
    };
    match find_anti_resonance(m, 6.0) {
        None => Ok(AxisModel {
            axis: axis.into(),
            anti_resonance: None,
            resonance: None,
            gain: low_gain,
            band: (m.frequencies[0], *m.frequencies.last().unwrap_or(&0.0)),
            fit_error: 0.0,
            fmu_parameters: BTreeMap::new(),
        }),
        Some(f) => {
            // Numerator: the anti-resonance pair and the shaft's real zero; denominator: the
            // absorber's and the shaft's resonances.
            let band = (0.3 * f, (6.0 * f).min(*m.frequencies.last().unwrap_or(&f)));
            let fit = fit_rational(m, band, 3, 4)?;
            let (zeros, _) = fit.zeros();
            let (poles, _) = fit.poles();
            // The anti-resonance: the zero pair nearest the minimum found.
            let zero = zeros
                .iter()
                .copied()
                .min_by(|a, b| (a.hz - f).abs().total_cmp(&(b.hz - f).abs()))
                .ok_or_else(|| anyhow!("the fitted model has no complex zero pair near {f:.1} Hz"))?;
            if zero.damping < 0.0 {
                bail!("the identified anti-resonance at {:.1} Hz has its zeros in the right half plane (damping {:.3}): the model cannot be used", zero.hz, zero.damping);
            }
            if let Some(p) = poles.iter().find(|p| p.damping <= 0.0) {
                bail!("the fitted model has unstable poles at {:.1} Hz (damping {:.3}): refused", p.hz, p.damping);
            }
            let pole = poles.iter().copied().filter(|p| p.hz > zero.hz).min_by(|a, b| a.hz.total_cmp(&b.hz));
            let gain = fit.numerator[0];
            Ok(AxisModel {
                axis: axis.into(),
                anti_resonance: Some(zero),
                resonance: pole,
                gain,
                band,
                fit_error: fit.fit_error,
                fmu_parameters: BTreeMap::new(),
            })
        }
    }
}

/// The plant's true anti-resonance for absorber parameters (for checks).
pub fn true_anti_resonance(inertia: f64, stiffness: f64, damping: f64) -> Factor {
    let w = (stiffness / inertia).sqrt();
    Factor { hz: w / std::f64::consts::TAU, damping: damping / (2.0 * (stiffness * inertia).sqrt()) }
}

/// FMU parameters of an axis with an absorber at `hz` with damping ratio `damping`.
pub fn absorber_parameters(hz: f64, damping: f64, inertia: f64) -> BTreeMap<String, Value> {
    let w = std::f64::consts::TAU * hz;
    [
        (name::plant_absorber_inertia, inertia),
        (name::plant_absorber_stiffness, inertia * w * w),
        (name::plant_absorber_damping, 2.0 * damping * inertia * w),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), Value::Float(v)))
    .collect()
}
