//! `servo accdec`: design a Butterworth acc/dec filter, compare it with cascaded moving
//! averages on the same move, measure both on the FMU's two-inertia load, sweep the cut-off.

use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use serde::Serialize;

use crate::accdec::study::{
    delay, matching_moving_average, position_period_parameters, profile, residual_vibration, Delay, FilterSpec,
    NoEqualDelay, PulseMove, Resonance, ShapeFigures, Vibration,
};
use crate::fmu::runner::Fmu;
use crate::fmu::trace::Trace;
use crate::plot::signals::{plot_against, plot_signals};

/// Everything `servo accdec` is asked.
#[derive(Clone, Debug)]
pub struct AccDecRequest {
    pub order: u32,
    pub cutoff_hz: f32,
    pub sample_period: f32,
    pub all_delays: bool,
    /// Moving-average lengths; None: three stages matched to the Butterworth's 99 % delay.
    pub ma_lengths: Option<Vec<u32>>,
    pub distance_rad: f64,
    pub speed_rad_s: f64,
    pub counts_per_rev: u32,
    pub resonances: Vec<Resonance>,
    /// Cut-offs of the trade-off sweep (Hz); empty: no sweep.
    pub sweep: Vec<f32>,
    /// The sweep's cut-offs were chosen automatically: one where no moving-average cascade
    /// within the drive's limit has the Butterworth's delay is left out (and named) instead
    /// of refused.
    pub sweep_is_automatic: bool,
    /// FMU for the residual-vibration runs; None: skip them.
    pub fmu: Option<PathBuf>,
    pub out: PathBuf,
}

#[derive(Clone, Debug, Serialize)]
pub struct Design {
    pub numerator: Vec<f64>,
    pub denominator: Vec<f64>,
    /// Poles (re, im) in z.
    pub poles: Vec<(f64, f64)>,
    /// Pole pairs as the drive runs them: (a1, a2, 1 + a1 + a2, 1 − a2); the real pole (p, 1 − p).
    pub sections: Vec<[f64; 4]>,
    pub real_pole: Option<[f64; 2]>,
}

#[derive(Clone, Debug, Serialize)]
pub struct FilterResult {
    pub filter: FilterSpec,
    pub label: String,
    pub delay: Delay,
    /// Shape of the move (rad, s).
    pub shape: ShapeFigures,
}

#[derive(Clone, Debug, Serialize)]
pub struct SweepPoint {
    pub cutoff_hz: f32,
    pub moving_average: String,
    pub butterworth_t99: f64,
    pub moving_average_t99: f64,
    pub butterworth_peak_jerk: f64,
    pub moving_average_peak_jerk: f64,
    /// Per resonance: (Hz, Butterworth residual, moving-average residual) in rad.
    pub residuals: Vec<(f64, f64, f64)>,
}

#[derive(Clone, Debug, Serialize)]
pub struct AccDecReport {
    pub sample_period: f32,
    pub move_counts: PulseMove,
    pub design: Design,
    pub butterworth: FilterResult,
    pub moving_average: FilterResult,
    /// Whether the moving averages' 99 % delay is the Butterworth's (to one tick): without
    /// --ma-lengths unless no cascade within the drive's limit is that long; with them, as
    /// they happen to be.
    pub equal_delay: bool,
    /// Why not, when not.
    pub unequal_delay: Option<String>,
    pub vibration: Vec<Vibration>,
    pub sweep: Vec<SweepPoint>,
    /// Automatic sweep cut-offs left out, with the reason.
    pub sweep_left_out: Vec<String>,
    pub files: Vec<PathBuf>,
}

/// Default cut-off: twice the position loop's bandwidth (`kp/2π`), the seed's rule.
pub fn default_cutoff_hz() -> f32 {
    let p = control_core::Params::default();
    2.0 * p.position.kp / control_core::TAU
}

fn design_of(spec: &FilterSpec, period: f32) -> Result<Design> {
    let d = spec.design(period)?.context("not a Butterworth")?;
    let n = d.order as usize;
    Ok(Design {
        numerator: d.numerator()[..=n].to_vec(),
        denominator: d.denominator()[..=n].to_vec(),
        poles: d.poles().collect(),
        sections: d.pole_pairs().iter().map(|p| [p.a1, p.a2, p.dc, p.one_minus_a2]).collect(),
        real_pole: d.real_pole().map(|r| [r.pole, r.one_minus_pole]),
    })
}

