//! `servo calibrate`: the twin fitted to the machine, written as a plant file.

use std::path::PathBuf;

use anyhow::{Context, Result};
use serde_json::json;

use super::friction_runs::FrictionRuns;
use super::{calibrate_machine, calibrate_on_fmu, Measurement};
use crate::analysis::response_point::ResponsePoint;
use crate::autotune::axis_under_test::{AxisUnderTest, OnDrive};
use crate::autotune::design_checks::{check_riding_speed, check_torque_amplitude};
use crate::autotune::drive_dynamics::DriveDynamics;
use crate::autotune::margins::log_grid;
use crate::autotune::mechanics::{AbsorberMechanics, Mechanics};
use crate::autotune::plant_response;
use crate::cli::{progress_bar, Common};
use crate::fmu::configuration::configuration;
use crate::fmu::plant_file::{machine_parameters, write_plant_file};
use crate::fmu::runner::Fmu;
use crate::fmu::trace::Trace;
use crate::paths::{default_fmu, default_out};
use servo_axis::plant::PlantParams;

/// Fit the twin to the machine: a torque-point sweep measures the plant (torque command →
/// velocity estimate) and the two-inertia mechanics are fitted to it (motor and load
/// inertia, shaft stiffness and damping); constant-speed runs in both directions measure the
/// torque that holds each speed, and Coulomb and viscous friction (and a constant load
/// torque) are fitted to it. Each value is printed with its standard error, and on the FMU
/// beside the twin's truth. Writes calibrated-plant.toml (the plant file every command that
/// runs a twin takes with --plant), calibration.json, plant.svg (the measured response beside
/// the calibrated model's) and friction.svg (torque against speed, measured and fitted).
/// Friction at a constant speed is the motor's and the load's together: the plant file
/// splits it in proportion to the inertias.
///
/// With --device PORT the machine is the drive's: the sweep and the runs are the drive's
/// (its velocity estimate and torque command read over the link), and the plant file is the
/// twin of that machine (the values without a truth to compare). The drive gets its
/// parameters back at the end.
///
/// Examples: servo calibrate --set plant.load_inertia=3e-4 --set plant.shaft_stiffness=80
///           servo calibrate --device /dev/ttyACM0
#[derive(clap::Args)]
pub struct CalibrateArgs {
    /// Plant file of the twin's machine (a [parameters] table of plant.* values, as this
    /// command writes); --set applies over it
    #[arg(long)]
    pub plant: Option<PathBuf>,
    /// FMU parameter NAME=VALUE (repeatable): the twin's machine, e.g. plant.load_inertia=3e-4
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Torque amplitude of the plant's sweep (N·m)
    #[arg(long, default_value_t = 0.2)]
    pub amplitude: f64,
    /// Constant speed the sweep rides on (rad/s; keeps friction on one side)
    #[arg(long, default_value_t = 50.0)]
    pub velocity: f64,
    /// Speeds of the friction runs (rad/s, comma-separated; each run in both directions, up
    /// to the drive's velocity limit)
    #[arg(long, value_delimiter = ',', default_values_t = [20.0, 50.0, 100.0, 150.0])]
    pub speeds: Vec<f64>,
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

impl CalibrateArgs {
    pub fn run(&self) -> Result<bool> {
        check_torque_amplitude(self.amplitude)?;
        check_riding_speed(self.velocity)?;
        let parameters = machine_parameters(self.plant.as_deref(), &self.set)?;
        let config = configuration(&parameters)?;
        let how = Measurement {
            amplitude: self.amplitude,
            velocity: self.velocity,
            friction_runs: FrictionRuns { speeds: self.speeds.clone(), ..Default::default() },
        };
        let out = self.common.out.clone().unwrap_or_else(|| default_out("calibrate"));
        std::fs::create_dir_all(&out).with_context(|| format!("creating {}", out.display()))?;
        let pb = progress_bar("calibrate", self.common.json);
        pb.set_position(100);
        // On a drive: its machine, no truth to compare; on the FMU: the twin's plant.
        let (c, truth, drive_params) = match self.target.session()? {
            Some(mut session) => {
                let port = self.target.device.clone().unwrap_or_default();
                // The drive's parameters as they are; given back when the runs end, whatever
                // happened.
                let before = session.params_for_twin()?;
                let mut drive = OnDrive { session: &mut session, port };
                let calibrated =
                    calibrate_machine(&mut drive, &parameters, &how).and_then(|c| Ok((c, drive.params(&parameters)?)));
                let restored = session.set_params(&before);
                let (c, ran) = calibrated?;
                restored.context("giving the drive its parameters back")?;
                (c, None, ran)
            }
            None => {
                how.friction_runs.validate(&parameters)?;
                let fmu = Fmu::load(&self.common.fmu.clone().unwrap_or_else(default_fmu))?;
                (calibrate_on_fmu(&fmu, &parameters, &how)?, Some(config.plant), config.control)
            }
        };
        pb.finish_and_clear();
        let header = format!(
            "servo calibrate: the machine's mechanics from a torque-point sweep, its friction from\n\
             constant-speed runs at {:?} rad/s (motor and load together, split in proportion to the inertias)",
            self.speeds
        );
        write_plant_file(&out.join("calibrated-plant.toml"), &header, &c.plant_parameters(&config.plant)?)?;
        // Plots: the plant measured and modelled; the friction measured and fitted.
        let drive = DriveDynamics::as_configured(&drive_params);
        let m = c.mechanics.mechanics;
        let period = drive_params.rates.velocity_period() as f64;
        let model: Vec<ResponsePoint> = log_grid(1.0, 0.999 * 0.5 / period, 400)
            .into_iter()
            .map(|f| ResponsePoint::from_complex(f, plant_response(&drive, &m, f), 1.0))
            .collect();
        let measured: Vec<ResponsePoint> =
            c.plant_points.iter().map(|p| ResponsePoint::from_complex(p.hz, p.response, 1.0)).collect();
        crate::plot::bode::plot_bode(
            &out.join("plant.svg"),
            "plant: torque command → velocity estimate",
            &[("measured (torque-point sweep)", &measured), ("calibrated model", &model)],
            None,
        )?;
        let mut runs = c.speed_points.clone();
        runs.sort_by(|a, b| a.velocity.total_cmp(&b.velocity));
        let mut measured_t = Trace::new(vec!["velocity".into(), "torque".into()]);
        let mut fitted_t = Trace::new(vec!["velocity".into(), "torque".into()]);
        for p in &runs {
            measured_t.rows.push([p.velocity, p.torque]);
        }
        let top = runs.iter().map(|p| p.velocity.abs()).fold(0.0, f64::max);
        for k in 0..=200 {
            let w = -top + 2.0 * top * k as f64 / 200.0;
            if w != 0.0 {
                fitted_t.rows.push([w, c.friction.torque(w)]);
            }
        }
        crate::plot::signals::plot_against(
            &out.join("friction.svg"),
            "friction: torque command holding each speed",
            &[("measured (constant-speed runs)", &measured_t), ("fitted", &fitted_t)],
            "velocity",
            "velocity estimate (rad/s)",
            &["torque".to_string()],
        )?;
        // The twin's truth, beside each value (NaN on a drive: none known).
        let (fr, fa) = m.resonance_hz();
        let e = c.mechanics.relative_errors;
        let f = &c.friction;
        let truth_of = |value: &dyn Fn(&PlantParams) -> f64| truth.as_ref().map_or(f64::NAN, value);
        let mechanics_truth = |value: &dyn Fn(&Mechanics) -> f64| truth_of(&|p| value(&Mechanics::of_plant(p)));
        let mut rows = vec![
            ("motor inertia", "kg·m²", m.motor_inertia, e[0] * m.motor_inertia, mechanics_truth(&|t| t.motor_inertia)),
            ("load inertia", "kg·m²", m.load_inertia, e[1] * m.load_inertia, mechanics_truth(&|t| t.load_inertia)),
            (
                "shaft stiffness",
                "N·m/rad",
                m.shaft_stiffness,
                e[2] * m.shaft_stiffness,
                mechanics_truth(&|t| t.shaft_stiffness),
            ),
            (
                "shaft damping",
                "N·m·s/rad",
                m.shaft_damping,
                e[3] * m.shaft_damping,
                mechanics_truth(&|t| t.shaft_damping),
            ),
            ("resonance", "Hz", fr, f64::NAN, mechanics_truth(&|t| t.resonance_hz().0)),
            ("anti-resonance", "Hz", fa, f64::NAN, mechanics_truth(&|t| t.resonance_hz().1)),
            ("Coulomb friction", "N·m", f.coulomb, f.coulomb_error, truth_of(&|p| p.motor_coulomb + p.load_coulomb)),
            (
                "viscous friction",
                "N·m·s/rad",
                f.viscous,
                f.viscous_error,
                truth_of(&|p| p.motor_viscous + p.load_viscous),
            ),
            // The twin's plant has no constant load torque.
            ("constant load torque", "N·m", f.load_torque, f.load_torque_error, truth_of(&|_| 0.0)),
        ];
        // The absorber, where the fit kept one or the twin has one (0: none).
        let true_absorber = truth.as_ref().is_some_and(|p| p.absorber_inertia > 0.0);
        if m.absorber.is_some() || true_absorber {
            let a = m.absorber.unwrap_or(AbsorberMechanics { inertia: 0.0, stiffness: 0.0, damping: 0.0 });
            let ea = c.mechanics.absorber_relative_errors.unwrap_or([f64::NAN; 3]);
            let own = |a: &AbsorberMechanics| if a.inertia > 0.0 { a.own_mode().0 } else { 0.0 };
            let truth_absorber = |value: &dyn Fn(&AbsorberMechanics) -> f64| {
                mechanics_truth(&|t| t.absorber.as_ref().map_or(0.0, value))
            };
            rows.extend([
                ("absorber inertia", "kg·m²", a.inertia, ea[0] * a.inertia, truth_absorber(&|t| t.inertia)),
                ("absorber stiffness", "N·m/rad", a.stiffness, ea[1] * a.stiffness, truth_absorber(&|t| t.stiffness)),
                ("absorber damping", "N·m·s/rad", a.damping, ea[2] * a.damping, truth_absorber(&|t| t.damping)),
                ("absorber's own mode", "Hz", own(&a), f64::NAN, truth_absorber(&own)),
            ]);
        }
        let table: Vec<serde_json::Value> = rows
            .iter()
            .map(|(name, unit, v, se, t)| {
                json!({"name": name, "unit": unit, "value": v, "standard_error": se,
                       "truth": t.is_finite().then_some(t),
                       "error_percent": (t.is_finite() && *t != 0.0).then(|| 100.0 * (v / t - 1.0))})
            })
            .collect();
        let report = json!({
            "values": table,
            "calibration": c,
            "fit": {"worst_gain_db": c.mechanics.worst_gain_db, "worst_phase_deg": c.mechanics.worst_phase_deg},
            "plant_file": out.join("calibrated-plant.toml"),
        });
        std::fs::write(out.join("calibration.json"), serde_json::to_string_pretty(&report)?)?;
        if self.common.json {
            println!("{}", serde_json::to_string_pretty(&report)?);
            return Ok(true);
        }
        let on = match &self.target.device {
            Some(port) => format!("the drive at {port}"),
            None => "the twin".into(),
        };
        println!("calibrated on {on}:");
        println!("{:<22} {:>12} {:>12} {:>12} {:>9}", "", "value", "± std. err.", "twin's truth", "error");
        for (name, unit, v, se, t) in rows {
            let err = if t.is_finite() && t != 0.0 { format!("{:+.2} %", 100.0 * (v / t - 1.0)) } else { "-".into() };
            let se = if se.is_finite() { format!("{se:.3e}") } else { "-".into() };
            let t = if t.is_finite() { format!("{t:.4e}") } else { "-".into() };
            println!("{name:<22} {v:>12.4e} {se:>12} {t:>12} {err:>9}  {unit}");
        }
        println!(
            "model vs measurement: within {:.2} dB, {:.1}° over {} points; drive time {:.1} s",
            c.mechanics.worst_gain_db,
            c.mechanics.worst_phase_deg,
            c.plant_points.len(),
            c.drive_time_s
        );
        if c.mechanics.rigid {
            println!("note: the shaft's resonance lies above the measured band: the split of the inertia and the stiffness are bounds only");
        }
        println!("plant file: {} (give it to any command with --plant)", out.join("calibrated-plant.toml").display());
        Ok(true)
    }
}
