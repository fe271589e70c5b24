//! `servo autotune`: the velocity loop tuned from the axis's own measured response, on the
//! FMU's twin. A torque-point sweep measures the plant; the machine's mechanics are
//! calibrated from it; the velocity PI, torque low-pass and notch are designed on the
//! calibrated model for the widest bandwidth within the margins; and the design is verified
//! on the twin by a feedback-point sweep (the open loop measured with the new gains).

use std::collections::BTreeMap;

use anyhow::{Context, Result};

use super::axis_under_test::{OnDrive, OnFmu};
use super::design::{Design, MarginGoal};
use super::disturbance_response;
use super::measured_mechanics::{measure_mechanics, MeasuredMechanics};
use super::position_loop_design::PositionTuning;
use super::report::{AutotuneReport, ReserveTaken};
use super::reserve::{design_and_verify, CloseDesign, Reserve};
use super::responses::{LoopModel, Responses};
use super::verification::{verify, with_tuning, Verification};
use crate::cli::{progress_bar, Common};
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::paths::{default_fmu, default_out};

/// Tune the velocity loop from the axis's measured response: a torque-point sweep on the
/// twin measures the plant (torque command → velocity estimate), the machine's mechanics
/// (motor and load inertia, shaft stiffness and damping) are calibrated from it with their
/// standard errors, and the velocity PI, the torque low-pass and a notch on the resonance (and one on an absorber's, or one that shapes the loop's phase) are
/// designed on the calibrated model for the widest closed-loop bandwidth whose loop keeps
/// its margins (--margin). The design is then verified on the twin: a feedback-point sweep
/// with the new gains measures the open loop (and looks closer, 1.5 % apart, between its
/// points wherever the margins come near the goal), whose crossover and phase margin are
/// printed beside the design's. Writes autotune.toml (the ctrl.* parameters, for a scenario's
/// [parameters] or --set), calibrated-plant.toml (the plant.* parameters of the calibrated
/// twin), autotune.json, plant.svg, open-loop.svg, nyquist.svg (the open loop near −1 with
/// the Ms circle), closed-loop.svg, step.svg (the velocity step predicted, tuned and before,
/// and measured on the twin) and disturbance.svg (a load step at the motor, predicted). Exit
/// status 1 when the verification misses the margins.
///
/// With --device PORT the machine is the drive's: the torque-point sweep runs on the drive,
/// the design is verified first on the twin of the measured machine (the FMU with the
/// calibrated mechanics and the drive's commissioning; nothing reaches the drive if it
/// misses), then the drive gets the tuning and a feedback-point sweep measures its margins
/// there; it keeps and saves the tuning only if they hold (--no-save: keep, do not save),
/// and gets its parameters back otherwise.
///
/// Examples: servo autotune --set plant.load_inertia=4.5e-4 --set plant.shaft_stiffness=60
///           servo autotune --device /dev/ttyACM0 --plant out/calibrate/calibrated-plant.toml
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
    /// With --device: verify the tuning on the drive and leave it running there, but do not
    /// save it to the drive's flash
    #[arg(long)]
    pub no_save: bool,
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

/// `before` with the velocity loop's `tuning` and the position loop's in place of its own.
fn tuned_set(
    before: &control_core::Params,
    tuning: &super::velocity_controller::VelocityTuning,
    position: &PositionTuning,
) -> control_core::Params {
    let mut p = *before;
    tuning.apply(&mut p);
    p.position.kp = position.kp as f32;
    p.position.velocity_feedforward = position.velocity_feedforward as f32;
    p
}

/// What a tuning on a drive came to: the measurement and design, the twin's verification, and
/// the drive's with the save's record (none where the twin missed and the drive was not given
/// the tuning).
struct DriveOutcome {
    mechanics: MeasuredMechanics,
    design: Design,
    position: PositionTuning,
    reserve: Reserve,
    close: CloseDesign<Verification>,
    close_reserve: Reserve,
    /// Drive time of the close design's verification on the drive, where it ran there (s).
    close_drive_time_s: f64,
    /// The drive ran the close design (and missed with it) before the full reserve's.
    close_ran_on_drive: bool,
    responses: Responses,
    twin: Verification,
    drive: Option<(Verification, Option<u32>)>,
}

