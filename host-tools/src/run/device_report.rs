//! `servo run --device`: each scenario on the drive, its checks on the drive's telemetry (a
//! check on a signal only a simulation has is listed as not measurable on a drive), the FMU
//! twin with the events as the drive got them, and the difference per trace — a table per
//! scenario, CSV of both runs, a plot, JSON.

use std::path::{Path, PathBuf};

use anyhow::Result;
use serde::Serialize;

use crate::cli::progress_bar;
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::telemetry_trace::difference;
use crate::device::timed_run::SentAt;
use crate::fmu::runner::{evaluate_checks, CheckResult, Fmu};
use crate::fmu::scenario::Scenario;
use crate::fmu::trace::Trace;
use crate::plot::signals::plot_signals;
use crate::run::device::scenario_on_drive;

/// The traces compared with the twin.
pub const COMPARED: [&str; 5] = ["motor_position", "velocity_estimate", "following_error", "iq", "torque_command_out"];

#[derive(Clone, Debug, Serialize)]
pub struct TraceDifference {
    pub signal: String,
    pub largest: f64,
    pub rms: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct DeviceScenarioReport {
    pub scenario: String,
    pub port: String,
    pub passed: bool,
    pub checks: Vec<CheckResult>,
    /// Checks on signals a drive does not have (the load's angle, the true speed, …).
    pub not_measurable: Vec<String>,
    pub events: Vec<SentAt>,
    pub twin_passed: bool,
    pub differences: Vec<TraceDifference>,
    pub files: Vec<PathBuf>,
}

pub fn run_on_device<T: DrivePort>(
    fmu: &Fmu,
    (port, session): (&str, &mut DriveSession<T>),
    files: &[PathBuf],
    out: &Path,
    json: bool,
) -> Result<bool> {
    let mut all_ok = true;
    let mut reports = Vec::new();
    for file in files {
        let scenario = Scenario::load(file)?;
        if let Some(why) = crate::run::device::not_for_a_drive(&scenario) {
            if !json {
                println!("{}: skipped on the drive: {why}", scenario.name);
            }
            continue;
        }
        let r = one(fmu, (port, session), &scenario, out, json)?;
        all_ok &= r.passed;
        if !json {
            print(&r);
        }
        reports.push(r);
    }
    if json {
        println!("{}", serde_json::to_string_pretty(&reports)?);
    }
    Ok(all_ok)
}

fn one<T: DrivePort>(
    fmu: &Fmu,
    (port, session): (&str, &mut DriveSession<T>),
    scenario: &Scenario,
    out: &Path,
    quiet: bool,
) -> Result<DeviceScenarioReport> {
    let pb = progress_bar(&scenario.name, quiet);
    let run = scenario_on_drive(session, scenario, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let (measurable, other): (Vec<_>, Vec<_>) =
        run.as_run.checks.iter().cloned().partition(|c| run.trace.index(&c.signal).is_some());
    let checks = evaluate_checks(&Scenario { checks: measurable, ..run.as_run.clone() }, &run.trace)?;
    let twin = fmu.run(&run.as_run, |_| {})?;
    let twin_passed = evaluate_checks(&run.as_run, &twin)?.iter().all(|c| c.passed);
    let differences = COMPARED
        .iter()
        .filter_map(|n| {
            difference(&run.trace, &twin, n).map(|(largest, rms)| TraceDifference {
                signal: n.to_string(),
                largest,
                rms,
            })
        })
        .collect();
    std::fs::create_dir_all(out)?;
    let csv = out.join(format!("{}.device.csv", scenario.name));
    run.trace.write_csv(&csv)?;
    let twin_csv = out.join(format!("{}.twin.csv", scenario.name));
    twin.write_csv(&twin_csv)?;
    let svg = out.join(format!("{}.svg", scenario.name));
    let signals: Vec<String> = COMPARED.iter().map(|s| s.to_string()).collect();
    let traces: Vec<(&str, &Trace)> = vec![("drive", &run.trace), ("FMU twin", &twin)];
    plot_signals(&svg, &format!("{} on the drive at {port}, and its twin", scenario.name), &traces, &signals)?;
    let mut r = DeviceScenarioReport {
        scenario: scenario.name.clone(),
        port: port.to_string(),
        passed: checks.iter().all(|c| c.passed),
        checks,
        not_measurable: other
            .iter()
            .map(|c| format!("{} ({})", c.description.clone().unwrap_or_default(), c.signal))
            .collect(),
        events: run.sent,
        twin_passed,
        differences,
        files: vec![csv, twin_csv, svg],
    };
    let json = out.join(format!("{}.json", scenario.name));
    std::fs::write(&json, serde_json::to_string_pretty(&r)?)?;
    r.files.push(json);
    Ok(r)
}

fn print(r: &DeviceScenarioReport) {
    println!("{} on the drive at {}", r.scenario, r.port);
    for c in &r.checks {
        println!(
            "  [{}] {:<45} {:<18} observed {:>11.6} … {:<11.6} bounds {} … {}",
            if c.passed { "pass" } else { "FAIL" },
            c.description,
            c.signal,
            c.observed.0,
            c.observed.1,
            c.min.map_or("-inf".into(), |x| x.to_string()),
            c.max.map_or("+inf".into(), |x| x.to_string()),
        );
    }
    for n in &r.not_measurable {
        println!("  [ -- ] not measurable on a drive: {n}");
    }
    let events: Vec<String> =
        r.events.iter().map(|k| format!("{:.4} → {:.4}…{:.4} s", k.planned, k.before, k.after)).collect();
    println!("  events as planned → when the drive got them: {}", events.join(", "));
    println!("  FMU twin (same events at the same times): checks {}", if r.twin_passed { "pass" } else { "FAIL" });
    for d in &r.differences {
        println!("  drive − twin {:<20} largest {:>10.4}  rms {:>10.4}", d.signal, d.largest, d.rms);
    }
    for f in &r.files {
        println!("  → {}", f.display());
    }
}
