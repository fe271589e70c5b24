//! `servo bench fmu`: simulated seconds per wall-clock second for the default axis, through
//! the Rust host and through fmpy, in one run.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Result};
use serde::Serialize;

use crate::fmu::fmpy::run_fmpy;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Scenario;

#[derive(Clone, Debug, Serialize)]
pub struct FmuBench {
    pub simulated_seconds: f64,
    pub communication_steps: usize,
    /// The outputs recorded at every step in the headline figures ([`BENCH_RECORD`]).
    pub recorded_outputs: Vec<String>,
    /// Median over [`RUST_RUNS`] runs.
    pub rust_wall_seconds: f64,
    pub rust_real_time_factor: f64,
    /// The same run recording every output of the FMU (median over [`RUST_RUNS`] runs).
    pub all_outputs: usize,
    pub all_outputs_wall_seconds: f64,
    pub all_outputs_real_time_factor: f64,
    /// The all-outputs run reading every output at every step without keeping the rows.
    pub read_only_wall_seconds: f64,
    /// (read-only run − bare) / bare: the FMI boundary alone (median of per-repeat ratios).
    pub read_only_overhead: f64,
    /// Core + plant stepped directly (no FMI, no outputs), same schedule (median of [`RUST_RUNS`]).
    pub bare_wall_seconds: f64,
    pub bare_real_time_factor: f64,
    /// (all outputs through the FMI host − bare) / bare: what the boundary and the recording cost.
    pub boundary_overhead: f64,
    pub fmpy_wall_seconds: Option<f64>,
    pub fmpy_real_time_factor: Option<f64>,
    /// Rust host real-time factor over fmpy's (both recording [`BENCH_RECORD`]).
    pub rust_over_fmpy: Option<f64>,
}

/// What the benchmark records at every step: the outputs the FMU's specification names (motor
/// and load position and velocity, load acceleration, iq, id, torque command, following error,
/// fault flags). The figure with every output is printed beside it, and the bare simulation
/// (no FMI) under both.
pub const BENCH_RECORD: [&str; 10] = [
    "motor_position",
    "motor_velocity",
    "load_position",
    "load_velocity",
    "load_acceleration",
    "iq",
    "id",
    "torque_command_out",
    "following_error",
    "faults",
];

/// Rust-host runs per figure; the median is reported (a shared machine's wall clock jumps).
pub const RUST_RUNS: usize = 15;

/// The benchmark scenario: default axis in velocity mode, a slow ramp up and down with a
/// load disturbance, over `seconds` of simulated time, recording `record` (empty: every
/// output).
pub fn bench_scenario(seconds: f64, record: &[&str]) -> String {
    let record = if record.is_empty() { String::new() } else { format!("record = {record:?}\n") };
    format!(
        r#"name = "bench_default_axis"
description = "Default axis, velocity mode, steps up and down with a load disturbance"
stop_time = {seconds:?}
{record}
# The simulation's speed, not the commissioning's at initialisation: the drive is given the
# plant's mounting, as the bare run below.
[parameters]
"commissioning.at_start" = false

[[events]]
time = 0.0
mode = 1
velocity_command = 0.0

[[events]]
time = {t1:?}
velocity_command = 50.0

[[events]]
time = {t2:?}
disturbance_torque = 0.1

[[events]]
time = {t3:?}
velocity_command = -50.0
"#,
        t1 = grid(0.1 * seconds),
        t2 = grid(0.4 * seconds),
        t3 = grid(0.6 * seconds),
    )
}

/// The benchmark's schedule on the core and the plant stepped directly (no FMI, nothing
/// recorded): the wall time of one run.
pub fn bare_simulation_wall(seconds: f64) -> Result<f64> {
    use control_core::Mode;
    use servo_axis::simulation::{AxisSimulation, UserInputs};
    let config = servo_axis::parameters::default_config_given_mounting().map_err(anyhow::Error::msg)?;
    let h = crate::fmu::scenario::DEFAULT_STEP;
    let steps = (seconds / h).round() as usize;
    let (t1, t2, t3) = (grid(0.1 * seconds), grid(0.4 * seconds), grid(0.6 * seconds));
    let ticks = (h * config.control.rates.current_loop_hz as f64).round() as u64;
    let mut sim = AxisSimulation::new(&config).map_err(|e| anyhow::anyhow!("{e}"))?;
    let start = Instant::now();
    for k in 0..steps {
        let t = k as f64 * h + 1e-9 * h;
        let inputs = UserInputs {
            mode: Mode::Velocity,
            velocity_command: if t >= t3 {
                -50.0
            } else if t >= t1 {
                50.0
            } else {
                0.0
            },
            disturbance_torque: if t >= t2 { 0.1 } else { 0.0 },
            ..Default::default()
        };
        sim.apply_mode(&inputs);
        sim.run_ticks(ticks, &inputs);
    }
    let wall = start.elapsed().as_secs_f64();
    // The run did something (and the optimiser cannot drop it).
    let v = sim.plant.state.motor_velocity;
    if !(v.is_finite() && v.abs() > 1.0) {
        bail!("the bare simulation did not move the axis (final velocity {v})");
    }
    Ok(wall)
}

