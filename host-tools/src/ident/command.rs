//! `servo ident` and `servo bench ident` (seed 001).

use anyhow::{bail, Result};

use crate::cli::progress_bar;
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::trace::Trace;
use crate::ident::args::{IdentArgs, IdentBenchArgs, TuneArgs};
use crate::paths::{default_fmu, default_out};

impl IdentArgs {
    pub fn run(&self) -> Result<bool> {
        ident(self)
    }
}

fn ident(args: &IdentArgs) -> Result<bool> {
    let (axes, set, anti_resonance, amplitude, snr_db, model, common) =
        (&args.axes, &args.set, &args.anti_resonance, args.amplitude, args.snr_db, &args.model, &args.common);
    use crate::ident::report::{identify_axis, plot, replot};
    let out = common.out.clone().unwrap_or_else(|| default_out("ident"));
    if args.target.device.is_some() {
        if !model.is_empty() {
            bail!("--model re-plots saved models; it takes no --device");
        }
        if snr_db.is_some() {
            bail!("--snr-db sets the FMU's accelerometer noise; over a drive the noise is the drive's own (give the twin the same with --set AXIS:plant.acceleration_noise_std=...)");
        }
    } else if let Some(axis) = &args.axis {
        bail!("--axis {axis} chooses the axis identified on a drive: it needs --device");
    }
    if !model.is_empty() {
        let svg = replot(model, &out)?;
        println!("re-plotted {} model(s) → {}", model.len(), svg.display());
        return Ok(true);
    }
    crate::ident::axis_name::check_axis_names(axes.iter().map(String::as_str), "--axes")?;
    let mut parameters: std::collections::BTreeMap<
        String,
        std::collections::BTreeMap<String, crate::fmu::scenario::Value>,
    > = axes.iter().map(|a| (a.clone(), Default::default())).collect();
    for s in set {
        let (axis, rest) = s.split_once(':').ok_or_else(|| anyhow::anyhow!("--set `{s}`: use AXIS:NAME=VALUE"))?;
        let (k, v) = crate::fmu::assignment::parse_assignment(rest)?;
        parameters
            .get_mut(axis)
            .ok_or_else(|| anyhow::anyhow!("--set `{s}`: no axis `{axis}` in --axes"))?
            .insert(k, v);
    }
    let mut absorbed: Vec<&str> = Vec::new();
    for s in anti_resonance {
        let (axis, hz) = s.split_once('=').ok_or_else(|| anyhow::anyhow!("--anti-resonance `{s}`: use AXIS=HZ"))?;
        if absorbed.contains(&axis) {
            bail!("--anti-resonance `{s}`: axis `{axis}` already has an anti-resonance (one absorber per axis)");
        }
        absorbed.push(axis);
        let hz: f64 = hz.parse().map_err(|_| anyhow::anyhow!("--anti-resonance `{s}`: `{hz}` is not a frequency"))?;
        let (lowest, highest) = crate::ident::identification::IDENTIFIABLE_HZ;
        if !(hz.is_finite() && (lowest..=highest).contains(&hz)) {
            bail!(
                "--anti-resonance `{s}`: the identification finds anti-resonances from {lowest} to {highest} Hz (the M-sequence's response is measured over {}–{} Hz at {:.2} Hz resolution; the notch search needs ±{:.0} % around a notch)",
                crate::ident::report::BAND.0,
                crate::ident::report::BAND.1,
                1.0 / crate::ident::identification::period_s(),
                (crate::ident::identification::NOTCH_SPAN - 1.0) * 100.0
            );
        }
        let axis_parameters = parameters
            .get_mut(axis)
            .ok_or_else(|| anyhow::anyhow!("--anti-resonance `{s}`: no axis `{axis}` in --axes"))?;
        // The absorber's inertia equals the load's: the load this axis runs with.
        let load = configuration(axis_parameters)?.plant.load_inertia;
        axis_parameters.extend(crate::ident::identification::absorber_parameters(hz, 0.05, load));
    }
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    if args.target.device.is_some() {
        return ident_on_device(args, &fmu, &parameters, &out);
    }
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
        .filter_map(|r| r.model.as_ref().map(|m| (m, &r.files[1])))
        .map(|(model, measured)| {
            let t = Trace::read_csv(measured)?;
            let (f, g, p) = (
                t.column("frequency").unwrap_or_default(),
                t.column("gain_db").unwrap_or_default(),
                t.column("phase_deg").unwrap_or_default(),
            );
            let pts = (0..f.len())
                .map(|i| crate::analysis::response_point::ResponsePoint {
                    frequency: f[i],
                    gain_db: g[i],
                    phase_deg: p[i],
                    quality: 1.0,
                })
                .collect();
            Ok((model.clone(), pts))
        })
        .collect::<Result<_>>()?;
    let svg = out.join("ident.svg");
    plot(&svg, &plotted)?;
    let refused = results.iter().filter(|r| r.refusal.is_some()).count();
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"axes": results, "plot": svg}))?);
        return Ok(refused == 0);
    }
    println!(
        "servo ident — M-sequence degree {} at 1 kHz on the torque at {} rad/s: {:.2} s of transients, then {} periods of {:.2} s averaged ({:.1} s per axis)",
        crate::ident::identification::DEGREE,
        crate::ident::identification::SPEED,
        crate::ident::identification::TRANSIENT_S,
        crate::ident::identification::PERIODS,
        crate::ident::identification::period_s(),
        crate::ident::identification::measurement_time_s()
    );
    for r in &results {
        let notch = r.notch.map_or("band too narrow to search for a notch".to_string(), |n| n.verdict());
        let noise = r
            .snr_db
            .map_or(String::new(), |s| format!(" (accelerometer noise {:.3e} rad/s² for {s} dB SNR)", r.noise_std));
        match (&r.model, &r.refusal) {
            (_, Some(why)) => println!("  {}: REFUSED: {why}; {notch}{noise}", r.axis),
            (Some(m), None) => match (m.anti_resonance, m.resonance) {
                (Some(z), p) => println!(
                    "  {}: anti-resonance {:.3} Hz{}, damping {:.4}{}; resonance {}; gain {:.4e}; fit band {:.1}–{:.1} Hz, rms fit error {:.1} %; {notch}{noise}",
                    m.axis,
                    z.hz,
                    m.anti_resonance_error.map_or(String::new(), |e| format!(" ± {:.2} %", e.frequency * 100.0)),
                    z.damping,
                    m.anti_resonance_error.map_or(String::new(), |e| format!(" ± {:.0} %", e.damping * 100.0)),
                    p.map_or("-".into(), |p| format!("{:.2} Hz, damping {:.4}", p.hz, p.damping)),
                    m.gain,
                    m.band.0,
                    m.band.1,
                    m.fit_error * 100.0,
                ),
                (None, _) => println!(
                    "  {}: {} (rigid axis, N = 1): {}; gain {:.4e}{noise}",
                    m.axis,
                    r.notch.filter(|_| r.undetermined.is_none()).map_or("no clear anti-resonance".to_string(), |n| n.none_clear()),
                    r.undetermined.as_deref().unwrap_or(&notch),
                    m.gain
                ),
            },
            (None, None) => {}
        }
        for f in &r.files {
            println!("    → {}", f.display());
        }
    }
    println!("  → {}", svg.display());
    if refused > 0 {
        println!("  {refused} axis/axes refused: no model written for them");
    }
    Ok(refused == 0)
}

