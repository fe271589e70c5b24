//! How well a sweep's standard errors ([`crate::sweep::standard_error`]) predict its actual
//! errors (`servo bench sweep --detail`): on a noisy, lightly damped axis, over several noise
//! seeds, every result's error against the oracle divided by its standard error. A calibrated
//! error gives a root mean square of that ratio near 1 (under 1: the errors are pessimistic,
//! over: a user trusts points the noise moved).

use anyhow::Result;
use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::SweepParams;
use serde::Serialize;

use crate::analysis::response_point::{difference, same_frequency};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::SweepRun;
use crate::sweep::bench::{PlantCase, DITHER_A, VELOCITY};
use crate::sweep::measurement::{online_results, stream_results, stream_standard_errors, unmeasurable};
use crate::sweep::report::oracle_run;
use servo_axis::variables::name;

/// The axis: a light load (0.303 of the motor's inertia) on a soft shaft (53.2 Hz), whose
/// lightly damped mode the current-sensor noise ([`DITHER_A`]) rings: colored noise in the
/// band of the sweep's lower frequencies.
pub const CALIBRATION_PLANT: PlantCase = PlantCase { inertia_ratio: 0.303, resonance_hz: Some(53.2) };

/// Noise seeds of each case (1..=this).
pub const CALIBRATION_SEEDS: u32 = 10;

/// One sweep setting's calibration over the seeds.
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationCase {
    pub label: String,
    /// Results compared (measurable, with a finite standard error), over all seeds.
    pub results: usize,
    /// Root mean square of error / standard error: gain, phase; the reported error's and the
    /// model's alone.
    pub gain_ratio_rms: f64,
    pub phase_ratio_rms: f64,
    pub model_gain_ratio_rms: f64,
    pub model_phase_ratio_rms: f64,
    /// Results off by more than three standard errors: gain, phase.
    pub beyond_three: (usize, usize),
    /// Root mean square of the errors (dB, deg) and of the standard errors (dB, deg).
    pub error_rms: (f64, f64),
    pub standard_error_rms: (f64, f64),
}

/// The cases: the drive's defaults, and without settling (no settling time, no minimum
/// record: up to 1 kHz, where two cycles still hold 8 samples; and over the full range with
/// the shortest minimum record that lets 3 kHz through, 3 ms).
fn cases() -> Vec<(&'static str, SweepParams)> {
    let defaults = SweepParams { point: InjectionPoint::VelocityFeedback, amplitude: 2.0, ..SweepParams::default() };
    let unsettled = SweepParams { min_measure_s: 0.0, min_settle_s: 0.0, settle_cycles: 0.0, ..defaults };
    vec![
        ("defaults, 10 Hz to 3 kHz", defaults),
        (
            "--min-measure 0 --min-settle 0 --settle-cycles 0 --stop 1000",
            SweepParams { stop_hz: 1000.0, extra_hz: 0.0, ..unsettled },
        ),
        ("--min-measure 0.003 --min-settle 0 --settle-cycles 0", SweepParams { min_measure_s: 0.003, ..unsettled }),
    ]
}

/// Every case on [`CALIBRATION_PLANT`] at the velocity feedback, [`CALIBRATION_SEEDS`] seeds.
pub fn calibration(fmu: &Fmu, mut progress: impl FnMut(f64)) -> Result<Vec<CalibrationCase>> {
    let cases = cases();
    let total = (cases.len() as u32 * (CALIBRATION_SEEDS + 1)) as f64;
    let mut done = 0.0;
    let mut out = Vec::new();
    for (label, settings) in cases {
        let mut parameters = CALIBRATION_PLANT.parameters();
        parameters.insert(name::plant_current_noise_std.to_string(), Value::Float(DITHER_A));
        let oracle_of = SweepRun { settings, parameters: parameters.clone(), velocity: VELOCITY };
        let oracle = online_results(&oracle_run(&oracle_of)?.run(fmu, |_| {})?)?;
        done += 1.0;
        progress(done / total);
        let mut ratios = Ratios::default();
        for seed in 1..=CALIBRATION_SEEDS {
            parameters.insert(name::plant_noise_seed.to_string(), Value::Int(seed as i64));
            let run = SweepRun { settings, parameters: parameters.clone(), velocity: VELOCITY };
            let trace = run.run(fmu, |_| {})?;
            let stream = stream_results(&trace, &settings)?;
            for (p, e) in stream.iter().zip(stream_standard_errors(&trace)?) {
                let Some(o) = oracle.iter().find(|o| same_frequency(o.frequency, p.frequency)) else { continue };
                if unmeasurable(p) || unmeasurable(o) || !(e.gain_db.is_finite() && e.phase_deg.is_finite()) {
                    continue;
                }
                ratios.add(difference(p, o), &e);
            }
            done += 1.0;
            progress(done / total);
        }
        out.push(ratios.case(label));
    }
    Ok(out)
}

