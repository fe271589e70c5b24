//! The options of `servo ident`, `servo tune` and `servo bench ident` (clap); their `run` is in the commands.

use std::path::PathBuf;

use crate::cli::Common;

/// Identify each axis's anti-resonance (seed 001) on the FMU: an M-sequence on the torque
/// command, the machine-end acceleration recorded, the response (measured over 5–500 Hz)
/// searched for an anti-resonance (moving-average-smoothed minimum, searched over 6.2–435 Hz;
/// none means N = 1) and a rational model fitted around it. Anti-resonances from 10 to 450 Hz
/// are identified; one outside that range is not seen.
///
/// Axes are named by --axes (default x,y); each gets its own FMU parameters with
/// --set AXIS:NAME=VALUE (for example y:plant.absorber_stiffness=19.34), or an absorber
/// (second mode) at a given anti-resonance with --anti-resonance AXIS=HZ. Writes
/// <axis>.model.json (editable), <axis>.measured.csv and ident.svg (measured response and
/// model) into --out (default out/ident/). With --model FILE... it only re-plots edited
/// models against the measurements saved next to them.
///
/// --device PORT: identify one axis (--axis, default the first of --axes) on a drive over its
/// link instead. The drive needs the removable machine-end accelerometer on its accelerometer
/// input (the G474 board: PC3, morpho CN7 pin 37; its sensitivity in V per rad/s² is the
/// parameter accelerometer.sensitivity, --set AXIS:accelerometer.sensitivity=...). The drive
/// runs the same M-sequence with U = kt·iq from its measured currents and Y = the
/// accelerometer, streams the samples, and the host identifies them exactly as on the FMU
/// (same files); the FMU runs the same sweep with the drive's parameters as its twin, and the
/// report gives their difference per frequency point and in the identified anti-resonance
/// (also in ident.json). Give the twin the plant the drive drives (--anti-resonance, --set).
///
/// Example: servo virtual-drive --speed max --set plant.absorber_inertia=1e-4 ... &
///          servo ident --device /tmp/servo-drive --anti-resonance x=40
#[derive(clap::Args)]
pub struct IdentArgs {
    #[arg(long, value_delimiter = ',', default_value = "x,y")]
    pub axes: Vec<String>,
    /// AXIS:NAME=VALUE FMU parameter of one axis (repeatable)
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// AXIS=HZ: an absorber on that axis's load with this anti-resonance (5 % damping,
    /// absorber inertia equal to the load's), 10–450 Hz (what the identification finds)
    #[arg(long = "anti-resonance", value_delimiter = ',')]
    pub anti_resonance: Vec<String>,
    /// M-sequence amplitude on the torque command (N·m)
    #[arg(long, default_value_t = 0.05)]
    pub amplitude: f64,
    /// Accelerometer noise for this signal-to-noise ratio (dB); default: the FMU's setting
    #[arg(long)]
    pub snr_db: Option<f64>,
    /// Re-plot these (edited) model files instead of identifying
    #[arg(long, num_args = 1..)]
    pub model: Vec<PathBuf>,
    /// With --device: the axis identified on the drive (default: the first of --axes)
    #[arg(long)]
    pub axis: Option<String>,
    /// Identify on this drive (its accelerometer input) instead of the FMU
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

/// Identification and correction (seed 001): anti-resonance frequency and damping errors
/// against the plant's truth at 20 dB SNR with 2 s of excitation (two and three axes, a
/// rigid axis); the axes' largest response difference before and after `servo tune`
/// (measured models, and the seed's zeros-only form); the XY circle's roundness without
/// and with the correction.
#[derive(clap::Args)]
pub struct IdentBenchArgs {
    /// Only these anti-resonances (Hz, repeatable) instead of the shipped grid of 15–300 Hz:
    /// the grid alone, without the demo axes and the correction (exit 1 on a miss). The
    /// bench's axis carries an absorber of the load's inertia and damping 0.05 (--damping)
    /// tuned to it.
    #[arg(long = "absorber", value_name = "HZ")]
    pub absorbers: Vec<f64>,
    /// N anti-resonances drawn at random instead of the shipped grid, log-uniform over
    /// 15–300 Hz (cases the project does not ship; the seed names the draw); the grid alone,
    /// as --absorber
    #[arg(long, value_name = "N", conflicts_with = "absorbers", value_parser = clap::value_parser!(u32).range(1..))]
    pub random: Option<u32>,
    /// Seed of the --random draw
    #[arg(long, default_value_t = 1, requires = "random")]
    pub plant_seed: u64,
    /// Damping ratio of the grid's absorbers (the demo axes keep 0.05). A more damped
    /// absorber shows a shallower notch: at 0.15 the plant's own is under 4 dB everywhere, and
    /// a case reported without an anti-resonance then counts as right
    #[arg(long, default_value_t = crate::ident::bench::DAMPING)]
    pub damping: f64,
    /// Noise seeds 1..=N per anti-resonance (a figure that holds on one noise realisation may
    /// not on the next)
    #[arg(long, default_value_t = crate::ident::bench::SEEDS, value_parser = clap::value_parser!(u32).range(1..))]
    pub seeds: u32,
    #[command(flatten)]
    pub common: Common,
}

/// Response-correction filters that make every axis's command → machine-end response
/// the same (seed 001).
///
/// Reads the model files `servo ident` wrote (edited or not) and runs each axis on the
/// FMU with the parameters it was identified with (friction off).
///
/// --method response (default): measures each axis's command → machine-end response
/// (a periodic multisine on the position command, 1 Hz to twice the position-loop
/// bandwidth), fits a model of second-order factors to it, and gives every axis the
/// OTHER axes' models: all axes then answer the product of all models, alike whatever
/// their closed-loop denominators. --method zeros: the seed as written, F·Π N_other from
/// the identified anti-resonances over a critically damped F; it equalises only when all
/// axes have the same closed-loop denominator, which a loop closed on the motor encoder
/// does not give (`servo bench ident` shows both).
///
/// Writes <axis>.corr.toml (the FMU's corr.* parameters, ready for a scenario's
/// [parameters] or --set), <axis>.corr.frame (the drive's LoadCorrection request, framed
/// for the link), tune.json (read by `servo circle --tuned DIR`) and tune.svg
/// (every axis before and after), and prints the largest difference between axes up to
/// the position-loop bandwidth before and after. The exit status is non-zero when the
/// correction does not bring the axes closer.
///
/// --device PORT: then loads one axis's correction (--axis, default the first model's) into
/// the drive over its link (LoadCorrection, the <axis>.corr.frame) and checks it there: the
/// single-axis pseudo-circle of the motor position (as `servo circle --single x --device`)
/// without and with the correction, each beside its FMU twin (the drive's parameters, and the
/// same corr.* parameters), and, over the drive's machine-end accelerometer, the axis's
/// position command → machine-end response at 5–40 Hz without and with the correction, beside
/// its twin (the tuned axis's plant) and against the other axes as the FMU measures them: in
/// the table and in tune.json's "device" section. Start a virtual drive with the tuned axis's
/// plant (--set plant.*), or the twin differs from it by its plant.
///
/// Example: servo ident --anti-resonance x=40,y=70 && servo tune --model out/ident/x.model.json out/ident/y.model.json
#[derive(clap::Args)]
pub struct TuneArgs {
    /// Model files from `servo ident`
    #[arg(long = "model", num_args = 1.., required = true)]
    pub models: Vec<PathBuf>,
    /// response (measured closed-loop models) or zeros (the seed's F·Π N_other)
    #[arg(long, default_value = "response")]
    pub method: String,
    /// Skip the check runs on the FMU (the response method still measures once)
    #[arg(long)]
    pub no_check: bool,
    /// With --device: the axis whose correction the drive gets (default: the first model's)
    #[arg(long)]
    pub axis: Option<String>,
    /// Load the correction into this drive and check it there
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}
