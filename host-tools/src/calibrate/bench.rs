//! `servo bench calibrate`: over machines drawn across the ranges users' axes span (the
//! autotune bench's draw: inertia ratio 0.2–5, shaft resonance 50–500 Hz, damping ratio
//! 0.01–0.1, sensor noise on; with friction drawn on each side), each machine calibrated on
//! its twin as `servo calibrate` does, and every value checked against the twin's truth.

use anyhow::Result;
use serde::Serialize;

use servo_axis::variables::name;

use super::friction_runs::FrictionRuns;
use super::{calibrate_machine, calibrate_on_fmu, Measurement};
use crate::autotune::axis_under_test::{AxisUnderTest, OnDrive};
use crate::autotune::bench::Machine;
use crate::autotune::drive_dynamics::DriveDynamics;
use crate::autotune::mechanics::Mechanics;
use crate::autotune::plant_response;
use crate::bench::figures::Recorder;
use crate::cli::Common;
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::random::XorShift64Star;
use crate::virtual_drive::in_process::commissioned_session;
use crate::virtual_drive::uart::LineSettings;

/// The twin calibrated from measurements, over drawn machines: inertia ratio 0.2–5, shaft
/// resonance 50–500 Hz, damping ratio 0.01–0.1 (the autotune bench's draw), Coulomb friction
/// 0.005–0.05 N·m and viscous 5e-6–5e-5 N·m·s/rad on each side (log-uniform), current-sensor
/// noise on. Each machine as `servo calibrate` runs it: a torque-point sweep, the mechanics
/// fitted to it, constant-speed runs at 20, 50, 100 and 150 rad/s each way, the friction
/// fitted to them. Goals: inertias and stiffness within 3 %, resonance and anti-resonance
/// within 1 %, Coulomb friction within 10 % and viscous within 20 % (motor and load
/// together), the calibrated model within 0.5 dB / 3° of the measurement below 1 kHz. One
/// line per machine, then the worst case (exit 1 when a goal is missed)
#[derive(clap::Args)]
pub struct CalibrateBenchArgs {
    /// Machines drawn
    #[arg(long, default_value_t = 200)]
    pub plants: u32,
    /// Seed of the draw (the same seed draws the same machines)
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run only this machine of the draw (its index in the table, from 0)
    #[arg(long)]
    pub plant: Option<u32>,
    /// Calibrate each machine on a virtual drive in this process (the drive's application on
    /// the simulated board, its motor commissioned first) instead of the FMU: the path
    /// `servo calibrate --device` takes, the constant-speed runs ramped and read over the link
    #[arg(long)]
    pub virtual_drive: bool,
    /// Machines calibrated at once, each on its own thread (default: one per core, one with
    /// --virtual-drive). Each machine's run is its own, so the figures do not depend on it;
    /// a virtual drive's link waits on wall-clock timeouts, which a loaded machine can meet
    #[arg(long)]
    pub jobs: Option<usize>,
    #[command(flatten)]
    pub common: Common,
}

/// One drawn machine with its friction.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct FrictionMachine {
    pub machine: Machine,
    pub motor_coulomb: f64,
    pub load_coulomb: f64,
    pub motor_viscous: f64,
    pub load_viscous: f64,
}

pub fn draw(n: u32, seed: u64) -> Vec<FrictionMachine> {
    // The friction from its own stream: the machines are the autotune bench's of this seed.
    let mut rng = XorShift64Star::from_seed(seed ^ 0x9e37_79b9_7f4a_7c15);
    crate::autotune::bench::draw(n, seed)
        .into_iter()
        .map(|machine| FrictionMachine {
            machine,
            motor_coulomb: rng.log_uniform_3_digits(0.005, 0.05),
            load_coulomb: rng.log_uniform_3_digits(0.005, 0.05),
            motor_viscous: rng.log_uniform_3_digits(5e-6, 5e-5),
            load_viscous: rng.log_uniform_3_digits(5e-6, 5e-5),
        })
        .collect()
}

