//! `servo sweep` (its options, the sweep settings they give) and `servo bench sweep` (seed 000).

use anyhow::{bail, Result};

use crate::cli::{progress_bar, Common};
use crate::fmu::runner::Fmu;
use crate::paths::{default_fmu, default_out};
use crate::sweep::args::{SweepArgs, SweepBenchArgs};

/// The extra frequency a sweep gets when --extra is not given and it lies in the sweep's
/// range: the acquisition Nyquist frequency of the default rates (16 kHz, acquisition every 4
/// ticks), where phase shifting starts.
const DEFAULT_EXTRA_HZ: f64 = 2000.0;

/// Sweep settings from the command line.
pub fn sweep_settings(args: &SweepArgs) -> Result<control_core::phase_shifted_sweep::SweepParams> {
    let (
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
    ) = (
        args.point.as_str(),
        args.amplitude,
        args.start,
        args.stop,
        args.points,
        args.linear,
        args.extra,
        args.settle_cycles,
        args.measure_cycles,
        args.min_settle,
        args.min_measure,
        args.shifts,
        args.repeats,
        args.threshold,
        args.acquisition_divider,
        args.precision_db,
        args.max_extensions,
    );
    let (point, default_amplitude) = injection_point(point)?;
    // One point measures --start alone.
    let top = if points > 1 { stop } else { start };
    Ok(control_core::phase_shifted_sweep::SweepParams {
        point,
        signal: control_core::phase_shifted_sweep::SweepSignal::SteppedSine,
        amplitude: amplitude.unwrap_or(default_amplitude) as f32,
        start_hz: start as f32,
        stop_hz: stop as f32,
        points,
        logarithmic: !linear,
        extra_hz: extra.unwrap_or(if (start..=top).contains(&DEFAULT_EXTRA_HZ) { DEFAULT_EXTRA_HZ } else { 0.0 })
            as f32,
        settle_cycles: settle_cycles as f32,
        min_settle_s: min_settle as f32,
        measure_cycles: measure_cycles as f32,
        min_measure_s: min_measure as f32,
        shifts,
        repeats,
        threshold_hz: threshold as f32,
        acquisition_divider,
        precision_db: precision_db as f32,
        max_extensions,
        time_budget_s: args.time_budget as f32,
        dither: args.dither as f32,
        ..Default::default()
    })
}

