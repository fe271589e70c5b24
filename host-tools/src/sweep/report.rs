//! `servo sweep`: run a frequency-response sweep on the FMU, compute the response from the
//! acquisition stream (equivalent time) and read the drive's on-line results, check that the
//! two agree, optionally measure the oracle, and write CSV, Bode plot and JSON.

use servo_axis::variables::name;
use std::path::{Path, PathBuf};

use anyhow::{bail, Result};
use control_core::phase_shifted_sweep::SweepParams;
use serde::Serialize;

use crate::analysis::response_point::{difference, ResponsePoint};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::SweepRun;
use crate::fmu::trace::Trace;
use crate::plot::bode::plot_bode;
use crate::sweep::measurement::{
    errors, flagged, limited_shares, limited_warning, measured_time, online_results, stream_results, ErrorSummary,
};

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
/// `sweep.dither` from the sweep's threshold up (`base_rate_hz`: the loop rate it runs at).
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

#[derive(Clone, Debug, Serialize)]
pub struct SweepReport {
    pub measurement_time_s: f64,
    pub acquisition_hz: f64,
    pub threshold_hz: f64,
    pub stream: Vec<ResponsePoint>,
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
    pub oracle: Option<Vec<ResponsePoint>>,
    pub errors_vs_oracle: Option<ErrorSummary>,
    pub files: Vec<PathBuf>,
}

pub fn read_reference(path: &Path) -> Result<Vec<ResponsePoint>> {
    let t = Trace::read_csv(path)?;
    let (Some(f), Some(g), Some(p)) = (t.column("frequency"), t.column("gain_db"), t.column("phase_deg")) else {
        bail!("{}: a reference needs the columns frequency, gain_db, phase_deg", path.display());
    };
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
    std::fs::create_dir_all(out)?;
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
    let online = online_results(&trace)?;
    if stream.len() != online.len() {
        bail!("{} frequencies from the stream, {} from the drive", stream.len(), online.len());
    }
    let agreement = stream.iter().zip(&online).fold((0.0f64, 0.0f64), |(g, p), (a, b)| {
        let (dg, dp) = difference(a, b);
        if a.quality < 0.01 {
            (g, p) // nothing measurable there (a single record at fs/2): both are noise
        } else {
            (g.max(dg.abs()), p.max(dp.abs()))
        }
    });
    // Each result's share of samples measured with the output limited (0 where none), in the
    // on-line results' order (both are read at each completion).
    let limited = limited_shares(&trace);
    let limited_hz = flagged(&limited);
    let limited_known = trace.column("sweep_last_limited").is_some();
    let mut files = Vec::new();
    let csv = out.join("sweep.csv");
    let mut t = Trace::new(
        [
            "frequency",
            "gain_db",
            "phase_deg",
            "quality",
            "online_gain_db",
            "online_phase_deg",
            "online_quality",
            "limited_share",
        ]
        .map(String::from)
        .to_vec(),
    );
    for ((a, b), &(_, share)) in stream.iter().zip(&online).zip(&limited) {
        t.rows.push(vec![a.frequency, a.gain_db, a.phase_deg, a.quality, b.gain_db, b.phase_deg, b.quality, share]);
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
    let limited_note = match (limited_hz.first(), limited_hz.last()) {
        (Some(a), Some(b)) => format!(" — output LIMITED at {a:.0}–{b:.0} Hz: not the linear loop there"),
        _ => String::new(),
    };
    plot_bode(
        &svg,
        &format!(
            "Frequency response, {measurement_time:.2} s of measurement, acquisition {acquisition_hz} Hz{limited_note}"
        ),
        &curves,
        Some((acquisition_hz / 2.0, "acquisition Nyquist")),
    )?;
    files.push(svg);
    let limited_share = limited.iter().map(|&(_, share)| share).collect();
    let report = SweepReport {
        measurement_time_s: measurement_time,
        acquisition_hz,
        threshold_hz: sweep.settings.threshold(fs) as f64,
        stream,
        online,
        stream_vs_online: agreement,
        limited_hz,
        limited_share,
        limited_known,
        oracle,
        errors_vs_oracle,
        files: files.clone(),
    };
    let json = out.join("sweep.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    Ok(SweepReport { files: [files, vec![json]].concat(), ..report })
}

impl SweepReport {
    pub fn print(&self) {
        println!(
            "servo sweep — {} frequencies, {:.3} s of measurement, acquisition {} Hz, phase shifting from {} Hz",
            self.stream.len(),
            self.measurement_time_s,
            self.acquisition_hz,
            self.threshold_hz
        );
        println!(
            "  {:>10} {:>10} {:>10} {:>8} {:>12} {:>12} {:>10}",
            "Hz", "gain dB", "phase deg", "quality", "online dB", "online deg", "limited %"
        );
        for ((a, b), share) in self.stream.iter().zip(&self.online).zip(&self.limited_share) {
            println!(
                "  {:>10.2} {:>10.3} {:>10.2} {:>8.4} {:>12.3} {:>12.2} {:>10}",
                a.frequency,
                a.gain_db,
                a.phase_deg,
                a.quality,
                b.gain_db,
                b.phase_deg,
                if *share > 0.0 { format!("{:.1}", 100.0 * share) } else { String::new() }
            );
        }
        println!(
            "  stream vs on-line correlator: largest difference {:.2e} dB, {:.2e} deg",
            self.stream_vs_online.0, self.stream_vs_online.1
        );
        if !self.limited_hz.is_empty() {
            println!("  WARNING: {}", limited_warning(&self.limited_hz));
        }
        if !self.limited_known {
            println!(
                "  this FMU does not report whether the drive's output was limited (no sweep_last_limited output)"
            );
        }
        if let Some(e) = &self.errors_vs_oracle {
            println!(
                "  against the oracle: below {} Hz max {:.3} dB / {:.2} deg; from {} Hz up max {:.3} dB / {:.2} deg",
                self.threshold_hz,
                e.below_gain_db,
                e.below_phase_deg,
                self.threshold_hz,
                e.above_gain_db,
                e.above_phase_deg
            );
        }
        for f in &self.files {
            println!("  → {}", f.display());
        }
    }
}