/// `servo ident --device`: one axis on the drive, beside its FMU twin.
fn ident_on_device(
    args: &IdentArgs,
    fmu: &Fmu,
    parameters: &std::collections::BTreeMap<String, std::collections::BTreeMap<String, crate::fmu::scenario::Value>>,
    out: &std::path::Path,
) -> Result<bool> {
    use crate::ident::device::{identify_on_device, DeviceIdentRequest};
    let axis = args.axis.clone().unwrap_or_else(|| args.axes.first().cloned().unwrap_or_else(|| "x".into()));
    let axis_parameters = parameters
        .get(&axis)
        .ok_or_else(|| anyhow::anyhow!("--axis {axis}: no such axis in --axes {}", args.axes.join(",")))?;
    if !(args.amplitude.is_finite() && args.amplitude > 0.0) {
        bail!("--amplitude must be a positive torque (N·m)");
    }
    // Checked before the port is opened: the run's parameters and the sweep's settings.
    crate::ident::device::device_run(axis_parameters, args.amplitude)?.drive_params()?;
    let port = args.target.device.as_deref().unwrap_or_default();
    let Some(mut session) = args.target.session()? else {
        return Ok(false);
    };
    let pb = progress_bar("identification", args.common.json);
    let request = DeviceIdentRequest { axis: &axis, parameters: axis_parameters, amplitude: args.amplitude };
    let r = identify_on_device(
        &*fmu.as_twin_of(&session.params_for_twin()?)?,
        &request,
        (port, &mut session),
        out,
        |label, f| {
            pb.set_prefix(label.to_string());
            pb.set_position((f * 1000.0) as u64)
        },
    )?;
    pb.finish_and_clear();
    if args.common.json {
        println!("{}", serde_json::to_string_pretty(&r)?);
    } else {
        r.print();
    }
    // As on the FMU: a refused fit is a failure; so is a drive that disagrees with its twin.
    Ok(r.drive.refusal.is_none() && r.passed)
}

