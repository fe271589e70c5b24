//! `servo`: experiments on the servo FMU (default) and, later, on a real drive.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};

use host_tools::cli::{progress_bar, Common};
use host_tools::fmu::runner::Fmu;
use host_tools::fmu::trace::{compare_exact, Trace};
use host_tools::paths::{default_fmu, default_out, workspace_root};
use host_tools::{accdec, bench, circle, device, ident, run, sequence, sweep};

#[derive(Parser)]
#[command(
    name = "servo",
    version,
    about = "Servo-drive toolkit: run experiments on the servo FMU, compare with fmpy, benchmark",
    long_about = "Servo-drive toolkit.\n\nEvery command runs against the FMU the project builds \
    (target/fmu/servo_axis.fmu, made by `cargo run -p xtask -- bundle`) unless --fmu says otherwise, \
    writes its files into out/<command>/ unless --out says otherwise, prints figures as JSON with --json, \
    and exits with status 1 when a check inside it fails."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run scenario files (TOML: parameters, input events, stop time, checks) on the FMU.
    ///
    /// Writes <name>.csv (all outputs at every communication step), <name>.svg (plot),
    /// <name>.json (check results) and index.html. With --fmpy the same scenario also runs
    /// through fmpy and the two traces must be identical bit for bit.
    /// Without scenario arguments, runs every file in scenarios/.
    Run {
        scenarios: Vec<PathBuf>,
        /// Also run each scenario through fmpy and demand identical outputs
        #[arg(long)]
        fmpy: bool,
        #[command(flatten)]
        common: Common,
    },
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
    /// Butterworth's 99 % delay, so the comparison is at equal delay.
    ///
    /// Writes profiles.svg, profile_*.csv, vibration_<Hz>hz.svg/.csv, sweep.csv/.svg and
    /// accdec.json into --out (default out/accdec/).
    ///
    /// Example (the seed's worked example): servo accdec --cutoff 1000 --order 3 --sample-period 0.0005
    Accdec {
        /// Butterworth order (1 to 6)
        #[arg(long, default_value_t = 3)]
        order: u32,
        /// Butterworth cut-off (Hz); default: twice the position loop's bandwidth kp/2π
        #[arg(long)]
        cutoff: Option<f32>,
        /// Sample period of the filter = the position-loop period (s)
        #[arg(long, default_value_t = 0.00025)]
        sample_period: f32,
        /// Keep every zero at infinity as a delay (python-control's `matched`) instead of the
        /// seed's N-1 zeros at z = -1 plus one delay (host only; the FMU runs the seed's form)
        #[arg(long)]
        zeros_as_delays: bool,
        /// Moving-average lengths in ticks, comma separated (1 to 3 stages); default: three
        /// stages matched to the Butterworth's 99 % delay
        #[arg(long, value_delimiter = ',')]
        ma_lengths: Option<Vec<u32>>,
        /// Move distance (rad, motor side)
        #[arg(long, default_value_t = 2.0)]
        distance: f64,
        /// Move speed (rad/s)
        #[arg(long, default_value_t = 50.0)]
        speed: f64,
        /// Encoder counts per revolution (the FMU's default)
        #[arg(long, default_value_t = 1 << 20)]
        counts_per_rev: u32,
        /// Load resonances to test on the FMU (Hz, comma separated): the load's natural
        /// frequency against a locked motor
        #[arg(long, value_delimiter = ',', default_values_t = [20.0, 60.0])]
        resonance: Vec<f64>,
        /// Damping ratio of those resonances
        #[arg(long, default_value_t = 0.02)]
        damping_ratio: f64,
        /// Cut-offs to sweep (Hz, comma separated); default: 1/4, 1/2, 1, 2 and 4 times the
        /// cut-off (up to the Nyquist frequency)
        #[arg(long, value_delimiter = ',')]
        sweep: Option<Vec<f32>>,
        /// No cut-off sweep
        #[arg(long)]
        no_sweep: bool,
        /// Filters only: no FMU runs
        #[arg(long)]
        no_fmu: bool,
        #[command(flatten)]
        common: Common,
    },
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
    Sequence {
        files: Vec<PathBuf>,
        /// Also run through fmpy and demand identical outputs
        #[arg(long)]
        fmpy: bool,
        #[command(flatten)]
        common: Common,
    },
    /// Circle tests (seed 002): the two-axis XY circle, or the single-axis pseudo-circle.
    ///
    /// Two axes (default): two FMU instances, each with its own parameters (--x-set, --y-set;
    /// --set for both), follow X = R·sin ωt and Y = R − R·cos ωt (feed = R·ω); the plot shows
    /// the machine-end (or --measure motor) path about the centre with the radial error
    /// magnified, over the commanded circle. Single axis (--single x): one axis follows
    /// R·sin ωt and its feedback is drawn against its own copy a quarter period later,
    /// (x(t), x(t − T/4)); the same construction on the command is the reference, and the
    /// feedback against the shifted command is drawn too. The first --lead-in revolutions
    /// settle the start; the last one is measured.
    ///
    /// Figures: roundness (max − min radius), mean radius error, quadrant protrusion heights
    /// and angles (at the axis reversals 0°, 90°, 180°, 270°). --compare NAME=VALUE[,...]
    /// runs a second time with those parameters and overlays both (for example
    /// --compare ctrl.friction_comp_amplitude=0.03). Writes circle.svg / pseudo_circle.svg,
    /// the points and traces as CSV, and the figures as JSON into --out (default out/circle/).
    ///
    /// Example: servo circle --radius 1 --feed 6.283185307179586 --compare ctrl.friction_comp_amplitude=0.03
    Circle {
        /// Axes of the XY test (only "x,y")
        #[arg(long, default_value = "x,y")]
        axes: String,
        /// Single-axis pseudo-circle on this axis (x or y: whose parameters it takes)
        #[arg(long)]
        single: Option<String>,
        /// Radius (rad of axis travel)
        #[arg(long, default_value_t = 1.0)]
        radius: f64,
        /// Feed: tangential speed (rad/s); the revolution must be a whole number of 250 µs samples
        #[arg(long, default_value_t = std::f64::consts::TAU)]
        feed: f64,
        /// Clockwise (two-axis test)
        #[arg(long)]
        cw: bool,
        /// Revolutions before the measured one
        #[arg(long, default_value_t = 1)]
        lead_in: u32,
        /// Position measured: load (machine end) or motor
        #[arg(long, default_value = "load")]
        measure: String,
        /// FMU parameter for both axes, NAME=VALUE (repeatable)
        #[arg(long = "set")]
        set: Vec<String>,
        /// FMU parameter for the X axis only
        #[arg(long = "x-set")]
        x_set: Vec<String>,
        /// FMU parameter for the Y axis only
        #[arg(long = "y-set")]
        y_set: Vec<String>,
        /// Second run with these parameter overrides, overlaid (NAME=VALUE, comma separated)
        #[arg(long, value_delimiter = ',')]
        compare: Vec<String>,
        /// A `servo tune` output directory: run its x and y axes without and then with their
        /// response corrections (seed 001), overlaid, and print the roundness ratio
        #[arg(long)]
        tuned: Option<PathBuf>,
        /// Single axis: also run through fmpy and demand the same feedback trace
        #[arg(long)]
        fmpy: bool,
        #[command(flatten)]
        common: Common,
    },
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
    /// on-line values), bode.svg and sweep.json into --out (default out/sweep/).
    Sweep {
        /// Injection point: velocity, torque or feedback
        #[arg(long, default_value = "velocity")]
        point: String,
        /// Sine amplitude (rad/s for velocity/feedback, N·m for torque); default 2 rad/s or 0.05 N·m
        #[arg(long)]
        amplitude: Option<f64>,
        #[arg(long, default_value_t = 10.0)]
        start: f64,
        #[arg(long, default_value_t = 3000.0)]
        stop: f64,
        /// Frequencies from start to stop (log spaced unless --linear)
        #[arg(long, default_value_t = 40)]
        points: u32,
        #[arg(long)]
        linear: bool,
        /// One more frequency (Hz) inserted in order; 0 for none
        #[arg(long, default_value_t = 2000.0)]
        extra: f64,
        #[arg(long, default_value_t = 2.0)]
        settle_cycles: f64,
        #[arg(long, default_value_t = 4.0)]
        measure_cycles: f64,
        /// Shortest settling and measurement per record (s)
        #[arg(long, default_value_t = 0.02)]
        min_settle: f64,
        #[arg(long, default_value_t = 0.08)]
        min_measure: f64,
        /// Phase step 2π/shifts between repeats
        #[arg(long, default_value_t = 3)]
        shifts: u32,
        /// Records per frequency at and above the threshold
        #[arg(long, default_value_t = 3)]
        repeats: u32,
        /// Phase shifting from this frequency (Hz) up; 0 = the acquisition Nyquist frequency
        #[arg(long, default_value_t = 0.0)]
        threshold: f64,
        /// Base ticks (62.5 µs) per acquisition sample
        #[arg(long, default_value_t = 4)]
        acquisition_divider: u32,
        /// Lengthen a frequency's records by whole blocks so that the standard error of its
        /// gain, predicted from the fit's residual after the first block (encoder
        /// quantisation, noise), is at most this (dB); 0 = fixed records. Low-gain points (an
        /// anti-resonance, the top of the sweep) need it; the others keep their base length
        #[arg(long, default_value_t = 0.03)]
        precision_db: f64,
        /// At most so many extra blocks (each one record's base measurement) per record
        #[arg(long, default_value_t = 8)]
        max_extensions: u32,
        /// Constant speed the sweep rides on (rad/s; keeps friction on one side)
        #[arg(long, default_value_t = 50.0)]
        velocity: f64,
        /// FMU parameter NAME=VALUE (repeatable), e.g. plant.current_noise_std=0.05
        #[arg(long = "set")]
        set: Vec<String>,
        /// Also measure the oracle and report the errors against it
        #[arg(long)]
        oracle: bool,
        /// Overlay a reference curve (CSV with frequency, gain_db, phase_deg)
        #[arg(long)]
        reference: Option<PathBuf>,
        #[command(flatten)]
        common: Common,
    },
    /// Identify each axis's anti-resonance (seed 001) on the FMU: an M-sequence on the torque
    /// command, the machine-end acceleration recorded, the response searched for an
    /// anti-resonance (moving-average-smoothed minimum; none means N = 1) and a rational
    /// model fitted around it.
    ///
    /// Axes are named by --axes (default x,y); each gets its own FMU parameters with
    /// --set AXIS:NAME=VALUE (for example y:plant.absorber_stiffness=19.34), or an absorber
    /// (second mode) at a given anti-resonance with --anti-resonance AXIS=HZ. Writes
    /// <axis>.model.json (editable), <axis>.measured.csv and ident.svg (measured response and
    /// model) into --out (default out/ident/). With --model FILE... it only re-plots edited
    /// models against the measurements saved next to them.
    Ident {
        #[arg(long, value_delimiter = ',', default_value = "x,y")]
        axes: Vec<String>,
        /// AXIS:NAME=VALUE FMU parameter of one axis (repeatable)
        #[arg(long = "set")]
        set: Vec<String>,
        /// AXIS=HZ: an absorber on that axis's load with this anti-resonance (5 % damping,
        /// absorber inertia equal to the load's)
        #[arg(long = "anti-resonance", value_delimiter = ',')]
        anti_resonance: Vec<String>,
        /// M-sequence amplitude on the torque command (N·m)
        #[arg(long, default_value_t = 0.05)]
        amplitude: f64,
        /// Accelerometer noise for this signal-to-noise ratio (dB); default: the FMU's setting
        #[arg(long)]
        snr_db: Option<f64>,
        /// Re-plot these (edited) model files instead of identifying
        #[arg(long, num_args = 1..)]
        model: Vec<PathBuf>,
        #[command(flatten)]
        common: Common,
    },
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
    /// Example: servo ident --anti-resonance x=40,y=70 && servo tune --model out/ident/x.model.json out/ident/y.model.json
    Tune {
        /// Model files from `servo ident`
        #[arg(long = "model", num_args = 1.., required = true)]
        models: Vec<PathBuf>,
        /// response (measured closed-loop models) or zeros (the seed's F·Π N_other)
        #[arg(long, default_value = "response")]
        method: String,
        /// Skip the check runs on the FMU (the response method still measures once)
        #[arg(long)]
        no_check: bool,
        #[command(flatten)]
        common: Common,
    },
    /// Compare two trace CSVs bit for bit on their common columns.
    Compare { a: PathBuf, b: PathBuf },
    /// Talk to a real drive (drive-g474) over its serial link: the core's protocol, version
    /// checked first. The NUCLEO's ST-LINK virtual COM port is usually /dev/ttyACM0.
    ///
    /// Actions: hello (version handshake), telemetry (one record, printed as JSON),
    /// clear-faults, start-sweep, load-correction FILE (an <axis>.corr.frame from
    /// `servo tune`, checked to be a correction request before it is sent), stream (turn
    /// acquisition streaming on for --seconds, write the samples to <out>/stream.csv, report
    /// how many arrived and how many the drive had to drop).
    ///
    /// Example: servo device --port /dev/ttyACM0 load-correction out/tune/x.corr.frame
    Device {
        /// Serial port of the drive
        #[arg(long)]
        port: String,
        /// Baud rate (the firmware's USART2 runs at 921600)
        #[arg(long, default_value_t = 921_600)]
        baud: u32,
        /// How long to wait for each answer (ms)
        #[arg(long, default_value_t = 500)]
        timeout_ms: u64,
        /// Streaming time (s), for `stream`
        #[arg(long, default_value_t = 1.0)]
        seconds: f64,
        /// hello, telemetry, clear-faults, start-sweep, load-correction FILE, stream
        #[arg(num_args = 1..=2, required = true)]
        action: Vec<String>,
        #[command(flatten)]
        common: Common,
    },
    /// Benchmarks that print the figures the issues ask for.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
