//! `servo sequence` and `servo bench sequence` (seed 004).

use anyhow::Result;

use crate::cli::progress_bar;
use crate::fmu::fmpy;
use crate::fmu::runner::Fmu;
use crate::fmu::trace::Trace;
use crate::paths::{default_fmu, default_out, workspace_root};
use crate::plot::signals::plot_signals;
use crate::sequence::args::{SequenceArgs, SequenceBenchArgs};

impl SequenceArgs {
    pub fn run(&self) -> Result<bool> {
        sequence(self)
    }
}

fn sequence(args: &SequenceArgs) -> Result<bool> {
    let (files, with_fmpy, common) = (&args.files, args.fmpy, &args.common);
    use crate::sequence::timeline::{SequenceScenario, PLOT};
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    let out = common.out.clone().unwrap_or_else(|| default_out("sequence"));
    crate::paths::create_out_dir(&out)?;
    let files = if files.is_empty() {
        crate::paths::toml_files_in(&workspace_root().join("scenarios/sequences"))?
    } else {
        files.to_vec()
    };
    let fmu = Fmu::load(&fmu_path)?;
    if let Some(mut session) = args.target.session()? {
        let port = args.target.device.as_deref().unwrap_or_default();
        return crate::sequence::device_report::run_on_device(
            &*fmu.as_twin_of(&session.params_for_twin()?)?,
            (port, &mut session),
            &files,
            &out,
            common.json,
        );
    }
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
            let v;
            (v, fmpy_trace) = fmpy::fmpy_cross_check(&fmu_path, &inputs, &trace, &fmpy_csv)?;
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
            "fmpy": fmpy_verdict.as_ref().map(fmpy::verdict_json),
            "csv": csv, "plot": svg,
        });
        std::fs::write(out.join(format!("{}.json", s.name)), serde_json::to_string_pretty(&json)?)?;
        if !common.json {
            println!("{} — {}", s.name, s.description);
            for o in &outcomes {
                o.print();
            }
            if let Some(v) = &fmpy_verdict {
                fmpy::print_verdict("fmpy cross-check", v);
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

impl SequenceBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_sequence(self)
    }
}

fn bench_sequence(args: &SequenceBenchArgs) -> Result<bool> {
    let (zero_speed, common) = (&args.zero_speed, &args.common);
    if !(args.gradient >= 1e-3 && args.gradient <= 1e8) {
        anyhow::bail!(
            "--gradient {}: the deceleration gradient (seq.acceleration) lies in 0.001–1e8 rad/s²",
            args.gradient
        );
    }
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("sequence bench", common.json);
    if let Some(n) = args.random {
        let grid = crate::sequence::bench::bench_random(&fmu, n, args.plant_seed, args.gradient, |f| {
            pb.set_position((f * 1000.0) as u64)
        })?;
        pb.finish_and_clear();
        let g = crate::sequence::bench::grid_figures(&grid);
        record_grid_figures("sequence-random", &format!("{n} drawn stops (seed {})", args.plant_seed), &g, None)
            .write(common.out.as_deref(), g.holds)?;
        if common.json {
            println!(
                "{}",
                serde_json::to_string_pretty(
                    &serde_json::json!({"bench": "sequence", "random": n, "plant_seed": args.plant_seed, "gradient": args.gradient, "grid": grid, "grid_figures": g})
                )?
            );
            return Ok(g.holds);
        }
        println!(
            "servo bench sequence --random — {n} stops drawn with seed {}, each on its own plant (inertia ratio 0.2–5 × shaft resonance 50–500 Hz, log-uniform), run speed 10–200 rad/s, zero-speed level 0.5–20 rad/s, width 1–100 counts (log-uniform), a gain of the table, gradient {} rad/s²: cases the project does not ship",
            args.plant_seed, args.gradient
        );
        let misses: Vec<_> = grid.iter().filter(|x| !crate::sequence::bench::stop_holds(x)).collect();
        if !misses.is_empty() {
            println!("  stops that miss (toggles, no completion, or a swing over its bound):");
            print_stops(misses.into_iter());
        }
        print_grid_figures(&g, "the drawn stops");
        return Ok(g.holds);
    }
    let r = crate::sequence::bench::bench(&fmu, zero_speed, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let g = &r.grid_figures;
    record_grid_figures(
        "sequence",
        &format!("the stop grid, {} stops", crate::bench::figures::number(g.runs as f64)),
        g,
        Some(r.settle_falls_with_gain),
    )
    .write(common.out.as_deref(), r.settle_falls_with_gain && g.holds)?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "sequence", "result": r}))?);
        return Ok(r.settle_falls_with_gain && r.grid_figures.holds);
    }
    println!(
        "servo bench sequence — stop grid: run speeds {:?} rad/s, zero-speed levels {:?} rad/s, widths {:?} counts, every gain of the table; gradient 2000 rad/s², completion hold {} ms, hysteresis {} counts ({} runs)",
        crate::sequence::bench::GRID_SPEEDS,
        crate::sequence::bench::GRID_ZERO_SPEEDS,
        crate::sequence::bench::GRID_WIDTHS,
        control_core::Params::default().sequence.completion_hold * 1e3,
        control_core::Params::default().sequence.completion_hysteresis,
        g.runs
    );
    print_stops(r.grid.iter());
    print_grid_figures(g, "the grid");
    println!("servo bench sequence — seed 004, default axis and friction, run at 100 rad/s, gradient 2000 rad/s², base gain 20/s, completion width 8 counts");
    println!("  stop at speed (run off + stop key at 0.3 s, zero-speed level 2 rad/s) and a 1 rad fine adjustment, per gain multiplier:");
    println!(
        "  {:>6} {:>12} {:>12} {:>16} {:>18} {:>14} {:>12} {:>16}",
        "gain",
        "accept ms",
        "settle ms",
        "overshoot cnt",
        "error@complete cnt",
        "error@rest cnt",
        "move ms",
        "move overshoot"
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
    println!(
        "  settle time falls as the gain rises (stop and move): {}",
        if r.settle_falls_with_gain { "yes" } else { "NO" }
    );
    println!("  time from the stop key to acceptance against the zero-speed level (deceleration from 100 rad/s):");
    println!("  {:>12} {:>14} {:>22}", "level rad/s", "measured ms", "ramp (V-VH)/a ms");
    for a in &r.acceptance {
        println!("  {:>12} {:>14.2} {:>22.2}", a.zero_speed, a.measured * 1e3, a.ramp * 1e3);
    }
    Ok(r.settle_falls_with_gain && r.grid_figures.holds)
}