impl IdentBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_ident(self)
    }
}

fn bench_ident(args: &IdentBenchArgs) -> Result<bool> {
    let common = &args.common;
    use crate::ident::identification::{absorber_parameters, true_anti_resonance, AxisModel};
    use crate::ident::tuning::{circle_check, tune, Method};
    let selection = selected_absorbers(args)?;
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let out = common.out.clone().unwrap_or_else(|| default_out("bench/ident"));
    if let Some(absorbers) = selection {
        return bench_ident_grid_alone(args, &fmu, &out, &absorbers);
    }
    let load = configuration(&Default::default())?.plant.load_inertia;
    // (case, [(axis, anti-resonance in Hz or none)])
    type Axes<'a> = Vec<(&'a str, Option<f64>)>;
    let cases: Vec<(&str, Axes)> = vec![
        ("two axes", vec![("x", Some(40.0)), ("y", Some(70.0))]),
        ("three axes", vec![("x", Some(40.0)), ("y", Some(70.0)), ("z", Some(55.0))]),
        ("rigid axis", vec![("w", None)]),
    ];
    let mut rows = Vec::new();
    let mut tunings = Vec::new();
    let (mut spreads, mut roundness) = (Vec::new(), None);
    let pb = progress_bar("ident bench", common.json);
    // The grid: every anti-resonance × every noise seed at 20 dB SNR.
    pb.set_prefix("grid");
    let grid =
        crate::ident::bench::run_grid(&fmu, &out, &crate::ident::bench::GRID_HZ, args.damping, args.seeds, |x| {
            pb.set_position((x * 800.0) as u64)
        })?;
    let record_bands = [(5.0, 8.0), (8.0, 15.0), (15.0, 25.0), (25.0, 100.0), (100.0, 300.0), (300.0, 500.0)];
    let record = crate::ident::bench::record_check(&fmu, 15.0, &record_bands)?;
    let mut ok = grid.iter().all(|c| c.passed());
    pb.set_prefix("tuning");
    let total: usize = cases.iter().map(|c| c.1.len()).sum::<usize>() + 5;
    let mut done = 0;
    let mut tick = |pb: &indicatif::ProgressBar| {
        pb.set_position((800 + done * 200 / total) as u64);
        done += 1;
    };
    for (case, axes) in &cases {
        let mut models: Vec<AxisModel> = Vec::new();
        for (axis, hz) in axes {
            tick(&pb);
            let params = hz.map(|h| absorber_parameters(h, 0.05, load)).unwrap_or_default();
            let r = crate::ident::report::identify_axis(
                &fmu,
                axis,
                &params,
                0.05,
                Some(20.0),
                &out.join(case.replace(' ', "_")),
            )?;
            let Some(model) = r.model else {
                bail!("axis {axis} of `{case}`: {}", r.refusal.unwrap_or_default());
            };
            let truth = hz.map(|h| {
                let w = std::f64::consts::TAU * h;
                true_anti_resonance(load, load * w * w, 2.0 * 0.05 * load * w)
            });
            let (f_err, d_err) = match (truth, model.anti_resonance) {
                (Some(t), Some(z)) => ((z.hz - t.hz) / t.hz, (z.damping - t.damping) / t.damping),
                (None, None) => (0.0, 0.0),
                _ => (f64::INFINITY, f64::INFINITY),
            };
            ok &= f_err.abs() <= 0.01 && d_err.abs() <= 0.2;
            rows.push(serde_json::json!({"case": case, "axis": axis, "truth": truth, "model": model, "notch": r.notch, "frequency_error": f_err, "damping_error": d_err}));
            models.push(model);
        }
        if models.len() < 2 {
            continue;
        }
        // Correction of the identified axes, measured form and the seed as written.
        tick(&pb);
        let response = tune(&fmu, &models, Method::Response, true, |_| {})?;
        tick(&pb);
        let zeros = tune(&fmu, &models, Method::Zeros, true, |_| {})?;
        let circle = if *case == "two axes" {
            tick(&pb);
            Some(circle_check(&fmu, &response, CIRCLE_RADIUS, CIRCLE_HZ, CIRCLE_LEAD_IN)?)
        } else {
            None
        };
        let (b, a) = (response.spread_before.unwrap_or_default(), response.spread_after.unwrap_or_default());
        ok &= a.0 < b.0 && a.1 < b.1;
        spreads.push((case.to_string(), b, a));
        if let Some(c) = &circle {
            ok &= c.roundness_without / c.roundness_with >= 20.0;
            roundness = Some(c.roundness_without / c.roundness_with);
        }
        tunings.push(serde_json::json!({"case": case, "response": response, "zeros": zeros, "circle": circle}));
    }
    pb.finish_and_clear();
    let mut figures = record_grid("ident", &grid, args.seeds);
    let demo_worst =
        |key: &str| rows.iter().map(|r| r[key].as_f64().unwrap_or(f64::INFINITY).abs()).fold(0.0, f64::max);
    figures
        .at_most(
            "demo axes (two, three and a rigid axis): worst |frequency error|",
            100.0 * demo_worst("frequency_error"),
            1.0,
            "%",
        )
        .at_most("demo axes: worst |damping error|", 100.0 * demo_worst("damping_error"), 20.0, "%");
    for (case, before, after) in &spreads {
        figures
            .at_most(
                &format!("{case}: command → machine-end responses apart after the correction, up to the position-loop bandwidth (gain)"),
                after.0,
                before.0,
                "dB",
            )
            .at_most("phase (goal: less than uncorrected)", after.1, before.1, "°");
    }
    if let Some(r) = roundness {
        figures.at_least(
            &format!("the two axes' {CIRCLE_HZ} Hz circle: times rounder than uncorrected (machine end)"),
            r,
            20.0,
            "×",
        );
    }
    figures.write(common.out.as_deref(), ok)?;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"bench": "ident", "damping": args.damping, "seeds": args.seeds, "grid": grid, "record": record, "measurement_time_s": crate::ident::identification::measurement_time_s(), "rows": rows, "tunings": tunings, "passed": ok})
            )?
        );
        return Ok(ok);
    }
    print_grid(&grid, Some(&record), args.seeds, args.damping);
    println!("  demo axes:");
    println!(
        "  {:<11} {:<5} {:>12} {:>12} {:>12} {:>12} {:>10} {:>10}",
        "case", "axis", "true Hz", "found Hz", "true ζ", "found ζ", "Hz err %", "ζ err %"
    );
    for r in &rows {
        let t = &r["truth"];
        let m = &r["model"]["anti_resonance"];
        let num = |v: &serde_json::Value, k: &str| {
            v.get(k).and_then(|x| x.as_f64()).map_or("-".to_string(), |x| format!("{x:.4}"))
        };
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
    println!("  goal: at most 1 % in frequency and 20 % in damping");
    println!("  largest difference between the axes' command → machine-end responses up to the position-loop bandwidth (friction off; controllers alike):");
    let pair = |v: &serde_json::Value| {
        format!("{:.4} dB / {:.3}°", v[0].as_f64().unwrap_or(f64::NAN), v[1].as_f64().unwrap_or(f64::NAN))
    };
    for t in &tunings {
        let (r, z) = (&t["response"], &t["zeros"]);
        println!(
            "    {:<10} before {}   after, measured models (default) {}   after, seed's F·Π N_other {}",
            t["case"].as_str().unwrap_or(""),
            pair(&r["spread_before"]),
            pair(&r["spread_after"]),
            pair(&z["spread_after"])
        );
        if let Some(c) = t["circle"].as_object() {
            let (w, c2) =
                (c["roundness_without"].as_f64().unwrap_or(f64::NAN), c["roundness_with"].as_f64().unwrap_or(f64::NAN));
            println!(
                "    XY circle of x and y, radius {} rad at {} Hz (the position-loop bandwidth), machine-end roundness: without {:.3e} rad, with {:.3e} rad: {:.1}× smaller (goal 20×)",
                CIRCLE_RADIUS, CIRCLE_HZ, w, c2, w / c2
            );
        }
    }
    println!("  {}", if ok { "all goals met" } else { "a goal is NOT met" });
    Ok(ok)
}