fn pulse_move(r: &AccDecRequest) -> Result<PulseMove> {
    if !(r.distance_rad.is_finite() && r.distance_rad != 0.0) {
        bail!("--distance must be a non-zero number of radians (got {})", r.distance_rad);
    }
    if !(r.speed_rad_s.is_finite() && r.speed_rad_s > 0.0) {
        bail!("--speed must be a positive number of rad/s (got {})", r.speed_rad_s);
    }
    if r.counts_per_rev < 4 {
        bail!("--counts-per-rev must be at least 4 (got {})", r.counts_per_rev);
    }
    let cpr = r.counts_per_rev as f64;
    let distance = (r.distance_rad / std::f64::consts::TAU * cpr).round() as i64;
    // The drive's own scale: f32, as `Params::counts_per_position_tick`.
    let speed = r.speed_rad_s as f32 * (r.counts_per_rev as f32 / control_core::TAU * r.sample_period);
    if speed < 1.0 {
        bail!(
            "--speed {} rad/s is less than one count per position tick; use a faster move or a finer encoder",
            r.speed_rad_s
        );
    }
    Ok(PulseMove { distance, speed })
}

fn analyse(spec: &FilterSpec, r: &AccDecRequest, m: PulseMove) -> Result<(FilterResult, Trace)> {
    let d = delay(spec, r.sample_period)?;
    let p = profile(spec, r.sample_period, m, 64)?;
    let to_rad = std::f64::consts::TAU / r.counts_per_rev as f64;
    let mut shape = p.figures();
    shape.peak_velocity *= to_rad;
    shape.peak_acceleration *= to_rad;
    shape.peak_jerk *= to_rad;
    shape.peak_jerk_pulses *= to_rad;
    Ok((FilterResult { filter: spec.clone(), label: spec.label(), delay: d, shape }, p.trace(to_rad)))
}

/// The moving averages compared: --ma-lengths, or three stages with the Butterworth's 99 %
/// delay; where the drive holds none that long, the closest, with the reason the comparison
/// is not at equal delay.
fn moving_average_for(r: &AccDecRequest, butterworth_t99: f64) -> Result<(FilterSpec, Option<String>)> {
    match &r.ma_lengths {
        Some(l) => Ok((FilterSpec::MovingAverage { lengths: l.clone() }, None)),
        None => match matching_moving_average(butterworth_t99, r.sample_period, 3) {
            Ok(spec) => Ok((spec, None)),
            Err(e) => {
                let no = e.downcast::<NoEqualDelay>()?;
                Ok((
                    no.closest.clone(),
                    Some(format!("{no} (raise --cutoff or --sample-period for one at equal delay)")),
                ))
            }
        },
    }
}

/// Start of the residual window: the interpolator's end plus the filter's 99 % delay.
fn window_start(f: &FilterResult) -> f64 {
    f.shape.interpolation_end + f.delay.t99
}

/// Time the FMU runs for: the later of arrival and window start, plus ten periods of the
/// slowest resonance (at least 0.1 s).
fn fmu_duration(results: &[&FilterResult], resonances: &[Resonance]) -> f64 {
    let start = results.iter().map(|f| f.shape.arrival.max(window_start(f))).fold(0.0, f64::max);
    let slowest = resonances.iter().map(|r| r.hz).fold(f64::INFINITY, f64::min);
    start + (10.0 / slowest).max(0.1)
}

/// The sample period: positive; with FMU runs, one the FMU's position loop can run at (a whole
/// multiple of its velocity-loop period, at most 1000 base ticks), checked with the filter's
/// parameters before anything runs.
fn check_sample_period(r: &AccDecRequest, butterworth: &FilterSpec) -> Result<()> {
    let t = r.sample_period;
    if !(t.is_finite() && t > 0.0) {
        bail!("--sample-period must be a positive number of seconds (got {t})");
    }
    if r.fmu.is_none() {
        return Ok(());
    }
    let rates = control_core::Params::default().rates;
    let fmu_accepts = || -> Result<()> {
        let mut p: std::collections::BTreeMap<String, crate::fmu::scenario::Value> =
            position_period_parameters(t as f64)?.into_iter().collect();
        p.extend(butterworth.fmu_parameters()?);
        let control = crate::fmu::configuration::configuration(&p)?.control;
        control.validate().map_err(|e| anyhow::anyhow!("{e}"))
    };
    fmu_accepts().map_err(|e| {
        anyhow::anyhow!(
            "--sample-period {t} s: the FMU runs the filter in its position loop, whose period is a whole multiple of its velocity-loop period, {:.1} µs, from {:.1} µs to {} ms ({e:#}); or give --no-fmu",
            rates.velocity_period() as f64 * 1e6,
            rates.velocity_period() as f64 * 1e6,
            1000.0 / rates.current_loop_hz as f64 * 1e3
        )
    })
}

