//! fmpy, the reference importer: the project's Python, a scenario run through fmpy
//! (tests/python/fmpy_run.py) and the bit-for-bit cross-check against the Rust host's trace.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};

use crate::fmu::trace::{compare_exact, Trace};
use crate::paths::workspace_root;

/// Path of the project's Python (creates the venv on first use).
pub fn python() -> Result<PathBuf> {
    let script = workspace_root().join("scripts/python-env");
    let out = Command::new(&script).output().with_context(|| format!("cannot run {}", script.display()))?;
    if !out.status.success() {
        bail!("{} failed:\n{}", script.display(), String::from_utf8_lossy(&out.stderr));
    }
    Ok(PathBuf::from(String::from_utf8_lossy(&out.stdout).trim()))
}

/// Run a scenario file through fmpy (tests/python/fmpy_run.py); returns the wall time.
pub fn run_fmpy(fmu: &Path, scenario: &Path, csv: &Path) -> Result<f64> {
    let timing = csv.with_extension("timing.json");
    let script = workspace_root().join("tests/python/fmpy_run.py");
    let status = Command::new(python()?)
        .arg(&script)
        .arg(fmu)
        .arg(scenario)
        .arg(csv)
        .arg("--timing")
        .arg(&timing)
        .status()
        .context("cannot start the fmpy runner")?;
    if !status.success() {
        bail!("fmpy run of {} failed ({status})", scenario.display());
    }
    let t: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&timing)?)?;
    t["wall_seconds"].as_f64().context("timing file without wall_seconds")
}

/// What fmpy says about a run: Ok(how much was identical) or Err(the first difference).
pub type FmpyVerdict = std::result::Result<String, String>;

/// Run `scenario_file` through fmpy into `csv` and compare it bit for bit with the Rust host's
/// trace `rust` of the same scenario; returns the verdict and fmpy's trace.
pub fn fmpy_cross_check(fmu: &Path, scenario_file: &Path, rust: &Trace, csv: &Path) -> Result<(FmpyVerdict, Trace)> {
    run_fmpy(fmu, scenario_file, csv)?;
    let fmpy = Trace::read_csv(csv)?;
    let verdict = match compare_exact(rust, &fmpy)? {
        Ok(n) => Ok(format!("identical: {} rows × {n} columns, bit for bit", rust.rows.len())),
        Err(m) => Err(format!(
            "differs: {} at row {} (t = {} s): Rust {:?} vs fmpy {:?}",
            m.column, m.row, rust.rows[m.row][0], m.left, m.right
        )),
    };
    Ok((verdict, fmpy))
}

/// The verdict as the commands' JSON reports it.
pub fn verdict_json(v: &FmpyVerdict) -> serde_json::Value {
    match v {
        Ok(s) => serde_json::json!({"identical": true, "detail": s}),
        Err(s) => serde_json::json!({"identical": false, "detail": s}),
    }
}

/// The verdict as the commands print it.
pub fn print_verdict(what: &str, v: &FmpyVerdict) {
    match v {
        Ok(s) => println!("  [pass] {what}: {s}"),
        Err(s) => println!("  [FAIL] {what}: {s}"),
    }
}