/// The anti-resonances `--absorber` or `--random` chose (None: the shipped grid), checked:
/// each a finite frequency inside the band the response is measured over.
fn selected_absorbers(args: &IdentBenchArgs) -> Result<Option<Vec<f64>>> {
    if !(args.damping > 0.0 && args.damping < 1.0) {
        bail!("--damping {}: an absorber's damping ratio lies between 0 and 1 (exclusive)", args.damping);
    }
    let mut absorbers = match args.random {
        Some(n) => crate::ident::bench::random_absorbers(n, args.plant_seed),
        None if args.absorbers.is_empty() => return Ok(None),
        None => args.absorbers.clone(),
    };
    let (lo, hi) = crate::ident::report::BAND;
    if let Some(bad) = absorbers.iter().find(|hz| !(**hz >= lo && **hz <= hi)) {
        bail!(
            "--absorber {bad}: the anti-resonance must lie in the measured band, {lo}–{hi} Hz (the goals cover {}–{} Hz)",
            crate::ident::bench::RANGE_HZ.0,
            crate::ident::bench::RANGE_HZ.1
        );
    }
    absorbers.sort_by(f64::total_cmp);
    absorbers.dedup();
    Ok(Some(absorbers))
}

/// `servo bench ident --absorber …` or `--random N`: those anti-resonances × the noise seeds,
/// without the demo axes and the correction; true when every identification meets the goals.
fn bench_ident_grid_alone(args: &IdentBenchArgs, fmu: &Fmu, out: &std::path::Path, absorbers: &[f64]) -> Result<bool> {
    let pb = progress_bar("ident bench", args.common.json);
    pb.set_prefix("grid");
    let grid = crate::ident::bench::run_grid(fmu, out, absorbers, args.damping, args.seeds, |x| {
        pb.set_position((x * 1000.0) as u64)
    })?;
    pb.finish_and_clear();
    let ok = grid.iter().all(|c| c.passed());
    record_grid("ident-grid", &grid, args.seeds).write(args.common.out.as_deref(), ok)?;
    if args.common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"bench": "ident", "absorbers_hz": absorbers, "random": args.random, "plant_seed": args.random.map(|_| args.plant_seed), "seeds": args.seeds, "damping": args.damping, "grid": grid, "measurement_time_s": crate::ident::identification::measurement_time_s(), "passed": ok})
            )?
        );
        return Ok(ok);
    }
    if let Some(n) = args.random {
        println!(
            "  {} anti-resonances ({n} drawn at random, plant seed {}, repeats run once): cases the project does not ship",
            absorbers.len(),
            args.plant_seed
        );
    }
    print_grid(&grid, None, args.seeds, args.damping);
    println!("  goal: at most 1 % in frequency and 20 % in damping: {}", if ok { "met" } else { "MISSED" });
    Ok(ok)
}

