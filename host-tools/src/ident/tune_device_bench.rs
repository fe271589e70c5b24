//! `servo bench tune-device`: `servo tune --device`'s check (the correction loaded into a
//! drive, the pseudo-circle and the machine-end response without and with it, each beside
//! its FMU twin) over the virtual drive in this process (deterministic, 921 600 Bd), for
//! every axis of pairs of absorbers across the identification grid's range (15–300 Hz, 5 %
//! damping, and a rigid axis), accelerometer noise off and on: the worst drive − twin
//! figures against their goals, and how far the drive's machine-end response lies from the
//! other axis's before and after the correction.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use serde::Serialize;
use servo_axis::plant::PlantParams;
use servo_axis::variables::name;

use crate::circle::device::GOAL_COUNTS;
use crate::cli::{progress_bar, Common};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::ident::bench::DAMPING;
use crate::ident::device_check::{check_on_device, TuneDeviceCheck};
use crate::ident::device_machine_end::{share_of_bound, GOAL_FLOOR, GOAL_STANDARD_ERRORS};
use crate::ident::identification::{absorber_parameters, true_anti_resonance, AxisModel};
use crate::ident::tuning::{tune, write, Method};
use crate::paths::{default_fmu, default_out};
use crate::virtual_drive::uart::LineSettings;

/// The pairs of axes (anti-resonance in Hz, None: rigid): the demo's 40/70 Hz, the ends of
/// the identification grid, and a rigid axis beside a resonant one.
pub const PAIRS: [(Option<f64>, Option<f64>); 5] = [
    (Some(40.0), Some(70.0)),
    (Some(15.0), Some(30.0)),
    (Some(70.0), Some(150.0)),
    (Some(150.0), Some(300.0)),
    (Some(40.0), None),
];
/// Accelerometer noise of the "on" rows (rad/s² per 16 kHz tick, `plant.acceleration_noise_std`):
/// 4 counts of the simulated accelerometer, the amplitude of the machine-end check's lowest
/// frequency's acceleration.
pub const NOISE_STD: f64 = 2.0;

/// `servo tune --device`'s check over the virtual drive (in process, 921 600 Bd) for every
/// axis of absorber pairs 15–300 Hz and a rigid axis, accelerometer noise off and on: drive
/// vs twin on the motor's pseudo-circle and at the machine end, and the machine end against
/// the other axis before and after the correction.
#[derive(clap::Args)]
pub struct TuneDeviceBenchArgs {
    #[command(flatten)]
    pub common: Common,
    /// Keep each case's raw per-sample traces (the drive's streamed samples and the twin's:
    /// hundreds of megabytes over the bench); by default they are removed once the case's
    /// figures, tables and plots are written
    #[arg(long)]
    pub keep_raw: bool,
}

/// One axis's check.
#[derive(Clone, Debug, Serialize)]
pub struct TuneDeviceCase {
    pub pair: (Option<f64>, Option<f64>),
    pub axis: String,
    pub noise_std: f64,
    /// Pseudo-circle drive − twin, largest over both runs (encoder counts).
    pub circle_counts: f64,
    /// Machine end drive − twin, largest over both runs and frequencies (dB, degrees), and
    /// relative (|ΔH|/|H|) and in standard errors.
    pub machine_end: (f64, f64),
    pub machine_end_relative: (f64, f64),
    /// Machine end drive − twin as a share of its bound (`GOAL_FLOOR` + `GOAL_STANDARD_ERRORS`
    /// standard errors), largest over both runs and frequencies (at most 1; infinite where a
    /// difference is not a number).
    pub machine_end_share_of_bound: f64,
    /// The sine's amplitude (rad: lowered from the default where the accelerometer would clip).
    pub amplitude: f64,
    /// Machine end against the other axis up to the bandwidth: before, after (dB, degrees).
    pub versus_other: Option<((f64, f64), (f64, f64))>,
    /// The FMU check's spread between the axes: before, after (dB, degrees).
    pub fmu_spread: Option<((f64, f64), (f64, f64))>,
    pub wall_time_s: f64,
    pub report: TuneDeviceCheck,
}

fn model(axis: &str, hz: Option<f64>) -> AxisModel {
    let load = PlantParams::default().load_inertia;
    let parameters = hz.map(|h| absorber_parameters(h, DAMPING, load)).unwrap_or_default();
    let fmu_parameters: BTreeMap<String, f64> = parameters.iter().map(|(k, v)| (k.clone(), v.as_f64())).collect();
    let anti_resonance = hz.map(|_| {
        let p = |n: &str| fmu_parameters[n];
        true_anti_resonance(
            p(name::plant_absorber_inertia),
            p(name::plant_absorber_stiffness),
            p(name::plant_absorber_damping),
        )
    });
    AxisModel {
        axis: axis.into(),
        anti_resonance,
        resonance: None,
        gain: 1.0 / (PlantParams::default().motor_inertia + load),
        band: (5.0, 500.0),
        fit_error: 0.0,
        anti_resonance_error: None,
        fmu_parameters,
    }
}

