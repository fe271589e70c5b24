//! `servo sequence --device`: each timeline on the drive, its expectations checked on the
//! drive's telemetry, the FMU twin replaying the keys as the drive got them, and the
//! difference per trace — a table per timeline, CSV of both runs, a plot, JSON.

use std::path::{Path, PathBuf};

use anyhow::Result;
use serde::Serialize;

use crate::cli::progress_bar;
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::timed_run::SentAt;
use crate::device::twin::{each_file, print_twin_lines, trace_differences, write_runs, TraceDifference};
use crate::fmu::runner::Fmu;
use crate::sequence::device::timeline_on_drive;
use crate::sequence::timeline::{Outcome, SequenceScenario, PLOT};

/// The traces compared with the twin.
pub const COMPARED: [&str; 4] = ["velocity_estimate", "following_error", "seq_deviation", "seq_state"];

#[derive(Clone, Debug, Serialize)]
pub struct DeviceTimelineReport {
    pub scenario: String,
    pub port: String,
    pub passed: bool,
    pub expectations: Vec<Outcome>,
    pub keys: Vec<SentAt>,
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
    let run_one = |file: &Path| -> Result<Option<DeviceTimelineReport>> {
        let s = SequenceScenario::load(file)?;
        crate::fmu::runner::refuse_drive_owned(s.parameters.keys())?;
        one(fmu, (port, &mut *session), &s, out, json).map(Some)
    };
    each_file(files, json, run_one, |r| r.passed, print)
}

fn one<T: DrivePort>(
    fmu: &Fmu,
    (port, session): (&str, &mut DriveSession<T>),
    s: &SequenceScenario,
    out: &Path,
    quiet: bool,
) -> Result<DeviceTimelineReport> {
    let pb = progress_bar(&s.name, quiet);
    let run = timeline_on_drive(session, s, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let expectations = run.as_run.evaluate(&run.trace)?;
    let twin = fmu.run(&run.twin.to_scenario(), |_| {})?;
    let twin_passed = run.twin.evaluate(&twin)?.iter().all(|o| o.passed);
    let differences = trace_differences(&run.trace, &twin, &COMPARED);
    let files = write_runs(out, (&s.name, port), (&run.trace, &twin), &PLOT.map(String::from))?;
    let mut r = DeviceTimelineReport {
        scenario: s.name.clone(),
        port: port.to_string(),
        passed: expectations.iter().all(|o| o.passed),
        expectations,
        keys: run.keys,
        twin_passed,
        differences,
        files,
    };
    let json = out.join(format!("{}.json", s.name));
    std::fs::write(&json, serde_json::to_string_pretty(&r)?)?;
    r.files.push(json);
    Ok(r)
}

fn print(r: &DeviceTimelineReport) {
    println!("{} on the drive at {}", r.scenario, r.port);
    for o in &r.expectations {
        o.print();
    }
    print_twin_lines(&r.keys, r.twin_passed, &r.differences, &r.files);
}
