//! Identification of an axis's anti-resonance (seed 001) on the FMU.
//!
//! The drive adds an M-sequence to its torque command (degree 11: 2047 chips at 1 kHz, one
//! period = 2.05 s) while it holds a constant speed (friction stays on one side). After
//! [`TRANSIENT_S`] for the transients, [`PERIODS`] full periods of the motor torque u and the
//! machine-end acceleration y are recorded and averaged into one period; with a periodic
//! excitation the DFT ratio `H = Y/U` at the period's harmonics has no leakage, and the
//! accelerometer noise (not fed back: the loop closes on the encoder) only adds variance,
//! which the averaging divides by the number of periods.
//!
//! Then, as embodiment 4: the response, smoothed by a moving average over neighbouring
//! frequencies, is searched for a notch (an anti-resonance: the deepest dip below the level
//! of its surroundings, with its depth and a confidence from the scatter of the measured
//! points); only if it is clear is the local model `H ≈ K·N(s)/P(s)`,
//! `N = s²/ωz² + 2ζz·s/ωz + 1`, `P` likewise, fitted around it by least squares in the
//! frequency domain (Levy's method with Sanathanan–Koerner reweighting, solved by SVD, then
//! the weighted output error minimised from there: [`crate::ident::output_error_fit`]); else
//! N = 1, with the reason.
//!
//! What went wrong before (issue 15): one period after 0.5 s, with point samples. Three causes,
//! each measured against the analytic plant (`servo bench ident` prints the record's error):
//! (1) aliasing: a 4 kHz point sample of the torque folds the velocity loop's
//! encoder-quantisation torque (near its 4 kHz Nyquist frequency) onto the lowest
//! frequencies, where the closed loop leaves little excitation in the torque: 30 % error at
//! 2–5 Hz, 15 % at 5–8 Hz, the resonance peak next to a 15 Hz anti-resonance 6 dB low, even
//! without noise; (2) transients: the closed-loop poles next to a low anti-resonance decay
//! slowly (0.5 s left 60–160 % error at 5–25 Hz for 15 Hz, 1.5 s is needed); (3) noise: the
//! closed velocity loop cuts the torque below its bandwidth, so at 20 dB SNR the bins below
//! 12 Hz were at −7 to +1 dB SNR; averaging periods buys it back, at the price of
//! measurement time.

use servo_axis::variables::name;
use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Result};
use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::{SweepParams, SweepSignal};
use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use crate::analysis::polynomial::roots;
use crate::analysis::response_point::ResponsePoint;
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::SweepRun;
use crate::ident::anti_resonance_error::{anti_resonance_error, FactorError, RESAMPLES};
use crate::ident::averaged_response::{averaged_response, Record};
use crate::sweep::torque_limit::TorqueLimits;
use nalgebra::{DMatrix, DVector};

pub const DEGREE: u32 = 11;
/// The anti-resonances `servo ident --anti-resonance` may put on an axis (Hz, 5 % damping):
/// those the identification finds. The response is measured over [`crate::ident::report::BAND`]
/// (5–500 Hz) at the M-sequence's resolution, one bin per period (0.49 Hz), and the notch
/// search needs a notch's surroundings (±15 %, [`NOTCH_SPAN`]) inside it: it searches
/// 6.2–435 Hz (the first bin at or above 5 Hz is 5.37 Hz). Below 10 Hz a 5 % notch (±0.5 Hz
/// wide) spans too few bins for a confident dip, and above 450 Hz its lower flank lies too
/// close to the band's top; 10 and 450 Hz are found within 1 % (a CLI test identifies both
/// ends).
pub const IDENTIFIABLE_HZ: (f64, f64) = (10.0, 450.0);

/// Base ticks per acquisition sample (4 kHz) and per chip (1 kHz: the chips' spectrum has its
/// first null at 1 kHz and little power left above the acquisition Nyquist frequency to fold
/// back; chips at 4 kHz put 2 % of bias on the anti-resonance frequency).
pub const DIVIDER: u32 = 4;
pub const CHIP_DIVIDER: u32 = 16;
pub const SPEED: f64 = 20.0;
/// Excitation before the measured periods, for the transients to die out (the response is
/// periodic after them; any window of whole periods is then made of full periods). The
/// closed-loop poles next to a 15 Hz anti-resonance (5 % damping) need 1.5 s to fall below
/// 1 % of the response; one period (2.05 s) is taken.
pub const TRANSIENT_S: f64 = 2.0;
/// Periods recorded and averaged into one (noise variance divided by as many).
pub const PERIODS: usize = 8;

/// One period of the M-sequence at the default loop rate (s).
pub fn period_s() -> f64 {
    ((1u64 << DEGREE) - 1) as f64 * CHIP_DIVIDER as f64 / control_core::Params::default().rates.current_loop_hz as f64
}

/// Simulated time of one axis's measurement at the default loop rate (s): transients and the
/// averaged periods.
pub fn measurement_time_s() -> f64 {
    TRANSIENT_S + PERIODS as f64 * period_s()
}

