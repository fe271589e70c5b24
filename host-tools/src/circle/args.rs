//! The options of `servo circle` and `servo bench circle` (clap); their `run` is in the commands.

use std::path::PathBuf;

use crate::cli::Common;

/// Circle tests (seed 002): the two-axis XY circle, or the single-axis pseudo-circle.
///
/// Two axes (default): two FMU instances, each with its own parameters (--x-set, --y-set;
/// --set for both), follow X = R·sin ωt and Y = R − R·cos ωt (feed = R·ω); the plot shows
/// the machine-end (or --measure motor) path about the centre with the radial error
/// magnified, over the commanded circle. Single axis (--single x): one axis follows
/// R·sin ωt and its feedback is drawn against its own copy a quarter period later,
/// (x(t), x(t − T/4)); the same construction on the command is the reference, and the
/// feedback against the shifted command is drawn too. The first --lead-in revolutions
/// settle the start; the last one is measured. --device PORT (with --single) runs the
/// pseudo-circle on a drive, which generates the sine itself (a one-frequency sweep at its
/// position-command injection point), and its FMU twin with the drive's parameters; the
/// report gives the largest and rms difference of the two feedback figures.
///
/// Figures: roundness (max − min radius), mean radius error, quadrant protrusion heights
/// and angles (at the axis reversals 0°, 90°, 180°, 270°). --compare NAME=VALUE[,...]
/// runs a second time with those parameters and overlays both (for example
/// --compare ctrl.friction_comp_amplitude=0.03). Writes circle.svg / pseudo_circle.svg,
/// the points and traces as CSV, and the figures as JSON into --out (default out/circle/).
///
/// Example: servo circle --radius 1 --feed 6.283185307179586 --compare ctrl.friction_comp_amplitude=0.03
#[derive(clap::Args)]
pub struct CircleArgs {
    /// Axes of the XY test (only "x,y")
    #[arg(long, default_value = "x,y")]
    pub axes: String,
    /// Single-axis pseudo-circle on this axis (x or y: whose parameters it takes)
    #[arg(long)]
    pub single: Option<String>,
    /// Radius (rad of axis travel)
    #[arg(long, default_value_t = 1.0)]
    pub radius: f64,
    /// Feed: tangential speed (rad/s); the revolution must be a whole number of 250 µs samples
    #[arg(long, default_value_t = std::f64::consts::TAU)]
    pub feed: f64,
    /// Clockwise (two-axis test)
    #[arg(long)]
    pub cw: bool,
    /// Revolutions before the measured one
    #[arg(long, default_value_t = 1)]
    pub lead_in: u32,
    /// Position measured: load (machine end; the default on the FMU) or motor (the only one
    /// a drive has, and the default with --device)
    #[arg(long)]
    pub measure: Option<String>,
    /// FMU parameter for both axes, NAME=VALUE (repeatable)
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// FMU parameter for the X axis only
    #[arg(long = "x-set")]
    pub x_set: Vec<String>,
    /// FMU parameter for the Y axis only
    #[arg(long = "y-set")]
    pub y_set: Vec<String>,
    /// Second run with these parameter overrides, overlaid (NAME=VALUE, comma separated)
    #[arg(long, value_delimiter = ',')]
    pub compare: Vec<String>,
    /// A `servo tune` output directory: run its x and y axes without and then with their
    /// response corrections (seed 001), overlaid, and print the roundness ratio
    #[arg(long)]
    pub tuned: Option<PathBuf>,
    /// Single axis: also run through fmpy and demand the same feedback trace
    #[arg(long)]
    pub fmpy: bool,
    /// --single only: the drive generates the sine (its sweep at the position-command point)
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

/// Circle tests (seed 002): quadrant protrusion with friction compensation off and on;
/// pseudo-circle of one friction-free axis against the two-axis circle.
#[derive(clap::Args)]
pub struct CircleBenchArgs {
    #[command(flatten)]
    pub common: Common,
}
