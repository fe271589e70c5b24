//! `servo`: experiments on the servo FMU (default) and, later, on a real drive.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::{Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use host_tools::bench;
use host_tools::fmu_runner::{evaluate_checks, Fmu};
use host_tools::paths::{default_fmu, default_out, workspace_root};
use host_tools::plot::plot_signals;
use host_tools::report::{write_html, ScenarioReport};
use host_tools::scenario::Scenario;
use host_tools::trace::{compare_exact, Trace};

#[derive(Parser)]
#[command(name = "servo", version, about = "Servo-drive toolkit: run experiments on the servo FMU, compare with fmpy, benchmark",
    long_about = "Servo-drive toolkit.\n\nEvery command runs against the FMU the project builds \
    (target/fmu/servo_axis.fmu, made by `cargo run -p xtask -- bundle`) unless --fmu says otherwise, \
    writes its files into out/<command>/ unless --out says otherwise, prints figures as JSON with --json, \
    and exits with status 1 when a check inside it fails.")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args, Clone)]
struct Common {
    /// FMU to run (default: the one the project builds)
    #[arg(long, global = true)]
    fmu: Option<PathBuf>,
    /// Output folder (default: out/<command>/)
    #[arg(long, global = true)]
    out: Option<PathBuf>,
    /// Print machine-readable figures (JSON) on stdout instead of tables
    #[arg(long, global = true)]
    json: bool,
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
    /// comment of host-tools/src/sequence_scenario.rs and scenarios/sequences/. Prints a
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
    /// Compare two trace CSVs bit for bit on their common columns.
    Compare { a: PathBuf, b: PathBuf },
    /// Benchmarks that print the figures the issues ask for.
    #[command(subcommand)]
    Bench(BenchCommand),
}

#[derive(Subcommand)]
enum BenchCommand {
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
    /// Identification (seed 001): anti-resonance frequency and damping errors against the
    /// plant's truth at 20 dB SNR with 2 s of excitation, two and three axes, a rigid axis.
    Ident {
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

fn progress_bar(label: &str, quiet: bool) -> ProgressBar {
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

fn scenario_files(given: &[PathBuf]) -> Result<Vec<PathBuf>> {
    if !given.is_empty() {
        return Ok(given.to_vec());
    }
    let dir = workspace_root().join("scenarios");
    let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
        .with_context(|| format!("cannot list {}", dir.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    v.sort();
    if v.is_empty() {
        bail!("no scenario files in {}", dir.display());
    }
    Ok(v)
}

const DEFAULT_PLOT: [&str; 5] = ["motor_position", "motor_velocity", "load_velocity", "iq", "torque_command_out"];

fn run(files: &[PathBuf], with_fmpy: bool, common: &Common) -> Result<bool> {
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("run"));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let fmu = Fmu::load(&fmu_path)?;
    let mut all_ok = true;
    let mut reports = Vec::new();
    let mut summary = Vec::new();
    for file in scenario_files(files)? {
        let scenario = Scenario::load(&file)?;
        let pb = progress_bar(&scenario.name, common.json);
        let trace = fmu.run(&scenario, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        let csv = out.join(format!("{}.csv", scenario.name));
        trace.write_csv(&csv)?;
        let checks = evaluate_checks(&scenario, &trace)?;
        let mut fmpy_verdict = None;
        let mut traces: Vec<(&str, &Trace)> = vec![("Rust host (fmi crate)", &trace)];
        let fmpy_trace;
        if with_fmpy {
            let fmpy_csv = out.join(format!("{}.fmpy.csv", scenario.name));
            bench::run_fmpy(&fmu_path, &file, &fmpy_csv)?;
            fmpy_trace = Trace::read_csv(&fmpy_csv)?;
            let verdict = match compare_exact(&trace, &fmpy_trace)? {
                Ok(n) => Ok(format!("identical: {} rows × {} columns, bit for bit", trace.rows.len(), n)),
                Err(m) => Err(format!(
                    "differs: {} at row {} (t = {} s): Rust {:?} vs fmpy {:?}",
                    m.column, m.row, trace.rows[m.row][0], m.left, m.right
                )),
            };
            all_ok &= verdict.is_ok();
            fmpy_verdict = Some(verdict);
            traces.push(("fmpy", &fmpy_trace));
        }
        let signals: Vec<String> = if scenario.plot.is_empty() {
            DEFAULT_PLOT.iter().map(|s| s.to_string()).collect()
        } else {
            scenario.plot.clone()
        };
        let svg = out.join(format!("{}.svg", scenario.name));
        plot_signals(&svg, &format!("{}: {}", scenario.name, scenario.description), &traces, &signals)?;
        let passed = checks.iter().all(|c| c.passed);
        all_ok &= passed;
        let json = serde_json::json!({
            "scenario": scenario.name,
            "passed": passed,
            "checks": checks,
            "fmpy": fmpy_verdict.as_ref().map(|v| match v { Ok(s) => serde_json::json!({"identical": true, "detail": s}), Err(s) => serde_json::json!({"identical": false, "detail": s}) }),
            "csv": csv,
            "plot": svg,
        });
        std::fs::write(out.join(format!("{}.json", scenario.name)), serde_json::to_string_pretty(&json)?)?;
        if !common.json {
            println!("{} — {}", scenario.name, scenario.description);
            for c in &checks {
                println!(
                    "  [{}] {:<45} {:<16} observed {:>11.6} … {:<11.6} bounds {} … {}",
                    if c.passed { "pass" } else { "FAIL" },
                    c.description,
                    c.signal,
                    c.observed.0,
                    c.observed.1,
                    c.min.map_or("-inf".into(), |x| x.to_string()),
                    c.max.map_or("+inf".into(), |x| x.to_string()),
                );
            }
            if let Some(v) = &fmpy_verdict {
                match v {
                    Ok(s) => println!("  [pass] fmpy cross-check: {s}"),
                    Err(s) => println!("  [FAIL] fmpy cross-check: {s}"),
                }
            }
            println!("  → {} , {}", csv.display(), svg.display());
        }
        summary.push(json);
        reports.push(ScenarioReport {
            name: scenario.name.clone(),
            description: scenario.description.clone(),
            checks,
            fmpy: fmpy_verdict,
            plot_file: format!("{}.svg", scenario.name),
            csv_file: format!("{}.csv", scenario.name),
        });
    }
    let index = out.join("index.html");
    write_html(
        &index,
        "Servo axis scenarios",
        &format!("<p>FMU: <code>{}</code></p>", fmu_path.display()),
        &reports,
    )?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    } else {
        println!("report: {}", index.display());
    }
    Ok(all_ok)
}

fn bench_fmu(seconds: f64, no_fmpy: bool, goal: f64, common: &Common) -> Result<bool> {
    if !(seconds.is_finite() && seconds > 0.0) {
        bail!("--seconds must be a positive number");
    }
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("bench"));
    let pb = progress_bar("Rust host", common.json);
    let r = bench::bench_fmu(&fmu_path, &out, seconds, !no_fmpy, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let ok = r.rust_real_time_factor >= goal;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "fmu", "result": r, "goal": goal, "passed": ok}))?);
    } else {
        println!("servo bench fmu — default axis, {} s simulated, {} communication steps", r.simulated_seconds, r.communication_steps);
        println!("  Rust host (fmi crate): {:>8.3} s wall  → {:>8.1} x real time", r.rust_wall_seconds, r.rust_real_time_factor);
        if let (Some(w), Some(f)) = (r.fmpy_wall_seconds, r.fmpy_real_time_factor) {
            println!("  fmpy                 : {:>8.3} s wall  → {:>8.1} x real time", w, f);
            println!("  ratio Rust / fmpy    : {:>8.2}", r.rust_over_fmpy.unwrap_or(f64::NAN));
        }
        println!("  goal ≥ {goal} x real time through the Rust host: {}", if ok { "met" } else { "NOT met" });
    }
    Ok(ok)
}