/// The identification grid's figures: the worst errors over the anti-resonances found and the
/// identifications outside the goals.
fn record_grid(bench: &str, grid: &[crate::ident::bench::GridCase], seeds: u32) -> crate::bench::figures::Recorder {
    use crate::ident::bench::{DAMPING_GOAL, FREQUENCY_GOAL, SNR_DB};
    let worst = |key: fn(&crate::ident::bench::GridCase) -> f64| {
        grid.iter().filter(|c| c.found.is_some()).map(|c| key(c).abs()).fold(0.0, f64::max)
    };
    let (lo, hi) = grid.iter().fold((f64::INFINITY, 0.0f64), |(a, b), c| (a.min(c.hz), b.max(c.hz)));
    let mut figures = crate::bench::figures::Recorder::new(bench);
    figures
        .at_most(
            &format!(
                "anti-resonance identification, {lo}–{hi} Hz × {seeds} noise seeds at {SNR_DB} dB SNR: worst |frequency error|"
            ),
            100.0 * worst(|c| c.frequency_error),
            100.0 * FREQUENCY_GOAL,
            "%",
        )
        .at_most("worst |damping error|", 100.0 * worst(|c| c.damping_error), 100.0 * DAMPING_GOAL, "%")
        .equal(
            "identifications outside the goals (a wrong value, or none where no mode masks the zero)",
            grid.iter().filter(|c| !c.passed()).count() as f64,
            0.0,
            "",
        );
    figures
}

