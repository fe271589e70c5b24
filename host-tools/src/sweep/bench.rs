//! `servo bench sweep`: the figures of the frequency-response issue (seed 000), on the default
//! axis: velocity loop 8 kHz, acquisition 4 kHz, 10 Hz to 3 kHz (plus 2 kHz exactly),
//! velocity-command injection riding on 50 rad/s.
//!
//! - errors against the oracle below and above 2 kHz, with phase shifting (ours) and without
//!   (the same records all at phase 0: the same measurement time), and the 2 kHz point itself;
//! - simulated measurement time of the full Bode;
//! - PRBS with an H1 (Welch) estimate over the same measurement time;
//! - the analytic linear model of the loop at low frequencies;
//! - with current-sensor noise: error against measurement time, ours against PRBS.
//!
//! The headline runs have [`DITHER_A`] of current-sensor noise. On a noise-free simulated
//! encoder at constant speed the count pattern is periodic and locks to the excitation: both
//! ours and the oracle then carry a quantisation error that depends on the excitation's
//! starting phase and does not shrink with longer records (about 0.25 dB at 3 kHz, −24.6 dB).
//! A real drive's current noise breaks the lock, as a 16 times finer encoder removes the
//! error; both are printed beside the headline.

use servo_axis::variables::name;
use std::collections::BTreeMap;

use anyhow::{anyhow, Result};
use control_core::phase_shifted_sweep::{SweepParams, SweepSignal};
use serde::Serialize;

use crate::analysis::response_point::ResponsePoint;
use crate::analysis::spectral::Complex;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::SweepRun;
use crate::sweep::measurement::{errors, measured_time, online_results, prbs_results, stream_results, ErrorSummary};
use crate::sweep::report::oracle_settings;

pub const VELOCITY: f64 = 50.0;
/// Current-sensor noise of the headline runs (A, standard deviation): about one count of a
/// 12-bit converter on the board's current range.
pub const DITHER_A: f64 = 0.01;
/// Encoder of the fine-encoder check (counts per revolution; the default is 2^20).
pub const FINE_ENCODER: i64 = 1 << 24;
/// Welch segment (samples at 4 kHz): 1 s, 1 Hz bins.
pub const SEGMENT: usize = 4096;

#[derive(Clone, Debug, Serialize)]
pub struct MethodErrors {
    pub method: String,
    pub measurement_time_s: f64,
    pub errors: ErrorSummary,
    /// Frequencies the method could not measure (non-finite result).
    pub unmeasured: Vec<f64>,
}

#[derive(Clone, Debug, Serialize)]
pub struct NoisePoint {
    pub measurement_time_s: f64,
    /// Largest error up to 1.9 kHz (where PRBS at 4 kHz acquisition still works): dB, deg.
    pub ours: (f64, f64),
    pub prbs: (f64, f64),
}

#[derive(Clone, Debug, Serialize)]
pub struct SweepBench {
    pub ours: MethodErrors,
    pub single_phase: MethodErrors,
    pub prbs: MethodErrors,
    /// The 2 kHz point: oracle, ours, single phase.
    pub at_nyquist: [ResponsePoint; 3],
    /// Largest |stream − on-line| difference of our run (dB, deg).
    pub stream_vs_online: (f64, f64),
    /// Analytic model against the oracle up to 30 Hz: largest dB, deg.
    pub analytic_low_frequency: (f64, f64),
    pub noise_std_a: f64,
    pub noise: Vec<NoisePoint>,
    /// Current-sensor noise of the headline runs (A).
    pub dither_a: f64,
    /// Ours against the oracle on a noise-free plant: the locked quantisation pattern.
    pub noise_free: ErrorSummary,
    /// The same with a 2^24-count encoder: the method's own accuracy.
    pub fine_encoder: ErrorSummary,
    /// Riding speeds of the spread check (rad/s) and the worst error over them (dB, deg)
    /// with fixed records and with records lengthened for precision.
    pub spread_speeds: Vec<f64>,
    pub spread_fixed: (f64, f64),
    pub spread_lengthened: (f64, f64),
}

/// Riding speeds of the spread check: the quantisation pattern, so the error at a low-gain
/// point, changes with them.
pub const SPREAD_SPEEDS: [f64; 6] = [49.0, 49.5, 50.0, 50.5, 51.0, 52.0];

fn base(parameters: BTreeMap<String, Value>, settings: SweepParams) -> SweepRun {
    SweepRun { settings, parameters, velocity: VELOCITY }
}

fn unmeasured(points: &[ResponsePoint]) -> Vec<f64> {
    points.iter().filter(|p| !(p.gain_db.is_finite() && p.phase_deg.is_finite())).map(|p| p.frequency).collect()
}