fn bench_plant(common: &Common) -> Result<bool> {
    let r = host_tools::bench_plant::step_error()?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        println!("servo bench plant — exact linear parts, {} sub-step(s) per 62.5 µs tick vs {} (reference), inverter commands of {} s of closed-loop velocity steps replayed open loop", r.substeps, r.reference_substeps, r.simulated_seconds);
        for (name, err, scale) in &r.errors {
            println!("  {name:<16} max |error| {err:>10.3e}  (signal peak {scale:.3e}, relative {:.2e})", err / scale);
        }
        println!("  largest relative error: {:.2e} (goal ≤ {:.0e}): {}", r.worst_relative, host_tools::bench_plant::GOAL, if r.passed { "met" } else { "NOT met" });
    }
    Ok(r.passed)
}

#[allow(clippy::too_many_arguments)]
fn accdec(
    order: u32,
    cutoff: Option<f32>,
    sample_period: f32,
    zeros_as_delays: bool,
    ma_lengths: &Option<Vec<u32>>,
    distance: f64,
    speed: f64,
    counts_per_rev: u32,
    resonance: &[f64],
    damping_ratio: f64,
    sweep: &Option<Vec<f32>>,
    no_sweep: bool,
    no_fmu: bool,
    common: &Common,
) -> Result<bool> {
    let cutoff = cutoff.unwrap_or_else(host_tools::acc_dec_report::default_cutoff_hz);
    let nyquist = 0.5 / sample_period;
    let sweep = match (no_sweep, sweep) {
        (true, _) => vec![],
        (false, Some(s)) => s.clone(),
        (false, None) => [0.25, 0.5, 1.0, 2.0, 4.0].iter().map(|f| f * cutoff).filter(|&c| c <= nyquist).collect(),
    };
    let request = host_tools::acc_dec_report::AccDecRequest {
        order,
        cutoff_hz: cutoff,
        sample_period,
        all_delays: zeros_as_delays,
        ma_lengths: ma_lengths.clone(),
        distance_rad: distance,
        speed_rad_s: speed,
        counts_per_rev,
        resonances: resonance
            .iter()
            .map(|&hz| host_tools::acc_dec_study::Resonance { hz, damping_ratio })
            .collect(),
        sweep,
        fmu: (!no_fmu && !zeros_as_delays).then(|| common.fmu.clone().unwrap_or_else(default_fmu)),
        out: common.out.clone().unwrap_or_else(|| default_out("accdec")),
    };
    if zeros_as_delays && !no_fmu && !common.json {
        eprintln!("note: --zeros-as-delays runs on the host only (the FMU's filter keeps the seed's zeros): no FMU runs");
    }
    let pb = progress_bar("accdec", common.json);
    let report = host_tools::acc_dec_report::run(&request, |label, f| {
        pb.set_prefix(label.to_string());
        pb.set_position((f * 1000.0) as u64)
    })?;
    pb.finish_and_clear();
    if common.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        report.print();
    }
    Ok(report.butterworth.shape.pulse_balance == 0 && report.moving_average.shape.pulse_balance == 0)
}

