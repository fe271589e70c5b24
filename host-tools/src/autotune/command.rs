//! `servo autotune`: the velocity loop tuned from the axis's own measured response, on the
//! FMU's twin. A torque-point sweep measures the plant; the machine's mechanics are
//! calibrated from it; the velocity PI, torque low-pass and notch are designed on the
//! calibrated model for the widest bandwidth within the margins; and the design is verified
//! on the twin by a feedback-point sweep (the open loop measured with the new gains).

use std::fmt::Write as _;

use anyhow::{Context, Result};
use num_complex::Complex64;
use serde_json::json;

use super::calibration::calibrate;
use super::design::{design, MarginGoal, SearchGrid};
use super::design_checks::{check_determined, check_linear, check_resonance_measured};
use super::drive_dynamics::DriveDynamics;
use super::margins::{crossover_margins, log_grid};
use super::responses::{plot_loops, LoopModel, Responses};
use super::velocity_controller::VelocityTuning;
use super::{disturbance_response, loop_plant, plant_points, plant_response, sweep_on_fmu};
use crate::analysis::response_point::ResponsePoint;
use crate::cli::{progress_bar, Common};
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::paths::{default_fmu, default_out};

/// Tune the velocity loop from the axis's measured response: a torque-point sweep on the
/// twin measures the plant (torque command → velocity estimate), the machine's mechanics
/// (motor and load inertia, shaft stiffness and damping) are calibrated from it with their
/// standard errors, and the velocity PI, the torque low-pass and a notch on the resonance are
/// designed on the calibrated model for the widest closed-loop bandwidth whose loop keeps
/// its margins (--margin). The design is then verified on the twin: a feedback-point sweep
/// with the new gains measures the open loop, whose crossover and phase margin are printed
/// beside the design's. Writes autotune.toml (the ctrl.* parameters, for a scenario's
/// [parameters] or --set), calibrated-plant.toml (the plant.* parameters of the calibrated
/// twin), autotune.json, plant.svg, open-loop.svg, nyquist.svg (the open loop near −1 with
/// the Ms circle), closed-loop.svg, step.svg (the velocity step predicted, tuned and before,
/// and measured on the twin) and disturbance.svg (a load step at the motor, predicted). Exit
/// status 1 when the verification misses the margins.
///
/// Example: servo autotune --set plant.load_inertia=4.5e-4 --set plant.shaft_stiffness=60
#[derive(clap::Args)]
pub struct AutotuneArgs {
    /// Margins the design keeps: conservative (Ms 1.3), standard (Ms 1.6) or aggressive
    /// (Ms 2.0), each with a phase margin of at least 45° and a gain margin of 6 dB
    #[arg(long, default_value = "standard")]
    pub margin: String,
    /// Plant file of the twin's machine (as `servo calibrate` writes it: the calibrated
    /// twin); --set applies over it
    #[arg(long)]
    pub plant: Option<std::path::PathBuf>,
    /// FMU parameter NAME=VALUE (repeatable): the twin's machine, e.g. plant.load_inertia=3e-4
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Torque amplitude of the plant's sweep (N·m)
    #[arg(long, default_value_t = 0.2)]
    pub amplitude: f64,
    /// Constant speed the sweeps ride on (rad/s; keeps friction on one side)
    #[arg(long, default_value_t = 50.0)]
    pub velocity: f64,
    #[command(flatten)]
    pub common: Common,
}