fn check_axis(
    fmu: &Fmu,
    tuning: &crate::ident::tuning::Tuning,
    axis: &crate::ident::tuning::TunedAxis,
    noise_std: f64,
    (out, seed): (&Path, u64),
) -> Result<TuneDeviceCheck> {
    let mut parameters: BTreeMap<String, Value> =
        axis.fmu_parameters.iter().map(|(k, v)| (k.clone(), Value::Float(*v))).collect();
    parameters.insert(name::plant_acceleration_noise_std.into(), Value::Float(noise_std));
    let mut session = crate::virtual_drive::in_process::commissioned_session(&parameters, LineSettings::default())?;
    // The drive runs on between the host's requests, as behind a real line: each case starts
    // its runs from states of its own.
    session.link.port_mut().lag_requests(crate::device::bench::REQUEST_LAG_S, seed);
    let frame = out.join(format!("{}.corr.frame", axis.axis));
    let device = out.join(format!("device_{}_{}", axis.axis, if noise_std > 0.0 { "noise" } else { "clean" }));
    check_on_device(
        &*fmu.as_twin_of(&session.params_for_twin()?)?,
        tuning,
        axis,
        ("in-process virtual drive", &mut session),
        &frame,
        &device,
        |_, _| {},
    )
}

pub fn bench(fmu: &Fmu, out: &Path, mut progress: impl FnMut(f64)) -> Result<Vec<TuneDeviceCase>> {
    let count = std::f64::consts::TAU / control_core::Params::default().encoder_counts_per_rev as f64;
    let mut cases = Vec::new();
    let total = (PAIRS.len() * 4) as f64;
    for &(x, y) in &PAIRS {
        let label = |h: Option<f64>| h.map_or("rigid".into(), |h| format!("{h}"));
        let dir = out.join(format!("{}_{}", label(x), label(y)));
        let models = [model("x", x), model("y", y)];
        // The tuning's runs on the models are the drive's twin's (its check then runs both).
        let tuning = tune(&fmu.as_drive_twin(), &models, Method::Response, true, |_| {})?;
        write(&tuning, &dir)?;
        for axis in &tuning.axes {
            for noise_std in [0.0, NOISE_STD] {
                progress(cases.len() as f64 / total);
                let started = std::time::Instant::now();
                let r = check_axis(fmu, &tuning, axis, noise_std, (&dir, cases.len() as u64 + 1))?;
                let m = &r.machine_end;
                let largest = |a: (f64, f64), b: (f64, f64)| (a.0.max(b.0), a.1.max(b.1));
                cases.push(TuneDeviceCase {
                    pair: (x, y),
                    axis: axis.axis.clone(),
                    noise_std,
                    circle_counts: r.without.difference.largest.max(r.with.difference.largest) / count,
                    machine_end: largest(m.without.largest_difference, m.with.largest_difference),
                    machine_end_relative: largest(
                        (m.without.largest_relative_difference, m.without.largest_standard_errors),
                        (m.with.largest_relative_difference, m.with.largest_standard_errors),
                    ),
                    machine_end_share_of_bound: [&m.without, &m.with]
                        .iter()
                        .flat_map(|run| &run.points)
                        .map(|p| share_of_bound(p.relative_difference, p.standard_error))
                        .fold(0.0, f64::max),
                    amplitude: m.amplitude,
                    versus_other: m.without.largest_versus_other_axes.zip(m.with.largest_versus_other_axes),
                    fmu_spread: m.fmu_spread,
                    wall_time_s: started.elapsed().as_secs_f64(),
                    report: r,
                });
            }
        }
    }
    Ok(cases)
}