fn bench_accdec(sequences: usize, resonance: &[f64], no_cost: bool, common: &Common) -> Result<bool> {
    use host_tools::bench_accdec as b;
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let pb = progress_bar("seed digits", common.json);
    let digits = b::seed_digits()?;
    let seed_test = b::seed_test()?;
    pb.set_prefix("python-control");
    pb.set_position(100);
    let matched = b::matched_comparison()?;
    pb.set_prefix("pulse conservation");
    pb.set_position(300);
    let props = b::properties(sequences);
    pb.set_prefix("FMU vibration");
    pb.set_position(600);
    let vibration = b::equal_delay_vibration(&fmu_path, resonance, false)?;
    let vibration_t50 = b::equal_delay_vibration(&fmu_path, resonance, true)?;
    pb.set_prefix("instruction count");
    pb.set_position(700);
    let costs = if no_cost { vec![] } else { b::filter_costs()? };
    pb.finish_and_clear();
    let worst = |f: fn(&b::MatchedComparison) -> f64| matched.iter().map(f).fold(0.0, f64::max);
    let (pole, den, gd, gs) =
        (worst(|m| m.pole_error), worst(|m| m.denominator_error), worst(|m| m.all_delays_gain_error), worst(|m| m.seed_gain_error));
    let ok = digits.iter().all(|d| d.equal)
        && pole < 1e-5
        && gd < 1e-4
        && gs < 1e-4
        && props.conservation_failures == 0
        && props.zero_input_nonzero_outputs == 0;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "bench": "accdec", "seed_digits": digits, "seed_test": seed_test, "matched": matched, "properties": props,
                "equal_delay_vibration": [vibration, vibration_t50], "costs": costs, "passed": ok
            }))?
        );
        return Ok(ok);
    }
    println!("servo bench accdec — seed 003");
    println!("  1. seed example, 3rd order, 1 kHz, 0.5 ms (printed digits):");
    for d in &digits {
        println!("     {:<20} seed {:>11}  ours {:>13.8}  {}", d.name, d.printed, d.ours, if d.equal { "equal" } else { "DIFFERENT" });
    }
    for (cutoff, out) in &seed_test {
        println!(
            "     seed's test, 100 pulses x 30 samples, {cutoff} Hz: {} pulses out over {} samples: {}",
            out.iter().sum::<i64>(),
            out.len(),
            out.iter().map(i64::to_string).collect::<Vec<_>>().join(" ")
        );
    }
    println!("  2. against python-control sample_system(method='matched'), orders 1-6 at {} (Hz, s):", b::MATCHED_CASES.map(|(c, t)| format!("{c}/{t}")).join(", "));
    println!("     largest pole error |z - z_py|            {pole:.2e}");
    println!("     largest denominator coefficient error    {den:.2e}");
    println!("     gain, every zero at infinity a delay: K = A(1), relative error {gd:.2e}  (python-control's convention)");
    println!("     gain, seed: N-1 zeros at z = -1 + one delay: K·2^(N-1) = A(1), relative error {gs:.2e}");
    println!("     (same poles; the seed's form answers one tick after the input and nulls Nyquist, python-control's waits N ticks)");
    println!("  3. properties of the whole-pulse filters (random Butterworth 1-6 / moving-average cascades):");
    println!("     {} random sequences: {} with output sum != input sum", props.sequences, props.conservation_failures);
    println!("     {} ticks of zero input: {} non-zero outputs", props.zero_input_ticks, props.zero_input_nonzero_outputs);
    println!("  4. residual load vibration (peak shaft twist after end of interpolation + 99 % delay; 2 rad at 50 rad/s, 2 % damping, friction off):");
    for v in [&vibration, &vibration_t50] {
        println!(
            "     at equal {}: {} (t50 {:.2} ms, t99 {:.2} ms) vs {} (t50 {:.2} ms, t99 {:.2} ms)",
            v.matched_on,
            v.butterworth,
            v.butterworth_t50 * 1e3,
            v.butterworth_t99 * 1e3,
            v.moving_average,
            v.moving_average_t50 * 1e3,
            v.moving_average_t99 * 1e3
        );
        for (hz, bw, ma, ratio) in &v.resonances {
            println!("     {hz:>7} Hz load resonance: Butterworth {bw:.3e} rad, moving average {ma:.3e} rad, ratio BW/MA {ratio:.3}");
        }
    }
    if !costs.is_empty() {
        println!("  5. cost per tick (x86-64 instructions, valgrind; the probe's own input generation subtracted):");
        for c in &costs {
            println!("     {:<22} {:>7.1}", c.filter, c.instructions_per_tick);
        }
    }
    println!("  checks (seed digits, poles < 1e-5, gains < 1e-4, conservation, zero in -> zero out): {}", if ok { "pass" } else { "FAIL" });
    Ok(ok)
}

