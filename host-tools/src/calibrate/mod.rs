//! `servo calibrate`: the twin fitted to a machine. The mechanics (motor and load inertia,
//! shaft stiffness and damping) from a torque-point sweep (the fit lives with the model it
//! fits, in `autotune::calibration`), and friction (Coulomb, viscous, a constant load torque)
//! from constant-speed runs in both directions (`friction`, `friction_runs`); the result is a
//! plant file (`fmu::plant_file`) every command that runs a twin takes with `--plant`.

pub mod bench;
pub mod command;
pub mod friction;
pub mod friction_runs;
pub mod friction_runs_on_drive;
pub mod index;

use std::collections::BTreeMap;

use anyhow::{Context, Result};
use serde::Serialize;
use servo_axis::plant::PlantParams;

use crate::analysis::response_point::ResponsePoint;
use crate::autotune::axis_under_test::{AxisUnderTest, OnFmu};
use crate::autotune::calibration::{Calibration, PlantPoint};
use crate::autotune::measured_mechanics::measure_mechanics;
use crate::autotune::mechanics::AbsorberMechanics;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use friction::{fit_friction, Friction, SpeedPoint};
use friction_runs::FrictionRuns;

/// How a machine is measured for its calibration.
#[derive(Clone, Debug)]
pub struct Measurement {
    /// Torque amplitude of the sweep (N·m).
    pub amplitude: f64,
    /// Speed the sweep rides at (rad/s).
    pub velocity: f64,
    pub friction_runs: FrictionRuns,
}

/// A machine calibrated: its mechanics and friction, and what they were fitted to.
#[derive(Clone, Debug, Serialize)]
pub struct MachineCalibration {
    pub mechanics: Calibration,
    pub friction: Friction,
    #[serde(skip)]
    pub readings: Vec<ResponsePoint>,
    #[serde(skip)]
    pub plant_points: Vec<PlantPoint>,
    pub speed_points: Vec<SpeedPoint>,
    /// Drive time the measurements took (s).
    pub drive_time_s: f64,
}

impl MachineCalibration {
    /// The calibrated twin's plant parameters, the other values (motor, sensors) from `base`.
    /// Friction at a constant speed is the motor's and the load's together: the twin splits
    /// it in proportion to the inertias (the split a constant speed cannot see; this one keeps
    /// the friction's stiffness near zero speed the lowest, never above the machine's). A
    /// constant load torque has no plant parameter and is reported only. The sub-steps are
    /// the fewest (not fewer than `base`'s) the twin's plant accepts.
    pub fn plant_parameters(&self, base: &PlantParams) -> Result<Vec<(&'static str, Value)>> {
        let m = &self.mechanics.mechanics;
        let f = &self.friction;
        let share = m.motor_inertia / m.total_inertia();
        let mut plant = *base;
        plant.motor_inertia = m.motor_inertia;
        plant.load_inertia = m.load_inertia;
        plant.shaft_stiffness = m.shaft_stiffness;
        plant.shaft_damping = m.shaft_damping;
        // No absorber fitted: none in the twin either, whatever the base had.
        let absorber = m.absorber.unwrap_or(AbsorberMechanics { inertia: 0.0, stiffness: 0.0, damping: 0.0 });
        plant.absorber_inertia = absorber.inertia;
        plant.absorber_stiffness = absorber.stiffness;
        plant.absorber_damping = absorber.damping;
        // The fit refuses negative friction (`fit_friction`): no clamp here.
        plant.motor_coulomb = share * f.coulomb;
        plant.load_coulomb = (1.0 - share) * f.coulomb;
        plant.motor_viscous = share * f.viscous;
        plant.load_viscous = (1.0 - share) * f.viscous;
        let substeps = fewest_substeps(&plant)?;
        let mut values: Vec<(&'static str, Value)> = [
            ("plant.motor_inertia", plant.motor_inertia),
            ("plant.load_inertia", plant.load_inertia),
            ("plant.shaft_stiffness", plant.shaft_stiffness),
            ("plant.shaft_damping", plant.shaft_damping),
            ("plant.motor_coulomb", plant.motor_coulomb),
            ("plant.load_coulomb", plant.load_coulomb),
            ("plant.motor_viscous", plant.motor_viscous),
            ("plant.load_viscous", plant.load_viscous),
            ("plant.absorber_inertia", plant.absorber_inertia),
            ("plant.absorber_stiffness", plant.absorber_stiffness),
            ("plant.absorber_damping", plant.absorber_damping),
        ]
        .into_iter()
        .map(|(k, v)| (k, Value::Float(v)))
        .collect();
        values.push(("plant.substeps", Value::Int(substeps as i64)));
        Ok(values)
    }
}

/// The fewest sub-steps, from `plant`'s own up to the FMU's most, with which the plant model
/// accepts `plant` (its friction near zero speed is integrated explicitly: a strong friction
/// on a light inertia needs shorter sub-steps); the plant model's reason when none does.
pub fn fewest_substeps(plant: &PlantParams) -> Result<u32> {
    let most = servo_axis::variables::by_name("plant.substeps").and_then(|d| d.range.max).map_or(1000, |m| m as u32);
    let mut p = *plant;
    for n in plant.substeps..=most.max(plant.substeps) {
        p.substeps = n;
        if p.validate().is_ok() {
            return Ok(n);
        }
    }
    p.substeps = most.max(plant.substeps);
    match p.validate() {
        Err(e) => anyhow::bail!("the calibrated twin cannot be simulated: {e}"),
        Ok(()) => Ok(p.substeps),
    }
}

/// Calibrate the machine `target` measures with `parameters` (on the FMU its twin, or the
/// plant those parameters describe; or a drive): the torque-point sweep, the mechanics fitted
/// to it, the constant-speed runs, the friction fitted to them.
pub fn calibrate_machine(
    target: &mut dyn AxisUnderTest,
    parameters: &BTreeMap<String, Value>,
    how: &Measurement,
) -> Result<MachineCalibration> {
    let limit = target.params(parameters)?.position.velocity_limit as f64;
    how.friction_runs.validate_within(limit)?;
    let measured = measure_mechanics(target, parameters, how.amplitude, how.velocity)?;
    let (speed_points, runs_time_s) = target.constant_speeds(&how.friction_runs, parameters)?;
    let friction = fit_friction(&speed_points).context("fitting the friction")?;
    Ok(MachineCalibration {
        mechanics: measured.calibration,
        friction,
        readings: measured.readings,
        plant_points: measured.points,
        speed_points,
        drive_time_s: measured.drive_time_s + runs_time_s,
    })
}

/// [`calibrate_machine`] on the FMU.
pub fn calibrate_on_fmu(
    fmu: &Fmu,
    parameters: &BTreeMap<String, Value>,
    how: &Measurement,
) -> Result<MachineCalibration> {
    calibrate_machine(&mut OnFmu(fmu), parameters, how)
}
