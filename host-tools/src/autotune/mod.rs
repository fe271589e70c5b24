//! Tuning the user's machine: its mechanics calibrated from a measured plant response
//! (`calibration`), and the velocity loop's gains and torque filters chosen from the
//! response for the widest bandwidth that keeps its margins (`design`), checked on the loop
//! the drive runs (`velocity_controller`, `drive_dynamics`, `margins`).

pub mod axis_under_test;
pub mod bench;
pub mod calibration;
pub mod command;
pub mod design;
pub mod design_checks;
pub mod drive_dynamics;
pub mod index;
pub mod margins;
pub mod measured_mechanics;
pub mod mechanics;
pub mod position_loop_design;
pub mod prediction;
pub mod refinement;
pub mod report;
pub mod reserve;
pub mod responses;
pub mod sampled_plant;
pub mod step_on_twin;
pub mod velocity_controller;
pub mod verification;

use num_complex::Complex64;

use drive_dynamics::DriveDynamics;
use mechanics::Mechanics;

/// The plant from the current loop's per-tick torque reference to the velocity estimate: the
/// drive's part times the machine's.
pub fn plant_response(drive: &DriveDynamics, mechanics: &Mechanics, f: f64) -> Complex64 {
    let m = mechanics.motor_velocity_per_torque(f);
    drive.around_machine(f, m) * m
}

/// A torque at the motor (a load step, N·m) to the velocity estimate: the machine's motor
/// velocity per torque behind the estimate, with what the back-EMF path leaves of it (no
/// command hold on that path).
pub fn disturbance_response(drive: &DriveDynamics, mechanics: &Mechanics, f: f64) -> Complex64 {
    let m = mechanics.motor_velocity_per_torque(f);
    drive.velocity_estimate(f) * m * drive.back_emf_path(f, m)
}

/// The plant the velocity loop drives: [`plant_response`] behind the command's hold over the
/// velocity period.
pub fn loop_plant(drive: &DriveDynamics, mechanics: &Mechanics, f: f64) -> Complex64 {
    drive.command_hold(f) * plant_response(drive, mechanics, f)
}

/// A stepped-sine sweep's settings at `point` with `amplitude` over the default frequencies
/// (10 Hz to 3 kHz, see [`SweepParams::default`](control_core::phase_shifted_sweep::SweepParams)).
pub fn sweep_settings(
    point: control_core::excitation::InjectionPoint,
    amplitude: f64,
) -> control_core::phase_shifted_sweep::SweepParams {
    control_core::phase_shifted_sweep::SweepParams { point, amplitude: amplitude as f32, ..Default::default() }
}

/// The measured points of a torque-point sweep turned into the plant [`plant_response`]
/// models, taking out the path the velocity loop running during the sweep (`during`) closes
/// beside U ([`DriveDynamics::plant_of_torque_sweep`]).
pub fn plant_points(
    readings: &[crate::analysis::response_point::ResponsePoint],
    drive: &DriveDynamics,
    during: &velocity_controller::VelocityTuning,
) -> Vec<calibration::PlantPoint> {
    readings
        .iter()
        .filter(|p| p.gain_db.is_finite() && p.phase_deg.is_finite())
        .map(|p| {
            let g = p.to_complex();
            let c = during.response(p.frequency, drive.velocity_period);
            calibration::PlantPoint { hz: p.frequency, response: drive.plant_of_torque_sweep(p.frequency, g, c) }
        })
        .collect()
}

/// A sweep's measured points with a finite response, the drive time it took (s, from the
/// command to ride to the sweep's end), and how many of its frequencies were measured with
/// the torque command at a limit (their response is not the linear loop's).
pub struct MeasuredSweep {
    pub points: Vec<crate::analysis::response_point::ResponsePoint>,
    pub drive_time_s: f64,
    pub torque_limited: usize,
    /// How many were measured with the current loop's output at the voltage circle (the
    /// drive's flag, on a drive's sweep; 0 on the FMU, whose plant runs without that limit).
    pub voltage_limited: usize,
    /// The torque command's limit the sweep ran under (N·m).
    pub torque_limit: f64,
}

/// A sweep of `settings` on the FMU (a drive's twin or the plant of `parameters`), riding at
/// `velocity` rad/s.
pub fn sweep_on_fmu(
    fmu: &crate::fmu::runner::Fmu,
    settings: &control_core::phase_shifted_sweep::SweepParams,
    parameters: &std::collections::BTreeMap<String, crate::fmu::scenario::Value>,
    velocity: f64,
) -> anyhow::Result<MeasuredSweep> {
    let run = crate::fmu::sweep_run::SweepRun { settings: *settings, parameters: parameters.clone(), velocity };
    let trace = run.run(fmu, |_| {})?;
    let points = crate::sweep::measurement::stream_results(&trace, &run.settings)?;
    let limits = crate::sweep::torque_limit::TorqueLimits::of(&run.params_on(fmu)?, &run.settings);
    let shares = crate::sweep::torque_limit::torque_limited_shares(&trace, &limits)?;
    Ok(MeasuredSweep {
        points: points.into_iter().filter(|p| p.gain_db.is_finite() && p.phase_deg.is_finite()).collect(),
        drive_time_s: trace.rows.last().map_or(0.0, |r| r[0]),
        torque_limited: shares.values().filter(|&&s| s > 0.0).count(),
        voltage_limited: 0,
        torque_limit: limits.lowest(),
    })
}
