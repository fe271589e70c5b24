//! What every experiment on a drive shares with its FMU twin: the difference per trace
//! (largest, rms), the files of both runs (CSV each, one plot with both), and their lines in
//! the report.

use std::path::{Path, PathBuf};

use anyhow::Result;
use serde::Serialize;

use crate::analysis::response_point::ResponsePoint;
use crate::device::telemetry_trace::difference;
use crate::device::timed_run::SentAt;
use crate::fmu::trace::Trace;
use crate::plot::signals::plot_signals;

/// One frequency point of a response measured on a drive and on its FMU twin (`servo ident
/// --device`, the machine end of `servo tune --device`).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct DriveTwinPoint {
    pub frequency: f64,
    pub drive_db: f64,
    pub drive_deg: f64,
    pub twin_db: f64,
    pub twin_deg: f64,
    /// Drive − twin (dB, degrees).
    pub difference_db: f64,
    pub difference_deg: f64,
}

impl DriveTwinPoint {
    /// The drive's and the twin's point at `drive`'s frequency, and their difference as the
    /// caller found it (infinite where the two grids do not match).
    pub fn new(drive: &ResponsePoint, twin: &ResponsePoint, (difference_db, difference_deg): (f64, f64)) -> Self {
        Self {
            frequency: drive.frequency,
            drive_db: drive.gain_db,
            drive_deg: drive.phase_deg,
            twin_db: twin.gain_db,
            twin_deg: twin.phase_deg,
            difference_db,
            difference_deg,
        }
    }

    /// The drive's point.
    pub fn drive(&self) -> ResponsePoint {
        ResponsePoint { frequency: self.frequency, gain_db: self.drive_db, phase_deg: self.drive_deg, quality: 1.0 }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct TraceDifference {
    pub signal: String,
    pub largest: f64,
    pub rms: f64,
}

/// Drive − twin for each of `signals` both traces have.
pub fn trace_differences(drive: &Trace, twin: &Trace, signals: &[&str]) -> Vec<TraceDifference> {
    signals
        .iter()
        .filter_map(|n| {
            difference(drive, twin, n).map(|(largest, rms)| TraceDifference { signal: n.to_string(), largest, rms })
        })
        .collect()
}

/// `<name>.device.csv`, `<name>.twin.csv` and `<name>.svg` (both runs on one plot) in `out`.
pub fn write_runs(
    out: &Path,
    (name, port): (&str, &str),
    (drive, twin): (&Trace, &Trace),
    signals: &[String],
) -> Result<Vec<PathBuf>> {
    crate::paths::create_out_dir(out)?;
    let csv = out.join(format!("{name}.device.csv"));
    drive.write_csv(&csv)?;
    let twin_csv = out.join(format!("{name}.twin.csv"));
    twin.write_csv(&twin_csv)?;
    let svg = out.join(format!("{name}.svg"));
    let traces: Vec<(&str, &Trace)> = vec![("drive", drive), ("FMU twin", twin)];
    plot_signals(&svg, &format!("{name} on the drive at {port}, and its twin"), &traces, signals)?;
    Ok(vec![csv, twin_csv, svg])
}

/// Each of `files` through `one` (`None`: skipped, it said why), its report printed unless
/// `json`, then the reports as one JSON array if `json`; whether every run passed.
pub fn each_file<R: Serialize>(
    files: &[PathBuf],
    json: bool,
    mut one: impl FnMut(&Path) -> Result<Option<R>>,
    passed: impl Fn(&R) -> bool,
    print: impl Fn(&R),
) -> Result<bool> {
    let mut all_ok = true;
    let mut reports = Vec::new();
    for file in files {
        let Some(r) = one(file)? else { continue };
        all_ok &= passed(&r);
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

/// The report's lines on the inputs as sent, the twin's verdict and the differences.
pub fn print_twin_lines(sent: &[SentAt], twin_passed: bool, differences: &[TraceDifference], files: &[PathBuf]) {
    let sent: Vec<String> =
        sent.iter().map(|k| format!("{} {:.4} → {:.4}…{:.4} s", k.label, k.planned, k.before, k.after)).collect();
    println!("  inputs as planned → when the drive got them: {}", sent.join(", "));
    println!("  FMU twin (the same inputs at the same times): {}", if twin_passed { "passes" } else { "FAILS" });
    for d in differences {
        println!("  drive − twin {:<20} largest {:>10.4}  rms {:>10.4}", d.signal, d.largest, d.rms);
    }
    for f in files {
        println!("  → {}", f.display());
    }
}