fn sequence(files: &[PathBuf], with_fmpy: bool, common: &Common) -> Result<bool> {
    use host_tools::sequence_scenario::{SequenceScenario, PLOT};
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("sequence"));
    std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
    let files = if files.is_empty() {
        let dir = workspace_root().join("scenarios/sequences");
        let mut v: Vec<PathBuf> = std::fs::read_dir(&dir)
            .with_context(|| format!("cannot list {}", dir.display()))?
            .filter_map(|e| e.ok().map(|e| e.path()))
            .filter(|p| p.extension().is_some_and(|x| x == "toml"))
            .collect();
        v.sort();
        v
    } else {
        files.to_vec()
    };
    let fmu = Fmu::load(&fmu_path)?;
    let mut all_ok = true;
    let mut summary = Vec::new();
    for file in files {
        let s = SequenceScenario::load(&file)?;
        let scenario = s.to_scenario();
        let pb = progress_bar(&s.name, common.json);
        let trace = fmu.run(&scenario, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        let csv = out.join(format!("{}.csv", s.name));
        trace.write_csv(&csv)?;
        let outcomes = s.evaluate(&trace)?;
        let mut traces: Vec<(&str, &Trace)> = vec![("Rust host", &trace)];
        let fmpy_trace;
        let mut fmpy_verdict = None;
        if with_fmpy {
            let inputs = out.join(format!("{}.inputs.toml", s.name));
            std::fs::write(&inputs, scenario.to_toml())?;
            let fmpy_csv = out.join(format!("{}.fmpy.csv", s.name));
            bench::run_fmpy(&fmu_path, &inputs, &fmpy_csv)?;
            fmpy_trace = Trace::read_csv(&fmpy_csv)?;
            let v = match compare_exact(&trace, &fmpy_trace)? {
                Ok(n) => Ok(format!("identical: {} rows × {n} columns, bit for bit", trace.rows.len())),
                Err(m) => Err(format!("differs: {} at row {}: {:?} vs {:?}", m.column, m.row, m.left, m.right)),
            };
            all_ok &= v.is_ok();
            fmpy_verdict = Some(v);
            traces.push(("fmpy", &fmpy_trace));
        }
        let svg = out.join(format!("{}.svg", s.name));
        plot_signals(&svg, &format!("{}: {}", s.name, s.description), &traces, &PLOT.map(String::from))?;
        let passed = outcomes.iter().all(|o| o.passed);
        all_ok &= passed;
        let json = serde_json::json!({
            "scenario": s.name, "passed": passed, "expectations": outcomes,
            "fmpy": fmpy_verdict.as_ref().map(|v| match v { Ok(t) => serde_json::json!({"identical": true, "detail": t}), Err(t) => serde_json::json!({"identical": false, "detail": t}) }),
            "csv": csv, "plot": svg,
        });
        std::fs::write(out.join(format!("{}.json", s.name)), serde_json::to_string_pretty(&json)?)?;
        if !common.json {
            println!("{} — {}", s.name, s.description);
            for o in &outcomes {
                println!("  [{}] {:<52} {:<48} asked: {}", if o.passed { "pass" } else { "FAIL" }, o.description, o.observed, o.bound);
            }
            if let Some(v) = &fmpy_verdict {
                match v {
                    Ok(t) => println!("  [pass] fmpy cross-check: {t}"),
                    Err(t) => println!("  [FAIL] fmpy cross-check: {t}"),
                }
            }
            println!("  → {} , {}", csv.display(), svg.display());
        }
        summary.push(json);
    }
    if common.json {
        println!("{}", serde_json::to_string_pretty(&summary)?);
    }
    Ok(all_ok)
}

fn bench_sequence(zero_speed: &[f64], common: &Common) -> Result<bool> {
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("sequence bench", common.json);
    let r = host_tools::bench_sequence::bench(&fmu, zero_speed, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "sequence", "result": r}))?);
        return Ok(r.settle_falls_with_gain);
    }
    println!("servo bench sequence — seed 004, default axis and friction, run at 100 rad/s, gradient 2000 rad/s², base gain 20/s, completion width 8 counts");
    println!("  stop at speed (run off + stop key at 0.3 s, zero-speed level 2 rad/s) and a 1 rad fine adjustment, per gain multiplier:");
    println!(
        "  {:>6} {:>12} {:>12} {:>16} {:>18} {:>14} {:>12} {:>16}",
        "gain", "accept ms", "settle ms", "overshoot cnt", "error@complete cnt", "error@rest cnt", "move ms", "move overshoot"
    );
    for g in &r.gains {
        println!(
            "  {:>5}x {:>12.2} {:>12.2} {:>16} {:>18} {:>14} {:>12.2} {:>16}",
            g.multiplier,
            g.acceptance * 1e3,
            g.stop_settle * 1e3,
            g.stop_overshoot_counts,
            g.stop_error_at_completion,
            g.stop_error_at_rest,
            g.move_settle * 1e3,
            g.move_overshoot_counts
        );
    }
    println!("  settle time falls as the gain rises (stop and move): {}", if r.settle_falls_with_gain { "yes" } else { "NO" });
    println!("  time from the stop key to acceptance against the zero-speed level (deceleration from 100 rad/s):");
    println!("  {:>12} {:>14} {:>22}", "level rad/s", "measured ms", "ramp (V-VH)/a ms");
    for a in &r.acceptance {
        println!("  {:>12} {:>14.2} {:>22.2}", a.zero_speed, a.measured * 1e3, a.ramp * 1e3);
    }
    Ok(r.settle_falls_with_gain)
}

