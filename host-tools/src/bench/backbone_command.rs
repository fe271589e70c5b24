//! `servo bench fmu` and `servo bench plant`: the backbone benchmarks.

use anyhow::{bail, Result};

use crate::bench::args::{FmuBenchArgs, PlantBenchArgs};
use crate::bench::figures::Recorder;
use crate::bench::fmu_speed as bench;
use crate::cli::progress_bar;
use crate::paths::{default_fmu, default_out};

impl FmuBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_fmu(self)
    }
}

/// The most the FMI boundary and the recording of every output may cost, as a share of the
/// bare simulation (median of the per-repeat ratios).
pub const BOUNDARY_GOAL: f64 = 0.10;

fn bench_fmu(args: &FmuBenchArgs) -> Result<bool> {
    let (seconds, no_fmpy, goal, common) = (args.seconds, args.no_fmpy, args.goal, &args.common);
    if !(seconds.is_finite() && seconds > 0.0) {
        bail!("--seconds must be a positive number");
    }
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("bench"));
    let pb = progress_bar("Rust host", common.json);
    let r = bench::bench_fmu(&fmu_path, &out, seconds, !no_fmpy, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    // Goals: the run recording every output through the Rust host at `goal` x real time or
    // faster, and the FMI boundary with the recording at most BOUNDARY_GOAL of the bare
    // simulation; either one missed fails the bench.
    let speed_ok = r.all_outputs_real_time_factor >= goal;
    let boundary_ok = r.boundary_overhead <= BOUNDARY_GOAL;
    let ok = speed_ok && boundary_ok;
    let mut figures = Recorder::new("fmu");
    figures
        .at_least(
            &format!("speed through the Rust host, recording all {} outputs (real-time factor)", r.all_outputs),
            r.all_outputs_real_time_factor,
            goal,
            "×",
        )
        .at_most(
            &format!("the FMI boundary and recording all {} outputs, against the bare simulation", r.all_outputs),
            100.0 * r.boundary_overhead,
            100.0 * BOUNDARY_GOAL,
            "%",
        )
        .info(
            &format!("speed recording the specification's {} outputs", r.recorded_outputs.len()),
            r.rust_real_time_factor,
            "×",
        )
        .info("speed of the bare simulation (core and plant, no FMI)", r.bare_real_time_factor, "×");
    if let Some(f) = r.fmpy_real_time_factor {
        figures.info("speed through fmpy", f, "×");
    }
    figures.write(common.out.as_deref(), ok)?;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "bench": "fmu",
                "result": r,
                "goal": goal,
                "boundary_goal": BOUNDARY_GOAL,
                "speed_met": speed_ok,
                "boundary_met": boundary_ok,
                "passed": ok
            }))?
        );
    } else {
        println!(
            "servo bench fmu — default axis, {} s simulated, {} communication steps",
            r.simulated_seconds, r.communication_steps
        );
        println!(
            "  recording the {} outputs the FMU's specification names ({}) at every step:",
            r.recorded_outputs.len(),
            r.recorded_outputs.join(", ")
        );
        println!(
            "    Rust host (fmi crate): {:>8.3} s wall  → {:>8.1} x real time  (median of {} runs)",
            r.rust_wall_seconds,
            r.rust_real_time_factor,
            bench::RUST_RUNS
        );
        if let (Some(w), Some(f)) = (r.fmpy_wall_seconds, r.fmpy_real_time_factor) {
            println!("    fmpy                 : {:>8.3} s wall  → {:>8.1} x real time", w, f);
            println!("    ratio Rust / fmpy    : {:>8.2}", r.rust_over_fmpy.unwrap_or(f64::NAN));
        }
        println!("  recording all {} outputs at every step:", r.all_outputs);
        println!(
            "    Rust host (fmi crate): {:>8.3} s wall  → {:>8.1} x real time  (median of {} runs)",
            r.all_outputs_wall_seconds,
            r.all_outputs_real_time_factor,
            bench::RUST_RUNS
        );
        println!(
            "  bare simulation (core + plant, no FMI): {:>8.3} s wall  → {:>8.1} x real time  (median of {} runs)",
            r.bare_wall_seconds,
            r.bare_real_time_factor,
            bench::RUST_RUNS
        );
        println!(
            "  reading all {} outputs at every step without keeping them: {:>8.3} s wall, {:+.1} % of the bare simulation (the boundary alone)",
            r.all_outputs,
            r.read_only_wall_seconds,
            100.0 * r.read_only_overhead
        );
        println!(
            "  goal: the FMI boundary and recording all {} outputs ≤ {:.0} % of the bare simulation: {:+.1} %, {}",
            r.all_outputs,
            100.0 * BOUNDARY_GOAL,
            100.0 * r.boundary_overhead,
            if boundary_ok { "met" } else { "NOT met" }
        );
        println!(
            "  goal: ≥ {goal} x real time through the Rust host recording all {} outputs: {:.1} x, {}",
            r.all_outputs,
            r.all_outputs_real_time_factor,
            if speed_ok { "met" } else { "NOT met" }
        );
    }
    Ok(ok)
}

impl PlantBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_plant(self)
    }
}

fn bench_plant(args: &PlantBenchArgs) -> Result<bool> {
    let common = &args.common;
    let r = crate::bench::plant::step_error()?;
    Recorder::new("plant")
        .at_most(
            "plant step error against a ten times finer step, relative to the signal's peak",
            r.worst_relative,
            crate::bench::plant::GOAL,
            "",
        )
        .write(common.out.as_deref(), r.passed)?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!("servo bench plant — exact linear parts, {} sub-step(s) per 62.5 µs tick vs {} (reference), inverter commands of {} s of closed-loop velocity steps replayed open loop", r.substeps, r.reference_substeps, r.simulated_seconds);
        for (name, err, scale) in &r.errors {
            println!("  {name:<16} max |error| {err:>10.3e}  (signal peak {scale:.3e}, relative {:.2e})", err / scale);
        }
        println!(
            "  largest relative error: {:.2e} (goal ≤ {:.0e}): {}",
            r.worst_relative,
            crate::bench::plant::GOAL,
            if r.passed { "met" } else { "NOT met" }
        );
    }
    Ok(r.passed)
}