/// Sums of squares of the ratios and the errors.
#[derive(Default)]
struct Ratios {
    n: usize,
    gain: f64,
    phase: f64,
    /// The model's, over the results where it is positive (it can be 0: a lag-one correlation
    /// that cancels the variance), with their counts.
    model_gain: (f64, usize),
    model_phase: (f64, usize),
    beyond: (usize, usize),
    error: (f64, f64),
    se: (f64, f64),
}

impl Ratios {
    fn add(&mut self, (dg, dp): (f64, f64), e: &crate::sweep::standard_error::ResponseStandardError) {
        let (zg, zp) = (dg / e.gain_db, dp / e.phase_deg);
        self.n += 1;
        self.gain += zg * zg;
        self.phase += zp * zp;
        for (sum, error, se) in
            [(&mut self.model_gain, dg, e.model_gain_db), (&mut self.model_phase, dp, e.model_phase_deg)]
        {
            if se > 0.0 {
                *sum = (sum.0 + (error / se).powi(2), sum.1 + 1);
            }
        }
        self.beyond.0 += (zg.abs() > 3.0) as usize;
        self.beyond.1 += (zp.abs() > 3.0) as usize;
        self.error = (self.error.0 + dg * dg, self.error.1 + dp * dp);
        self.se = (self.se.0 + e.gain_db * e.gain_db, self.se.1 + e.phase_deg * e.phase_deg);
    }

    fn case(&self, label: &str) -> CalibrationCase {
        let rms = |s: f64| (s / self.n.max(1) as f64).sqrt();
        let rms_of = |(s, n): (f64, usize)| (s / n.max(1) as f64).sqrt();
        CalibrationCase {
            label: label.to_string(),
            results: self.n,
            gain_ratio_rms: rms(self.gain),
            phase_ratio_rms: rms(self.phase),
            model_gain_ratio_rms: rms_of(self.model_gain),
            model_phase_ratio_rms: rms_of(self.model_phase),
            beyond_three: self.beyond,
            error_rms: (rms(self.error.0), rms(self.error.1)),
            standard_error_rms: (rms(self.se.0), rms(self.se.1)),
        }
    }
}

/// The cases as `servo bench sweep --detail` prints them.
pub fn print_calibration(cases: &[CalibrationCase]) {
    let plant = &CALIBRATION_PLANT;
    println!(
        "  standard error calibration (servo sweep's ± dB / ± deg): velocity feedback, J_L/J_M {}, {} Hz shaft, current-sensor noise {DITHER_A} A, seeds 1..={CALIBRATION_SEEDS}; RMS of error vs oracle / standard error (1: calibrated):",
        plant.inertia_ratio,
        plant.resonance_hz.unwrap_or(f64::NAN)
    );
    println!(
        "  {:<62} {:>7} {:>15} {:>15} {:>10} {:>17} {:>17}",
        "settings", "results", "gain (model)", "phase (model)", "beyond 3σ", "RMS error dB/deg", "RMS SE dB/deg"
    );
    for c in cases {
        println!(
            "  {:<62} {:>7} {:>6.2} ({:>5.2}) {:>6.2} ({:>5.2}) {:>4} / {:<3} {:>8.4} / {:<6.3} {:>8.4} / {:<6.3}",
            c.label,
            c.results,
            c.gain_ratio_rms,
            c.model_gain_ratio_rms,
            c.phase_ratio_rms,
            c.model_phase_ratio_rms,
            c.beyond_three.0,
            c.beyond_three.1,
            c.error_rms.0,
            c.error_rms.1,
            c.standard_error_rms.0,
            c.standard_error_rms.1
        );
    }
}
