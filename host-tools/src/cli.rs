//! What every command takes (`--fmu`, `--out`, `--json`) and its progress bar.

use std::path::PathBuf;

use indicatif::{ProgressBar, ProgressStyle};

#[derive(clap::Args, Clone)]
pub struct Common {
    /// FMU to run (default: the one the project builds)
    #[arg(long, global = true)]
    pub fmu: Option<PathBuf>,
    /// Output folder (default: out/<command>/)
    #[arg(long, global = true)]
    pub out: Option<PathBuf>,
    /// Print machine-readable figures (JSON) on stdout instead of tables
    #[arg(long, global = true)]
    pub json: bool,
}

pub fn progress_bar(label: &str, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let pb = ProgressBar::new(1000);
    pb.set_style(
        ProgressStyle::with_template("{prefix:>22} [{bar:40}] {percent:>3}% {elapsed_precise}")
            .unwrap()
            .progress_chars("=> "),
    );
    pb.set_prefix(label.to_string());
    pb
}