pub fn run(r: &AccDecRequest, mut progress: impl FnMut(&str, f64)) -> Result<AccDecReport> {
    let bw_spec = FilterSpec::Butterworth { order: r.order, cutoff_hz: r.cutoff_hz, all_delays: r.all_delays };
    check_sample_period(r, &bw_spec)?;
    crate::paths::create_out_dir(&r.out)?;
    let m = pulse_move(r)?;
    let design = design_of(&bw_spec, r.sample_period)?;
    let (bw, bw_trace) = analyse(&bw_spec, r, m)?;
    let (ma_spec, unmatched) = moving_average_for(r, bw.delay.t99)?;
    let (ma, ma_trace) = analyse(&ma_spec, r, m)?;
    let equal_delay = (ma.delay.t99 - bw.delay.t99).abs() <= r.sample_period as f64 * (1.0 + 1e-6);
    let unequal_delay = (!equal_delay).then(|| {
        unmatched.unwrap_or_else(|| {
            format!(
                "the moving averages (--ma-lengths) settle in {:.3} ms, the Butterworth in {:.3} ms",
                ma.delay.t99 * 1e3,
                bw.delay.t99 * 1e3
            )
        })
    });
    let mut files = Vec::new();

    for (name, t) in [("profile_butterworth.csv", &bw_trace), ("profile_moving_average.csv", &ma_trace)] {
        let path = r.out.join(name);
        t.write_csv(&path)?;
        files.push(path);
    }
    let mut interpolator = Trace::new(vec!["time".into(), "velocity".into()]);
    for row in &bw_trace.rows {
        interpolator.rows.push(vec![row[0], row[6]]);
    }
    let path = r.out.join("profiles.svg");
    plot_signals(
        &path,
        &format!("Same move through both filters (rad/s, rad/s², rad/s³; T = {} s)", r.sample_period),
        &[(&bw.label, &bw_trace), (&ma.label, &ma_trace), ("interpolator", &interpolator)],
        &["velocity", "acceleration", "jerk"].map(String::from),
    )?;
    files.push(path);

    let fmu = r.fmu.as_deref().map(Fmu::load).transpose()?;
    let mut vibration = Vec::new();
    if let Some(fmu) = &fmu {
        let duration = fmu_duration(&[&bw, &ma], &r.resonances);
        for (i, res) in r.resonances.iter().enumerate() {
            progress("FMU moves", i as f64 / r.resonances.len() as f64);
            let mut traces = Vec::new();
            for (spec, f) in [(&bw_spec, &bw), (&ma_spec, &ma)] {
                let (v, t) = residual_vibration(
                    fmu,
                    spec,
                    *res,
                    r.sample_period as f64,
                    r.distance_rad,
                    r.speed_rad_s,
                    (window_start(f), duration),
                )?;
                vibration.push(v);
                traces.push(t);
            }
            let path = r.out.join(format!("vibration_{}hz.svg", res.hz));
            plot_signals(
                &path,
                &format!("Load after the move, {} Hz load resonance (damping ratio {})", res.hz, res.damping_ratio),
                &[(&bw.label, &traces[0]), (&ma.label, &traces[1])],
                &["command_velocity", "load_velocity", "load_error", "shaft_twist"].map(String::from),
            )?;
            files.push(path);
            for (spec, t) in [("butterworth", &traces[0]), ("moving_average", &traces[1])] {
                let path = r.out.join(format!("vibration_{}hz_{spec}.csv", res.hz));
                t.write_csv(&path)?;
                files.push(path);
            }
        }
    }

    let mut sweep = Vec::new();
    let mut sweep_left_out = Vec::new();
    for (i, &cutoff) in r.sweep.iter().enumerate() {
        progress("cut-off sweep", i as f64 / r.sweep.len() as f64);
        let b = FilterSpec::Butterworth { order: r.order, cutoff_hz: cutoff, all_delays: r.all_delays };
        let (bres, _) = analyse(&b, r, m).with_context(|| format!("sweep at {cutoff} Hz"))?;
        let a = match matching_moving_average(bres.delay.t99, r.sample_period, 3) {
            Ok(a) => a,
            Err(e) if r.sweep_is_automatic && e.downcast_ref::<NoEqualDelay>().is_some() => {
                sweep_left_out.push(format!("{cutoff} Hz: {e}"));
                continue;
            }
            Err(e) => return Err(e.context(format!("sweep at {cutoff} Hz"))),
        };
        let (ares, _) = analyse(&a, r, m)?;
        let mut residuals = Vec::new();
        if let Some(fmu) = &fmu {
            let duration = fmu_duration(&[&bres, &ares], &r.resonances);
            for res in &r.resonances {
                let period = r.sample_period as f64;
                let (vb, _) = residual_vibration(
                    fmu,
                    &b,
                    *res,
                    period,
                    r.distance_rad,
                    r.speed_rad_s,
                    (window_start(&bres), duration),
                )?;
                let (va, _) = residual_vibration(
                    fmu,
                    &a,
                    *res,
                    period,
                    r.distance_rad,
                    r.speed_rad_s,
                    (window_start(&ares), duration),
                )?;
                residuals.push((res.hz, vb.residual, va.residual));
            }
        }
        sweep.push(SweepPoint {
            cutoff_hz: cutoff,
            moving_average: ares.label,
            butterworth_t99: bres.delay.t99,
            moving_average_t99: ares.delay.t99,
            butterworth_peak_jerk: bres.shape.peak_jerk,
            moving_average_peak_jerk: ares.shape.peak_jerk,
            residuals,
        });
    }
    progress("", 1.0);
    if !sweep.is_empty() {
        files.extend(write_sweep(&r.out, &sweep)?);
    }
    let report = AccDecReport {
        sample_period: r.sample_period,
        move_counts: m,
        design,
        butterworth: bw,
        moving_average: ma,
        equal_delay,
        unequal_delay,
        vibration,
        sweep,
        sweep_left_out,
        files: files.clone(),
    };
    let path = r.out.join("accdec.json");
    std::fs::write(&path, serde_json::to_string_pretty(&report)?)?;
    Ok(AccDecReport { files: [files, vec![path]].concat(), ..report })
}