impl AutotuneArgs {
    pub fn run(&self) -> Result<bool> {
        let goal = MarginGoal::named(&self.margin).ok_or_else(|| {
            anyhow::anyhow!("--margin must be conservative, standard or aggressive (got `{}`)", self.margin)
        })?;
        super::design_checks::check_riding_speed(self.velocity)?;
        super::design_checks::check_torque_amplitude(self.amplitude)?;
        if self.no_save && self.target.device.is_none() {
            anyhow::bail!("--no-save is for a tuning loaded on a drive (--device PORT)");
        }
        let parameters = crate::fmu::plant_file::machine_parameters(self.plant.as_deref(), &self.set)?;
        let out = self.common.out.clone().unwrap_or_else(|| default_out("autotune"));
        crate::paths::create_out_dir(&out)?;
        let fmu = Fmu::load(&self.common.fmu.clone().unwrap_or_else(default_fmu))?;
        let pb = progress_bar("autotune", self.common.json);
        pb.set_position(50);
        let passed = match self.target.session()? {
            None => {
                // 1. The plant measured and calibrated, 2. the design, 3. verified on the twin.
                let mechanics = measure_mechanics(&mut OnFmu(&fmu), &parameters, self.amplitude, self.velocity)?;
                pb.set_position(400);
                let verified = design_and_verify(&mechanics, &goal, &self.margin, |design, position| {
                    let tuned = with_tuning(&parameters, &design.tuning, Some(position));
                    let predicted = |f: f64| mechanics.open_loop(&design.tuning, f);
                    let twin = verify(&mut OnFmu(&fmu), &tuned, self.velocity, &goal, &predicted)?;
                    let held = twin.passed;
                    Ok((twin, held))
                })?;
                pb.set_position(900);
                let (design, position) = (&verified.design, &verified.position);
                let tuned = with_tuning(&parameters, &design.tuning, Some(position));
                let responses = self.responses(&fmu, &tuned, &mechanics, design)?;
                pb.finish_and_clear();
                let close_drive_time_s = verified.close.missed().map_or(0.0, |v| v.drive_time_s);
                let reserve = ReserveTaken {
                    reserve: verified.reserve,
                    close: &verified.close,
                    close_reserve: verified.close_reserve,
                    close_drive_time_s,
                };
                self.report(&out, &goal, (&mechanics, design, position, &responses), reserve, &verified.outcome, None)?
            }
            Some(mut session) => self.on_drive(&fmu, &mut session, &parameters, &goal, &out, &pb)?,
        };
        Ok(passed)
    }

    /// The tuning from the drive's measured machine, checked on its twin, loaded on the drive
    /// and verified there; saved only if it holds, the drive's parameters restored if not.
    fn on_drive<T: DrivePort>(
        &self,
        fmu: &Fmu,
        session: &mut DriveSession<T>,
        parameters: &BTreeMap<String, Value>,
        goal: &MarginGoal,
        out: &std::path::Path,
        pb: &indicatif::ProgressBar,
    ) -> Result<bool> {
        // The drive's parameters as they are (faults and a missing commissioning named first).
        let before = session.params_for_twin()?;
        // Kept before anything changes: a restore that the drive refuses (a fault latched)
        // leaves the user this file.
        let kept = out.join("drive-params-before.json");
        std::fs::write(&kept, serde_json::to_string_pretty(&before)?)
            .with_context(|| format!("writing {}", kept.display()))?;
        let tuned = self.tune_drive(fmu, session, &before, parameters, goal, pb);
        pb.finish_and_clear();
        let o = tuned.map_err(|e| {
            // Whatever stopped it (a refusal, a fault, a lost link, a failed save), the drive
            // gets its parameters back, and nothing is saved.
            match session.set_params(&before) {
                Ok(()) => e.context("the drive's parameters are back as they were; nothing saved"),
                Err(r) => e.context(format!(
                    "the drive could not be given its parameters back ({r:#}): it runs the parameters of the \
                     experiment that stopped, unsaved; power-cycle it to reload the set in its flash (the set it \
                     ran before is in {})",
                    kept.display()
                )),
            }
        })?;
        let results = (&o.mechanics, &o.design, &o.position, &o.responses);
        let reserve = ReserveTaken {
            reserve: o.reserve,
            close: &o.close,
            close_reserve: o.close_reserve,
            close_drive_time_s: o.close_drive_time_s,
        };
        let passed = self.report(out, goal, results, reserve, &o.twin, o.drive.as_ref().map(|(v, s)| (v, *s)))?;
        if o.drive.is_none() {
            if o.close_ran_on_drive {
                eprintln!(
                    "the drive ran the close design for its verification and has its parameters back; the \
                     full reserve's design misses the margins on the twin of the drive's machine: the drive was not \
                     given it"
                );
            } else {
                eprintln!(
                    "the tuning misses the margins on the twin of the drive's machine: the drive was not given it"
                );
            }
        }
        Ok(passed)
    }