/// The figures of a set of stops (and, on the shipped grid, whether the settle time falls as
/// the gain rises).
fn record_grid_figures(
    bench: &str,
    stops: &str,
    g: &crate::sequence::bench::GridFigures,
    settle_falls: Option<bool>,
) -> crate::bench::figures::Recorder {
    let mut figures = crate::bench::figures::Recorder::new(bench);
    figures
        .equal(
            &format!("stop sequence, {stops}: completion toggles after the first raise"),
            g.max_toggles as f64,
            0.0,
            "",
        )
        .equal("stops that never complete", g.never_complete as f64, 0.0, "")
        .at_most("swing after acceptance over its bound", g.worst_swing_ratio, 1.0, "")
        .info("settle time, acceptance to completion", g.max_settle * 1e3, "ms");
    if let Some(falls) = settle_falls {
        figures.equal(
            "settle time not falling as the gain rises (stop and move)",
            if falls { 0.0 } else { 1.0 },
            0.0,
            "",
        );
    }
    figures
}

/// One table row per stop (see [`crate::sequence::bench::GridStop`]); the plant where a stop
/// has its own.
fn print_stops<'a>(stops: impl Iterator<Item = &'a crate::sequence::bench::GridStop>) {
    println!(
        "  {:>8} {:>8} {:>6} {:>6} {:>10} {:>12} {:>10} {:>12} {:>10} {:>8}",
        "speed", "level", "width", "gain", "v@acc", "stop dist", "swing", "overshoot", "settle ms", "toggles"
    );
    for x in stops {
        let plant = if x.plant == "default" { String::new() } else { format!("   {}", x.plant) };
        println!(
            "  {:>8} {:>8} {:>6} {:>5}x {:>10.3} {:>12.0} {:>10} {:>12} {:>10.1} {:>8}{plant}",
            x.speed,
            x.zero_speed,
            x.width,
            x.multiplier,
            x.speed_at_acceptance,
            x.stopping_counts,
            x.swing_counts,
            x.overshoot_counts,
            x.settle * 1e3,
            x.toggles
        );
    }
}

fn print_grid_figures(g: &crate::sequence::bench::GridFigures, over: &str) {
    println!("  worst case over {over}: completion toggles after the first raise {} (goal 0); runs never complete {}; overshoot beyond the width after completion {} counts; settle time (acceptance to completion) {:.1} ms",
        g.max_toggles, g.never_complete, g.max_overshoot_counts, g.max_settle * 1e3);
    if let Some(w) = &g.worst_swing {
        let plant = if w.plant == "default" { String::new() } else { format!(" ({})", w.plant) };
        println!(
            "  swing after acceptance / bound (v²/(2a) + v·J/k_p (the velocity loop's lag) + v·δv/a (one count of the speed estimate) + {:.2}·J_L·a/k (the shaft's wind-up) + width + hysteresis): worst {:.2} (goal <= 1) at {} rad/s, level {} rad/s, width {}, gain {}x{plant}: swing {} counts, v@acc {:.3} rad/s, stopping distance {:.0} counts, lag {:.0} counts, resolution {:.0} counts, wind-up {:.0} counts",
            crate::sequence::bench::SWING_WINDUP_FACTOR, g.worst_swing_ratio, w.speed, w.zero_speed, w.width, w.multiplier, w.swing_counts, w.speed_at_acceptance, w.stopping_counts, w.lag_counts, w.resolution_counts, w.windup_counts
        );
    }
    println!("  figure holds over {over}: {}", if g.holds { "yes" } else { "NO" });
}
