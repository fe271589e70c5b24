//! `servo bench accdec`: the figures of the acc/dec issue (seed 003).
//!
//! 1. The seed's worked example (1 kHz, 0.5 ms) to its printed digits.
//! 2. Poles and gains against python-control's `sample_system(method='matched')`, both zero
//!    conventions, orders 1–6 at several cut-offs.
//! 3. Properties of the drive's whole-pulse filters: pulse conservation over random
//!    sequences, zero in → zero out.
//! 4. Residual load vibration at equal 99 % delay, Butterworth vs 3 × moving average, on
//!    two load resonances of the FMU.
//! 5. Filter cost per tick in instructions (valgrind, difference of two run lengths).

use std::path::Path;
use std::process::Command;

use anyhow::{bail, Context, Result};
use control_core::acc_dec::{AccDecFilter, ButterworthDesign, MovingAverageCascade, ZeroPlacement, MAX_ORDER};
use serde::Serialize;

use crate::accdec::study::{
    delay, moving_average_matched_on, profile, residual_vibration, DelayMatch, FilterSpec, PulseMove, Resonance,
};
use crate::analysis::polynomial::roots;
use crate::fmu::fmpy::python;
use crate::fmu::runner::Fmu;
use crate::paths::workspace_root;

/// The seed's printed example: (name, printed text, our value).
#[derive(Clone, Debug, Serialize)]
pub struct SeedDigit {
    pub name: &'static str,
    pub printed: &'static str,
    pub ours: f64,
    pub equal: bool,
}

pub fn seed_digits() -> Result<Vec<SeedDigit>> {
    let d = ButterworthDesign::new(3, 1000.0, 0.0005).map_err(|e| anyhow::anyhow!("{e}"))?;
    let a = d.denominator();
    let rows = [
        ("K (numerator gain)", "0.3403", d.gain),
        ("a1", "0.33626", a[1]),
        ("a2", "0.026815", a[2]),
        ("a3", "-0.0018674", a[3]),
    ];
    Ok(rows
        .into_iter()
        .map(|(name, printed, ours)| {
            let decimals = printed.split('.').nth(1).map_or(0, str::len);
            SeedDigit { name, printed, ours, equal: format!("{ours:.decimals$}") == printed }
        })
        .collect())
}

/// The seed's own test: 100 pulses per sample for 30 samples through the 3rd-order filter at
/// 0.5 ms, cut-off 1 kHz and 300 Hz (the seed's result tables were lost); whole-pulse output
/// until the filter is empty.
pub fn seed_test() -> Result<Vec<(f32, Vec<i64>)>> {
    [1000.0f32, 300.0]
        .iter()
        .map(|&cutoff| {
            let d = ButterworthDesign::new(3, cutoff, 0.0005).map_err(|e| anyhow::anyhow!("{e}"))?;
            let mut f = control_core::acc_dec::ButterworthPulseFilter::new(d);
            let mut out: Vec<i64> = (0..200).map(|k| f.step(if k < 30 { 100 } else { 0 })).collect();
            while out.len() > 31 && out.last() == Some(&0) {
                out.pop();
            }
            Ok((cutoff, out))
        })
        .collect()
}

#[derive(Clone, Debug, Serialize)]
pub struct MatchedComparison {
    pub order: u32,
    pub cutoff_hz: f32,
    pub sample_period: f32,
    /// Largest |z_ours − z_python| over the poles.
    pub pole_error: f64,
    /// Largest |a_ours − a_python| over the denominator coefficients.
    pub denominator_error: f64,
    /// python-control's numerator constant K (every zero at infinity a delay).
    pub python_gain: f64,
    /// Relative error of our all-delays gain against it.
    pub all_delays_gain_error: f64,
    /// Relative error of our seed gain × 2^(N−1) (the DC value of (1 + z⁻¹)^(N−1)) against it.
    pub seed_gain_error: f64,
}

/// Cases compared with python-control: the seed's two cut-offs at 0.5 ms, the FMU's default
/// at 250 µs, and the Nyquist frequency itself.
pub const MATCHED_CASES: [(f32, f32); 4] = [(1000.0, 0.0005), (300.0, 0.0005), (40.0, 0.00025), (2000.0, 0.00025)];

