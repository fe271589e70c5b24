//! The options of `servo bench fmu`, `plant`, `firmware`, `robustness`, `fmi-campaign` and `fault-campaign` (clap); their `run` is in the commands.

use crate::cli::Common;

/// Simulated seconds per wall second, Rust host vs fmpy (default axis, 10 s simulated).
#[derive(clap::Args)]
pub struct FmuBenchArgs {
    /// Simulated time (s)
    #[arg(long, default_value_t = 10.0)]
    pub seconds: f64,
    /// Skip the fmpy half
    #[arg(long)]
    pub no_fmpy: bool,
    /// Fail (exit 1) below this real-time factor through the Rust host recording every output
    /// (the FMI boundary and the recording above 10 % of the bare simulation fail it too)
    #[arg(long, default_value_t = 400.0)]
    pub goal: f64,
    #[command(flatten)]
    pub common: Common,
}

/// Plant integration error: the default sub-step against one ten times finer.
#[derive(clap::Args)]
pub struct PlantBenchArgs {
    #[command(flatten)]
    pub common: Common,
}

/// Random FMI call sequences through fmpy on both archives (FMI 3.0 and 2.0): every
/// function in any state, valid and hostile arguments (unknown value references, NaN,
/// huge values, steps of 0, 1e300 or off the grid, corrupt serialized states). Goals: no
/// crash, no hang, no OK step with a non-finite output.
#[derive(clap::Args)]
pub struct FmiCampaignArgs {
    /// Seconds of calls per archive
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Seed of the call sequences (the same seed gives the same calls)
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub common: Common,
}

/// Faults injected at random times into the simulated axis: a NaN or saturated current
/// sample, an encoder disconnect, bus under- and over-voltage, the power stage's break, a
/// following-error runaway. Prints per fault the worst reaction (ticks from detection to
/// the bridge off; goal ≤ 1), restarts before ClearFaults (goal 0) and recovery after it.
#[derive(clap::Args)]
pub struct FaultCampaignArgs {
    /// Runs per fault kind
    #[arg(long, default_value_t = 100)]
    pub runs: usize,
    /// Seed of the injection times and settings
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    #[command(flatten)]
    pub common: Common,
}

/// Robustness campaigns of the drive link, seeded and time-bounded, run with integer
/// overflow checks on (cargo profile `robustness`, built on first use): `frames` (the
/// frame decoder under byte mutations), `requests` (decode → handle → ticks of the
/// drive), `stream` (the host's parsing of the drive's bytes). Prints inputs tried,
/// crashes, accepted-corrupt frames, overflow panics (goal 0 each) and wall time; exits 1
/// when a goal is missed.
#[derive(clap::Args)]
pub struct RobustnessBenchArgs {
    /// frames, requests, stream or all
    #[arg(long, default_value = "all")]
    pub campaign: String,
    /// Wall time per campaign (s)
    #[arg(long, default_value_t = 20.0)]
    pub seconds: f64,
    /// Seed of the mutations
    #[arg(long, default_value_t = 0x5EED_0018)]
    pub seed: u64,
    #[command(flatten)]
    pub common: Common,
}

/// The firmware's figures: flash and RAM of the drive image; golden vectors
/// replayed bit for bit on a Cortex-M4F in QEMU against the host; instructions per 16 kHz
/// tick on the Cortex-M4 (QEMU -icount: instructions, not cycles), on average over the
/// vectors and with every feature on at once. Builds the firmware first (scripts/fw
/// installs the toolchain and QEMU on first use).
#[derive(clap::Args)]
pub struct FirmwareBenchArgs {
    #[command(flatten)]
    pub common: Common,
}
