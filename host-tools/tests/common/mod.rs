//! What the `servo` binary's tests share: the binary as a user runs it, on the FMU the project
//! builds, writing into a folder of the test's own.

use std::ffi::OsStr;
use std::path::PathBuf;
use std::process::Command;

/// The `servo` binary, run from the temporary folder (relative outputs land there, not in
/// the repository).
pub fn servo() -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_servo"));
    c.current_dir(std::env::temp_dir());
    c
}

/// A folder `servo-test-<process>-<name>` under the temporary folder (each test binary is
/// its own process).
pub fn tmp(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("servo-test-{}-{name}", std::process::id()));
    // Process ids come round again: a folder of an earlier run with this one's id is not
    // this run's (a stale output in it would pass for this run's).
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// `--fmu <the project's FMU> --out <out>`, the two options nearly every command takes.
pub trait OnTheFmu {
    fn on_fmu(&mut self, out: impl AsRef<OsStr>) -> &mut Self;
}

impl OnTheFmu for Command {
    fn on_fmu(&mut self, out: impl AsRef<OsStr>) -> &mut Self {
        self.arg("--fmu").arg(host_tools::paths::default_fmu()).arg("--out").arg(out)
    }
}