#[allow(clippy::too_many_arguments)]
fn circle(
    axes: &str,
    single: &Option<String>,
    radius: f64,
    feed: f64,
    cw: bool,
    lead_in: u32,
    measure: &str,
    set: &[String],
    x_set: &[String],
    y_set: &[String],
    compare: &[String],
    with_fmpy: bool,
    common: &Common,
) -> Result<bool> {
    use host_tools::circle_report::{axis_parameters, parse_assignment, run};
    use host_tools::circle_test::{CircleRequest, Direction, Measure};
    if axes.replace(' ', "") != "x,y" {
        bail!("--axes: the XY test runs the axes x,y (got `{axes}`)");
    }
    let measure = match measure {
        "load" => Measure::Load,
        "motor" => Measure::Motor,
        other => bail!("--measure must be load or motor (got `{other}`)"),
    };
    let (xp, yp) = (axis_parameters(set, x_set)?, axis_parameters(set, y_set)?);
    let (x_parameters, y_parameters) = match single.as_deref() {
        None | Some("x") => (xp, yp),
        Some("y") => (yp.clone(), yp),
        Some(other) => bail!("--single takes x or y (got `{other}`)"),
    };
    if lead_in == 0 && single.is_some() {
        bail!("--lead-in must be at least 1 for the single-axis test (the quarter-period copy needs history)");
    }
    let request = CircleRequest {
        radius,
        feed,
        direction: if cw { Direction::Clockwise } else { Direction::CounterClockwise },
        lead_in,
        measure,
        x_parameters,
        y_parameters,
    };
    let compare: Vec<_> = compare.iter().map(|s| parse_assignment(s)).collect::<Result<_>>()?;
    let out = common.out.clone().unwrap_or_else(|| default_out("circle"));
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let fmu = Fmu::load(&fmu_path)?;
    let second = compare.iter().map(|(k, v)| format!("{k} = {}", v.as_f64())).collect::<Vec<_>>().join(", ");
    let labels = ("as given", second.as_str());
    let pb = progress_bar("circle", common.json);
    pb.set_position(100);
    let (report, pseudo) = run(&fmu, &request, single.is_some(), &compare, labels, &out)?;
    pb.finish_and_clear();
    let mut ok = true;
    let mut fmpy_note = None;
    if with_fmpy {
        let Some((_, first)) = pseudo.first() else {
            bail!("--fmpy cross-checks the single-axis run: add --single x");
        };
        let inputs = out.join("pseudo_circle.inputs.toml");
        std::fs::write(&inputs, first.scenario.to_toml())?;
        let csv = out.join("pseudo_circle.fmpy.csv");
        bench::run_fmpy(&fmu_path, &inputs, &csv)?;
        let verdict = match compare_exact(&first.trace, &Trace::read_csv(&csv)?)? {
            Ok(n) => Ok(format!("identical: {} rows × {n} columns, bit for bit", first.trace.rows.len())),
            Err(m) => Err(format!("differs: {} at row {}: {:?} vs {:?}", m.column, m.row, m.left, m.right)),
        };
        ok &= verdict.is_ok();
        fmpy_note = Some(verdict);
    }
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"circle": report, "fmpy": fmpy_note.map(|v| v.map_err(|e| e))}))?);
    } else {
        report.print();
        match fmpy_note {
            Some(Ok(t)) => println!("  [pass] fmpy cross-check of the single-axis feedback: {t}"),
            Some(Err(t)) => println!("  [FAIL] fmpy cross-check of the single-axis feedback: {t}"),
            None => {}
        }
    }
    Ok(ok)
}

fn bench_circle(common: &Common) -> Result<bool> {
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let r = host_tools::bench_circle::bench(&fmu)?;
    let ok = r.pseudo_vs_two_axis_relative <= 1e-3 && r.protrusion_ratio < 1.0;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "circle", "result": r, "passed": ok}))?);
        return Ok(ok);
    }
    println!("servo bench circle — seed 002, radius {} rad, feed {} rad/s (1 revolution per second), machine-end positions", r.radius, r.feed);
    println!("  demo axis (default Coulomb friction 0.01 N·m motor, 0.02 N·m load), two-axis circle:");
    println!("    compensation off: largest quadrant protrusion {:.3e} rad, roundness {:.3e} rad", r.protrusion_off, r.roundness_off);
    println!(
        "    compensation on ({}): largest quadrant protrusion {:.3e} rad, roundness {:.3e} rad",
        host_tools::bench_circle::COMPENSATION.map(|(k, v)| format!("{k} = {v}")).join(", "),
        r.protrusion_on,
        r.roundness_on
    );
    println!("    ratio on / off: {:.3}", r.protrusion_ratio);
    println!(
        "  friction-free axis: pseudo-circle (x(t), x(t - T/4)) vs two-axis circle of two identical axes: largest radial difference {:.3e} rad = {:.5} % of the radius (goal <= 0.1 %)",
        r.pseudo_vs_two_axis,
        r.pseudo_vs_two_axis_relative * 100.0
    );
    Ok(ok)
}