/// The grid's table: per anti-resonance, each seed's errors; then the worst case.
fn print_grid(
    grid: &[crate::ident::bench::GridCase],
    record: Option<&crate::ident::bench::RecordCheck>,
    seeds: u32,
    damping: f64,
) {
    use crate::ident::bench::SNR_DB;
    use crate::ident::identification::{measurement_time_s, period_s, PERIODS, TRANSIENT_S};
    println!(
        "servo bench ident — seed 001: absorbers {}–{} Hz (damping {damping}) × {seeds} noise seeds, accelerometer noise at {SNR_DB} dB SNR of the record",
        grid.first().map_or(0.0, |c| c.hz),
        grid.last().map_or(0.0, |c| c.hz)
    );
    println!(
        "  measurement per axis: {TRANSIENT_S} s of transients + {PERIODS} periods of {:.2} s averaged = {:.1} s (was 0.5 s + one period = 2.55 s)",
        period_s(),
        measurement_time_s()
    );
    println!("  frequency error % / damping error % per seed:");
    let mut hz: Vec<f64> = grid.iter().map(|c| c.hz).collect();
    hz.dedup();
    for f in &hz {
        let row: Vec<&crate::ident::bench::GridCase> = grid.iter().filter(|c| c.hz == *f).collect();
        let cells: Vec<String> = row.iter().map(|c| format!("{:>11}", c.outcome())).collect();
        let masked = row
            .first()
            .filter(|c| c.masked_by_plant())
            .map_or(String::new(), |c| format!("   (the plant's own notch {:.1} dB: not clear)", c.plant_notch_db));
        println!("  {f:>6.1} Hz {}{masked}", cells.join(""));
    }
    // Over the anti-resonances found (a case without one has no error to rank).
    let worst = |key: fn(&crate::ident::bench::GridCase) -> f64| {
        grid.iter().filter(|c| c.found.is_some()).max_by(|a, b| key(a).abs().total_cmp(&key(b).abs()))
    };
    let describe = |c: Option<&crate::ident::bench::GridCase>, v: fn(&crate::ident::bench::GridCase) -> f64| {
        c.map_or("-".to_string(), |c| {
            let why = match (&c.refusal, c.found, c.notch) {
                (Some(r), _, _) => format!(" (refused: {r})"),
                (None, None, Some(n)) => format!(" (no clear anti-resonance: {})", n.verdict()),
                _ => String::new(),
            };
            format!("{:.2} % at {} Hz, seed {}{why}", v(c) * 100.0, c.hz, c.seed)
        })
    };
    println!(
        "  worst frequency error over the grid: {} (goal 1 %)",
        describe(worst(|c| c.frequency_error), |c| c.frequency_error)
    );
    println!(
        "  worst damping error over the grid:   {} (goal 20 %)",
        describe(worst(|c| c.damping_error), |c| c.damping_error)
    );
    let masked: Vec<&crate::ident::bench::GridCase> = grid.iter().filter(|c| c.masked_by_plant()).collect();
    if !masked.is_empty() {
        let count = |p: fn(&crate::ident::bench::GridCase) -> bool| masked.iter().filter(|c| p(c)).count();
        println!(
            "  where the plant's own notch is under {} dB (a resonance masks the anti-resonance or the absorber's damping flattens it; {} identifications): {} found within the goals, {} off, {} undetermined (the refits' spread), {} refused, {} without a clear notch",
            crate::ident::bench::MASKED_NOTCH_DB,
            masked.len(),
            count(|c| c.found.is_some() && c.passed()),
            count(|c| c.found.is_some() && !c.passed()),
            count(|c| c.undetermined.is_some()),
            count(|c| c.refusal.is_some()),
            count(|c| c.found.is_none() && c.refusal.is_none() && c.undetermined.is_none()),
        );
    }
    let missed = grid.iter().filter(|c| !c.passed()).count();
    println!("  identifications missing a goal: {missed} of {} (found off the goals, or none found where the plant shows its notch)", grid.len());
    let Some(record) = record else { return };
    println!(
        "  the record against the analytic plant, noise-free, {} Hz absorber, damping {} (largest relative error; point samples / means over each acquisition period):",
        record.hz,
        crate::ident::bench::DAMPING
    );
    for ((lo, hi), point, mean) in &record.bands {
        println!("    {lo:>5.0}–{hi:<5.0} Hz: {:>8.2} % / {:>6.2} %", point * 100.0, mean * 100.0);
    }
}

