//! `servo sweep`: run a frequency-response sweep on the FMU, compute the response from the
//! acquisition stream (equivalent time) and read the drive's on-line results, check that the
//! two agree, optionally measure the oracle, and write CSV, Bode plot and JSON.

use servo_axis::variables::name;
use std::f64::consts::LN_10;
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use control_core::phase_shifted_sweep::SweepParams;
use serde::Serialize;

use crate::analysis::response_point::{difference, ResponsePoint};
use crate::fmu::axis_health::{first_trip, Trip};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::SweepRun;
use crate::fmu::trace::Trace;
use crate::plot::bode::plot_bode;
use crate::sweep::measurement::{
    errors, flagged, frequency_list, limited_shares, limited_warning, measured_time, online_results, stream_results,
    stream_standard_errors, unmeasurable, unmeasured, ErrorSummary,
};
use crate::sweep::standard_error::ResponseStandardError;
use crate::sweep::torque_limit::{torque_limited_shares, TorqueLimits};

/// Encoder of the oracle (counts per revolution; the FMU's finest, 16 times the default 2^20).
pub const ORACLE_ENCODER: i64 = 1 << 24;

/// Shortest settling of each oracle frequency (s). The oracle has no settling check: on a
/// soft shaft (50 Hz) inside the default velocity loop the mode near 50 Hz rings with a time
/// constant of about 65 ms and the anti-resonance's (J_L/J_M 5: 20 Hz) about 160 ms; after
/// 50 ms the oracle's own records were 0.13-0.18 dB and 0.7-1.3 deg off at 49-50 Hz (against
/// itself with four times the settling and the records). 0.5 s is three of the slower time
/// constant.
pub const ORACLE_MIN_SETTLE_S: f32 = 0.5;

/// The oracle's settings: acquisition at the velocity-loop rate (every 2 ticks: no aliasing
/// up to 4 kHz, each sample a single velocity estimate), one unshifted record ten times as
/// long (at least 40 cycles and 1 s), settling twice as long and at least 4 cycles and
/// [`ORACLE_MIN_SETTLE_S`], read from the on-line correlator; dithered by the default
/// `sweep.dither` from the sweep's threshold up, or from 2 kHz where a faster loop's threshold
/// lies higher, as the sweep is (`base_rate_hz`: the loop rate it runs at).
///
/// The dither is there for the same reason as in the sweep: at the top the response is a few
/// tens of counts even on the oracle's encoder, and at a constant riding speed the count
/// pattern locks to the excitation. Without it the oracle's 3 kHz point varied by 0.010 dB
/// (standard deviation; 0.042 dB range) and 0.05° over riding speeds of 40–55 rad/s on the
/// default axis (torque command), with it by 0.001 dB and 0.01°. Below the threshold it is
/// left out: there the responses are large and the dither's own noise made the oracle worse
/// (0.075 dB at 10 Hz on the light 0.2:1 axis with the dither on every frequency).
pub fn oracle_settings(s: &SweepParams, base_rate_hz: f32) -> SweepParams {
    SweepParams {
        acquisition_divider: 2,
        shifts: 1,
        repeats: 1,
        measure_cycles: (s.measure_cycles * 10.0).max(40.0),
        min_measure_s: (s.min_measure_s * 10.0).max(1.0),
        settle_cycles: (s.settle_cycles * 2.0).max(4.0),
        min_settle_s: s.min_settle_s.max(ORACLE_MIN_SETTLE_S),
        // Fixed long records: the reference does not adapt its length.
        precision_db: 0.0,
        dither: SweepParams::default().dither,
        threshold_hz: s.threshold(base_rate_hz),
        ..*s
    }
}

/// The oracle of a sweep: the same axis, loop, injection point, amplitude, riding speed and
/// frequencies, measured with [`oracle_settings`] on a 2^24-count encoder without current-sensor
/// noise: the loop's linear response, without the quantisation and the noise a measurement
/// has to average out (its own residual error, against itself with settling and records twice as
/// long at a riding speed 1 % higher, is printed by `servo bench sweep`).
pub fn oracle_run(run: &SweepRun) -> Result<SweepRun> {
    let mut parameters = run.parameters.clone();
    parameters.insert(name::plant_encoder_counts_per_rev.to_string(), Value::Int(ORACLE_ENCODER));
    parameters.insert(name::plant_current_noise_std.to_string(), Value::Float(0.0));
    let base_rate_hz = run.rates()?.current_loop_hz;
    Ok(SweepRun { settings: oracle_settings(&run.settings, base_rate_hz), parameters, velocity: run.velocity })
}