/// Sweep settings from the command line.
#[allow(clippy::too_many_arguments)]
fn sweep_settings(
    point: &str,
    amplitude: Option<f64>,
    start: f64,
    stop: f64,
    points: u32,
    linear: bool,
    extra: f64,
    settle_cycles: f64,
    measure_cycles: f64,
    min_settle: f64,
    min_measure: f64,
    shifts: u32,
    repeats: u32,
    threshold: f64,
    acquisition_divider: u32,
) -> Result<control_core::phase_shifted_sweep::SweepParams> {
    use control_core::excitation::InjectionPoint;
    let (point, default_amplitude) = match point {
        "velocity" => (InjectionPoint::VelocityCommand, 2.0),
        "torque" => (InjectionPoint::TorqueCommand, 0.05),
        "feedback" => (InjectionPoint::VelocityFeedback, 2.0),
        other => bail!("--point must be velocity, torque or feedback (got `{other}`)"),
    };
    Ok(control_core::phase_shifted_sweep::SweepParams {
        point,
        signal: control_core::phase_shifted_sweep::SweepSignal::SteppedSine,
        amplitude: amplitude.unwrap_or(default_amplitude) as f32,
        start_hz: start as f32,
        stop_hz: stop as f32,
        points,
        logarithmic: !linear,
        extra_hz: extra as f32,
        settle_cycles: settle_cycles as f32,
        min_settle_s: min_settle as f32,
        measure_cycles: measure_cycles as f32,
        min_measure_s: min_measure as f32,
        shifts,
        repeats,
        threshold_hz: threshold as f32,
        acquisition_divider,
        ..Default::default()
    })
}

fn bench_sweep(noise: f64, common: &Common) -> Result<bool> {
    if !(noise.is_finite() && noise > 0.0) {
        bail!("--noise must be a positive current (A)");
    }
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("sweep bench", common.json);
    let r = host_tools::bench_sweep::bench(&fmu, noise, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let e = &r.ours.errors;
    let ok = e.below_gain_db.max(e.above_gain_db) <= 0.1 && e.below_phase_deg.max(e.above_phase_deg) <= 1.0 && r.ours.measurement_time_s <= 10.0;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "sweep", "result": r, "passed": ok}))?);
        return Ok(ok);
    }
    println!("servo bench sweep — seed 000: velocity loop 8 kHz, acquisition 4 kHz, 10 Hz to 3 kHz (41 points incl. 2 kHz), velocity-command injection 2 rad/s on 50 rad/s");
    println!("  max error against the oracle (acquisition 8 kHz, records 10x longer):");
    println!("  {:<58} {:>8} {:>22} {:>22}", "method", "time s", "below 2 kHz dB / deg", "2 kHz and up dB / deg");
    for m in [&r.ours, &r.single_phase, &r.prbs] {
        let x = &m.errors;
        println!(
            "  {:<58} {:>8.3} {:>10.3} / {:>9.2} {:>10.3} / {:>9.2}{}",
            m.method,
            m.measurement_time_s,
            x.below_gain_db,
            x.below_phase_deg,
            x.above_gain_db,
            x.above_phase_deg,
            if m.unmeasured.is_empty() { String::new() } else { format!("   cannot measure {} point(s): {:?} Hz", m.unmeasured.len(), m.unmeasured.iter().map(|f| f.round()).collect::<Vec<_>>()) }
        );
    }
    let [o, ours, single] = r.at_nyquist;
    println!(
        "  at exactly 2 kHz: oracle {:.3} dB / {:.2} deg; phase shifted {:.3} dB / {:.2} deg (quality {:.3}); single phase {:.3} dB / {:.2} deg (quality {:.3})",
        o.gain_db, o.phase_deg, ours.gain_db, ours.phase_deg, ours.quality, single.gain_db, single.phase_deg, single.quality
    );
    println!("  equivalent-time stream vs the drive's on-line correlator: {:.1e} dB, {:.1e} deg", r.stream_vs_online.0, r.stream_vs_online.1);
    println!("  analytic linear model vs oracle up to 30 Hz: {:.3} dB, {:.2} deg", r.analytic_low_frequency.0, r.analytic_low_frequency.1);
    println!(
        "  goal: full Bode in <= 10 s with <= 0.1 dB / 1 deg everywhere: {:.2} s, {:.3} dB, {:.2} deg: {}",
        r.ours.measurement_time_s,
        e.below_gain_db.max(e.above_gain_db),
        e.below_phase_deg.max(e.above_phase_deg),
        if ok { "met" } else { "NOT met" }
    );
    println!("  with current-sensor noise {} A: max error up to 1.9 kHz against measurement time", r.noise_std_a);
    println!("  {:>10} {:>24} {:>24}", "time s", "ours dB / deg", "PRBS H1 dB / deg");
    for n in &r.noise {
        println!("  {:>10.2} {:>12.3} / {:>9.2} {:>12.3} / {:>9.2}", n.measurement_time_s, n.ours.0, n.ours.1, n.prbs.0, n.prbs.1);
    }
    Ok(ok)
}