enum BenchCommand {
    /// Robustness campaigns of the drive link, seeded and time-bounded, run with integer
    /// overflow checks on (cargo profile `robustness`, built on first use): `frames` (the
    /// frame decoder under byte mutations), `requests` (decode → handle → ticks of the
    /// drive), `stream` (the host's parsing of the drive's bytes). Prints inputs tried,
    /// crashes, accepted-corrupt frames, overflow panics (goal 0 each) and wall time; exits 1
    /// when a goal is missed.
    Robustness {
        /// frames, requests, stream or all
        #[arg(long, default_value = "all")]
        campaign: String,
        /// Wall time per campaign (s)
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// Seed of the mutations
        #[arg(long, default_value_t = 0x5EED_0018)]
        seed: u64,
        #[command(flatten)]
        common: Common,
    },
    /// The firmware's figures: flash and RAM of the drive image; golden vectors
    /// replayed bit for bit on a Cortex-M4F in QEMU against the host; instructions per 16 kHz
    /// tick on the Cortex-M4 (QEMU -icount: instructions, not cycles), on average over the
    /// vectors and with every feature on at once. Builds the firmware first (scripts/fw
    /// installs the toolchain and QEMU on first use).
    Firmware {
        #[command(flatten)]
        common: Common,
    },
    /// Simulated seconds per wall second, Rust host vs fmpy (default axis, 10 s simulated).
    Fmu {
        /// Simulated time (s)
        #[arg(long, default_value_t = 10.0)]
        seconds: f64,
        /// Skip the fmpy half
        #[arg(long)]
        no_fmpy: bool,
        /// Fail (exit 1) below this real-time factor through the Rust host
        #[arg(long, default_value_t = 300.0)]
        goal: f64,
        #[command(flatten)]
        common: Common,
    },
    /// Plant integration error: the default sub-step against one ten times finer.
    Plant {
        #[command(flatten)]
        common: Common,
    },
    /// Acc/dec filters (seed 003): seed digits, python-control `matched` poles (both zero
    /// conventions), pulse conservation, residual vibration at equal delay, cost per tick.
    Accdec {
        /// Random pulse sequences for the conservation property
        #[arg(long, default_value_t = 10_000)]
        sequences: usize,
        /// Load resonances for the equal-delay vibration comparison (Hz)
        #[arg(long, value_delimiter = ',', default_values_t = [20.0, 60.0])]
        resonance: Vec<f64>,
        /// Skip the instruction count (needs valgrind)
        #[arg(long)]
        no_cost: bool,
        #[command(flatten)]
        common: Common,
    },
    /// Stop sequence (seed 004): per gain multiplier the stop error, settle time and
    /// overshoot (stop at speed and a 1 rad fine adjustment); time from the stop key to
    /// acceptance against the zero-speed level.
    Sequence {
        /// Zero-speed levels to try (rad/s, comma separated)
        #[arg(long, value_delimiter = ',', default_values_t = [0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0])]
        zero_speed: Vec<f64>,
        #[command(flatten)]
        common: Common,
    },
    /// Circle tests (seed 002): quadrant protrusion with friction compensation off and on;
    /// pseudo-circle of one friction-free axis against the two-axis circle.
    Circle {
        #[command(flatten)]
        common: Common,
    },
    /// Frequency response (seed 000): errors against the oracle below and above 2 kHz with
    /// and without phase shifting, the 2 kHz point, measurement time, PRBS/H1 baseline,
    /// analytic model at low frequencies, error against measurement time with sensor noise.
    Sweep {
        /// Current-sensor noise for the noise comparison (A, standard deviation)
        #[arg(long, default_value_t = 0.05)]
        noise: f64,
        #[command(flatten)]
        common: Common,
    },
    /// Identification and correction (seed 001): anti-resonance frequency and damping errors
    /// against the plant's truth at 20 dB SNR with 2 s of excitation (two and three axes, a
    /// rigid axis); the axes' largest response difference before and after `servo tune`
    /// (measured models, and the seed's zeros-only form); the XY circle's roundness without
    /// and with the correction.
    Ident {
        #[command(flatten)]
        common: Common,
    },
    /// Random FMI call sequences through fmpy on both archives (FMI 3.0 and 2.0): every
    /// function in any state, valid and hostile arguments (unknown value references, NaN,
    /// huge values, steps of 0, 1e300 or off the grid, corrupt serialized states). Goals: no
    /// crash, no hang, no OK step with a non-finite output.
    FmiCampaign {
        /// Seconds of calls per archive
        #[arg(long, default_value_t = 20.0)]
        seconds: f64,
        /// Seed of the call sequences (the same seed gives the same calls)
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[command(flatten)]
        common: Common,
    },
    /// Faults injected at random times into the simulated axis: a NaN or saturated current
    /// sample, an encoder disconnect, bus under- and over-voltage, the power stage's break, a
    /// following-error runaway. Prints per fault the worst reaction (ticks from detection to
    /// the bridge off; goal ≤ 1), restarts before ClearFaults (goal 0) and recovery after it.
    FaultCampaign {
        /// Runs per fault kind
        #[arg(long, default_value_t = 100)]
        runs: usize,
        /// Seed of the injection times and settings
        #[arg(long, default_value_t = 1)]
        seed: u64,
        #[command(flatten)]
        common: Common,
    },
    /// Run a filter for the instruction count of `servo bench accdec` (valgrind runs this).
    #[command(hide = true)]
    AccdecProbe {
        #[arg(long)]
        filter: String,
        #[arg(long)]
        ticks: usize,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Run { scenarios, fmpy, common } => run::command::run(scenarios, *fmpy, common),
        Command::Sequence { files, fmpy, common } => sequence::command::sequence(files, *fmpy, common),
        Command::Tune { models, method, no_check, common } => ident::command::tune(models, method, *no_check, common),
        Command::Ident { axes, set, anti_resonance, amplitude, snr_db, model, common } => {
            ident::command::ident(axes, set, anti_resonance, *amplitude, *snr_db, model, common)
        }
        Command::Sweep {
            point,
            amplitude,
            start,
            stop,
            points,
            linear,
            extra,
            settle_cycles,
            measure_cycles,
            min_settle,
            min_measure,
            shifts,
            repeats,
            threshold,
            acquisition_divider,
            precision_db,
            max_extensions,
            velocity,
            set,
            oracle,
            reference,
            common,
        } => (|| {
            let settings = sweep::command::sweep_settings(
                point,
                *amplitude,
                *start,
                *stop,
                *points,
                *linear,
                *extra,
                *settle_cycles,
                *measure_cycles,
                *min_settle,
                *min_measure,
                *shifts,
                *repeats,
                *threshold,
                *acquisition_divider,
                *precision_db,
                *max_extensions,
            )?;
            let parameters = host_tools::fmu::assignment::axis_parameters(set, &[])?;
            let run = host_tools::fmu::sweep_run::SweepRun { settings, parameters, velocity: *velocity };
            let reference = match reference {
                Some(p) => Some((p.display().to_string(), host_tools::sweep::report::read_reference(p)?)),
                None => None,
            };
            let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
            let out = common.out.clone().unwrap_or_else(|| default_out("sweep"));
            let pb = progress_bar("sweep", common.json);
            let r = host_tools::sweep::report::run(
                &fmu,
                &run,
                *oracle,
                reference.as_ref().map(|(l, v)| (l.as_str(), v.clone())),
                &out,
                |label, f| {
                    pb.set_prefix(label.to_string());
                    pb.set_position((f * 1000.0) as u64)
                },
            )?;
            pb.finish_and_clear();
            if common.json {
                println!("{}", serde_json::to_string_pretty(&r)?);
            } else {
                r.print();
            }
            // The drive's correlator and the host's equivalent-time estimate must agree.
            Ok(r.stream_vs_online.0 <= 0.01 && r.stream_vs_online.1 <= 0.1)
        })(),
        Command::Circle {
            axes,
            single,
            radius,
            feed,
            cw,
            lead_in,
            measure,
            set,
            x_set,
            y_set,
            compare,
            tuned,
            fmpy,
            common,
        } => circle::command::circle(
            axes, single, *radius, *feed, *cw, *lead_in, measure, set, x_set, y_set, compare, tuned, *fmpy, common,
        ),
        Command::Device { port, baud, timeout_ms, seconds, action, common } => {
            device::command::device(port, *baud, *timeout_ms, *seconds, action, common)
        }
        Command::Compare { a, b } => (|| {
            let (ta, tb) = (Trace::read_csv(a)?, Trace::read_csv(b)?);
            match compare_exact(&ta, &tb)? {
                Ok(n) => {
                    println!("identical: {} rows × {n} common columns, bit for bit", ta.rows.len());
                    Ok(true)
                }
                Err(m) => {
                    println!("differ: {} at row {}: {:?} vs {:?}", m.column, m.row, m.left, m.right);
                    Ok(false)
                }
            }
        })(),
        Command::Accdec {
            order,
            cutoff,
            sample_period,
            zeros_as_delays,
            ma_lengths,
            distance,
            speed,
            counts_per_rev,
            resonance,
            damping_ratio,
            sweep,
            no_sweep,
            no_fmu,
            common,
        } => accdec::command::accdec(
            *order,
            *cutoff,
            *sample_period,
            *zeros_as_delays,
            ma_lengths,
            *distance,
            *speed,
            *counts_per_rev,
            resonance,
            *damping_ratio,
            sweep,
            *no_sweep,
            *no_fmu,
            common,
        ),
        Command::Bench(BenchCommand::Fmu { seconds, no_fmpy, goal, common }) => {
            bench::backbone_command::bench_fmu(*seconds, *no_fmpy, *goal, common)
        }
        Command::Bench(BenchCommand::Plant { common }) => bench::backbone_command::bench_plant(common),
        Command::Bench(BenchCommand::FmiCampaign { seconds, seed, common }) => {
            bench::campaign_command::bench_fmi_campaign(*seconds, *seed, common)
        }
        Command::Bench(BenchCommand::FaultCampaign { runs, seed, common }) => {
            bench::campaign_command::bench_fault_campaign(*runs, *seed, common)
        }
        Command::Bench(BenchCommand::Robustness { campaign, seconds, seed, common }) => {
            bench_robustness(campaign, *seconds, *seed, common)
        }
        Command::Bench(BenchCommand::Firmware { common }) => bench::firmware_command::bench_firmware(common),
        Command::Bench(BenchCommand::Accdec { sequences, resonance, no_cost, common }) => {
            accdec::command::bench_accdec(*sequences, resonance, *no_cost, common)
        }
        Command::Bench(BenchCommand::Sequence { zero_speed, common }) => {
            sequence::command::bench_sequence(zero_speed, common)
        }
        Command::Bench(BenchCommand::Circle { common }) => circle::command::bench_circle(common),
        Command::Bench(BenchCommand::Ident { common }) => ident::command::bench_ident(common),
        Command::Bench(BenchCommand::Sweep { noise, common }) => sweep::command::bench_sweep(*noise, common),
        Command::Bench(BenchCommand::AccdecProbe { filter, ticks }) => {
            host_tools::accdec::bench::cost_probe(filter, *ticks).map(|s| {
                println!("{s}");
                true
            })
        }
    };
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::from(2)
        }
    }
}

/// `servo bench robustness`: the campaigns live in `robustness/` and run from a build with
/// overflow checks (`cargo run --profile robustness -p robustness`), which this release
/// binary is not; their figures are printed as they come.
fn bench_robustness(campaign: &str, seconds: f64, seed: u64, common: &Common) -> Result<bool> {
    if !["frames", "requests", "stream", "all"].contains(&campaign) {
        bail!("unknown campaign `{campaign}`: frames, requests, stream or all");
    }
    if !(seconds.is_finite() && seconds > 0.0 && seconds <= 86_400.0) {
        bail!("--seconds must be in (0, 86400] (got {seconds})");
    }
    let mut cmd = std::process::Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(workspace_root()).args(["run", "--profile", "robustness", "-q", "-p", "robustness", "--"]).args([
        "--campaign",
        campaign,
        "--seconds",
        &seconds.to_string(),
        "--seed",
        &seed.to_string(),
    ]);
    if common.json {
        cmd.arg("--json");
    }
    let status = cmd.status().context("cannot run cargo for the robustness campaigns")?;
    match status.code() {
        Some(0) => Ok(true),
        Some(1) => Ok(false),
        _ => bail!("the robustness campaigns did not run to the end ({status})"),
    }
}