impl AutotuneArgs {
    pub fn run(&self) -> Result<bool> {
        use control_core::excitation::InjectionPoint;
        let goal = MarginGoal::named(&self.margin).ok_or_else(|| {
            anyhow::anyhow!("--margin must be conservative, standard or aggressive (got `{}`)", self.margin)
        })?;
        super::design_checks::check_riding_speed(self.velocity)?;
        if !(self.amplitude.is_finite() && self.amplitude > 0.0) {
            anyhow::bail!("--amplitude must be a positive torque (N·m), got {}", self.amplitude);
        }
        let parameters = crate::fmu::plant_file::machine_parameters(self.plant.as_deref(), &self.set)?;
        let params = configuration(&parameters)?.control;
        let period = params.rates.velocity_period() as f64;
        let out = self.common.out.clone().unwrap_or_else(|| default_out("autotune"));
        std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        let fmu = Fmu::load(&self.common.fmu.clone().unwrap_or_else(default_fmu))?;
        let pb = progress_bar("autotune", self.common.json);
        pb.set_position(50);
        // 1. The plant, measured.
        let sweep = sweep_on_fmu(&fmu, InjectionPoint::TorqueCommand, self.amplitude, &parameters, self.velocity)
            .context("the torque-point sweep")?;
        check_linear(&sweep, self.amplitude)?;
        let measured = sweep.points;
        pb.set_position(400);
        // 2. The mechanics, calibrated (from the plant behind the sweep's readings).
        let drive = DriveDynamics::as_configured(&params);
        let before = VelocityTuning::of_params(&params);
        let points = plant_points(&measured, &drive, &before);
        let c = calibrate(&points, &drive).context("calibrating the mechanics")?;
        check_determined(&c)?;
        check_resonance_measured(&c, points.iter().map(|p| p.hz).fold(0.0, f64::max))?;
        let m = c.mechanics;
        // 3. The design on the calibrated model.
        let model = |f: f64| loop_plant(&drive, &m, f);
        let d =
            design(&model, period, &goal.with_reserve(), &SearchGrid::STANDARD, &m.features_hz()).ok_or_else(|| {
                anyhow::anyhow!("no velocity-loop design keeps the {} margins on the calibrated model", self.margin)
            })?;
        pb.set_position(550);
        // 4. Verified on the twin: the open loop measured with the new gains.
        let mut tuned = parameters.clone();
        for (k, v) in d.tuning.parameters() {
            tuned.insert(k, Value::Float(v));
        }
        let open_loop = sweep_on_fmu(&fmu, InjectionPoint::VelocityFeedback, 2.0, &tuned, self.velocity)
            .context("the feedback-point sweep with the new gains")?
            .points;
        pb.set_position(900);
        // The time responses: predicted on the model (tuned and before), a step on the twin.
        let before = VelocityTuning::of_params(&params);
        let disturbance = |f: f64| disturbance_response(&drive, &m, f);
        let loop_model = LoopModel { plant: &model, disturbance: &disturbance, period };
        let responses = Responses::of(&fmu, &tuned, &d.tuning, &before, &loop_model, self.velocity)?;
        pb.finish_and_clear();
        let hz: Vec<f64> = open_loop.iter().map(|p| p.frequency).collect();
        let l: Vec<Complex64> = open_loop.iter().map(ResponsePoint::to_complex).collect();
        // The margins a sparse measured grid can show: the phase margin at its gain crossovers
        // and the sensitivity peak over the measured points (the stability and the gain
        // margin need the model's dense grid). A sweep that measured no crossover has not
        // shown a margin: it fails (NaN compares false).
        let (measured_pm, measured_ms) = crossover_margins(&hz, &l);
        let ok = measured_pm >= goal.phase_margin_deg && measured_ms <= goal.sensitivity_peak;
        // Files.
        let mut toml = String::from("# servo autotune: the velocity loop's gains and torque filters\n[parameters]\n");
        for (k, v) in d.tuning.parameters() {
            writeln!(toml, "\"{k}\" = {v:e}")?;
        }
        std::fs::write(out.join("autotune.toml"), &toml)?;
        crate::fmu::plant_file::write_plant_file(
            &out.join("calibrated-plant.toml"),
            "servo autotune: the twin's mechanics calibrated from the measured response\n\
             (servo calibrate also measures the friction)",
            &[
                ("plant.motor_inertia", Value::Float(m.motor_inertia)),
                ("plant.load_inertia", Value::Float(m.load_inertia)),
                ("plant.shaft_stiffness", Value::Float(m.shaft_stiffness)),
                ("plant.shaft_damping", Value::Float(m.shaft_damping)),
            ],
        )?;
        let dense = log_grid(1.0, 0.999 * 0.5 / period, 400);
        let model_points: Vec<ResponsePoint> =
            dense.iter().map(|&f| ResponsePoint::from_complex(f, plant_response(&drive, &m, f), 1.0)).collect();
        let measured_plant: Vec<ResponsePoint> =
            points.iter().map(|p| ResponsePoint::from_complex(p.hz, p.response, 1.0)).collect();
        crate::plot::bode::plot_bode(
            &out.join("plant.svg"),
            "plant: torque command → velocity estimate",
            &[("measured (torque-point sweep)", &measured_plant), ("calibrated model", &model_points)],
            None,
        )?;
        let predicted: Vec<ResponsePoint> = dense
            .iter()
            .map(|&f| ResponsePoint::from_complex(f, d.tuning.response(f, period) * model(f), 1.0))
            .collect();
        crate::plot::bode::plot_bode(
            &out.join("open-loop.svg"),
            &format!(
                "open loop: crossover {:.0} Hz, phase margin {:.0}° designed, {:.0}° measured",
                d.margins.crossover_hz, d.margins.phase_margin_deg, measured_pm
            ),
            &[("measured with the new gains (feedback-point sweep)", &open_loop), ("designed", &predicted)],
            Some((d.margins.crossover_hz, "crossover")),
        )?;
        responses.plot(&out)?;
        plot_loops(
            &out,
            &|f| d.tuning.response(f, period) * model(f),
            &open_loop,
            &d.margins,
            goal.sensitivity_peak,
            period,
        )?;
        let plant_json: Vec<serde_json::Value> = points
            .iter()
            .map(|p| {
                let measured = ResponsePoint::from_complex(p.hz, p.response, 1.0);
                let fit = ResponsePoint::from_complex(p.hz, plant_response(&drive, &m, p.hz), 1.0);
                json!({"hz": p.hz, "gain_db": measured.gain_db, "phase_deg": measured.phase_deg,
                       "model_gain_db": fit.gain_db, "model_phase_deg": fit.phase_deg})
            })
            .collect();
        let report = json!({
            "margin": self.margin,
            "plant": plant_json,
            "calibration": c,
            "design": d,
            "before": before,
            "verification": {"phase_margin_deg": measured_pm, "sensitivity_peak": measured_ms, "passed": ok},
            "responses": {
                "tuned": {"overshoot_percent": responses.tuned.overshoot_percent,
                          "settling_time_s": responses.tuned.settling_time_s,
                          "disturbance_peak": responses.tuned.disturbance_peak,
                          "disturbance_recovery_s": responses.tuned.disturbance_recovery_s},
                "before": {"overshoot_percent": responses.before.overshoot_percent,
                           "settling_time_s": responses.before.settling_time_s,
                           "disturbance_peak": responses.before.disturbance_peak,
                           "disturbance_recovery_s": responses.before.disturbance_recovery_s},
                "measured_step": {"overshoot_percent": responses.measured.overshoot_percent,
                                  "settling_time_s": responses.measured.settling_time_s},
            },
        });
        std::fs::write(out.join("autotune.json"), serde_json::to_string_pretty(&report)?)?;
        if self.common.json {
            println!("{}", serde_json::to_string_pretty(&report)?);
            return Ok(ok);
        }
        let e = c.relative_errors;
        println!("calibrated mechanics (± standard error):");
        println!("  motor inertia   {:.4e} kg·m² ± {:.2} %", m.motor_inertia, 100.0 * e[0]);
        println!("  load inertia    {:.4e} kg·m² ± {:.2} %", m.load_inertia, 100.0 * e[1]);
        println!("  shaft stiffness {:.4e} N·m/rad ± {:.2} %", m.shaft_stiffness, 100.0 * e[2]);
        println!("  shaft damping   {:.4e} N·m·s/rad (damping ratio ± {:.1} %)", m.shaft_damping, 100.0 * e[3]);
        let (fr, fa) = m.resonance_hz();
        println!(
            "  resonance {fr:.1} Hz, anti-resonance {fa:.1} Hz; fit within {:.2} dB, {:.1}°",
            c.worst_gain_db, c.worst_phase_deg
        );
        let t = &d.tuning;
        println!("velocity loop ({} margins):", self.margin);
        println!("  kp {:.4} N·m·s/rad (was {:.4}), ki {:.2} N·m/rad (was {:.2})", t.kp, before.kp, t.ki, before.ki);
        match t.notch {
            Some(n) => println!("  notch {:.1} Hz, Q {:.2}, depth {:.2}", n.hz, n.q, n.depth),
            None => println!("  no notch"),
        }
        if t.low_pass_hz > 0.0 {
            println!("  torque low-pass {:.0} Hz", t.low_pass_hz);
        } else {
            println!("  no torque low-pass");
        }
        let dm = &d.margins;
        println!(
            "  designed: bandwidth {:.0} Hz, crossover {:.0} Hz, phase margin {:.1}°, gain margin {:.1} dB, Ms {:.2}",
            dm.bandwidth_hz, dm.crossover_hz, dm.phase_margin_deg, dm.gain_margin_db, dm.sensitivity_peak
        );
        if measured_pm.is_nan() {
            println!("  verified on the twin: NO gain crossover among the measured points, the margin is not shown");
        } else {
            println!(
                "  verified on the twin: phase margin {measured_pm:.1}°, Ms {measured_ms:.2} over the measured points: {}",
                if ok { "holds" } else { "MISSES the margins" }
            );
        }
        let (r, b, ms) = (&responses.tuned, &responses.before, &responses.measured);
        // A step figure: its value, or what its NaN means.
        let step = |p: &super::prediction::StepPrediction| {
            if !p.stable {
                "unstable".to_string()
            } else if p.settling_time_s.is_nan() {
                format!(
                    "overshoot {:.1} %, not settled within {:.0} ms",
                    p.overshoot_percent,
                    1e3 * p.time.len() as f64 * period
                )
            } else {
                format!("overshoot {:.1} %, settles in {:.1} ms", p.overshoot_percent, 1e3 * p.settling_time_s)
            }
        };
        let measured_settling = if ms.settling_time_s.is_nan() {
            "not settled".to_string()
        } else {
            format!("settles in {:.1} ms", 1e3 * ms.settling_time_s)
        };
        println!(
            "  velocity step: {} predicted (before: {}); on the twin overshoot {:.1} %, {measured_settling}",
            step(r),
            step(b),
            ms.overshoot_percent
        );
        let load = |p: &super::prediction::StepPrediction| {
            if !p.stable {
                "unstable".to_string()
            } else {
                format!(
                    "peak {:.4} rad/s per N·m, back within 10 % in {:.1} ms",
                    p.disturbance_peak,
                    1e3 * p.disturbance_recovery_s
                )
            }
        };
        println!("  load step at the motor: {} (before: {})", load(r), load(b));
        println!("files: {} (plant, open-loop, nyquist, closed-loop, step, disturbance .svg)", out.display());
        Ok(ok)
    }
}