#[allow(clippy::too_many_arguments)]
fn ident(
    axes: &[String],
    set: &[String],
    anti_resonance: &[String],
    amplitude: f64,
    snr_db: Option<f64>,
    model: &[PathBuf],
    common: &Common,
) -> Result<bool> {
    use host_tools::ident_report::{identify_axis, plot, replot};
    let out = common.out.clone().unwrap_or_else(|| default_out("ident"));
    if !model.is_empty() {
        let svg = replot(model, &out)?;
        println!("re-plotted {} model(s) → {}", model.len(), svg.display());
        return Ok(true);
    }
    let mut parameters: std::collections::BTreeMap<String, std::collections::BTreeMap<String, host_tools::scenario::Value>> =
        axes.iter().map(|a| (a.clone(), Default::default())).collect();
    for s in set {
        let (axis, rest) = s.split_once(':').ok_or_else(|| anyhow::anyhow!("--set `{s}`: use AXIS:NAME=VALUE"))?;
        let (k, v) = host_tools::circle_report::parse_assignment(rest)?;
        parameters.get_mut(axis).ok_or_else(|| anyhow::anyhow!("--set `{s}`: no axis `{axis}` in --axes"))?.insert(k, v);
    }
    for s in anti_resonance {
        let (axis, hz) = s.split_once('=').ok_or_else(|| anyhow::anyhow!("--anti-resonance `{s}`: use AXIS=HZ"))?;
        let hz: f64 = hz.parse().map_err(|_| anyhow::anyhow!("--anti-resonance `{s}`: `{hz}` is not a frequency"))?;
        if !(hz.is_finite() && hz > 0.0) {
            bail!("--anti-resonance `{s}`: the frequency must be positive");
        }
        let load = servo_axis::plant::PlantParams::default().load_inertia;
        parameters
            .get_mut(axis)
            .ok_or_else(|| anyhow::anyhow!("--anti-resonance `{s}`: no axis `{axis}` in --axes"))?
            .extend(host_tools::identification::absorber_parameters(hz, 0.05, load));
    }
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("identification", common.json);
    let mut results = Vec::new();
    for (i, axis) in axes.iter().enumerate() {
        pb.set_prefix(format!("axis {axis}"));
        pb.set_position((i * 1000 / axes.len()) as u64);
        results.push(identify_axis(&fmu, axis, &parameters[axis], amplitude, snr_db, &out)?);
    }
    pb.finish_and_clear();
    let plotted: Vec<_> = results
        .iter()
        .map(|r| {
            let t = Trace::read_csv(&r.files[1])?;
            let (f, g, p) = (t.column("frequency").unwrap_or_default(), t.column("gain_db").unwrap_or_default(), t.column("phase_deg").unwrap_or_default());
            let pts = (0..f.len()).map(|i| host_tools::frequency_response::ResponsePoint { frequency: f[i], gain_db: g[i], phase_deg: p[i], quality: 1.0 }).collect();
            Ok((r.model.clone(), pts))
        })
        .collect::<Result<_>>()?;
    let svg = out.join("ident.svg");
    plot(&svg, &plotted)?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"axes": results, "plot": svg}))?);
        return Ok(true);
    }
    println!("servo ident — M-sequence degree {} at 1 kHz on the torque, one 2.05 s period measured after 0.5 s of transients", host_tools::identification::DEGREE);
    for r in &results {
        let m = &r.model;
        match (m.anti_resonance, m.resonance) {
            (Some(z), p) => println!(
                "  {}: anti-resonance {:.3} Hz, damping {:.4}; resonance {}; gain {:.4e}; fit band {:.1}–{:.1} Hz, rms fit error {:.1} %{}",
                m.axis,
                z.hz,
                z.damping,
                p.map_or("-".into(), |p| format!("{:.2} Hz, damping {:.4}", p.hz, p.damping)),
                m.gain,
                m.band.0,
                m.band.1,
                m.fit_error * 100.0,
                r.snr_db.map_or(String::new(), |s| format!(" (accelerometer noise {:.3e} rad/s² for {s} dB SNR)", r.noise_std))
            ),
            (None, _) => println!("  {}: no anti-resonance found (rigid axis, N = 1); gain {:.4e}", m.axis, m.gain),
        }
        for f in &r.files {
            println!("    → {}", f.display());
        }
    }
    println!("  → {}", svg.display());
    Ok(true)
}

