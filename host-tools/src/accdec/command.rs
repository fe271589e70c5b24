//! `servo accdec` and `servo bench accdec` (seed 003).

use anyhow::{Context, Result};

use crate::accdec::args::{AccdecArgs, AccdecBenchArgs, AccdecProbeArgs};
use crate::cli::progress_bar;
use crate::paths::{default_fmu, default_out};

impl AccdecArgs {
    pub fn run(&self) -> Result<bool> {
        accdec(self)
    }
}

fn accdec(args: &AccdecArgs) -> Result<bool> {
    let (
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
    ) = (
        args.order,
        args.cutoff,
        args.sample_period,
        args.zeros_as_delays,
        &args.ma_lengths,
        args.distance,
        args.speed,
        args.counts_per_rev,
        &args.resonance,
        args.damping_ratio,
        &args.sweep,
        args.no_sweep,
        args.no_fmu,
        &args.common,
    );
    let cutoff = cutoff.unwrap_or_else(crate::accdec::report::default_cutoff_hz);
    let nyquist = 0.5 / sample_period;
    let sweep = match (no_sweep, sweep) {
        (true, _) => vec![],
        (false, Some(s)) => s.clone(),
        // Only the cut-offs the design accepts at this period (at least 0.5 Hz and 6e-5/T, at
        // most the Nyquist frequency): the sweep shows the design's range, it does not fail on it.
        (false, None) => [0.25, 0.5, 1.0, 2.0, 4.0]
            .iter()
            .map(|f| f * cutoff)
            .filter(|&c| {
                let spec =
                    crate::accdec::study::FilterSpec::Butterworth { order, cutoff_hz: c, all_delays: zeros_as_delays };
                c <= nyquist && spec.design(sample_period).is_ok()
            })
            .collect(),
    };
    let request = crate::accdec::report::AccDecRequest {
        order,
        cutoff_hz: cutoff,
        sample_period,
        all_delays: zeros_as_delays,
        ma_lengths: ma_lengths.clone(),
        distance_rad: distance,
        speed_rad_s: speed,
        counts_per_rev,
        resonances: resonance.iter().map(|&hz| crate::accdec::study::Resonance { hz, damping_ratio }).collect(),
        sweep,
        sweep_is_automatic: args.sweep.is_none(),
        fmu: (!no_fmu && !zeros_as_delays).then(|| common.fmu.clone().unwrap_or_else(default_fmu)),
        out: common.out.clone().unwrap_or_else(|| default_out("accdec")),
    };
    if zeros_as_delays && !no_fmu && !common.json {
        eprintln!(
            "note: --zeros-as-delays runs on the host only (the FMU's filter keeps the seed's zeros): no FMU runs"
        );
    }
    let pb = progress_bar("accdec", common.json);
    let report = crate::accdec::report::run(&request, |label, f| {
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

/// `servo bench accdec --random N`: drawn moves against the f64 filter, worst deviation.
fn bench_accdec_random(args: &AccdecBenchArgs, n: u32) -> Result<bool> {
    use crate::accdec::deviation::{random_cases_marked, run_cases};
    let marked = random_cases_marked(n, args.plant_seed);
    let cases: Vec<_> = marked.iter().map(|&(case, _)| case).collect();
    let pb = progress_bar("f64 reference, drawn moves", args.common.json);
    let rows = run_cases(&cases, |f| pb.set_position((f * 1000.0) as u64)).map_err(|e| anyhow::anyhow!("{e}"))?;
    pb.finish_and_clear();
    let worst = rows.iter().max_by(|a, b| a.worst.total_cmp(&b.worst)).context("no moves")?.clone();
    // The large, fast moves at a low cut-off × period on their own (none when N is small).
    let hard: Vec<_> = rows.iter().zip(&marked).filter(|(_, (_, h))| *h).map(|(r, _)| r).collect();
    let worst_hard = hard.iter().max_by(|a, b| a.worst.total_cmp(&b.worst)).map(|r| (*r).clone());
    let worst_lag_error = rows.iter().map(|r| r.lag_error).fold(0.0, f64::max);
    let unbalanced = rows.iter().filter(|r| r.pulse_balance != 0).count();
    let ticks: usize = rows.iter().map(|r| r.ticks).sum();
    let ok = worst.worst <= 1.0 && unbalanced == 0;
    let mut figures = crate::bench::figures::Recorder::new("accdec-random");
    figures
        .at_most(
            &format!(
                "acc/dec on {} drawn moves (seed {}), one in three large and fast at the lowest cut-off × period: worst |position − f64 filter|",
                crate::bench::figures::number(rows.len() as f64),
                args.plant_seed
            ),
            worst.worst,
            1.0,
            "count",
        )
        .equal("moves whose pulses out differ from the pulses in", unbalanced as f64, 0.0, "")
        .info("worst lag error before rounding to whole pulses", worst_lag_error, "count");
    if let Some(h) = &worst_hard {
        figures.info("worst of the large, fast moves", h.worst, "count");
    }
    figures.write(args.common.out.as_deref(), ok)?;
    if args.common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "bench": "accdec", "random": n, "plant_seed": args.plant_seed, "runs": rows.len(), "ticks": ticks,
                "worst": worst, "hard_runs": hard.len(), "worst_hard": worst_hard,
                "worst_lag_error": worst_lag_error, "unbalanced_runs": unbalanced, "passed": ok
            }))?
        );
        return Ok(ok);
    }
    println!(
        "servo bench accdec --random — {n} moves drawn with seed {} (two in three: order 1-6, period 0.125-2 ms, cut-off 0.5 Hz to a quarter of the rate, 1-10^9 counts, step/rectangle/trapezoid of 1 ms-2 s; one in three large and fast at a low cut-off x period: order 4-6, period 5 us-0.25 ms, cut-off from the design's minimum (0.5 Hz and {} / period) to {} times it, 10^6-2x10^9 counts, step/rectangle/trapezoid of 0.1 ms-0.2 s): cases the project does not ship",
        args.plant_seed,
        control_core::acc_dec::MIN_CUTOFF_TIMES_PERIOD,
        crate::accdec::deviation::hard::CUTOFF_SPAN
    );
    println!("  {} ticks; output sum != input sum in {unbalanced} of them", ticks);
    println!(
        "  worst |position - reference position|: {:.4} counts (goal <= 1: {}) at order {}, {} Hz, T = {:.3} ms, {} counts, {}, tick {}",
        worst.worst,
        if worst.worst <= 1.0 { "met" } else { "MISSED" },
        worst.order,
        worst.cutoff_hz,
        worst.sample_period * 1e3,
        worst.distance,
        worst.profile.label(),
        worst.worst_tick
    );
    if let Some(h) = &worst_hard {
        println!(
            "  of them {} large and fast at a low cut-off x period: worst {:.4} counts at order {}, {} Hz, T = {:.4} ms (cut-off x period {:.3e}), {} counts, {}, tick {}",
            hard.len(),
            h.worst,
            h.order,
            h.cutoff_hz,
            h.sample_period * 1e3,
            h.cutoff_hz as f64 * h.sample_period as f64,
            h.distance,
            h.profile.label(),
            h.worst_tick
        );
    }
    println!("  worst lag error before rounding to whole pulses: {worst_lag_error:.2e} counts");
    Ok(ok)
}