/// Largest gain/phase error up to `max_hz`.
fn worst_up_to(a: &[ResponsePoint], reference: &[ResponsePoint], max_hz: f64) -> (f64, f64) {
    let e = errors(&a.iter().copied().filter(|p| p.frequency <= max_hz).collect::<Vec<_>>(), reference, f64::INFINITY);
    (e.below_gain_db, e.below_phase_deg)
}

/// Closed velocity loop of the default axis, linearised: PI velocity controller, two-inertia
/// plant (motor side), backward-difference velocity estimate (half a velocity period of
/// delay) and one and a half base ticks of torque delay (computation and PWM hold).
pub fn analytic_closed_loop(f: f64) -> ResponsePoint {
    let p = control_core::Params::default();
    let plant = servo_axis::plant::PlantParams::default();
    let w = std::f64::consts::TAU * f;
    let s = Complex::new(0.0, w);
    let (jm, jl, k, c) = (plant.motor_inertia, plant.load_inertia, plant.shaft_stiffness, plant.shaft_damping);
    let (bm, bl) = (plant.motor_viscous, plant.load_viscous);
    // Motor velocity / torque: (JL s + bl + (cs + k)/s) / ((Jm s + bm)(JL s + bl) + (Jm s + bm + JL s + bl)(cs + k)/s).
    let spring = Complex::new(k, c * w).div(s);
    let load = s.scale(jl).add(Complex::new(bl, 0.0));
    let motor = s.scale(jm).add(Complex::new(bm, 0.0));
    let plant_tf = load.add(spring).div(motor.mul(load).add(motor.add(load).mul(spring)));
    let controller = Complex::new(p.velocity.kp as f64, 0.0).add(Complex::new(p.velocity.ki as f64, 0.0).div(s));
    let delay = |t: f64| Complex::new((w * t).cos(), -(w * t).sin());
    let tick = 1.0 / p.rates.current_loop_hz as f64;
    let feedback = delay(0.5 * p.rates.velocity_period() as f64);
    let forward = controller.mul(plant_tf).mul(delay(1.5 * tick));
    let loop_gain = forward.mul(feedback);
    let t = loop_gain.div(Complex::new(1.0, 0.0).add(loop_gain));
    ResponsePoint::from_complex(f, t, 1.0)
}

