//! The options of `servo sequence` and `servo bench sequence` (clap); their `run` is in the commands.

use std::path::PathBuf;

use crate::cli::Common;

/// Stop, zero-servo and fine-adjust sequences (seed 004) on the FMU, from timeline files.
///
/// A file lists key events (run, run_off, stop, release, move, return, gain) at times
/// and expectations ("completion within 200 ms after 0.3 s", "state servo_lock at 0.5 s",
/// "|deviation| <= 2 counts at 1.5 s", "1 refused by 0.4 s", signal bounds); see the doc
/// comment of host-tools/src/sequence/timeline.rs and scenarios/sequences/. Prints a
/// pass/fail table, writes <name>.csv, <name>.svg (speed, position, deviation, state,
/// completion, refusals on one timeline) and <name>.json. With --fmpy the same input
/// table also runs through fmpy and must give identical outputs.
/// Without files, runs every file in scenarios/sequences/.
/// With --device PORT the keys go to a drive at their times (its clock), its telemetry is
/// the trace the expectations are checked on, and the FMU replays the keys as the drive got
/// them (the twin): the report gives the difference per trace (largest, rms).
#[derive(clap::Args)]
pub struct SequenceArgs {
    pub files: Vec<PathBuf>,
    /// Also run through fmpy and demand identical outputs
    #[arg(long)]
    pub fmpy: bool,
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

/// Stop sequence (seed 004): per gain multiplier the stop error, settle time and
/// overshoot (stop at speed and a 1 rad fine adjustment); time from the stop key to
/// acceptance against the zero-speed level.
#[derive(clap::Args)]
pub struct SequenceBenchArgs {
    /// Zero-speed levels to try (rad/s, comma separated)
    #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0], conflicts_with = "random")]
    pub zero_speed: Vec<f64>,
    /// N stops drawn at random instead of the shipped grid, each on its own plant (inertia
    /// ratio log-uniform over 0.2–5, shaft resonance over 50–500 Hz) with a run speed (10–200
    /// rad/s), zero-speed level (0.5–20 rad/s) and completion width (1–100 counts) each
    /// log-uniform and a gain of the table: cases the project does not ship (the seed names
    /// the draw). Prints the grid's figures over them and the stops that miss (exit 1)
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub random: Option<u32>,
    /// Seed of the --random draw
    #[arg(long, default_value_t = 1, requires = "random")]
    pub plant_seed: u64,
    /// Gradient of the drawn stops (rad/s², seq.acceleration; the grid runs the default, 2000).
    /// The swing's bound counts the velocity loop's lag behind the ramp (v·J/k_p), which
    /// steep gradients bring out, and one count of the speed estimate (v·δv/a), which low ones
    /// do; there the swing is the stopping distance itself and its ratio to the bound nears 1
    #[arg(long, default_value_t = crate::sequence::bench::ACCELERATION, requires = "random")]
    pub gradient: f64,
    #[command(flatten)]
    pub common: Common,
}