impl AccdecBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_accdec(self)
    }
}

fn bench_accdec(args: &AccdecBenchArgs) -> Result<bool> {
    if let Some(n) = args.random {
        return bench_accdec_random(args, n);
    }
    let (sequences, resonance, no_cost, common) = (args.sequences, &args.resonance, args.no_cost, &args.common);
    use crate::accdec::bench as b;
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
    pb.set_prefix("f64 reference grid");
    pb.set_position(350);
    let grid = crate::accdec::deviation::run_grid(|f| pb.set_position(350 + (f * 250.0) as u64))
        .map_err(|e| anyhow::anyhow!("{e}"))?;
    let worst_position = grid.iter().max_by(|a, b| a.worst.total_cmp(&b.worst)).context("an empty grid")?.clone();
    let worst_lag_error = grid.iter().max_by(|a, b| a.lag_error.total_cmp(&b.lag_error)).context("grid")?.clone();
    let largest_state = grid.iter().map(|r| r.largest_state).fold(0.0, f64::max);
    let unbalanced = grid.iter().filter(|r| r.pulse_balance != 0).count();
    let grid_ticks: usize = grid.iter().map(|r| r.ticks).sum();
    pb.set_prefix("FMU vibration");
    pb.set_position(600);
    let vibration = b::equal_delay_vibration(&fmu_path, resonance, false)?;
    let vibration_t50 = b::equal_delay_vibration(&fmu_path, resonance, true)?;
    pb.set_prefix("instruction count");
    pb.set_position(700);
    let costs = if no_cost { vec![] } else { b::filter_costs()? };
    pb.finish_and_clear();
    let worst = |f: fn(&b::MatchedComparison) -> f64| matched.iter().map(f).fold(0.0, f64::max);
    let (pole, den, gd, gs) = (
        worst(|m| m.pole_error),
        worst(|m| m.denominator_error),
        worst(|m| m.all_delays_gain_error),
        worst(|m| m.seed_gain_error),
    );
    let ok = digits.iter().all(|d| d.equal)
        && pole < 1e-7
        && gd < 1e-10
        && gs < 1e-10
        && props.conservation_failures == 0
        && props.zero_input_nonzero_outputs == 0
        && worst_position.worst <= 1.0
        && unbalanced == 0;
    crate::bench::figures::Recorder::new("accdec")
        .at_most(
            &format!(
                "acc/dec commanded position vs the f64 filter, {} moves of the grid: worst |error|",
                crate::bench::figures::number(grid.len() as f64)
            ),
            worst_position.worst,
            1.0,
            "count",
        )
        .equal("moves whose pulses out differ from the pulses in", unbalanced as f64, 0.0, "")
        .equal("random whole-pulse sequences: output sum ≠ input sum", props.conservation_failures as f64, 0.0, "")
        .equal(
            "the seed example's printed digits that differ",
            digits.iter().filter(|d| !d.equal).count() as f64,
            0.0,
            "",
        )
        .at_most("poles against python-control's matched method: largest error", pole, 1e-7, "")
        .info("worst lag error before rounding to whole pulses", worst_lag_error.lag_error, "count")
        .write(common.out.as_deref(), ok)?;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "bench": "accdec", "seed_digits": digits, "seed_test": seed_test, "matched": matched, "properties": props,
                "equal_delay_vibration": [vibration, vibration_t50], "costs": costs,
                "reference_grid": {"runs": grid.len(), "ticks": grid_ticks, "worst": worst_position,
                    "worst_lag_error": worst_lag_error, "largest_state_counts": largest_state,
                    "unbalanced_runs": unbalanced},
                "passed": ok
            }))?
        );
        return Ok(ok);
    }
    println!("servo bench accdec — seed 003");
    println!("  1. seed example, 3rd order, 1 kHz, 0.5 ms (printed digits):");
    for d in &digits {
        println!(
            "     {:<20} seed {:>11}  ours {:>13.8}  {}",
            d.name,
            d.printed,
            d.ours,
            if d.equal { "equal" } else { "DIFFERENT" }
        );
    }
    for (cutoff, out) in &seed_test {
        println!(
            "     seed's test, 100 pulses x 30 samples, {cutoff} Hz: {} pulses out over {} samples: {}",
            out.iter().sum::<i64>(),
            out.len(),
            out.iter().map(i64::to_string).collect::<Vec<_>>().join(" ")
        );
    }
    println!(
        "  2. against python-control sample_system(method='matched'), orders 1-6 at {} (Hz, s):",
        b::MATCHED_CASES.map(|(c, t)| format!("{c}/{t}")).join(", ")
    );
    println!("     largest pole error |z - z_py|            {pole:.2e}");
    println!("     largest denominator coefficient error    {den:.2e}");
    println!(
        "     gain, every zero at infinity a delay: K = A(1), relative error {gd:.2e}  (python-control's convention)"
    );
    println!("     gain, seed: N-1 zeros at z = -1 + one delay: K·2^(N-1) = A(1), relative error {gs:.2e}");
    println!("     (same poles; the seed's form answers one tick after the input and nulls Nyquist, python-control's waits N ticks)");
    println!("  3. properties of the whole-pulse filters (random Butterworth 1-6 / moving-average cascades):");
    println!("     {} random sequences: {} with output sum != input sum", props.sequences, props.conservation_failures);
    println!(
        "     {} ticks of zero input: {} non-zero outputs",
        props.zero_input_ticks, props.zero_input_nonzero_outputs
    );
    println!(
        "  4. commanded position against the same filter in f64 (control_core::acc_dec::reference), at every tick until settled:"
    );
    println!(
        "     grid: orders 1-6 x cut-offs {} Hz and a quarter of the sampling rate (up to it) x periods {} ms x moves ±{} counts x {}",
        crate::accdec::deviation::CUTOFFS_HZ.map(|c| c.to_string()).join(", "),
        crate::accdec::deviation::PERIODS.map(|t| (t * 1e3).to_string()).join(", "),
        crate::accdec::deviation::DISTANCES.map(|d| d.to_string()).join(", "),
        crate::accdec::deviation::PROFILES.map(|p| p.label()).join(", ")
    );
    println!("     {} runs, {} ticks; output sum != input sum in {} of them", grid.len(), grid_ticks, unbalanced);
    let describe = |r: &crate::accdec::deviation::Deviation| {
        format!(
            "order {}, {} Hz, T = {} ms, {} counts, {}, tick {} (reference lag there {:.4e} counts)",
            r.order,
            r.cutoff_hz,
            r.sample_period * 1e3,
            r.distance,
            r.profile.label(),
            r.worst_tick,
            r.lag_then
        )
    };
    println!(
        "     worst |position - reference position|: {:.4} counts (goal <= 1: {}) at {}",
        worst_position.worst,
        if worst_position.worst <= 1.0 { "met" } else { "NOT met" },
        describe(&worst_position)
    );
    println!(
        "     worst lag error before rounding to whole pulses: {:.2e} counts (order {}, {} Hz, T = {} ms, {} counts, {})",
        worst_lag_error.lag_error,
        worst_lag_error.order,
        worst_lag_error.cutoff_hz,
        worst_lag_error.sample_period * 1e3,
        worst_lag_error.distance,
        worst_lag_error.profile.label()
    );
    println!("     largest state of the drive's filter: {largest_state:.4e} counts (saturates at 2^31 = 2.147e9)");
    println!("  5. residual load vibration (peak shaft twist after end of interpolation + 99 % delay; 2 rad at 50 rad/s, 2 % damping, friction off):");
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
        println!("  6. cost per tick (x86-64 instructions, valgrind; the probe's own input generation subtracted):");
        for c in &costs {
            println!("     {:<22} {:>7.1}", c.filter, c.instructions_per_tick);
        }
    }
    println!(
        "  checks (seed digits, poles < 1e-7, gains < 1e-10, conservation, zero in -> zero out, position within 1 count of the f64 filter): {}",
        if ok { "pass" } else { "FAIL" }
    );
    Ok(ok)
}

impl AccdecProbeArgs {
    pub fn run(&self) -> Result<bool> {
        crate::accdec::bench::cost_probe(&self.filter, self.ticks).map(|s| {
            println!("{s}");
            true
        })
    }
}