/// The torque the identification relates the acceleration to: the motor's torque, as the
/// drive estimates it from its measured q current (the FMU gives it exactly). The torque
/// *command* would add the current loop's lag and delay, which the rational model has no
/// term for (+2 % on the anti-resonance frequency at 40 Hz).
///
/// Both signals are recorded as their means over each acquisition period (4 base ticks), not
/// as one sample per period: the velocity loop (8 kHz) turns the encoder's quantisation into
/// torque noise near its Nyquist frequency, 4 kHz, which a 4 kHz point sample folds onto the
/// lowest frequencies, where the closed velocity loop leaves little excitation in the torque
/// (the measured response was 30 % off at 2–5 Hz, 15 % at 5–8 Hz, and its resonance peak
/// 6 dB low). The mean has nulls at 4 kHz and its multiples, and the same filter on both
/// signals cancels in their ratio (`servo bench ident` shows both records' error against the
/// analytic plant).
pub const INPUT_SIGNAL: &str = "electromagnetic_torque_mean";
pub const OUTPUT_SIGNAL: &str = "load_acceleration_mean";

/// A second-order factor `s²/ω² + 2ζs/ω + 1`.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Factor {
    pub hz: f64,
    pub damping: f64,
}

impl Factor {
    pub fn at(&self, f: f64) -> Complex64 {
        let x = f / self.hz;
        Complex64::new(1.0 - x * x, 2.0 * self.damping * x)
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
    /// Relative standard errors of the anti-resonance's frequency and damping (see
    /// [`anti_resonance_error`]; None without one, or from an exact response).
    #[serde(default)]
    pub anti_resonance_error: Option<FactorError>,
    /// The FMU parameters the axis was identified with (for `servo tune`'s check runs).
    #[serde(default)]
    pub fmu_parameters: BTreeMap<String, f64>,
}

impl AxisModel {
    pub fn response(&self, f: f64) -> Complex64 {
        let n = self.anti_resonance.map_or(Complex64::new(1.0, 0.0), |z| z.at(f));
        let p = self.resonance.map_or(Complex64::new(1.0, 0.0), |z| z.at(f));
        n / p * self.gain
    }
}

/// A measured torque → acceleration response.
#[derive(Clone, Debug, Serialize)]
pub struct Measured {
    pub frequencies: Vec<f64>,
    #[serde(with = "crate::analysis::complex_json::vec")]
    pub response: Vec<Complex64>,
    /// |U|² per frequency: the inverse variance of H under output noise (fit weights).
    pub input_power: Vec<f64>,
    /// Standard error of each H (absolute), from the scatter of the averaged periods about
    /// their mean (0 where unknown).
    pub standard_error: Vec<f64>,
}

impl Measured {
    pub fn points(&self) -> Vec<ResponsePoint> {
        self.frequencies.iter().zip(&self.response).map(|(&f, &h)| ResponsePoint::from_complex(f, h, 1.0)).collect()
    }
}

/// The drive's M-sequence on the torque command for `seconds`, at constant speed.
pub fn excitation(parameters: &BTreeMap<String, Value>, amplitude: f64, seconds: f64) -> SweepRun {
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
/// `f_min` and `f_max` (from the records [`INPUT_SIGNAL`] and [`OUTPUT_SIGNAL`]).
pub fn measure(
    fmu: &Fmu,
    parameters: &BTreeMap<String, Value>,
    amplitude: f64,
    f_min: f64,
    f_max: f64,
) -> Result<Measured> {
    measure_records(fmu, parameters, amplitude, (f_min, f_max), (INPUT_SIGNAL, OUTPUT_SIGNAL))
}

/// As [`measure`], from the FMU outputs `signals` = (torque, acceleration) (the bench compares
/// the point-sampled outputs with the means).
pub fn measure_records(
    fmu: &Fmu,
    parameters: &BTreeMap<String, Value>,
    amplitude: f64,
    (f_min, f_max): (f64, f64),
    (input, output): (&str, &str),
) -> Result<Measured> {
    let chips = (1u64 << DEGREE) - 1;
    let control = configuration(parameters)?.control;
    let fs = control.rates.current_loop_hz as f64;
    let periods = PERIODS;
    // The run's own loop rate sets the period (`measurement_time_s` is the default axis's).
    let period = chips as f64 * CHIP_DIVIDER as f64 / fs;
    let run = excitation(parameters, amplitude, TRANSIENT_S + periods as f64 * period);
    let trace = run.run(fmu, |_| {})?;
    let col = |n: &str| trace.column(n).ok_or_else(|| anyhow!("the FMU has no output {n}"));
    let (measuring, u_all, y_all) = (col("acq_measuring")?, col(input)?, col(output)?);
    if let Some(trip) = crate::fmu::axis_health::first_trip(&trace)? {
        bail!("the axis tripped during the excitation: {}; lower the amplitude", trip.sentence());
    }
    excitation_within_ceiling(&TorqueLimits::of(&run.params_on(fmu)?, &run.settings), &col("torque_command_out")?)?;
    // Rows following a measuring step: one sample of each signal per acquisition period.
    let rows: Vec<usize> = (1..measuring.len()).filter(|&i| measuring[i] != 0.0).collect();
    let u: Vec<f64> = rows.iter().map(|&i| u_all[i]).collect();
    let y: Vec<f64> = rows.iter().map(|&i| y_all[i]).collect();
    let n = samples_per_period();
    let record = Record { u: &u, y: &y, acquisition_hz: fs / DIVIDER as f64 };
    averaged_response(&record, n, periods, (f_min, f_max))
}

/// The M-sequence is added to the torque command after the velocity loop's clamp: what cuts
/// it is the current clamp (kt·max_current), which the drive's torque command (`torque`, the
/// loop's torque with the sequence) reaches exactly where it acts — the sweep's rule at the
/// same injection point ([`TorqueLimits`]). Refused, naming the limit, where it does.
pub fn excitation_within_ceiling(limits: &TorqueLimits, torque: &[f64]) -> Result<()> {
    let peak = torque.iter().fold(0.0f64, |m, t| m.max(t.abs()));
    if limits.reached(peak) {
        bail!(
            "the torque command saturated at the drive's limit ({}) during the excitation, reaching {peak:.4} N·m: the excitation was cut there and the data cannot be used (lower the amplitude)",
            limits.ceiling
        );
    }
    Ok(())
}

/// Acquisition samples in one period of the M-sequence.
pub fn samples_per_period() -> usize {
    (((1u64 << DEGREE) - 1) * (CHIP_DIVIDER / DIVIDER) as u64) as usize
}

/// Noise-free run, to set the accelerometer noise for a signal-to-noise ratio.
pub fn acceleration_rms(fmu: &Fmu, parameters: &BTreeMap<String, Value>, amplitude: f64) -> Result<f64> {
    let trace = excitation(parameters, amplitude, 0.5).run(fmu, |_| {})?;
    let (m, a) = (trace.column("acq_measuring").unwrap_or_default(), trace.column(OUTPUT_SIGNAL).unwrap_or_default());
    let v: Vec<f64> = (0..a.len()).filter(|&i| m[i] != 0.0).map(|i| a[i]).collect();
    let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
    Ok((v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / v.len().max(1) as f64).sqrt())
}

/// Ratio of the frequencies either side of a candidate notch to its own: the notch's level is
/// compared with the mean of the levels at `f / NOTCH_SPAN` and `f · NOTCH_SPAN` (a straight
/// line on the Bode plot), so that a dip on a rising or falling stretch counts too (an
/// anti-resonance just below a resonance, 200 Hz on the default shaft, is 1 dB below its
/// lower side only but 4.5 dB below that line; a rigid axis's largest such dip, above its
/// shaft resonance, is 1 dB).
pub const NOTCH_SPAN: f64 = 1.15;
/// Half-width of the moving average, relative to the frequency (at least one bin each side).
pub const SMOOTHING: f64 = 0.03;
/// Whether `hz` lies within a notch's surroundings (±(`NOTCH_SPAN` − 1)) of `centre`: where a
/// zero pair can explain the notch.
pub fn within_notch_surroundings(hz: f64, centre: f64) -> bool {
    (hz / centre - 1.0).abs() <= NOTCH_SPAN - 1.0
}

/// A notch is clear from this depth (dB) and this confidence (depth over its standard error).
pub const MIN_DEPTH_DB: f64 = 2.5;
pub const MIN_CONFIDENCE: f64 = 4.0;

/// The deepest dip of the smoothed response (embodiment 4's search).
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Notch {
    /// Frequency of the smoothed minimum (Hz).
    pub hz: f64,
    /// Depth below the line between its surroundings (dB).
    pub depth_db: f64,
    /// Depth over its standard error (from the measured points' scatter about the average).
    pub confidence: f64,
    /// The band the search looked for notches in (Hz): where a notch's surroundings
    /// (±`NOTCH_SPAN`) lie inside the measured band. A notch outside it is not seen.
    pub searched_hz: (f64, f64),
}

impl Notch {
    pub fn is_clear(&self) -> bool {
        self.depth_db >= MIN_DEPTH_DB && self.confidence >= MIN_CONFIDENCE
    }

    /// The sentence for an axis the search found no clear notch on: the band searched.
    pub fn none_clear(&self) -> String {
        format!(
            "no clear anti-resonance between {:.1} and {:.1} Hz, the band searched (one outside it is not seen)",
            self.searched_hz.0, self.searched_hz.1
        )
    }

    /// Why the notch does or does not count as an anti-resonance.
    pub fn verdict(&self) -> String {
        format!(
            "deepest notch {:.1} Hz: {:.1} dB deep (needs {MIN_DEPTH_DB}), confidence {:.1} (needs {MIN_CONFIDENCE})",
            self.hz, self.depth_db, self.confidence
        )
    }
}

/// Moving average of the gain (dB) over ±`SMOOTHING`·f, with the standard error of each mean.
fn smoothed_db(m: &Measured) -> (Vec<f64>, Vec<f64>) {
    let db: Vec<f64> = m.response.iter().map(|h| 20.0 * h.norm().log10()).collect();
    let n = db.len();
    let mut mean = Vec::with_capacity(n);
    let mut error = Vec::with_capacity(n);
    for (i, &f) in m.frequencies.iter().enumerate() {
        let lo = m.frequencies.partition_point(|&x| x < f * (1.0 - SMOOTHING)).min(i.saturating_sub(1));
        let hi = m.frequencies.partition_point(|&x| x <= f * (1.0 + SMOOTHING)).max((i + 2).min(n));
        let w = &db[lo..hi];
        let k = w.len() as f64;
        let mu = w.iter().sum::<f64>() / k;
        let var = w.iter().map(|x| (x - mu).powi(2)).sum::<f64>() / (k - 1.0).max(1.0);
        mean.push(mu);
        error.push((var / k).sqrt());
    }
    (mean, error)
}

/// Linear interpolation of `v` (given at `f`) at `x` inside the range.
fn interpolate(f: &[f64], v: &[f64], x: f64) -> f64 {
    let i = f.partition_point(|&g| g < x).clamp(1, f.len() - 1);
    let t = (x - f[i - 1]) / (f[i] - f[i - 1]);
    v[i - 1] + t * (v[i] - v[i - 1])
}

/// Embodiment 4: the deepest notch of the smoothed response, if the band is wide enough to
/// see one (its surroundings must lie inside the band).
pub fn deepest_notch(m: &Measured) -> Option<Notch> {
    let f = &m.frequencies;
    if f.len() < 8 {
        return None;
    }
    let (s, se) = smoothed_db(m);
    let (first, last) = (f[0], f[f.len() - 1]);
    let searched_hz = (first * NOTCH_SPAN, last / NOTCH_SPAN);
    let mut candidates = Vec::new();
    for i in 0..f.len() {
        let (below, above) = (f[i] / NOTCH_SPAN, f[i] * NOTCH_SPAN);
        if below < first || above > last {
            continue;
        }
        let around = 0.5 * (interpolate(f, &s, below) + interpolate(f, &s, above));
        let depth = around - s[i];
        let e_around = 0.5 * (interpolate(f, &se, below).powi(2) + interpolate(f, &se, above).powi(2)).sqrt();
        let error = (se[i].powi(2) + e_around.powi(2)).sqrt().max(1e-12);
        candidates.push(Notch { hz: f[i], depth_db: depth, confidence: depth / error, searched_hz });
    }
    // The deepest of the confident dips; if none is confident, the deepest dip (to report).
    let deepest = |c: &mut dyn Iterator<Item = Notch>| c.max_by(|a, b| a.depth_db.total_cmp(&b.depth_db));
    deepest(&mut candidates.iter().copied().filter(|n| n.confidence >= MIN_CONFIDENCE))
        .or_else(|| deepest(&mut candidates.iter().copied()))
}

/// Least-squares solution of `a·x ≈ b` by SVD, with the columns scaled to unit length first
/// (their magnitudes differ by the powers of the normalised frequency), and the condition
/// number of the scaled matrix. The normal equations this replaced square that number.
fn least_squares(mut a: DMatrix<f64>, b: DVector<f64>) -> Result<(Vec<f64>, f64)> {
    let scale: Vec<f64> = a.column_iter().map(|c| c.norm()).collect();
    if scale.iter().any(|&s| !(s.is_finite() && s > 0.0)) || b.iter().any(|v| !v.is_finite()) {
        bail!("the identification equations are singular (no usable excitation in the band)");
    }
    for (mut c, s) in a.column_iter_mut().zip(&scale) {
        c /= *s;
    }
    let svd = a.svd(true, true);
    let (max, min) = (svd.singular_values.max(), svd.singular_values.min());
    if !(min > max * 1e-14) {
        bail!("the identification equations are singular (no usable excitation in the band)");
    }
    let x = svd.solve(&b, 0.0).map_err(|e| anyhow!("least squares: {e}"))?;
    Ok((x.iter().zip(&scale).map(|(v, s)| v / s).collect(), max / min))
}

/// Polynomial in s = jx at x.
pub(crate) fn poly_at(c: &[f64], x: f64) -> Complex64 {
    let s = Complex64::new(0.0, x);
    c.iter().rev().fold(Complex64::default(), |acc, &ci| acc * s + ci)
}

/// A fitted rational model `B(s)/A(s)` (s normalised by `w0`), A(0) = 1.
#[derive(Clone, Debug)]
pub struct RationalFit {
    pub w0: f64,
    pub numerator: Vec<f64>,
    pub denominator: Vec<f64>,
    pub fit_error: f64,
    /// Condition number of the last least-squares problem (columns scaled to unit length).
    pub condition: f64,
}

impl RationalFit {
    pub fn at(&self, f: f64) -> Complex64 {
        let x = std::f64::consts::TAU * f / self.w0;
        poly_at(&self.numerator, x) / poly_at(&self.denominator, x)
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
/// Sanathanan–Koerner reweighting (s normalised by the band's centre), refined by the
/// weighted output error's own minimisation ([`crate::ident::output_error_fit`]).
pub fn fit_rational(m: &Measured, band: (f64, f64), nb: usize, na: usize) -> Result<RationalFit> {
    fit_rational_near(m, band, nb, na, None)
}

/// As [`fit_rational`], the output error's minimisation also started from `near` (a fit of
/// the same orders over the same band), the lower of the two kept: a refit of a perturbed
/// measurement starts beside the fit it perturbs, where the linearised solution alone can
/// land on a pole cancelling a zero far from the notch (a local minimum of the criterion
/// three times the fit's).
pub fn fit_rational_near(
    m: &Measured,
    band: (f64, f64),
    nb: usize,
    na: usize,
    near: Option<&RationalFit>,
) -> Result<RationalFit> {
    let selected: Vec<usize> =
        (0..m.frequencies.len()).filter(|&i| m.frequencies[i] >= band.0 && m.frequencies[i] <= band.1).collect();
    let pts: Vec<(f64, Complex64)> = selected.iter().map(|&i| (m.frequencies[i], m.response[i])).collect();
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
    let mut condition = 0.0;
    for _ in 0..10 {
        // Two rows per frequency (real and imaginary parts) of
        // Σ b_i (jx)^i − H·Σ_{i≥1} a_i (jx)^i = H, each scaled by √weight.
        let mut a = DMatrix::<f64>::zeros(2 * pts.len(), unknowns);
        let mut b = DVector::<f64>::zeros(2 * pts.len());
        for (r, ((f, h), w)) in pts.iter().zip(&weight).enumerate() {
            let x = std::f64::consts::TAU * f / w0;
            let sw = w.sqrt();
            for i in 0..=nb {
                let (pr, pi) = power(x, i);
                a[(2 * r, i)] = sw * pr;
                a[(2 * r + 1, i)] = sw * pi;
            }
            for i in 1..=na {
                let (pr, pi) = power(x, i);
                let hp = h * Complex64::new(pr, pi);
                a[(2 * r, nb + i)] = -sw * hp.re;
                a[(2 * r + 1, nb + i)] = -sw * hp.im;
            }
            b[2 * r] = sw * h.re;
            b[2 * r + 1] = sw * h.im;
        }
        (theta, condition) = least_squares(a, b)?;
        let mut den = vec![1.0];
        den.extend_from_slice(&theta[nb + 1..]);
        for (((f, _), w), c) in pts.iter().zip(weight.iter_mut()).zip(&confidence) {
            *w = c / poly_at(&den, std::f64::consts::TAU * f / w0).norm_sqr();
        }
    }
    let normalised: Vec<(f64, Complex64)> = pts.iter().map(|&(f, h)| (std::f64::consts::TAU * f / w0, h)).collect();
    let (mut theta, cost) = crate::ident::output_error_fit::refined(&normalised, &confidence, nb, na, &theta);
    if let Some(near) = near.filter(|n| n.w0 == w0 && n.numerator.len() == nb + 1 && n.denominator.len() == na + 1) {
        let start: Vec<f64> = near.numerator.iter().chain(&near.denominator[1..]).copied().collect();
        let (other, other_cost) = crate::ident::output_error_fit::refined(&normalised, &confidence, nb, na, &start);
        if other_cost < cost || (cost.is_nan() && other_cost.is_finite()) {
            theta = other;
        }
    }
    let numerator = theta[..=nb].to_vec();
    let mut denominator = vec![1.0];
    denominator.extend_from_slice(&theta[nb + 1..]);
    let mut fit = RationalFit { w0, numerator, denominator, fit_error: 0.0, condition };
    fit.fit_error =
        (pts.iter().map(|(f, h)| ((fit.at(*f) - *h).norm() / h.norm()).powi(2)).sum::<f64>() / pts.len() as f64).sqrt();
    Ok(fit)
}

/// A fitted model the identification refuses (zeros in the right half plane, unstable poles,
/// no zero pair near the notch): no model file is written and `servo ident` exits with
/// status 1 and this reason.
#[derive(Clone, Debug)]
pub struct FitRefused {
    pub notch: Notch,
    pub reason: String,
}

impl std::fmt::Display for FitRefused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "fit refused: {} ({})", self.reason, self.notch.verdict())
    }
}

impl std::error::Error for FitRefused {}

/// An identified axis: its model and the notch search that decided it.
#[derive(Clone, Debug, Serialize)]
pub struct Identified {
    pub model: AxisModel,
    /// The deepest notch found (None: the band is too narrow to search).
    pub notch: Option<Notch>,
    /// Why a clear notch gave no anti-resonance: the measurement does not determine the zero
    /// pair fitted to it (see [`MAX_FREQUENCY_ERROR`]).
    pub undetermined: Option<String>,
}

/// An anti-resonance is kept when the measurement determines it within these relative errors
/// of frequency and damping (the identification's promise, 1 % and 20 %; the damping's
/// absolute below [`DAMPING_ERROR_FLOOR`]) at [`STANDARD_ERRORS`] of the refits' standard
/// errors; else the axis is reported without one (N = 1), with the fitted values, their
/// errors and the resonance that masks the notch. Over `servo bench ident`'s grid at 20 dB
/// SNR the kept ones have standard errors of at most 0.27 % and 4.0 %. Where a resonance lies
/// within 2 % of the zero (absorbers of 205 and 220 Hz on the bench's axis) the refits give
/// ± 0.2 % and ± 3–4 % while the found dampings lie up to 17 % off (two of ten seeds at 205 Hz):
/// the pole's near cancellation makes the damping sensitive to what the model's form leaves
/// out of the record, which the scatter does not show.
pub const MAX_FREQUENCY_ERROR: f64 = 0.01;
pub const MAX_DAMPING_ERROR: f64 = 0.2;
/// Below this damping ratio the damping's limit is absolute, `MAX_DAMPING_ERROR` of it
/// (0.01): the refits' absolute error hardly depends on the damping, so a relative limit
/// would throw away a sharp, well-separated notch (damping 0.005 at 4 % scatter: ± 0.10 % in
/// frequency, ± 22 % in damping).
pub const DAMPING_ERROR_FLOOR: f64 = 0.05;
/// How many standard errors the promise must hold at: a found value lies outside it about once
/// in eighty where the errors are normal. The refits' standard errors follow the found
/// values' scatter: on a well-damped absorber (damping 0.15, a notch under 3 dB) at 15–19 Hz,
/// ten noise seeds at 20 dB SNR, the frequencies scatter by 0.50 % where the refits give
/// 0.64 % on average; kept at one standard error, one of those forty came out 1.16 % off.
pub const STANDARD_ERRORS: f64 = 2.5;

/// Whether the refits' errors `e` determine an anti-resonance of damping ratio `damping`.
fn determined(e: &FactorError, damping: f64) -> bool {
    let damping_error = e.damping * damping.abs();
    STANDARD_ERRORS * e.frequency <= MAX_FREQUENCY_ERROR
        && STANDARD_ERRORS * damping_error <= MAX_DAMPING_ERROR * damping.abs().max(DAMPING_ERROR_FLOOR)
}

/// Identify one axis: look for an anti-resonance, fit. A refused fit is an error holding a
/// [`FitRefused`].
pub fn identify(axis: &str, m: &Measured) -> Result<Identified> {
    if m.frequencies.is_empty() {
        bail!("no measured frequencies");
    }
    let low_gain = {
        let n = (m.response.len() / 20).max(1);
        m.response[..n].iter().map(|h| h.norm()).sum::<f64>() / n as f64
    };
    let notch = deepest_notch(m);
    let rigid = |undetermined: Option<String>| Identified {
        model: AxisModel {
            axis: axis.into(),
            anti_resonance: None,
            resonance: None,
            gain: low_gain,
            band: (m.frequencies[0], *m.frequencies.last().unwrap_or(&0.0)),
            fit_error: 0.0,
            anti_resonance_error: None,
            fmu_parameters: BTreeMap::new(),
        },
        notch,
        undetermined,
    };
    let Some(found) = notch.filter(Notch::is_clear) else {
        return Ok(rigid(None));
    };
    let f = found.hz;
    let refuse = |reason: String| anyhow::Error::new(FitRefused { notch: found, reason });
    // Numerator: the anti-resonance pair and the shaft's real zero; denominator: the
    // absorber's and the shaft's resonances.
    let band = ((0.3 * f).max(m.frequencies[0]), (6.0 * f).min(*m.frequencies.last().unwrap_or(&f)));
    let orders = (3, 4);
    let fit = fit_rational(m, band, orders.0, orders.1)?;
    let (zeros, _) = fit.zeros();
    let (poles, _) = fit.poles();
    // The anti-resonance: the zero pair nearest the notch found.
    let zero = zeros
        .iter()
        .copied()
        .min_by(|a, b| (a.hz - f).abs().total_cmp(&(b.hz - f).abs()))
        .ok_or_else(|| refuse(format!("the fitted model has no complex zero pair near {f:.1} Hz")))?;
    // A zero pair outside the notch's surroundings does not explain it.
    if !within_notch_surroundings(zero.hz, f) {
        return Err(refuse(format!(
            "the fitted model's zero pair nearest the notch is at {:.1} Hz, {:+.0} % from it (outside ±{:.0} %): the model does not explain the notch",
            zero.hz,
            (zero.hz / f - 1.0) * 100.0,
            (NOTCH_SPAN - 1.0) * 100.0
        )));
    }
    if zero.damping < 0.0 {
        return Err(refuse(format!(
            "the identified anti-resonance at {:.1} Hz has its zeros in the right half plane (damping {:.3}): the model cannot be used",
            zero.hz, zero.damping
        )));
    }
    // Within the fitted band the data determine the poles: an unstable one there is a model
    // that cannot be used. Beyond it the fit only extrapolates (a 15 Hz notch is fitted up to
    // 90 Hz: a pole at the shaft's 260 Hz is whatever the noise leaves), so such a pole is
    // neither a refusal nor the model's resonance.
    let in_band = |p: &Factor| p.hz >= band.0 && p.hz <= band.1;
    if let Some(p) = poles.iter().find(|p| p.damping <= 0.0 && in_band(p)) {
        return Err(refuse(format!(
            "the fitted model has unstable poles at {:.1} Hz (damping {:.3})",
            p.hz, p.damping
        )));
    }
    let pole = poles.iter().copied().filter(|p| p.hz > zero.hz && p.damping > 0.0).min_by(|a, b| a.hz.total_cmp(&b.hz));
    let error = anti_resonance_error(m, band, orders, zero, &fit);
    if let Some(e) = error.filter(|e| !determined(e, zero.damping)) {
        let nearest = poles.iter().min_by(|a, b| (a.hz / zero.hz - 1.0).abs().total_cmp(&(b.hz / zero.hz - 1.0).abs()));
        let masking = nearest.filter(|p| within_notch_surroundings(p.hz, zero.hz)).map_or(String::new(), |p| {
            format!("; the fitted resonance at {:.1} Hz ({:+.1} %) masks it", p.hz, (p.hz / zero.hz - 1.0) * 100.0)
        });
        if !e.frequency.is_finite() {
            return Ok(rigid(Some(format!(
                "the measurement does not determine the notch's zero pair: fitted at {:.1} Hz, damping {:.4}, but more than a quarter of {RESAMPLES} refits under the measured scatter find no zero pair within ±{:.0} % of it{masking}",
                zero.hz,
                zero.damping,
                (NOTCH_SPAN - 1.0) * 100.0
            ))));
        }
        return Ok(rigid(Some(format!(
            "the measurement does not determine the notch's zero pair: {:.1} Hz ± {:.2} %, damping {:.4} ± {:.1} % (standard errors of {RESAMPLES} refits under the measured scatter; kept up to ± {:.2} % and ± {:.0} %, the damping's at least ± {:.4}: the promise of {:.0} % and {:.0} % at {STANDARD_ERRORS} standard errors){masking}; a larger --amplitude narrows them",
            zero.hz,
            e.frequency * 100.0,
            zero.damping,
            e.damping * 100.0,
            MAX_FREQUENCY_ERROR / STANDARD_ERRORS * 100.0,
            MAX_DAMPING_ERROR / STANDARD_ERRORS * 100.0,
            MAX_DAMPING_ERROR * DAMPING_ERROR_FLOOR / STANDARD_ERRORS,
            MAX_FREQUENCY_ERROR * 100.0,
            MAX_DAMPING_ERROR * 100.0,
        ))));
    }
    let model = AxisModel {
        axis: axis.into(),
        anti_resonance: Some(zero),
        resonance: pole,
        gain: fit.numerator[0],
        band,
        fit_error: fit.fit_error,
        anti_resonance_error: error,
        fmu_parameters: BTreeMap::new(),
    };
    Ok(Identified { model, notch, undetermined: None })
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Torque → acceleration of a known model: gain · zero pair · real zero / (two pole pairs),
    /// evaluated from its factors, on the measurement's frequency grid.
    fn synthetic(zero: Factor, real_zero_hz: f64, poles: [Factor; 2]) -> Measured {
        let df = 4000.0 / 8188.0;
        let frequencies: Vec<f64> = (11..1024).map(|k| k as f64 * df).collect();
        let response = frequencies
            .iter()
            .map(|&f| {
                let real = Complex64::new(1.0, f / real_zero_hz);
                zero.at(f) * real / (poles[0].at(f) * poles[1].at(f)) * 4000.0
            })
            .collect();
        let input_power = vec![1.0; frequencies.len()];
        let standard_error = vec![0.0; frequencies.len()];
        Measured { frequencies, response, input_power, standard_error }
    }

    #[test]
    fn an_anti_resonance_is_recovered_from_its_exact_response() {
        for hz in [15.0, 60.0, 300.0] {
            let truth = Factor { hz, damping: 0.05 };
            let m = synthetic(
                truth,
                1500.0,
                [Factor { hz: 1.3 * hz, damping: 0.06 }, Factor { hz: 260.0 * 1.7, damping: 0.08 }],
            );
            let found = identify("x", &m).expect("identified");
            let notch = found.notch.expect("a notch");
            assert!(notch.is_clear(), "{hz} Hz: {notch:?}");
            let z = found.model.anti_resonance.expect("an anti-resonance");
            assert!((z.hz - hz).abs() < 1e-6 * hz && (z.damping - 0.05).abs() < 1e-6, "{hz} Hz: {z:?}");
        }
    }

    #[test]
    fn a_rigid_response_has_no_clear_notch_and_says_why() {
        // No zero pair: one shaft resonance (a peak, no dip).
        let m = synthetic(
            Factor { hz: 1e9, damping: 1.0 },
            1500.0,
            [Factor { hz: 260.0, damping: 0.05 }, Factor { hz: 1e9, damping: 1.0 }],
        );
        let found = identify("w", &m).expect("a rigid model");
        assert!(found.model.anti_resonance.is_none());
        let notch = found.notch.expect("searched");
        assert!(notch.depth_db < MIN_DEPTH_DB, "{notch:?}");
        assert!(notch.verdict().contains("dB deep"), "{}", notch.verdict());
    }

    #[test]
    fn zeros_in_the_right_half_plane_are_refused_with_the_reason() {
        let m = synthetic(
            Factor { hz: 40.0, damping: -0.05 },
            1500.0,
            [Factor { hz: 52.0, damping: 0.06 }, Factor { hz: 440.0, damping: 0.08 }],
        );
        let e = identify("y", &m).unwrap_err();
        let refused = e.downcast_ref::<FitRefused>().expect("a refusal, not another error");
        assert!(refused.reason.contains("right half plane"), "{}", refused.reason);
    }

    /// A resonance 2.5 % above the zero (a 2.7 dB notch, still clear) and the measured scatter
    /// decide: at 10 % of |H| on every frequency the refits determine the zero to 0.2 % and it
    /// is kept; at 30 % they scatter by 0.67 % and 18 % (within the promise at one standard
    /// error, not at [`STANDARD_ERRORS`]) and the axis is reported without one, with the fitted
    /// values and the masking resonance.
    #[test]
    fn a_zero_the_measurement_does_not_determine_is_not_kept() {
        let with_scatter = |scatter: f64| {
            let mut m = synthetic(
                Factor { hz: 200.0, damping: 0.05 },
                1500.0,
                [Factor { hz: 205.0, damping: 0.05 }, Factor { hz: 330.0, damping: 0.08 }],
            );
            m.standard_error = m.response.iter().map(|h| scatter * h.norm()).collect();
            m
        };
        let kept = identify("x", &with_scatter(0.1)).expect("identified");
        let e = kept.model.anti_resonance_error.expect("errors from the scatter");
        assert!(kept.model.anti_resonance.is_some() && kept.undetermined.is_none(), "{kept:?}");
        assert!(STANDARD_ERRORS * e.frequency <= MAX_FREQUENCY_ERROR && e.frequency > 0.001, "{e:?}");
        let masked = identify("x", &with_scatter(0.3)).expect("reported");
        let n = masked.notch.filter(Notch::is_clear).expect("the synthetic pair leaves a clear notch");
        assert!(masked.model.anti_resonance.is_none(), "{n:?}: {:?}", masked.model);
        let why = masked.undetermined.expect("the reason");
        assert!(why.contains("does not determine") && why.contains("masks it"), "{why}");
        // The frequency's standard error it names lies between the rule's limit and the
        // promise at one standard error, and the damping's within the promise at one.
        let named = |after: &str| -> f64 {
            why.split(after).nth(1).and_then(|t| t.split(' ').next()).unwrap().parse().unwrap()
        };
        let (frequency, damping) = (named("Hz ± "), named("damping 0.0500 ± "));
        assert!(frequency > 100.0 * MAX_FREQUENCY_ERROR / STANDARD_ERRORS, "{why}");
        assert!(frequency < 100.0 * MAX_FREQUENCY_ERROR, "{why}");
        assert!(damping < 100.0 * MAX_DAMPING_ERROR, "{why}");
        assert!(why.contains("kept up to ± 0.40 % and ± 8 %"), "{why}");
    }

    /// Under scatter too: zeros just inside the right half plane are refused (the damping's
    /// relative error there is huge, which must not turn them into an "undetermined" axis with
    /// exit status 0), and a sharp, well-separated zero (damping 0.005) is kept although its
    /// damping's relative error exceeds 20 %.
    #[test]
    fn scatter_neither_hides_right_half_plane_zeros_nor_drops_a_sharp_notch() {
        let with_scatter = |zero: Factor| {
            let mut m =
                synthetic(zero, 1500.0, [Factor { hz: 78.0, damping: 0.06 }, Factor { hz: 442.0, damping: 0.08 }]);
            m.standard_error = m.response.iter().map(|h| 0.04 * h.norm()).collect();
            m
        };
        let e = identify("y", &with_scatter(Factor { hz: 60.0, damping: -0.002 })).unwrap_err();
        let refused = e.downcast_ref::<FitRefused>().expect("a refusal, not an undetermined axis");
        assert!(refused.reason.contains("right half plane"), "{}", refused.reason);
        let sharp = identify("x", &with_scatter(Factor { hz: 60.0, damping: 0.005 })).expect("identified");
        let z = sharp.model.anti_resonance.expect("kept");
        assert!((z.hz / 60.0 - 1.0).abs() < 0.01, "{z:?}");
    }
}
