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
use crate::device::timed_run::SentAt;
use crate::device::twin::{each_file, print_twin_lines, trace_differences, write_runs, TraceDifference};
use crate::fmu::runner::{evaluate_checks, CheckResult, Fmu};
use crate::fmu::scenario::Scenario;
use crate::run::device::scenario_on_drive;

/// The traces compared with the twin.
pub const COMPARED: [&str; 5] = ["motor_position", "velocity_estimate", "following_error", "iq", "torque_command_out"];

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
    let run_one = |file: &Path| -> Result<Option<DeviceScenarioReport>> {
        let scenario = Scenario::load(file)?;
        crate::fmu::runner::refuse_drive_owned(scenario.parameters.keys())?;
        if let Some(why) = crate::run::device::not_for_a_drive(&scenario) {
            if !json {
                println!("{}: skipped on the drive: {why}", scenario.name);
            }
            return Ok(None);
        }
        one(fmu, (port, &mut *session), &scenario, out, json).map(Some)
    };
    each_file(files, json, run_one, |r| r.passed, print)
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
    let twin = fmu.run(&run.twin, |_| {})?;
    let twin_passed = evaluate_checks(&run.twin, &twin)?.iter().all(|c| c.passed);
    let differences = trace_differences(&run.trace, &twin, &COMPARED);
    let signals: Vec<String> = COMPARED.iter().map(|s| s.to_string()).collect();
    let files = write_runs(out, (&scenario.name, port), (&run.trace, &twin), &signals)?;
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
        files,
    };
    let json = out.join(format!("{}.json", scenario.name));
    std::fs::write(&json, serde_json::to_string_pretty(&r)?)?;
    r.files.push(json);
    Ok(r)
}

fn print(r: &DeviceScenarioReport) {
    println!("{} on the drive at {}", r.scenario, r.port);
    for c in &r.checks {
        crate::run::report::print_check(c);
    }
    for n in &r.not_measurable {
        println!("  [ -- ] not measurable on a drive: {n}");
    }
    print_twin_lines(&r.events, r.twin_passed, &r.differences, &r.files);
}
