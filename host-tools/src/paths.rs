//! Default locations: the FMU the project builds, the output folder, the files of a folder.

use std::path::PathBuf;

use anyhow::{Context, Result};

/// Workspace root (where `Cargo.toml` of the host workspace is).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().map(PathBuf::from).unwrap_or_default()
}

/// `target/fmu/servo_axis.fmu`, built by `cargo run -p xtask -- bundle`.
pub fn default_fmu() -> PathBuf {
    workspace_root().join("target/fmu/servo_axis.fmu")
}

/// The x86_64 Linux FMU library the archives carry (glibc 2.17 build by `scripts/platforms`,
/// `cargo zigbuild -p servo-fmu-library --profile fmu-library --target
/// x86_64-unknown-linux-gnu.2.17`). Tests that call the C API load this one: a plain `cargo
/// test` does not build the shipped library (glibc 2.17, the `fmu-library` profile).
pub fn shipped_linux_fmu_library() -> PathBuf {
    workspace_root().join("target/x86_64-unknown-linux-gnu/fmu-library/libservo_axis_fmu.so")
}

/// `out/<command>/` under the current directory.
pub fn default_out(command: &str) -> PathBuf {
    PathBuf::from("out").join(command)
}

/// Create an experiment's output folder (and its parents); the error names the folder, for
/// example when --out names a file.
pub fn create_out_dir(out: &std::path::Path) -> Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create the output folder {}", out.display()))
}

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