    /// [`Self::on_drive`]'s steps up to the report; an error leaves restoring the drive to the
    /// caller.
    fn tune_drive<T: DrivePort>(
        &self,
        fmu: &Fmu,
        session: &mut DriveSession<T>,
        before: &control_core::Params,
        parameters: &BTreeMap<String, Value>,
        goal: &MarginGoal,
        pb: &indicatif::ProgressBar,
    ) -> Result<DriveOutcome> {
        let port = self.target.device.clone().unwrap_or_default();
        let mut drive = OnDrive { session, port };
        let mechanics = measure_mechanics(&mut drive, parameters, self.amplitude, self.velocity)?;
        pb.set_position(400);
        // The twin of the measured machine: the drive's commissioning, the calibrated mechanics.
        let twin_fmu = fmu.as_twin_of(before)?;
        let mut on_twin = parameters.clone();
        on_twin.extend(mechanics.plant_parameters().map(|(k, v)| (k.to_string(), v)));
        // Verified on the twin, then (only where the twin holds) on the drive: its open loop
        // measured with the tuning. The full reserve's design where the close one misses.
        let verified = design_and_verify(&mechanics, goal, &self.margin, |design, position| {
            let twin_tuned = with_tuning(&on_twin, &design.tuning, Some(position));
            let predicted = |f: f64| mechanics.open_loop(&design.tuning, f);
            let twin = verify(&mut OnFmu(&twin_fmu), &twin_tuned, self.velocity, goal, &predicted)?;
            if !twin.passed {
                return Ok(((twin, None), false));
            }
            let tuned = with_tuning(parameters, &design.tuning, Some(position));
            let on_drive = verify(&mut drive, &tuned, self.velocity, goal, &predicted)?;
            let held = on_drive.passed;
            Ok(((twin, Some(on_drive)), held))
        })?;
        pb.set_position(550);
        let (design, position, reserve, close_reserve) =
            (verified.design, verified.position, verified.reserve, verified.close_reserve);
        // The verification the close design missed: the drive's where it ran (its sweep is
        // drive time), else the twin's.
        let close_on_drive = verified.close.missed().and_then(|(_, on_drive)| on_drive.as_ref());
        let close_ran_on_drive = close_on_drive.is_some();
        let close_drive_time_s = close_on_drive.map_or(0.0, |v| v.drive_time_s);
        let close = verified.close.map(|(twin, on_drive)| on_drive.unwrap_or(twin));
        let twin_tuned = with_tuning(&on_twin, &design.tuning, Some(&position));
        let responses = self.responses(&twin_fmu, &twin_tuned, &mechanics, &design)?;
        let (twin, on_drive) = verified.outcome;
        let outcome = |twin, drive| DriveOutcome {
            mechanics,
            design,
            position,
            reserve,
            close,
            close_reserve,
            close_drive_time_s,
            close_ran_on_drive,
            responses,
            twin,
            drive,
        };
        let Some(on_drive) = on_drive else {
            // Never on the drive: the twin of its own machine missed.
            drive.session.set_params(before)?;
            return Ok(outcome(twin, None));
        };
        let saved = if on_drive.passed {
            // The drive's own set with the tuning in it (not the run's other settings).
            drive.session.set_params(&tuned_set(before, &design.tuning, &position))?;
            if self.no_save {
                None
            } else {
                Some(drive.session.save_params()?)
            }
        } else {
            drive.session.set_params(before)?;
            None
        };
        Ok(outcome(twin, Some((on_drive, saved))))
    }

    /// The predicted step and load step (tuned and before) on the calibrated model, and the
    /// step of `tuned` measured on `twin`.
    fn responses(
        &self,
        twin: &Fmu,
        tuned: &BTreeMap<String, Value>,
        mechanics: &MeasuredMechanics,
        design: &Design,
    ) -> Result<Responses> {
        let model = |f: f64| mechanics.model(f);
        let disturbance = |f: f64| disturbance_response(&mechanics.drive, &mechanics.calibration.mechanics, f);
        let loop_model = LoopModel { plant: &model, disturbance: &disturbance, period: mechanics.period() };
        Responses::of(twin, tuned, &design.tuning, &mechanics.during, &loop_model, self.velocity)
            .context("the responses on the twin")
    }

    fn report(
        &self,
        out: &std::path::Path,
        goal: &MarginGoal,
        (mechanics, design, position, responses): (&MeasuredMechanics, &Design, &PositionTuning, &Responses),
        reserve: ReserveTaken,
        twin: &Verification,
        drive: Option<(&Verification, Option<u32>)>,
    ) -> Result<bool> {
        let report = AutotuneReport {
            margin: &self.margin,
            goal_ms: goal.sensitivity_peak,
            mechanics,
            design,
            position,
            reserve,
            responses,
            twin,
            drive,
            on_drive: self.target.device.is_some(),
        };
        report.write_files(out)?;
        if self.common.json {
            println!("{}", serde_json::to_string_pretty(&report.json())?);
        } else {
            report.print(out);
        }
        Ok(report.passed())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autotune::velocity_controller::{Notch, VelocityTuning};

    /// The set a drive saves and the parameters the twin and the verification run with carry
    /// the same tuning: the FMU's configuration of the default parameters with the tuning in
    /// them is the default set with the tuning put in its fields.
    #[test]
    fn the_saved_set_holds_the_tuning_the_parameters_name() {
        let tuning = VelocityTuning {
            kp: 0.1234,
            ki: 17.5,
            low_pass_hz: 900.0,
            notch: Some(Notch { hz: 263.0, q: 0.7, depth: 0.1 }),
            notch2: Some(Notch { hz: 1450.0, q: 1.2, depth: 0.25 }),
        };
        let margins = crate::autotune::margins::margins(&[1.0, 2.0], &[Complex::new(10.0, 0.0); 2]).unwrap();
        let position = PositionTuning { kp: 177.8, velocity_feedforward: 1.0, margins };
        let named = crate::fmu::configuration::configuration(&with_tuning(&BTreeMap::new(), &tuning, Some(&position)))
            .unwrap()
            .control;
        assert_eq!(tuned_set(&control_core::Params::default(), &tuning, &position), named);
    }

    type Complex = num_complex::Complex64;
}