impl FrictionMachine {
    pub fn parameters(&self) -> std::collections::BTreeMap<String, Value> {
        let mut p = self.machine.parameters();
        for (k, v) in [
            (name::plant_motor_coulomb, self.motor_coulomb),
            (name::plant_load_coulomb, self.load_coulomb),
            (name::plant_motor_viscous, self.motor_viscous),
            (name::plant_load_viscous, self.load_viscous),
        ] {
            p.insert(k.to_string(), Value::Float(v));
        }
        // The sub-steps this friction needs (a user's strong friction on a light motor needs
        // them too: the FMU says so when it refuses the plant).
        let base = match p.get(name::plant_substeps) {
            Some(Value::Int(n)) => *n as u32,
            _ => 1,
        };
        let mut most = p.clone();
        most.insert(name::plant_substeps.to_string(), Value::Int(64));
        if let Ok(config) = configuration(&most) {
            let plant = servo_axis::plant::PlantParams { substeps: base, ..config.plant };
            if let Ok(n) = super::fewest_substeps(&plant) {
                p.insert(name::plant_substeps.to_string(), Value::Int(n as i64));
            }
        }
        p
    }
}

/// One machine's result: relative errors (0.01 = 1 %).
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationRow {
    pub machine: FrictionMachine,
    pub failed: Option<String>,
    /// J_M, J_L, k, resonance, anti-resonance, Coulomb, viscous.
    pub errors: [f64; 7],
    /// The calibrated model against the measurement below 1 kHz: worst gain (dB), phase (deg).
    pub fit_below_1khz: [f64; 2],
    pub drive_time_s: f64,
}

/// One machine calibrated on its twin or (`on_drive`) on a virtual drive with its plant.
fn calibrate_one(fmu: &Fmu, m: &FrictionMachine, on_drive: bool) -> CalibrationRow {
    let mut row = CalibrationRow {
        machine: *m,
        failed: None,
        errors: [f64::NAN; 7],
        fit_below_1khz: [f64::NAN; 2],
        drive_time_s: f64::NAN,
    };
    let result = (|| -> Result<()> {
        let parameters = m.parameters();
        let config = configuration(&parameters)?;
        let how = Measurement {
            amplitude: 0.2,
            velocity: crate::sweep::bench::VELOCITY,
            friction_runs: FrictionRuns::default(),
        };
        // The drive parameters the measurement ran with: the drive's own on a virtual drive
        // (its commissioned current loop), what the fit took out.
        let (c, ran) = if on_drive {
            let mut session = commissioned_session(&parameters, LineSettings::default())?;
            let mut drive = OnDrive { session: &mut session, port: "an in-process virtual drive".into() };
            let c = calibrate_machine(&mut drive, &parameters, &how)?;
            (c, drive.params(&parameters)?)
        } else {
            (calibrate_on_fmu(fmu, &parameters, &how)?, config.control)
        };
        let truth = Mechanics::of_plant(&config.plant);
        let fitted = c.mechanics.mechanics;
        let rel = |a: f64, b: f64| (a / b - 1.0).abs();
        let (fr, fa) = fitted.resonance_hz();
        let (tr, ta) = truth.resonance_hz();
        row.errors = [
            rel(fitted.motor_inertia, truth.motor_inertia),
            rel(fitted.load_inertia, truth.load_inertia),
            rel(fitted.shaft_stiffness, truth.shaft_stiffness),
            rel(fr, tr),
            rel(fa, ta),
            rel(c.friction.coulomb, m.motor_coulomb + m.load_coulomb),
            rel(c.friction.viscous, m.motor_viscous + m.load_viscous),
        ];
        let drive = DriveDynamics::as_configured(&ran);
        let (mut gain, mut phase) = (0.0f64, 0.0f64);
        for p in c.plant_points.iter().filter(|p| p.hz < 1000.0) {
            let e = (p.response / plant_response(&drive, &fitted, p.hz)).ln();
            gain = gain.max((20.0 / std::f64::consts::LN_10 * e.re).abs());
            phase = phase.max(e.im.to_degrees().abs());
        }
        row.fit_below_1khz = [gain, phase];
        row.drive_time_s = c.drive_time_s;
        Ok(())
    })();
    if let Err(e) = result {
        row.failed = Some(format!("{e:#}"));
    }
    row
}

