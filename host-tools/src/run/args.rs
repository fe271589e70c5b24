//! The options of `servo run` and `servo compare` (clap); their `run` is in the commands.

use std::path::PathBuf;

use crate::cli::Common;

/// Run scenario files (TOML: parameters, input events, stop time, checks) on the FMU.
///
/// Writes <name>.csv (all outputs at every communication step), <name>.svg (plot),
/// <name>.json (check results) and index.html. With --fmpy the same scenario also runs
/// through fmpy and the two traces must be identical bit for bit.
/// Without scenario arguments, runs every file in scenarios/.
/// With --device PORT the events go to a drive as set-points at their times (its clock), its
/// telemetry is the trace the checks read, and the FMU runs the events as the drive got them
/// (the twin): the report gives the difference per trace (largest, rms).
#[derive(clap::Args)]
pub struct RunArgs {
    pub scenarios: Vec<PathBuf>,
    /// Also run each scenario through fmpy and demand identical outputs
    #[arg(long)]
    pub fmpy: bool,
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

/// Compare two trace CSVs bit for bit on their common columns.
#[derive(clap::Args)]
pub struct CompareArgs {
    pub a: PathBuf,
    pub b: PathBuf,
}