fn write_sweep(out: &Path, sweep: &[SweepPoint]) -> Result<Vec<PathBuf>> {
    let mut columns = vec![
        "cutoff_hz",
        "butterworth_t99_ms",
        "moving_average_t99_ms",
        "butterworth_peak_jerk",
        "moving_average_peak_jerk",
    ]
    .into_iter()
    .map(String::from)
    .collect::<Vec<_>>();
    // Every column is named before a trace is made: a trace's rows take its width then.
    let mut one_filter: Vec<String> = vec!["cutoff_hz".into(), "t99_ms".into(), "peak_jerk".into()];
    if let Some(p) = sweep.first() {
        for (hz, _, _) in &p.residuals {
            columns.push(format!("butterworth_residual_{hz}hz"));
            columns.push(format!("moving_average_residual_{hz}hz"));
            one_filter.push(format!("residual_{hz}hz"));
        }
    }
    let mut bw = Trace::new(one_filter);
    let mut ma = bw.clone();
    let mut all = Trace::new(columns);
    for p in sweep {
        let mut row = vec![
            p.cutoff_hz as f64,
            p.butterworth_t99 * 1e3,
            p.moving_average_t99 * 1e3,
            p.butterworth_peak_jerk,
            p.moving_average_peak_jerk,
        ];
        let mut rb = vec![p.cutoff_hz as f64, p.butterworth_t99 * 1e3, p.butterworth_peak_jerk];
        let mut rm = vec![p.cutoff_hz as f64, p.moving_average_t99 * 1e3, p.moving_average_peak_jerk];
        for (_, b, m) in &p.residuals {
            row.extend([*b, *m]);
            rb.push(*b);
            rm.push(*m);
        }
        all.rows.push(row);
        bw.rows.push(rb);
        ma.rows.push(rm);
    }
    let csv = out.join("sweep.csv");
    all.write_csv(&csv)?;
    let svg = out.join("sweep.svg");
    let signals: Vec<String> = bw.columns[1..].to_vec();
    plot_against(
        &svg,
        "Cut-off sweep: 99 % delay, peak jerk (rad/s³) and residual load vibration (rad); moving averages matched in delay",
        &[("Butterworth", &bw), ("3 x moving average", &ma)],
        "cutoff_hz",
        "Butterworth cut-off (Hz)",
        &signals,
    )?;
    Ok(vec![csv, svg])
}