fn grid(t: f64) -> f64 {
    let h = crate::fmu::scenario::DEFAULT_STEP;
    (t / h).round() * h
}

pub fn bench_fmu(
    fmu_path: &Path,
    out: &Path,
    seconds: f64,
    with_fmpy: bool,
    mut progress: impl FnMut(f64),
) -> Result<FmuBench> {
    crate::paths::create_out_dir(out)?;
    let fmu = Fmu::load(fmu_path)?;
    let load = |record: &[&str], name: &str| -> Result<Scenario> {
        let path = out.join(format!("{name}.toml"));
        std::fs::write(&path, bench_scenario(seconds, record))?;
        Scenario::load(&path)
    };
    let scenario = load(&BENCH_RECORD, "bench")?;
    let all = load(&[], "bench_all_outputs")?;
    // The three runs interleaved in every repeat (a shared machine's speed drifts): each
    // figure is the median of its runs, the boundary's cost the median of the per-repeat
    // ratios of the all-outputs run to the bare run.
    let (mut walls, mut all_walls, mut bare_walls, mut ratios) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut read_walls, mut read_ratios) = (Vec::new(), Vec::new());
    let (mut trace, mut all_trace) = (None, None);
    for run in 0..RUST_RUNS {
        // The previous runs' traces are dropped before the clock starts.
        drop((trace.take(), all_trace.take()));
        let start = Instant::now();
        trace = Some(fmu.run(&scenario, |_| {})?);
        walls.push(start.elapsed().as_secs_f64());
        let start = Instant::now();
        all_trace = Some(fmu.run(&all, |_| {})?);
        let all_wall = start.elapsed().as_secs_f64();
        let start = Instant::now();
        fmu.run_reading_only(&all)?;
        let read_wall = start.elapsed().as_secs_f64();
        let bare = bare_simulation_wall(seconds)?;
        read_walls.push(read_wall);
        read_ratios.push(read_wall / bare - 1.0);
        all_walls.push(all_wall);
        bare_walls.push(bare);
        ratios.push(all_wall / bare - 1.0);
        progress((run + 1) as f64 / RUST_RUNS as f64);
    }
    trace.expect("RUST_RUNS > 0").write_csv(&out.join("bench_rust.csv"))?;
    all_trace.expect("RUST_RUNS > 0").write_csv(&out.join("bench_all_outputs_rust.csv"))?;
    let median = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let (rust_wall, all_wall, bare_wall, overhead) =
        (median(walls), median(all_walls), median(bare_walls), median(ratios));
    let (read_wall, read_overhead) = (median(read_walls), median(read_ratios));
    let fmpy_wall =
        if with_fmpy { Some(run_fmpy(fmu_path, &out.join("bench.toml"), &out.join("bench_fmpy.csv"))?) } else { None };
    let rust_rt = seconds / rust_wall;
    let fmpy_rt = fmpy_wall.map(|w| seconds / w);
    Ok(FmuBench {
        simulated_seconds: seconds,
        communication_steps: scenario.steps(),
        recorded_outputs: BENCH_RECORD.iter().map(|s| s.to_string()).collect(),
        rust_wall_seconds: rust_wall,
        rust_real_time_factor: rust_rt,
        all_outputs: fmu.outputs().len(),
        all_outputs_wall_seconds: all_wall,
        all_outputs_real_time_factor: seconds / all_wall,
        bare_wall_seconds: bare_wall,
        bare_real_time_factor: seconds / bare_wall,
        boundary_overhead: overhead,
        read_only_wall_seconds: read_wall,
        read_only_overhead: read_overhead,
        fmpy_wall_seconds: fmpy_wall,
        fmpy_real_time_factor: fmpy_rt,
        rust_over_fmpy: fmpy_rt.map(|f| rust_rt / f),
    })
}
