//! `servo bench fmi-campaign`: random FMI call sequences through fmpy on both archives
//! (tests/python/fmi_campaign.py): calls in any order, valid and hostile arguments. Goals:
//! no crash, no hang, no OK step with a non-finite output.

use std::path::Path;
use std::process::Command;

use anyhow::{Context, Result};
use serde::{Deserialize, Serialize};

use crate::fmu::fmpy::python;
use crate::paths::workspace_root;

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct Statuses {
    pub ok: u64,
    pub warning: u64,
    pub error: u64,
    /// fmpy's own argument conversion refused a value before the call.
    pub exception: u64,
}

#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct ArchiveResult {
    #[serde(default)]
    pub archive: String,
    pub fmi_version: String,
    pub sequences: u64,
    pub calls: u64,
    pub statuses: Statuses,
    pub hangs: u64,
    pub ok_with_non_finite_output: u64,
    pub steps_ok: u64,
    pub crashes: u64,
    #[serde(default)]
    pub findings: Vec<String>,
    #[serde(default)]
    pub wall_seconds: f64,
}

/// Run the campaign on one archive for `seconds`; a crash of the campaign process is counted
/// with the tail of its error output as the finding.
pub fn run_archive(fmu: &Path, seconds: f64, seed: u64) -> Result<ArchiveResult> {
    let script = workspace_root().join("tests/python/fmi_campaign.py");
    let start = std::time::Instant::now();
    let out = Command::new(python()?)
        .arg(&script)
        .arg(fmu)
        .args(["--seconds", &seconds.to_string(), "--seed", &seed.to_string()])
        .output()
        .with_context(|| format!("cannot start {}", script.display()))?;
    let wall = start.elapsed().as_secs_f64();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let last = stdout.lines().rev().find(|l| l.starts_with('{'));
    let mut r = match (out.status.success(), last) {
        (true, Some(line)) => serde_json::from_str::<ArchiveResult>(line).context("reading the campaign's summary")?,
        _ => {
            let stderr = String::from_utf8_lossy(&out.stderr);
            let tail: Vec<&str> = stderr.lines().rev().take(12).collect();
            ArchiveResult {
                crashes: 1,
                findings: vec![format!(
                    "the campaign process ended with {} (seed {seed}):\n{}",
                    out.status,
                    tail.into_iter().rev().collect::<Vec<_>>().join("\n")
                )],
                ..Default::default()
            }
        }
    };
    r.archive = fmu.display().to_string();
    r.wall_seconds = wall;
    Ok(r)
}

impl ArchiveResult {
    pub fn passed(&self) -> bool {
        self.crashes == 0 && self.hangs == 0 && self.ok_with_non_finite_output == 0 && self.calls > 0
    }
}
