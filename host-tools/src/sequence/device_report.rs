//! `servo sequence --device`: each timeline on the drive, its expectations checked on the
//! drive's telemetry, the FMU twin replaying the keys as the drive got them, and the
//! difference per trace — a table per timeline, CSV of both runs, a plot, JSON.

use std::path::{Path, PathBuf};

use anyhow::Result;
use serde::Serialize;

use crate::cli::progress_bar;
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::telemetry_trace::difference;
use crate::device::timed_run::SentAt;
use crate::fmu::runner::Fmu;
use crate::fmu::trace::Trace;
use crate::plot::signals::plot_signals;
use crate::sequence::device::timeline_on_drive;
use crate::sequence::timeline::{Outcome, SequenceScenario, PLOT};

/// The traces compared with the twin.
pub const COMPARED: [&str; 4] = ["velocity_estimate", "following_error", "seq_deviation", "seq_state"];

#[derive(Clone, Debug, Serialize)]
pub struct TraceDifference {
    pub signal: String,
    pub largest: f64,
    pub rms: f64,
}

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
    let mut all_ok = true;
    let mut reports = Vec::new();
    for file in files {
        let s = SequenceScenario::load(file)?;
        let r = one(fmu, (port, session), &s, out, json)?;
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
    s: &SequenceScenario,
    out: &Path,
    quiet: bool,
) -> Result<DeviceTimelineReport> {
    let pb = progress_bar(&s.name, quiet);
    let run = timeline_on_drive(session, s, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let expectations = run.as_run.evaluate(&run.trace)?;
    let twin = fmu.run(&run.as_run.to_scenario(), |_| {})?;
    let twin_passed = run.as_run.evaluate(&twin)?.iter().all(|o| o.passed);
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
    let csv = out.join(format!("{}.device.csv", s.name));
    run.trace.write_csv(&csv)?;
    let twin_csv = out.join(format!("{}.twin.csv", s.name));
    twin.write_csv(&twin_csv)?;
    let svg = out.join(format!("{}.svg", s.name));
    let traces: Vec<(&str, &Trace)> = vec![("drive", &run.trace), ("FMU twin", &twin)];
    plot_signals(&svg, &format!("{} on the drive at {port}, and its twin", s.name), &traces, &PLOT.map(String::from))?;
    let mut r = DeviceTimelineReport {
        scenario: s.name.clone(),
        port: port.to_string(),
        passed: expectations.iter().all(|o| o.passed),
        expectations,
        keys: run.keys,
        twin_passed,
        differences,
        files: vec![csv, twin_csv, svg],
    };
    let json = out.join(format!("{}.json", s.name));
    std::fs::write(&json, serde_json::to_string_pretty(&r)?)?;
    r.files.push(json);
    Ok(r)
}

fn print(r: &DeviceTimelineReport) {
    println!("{} on the drive at {}", r.scenario, r.port);
    for o in &r.expectations {
        println!(
            "  [{}] {:<52} {:<48} asked: {}",
            if o.passed { "pass" } else { "FAIL" },
            o.description,
            o.observed,
            o.bound
        );
    }
    let keys: Vec<String> =
        r.keys.iter().map(|k| format!("{} {:.4} → {:.4}…{:.4} s", k.label, k.planned, k.before, k.after)).collect();
    println!("  keys as planned → when the drive got them: {}", keys.join(", "));
    println!("  FMU twin (same keys at the same times): expectations {}", if r.twin_passed { "pass" } else { "FAIL" });
    for d in &r.differences {
        println!("  drive − twin {:<20} largest {:>10.4}  rms {:>10.4}", d.signal, d.largest, d.rms);
    }
    for f in &r.files {
        println!("  → {}", f.display());
    }
}