pub fn bench(fmu: &Fmu, noise_std: f64, mut progress: impl FnMut(f64)) -> Result<SweepBench> {
    let fs = control_core::Params::default().rates.current_loop_hz;
    let ours_settings = SweepParams::default();
    let split = ours_settings.threshold(fs) as f64;
    let clean: BTreeMap<String, Value> =
        [(name::plant_current_noise_std.to_string(), Value::Float(DITHER_A))].into_iter().collect();
    progress(0.0);
    let oracle_run = base(clean.clone(), oracle_settings(&ours_settings));
    let oracle = online_results(&oracle_run.run(fmu, |_| {})?)?;
    progress(0.2);
    let ours_run = base(clean.clone(), ours_settings);
    let ours_trace = ours_run.run(fmu, |_| {})?;
    let ours = stream_results(&ours_trace, &ours_settings)?;
    let online = online_results(&ours_trace)?;
    let stream_vs_online =
        ours.iter().zip(&online).filter(|(a, _)| a.quality > 0.01).fold((0.0f64, 0.0f64), |(g, p), (a, b)| {
            let (dg, dp) = crate::analysis::response_point::difference(a, b);
            (g.max(dg.abs()), p.max(dp.abs()))
        });
    progress(0.35);
    let single_settings = SweepParams { shifts: 1, ..ours_settings };
    let single_run = base(clean.clone(), single_settings);
    let single_trace = single_run.run(fmu, |_| {})?;
    let single = stream_results(&single_trace, &single_settings)?;
    progress(0.5);
    let time = measured_time(&ours_trace)?;
    // Chips at half the acquisition rate (2 kHz): every chip is seen by two samples, none
    // between them; the hold between samples is divided out (see `prbs_results`).
    let prbs_settings = SweepParams {
        signal: SweepSignal::Prbs,
        prbs_seconds: time as f32,
        amplitude: 2.0,
        prbs_divider: 2 * ours_settings.acquisition_divider,
        ..ours_settings
    };
    let prbs_run = base(clean.clone(), prbs_settings);
    let frequencies: Vec<f64> = oracle.iter().map(|p| p.frequency).collect();
    let prbs = prbs_results(&prbs_run.run(fmu, |_| {})?, &prbs_run, &frequencies, SEGMENT)?;
    progress(0.6);
    let find = |v: &[ResponsePoint], f: f64| {
        v.iter().copied().find(|p| (p.frequency - f).abs() < 1e-3).ok_or_else(|| anyhow!("no {f} Hz point"))
    };
    let at_nyquist = [find(&oracle, 2000.0)?, find(&ours, 2000.0)?, find(&single, 2000.0)?];
    let analytic: Vec<ResponsePoint> =
        oracle.iter().filter(|p| p.frequency <= 30.0).map(|p| analytic_closed_loop(p.frequency)).collect();
    let analytic_low_frequency = worst_up_to(&analytic, &oracle, 30.0);

    // Noise: our sweep with longer records against PRBS over the same time.
    let noisy: BTreeMap<String, Value> =
        [(name::plant_current_noise_std.to_string(), Value::Float(noise_std))].into_iter().collect();
    let mut noise = Vec::new();
    for (i, scale) in [1.0f32, 2.0, 4.0].iter().enumerate() {
        let settings = SweepParams {
            measure_cycles: ours_settings.measure_cycles * scale,
            min_measure_s: ours_settings.min_measure_s * scale,
            ..ours_settings
        };
        let run = base(noisy.clone(), settings);
        let noisy_trace = run.run(fmu, |_| {})?;
        let ours_noisy = stream_results(&noisy_trace, &settings)?;
        let t = measured_time(&noisy_trace)?;
        let p_settings = SweepParams { prbs_seconds: t as f32, ..prbs_settings };
        let p_run = base(noisy.clone(), p_settings);
        let prbs_noisy = prbs_results(&p_run.run(fmu, |_| {})?, &p_run, &frequencies, SEGMENT)?;
        noise.push(NoisePoint {
            measurement_time_s: t,
            ours: worst_up_to(&ours_noisy, &oracle, 1900.0),
            prbs: worst_up_to(&prbs_noisy, &oracle, 1900.0),
        });
        progress(0.6 + 0.1 * (i + 1) as f64);
    }
    // Ours (each of `settings`) against the oracle, riding on `velocity` with `parameters`.
    let against_oracle = |parameters: &BTreeMap<String, Value>,
                          velocity: f64,
                          settings: &[SweepParams]|
     -> Result<Vec<ErrorSummary>> {
        let at = |settings: SweepParams| SweepRun { settings, parameters: parameters.clone(), velocity };
        let oracle = online_results(&at(oracle_settings(&ours_settings)).run(fmu, |_| {})?)?;
        settings.iter().map(|s| Ok(errors(&stream_results(&at(*s).run(fmu, |_| {})?, s)?, &oracle, split))).collect()
    };
    // The same measurement without the dither, and without it on a finer encoder.
    let noise_free = against_oracle(&BTreeMap::new(), VELOCITY, &[ours_settings])?[0];
    progress(0.8);
    let fine: BTreeMap<String, Value> =
        [(name::plant_encoder_counts_per_rev.to_string(), Value::Int(FINE_ENCODER))].into_iter().collect();
    let fine_encoder = against_oracle(&fine, VELOCITY, &[ours_settings])?[0];
    progress(0.85);
    // Worst error over riding speeds, with fixed and with lengthened records.
    let fixed_settings = SweepParams { precision_db: 0.0, ..ours_settings };
    let (mut spread_fixed, mut spread_lengthened) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
    for (i, &v) in SPREAD_SPEEDS.iter().enumerate() {
        let e = against_oracle(&clean, v, &[fixed_settings, ours_settings])?;
        for (e, worst) in e.iter().zip([&mut spread_fixed, &mut spread_lengthened]) {
            worst.0 = worst.0.max(e.below_gain_db).max(e.above_gain_db);
            worst.1 = worst.1.max(e.below_phase_deg).max(e.above_phase_deg);
        }
        progress(0.85 + 0.15 * (i + 1) as f64 / SPREAD_SPEEDS.len() as f64);
    }
    Ok(SweepBench {
        ours: MethodErrors {
            method: "phase-shifted stepped sine".into(),
            measurement_time_s: time,
            errors: errors(&ours, &oracle, split),
            unmeasured: unmeasured(&ours),
        },
        single_phase: MethodErrors {
            method: "single-phase stepped sine (same records, all at phase 0)".into(),
            measurement_time_s: measured_time(&single_trace)?,
            errors: errors(&single, &oracle, split),
            unmeasured: unmeasured(&single),
        },
        prbs: MethodErrors {
            method: format!("PRBS 2 kHz chips, H1 Welch ({SEGMENT}-sample Hann)"),
            measurement_time_s: prbs_run.measurement_time()?,
            errors: errors(&prbs, &oracle, split),
            unmeasured: frequencies.iter().copied().filter(|f| !prbs.iter().any(|p| p.frequency == *f)).collect(),
        },
        at_nyquist,
        stream_vs_online,
        analytic_low_frequency,
        noise_std_a: noise_std,
        noise,
        dither_a: DITHER_A,
        noise_free,
        fine_encoder,
        spread_speeds: SPREAD_SPEEDS.to_vec(),
        spread_fixed,
        spread_lengthened,
    })
}