/// The bench's circle: at the position-loop bandwidth, where the axes differ most in band;
/// 30 revolutions (1.5 s) of lead-in let the lightly damped closed-loop poles settle.
const CIRCLE_RADIUS: f64 = 0.05;
const CIRCLE_HZ: f64 = 20.0;
const CIRCLE_LEAD_IN: u32 = 30;

impl TuneArgs {
    pub fn run(&self) -> Result<bool> {
        tune(self)
    }
}

fn tune(args: &TuneArgs) -> Result<bool> {
    let (models, method, no_check, common) = (&args.models, args.method.as_str(), args.no_check, &args.common);
    use crate::ident::identification::AxisModel;
    use crate::ident::tuning::Method;
    let method: Method = method.parse()?;
    let out = common.out.clone().unwrap_or_else(|| default_out("tune"));
    let models: Vec<AxisModel> = models.iter().map(|p| AxisModel::load(p)).collect::<Result<_>>()?;
    crate::paths::create_out_dir(&out)?;
    if args.axis.is_some() && args.target.device.is_none() {
        bail!("--axis chooses the axis a drive gets: add --device PORT");
    }
    if let Some(name) = &args.axis {
        if !models.iter().any(|m| &m.axis == name) {
            let names: Vec<&str> = models.iter().map(|m| m.axis.as_str()).collect();
            bail!("--axis {name}: the models are of axes {} (one drive is one axis)", names.join(", "));
        }
    }
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("tune", common.json);
    // With --device the tuning's runs on the models are the drive's twin's, as its check's:
    // the drive's commissioned motor and current loop, read from it first.
    let mut session = args.target.session()?;
    let drive = session.as_mut().map(|s| s.params_for_twin()).transpose()?;
    let twin = drive.as_ref().map(|d| fmu.as_twin_of(d)).transpose()?;
    let tuning =
        crate::ident::tuning::tune(&fmu, &models, method, !no_check, |x| pb.set_position((x * 1000.0) as u64))?;
    drop(twin);
    pb.finish_and_clear();
    let mut files = crate::ident::tuning::write(&tuning, &out)?;
    let improved = match (tuning.spread_before, tuning.spread_after) {
        (Some(b), Some(a)) => a.0 < b.0 && a.1 < b.1,
        _ => true,
    };
    let device = match (session, drive) {
        (Some(session), Some(drive)) => Some(device_check(args, (&fmu, &drive), session, &tuning, &out)?),
        _ => None,
    };
    if let Some(d) = &device {
        // tune.json gets the check over the drive as its "device" section.
        let json = out.join("tune.json");
        let mut saved = serde_json::to_value(&tuning)?;
        saved["device"] = serde_json::to_value(d)?;
        std::fs::write(&json, serde_json::to_string_pretty(&saved)?)?;
        files.extend(d.without.files.iter().chain(&d.with.files).cloned());
    }
    let device_ok = device.as_ref().is_none_or(|d| d.passed);
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"tuning": tuning, "device": device, "files": files, "improved": improved})
            )?
        );
        return Ok(improved && device_ok);
    }
    tuning.print();
    if let Some(d) = &device {
        d.print();
    }
    for f in files.iter().filter(|f| f.parent() == Some(out.as_path())) {
        println!("  → {}", f.display());
    }
    if !improved {
        println!("  the correction does NOT bring the axes' responses closer");
    }
    Ok(improved && device_ok)
}

/// With --device: the chosen axis's correction loaded into the drive and checked there, the
/// FMU as the twin of the drive whose parameters are `drive`.
fn device_check(
    args: &TuneArgs,
    (fmu, drive): (&Fmu, &control_core::Params),
    mut session: crate::device::session::DriveSession<Box<dyn serialport::SerialPort>>,
    tuning: &crate::ident::tuning::Tuning,
    out: &std::path::Path,
) -> Result<crate::ident::device_check::TuneDeviceCheck> {
    use crate::ident::device_check::{check_on_device, check_request, tuned_axis};
    let port = args.target.device.as_deref().unwrap_or_default();
    let axis = tuned_axis(tuning, args.axis.as_deref())?;
    check_request(tuning, axis)?;
    let pb = progress_bar("tune on the drive", args.common.json);
    let frame = out.join(format!("{}.corr.frame", axis.axis));
    let check = check_on_device(
        &*fmu.as_twin_of(drive)?,
        tuning,
        axis,
        (port, &mut session),
        &frame,
        &out.join("device"),
        |label, f| {
            pb.set_prefix(label.to_string());
            pb.set_position((f * 1000.0) as u64)
        },
    )?;
    pb.finish_and_clear();
    Ok(check)
}