/// A result's standard error (the larger of the gain's and the phase's, in dB) above so many
/// times the sweep's precision target is named in a warning: the noise may have moved it by
/// more than the precision the sweep promises.
pub const IMPRECISE_FACTOR: f64 = 2.0;

/// The precision (dB) a sweep's standard errors are held against: its `precision_db`, or the
/// default's where the precision control is off (0: fixed records).
pub fn precision_target_db(settings: &SweepParams) -> f64 {
    if settings.precision_db > 0.0 {
        settings.precision_db as f64
    } else {
        SweepParams::default().precision_db as f64
    }
}

/// The frequencies of the measurable `points` whose standard error exceeds
/// [`IMPRECISE_FACTOR`] times `target_db` (the phase's taken as a gain of the same relative
/// size: `precision_db·ln10/20` rad).
pub fn imprecise(points: &[ResponsePoint], errors: &[ResponseStandardError], target_db: f64) -> Vec<f64> {
    points
        .iter()
        .zip(errors)
        .filter(|(p, e)| !unmeasurable(p) && e.larger_db() > IMPRECISE_FACTOR * target_db)
        .map(|(p, _)| p.frequency)
        .collect()
}

/// What a user reads when results' standard errors exceed [`IMPRECISE_FACTOR`] times the
/// precision `target_db`.
pub fn imprecise_warning(hz: &[f64], target_db: f64) -> String {
    format!(
        "the standard error at {} is more than {IMPRECISE_FACTOR} times the precision of {} dB ({:.2} deg): noise, or a transient that had not died out, may have moved these results by that much; measure longer there (--min-measure, --max-extensions, --min-settle) or with a larger --amplitude",
        frequency_list(hz),
        target_db as f32,
        (target_db * LN_10 / 20.0).to_degrees(),
    )
}

/// Largest difference between the drive's on-line results and the host's estimate from the
/// stream that a sweep accepts (dB, degrees): the same samples, fitted in f32 and in f64.
pub const AGREEMENT_LIMIT: (f64, f64) = (0.01, 0.1);

#[derive(Clone, Debug, Serialize)]
pub struct SweepReport {
    pub measurement_time_s: f64,
    /// The sweep's time budget (s; `--time-budget`), 0 where none applies (no precision
    /// control, the PRBS mode): the time the records may take past their caps, and for the
    /// finer target, where the sweep has room (see `SweepParams::time_budget_s`).
    pub time_budget_s: f32,
    pub acquisition_hz: f64,
    pub threshold_hz: f64,
    pub stream: Vec<ResponsePoint>,
    /// Standard error of every `stream` result (gain dB, phase deg; see
    /// [`crate::sweep::standard_error`]), in its order.
    pub standard_error: Vec<ResponseStandardError>,
    /// The precision (dB) the standard errors are held against ([`precision_target_db`]) and
    /// the frequencies whose error exceeds [`IMPRECISE_FACTOR`] times it.
    pub precision_target_db: f64,
    pub imprecise_hz: Vec<f64>,
    pub online: Vec<ResponsePoint>,
    /// Largest |stream − on-line| difference: (dB, degrees).
    pub stream_vs_online: (f64, f64),
    /// Frequencies the drive measured while its output was limited (see
    /// [`crate::sweep::measurement::limited_frequencies`]): the loop was not linear there.
    pub limited_hz: Vec<f64>,
    /// Each on-line result's share of samples measured with the output limited (0..1).
    pub limited_share: Vec<f64>,
    /// The FMU reports the share (`sweep_last_limited`; an older build does not).
    pub limited_known: bool,
    /// Frequencies measured with the torque command at the velocity loop's torque limit or
    /// the current limit on any sample (see [`crate::sweep::torque_limit`]), and every
    /// result's share of such samples (0..1).
    pub torque_limited_hz: Vec<f64>,
    pub torque_limited_share: Vec<f64>,
    /// The torque (N·m) from which a sample counts as at a limit (the lower clamp).
    pub torque_limit_nm: f64,
    /// That clamp by its parameter and value (see [`control_core::torque_ceiling`]).
    pub torque_limit_by: String,
    /// Frequencies with no measurable result (see [`crate::sweep::measurement::unmeasurable`]),
    /// from the stream or the drive.
    pub unmeasured_hz: Vec<f64>,
    /// The first fault the drive latched during the run, if any: the results from there on
    /// are not the loop's response.
    pub fault: Option<Trip>,
    /// Largest stream vs on-line difference allowed: (dB, degrees).
    pub agreement_limit: (f64, f64),
    pub oracle: Option<Vec<ResponsePoint>>,
    pub errors_vs_oracle: Option<ErrorSummary>,
    pub files: Vec<PathBuf>,
}