impl AccDecReport {
    /// The human-readable summary.
    pub fn print(&self) {
        let d = &self.design;
        let b = &self.butterworth;
        println!("servo accdec — {} at T = {} s", b.label, self.sample_period);
        let poly = |c: &[f64]| c.iter().map(|x| format!("{x:.8}")).collect::<Vec<_>>().join(", ");
        // K is (ωc·T)^N small: scientific notation keeps its digits.
        let numerator = d.numerator.iter().map(|x| format!("{x:.9e}")).collect::<Vec<_>>().join(", ");
        println!("  numerator   b0..bN : [{numerator}]");
        println!("  denominator 1..aN  : [{}]", poly(&d.denominator));
        println!(
            "  poles (z)          : {}",
            d.poles.iter().map(|(re, im)| format!("{re:.6}{im:+.6}j")).collect::<Vec<_>>().join(", ")
        );
        for (i, s) in d.sections.iter().enumerate() {
            println!(
                "  pole pair {} a1 a2 | 1+a1+a2 1-a2 (what the drive runs) : {:.8} {:.8} | {:.6e} {:.6e}",
                i + 1,
                s[0],
                s[1],
                s[2],
                s[3]
            );
        }
        if let Some(r) = d.real_pole {
            println!("  real pole p | 1-p : {:.8} | {:.6e}", r[0], r[1]);
        }
        println!(
            "\n  move: {} counts at {:.3} counts per tick (interpolator), both filters give out exactly the pulses they take in",
            self.move_counts.distance, self.move_counts.speed
        );
        println!(
            "  {:<38} {:>9} {:>9} {:>9} {:>12} {:>12} {:>14} {:>10} {:>8}",
            "filter", "t50 ms", "t99 ms", "overshoot", "peak acc", "peak jerk", "jerk (pulses)", "arrive ms", "balance"
        );
        for f in [&self.butterworth, &self.moving_average] {
            println!(
                "  {:<38} {:>9.3} {:>9.3} {:>8.2}% {:>12.4e} {:>12.4e} {:>14.4e} {:>10.2} {:>8}",
                f.label,
                f.delay.t50 * 1e3,
                f.delay.t99 * 1e3,
                f.delay.overshoot * 100.0,
                f.shape.peak_acceleration,
                f.shape.peak_jerk,
                f.shape.peak_jerk_pulses,
                f.shape.arrival * 1e3,
                f.shape.pulse_balance
            );
        }
        println!("  (delays: response to a velocity step; rad/s² and rad/s³ of the unrounded output; jerk (pulses): of the whole-pulse output, quantisation included)");
        let delays = match &self.unequal_delay {
            None => "at equal 99 % delay".to_string(),
            Some(why) => format!("NOT at equal delay: {why}"),
        };
        println!("  comparison {delays}");
        if !self.vibration.is_empty() {
            let delays = if self.equal_delay { "at equal 99 % delay" } else { "NOT at equal delay (see above)" };
            println!("\n  residual load vibration on the FMU, {delays} (peak shaft twist |θ_load − θ_motor| from the end of interpolation + the filter's 99 % delay; friction off):");
            for pair in self.vibration.chunks(2) {
                if let [b, m] = pair {
                    println!(
                        "  {:>6} Hz load resonance: Butterworth {:>10.3e} rad, moving average {:>10.3e} rad, ratio Butterworth / MA {:.3}",
                        b.resonance_hz,
                        b.residual,
                        m.residual,
                        b.residual / m.residual
                    );
                }
            }
        }
        if !self.sweep.is_empty() {
            println!("\n  cut-off sweep (moving averages matched to the Butterworth's 99 % delay):");
            print!("  {:>9} {:>9} {:>22} {:>12} {:>12}", "cut-off", "t99 ms", "moving average", "jerk BW", "jerk MA");
            for (hz, _, _) in self.sweep[0].residuals.iter() {
                print!(" {:>12} {:>12}", format!("res BW {hz}"), format!("res MA {hz}"));
            }
            println!();
            for p in &self.sweep {
                print!(
                    "  {:>9.1} {:>9.3} {:>22} {:>12.4e} {:>12.4e}",
                    p.cutoff_hz,
                    p.butterworth_t99 * 1e3,
                    p.moving_average.trim_start_matches("3 x moving average "),
                    p.butterworth_peak_jerk,
                    p.moving_average_peak_jerk
                );
                for (_, b, m) in &p.residuals {
                    print!(" {b:>12.4e} {m:>12.4e}");
                }
                println!();
            }
        }
        for why in &self.sweep_left_out {
            println!("  sweep: left out {why}");
        }
        println!();
        for f in &self.files {
            println!("  → {}", f.display());
        }
    }
}