impl TuneDeviceBenchArgs {
    pub fn run(&self) -> Result<bool> {
        let c = &self.common;
        let fmu = Fmu::load(&c.fmu.clone().unwrap_or_else(default_fmu))?;
        let out = c.out.clone().unwrap_or_else(|| default_out("bench/tune-device"));
        let pb = progress_bar("tune-device bench", c.json);
        let cases = bench(&fmu, &out, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        crate::bench::raw_traces::tidy(&out, self.keep_raw)?;
        let ok = cases.iter().all(|c| c.report.passed);
        let worst = |f: &dyn Fn(&TuneDeviceCase) -> f64| cases.iter().map(f).fold(0.0, f64::max);
        crate::bench::figures::Recorder::new("tune-device")
            .at_most(
                "pseudo-circle over the link to the virtual drive: drive vs twin",
                worst(&|c| c.circle_counts),
                GOAL_COUNTS,
                "counts",
            )
            .info(
                "machine end, drive vs twin, largest share of the response",
                100.0 * worst(&|c| c.machine_end_relative.0),
                "%",
            )
            .at_most(
                "machine end, drive vs twin, largest share of its bound (the floor plus 5 standard errors)",
                worst(&|c| c.machine_end_share_of_bound),
                1.0,
                "",
            )
            .equal("cases missing a goal", cases.iter().filter(|c| !c.report.passed).count() as f64, 0.0, "")
            .write(c.out.as_deref(), ok)?;
        if c.json {
            let j = serde_json::json!({"bench": "tune-device", "cases": cases, "passed": ok});
            println!("{}", serde_json::to_string_pretty(&j)?);
            return Ok(ok);
        }
        print(&cases);
        println!("  goal on every row: {}", if ok { "met" } else { "NOT met" });
        Ok(ok)
    }
}

fn print(cases: &[TuneDeviceCase]) {
    println!(
        "servo bench tune-device — servo tune --device's check over the virtual drive (in process, 921 600 Bd), response method, absorber pairs (damping {DAMPING}) and a rigid axis, accelerometer noise off and {NOISE_STD} rad/s² a tick"
    );
    println!(
        "  goals: drive − twin ≤ {GOAL_COUNTS} counts on the pseudo-circle; at the machine end |H_drive − H_twin| ≤ {} % of |H| + {GOAL_STANDARD_ERRORS} standard errors (every frequency, both runs); the machine end closer to the other axis with the correction than without (up to the bandwidth); 0 samples lost",
        100.0 * GOAL_FLOOR
    );
    println!(
        "  {:>12} {:>4} {:>6} {:>8} {:>7} {:>18} {:>14} {:>22} {:>22} {:>22} {:>6}  goal",
        "pair Hz",
        "axis",
        "noise",
        "circle",
        "mrad",
        "machine end",
        "rel. % / σ",
        "vs other: before",
        "after",
        "FMU check: after",
        "wall s"
    );
    let h = |v: Option<f64>| v.map_or("rigid".to_string(), |x| format!("{x}"));
    let pair = |v: Option<(f64, f64)>| v.map_or("-".to_string(), |(a, b)| format!("{a:.4} dB {b:.3}°"));
    for c in cases {
        println!(
            "  {:>12} {:>4} {:>6} {:>8.2} {:>7.2} {:>18} {:>14} {:>22} {:>22} {:>22} {:>6.1}  {}",
            format!("{}/{}", h(c.pair.0), h(c.pair.1)),
            c.axis,
            if c.noise_std > 0.0 { "on" } else { "off" },
            c.circle_counts,
            1e3 * c.amplitude,
            pair(Some(c.machine_end)),
            format!("{:.3}/{:.2}", 100.0 * c.machine_end_relative.0, c.machine_end_relative.1),
            pair(c.versus_other.map(|v| v.0)),
            pair(c.versus_other.map(|v| v.1)),
            pair(c.fmu_spread.map(|v| v.1)),
            c.wall_time_s,
            if c.report.passed { "met" } else { "MISSED" }
        );
    }
    for noisy in [false, true] {
        let rows: Vec<&TuneDeviceCase> = cases.iter().filter(|c| (c.noise_std > 0.0) == noisy).collect();
        let worst = |f: &dyn Fn(&TuneDeviceCase) -> f64| rows.iter().map(|c| f(c)).fold(0.0f64, f64::max);
        println!(
            "  worst, noise {}: circle drive − twin {:.2} counts; machine end drive − twin {:.4} dB, {:.3}°, {:.3} % of the response, {:.2} standard errors; after the correction vs the other axis {:.4} dB, {:.3}°",
            if noisy { "on" } else { "off" },
            worst(&|c| c.circle_counts),
            worst(&|c| c.machine_end.0),
            worst(&|c| c.machine_end.1),
            100.0 * worst(&|c| c.machine_end_relative.0),
            worst(&|c| c.machine_end_relative.1),
            worst(&|c| c.versus_other.map_or(0.0, |v| v.1 .0)),
            worst(&|c| c.versus_other.map_or(0.0, |v| v.1 .1)),
        );
    }
}