impl CalibrateBenchArgs {
    pub fn run(&self) -> Result<bool> {
        if self.plants == 0 {
            anyhow::bail!("--plants must be at least 1");
        }
        let machines =
            crate::bench::drawn::one_or_all(draw(self.plants, self.seed), self.plant, "--plant", "machines")?;
        let fmu_path = self.common.fmu.clone().unwrap_or_else(crate::paths::default_fmu);
        let rows: Vec<CalibrationRow> = crate::bench::drawn::run_each(
            "calibrate",
            self.common.json,
            &machines,
            self.jobs.unwrap_or_else(|| crate::bench::drawn::default_jobs(self.virtual_drive)),
            || Fmu::load(&fmu_path),
            |fmu, m| calibrate_one(fmu, m, self.virtual_drive),
        )?;
        let finished = || rows.iter().filter(|r| r.failed.is_none());
        let worst = |f: &dyn Fn(&CalibrationRow) -> f64| finished().map(f).fold(f64::NEG_INFINITY, f64::max);
        let failed = rows.iter().filter(|r| r.failed.is_some()).count();
        let mut rec = Recorder::new(if self.virtual_drive { "calibrate-virtual-drive" } else { "calibrate" });
        rec.equal("machines not calibrated", failed as f64, 0.0, "machines");
        for (i, label, goal) in [
            (0, "motor inertia error", 3.0),
            (1, "load inertia error", 3.0),
            (2, "stiffness error", 3.0),
            (3, "resonance error", 1.0),
            (4, "anti-resonance error", 1.0),
            (5, "Coulomb friction error", 10.0),
            (6, "viscous friction error", 20.0),
        ] {
            rec.at_most(label, 100.0 * worst(&|r| r.errors[i]), goal, "%");
        }
        rec.at_most("model vs measurement below 1 kHz, gain", worst(&|r| r.fit_below_1khz[0]), 0.5, "dB");
        rec.at_most("model vs measurement below 1 kHz, phase", worst(&|r| r.fit_below_1khz[1]), 3.0, "deg");
        rec.info("drive time", worst(&|r| r.drive_time_s), "s");
        let passed = rec.all_met();
        rec.write(self.common.out.as_deref(), passed)?;
        if self.common.json {
            println!(
                "{}",
                serde_json::to_string_pretty(
                    &serde_json::json!({"bench": "calibrate", "rows": rows, "figures": rec.figures()})
                )?
            );
            return Ok(passed);
        }
        println!(
            "{:>3} {:>5} {:>6} {:>6} {:>7} {:>7} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>6} {:>5}",
            "#",
            "ratio",
            "fr Hz",
            "zeta",
            "Fc N·m",
            "B",
            "JM %",
            "JL %",
            "k %",
            "fr %",
            "fa %",
            "Fc %",
            "B %",
            "dB",
            "°"
        );
        for (k, r) in rows.iter().enumerate() {
            let m = &r.machine;
            let (fc, b) = (m.motor_coulomb + m.load_coulomb, m.motor_viscous + m.load_viscous);
            match &r.failed {
                None => {
                    let e = r.errors.map(|x| 100.0 * x);
                    println!(
                        "{k:>3} {:>5.2} {:>6.0} {:>6.3} {fc:>7.4} {b:>7.1e} {:>6.2} {:>6.2} {:>6.2} {:>6.2} {:>6.2} {:>6.2} {:>6.1} {:>6.2} {:>5.1}",
                        m.machine.inertia_ratio, m.machine.resonance_hz, m.machine.damping_ratio,
                        e[0], e[1], e[2], e[3], e[4], e[5], e[6], r.fit_below_1khz[0], r.fit_below_1khz[1]
                    );
                }
                Some(e) => println!(
                    "{k:>3} {:>5.2} {:>6.0} {:>6.3} {fc:>7.4} {b:>7.1e}  FAILED: {e}",
                    m.machine.inertia_ratio, m.machine.resonance_hz, m.machine.damping_ratio
                ),
            }
        }
        rec.print_worst(&format!(
            "worst over {} machines (seed {}, calibrated on {}):",
            rows.len(),
            self.seed,
            if self.virtual_drive { "a virtual drive" } else { "the FMU" }
        ));
        Ok(passed)
    }
}
