//! Plant integration error: the closed-loop default axis simulated with the default RK4
//! sub-steps and with ten times as many, compared sample by sample.

use anyhow::Result;
use control_core::Mode;
use serde::Serialize;
use servo_axis::simulation::{AxisSimulation, SimulationConfig, UserInputs};

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
    let base = SimulationConfig::default();
    let substeps = base.plant.substeps;
    let mut fine = base;
    fine.plant.substeps = substeps * 10;
    let mut a = AxisSimulation::new(&base)?;
    let mut b = AxisSimulation::new(&fine)?;
    let seconds = 0.2;
    let ticks = (seconds / a.tick_period()).round() as usize;
    let mut err = [0.0f64; 4];
    let mut peak = [0.0f64; 4];
    for k in 0..ticks {
        let t = k as f64 * a.tick_period();
        let u = UserInputs {
            mode: Mode::Velocity,
            velocity_command: if t < 0.1 { 100.0 } else { -50.0 },
            disturbance_torque: if t > 0.05 { 0.2 } else { 0.0 },
            ..Default::default()
        };
        a.tick(&u);
        b.tick(&u);
        let (x, y) = (a.plant.state, b.plant.state);
        let pairs = [
            (x.iq, y.iq),
            (x.motor_velocity, y.motor_velocity),
            (x.load_velocity, y.load_velocity),
            (a.plant.load_acceleration, b.plant.load_acceleration),
        ];
        for (i, (p, q)) in pairs.iter().enumerate() {
            err[i] = err[i].max((p - q).abs());
            peak[i] = peak[i].max(q.abs());
        }
    }
    let names = ["iq", "motor_velocity", "load_velocity", "load_acceleration"];
    let errors: Vec<(String, f64, f64)> = (0..4).map(|i| (names[i].to_string(), err[i], peak[i])).collect();
    let worst = errors.iter().map(|(_, e, p)| e / p).fold(0.0, f64::max);
    Ok(StepError {
        substeps,
        reference_substeps: fine.plant.substeps,
        simulated_seconds: seconds,
        errors,
        worst_relative: worst,
        passed: worst <= 1e-4,
    })
}
