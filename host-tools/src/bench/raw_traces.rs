//! The benches' raw per-sample traces: each device case writes the drive's streamed samples and
//! the twin's (tens of megabytes per case, hundreds over a bench) beside the figures, tables and
//! plots it derives from them. A bench removes them once its figures are written, unless asked
//! to keep them (`--keep-raw`), so that `out/` stays small by default.

use std::path::Path;

use anyhow::{Context, Result};

/// Whether a file is a raw per-sample trace (by the names the device runs give them).
fn is_raw_trace(name: &str) -> bool {
    name == "machine_end_samples.csv"
        || name.ends_with("_samples.csv") && name.starts_with("pseudo_circle")
        || name.ends_with("device_stream.csv")
}

/// Remove every raw trace under `dir`: how many files and bytes went.
pub fn remove(dir: &Path) -> Result<(usize, u64)> {
    let (mut files, mut bytes) = (0, 0);
    if !dir.is_dir() {
        return Ok((0, 0));
    }
    for entry in std::fs::read_dir(dir).with_context(|| format!("reading {}", dir.display()))? {
        let entry = entry?;
        let path = entry.path();
        let kind = entry.file_type()?;
        if kind.is_dir() {
            let (f, b) = remove(&path)?;
            files += f;
            bytes += b;
        } else if kind.is_file() && is_raw_trace(&entry.file_name().to_string_lossy()) {
            bytes += entry.metadata()?.len();
            std::fs::remove_file(&path).with_context(|| format!("removing {}", path.display()))?;
            files += 1;
        }
    }
    Ok((files, bytes))
}

/// After a bench: remove its raw traces unless `keep`, and say so (on stderr: stdout may be
/// JSON).
pub fn tidy(dir: &Path, keep: bool) -> Result<()> {
    if keep {
        return Ok(());
    }
    let (files, bytes) = remove(dir)?;
    if files > 0 {
        eprintln!(
            "  raw per-sample traces removed: {files} files, {:.0} MB (--keep-raw keeps them)",
            bytes as f64 / 1e6
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn only_the_raw_traces_go() {
        let dir = std::env::temp_dir().join(format!("raw-traces-{}", std::process::id()));
        let case = dir.join("40_70/device_x_clean/machine_end_with");
        std::fs::create_dir_all(&case).unwrap();
        for name in
            ["machine_end_samples.csv", "x.device_stream.csv", "pseudo_circle_twin_samples.csv", "device_stream.csv"]
        {
            std::fs::write(case.join(name), "t,x\n0,1\n").unwrap();
        }
        for name in ["tune.json", "tune.svg", "sweep.csv", "machine_end.csv"] {
            std::fs::write(case.join(name), "kept").unwrap();
        }
        assert_eq!(remove(&dir).unwrap().0, 4);
        let mut left: Vec<String> =
            std::fs::read_dir(&case).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
        left.sort();
        assert_eq!(left, ["machine_end.csv", "sweep.csv", "tune.json", "tune.svg"]);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