pub fn read_reference(path: &Path) -> Result<Vec<ResponsePoint>> {
    let t = Trace::read_csv(path)?;
    let (Some(f), Some(g), Some(p)) = (t.column("frequency"), t.column("gain_db"), t.column("phase_deg")) else {
        bail!("{}: a reference needs the columns frequency, gain_db, phase_deg", path.display());
    };
    if f.is_empty() {
        bail!("{}: the reference has no rows", path.display());
    }
    for i in 0..f.len() {
        // Rows are counted as a user sees them in the file: the header is line 1.
        let line = i + 2;
        if !(f[i].is_finite() && f[i] > 0.0) {
            bail!("{} line {line}: frequency {} is not a positive number (Hz)", path.display(), f[i]);
        }
        if !(g[i].is_finite() && p[i].is_finite()) {
            bail!("{} line {line}: gain_db {} and phase_deg {} must be finite numbers", path.display(), g[i], p[i]);
        }
    }
    Ok((0..f.len()).map(|i| ResponsePoint { frequency: f[i], gain_db: g[i], phase_deg: p[i], quality: 1.0 }).collect())
}

pub fn run(
    fmu: &Fmu,
    sweep: &SweepRun,
    with_oracle: bool,
    reference: Option<(&str, Vec<ResponsePoint>)>,
    out: &Path,
    mut progress: impl FnMut(&str, f64),
) -> Result<SweepReport> {
    crate::paths::create_out_dir(out)?;
    let rates = sweep.rates()?;
    let (fs, pdiv) = (rates.current_loop_hz, rates.position_divider);
    sweep.scenario()?; // refuses invalid settings with the drive's reason first
    if sweep.settings.acquisition_divider != pdiv {
        bail!(
            "the acquisition stream reaches the host once per communication step ({pdiv} ticks): use --acquisition-divider {pdiv} (the oracle uses the drive's own correlator at any rate)"
        );
    }
    let trace = sweep.run(fmu, |f| progress("sweep", f))?;
    let measurement_time = measured_time(&trace)?;
    let stream = stream_results(&trace, &sweep.settings)?;
    let standard_error = stream_standard_errors(&trace)?;
    let precision_target = precision_target_db(&sweep.settings);
    let imprecise_hz = imprecise(&stream, &standard_error, precision_target);
    let online = online_results(&trace)?;
    if stream.len() != online.len() {
        bail!("{} frequencies from the stream, {} from the drive", stream.len(), online.len());
    }
    let agreement = stream.iter().zip(&online).fold((0.0f64, 0.0f64), |(g, p), (a, b)| {
        let (dg, dp) = difference(a, b);
        if unmeasurable(a) || unmeasurable(b) {
            (g, p) // nothing measurable there (named in `unmeasured_hz`): both are noise
        } else {
            (g.max(dg.abs()), p.max(dp.abs()))
        }
    });
    // Each result's share of samples measured with the output limited (0 where none), in the
    // on-line results' order (both are read at each completion).
    let limited = limited_shares(&trace);
    let limited_hz = flagged(&limited);
    let limited_known = trace.column("sweep_last_limited").is_some();
    let limits = TorqueLimits::of(&sweep.params_on(fmu)?, &sweep.settings);
    // By frequency index: the on-line results come one per frequency, in order.
    let torque_limited = torque_limited_shares(&trace, &limits)?;
    let torque_limited_share: Vec<f64> =
        (0..online.len()).map(|k| torque_limited.get(&(k as i64)).copied().unwrap_or(0.0)).collect();
    let torque_limited_hz: Vec<f64> =
        online.iter().zip(&torque_limited_share).filter(|(_, &share)| share > 0.0).map(|(p, _)| p.frequency).collect();
    let mut unmeasured_hz = unmeasured(&stream);
    for f in unmeasured(&online) {
        if !unmeasured_hz.contains(&f) {
            unmeasured_hz.push(f);
        }
    }
    unmeasured_hz.sort_by(f64::total_cmp);
    let fault = first_trip(&trace)?;
    let mut files = Vec::new();
    let csv = out.join("sweep.csv");
    let mut t = Trace::new(
        [
            "frequency",
            "gain_db",
            "phase_deg",
            "quality",
            "gain_se_db",
            "phase_se_deg",
            "online_gain_db",
            "online_phase_deg",
            "online_quality",
            "limited_share",
            "torque_limited_share",
        ]
        .map(String::from)
        .to_vec(),
    );
    for ((((a, b), &(_, share)), &torque_share), se) in
        stream.iter().zip(&online).zip(&limited).zip(&torque_limited_share).zip(&standard_error)
    {
        t.rows.push(vec![
            a.frequency,
            a.gain_db,
            a.phase_deg,
            a.quality,
            se.gain_db,
            se.phase_deg,
            b.gain_db,
            b.phase_deg,
            b.quality,
            share,
            torque_share,
        ]);
    }
    t.write_csv(&csv)?;
    let trace_csv = out.join("sweep_trace.csv");
    trace.write_csv(&trace_csv)?;
    files.extend([csv, trace_csv]);
    let (oracle, errors_vs_oracle) = if with_oracle {
        let o = oracle_run(sweep)?;
        let ot = o.run(fmu, |f| progress("oracle", f))?;
        let oracle = online_results(&ot)?;
        let e = errors(&stream, &oracle, sweep.settings.threshold(fs) as f64);
        let path = out.join("oracle.csv");
        let mut t = Trace::new(["frequency", "gain_db", "phase_deg", "quality"].map(String::from).to_vec());
        for p in &oracle {
            t.rows.push(vec![p.frequency, p.gain_db, p.phase_deg, p.quality]);
        }
        t.write_csv(&path)?;
        files.push(path);
        (Some(oracle), Some(e))
    } else {
        (None, None)
    };
    let acquisition_hz = fs as f64 / sweep.settings.acquisition_divider as f64;
    let mut curves: Vec<(&str, &[ResponsePoint])> = vec![];
    if let Some(o) = &oracle {
        curves.push(("oracle (8 kHz acquisition, 10x longer, 2^24-count encoder, no noise)", o));
    }
    if let Some((label, r)) = &reference {
        curves.push((label, r));
    }
    curves.push(("equivalent time (acquisition stream)", &stream));
    curves.push(("on-line correlator (drive)", &online));
    let svg = out.join("bode.svg");
    // Where the drive's output was limited, the plot says so in its title.
    let mut any_limited: Vec<f64> = limited_hz.iter().chain(&torque_limited_hz).copied().collect();
    any_limited.sort_by(f64::total_cmp);
    let limited_note = match (any_limited.first(), any_limited.last()) {
        (Some(a), Some(b)) => format!(" — output LIMITED at {a:.0}–{b:.0} Hz: not the linear loop there"),
        _ => String::new(),
    };
    let fault_note = fault.as_ref().map_or(String::new(), |e| format!(" — FAULT at {:.3} s ({})", e.time_s, e.faults));
    plot_bode(
        &svg,
        &format!(
            "Frequency response, {measurement_time:.2} s of measurement, acquisition {acquisition_hz} Hz{limited_note}{fault_note}"
        ),
        &curves,
        Some((acquisition_hz / 2.0, "acquisition Nyquist")),
    )?;
    files.push(svg);
    let limited_share = limited.iter().map(|&(_, share)| share).collect();
    let report = SweepReport {
        measurement_time_s: measurement_time,
        time_budget_s: if sweep.settings.budget_ticks(fs) > 0 { sweep.settings.time_budget_s } else { 0.0 },
        acquisition_hz,
        threshold_hz: sweep.settings.threshold(fs) as f64,
        stream,
        standard_error,
        precision_target_db: precision_target,
        imprecise_hz,
        online,
        stream_vs_online: agreement,
        limited_hz,
        limited_share,
        limited_known,
        torque_limited_hz,
        torque_limited_share,
        torque_limit_nm: limits.lowest(),
        torque_limit_by: limits.ceiling.to_string(),
        unmeasured_hz,
        fault,
        agreement_limit: AGREEMENT_LIMIT,
        oracle,
        errors_vs_oracle,
        files: files.clone(),
    };
    let json = out.join("sweep.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    Ok(SweepReport { files: [files, vec![json]].concat(), ..report })
}

impl SweepReport {
    /// Every check inside the sweep passed: no fault, a result at every frequency, and the
    /// drive's on-line results agree with the stream's within [`AGREEMENT_LIMIT`]. (Results
    /// measured at a limit are warned about, not failed: how far off they are depends on how
    /// deep the limit cut.)
    pub fn passed(&self) -> bool {
        self.fault.is_none() && self.unmeasured_hz.is_empty() && self.agrees()
    }

    fn agrees(&self) -> bool {
        self.stream_vs_online.0 <= self.agreement_limit.0 && self.stream_vs_online.1 <= self.agreement_limit.1
    }

    pub fn print(&self) {
        // Why a sweep takes longer than its caps: what the budget let it spend on precision.
        let budget = if self.time_budget_s > 0.0 {
            format!(" (time budget {} s: --time-budget 0 for the caps alone)", self.time_budget_s)
        } else {
            String::new()
        };
        println!(
            "servo sweep — {} frequencies, {:.3} s of measurement{budget}, acquisition {} Hz, phase shifting from {} Hz",
            self.stream.len(),
            self.measurement_time_s,
            self.acquisition_hz,
            self.threshold_hz
        );
        println!(
            "  {:>10} {:>10} {:>10} {:>8} {:>8} {:>8} {:>12} {:>12} {:>10} {:>12}",
            "Hz",
            "gain dB",
            "phase deg",
            "quality",
            "± dB",
            "± deg",
            "online dB",
            "online deg",
            "limited %",
            "torque lim %"
        );
        let percent = |share: f64| if share > 0.0 { format!("{:.1}", 100.0 * share) } else { String::new() };
        for ((((a, b), &share), &torque_share), se) in self
            .stream
            .iter()
            .zip(&self.online)
            .zip(&self.limited_share)
            .zip(&self.torque_limited_share)
            .zip(&self.standard_error)
        {
            println!(
                "  {:>10.2} {:>10.3} {:>10.2} {:>8.4} {:>8.3} {:>8.2} {:>12.3} {:>12.2} {:>10} {:>12}",
                a.frequency,
                a.gain_db,
                a.phase_deg,
                a.quality,
                se.gain_db,
                se.phase_deg,
                b.gain_db,
                b.phase_deg,
                percent(share),
                percent(torque_share)
            );
        }
        println!(
            "  stream vs on-line correlator: largest difference {:.2e} dB, {:.2e} deg",
            self.stream_vs_online.0, self.stream_vs_online.1
        );
        if !self.agrees() {
            println!(
                "  FAILED: the drive's on-line results and the host's estimate from the same samples differ by more than {} dB / {} deg: the stream lost or mislabelled samples",
                self.agreement_limit.0, self.agreement_limit.1
            );
        }
        if let Some(e) = &self.fault {
            println!("  FAILED: {}", e.sentence());
        }
        if !self.unmeasured_hz.is_empty() {
            let why = if self.fault.is_some() {
                "the drive's bridge was off after the fault"
            } else {
                "the samples' phases cannot tell a sine there (one record at a multiple of half the acquisition rate sees the sine at one phase and its opposite only: keep --repeats and --shifts at 2 or more there, or move the frequency)"
            };
            println!("  FAILED: no measurable result at {}: {why}", frequency_list(&self.unmeasured_hz));
        }
        if !self.limited_hz.is_empty() {
            println!("  WARNING: {}", limited_warning(&self.limited_hz));
        }
        if !self.imprecise_hz.is_empty() {
            println!("  WARNING: {}", imprecise_warning(&self.imprecise_hz, self.precision_target_db));
        }
        if !self.torque_limited_hz.is_empty() {
            println!(
                "  WARNING: the torque command reached the drive's limit ({:.3} N·m: {}) while it measured {}: the loop was not linear there, and the result can be off by decibels. Lower --amplitude",
                self.torque_limit_nm,
                self.torque_limit_by,
                frequency_list(&self.torque_limited_hz)
            );
        }
        if !self.limited_known {
            println!(
                "  this FMU does not report whether the drive's output was limited (no sweep_last_limited output)"
            );
        }
        if let Some(e) = &self.errors_vs_oracle {
            let below = e.points_compared - e.points_above;
            let side = |n: usize, gain: f64, phase: f64| {
                if n == 0 {
                    "no frequency".to_string()
                } else {
                    format!("max {gain:.3} dB / {phase:.2} deg over {n}")
                }
            };
            println!(
                "  against the oracle: below {} Hz {}; from {} Hz up {}",
                self.threshold_hz,
                side(below, e.below_gain_db, e.below_phase_deg),
                self.threshold_hz,
                side(e.points_above, e.above_gain_db, e.above_phase_deg)
            );
        }
        for f in &self.files {
            println!("  → {}", f.display());
        }
    }
}