fn pole_distance(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    // Each pole of `a` to its nearest in `b`.
    a.iter()
        .map(|p| b.iter().map(|q| ((p.0 - q.0).powi(2) + (p.1 - q.1).powi(2)).sqrt()).fold(f64::INFINITY, f64::min))
        .fold(0.0, f64::max)
}

pub fn matched_comparison() -> Result<Vec<MatchedComparison>> {
    let cases: Vec<serde_json::Value> = MATCHED_CASES
        .iter()
        .flat_map(|&(c, t)| {
            (1..=MAX_ORDER).map(move |n| serde_json::json!({"order": n, "cutoff_hz": c, "sample_period": t}))
        })
        .collect();
    let script = workspace_root().join("tests/python/matched_reference.py");
    let mut child = Command::new(python()?)
        .arg(&script)
        .stdin(std::process::Stdio::piped())
        .stdout(std::process::Stdio::piped())
        .spawn()
        .with_context(|| format!("cannot run {}", script.display()))?;
    serde_json::to_writer(child.stdin.take().context("no stdin")?, &cases)?;
    let out = child.wait_with_output()?;
    if !out.status.success() {
        bail!("{} failed ({})", script.display(), out.status);
    }
    let reference: Vec<serde_json::Value> = serde_json::from_slice(&out.stdout).context("python-control output")?;
    let mut rows = Vec::new();
    for r in reference {
        let order = r["order"].as_u64().context("order")? as u32;
        let cutoff_hz = r["cutoff_hz"].as_f64().context("cut-off")? as f32;
        let sample_period = r["sample_period"].as_f64().context("period")? as f32;
        let den: Vec<f64> = serde_json::from_value(r["denominator"].clone())?;
        let num: Vec<f64> = serde_json::from_value(r["numerator"].clone())?;
        let python_gain = num[0];
        let seed = ButterworthDesign::with_zeros(order, cutoff_hz, sample_period, ZeroPlacement::Seed)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let delays = ButterworthDesign::with_zeros(order, cutoff_hz, sample_period, ZeroPlacement::AllDelays)
            .map_err(|e| anyhow::anyhow!("{e}"))?;
        let ours: Vec<f64> = seed.denominator()[..=order as usize].to_vec();
        let denominator_error = ours.iter().zip(&den).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
        // Our poles straight from the design (what the drive runs), theirs from the roots.
        let our_poles: Vec<(f64, f64)> = seed.poles().collect();
        // den = [1, a1, …, aN] of z^N + a1·z^(N−1) + …: ascending order is its reverse.
        let ascending: Vec<f64> = den.iter().rev().copied().collect();
        let their_poles: Vec<(f64, f64)> = roots(&ascending).iter().map(|z| (z.re, z.im)).collect();
        let pole_error = pole_distance(&our_poles, &their_poles).max(pole_distance(&their_poles, &our_poles));
        rows.push(MatchedComparison {
            order,
            cutoff_hz,
            sample_period,
            pole_error,
            denominator_error,
            python_gain,
            all_delays_gain_error: (delays.gain - python_gain).abs() / python_gain,
            seed_gain_error: (seed.gain * (1u32 << (order - 1)) as f64 - python_gain).abs() / python_gain,
        });
    }
    Ok(rows)
}

/// Reproducible pulse sequences.
type Random = crate::random::XorShift64Star;