impl SweepBenchArgs {
    pub fn run(&self) -> Result<bool> {
        let random = self.random.map(|n| (n, self.plant_seed));
        if self.plants.is_empty()
            && self.points.is_empty()
            && self.noise.is_none()
            && !self.interior
            && random.is_none()
        {
            return bench_sweep(&self.common, self.detail, self.seeds);
        }
        let points = self.points.iter().map(|p| injection_point(p).map(|(p, _)| p)).collect::<Result<Vec<_>>>()?;
        let selection = crate::sweep::bench::GridSelection {
            plants: self.plants.clone(),
            points,
            noise: self.noise,
            seeds: self.seeds,
            interior: self.interior,
            random,
        };
        selection.validate()?;
        let fmu = Fmu::load(&self.common.fmu.clone().unwrap_or_else(default_fmu))?;
        let pb = progress_bar("sweep bench", self.common.json);
        let rows = crate::sweep::bench::grid(&fmu, &selection, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        let ok = rows.iter().all(|r| r.met);
        let bench = if random.is_some() { "sweep-random" } else { "sweep-grid" };
        record_rows(bench, &rows, "").write(self.common.out.as_deref(), ok)?;
        if self.common.json {
            println!(
                "{}",
                serde_json::to_string_pretty(&serde_json::json!({"bench": "sweep", "grid": rows, "passed": ok}))?
            );
        } else if (self.interior || random.is_some()) && !self.detail {
            let plants = match random {
                Some((n, seed)) => format!(
                    "{n} plants drawn with seed {seed}: inertia ratio log-uniform in 0.2–5 × shaft resonance log-uniform in 50–500 Hz"
                ),
                None => "36 plants: inertia ratio 0.2–5 × shaft resonance 50–500 Hz".to_string(),
            };
            let flag = if random.is_some() { "--random" } else { "--interior" };
            print_summary(&rows, flag, &plants);
        } else {
            print_grid(&rows, self.detail);
        }
        Ok(ok)
    }
}

/// The sweep grid's figures: the worst gain error, phase error and measurement time over its
/// rows against the goals, and the rows that miss one.
fn record_rows(bench: &str, rows: &[crate::sweep::bench::GridRow], what: &str) -> crate::bench::figures::Recorder {
    use crate::sweep::bench::{GOAL_DB, GOAL_DEG, GOAL_SECONDS};
    let worst = |f: fn(&crate::sweep::bench::GridRow) -> f64| rows.iter().map(f).fold(0.0, f64::max);
    let seeds = rows.iter().map(|r| r.seeds).max().unwrap_or(0);
    let mut figures = crate::bench::figures::Recorder::new(bench);
    figures
        .at_most(
            &format!(
                "frequency response vs the oracle, 10 Hz–3 kHz, {} rows{what}, {seeds} noise seed(s): gain",
                rows.len()
            ),
            worst(|r| r.gain_db),
            GOAL_DB,
            "dB",
        )
        .at_most("phase", worst(|r| r.phase_deg), GOAL_DEG, "°")
        .at_most("time per sweep", worst(|r| r.measurement_time_s), GOAL_SECONDS, "s")
        .equal("rows missing a goal", rows.iter().filter(|r| !r.met).count() as f64, 0.0, "");
    figures
}

/// The injection point of a `--point` word and its default amplitude.
fn injection_point(word: &str) -> Result<(control_core::excitation::InjectionPoint, f64)> {
    use control_core::excitation::InjectionPoint;
    Ok(match word {
        "velocity" => (InjectionPoint::VelocityCommand, 2.0),
        "torque" => (InjectionPoint::TorqueCommand, 0.2),
        "feedback" => (InjectionPoint::VelocityFeedback, 2.0),
        other => bail!("--point must be velocity, torque or feedback (got `{other}`)"),
    })
}

/// The interior grid in brief: per injection point and noise level the rows that meet every
/// goal and the worst gain error, phase error and time with their plants; then the rows that
/// miss a goal.
fn print_summary(rows: &[crate::sweep::bench::GridRow], flag: &str, plants: &str) {
    use crate::sweep::bench::GridRow;
    println!(
        "servo bench sweep {flag} — {} rows ({plants}; each point, with and without current-sensor noise); goal <= 0.1 dB, <= 1 deg, <= 10 s",
        rows.len()
    );
    println!(
        "  {:<18} {:>7} {:>9}   {:<30} {:<30} {:<30}",
        "injection point", "noise A", "rows met", "worst dB (plant)", "worst deg (plant)", "longest s (plant)"
    );
    // Point and noise level, in the order the grid first has them.
    let mut keys: Vec<(String, u64)> = Vec::new();
    for key in rows.iter().map(|r| (r.point.clone(), r.noise_a.to_bits())) {
        if !keys.contains(&key) {
            keys.push(key);
        }
    }
    for (point, noise) in keys {
        let group: Vec<&GridRow> = rows.iter().filter(|r| r.point == point && r.noise_a.to_bits() == noise).collect();
        let worst = |key: fn(&GridRow) -> f64| group.iter().copied().max_by(|a, b| key(a).total_cmp(&key(b)));
        let cell = |r: Option<&GridRow>, v: fn(&GridRow) -> f64, digits: usize| {
            r.map_or("-".into(), |r| format!("{:.digits$} ({})", v(r), r.plant.replace("J_L/J_M ", "")))
        };
        println!(
            "  {:<18} {:>7} {:>4} / {:<3}   {:<30} {:<30} {:<30}",
            point,
            f64::from_bits(noise),
            group.iter().filter(|r| r.met).count(),
            group.len(),
            cell(worst(|r| r.gain_db), |r| r.gain_db, 3),
            cell(worst(|r| r.phase_deg), |r| r.phase_deg, 2),
            cell(worst(|r| r.measurement_time_s), |r| r.measurement_time_s, 2),
        );
    }
    let missed: Vec<&GridRow> = rows.iter().filter(|r| !r.met).collect();
    println!("  rows missing a goal: {} of {}", missed.len(), rows.len());
    for r in missed {
        println!(
            "    {:<18} {:<24} noise {:<5} seeds {:<3} {:.3} dB at {:.1} Hz, {:.2} deg at {:.1} Hz, {:.2} s{}",
            r.point,
            r.plant,
            r.noise_a,
            r.seeds,
            r.gain_db,
            r.gain_at_hz,
            r.phase_deg,
            r.phase_at_hz,
            r.measurement_time_s,
            if r.limited_points > 0 {
                format!(", {} results measured with the output limited", r.limited_points)
            } else {
                String::new()
            }
        );
    }
}

/// The grid's table (and, with `detail`, every frequency's error under its row).
fn print_grid(rows: &[crate::sweep::bench::GridRow], detail: bool) {
    println!(
        "  {:<18} {:<28} {:>7} {:>5} {:>9} {:>8} {:>9} {:>8} {:>9} {:>7}  goal",
        "injection point", "plant", "noise A", "seeds", "amplitude", "dB", "at Hz", "deg", "at Hz", "time s"
    );
    for row in rows {
        println!(
            "  {:<18} {:<28} {:>7} {:>5} {:>9} {:>8.3} {:>9.1} {:>8.2} {:>9.1} {:>7.2}  {}",
            row.point,
            row.plant,
            row.noise_a,
            row.seeds,
            row.amplitude,
            row.gain_db,
            row.gain_at_hz,
            row.phase_deg,
            row.phase_at_hz,
            row.measurement_time_s,
            match (row.met, row.limited_points) {
                (true, 0) => "met".to_string(),
                (false, 0) => "MISSED".to_string(),
                (met, n) => format!("{} ({n} measured with the output limited)", if met { "met" } else { "MISSED" }),
            }
        );
        if detail {
            for e in &row.per_frequency {
                println!(
                    "      {:>9.1} Hz {:>+8.3} dB {:>+8.2} deg {:>7.3} s",
                    e.frequency, e.gain_db, e.phase_deg, e.seconds
                );
            }
        }
    }
    let missed = rows.iter().filter(|row| !row.met).count();
    println!("  rows missing a goal: {missed} of {}", rows.len());
}

fn bench_sweep(common: &Common, detail: bool, seeds: u32) -> Result<bool> {
    use crate::sweep::bench::{GOAL_DB, GOAL_DEG, GOAL_SECONDS};
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("sweep bench", common.json);
    let r = crate::sweep::bench::bench(&fmu, seeds, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let ok = r.goals_met();
    let mut figures = record_rows("sweep", &r.grid, ", 3 injection points × 5 plants × 2 noise levels");
    figures
        .equal(
            "results measured with the drive's output limited and not flagged, outside the goals",
            r.limit_detection.iter().filter(|c| !c.met).count() as f64,
            0.0,
            "",
        )
        .info("the oracle against itself, gain", r.oracle_self_check.0, "dB")
        .info("equivalent-time stream vs the drive's on-line correlator, gain", r.stream_vs_online.0, "dB")
        .write(common.out.as_deref(), ok)?;
    // With --detail, how well the sweep's standard errors predict its errors (not a goal).
    let calibration = if detail {
        let pb = progress_bar("standard error calibration", common.json);
        let c = crate::sweep::standard_error_calibration::calibration(&fmu, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        Some(c)
    } else {
        None
    };
    if common.json {
        let mut json = serde_json::json!({"bench": "sweep", "result": r, "passed": ok});
        if let Some(c) = &calibration {
            json["standard_error_calibration"] = serde_json::to_value(c)?;
        }
        println!("{}", serde_json::to_string_pretty(&json)?);
        return Ok(ok);
    }
    let d = control_core::phase_shifted_sweep::SweepParams::default();
    println!(
        "servo bench sweep — seed 000: velocity loop 8 kHz, acquisition 4 kHz, 10 Hz to 3 kHz (41 points incl. 2 kHz), riding on 50 rad/s, default settings (precision {} dB, dither {} N·m)",
        d.precision_db, d.dither
    );
    println!(
        "  worst error over all frequencies against the oracle (8 kHz acquisition, 10x longer records, at least 0.5 s settling, 2^24-count encoder, no sensor noise); goal <= {GOAL_DB} dB, <= {GOAL_DEG} deg, <= {GOAL_SECONDS} s:"
    );
    print_grid(&r.grid, detail);
    println!(
        "  the oracle against itself with settling and records twice as long, riding 1 % faster (every plant and point): {:.4} dB, {:.3} deg",
        r.oracle_self_check.0, r.oracle_self_check.1
    );
    println!("  default axis, velocity command, current-sensor noise {} A:", crate::sweep::bench::DITHER_A);
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
            if m.unmeasured.is_empty() {
                String::new()
            } else {
                format!(
                    "   cannot measure {} point(s): {:?} Hz",
                    m.unmeasured.len(),
                    m.unmeasured.iter().map(|f| f.round()).collect::<Vec<_>>()
                )
            }
        );
    }
    let [o, ours, single] = r.at_nyquist;
    println!(
        "  at exactly 2 kHz: oracle {:.3} dB / {:.2} deg; phase shifted {:.3} dB / {:.2} deg (quality {:.3}); single phase {:.3} dB / {:.2} deg (quality {:.3})",
        o.gain_db, o.phase_deg, ours.gain_db, ours.phase_deg, ours.quality, single.gain_db, single.phase_deg, single.quality
    );
    println!(
        "  equivalent-time stream vs the drive's on-line correlator: {:.1e} dB, {:.1e} deg",
        r.stream_vs_online.0, r.stream_vs_online.1
    );
    println!(
        "  analytic linear model vs oracle up to 30 Hz: {:.3} dB, {:.2} deg",
        r.analytic_low_frequency.0, r.analytic_low_frequency.1
    );
    print_limit_detection(&r.limit_detection);
    if let Some(c) = &calibration {
        crate::sweep::standard_error_calibration::print_calibration(c);
    }
    println!("  goal on every row: {}", if ok { "met" } else { "NOT met" });
    Ok(ok)
}

fn print_limit_detection(cases: &[crate::sweep::limit_detection::LimitCase]) {
    println!(
        "  results measured with the drive's output limited, flagged (default axis riding faster, 48 V bus; goal: every unflagged result within {} dB, {} deg):",
        crate::sweep::bench::GOAL_DB,
        crate::sweep::bench::GOAL_DEG
    );
    println!(
        "  {:<18} {:>9} {:>8}  {:<30} {:>18} {:>18}  goal",
        "injection point", "amplitude", "rad/s", "flagged", "unflagged dB / deg", "flagged dB / deg"
    );
    for c in cases {
        let mut flagged = match (c.flagged_hz.first(), c.flagged_hz.last()) {
            (Some(a), Some(b)) => format!("{} from {a:.0} to {b:.0} Hz", c.flagged_hz.len()),
            _ => "none".to_string(),
        };
        // Where only the oracle was limited, nothing is compared: say how many.
        let oracle_only = c.oracle_flagged_hz.iter().filter(|f| !c.flagged_hz.contains(f)).count();
        if oracle_only > 0 {
            flagged.push_str(&format!(" (+{oracle_only} oracle's)"));
        }
        println!(
            "  {:<18} {:>9} {:>8}  {:<30} {:>9.3} / {:>6.2} {:>9.3} / {:>6.2}  {}",
            c.point,
            c.amplitude,
            c.riding_rad_s,
            flagged,
            c.unflagged.0,
            c.unflagged.1,
            c.flagged.0,
            c.flagged.1,
            if c.met { "met" } else { "MISSED" }
        );
    }
}

impl SweepArgs {
    pub fn run(&self) -> Result<bool> {
        let settings = sweep_settings(self)?;
        let parameters = crate::fmu::plant_file::machine_parameters(self.plant.as_deref(), &self.set)?;
        // The sweep's settings come from this command's options: a `--set sweep.…` would be
        // overwritten by them without a word.
        if let Some(name) = parameters.keys().find(|name| name.starts_with("sweep.")) {
            bail!(
                "--set {name}: the sweep's settings come from this command's options (see `servo sweep --help`: --start, --stop, --points, --amplitude, ...), not from --set"
            );
        }
        let run = crate::fmu::sweep_run::SweepRun { settings, parameters, velocity: self.velocity };
        let reference = match &self.reference {
            Some(p) => Some((p.display().to_string(), crate::sweep::report::read_reference(p)?)),
            None => None,
        };
        let common = &self.common;
        let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
        let out = common.out.clone().unwrap_or_else(|| default_out("sweep"));
        if self.target.device.is_some() && (self.oracle || self.reference.is_some()) {
            bail!("--oracle and --reference are for a sweep on the FMU; with --device the FMU runs the drive's twin");
        }
        if let Some(mut session) = self.target.session()? {
            let port = self.target.device.as_deref().unwrap_or_default();
            let pb = progress_bar("sweep", common.json);
            let r = crate::sweep::device_report::run_on_device(
                &*fmu.as_twin_of(&session.params_for_twin()?)?,
                &run,
                (port, &mut session),
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
            return Ok(r.passed);
        }
        let pb = progress_bar("sweep", common.json);
        let r = crate::sweep::report::run(
            &fmu,
            &run,
            self.oracle,
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
        Ok(r.passed())
    }
}
