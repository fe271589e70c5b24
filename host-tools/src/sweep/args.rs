//! The options of `servo sweep` and `servo bench sweep` (clap); their `run` is in the commands.

use std::path::PathBuf;

use crate::cli::Common;

/// Frequency response with phase-shifted sine repeats (seed 000), beyond the acquisition
/// Nyquist frequency.
///
/// The drive injects a stepped sine (velocity command by default: closed velocity loop;
/// torque: the plant inside the loop; feedback: the open loop, G = −Y/U) and acquires U
/// and Y every --acquisition-divider ticks with the excitation's phase. At and above the
/// threshold (default: the acquisition Nyquist frequency, 2 kHz) each frequency is
/// measured --repeats times with the initial phase shifted by 2π/--shifts; the host
/// computes G from the acquisition stream in equivalent time and reads the drive's
/// on-line correlator results; the two must agree. --oracle also measures the same loop
/// with acquisition at the full velocity-loop rate and ten times longer records and
/// reports the errors against it. Writes sweep.csv (frequency, gain, phase, quality, the
/// standard errors, the on-line values), bode.svg and sweep.json into --out (default
/// out/sweep/).
///
/// "± dB" and "± deg" (gain_se_db, phase_se_deg) are each result's standard error from the
/// stream's samples: the larger of the white/lag-one noise model's and the spread of the
/// result over batches of its samples (which sees colored noise and a transient that drifts
/// within the record); "quality" only tells whether the phases could tell a sine. Results
/// whose error exceeds twice --precision-db (its phase equivalent: 0.03 dB = 0.2 deg; twice
/// the default 0.03 dB with --precision-db 0) are named in a warning.
#[derive(clap::Args)]
pub struct SweepArgs {
    /// Injection point: velocity, torque or feedback
    #[arg(long, default_value = "velocity")]
    pub point: String,
    /// Sine amplitude (rad/s for velocity/feedback, N·m for torque); default 2 rad/s or 0.05 N·m
    #[arg(long)]
    pub amplitude: Option<f64>,
    #[arg(long, default_value_t = 10.0)]
    pub start: f64,
    #[arg(long, default_value_t = 3000.0)]
    pub stop: f64,
    /// Frequencies from start to stop (log spaced unless --linear)
    #[arg(long, default_value_t = 40)]
    pub points: u32,
    #[arg(long)]
    pub linear: bool,
    /// One more frequency (Hz) inserted in order; 0 for none. Default: 2000 Hz (the default
    /// acquisition Nyquist frequency) when it lies between --start and --stop, else none
    #[arg(long)]
    pub extra: Option<f64>,
    /// Settling before each record (cycles; the first record of a frequency then waits until
    /// the response of successive half records agrees: the settling check)
    #[arg(long, default_value_t = 1.0)]
    pub settle_cycles: f64,
    #[arg(long, default_value_t = 2.0)]
    pub measure_cycles: f64,
    /// Shortest settling per record (s)
    #[arg(long, default_value_t = 0.01)]
    pub min_settle: f64,
    /// Shortest measurement per record (s); half of it below half the threshold while the
    /// precision control runs (there the response is usually many encoder counts and the
    /// shorter block halves the settling check's steps; the caps of --max-extensions stay the
    /// same in time; from half the threshold up the full block carries the accuracy)
    #[arg(long, default_value_t = 0.04)]
    pub min_measure: f64,
    /// Phase step 2π/shifts between repeats
    #[arg(long, default_value_t = 3)]
    pub shifts: u16,
    /// Records per frequency at and above the threshold
    #[arg(long, default_value_t = 3)]
    pub repeats: u16,
    /// Phase shifting from this frequency (Hz) up; 0 = the acquisition Nyquist frequency
    #[arg(long, default_value_t = 0.0)]
    pub threshold: f64,
    /// Base ticks (62.5 µs) per acquisition sample
    #[arg(long, default_value_t = 4)]
    pub acquisition_divider: u32,
    /// Lengthen a frequency's records by half blocks so that the standard errors of its
    /// response G = Y/U, gain and phase (the phase's in the same relative size: 0.03 dB =
    /// 0.2 deg), predicted from the residuals of U and Y after the first block (encoder
    /// quantisation, noise) and, below the threshold, checked against the half blocks' own
    /// spread (more half blocks when it reads above 1.25 times this, an early end when six
    /// read half of it or less), are at most this (dB); 0 = fixed records, no settling check.
    /// Low-gain points (an anti-resonance, the top of the sweep) need it; the others keep
    /// their base length
    #[arg(long, default_value_t = 0.03)]
    pub precision_db: f64,
    /// Pseudo-random ±dither on the torque command at and above the threshold, or 2 kHz where
    /// the threshold is higher (N·m; 0 = none): breaks the lock of the encoder's count pattern
    /// to the excitation
    #[arg(long, default_value_t = 0.003)]
    pub dither: f64,
    /// At most so many extra blocks (each one record's base measurement with the full
    /// --min-measure) per record, and twice as many half blocks discarded while settling
    /// (past it only with --time-budget's room)
    #[arg(long, default_value_t = 8)]
    pub max_extensions: u32,
    /// Let a frequency's records go past --max-extensions (up to 64 blocks) while the whole
    /// sweep still ends within this time from its start, every later frequency counted at its
    /// own longest (s; 0 = never): frequencies that finish early leave their time to later ones
    /// that need more, in practice the top, where the response is a few encoder counts; with
    /// room an extended frequency also measures to 1/1.25 of --precision-db. It also bounds the
    /// sweep: where earlier frequencies took long, a frequency is cut short so that the sweep
    /// ends within it (every later one at its shortest). The default: a tenth under the 10 s of
    /// `servo bench sweep`'s goal (a trace sees the end up to a communication step late)
    #[arg(long, default_value_t = 9.9)]
    pub time_budget: f64,
    /// Constant speed the sweep rides on (rad/s; keeps friction on one side)
    #[arg(long, default_value_t = 50.0)]
    pub velocity: f64,
    /// Plant file of the twin's machine (as `servo calibrate` writes it); --set applies over it
    #[arg(long)]
    pub plant: Option<PathBuf>,
    /// FMU parameter NAME=VALUE (repeatable), e.g. plant.current_noise_std=0.05
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Also measure the oracle and report the errors against it
    #[arg(long)]
    pub oracle: bool,
    /// Overlay a reference curve (CSV with frequency, gain_db, phase_deg)
    #[arg(long)]
    pub reference: Option<PathBuf>,
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

/// Frequency response (seed 000): one row per injection point × plant × sensor noise with
/// the worst gain and phase error against the oracle and the measurement time (exit 1
/// when a row misses 0.1 dB, 1 deg or 10 s); phase shifting against a single phase at
/// 2 kHz, PRBS/H1 baseline, on-line vs stream, analytic model at low frequencies.
#[derive(clap::Args)]
pub struct SweepBenchArgs {
    /// Only these plants of the grid (repeatable; 0 = the default axis, 1–4 the corners in
    /// the printed order); the grid alone, without the comparisons (and exit 1 on a miss)
    #[arg(long = "plant")]
    pub plants: Vec<usize>,
    /// Only these injection points (repeatable: velocity, torque, feedback); the grid alone
    #[arg(long = "point")]
    pub points: Vec<String>,
    /// Only this current-sensor noise (A) of the grid (0 or the noisy rows' level)
    #[arg(long)]
    pub noise: Option<f64>,
    /// Run each noisy row with noise seeds 1..=N and print its worst error and longest time
    /// over them (a figure that holds on one noise realisation may not on the next)
    #[arg(long, default_value_t = 1)]
    pub seeds: u32,
    /// Also print every frequency's gain and phase error and the time it took, for each selected row
    #[arg(long)]
    pub detail: bool,
    /// The interior grid instead of the shipped one: inertia ratios 0.2, 0.5, 1, 2, 3, 5 ×
    /// shaft resonances 50, 70, 100, 150, 250, 500 Hz (36 plants, each point and noise level;
    /// about two minutes per noise seed); prints a summary per point and noise level and the
    /// rows that miss a goal (all rows with --detail)
    #[arg(long)]
    pub interior: bool,
    /// N plants drawn at random instead of the shipped grid: inertia ratio and shaft resonance
    /// each log-uniform over 0.2–5 and 50–500 Hz (cases the project does not ship; the seed
    /// names the draw); each point and noise level, summarised as --interior
    #[arg(long, value_name = "N")]
    pub random: Option<u32>,
    /// Seed of the --random draw
    #[arg(long, default_value_t = 1, requires = "random")]
    pub plant_seed: u64,
    #[command(flatten)]
    pub common: Common,
}