/// Pulses of one tick: none, small, medium or large, either sign.
fn pulses(rng: &mut Random) -> i64 {
    match rng.below(4) {
        0 => 0,
        1 => rng.below(201) as i64 - 100,
        2 => rng.below(40_001) as i64 - 20_000,
        _ => rng.below(2_000_001) as i64 - 1_000_000,
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct Properties {
    pub sequences: usize,
    /// Sequences whose output sum differed from the input sum once settled (must be 0).
    pub conservation_failures: usize,
    /// Ticks of all-zero input given to fresh random filters.
    pub zero_input_ticks: usize,
    /// Non-zero outputs for an all-zero input (must be 0).
    pub zero_input_nonzero_outputs: usize,
}

/// A random filter: Butterworth order 1–6 at a random cut-off up to Nyquist (either zero
/// placement) or a 1–3 stage moving average of random lengths.
fn random_filter(rng: &mut Random) -> AccDecFilter {
    let period = 0.00025f32;
    if rng.below(2) == 0 {
        let order = 1 + rng.below(MAX_ORDER as u64) as u32;
        let cutoff = 1.0 + rng.below(1999) as f32;
        let zeros = if rng.below(2) == 0 { ZeroPlacement::Seed } else { ZeroPlacement::AllDelays };
        let d = ButterworthDesign::with_zeros(order, cutoff, period, zeros).expect("valid by construction");
        AccDecFilter::Butterworth(control_core::acc_dec::ButterworthPulseFilter::new(d))
    } else {
        let stages = 1 + rng.below(3) as usize;
        let lengths: Vec<u32> = (0..stages).map(|_| 1 + rng.below(64) as u32).collect();
        AccDecFilter::MovingAverage(MovingAverageCascade::new(&lengths).expect("valid by construction"))
    }
}

pub fn properties(sequences: usize) -> Properties {
    let mut rng = crate::random::XorShift64Star(0x5EED_0003);
    let mut failures = 0;
    for _ in 0..sequences {
        let mut f = random_filter(&mut rng);
        let n = 1 + rng.below(300) as usize;
        let mut sum_in = 0i64;
        let mut sum_out = 0i64;
        for _ in 0..n {
            let x = pulses(&mut rng);
            sum_in += x;
            sum_out += f.step(x);
        }
        // Settle: a low cut-off Butterworth needs a few thousand ticks.
        for _ in 0..40_000 {
            sum_out += f.step(0);
        }
        failures += usize::from(sum_in != sum_out);
    }
    let mut nonzero = 0;
    let ticks = 10_000;
    for _ in 0..100 {
        let mut f = random_filter(&mut rng);
        nonzero += (0..ticks / 100).filter(|_| f.step(0) != 0).count();
    }
    Properties {
        sequences,
        conservation_failures: failures,
        zero_input_ticks: ticks,
        zero_input_nonzero_outputs: nonzero,
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct EqualDelayVibration {
    /// What the two filters are matched on.
    pub matched_on: &'static str,
    pub butterworth: String,
    pub moving_average: String,
    pub butterworth_t99: f64,
    pub moving_average_t99: f64,
    pub butterworth_t50: f64,
    pub moving_average_t50: f64,
    /// (resonance Hz, Butterworth residual rad, moving-average residual rad, ratio BW / MA)
    pub resonances: Vec<(f64, f64, f64, f64)>,
}

/// The default move (2 rad at 50 rad/s) with the default Butterworth (order 3, twice the
/// position bandwidth) and three moving averages matched to its 99 % delay, on two load
/// resonances (one below, one above the cut-off), 2 % damping, friction off.
/// With `on_t50`, the moving averages are matched on the 50 % delay instead (a second view:
/// the Butterworth's overshoot and ringing make its 99 % delay long for its 50 % delay).
pub fn equal_delay_vibration(fmu_path: &Path, resonances_hz: &[f64], on_t50: bool) -> Result<EqualDelayVibration> {
    let period = 0.00025f32;
    let (distance, speed) = (2.0, 50.0);
    let cutoff = crate::accdec::report::default_cutoff_hz();
    let bw = FilterSpec::butterworth(3, cutoff);
    let bd = delay(&bw, period)?;
    let target = if on_t50 { DelayMatch::T50(bd.t50) } else { DelayMatch::T99(bd.t99) };
    let ma = moving_average_matched_on(target, period, 3)?;
    let md = delay(&ma, period)?;
    let cpr = servo_axis::plant::PlantParams::default().encoder_counts_per_rev;
    let m = PulseMove {
        distance: (distance / std::f64::consts::TAU * cpr as f64).round() as i64,
        speed: speed as f32 * (cpr as f32 / control_core::TAU * period),
    };
    let fmu = Fmu::load(fmu_path)?;
    let mut rows = Vec::new();
    let windows: Vec<f64> = [(&bw, bd.t99), (&ma, md.t99)]
        .iter()
        .map(|(s, t99)| Ok(profile(s, period, m, 64)?.figures().interpolation_end + t99))
        .collect::<Result<_>>()?;
    for &hz in resonances_hz {
        let res = Resonance { hz, damping_ratio: 0.02 };
        let duration = windows[0].max(windows[1]) + 0.3;
        let (vb, _) = residual_vibration(&fmu, &bw, res, period as f64, distance, speed, (windows[0], duration))?;
        let (vm, _) = residual_vibration(&fmu, &ma, res, period as f64, distance, speed, (windows[1], duration))?;
        rows.push((hz, vb.residual, vm.residual, vb.residual / vm.residual));
    }
    Ok(EqualDelayVibration {
        matched_on: if on_t50 { "50 % delay" } else { "99 % delay" },
        butterworth: bw.label(),
        moving_average: ma.label(),
        butterworth_t99: bd.t99,
        moving_average_t99: md.t99,
        butterworth_t50: bd.t50,
        moving_average_t50: md.t50,
        resonances: rows,
    })
}

/// The filters whose cost is measured, by name.
pub const COST_FILTERS: [&str; 5] =
    ["none", "butterworth3", "butterworth6", "moving_average3x16", "moving_average1x16"];

/// Run `ticks` ticks of a filter on reproducible pulses (the probe valgrind counts).
pub fn cost_probe(filter: &str, ticks: usize) -> Result<i64> {
    let period = 0.00025f32;
    let mut f = match filter {
        "none" => AccDecFilter::None,
        "butterworth3" | "butterworth6" => {
            let order = if filter == "butterworth3" { 3 } else { 6 };
            let d = ButterworthDesign::new(order, 40.0, period).map_err(|e| anyhow::anyhow!("{e}"))?;
            AccDecFilter::Butterworth(control_core::acc_dec::ButterworthPulseFilter::new(d))
        }
        "moving_average3x16" => {
            AccDecFilter::MovingAverage(MovingAverageCascade::new(&[16, 16, 16]).map_err(|e| anyhow::anyhow!("{e}"))?)
        }
        "moving_average1x16" => {
            AccDecFilter::MovingAverage(MovingAverageCascade::new(&[16]).map_err(|e| anyhow::anyhow!("{e}"))?)
        }
        other => bail!("unknown filter `{other}` (one of {COST_FILTERS:?})"),
    };
    let mut rng = crate::random::XorShift64Star(7);
    let mut sum = 0i64;
    for _ in 0..ticks {
        let x = std::hint::black_box(pulses(&mut rng));
        sum = sum.wrapping_add(std::hint::black_box(f.step(x)));
    }
    Ok(sum)
}

#[derive(Clone, Debug, Serialize)]
pub struct FilterCost {
    pub filter: String,
    /// x86-64 instructions per tick, the probe's own input generation subtracted.
    pub instructions_per_tick: f64,
}

fn instructions(exe: &Path, filter: &str, ticks: usize) -> Result<u64> {
    let out = Command::new("valgrind")
        .args(["--tool=cachegrind", "--cache-sim=no", "--cachegrind-out-file=/dev/null"])
        .arg(exe)
        .args(["bench", "accdec-probe", "--filter", filter, "--ticks", &ticks.to_string()])
        .output()
        .context("cannot run valgrind: install it (scripts/setup-deps does) or pass --no-cost")?;
    let text = String::from_utf8_lossy(&out.stderr);
    if !out.status.success() {
        bail!("valgrind run failed: {text}");
    }
    let line = text.lines().find(|l| l.contains("I") && l.contains("refs:")).context("valgrind printed no I refs")?;
    let number: String = line.split("refs:").nth(1).unwrap_or("").chars().filter(|c| c.is_ascii_digit()).collect();
    number.parse().context("valgrind I refs")
}

/// Instructions per tick: (count(N2) − count(N1)) / (N2 − N1), minus the same for `none`.
pub fn filter_costs() -> Result<Vec<FilterCost>> {
    let exe = std::env::current_exe()?;
    let (n1, n2) = (10_000usize, 110_000usize);
    let per_tick = |f: &str| -> Result<f64> {
        Ok((instructions(&exe, f, n2)? as f64 - instructions(&exe, f, n1)? as f64) / (n2 - n1) as f64)
    };
    let base = per_tick("none")?;
    COST_FILTERS[1..]
        .iter()
        .map(|f| Ok(FilterCost { filter: f.to_string(), instructions_per_tick: per_tick(f)? - base }))
        .collect()
}