fn bench_ident(common: &Common) -> Result<bool> {
    use host_tools::identification::{absorber_parameters, true_anti_resonance};
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let out = common.out.clone().unwrap_or_else(|| default_out("bench/ident"));
    let load = servo_axis::plant::PlantParams::default().load_inertia;
    let cases: Vec<(&str, Vec<(&str, Option<f64>)>)> = vec![
        ("two axes", vec![("x", Some(40.0)), ("y", Some(70.0))]),
        ("three axes", vec![("x", Some(40.0)), ("y", Some(70.0)), ("z", Some(55.0))]),
        ("rigid axis", vec![("w", None)]),
    ];
    let mut rows = Vec::new();
    let mut ok = true;
    let pb = progress_bar("ident bench", common.json);
    let total: usize = cases.iter().map(|c| c.1.len()).sum();
    let mut done = 0;
    for (case, axes) in &cases {
        for (axis, hz) in axes {
            pb.set_position((done * 1000 / total) as u64);
            done += 1;
            let params = hz.map(|h| absorber_parameters(h, 0.05, load)).unwrap_or_default();
            let r = host_tools::ident_report::identify_axis(&fmu, axis, &params, 0.05, Some(20.0), &out.join(case.replace(' ', "_")))?;
            let truth = hz.map(|h| {
                let w = std::f64::consts::TAU * h;
                true_anti_resonance(load, load * w * w, 2.0 * 0.05 * load * w)
            });
            let (f_err, d_err) = match (truth, r.model.anti_resonance) {
                (Some(t), Some(z)) => ((z.hz - t.hz) / t.hz, (z.damping - t.damping) / t.damping),
                (None, None) => (0.0, 0.0),
                _ => (f64::INFINITY, f64::INFINITY),
            };
            ok &= f_err.abs() <= 0.01 && d_err.abs() <= 0.2;
            rows.push(serde_json::json!({"case": case, "axis": axis, "truth": truth, "model": r.model, "frequency_error": f_err, "damping_error": d_err}));
        }
    }
    pb.finish_and_clear();
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "ident", "rows": rows, "passed": ok}))?);
        return Ok(ok);
    }
    println!("servo bench ident — seed 001: accelerometer noise at 20 dB SNR, 2.05 s of M-sequence measured after 0.5 s of transients");
    println!("  {:<11} {:<5} {:>12} {:>12} {:>12} {:>12} {:>10} {:>10}", "case", "axis", "true Hz", "found Hz", "true ζ", "found ζ", "Hz err %", "ζ err %");
    for r in &rows {
        let t = &r["truth"];
        let m = &r["model"]["anti_resonance"];
        let num = |v: &serde_json::Value, k: &str| v.get(k).and_then(|x| x.as_f64()).map_or("-".to_string(), |x| format!("{x:.4}"));
        println!(
            "  {:<11} {:<5} {:>12} {:>12} {:>12} {:>12} {:>10.3} {:>10.2}",
            r["case"].as_str().unwrap_or(""),
            r["axis"].as_str().unwrap_or(""),
            num(t, "hz"),
            num(m, "hz"),
            num(t, "damping"),
            num(m, "damping"),
            r["frequency_error"].as_f64().unwrap_or(f64::NAN) * 100.0,
            r["damping_error"].as_f64().unwrap_or(f64::NAN) * 100.0
        );
    }
    println!("  goal: at most 1 % in frequency and 20 % in damping: {}", if ok { "met" } else { "NOT met" });
    Ok(ok)
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Run { scenarios, fmpy, common } => run(scenarios, *fmpy, common),
        Command::Sequence { files, fmpy, common } => sequence(files, *fmpy, common),
        Command::Ident { axes, set, anti_resonance, amplitude, snr_db, model, common } => {
            ident(axes, set, anti_resonance, *amplitude, *snr_db, model, common)
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
            velocity,
            set,
            oracle,
            reference,
            common,
        } => (|| {
            let settings = sweep_settings(
                point, *amplitude, *start, *stop, *points, *linear, *extra, *settle_cycles, *measure_cycles, *min_settle,
                *min_measure, *shifts, *repeats, *threshold, *acquisition_divider,
            )?;
            let parameters = host_tools::circle_report::axis_parameters(set, &[])?;
            let run = host_tools::frequency_response::SweepRun { settings, parameters, velocity: *velocity };
            let reference = match reference {
                Some(p) => Some((p.display().to_string(), host_tools::sweep_report::read_reference(p)?)),
                None => None,
            };
            let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
            let out = common.out.clone().unwrap_or_else(|| default_out("sweep"));
            let pb = progress_bar("sweep", common.json);
            let r = host_tools::sweep_report::run(
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
        Command::Circle { axes, single, radius, feed, cw, lead_in, measure, set, x_set, y_set, compare, fmpy, common } => {
            circle(axes, single, *radius, *feed, *cw, *lead_in, measure, set, x_set, y_set, compare, *fmpy, common)
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
        } => accdec(
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
        Command::Bench(BenchCommand::Fmu { seconds, no_fmpy, goal, common }) => bench_fmu(*seconds, *no_fmpy, *goal, common),
        Command::Bench(BenchCommand::Plant { common }) => bench_plant(common),
        Command::Bench(BenchCommand::Accdec { sequences, resonance, no_cost, common }) => {
            bench_accdec(*sequences, resonance, *no_cost, common)
        }
        Command::Bench(BenchCommand::Sequence { zero_speed, common }) => bench_sequence(zero_speed, common),
        Command::Bench(BenchCommand::Circle { common }) => bench_circle(common),
        Command::Bench(BenchCommand::Ident { common }) => bench_ident(common),
        Command::Bench(BenchCommand::Sweep { noise, common }) => bench_sweep(*noise, common),
        Command::Bench(BenchCommand::AccdecProbe { filter, ticks }) => {
            host_tools::bench_accdec::cost_probe(filter, *ticks).map(|s| {
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
