//! `servo run`: scenarios on the FMU; `servo compare`: two traces bit for bit.

use std::path::PathBuf;

use anyhow::{bail, Result};

use crate::cli::progress_bar;
use crate::fmu::fmpy;
use crate::fmu::runner::{evaluate_checks, Fmu};
use crate::fmu::scenario::Scenario;
use crate::fmu::trace::{compare_exact, Trace};
use crate::paths::toml_files_in;
use crate::paths::{default_fmu, default_out, workspace_root};
use crate::plot::signals::plot_signals;
use crate::run::args::{CompareArgs, RunArgs};
use crate::run::report::{write_html, ScenarioReport};

const DEFAULT_PLOT: [&str; 5] = ["motor_position", "motor_velocity", "load_velocity", "iq", "torque_command_out"];

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

impl RunArgs {
    pub fn run(&self) -> Result<bool> {
        run(self)
    }
}

fn run(args: &RunArgs) -> Result<bool> {
    let (files, with_fmpy, common) = (&args.scenarios, args.fmpy, &args.common);
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("run"));
    crate::paths::create_out_dir(&out)?;
    let fmu = Fmu::load(&fmu_path)?;
    if let Some(mut session) = args.target.session()? {
        let port = args.target.device.as_deref().unwrap_or_default();
        return crate::run::device_report::run_on_device(
            &*fmu.as_twin_of(&session.params_for_twin()?)?,
            (port, &mut session),
            &scenario_files(files)?,
            &out,
            common.json,
        );
    }
    let mut all_ok = true;
    let mut reports = Vec::new();
    let mut summary = Vec::new();
    for file in scenario_files(files)? {
        let scenario = Scenario::load(&file)?;
        let pb = progress_bar(&scenario.name, common.json);
        let trace = fmu.run(&scenario, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        // What the FMU refused during the run (a sweep it cannot run, a refused key).
        let fmu_warnings = crate::fmu::log::take();
        let csv = out.join(format!("{}.csv", scenario.name));
        trace.write_csv(&csv)?;
        let checks = evaluate_checks(&scenario, &trace)?;
        let mut fmpy_verdict = None;
        let mut traces: Vec<(&str, &Trace)> = vec![("Rust host (fmi crate)", &trace)];
        let fmpy_trace;
        if with_fmpy {
            let fmpy_csv = out.join(format!("{}.fmpy.csv", scenario.name));
            let verdict;
            (verdict, fmpy_trace) = fmpy::fmpy_cross_check(&fmu_path, &file, &trace, &fmpy_csv)?;
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
            "fmpy": fmpy_verdict.as_ref().map(fmpy::verdict_json),
            "fmu_warnings": fmu_warnings,
            "csv": csv,
            "plot": svg,
        });
        std::fs::write(out.join(format!("{}.json", scenario.name)), serde_json::to_string_pretty(&json)?)?;
        if !common.json {
            println!("{} — {}", scenario.name, scenario.description);
            for c in &checks {
                crate::run::report::print_check(c);
            }
            for w in &fmu_warnings {
                println!("  FMU: {w}");
            }
            if let Some(v) = &fmpy_verdict {
                fmpy::print_verdict("fmpy cross-check", v);
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

impl CompareArgs {
    pub fn run(&self) -> Result<bool> {
        let (ta, tb) = (Trace::read_csv(&self.a)?, Trace::read_csv(&self.b)?);
        // Traces of different lengths are an answer (they differ), not bad input.
        if ta.rows.len() != tb.rows.len() {
            println!("differ: {} vs {} rows", ta.rows.len(), tb.rows.len());
            return Ok(false);
        }
        match compare_exact(&ta, &tb)? {
            Ok(n) => {
                println!("identical: {} rows × {n} common columns, bit for bit", ta.rows.len());
                Ok(true)
            }
            Err(m) => {
                println!("differ: {} at row {}: {:?} vs {:?}", m.column, m.row, m.left, m.right);
                Ok(false)
            }
        }
    }
}
