//! Plant integration error: the inverter commands of a closed-loop run of the default axis,
//! replayed open loop into the plant with the default sub-steps and with ten times as
//! many, compared tick by tick.

use anyhow::Result;
use control_core::Mode;
use serde::Serialize;
use servo_axis::plant::{Plant, PlantInputs};
use servo_axis::simulation::{AxisSimulation, UserInputs};

/// Largest accepted error, relative to the signal's peak. The error concentrates where the
/// smoothed Coulomb friction bends within one tick (speed reversals) and where the current
/// slews at the voltage limit.
pub const GOAL: f64 = 5e-4;

#[derive(Clone, Debug, Serialize)]
pub struct StepError {
    pub substeps: u32,
    pub reference_substeps: u32,
    pub simulated_seconds: f64,
    /// (signal, max |error|, peak |signal|)
    pub errors: Vec<(String, f64, f64)>,
    pub worst_relative: f64,
    pub passed: bool,
}

pub fn step_error() -> Result<StepError> {
    // 1. Closed loop with the default plant: record the inverter command of every tick. The
    //    drive is given the plant's mounting (the FMU with `commissioning.at_start` off): a
    //    drive that has not been commissioned refuses every mode.
    let base = servo_axis::parameters::default_config_given_mounting().map_err(anyhow::Error::msg)?;
    let substeps = base.plant.substeps;
    let mut sim = AxisSimulation::new(&base)?;
    let seconds = 0.2;
    let ticks = (seconds / sim.tick_period()).round() as usize;
    let mut inputs = Vec::with_capacity(ticks);
    for k in 0..ticks {
        let t = k as f64 * sim.tick_period();
        let disturbance = if t > 0.05 { 0.2 } else { 0.0 };
        let u = UserInputs {
            mode: Mode::Velocity,
            velocity_command: if t < 0.1 { 100.0 } else { -50.0 },
            disturbance_torque: disturbance,
            ..Default::default()
        };
        let pwm = sim.pending_pwm();
        inputs.push(PlantInputs {
            duties: pwm.duties.map(|d| d as f64),
            bridge_enabled: pwm.enabled,
            disturbance_torque: disturbance,
        });
        sim.tick(&u);
    }
    // 2. Replay the same inputs open loop with the default and a ten times finer sub-step:
    //    the difference is the integration error alone (no feedback to amplify it).
    let mut coarse = Plant::new(*sim.plant.params())?;
    let mut fine_params = *sim.plant.params();
    fine_params.substeps = substeps * 10;
    let mut fine = Plant::new(fine_params)?;
    let mut err = [0.0f64; 4];
    let mut peak = [0.0f64; 4];
    for u in &inputs {
        // Each tick as the simulation runs it: the sensors sampled at its start (the plant
        // keeps the rotor's angle they saw for the step), then the step.
        for plant in [&mut coarse, &mut fine] {
            plant.measure();
            plant.advance(u);
        }
        let (x, y) = (coarse.state, fine.state);
        let pairs = [
            (x.iq, y.iq),
            (x.motor_velocity, y.motor_velocity),
            (x.load_velocity, y.load_velocity),
            (coarse.load_acceleration, fine.load_acceleration),
        ];
        for (i, (p, q)) in pairs.iter().enumerate() {
            err[i] = err[i].max((p - q).abs());
            peak[i] = peak[i].max(q.abs());
        }
    }
    // What the closed loop did is what is measured: a run whose bridge never drove a current
    // (a refused mode) measures nothing.
    if !(peak[0] > 0.1) {
        anyhow::bail!("the closed-loop run drove no current (iq peak {} A): nothing to replay", peak[0]);
    }
    let names = ["iq", "motor_velocity", "load_velocity", "load_acceleration"];
    let errors: Vec<(String, f64, f64)> = (0..4).map(|i| (names[i].to_string(), err[i], peak[i])).collect();
    let worst = errors.iter().map(|(_, e, p)| e / p).fold(0.0, f64::max);
    Ok(StepError {
        substeps,
        reference_substeps: fine_params.substeps,
        simulated_seconds: seconds,
        errors,
        worst_relative: worst,
        passed: worst <= GOAL,
    })
}

#[cfg(test)]
mod tests {
    /// The closed loop the bench replays drives the motor (a refused mode would leave the
    /// bridge off and nothing to measure), and the default sub-step holds its goal.
    #[test]
    fn the_replayed_run_drives_the_motor_and_the_default_step_holds_its_goal() {
        let r = super::step_error().unwrap();
        let (_, _, iq_peak) = &r.errors[0];
        assert!(*iq_peak > 1.0, "{r:?}");
        assert!(r.passed && r.worst_relative > 0.0, "{r:?}");
    }
}
