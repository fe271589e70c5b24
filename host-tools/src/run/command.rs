//! `servo run`, `servo bench fmu`, `servo bench plant`: scenarios on the FMU and the backbone benchmarks.

use std::path::PathBuf;

use anyhow::{bail, Context, Result};

use crate::bench::fmu_speed as bench;
use crate::cli::{progress_bar, Common};
use crate::fmu::runner::{evaluate_checks, Fmu};
use crate::fmu::scenario::Scenario;
use crate::fmu::trace::Trace;
use crate::paths::{default_fmu, default_out, workspace_root};
use crate::plot::signals::plot_signals;
use crate::run::report::{write_html, ScenarioReport};

const DEFAULT_PLOT: [&str; 5] = ["motor_position", "motor_velocity", "load_velocity", "iq", "torque_command_out"];

/// The `.toml` files of a folder, sorted.
pub fn toml_files_in(dir: &std::path::Path) -> Result<Vec<PathBuf>> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    v.sort();
    Ok(v)
}

pub fn scenario_files(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
    if !given.is_empty() {
        return Ok(given.to_vec());
    }
    let dir = workspace_root().join("scenarios");
    let v = toml_files_in(&dir)?;
    if v.is_empty() {
        bail!("no scenario files in {}", dir.display());
    }
    Ok(v)
}

pub fn run(files: &[PathBuf], with_fmpy: bool, common: &Common) -> Result<bool> {
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("run"));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let fmu = Fmu::load(&fmu_path)?;
    let mut all_ok = true;
    let mut reports = Vec::new();
    let mut summary = Vec::new();
    for file in scenario_files(files)? {
        let scenario = Scenario::load(&file)?;
        let pb = progress_bar(&scenario.name, common.json);
        let trace = fmu.run(&scenario, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        let csv = out.join(format!("{}.csv", scenario.name));
        trace.write_csv(&csv)?;
        let checks = evaluate_checks(&scenario, &trace)?;
        let mut fmpy_verdict = None;
        let mut traces: Vec<(&str, &Trace)> = vec![("Rust host (fmi crate)", &trace)];
        let fmpy_trace;
        if with_fmpy {
            let fmpy_csv = out.join(format!("{}.fmpy.csv", scenario.name));
            let verdict;
            (verdict, fmpy_trace) = bench::fmpy_cross_check(&fmu_path, &file, &trace, &fmpy_csv)?;
            all_ok &= verdict.is_ok();
            fmpy_verdict = Some(verdict);
            traces.push(("fmpy", &fmpy_trace));
        }
        let signals: Vec<String> = if scenario.plot.is_empty() {
            // The standard set, as far as the scenario records it (else what it records).
            let standard: Vec<String> =
                DEFAULT_PLOT.iter().filter(|s| trace.index(s).is_some()).map(|s| s.to_string()).collect();
            if standard.is_empty() {
                trace.columns.iter().skip(1).take(DEFAULT_PLOT.len()).cloned().collect()
            } else {
                standard
            }
        } else {
            scenario.plot.clone()
        };
        let svg = out.join(format!("{}.svg", scenario.name));
        plot_signals(&svg, &format!("{}: {}", scenario.name, scenario.description), &traces, &signals)?;
        let passed = checks.iter().all(|c| c.passed);
        all_ok &= passed;
        let json = serde_json::json!({
            "scenario": scenario.name,
            "passed": passed,
            "checks": checks,
            "fmpy": fmpy_verdict.as_ref().map(bench::verdict_json),
            "csv": csv,
            "plot": svg,
        });
        std::fs::write(out.join(format!("{}.json", scenario.name)), serde_json::to_string_pretty(&json)?)?;
        if !common.json {
            println!("{} — {}", scenario.name, scenario.description);
            for c in &checks {
                println!(
                    "  [{}] {:<45} {:<16} observed {:>11.6} … {:<11.6} bounds {} … {}",
                    if c.passed { "pass" } else { "FAIL" },
                    c.description,
                    c.signal,
                    c.observed.0,
                    c.observed.1,
                    c.min.map_or("-inf".into(), |x| x.to_string()),
                    c.max.map_or("+inf".into(), |x| x.to_string()),
                );
            }
            if let Some(v) = &fmpy_verdict {
                bench::print_verdict("fmpy cross-check", v);
            }
            println!("  → {} , {}", csv.display(), svg.display());
        }
        summary.push(json);
        reports.push(ScenarioReport {
            name: scenario.name.clone(),
            description: scenario.description.clone(),
            checks,
            fmpy: fmpy_verdict,
            plot_file: format!("{}.svg", scenario.name),
            csv_file: format!("{}.csv", scenario.name),
        });
    }
    let index = out.join("index.html");
    write_html(&index, "Servo axis scenarios", &format!("<p>FMU: <code>{}</code></p>", fmu_path.display()), &reports)?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("report: {}", index.display());
    }
    Ok(all_ok)
}

pub fn bench_fmu(seconds: f64, no_fmpy: bool, goal: f64, common: &Common) -> Result<bool> {
    if !(seconds.is_finite() && seconds > 0.0) {
        bail!("--seconds must be a positive number");
    }
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("bench"));
    let pb = progress_bar("Rust host", common.json);
    let r = bench::bench_fmu(&fmu_path, &out, seconds, !no_fmpy, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let speed_ok = r.rust_real_time_factor >= goal;
    let ok = speed_ok && r.boundary_overhead <= 0.10;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"bench": "fmu", "result": r, "goal": goal, "passed": ok})
            )?
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
            "  the FMI boundary and recording all {} outputs cost {:+.1} % of the bare simulation (goal ≤ 10 %): {}",
            r.all_outputs,
            100.0 * r.boundary_overhead,
            if r.boundary_overhead <= 0.10 { "met" } else { "NOT met" }
        );
        println!(
            "  goal ≥ {goal} x real time through the Rust host (the specification's outputs): {}",
            if speed_ok { "met" } else { "NOT met" }
        );
    }
    Ok(ok)
}

pub fn bench_plant(common: &Common) -> Result<bool> {
    let r = crate::bench::plant::step_error()?;
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
