//! Default locations: the FMU the project builds and the output folder.

use std::path::PathBuf;

/// Workspace root (where `Cargo.toml` of the host workspace is).
pub fn workspace_root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).parent().map(PathBuf::from).unwrap_or_default()
}

/// `target/fmu/servo_axis.fmu`, built by `cargo run -p xtask -- bundle`.
pub fn default_fmu() -> PathBuf {
    workspace_root().join("target/fmu/servo_axis.fmu")
}

/// `out/<command>/` under the current directory.
pub fn default_out(command: &str) -> PathBuf {
    PathBuf::from("out").join(command)
}
