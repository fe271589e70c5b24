//! The options of `servo accdec` and `servo bench accdec` (clap); their `run` is in the commands.

use crate::cli::Common;

/// Acc/dec after interpolation (seed 003): a pole-zero-matched Butterworth against
/// cascaded moving averages.
///
/// Prints the Butterworth's coefficients (direct form and the sections the drive runs),
/// runs the same move (--distance at --speed, in the drive's whole pulses) through both
/// filters and reports their delay (velocity-step response: time to 50 % and until it
/// stays within 1 %), peak acceleration and jerk; runs the move on the FMU's two-inertia
/// load for each --resonance and reports the load's residual vibration after the command
/// arrives; sweeps the cut-off to show the delay / jerk / vibration trade-off. Unless
/// --ma-lengths is given, the moving averages are three stages matched to the
/// Butterworth's 99 % delay (to one tick), so the comparison is at equal delay; where no
/// cascade within the drive's limit (512 ticks a stage) reaches that delay, the closest is
/// compared and the report says the comparison is NOT at equal delay, and why (as it does for
/// --ma-lengths of another delay).
///
/// Writes profiles.svg, profile_*.csv, vibration_<Hz>hz.svg/.csv, sweep.csv/.svg and
/// accdec.json into --out (default out/accdec/).
///
/// Example (the seed's worked example): servo accdec --cutoff 1000 --order 3 --sample-period 0.0005
#[derive(clap::Args)]
pub struct AccdecArgs {
    /// Butterworth order (1 to 6)
    #[arg(long, default_value_t = 3)]
    pub order: u32,
    /// Butterworth cut-off (Hz); default: twice the position loop's bandwidth kp/2π. From
    /// 0.5 Hz (and 6e-5/T) up to the Nyquist frequency 1/(2T) inclusive, as the drive's
    /// design accepts (the seed's worked example, 1 kHz at 0.5 ms, sits at Nyquist)
    #[arg(long)]
    pub cutoff: Option<f32>,
    /// Sample period of the filter = the position-loop period (s); with FMU runs a whole
    /// multiple of the FMU's velocity-loop period (125 µs) up to 62.5 ms
    #[arg(long, default_value_t = 0.00025)]
    pub sample_period: f32,
    /// Keep every zero at infinity as a delay (python-control's `matched`) instead of the
    /// seed's N-1 zeros at z = -1 plus one delay (host only; the FMU runs the seed's form)
    #[arg(long)]
    pub zeros_as_delays: bool,
    /// Moving-average lengths in ticks, comma separated (1 to 3 stages); default: three
    /// stages matched to the Butterworth's 99 % delay
    #[arg(long, value_delimiter = ',')]
    pub ma_lengths: Option<Vec<u32>>,
    /// Move distance (rad, motor side)
    #[arg(long, default_value_t = 2.0)]
    pub distance: f64,
    /// Move speed (rad/s)
    #[arg(long, default_value_t = 50.0)]
    pub speed: f64,
    /// Encoder counts per revolution (the FMU's default)
    #[arg(long, default_value_t = 1 << 20)]
    pub counts_per_rev: u32,
    /// Load resonances to test on the FMU (Hz, comma separated): the load's natural
    /// frequency against a locked motor
    #[arg(long, value_delimiter = ',', default_values_t = [20.0, 60.0])]
    pub resonance: Vec<f64>,
    /// Damping ratio of those resonances
    #[arg(long, default_value_t = 0.02)]
    pub damping_ratio: f64,
    /// Cut-offs to sweep (Hz, comma separated); default: 1/4, 1/2, 1, 2 and 4 times the
    /// cut-off, those the design accepts (see --cutoff) and where three moving averages within
    /// the drive's limit have the Butterworth's delay (the others are named as left out)
    #[arg(long, value_delimiter = ',')]
    pub sweep: Option<Vec<f32>>,
    /// No cut-off sweep
    #[arg(long)]
    pub no_sweep: bool,
    /// Filters only: no FMU runs
    #[arg(long)]
    pub no_fmu: bool,
    #[command(flatten)]
    pub common: Common,
}

/// Acc/dec filters (seed 003): seed digits, python-control `matched` poles (both zero
/// conventions), pulse conservation, residual vibration at equal delay, cost per tick.
#[derive(clap::Args)]
pub struct AccdecBenchArgs {
    /// Random pulse sequences for the conservation property
    #[arg(long, default_value_t = 10_000, conflicts_with = "random")]
    pub sequences: usize,
    /// Load resonances for the equal-delay vibration comparison (Hz)
    #[arg(long, value_delimiter = ',', default_values_t = [20.0, 60.0], conflicts_with = "random")]
    pub resonance: Vec<f64>,
    /// Skip the instruction count (needs valgrind)
    #[arg(long, conflicts_with = "random")]
    pub no_cost: bool,
    /// N moves drawn at random instead of the checks above, each through the drive's filter
    /// against the same filter in f64. Two in three: order 1–6, either sign and a step,
    /// rectangle or trapezoid, each uniform; period 0.125–2 ms, cut-off 0.5 Hz to a quarter of
    /// the rate, 1–10⁹ counts and a duration of 1 ms–2 s, each log-uniform. One in three large
    /// and fast at a low cut-off × period: order 4–6, sign and shape uniform; period 5 µs–0.25
    /// ms, cut-off from the design's minimum (0.5 Hz and 6e-5 / period) to 4 times it,
    /// 10⁶–2·10⁹ counts and a duration of 0.1 ms–0.2 s, each log-uniform. Cases the project
    /// does not ship (the seed names the draw). Prints the worst deviation (and that of the
    /// large, fast moves) and exits 1 above one count or on a lost pulse
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u32).range(1..))]
    pub random: Option<u32>,
    /// Seed of the --random draw
    #[arg(long, default_value_t = 1, requires = "random")]
    pub plant_seed: u64,
    #[command(flatten)]
    pub common: Common,
}

/// Run a filter for the instruction count of `servo bench accdec` (valgrind runs this).
#[derive(clap::Args)]
pub struct AccdecProbeArgs {
    #[arg(long)]
    pub filter: String,
    #[arg(long)]
    pub ticks: usize,
}
