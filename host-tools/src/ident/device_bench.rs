//! `servo bench ident-device`: seed 001's identification over a drive (the virtual drive in
//! this process, deterministic, over the simulated 921 600 Bd line) for the absorbers of
//! `servo bench ident`'s grid (15–300 Hz, 5 % damping) and a rigid axis, without accelerometer
//! noise and at the grid's 20 dB SNR: the identified anti-resonance against the plant's
//! analytic one and against the FMU twin's, the largest per-point difference from the twin,
//! the wall time of the measurement, and what the link carried.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use serde::Serialize;
use servo_axis::plant::PlantParams;
use servo_axis::variables::name;

use crate::cli::{progress_bar, Common};
use crate::device::link::DeviceLink;
use crate::device::session::DriveSession;
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::ident::bench::{masked_by_plant, AMPLITUDE, DAMPING, DAMPING_GOAL, FREQUENCY_GOAL, GRID_HZ, SNR_DB};
use crate::ident::device::{identify_on_device, DeviceIdentRequest, DeviceIdentification};
use crate::ident::device::{GOAL_DAMPING, GOAL_HZ, GOAL_STANDARD_ERRORS};
use crate::ident::identification::{absorber_parameters, acceleration_rms};
use crate::paths::{default_fmu, default_out};
use crate::virtual_drive::flash::FileFlash;
use crate::virtual_drive::in_process::InProcessDrive;
use crate::virtual_drive::simulator::{VirtualDrive, VirtualDriveSettings};
use crate::virtual_drive::uart::LineSettings;

/// Time the bench gives each answer (the drive runs in this process: generous).
const ANSWER_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// Seed 001's identification over a drive (the virtual drive in this process, 921 600 Bd):
/// absorbers 15–300 Hz and a rigid axis, accelerometer noise off and at 20 dB SNR; the
/// identified anti-resonance against the analytic plant and the FMU twin, the largest
/// per-point difference from the twin, wall time, link use and lost samples.
#[derive(clap::Args)]
pub struct IdentDeviceBenchArgs {
    #[command(flatten)]
    pub common: Common,
    /// Keep each case's raw per-sample traces (the drive's streamed samples and the twin's:
    /// hundreds of megabytes over the bench); by default they are removed once the case's
    /// figures, tables and plots are written
    #[arg(long)]
    pub keep_raw: bool,
}

/// One identification over the virtual drive.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceCase {
    /// The absorber's anti-resonance (Hz), None for the rigid axis.
    pub hz: Option<f64>,
    /// Accelerometer noise (rad/s² per tick; 0: none) and the SNR it was set for.
    pub noise_std: f64,
    pub snr_db: Option<f64>,
    pub report: DeviceIdentification,
}

impl DeviceCase {
    /// The drive within `servo bench ident`'s goals against the analytic plant; drive and twin
    /// within [`GOAL_STANDARD_ERRORS`] at every point, no sample lost (`DeviceIdentification::
    /// passed`); without accelerometer noise, their anti-resonances within [`GOAL_HZ`] and
    /// [`GOAL_DAMPING`].
    pub fn passed(&self) -> bool {
        let r = &self.report;
        let against_truth = match (self.hz, r.truth_error) {
            (Some(_), Some((f, d))) => f.abs() <= FREQUENCY_GOAL && d.abs() <= DAMPING_GOAL,
            // None found: right only where the plant masks its anti-resonance (as `servo bench
            // ident` counts it).
            (Some(h), None) => masked_by_plant(h),
            (None, _) => r.drive.model.as_ref().is_some_and(|m| m.anti_resonance.is_none()),
        };
        // Without accelerometer noise the two identify the same anti-resonance closely.
        let against_twin = self.snr_db.is_some()
            || r.anti_resonance_difference.is_none_or(|(f, d)| f.abs() <= GOAL_HZ && d.abs() <= GOAL_DAMPING);
        against_truth && against_twin && r.passed
    }
}

/// One axis identified on a fresh virtual drive with the plant of `parameters`, the drive
/// running on between requests from a start state drawn from `seed` (as for `servo bench
/// device`).
fn identify_case(
    fmu: &Fmu,
    parameters: &BTreeMap<String, Value>,
    (out, seed): (&Path, u64),
) -> Result<DeviceIdentification> {
    let c = configuration(parameters)?;
    let vd =
        VirtualDriveSettings { defaults: c.control, plant: c.plant, line: LineSettings::default(), faults: vec![] };
    let drive = VirtualDrive::power_on(&vd, FileFlash::in_memory())?;
    let mut session = DriveSession::open(DeviceLink::new(InProcessDrive::new(drive), ANSWER_TIMEOUT))?;
    session.baud = LineSettings::default().baud;
    session.commission_with_defaults()?;
    session.link.port_mut().lag_requests(crate::device::bench::REQUEST_LAG_S, seed);
    let request = DeviceIdentRequest { axis: "x", parameters, amplitude: AMPLITUDE };
    identify_on_device(
        &*fmu.as_twin_of(&session.params_for_twin()?)?,
        &request,
        ("in-process virtual drive", &mut session),
        out,
        |_, _| {},
    )
}

pub fn bench(fmu: &Fmu, out: &Path, mut progress: impl FnMut(f64)) -> Result<Vec<DeviceCase>> {
    let load = PlantParams::default().load_inertia;
    let axes: Vec<Option<f64>> = GRID_HZ.iter().map(|&h| Some(h)).chain([None]).collect();
    let mut cases = Vec::new();
    let total = 2 * axes.len();
    for (i, hz) in axes.iter().enumerate() {
        let parameters = hz.map(|h| absorber_parameters(h, DAMPING, load)).unwrap_or_default();
        let label = hz.map_or("rigid".to_string(), |h| format!("{h}hz"));
        for (j, snr_db) in [None, Some(SNR_DB)].into_iter().enumerate() {
            progress((2 * i + j) as f64 / total as f64);
            let mut p = parameters.clone();
            // As `servo ident --snr-db`: the noise per tick for that SNR of the record's means.
            let noise_std = match snr_db {
                None => 0.0,
                Some(snr) => {
                    let rms = acceleration_rms(&fmu.as_drive_twin(), &parameters, AMPLITUDE)?;
                    let ticks = (crate::fmu::scenario::DEFAULT_STEP
                        * control_core::Params::default().rates.current_loop_hz as f64)
                        .round();
                    rms / 10f64.powf(snr / 20.0) * ticks.sqrt()
                }
            };
            p.insert(name::plant_acceleration_noise_std.into(), Value::Float(noise_std));
            let dir = out.join(format!("{label}_{}", if snr_db.is_some() { "noise" } else { "clean" }));
            let report = identify_case(fmu, &p, (&dir, cases.len() as u64 + 1))?;
            cases.push(DeviceCase { hz: *hz, noise_std, snr_db, report });
        }
    }
    Ok(cases)
}

impl IdentDeviceBenchArgs {
    pub fn run(&self) -> Result<bool> {
        let c = &self.common;
        let fmu = Fmu::load(&c.fmu.clone().unwrap_or_else(default_fmu))?;
        let out = c.out.clone().unwrap_or_else(|| default_out("bench/ident-device"));
        let pb = progress_bar("ident-device bench", c.json);
        let cases = bench(&fmu, &out, |f| pb.set_position((f * 1000.0) as u64))?;
        pb.finish_and_clear();
        crate::bench::raw_traces::tidy(&out, self.keep_raw)?;
        let ok = cases.iter().all(DeviceCase::passed);
        let worst = |f: &dyn Fn(&DeviceCase) -> f64| cases.iter().map(f).fold(0.0, f64::max);
        crate::bench::figures::Recorder::new("ident-device")
            .at_most(
                "identification over the link to the virtual drive: drive vs twin per point",
                worst(&|c| c.report.largest_standard_errors),
                GOAL_STANDARD_ERRORS,
                "standard errors",
            )
            .equal(
                "samples lost or corrupt",
                cases.iter().map(|c| c.report.link.dropped as f64 + c.report.link.corrupt_frames as f64).sum(),
                0.0,
                "",
            )
            .equal("cases missing a goal", cases.iter().filter(|c| !c.passed()).count() as f64, 0.0, "")
            .write(c.out.as_deref(), ok)?;
        if c.json {
            let j = serde_json::json!({"bench": "ident-device", "cases": cases, "passed": ok});
            println!("{}", serde_json::to_string_pretty(&j)?);
            return Ok(ok);
        }
        print(&cases);
        println!("  goal on every row: {}", if ok { "met" } else { "NOT met" });
        Ok(ok)
    }
}

fn print(cases: &[DeviceCase]) {
    println!(
        "servo bench ident-device — seed 001 over the virtual drive (in process, 921 600 Bd): absorbers {}–{} Hz (damping {DAMPING}) and a rigid axis, accelerometer noise off and at {SNR_DB} dB SNR",
        GRID_HZ[0],
        GRID_HZ[GRID_HZ.len() - 1]
    );
    println!(
        "  goals: drive vs analytic plant {} % / {} % (as servo bench ident); drive vs twin: every point within {GOAL_STANDARD_ERRORS} standard errors of the difference, and with noise off the anti-resonance within {} % / {} %; 0 samples lost",
        100.0 * FREQUENCY_GOAL,
        100.0 * DAMPING_GOAL,
        100.0 * GOAL_HZ,
        100.0 * GOAL_DAMPING
    );
    println!(
        "  {:>6} {:>6} {:>16} {:>16} {:>16} {:>6} {:>8} {:>7} {:>9} {:>7}  goal",
        "Hz", "noise", "vs plant Hz/ζ %", "vs twin Hz/ζ %", "points dB/deg", "σ", "wall s", "drive s", "B/s", "lost"
    );
    let pair = |v: Option<(f64, f64)>, digits: usize| {
        v.map_or("-".to_string(), |(a, b)| format!("{:+.*}/{:+.*}", digits, 100.0 * a, digits.min(2), 100.0 * b))
    };
    for c in cases {
        let r = &c.report;
        println!(
            "  {:>6} {:>6} {:>16} {:>16} {:>16} {:>6.2} {:>8.2} {:>7.2} {:>9.0} {:>7}  {}",
            c.hz.map_or("rigid".into(), |h| format!("{h}")),
            if c.snr_db.is_some() { "20 dB" } else { "off" },
            match (c.hz, r.truth_error) {
                (None, _) =>
                    if r.drive.model.as_ref().is_some_and(|m| m.anti_resonance.is_none()) {
                        "rigid".into()
                    } else {
                        "NOTCH".into()
                    },
                (Some(h), None) if masked_by_plant(h) => "masked".into(),
                (Some(_), e) => pair(e, 3),
            },
            pair(r.anti_resonance_difference, 3),
            format!("{:.3}/{:.2}", r.largest_difference.0, r.largest_difference.1),
            r.largest_standard_errors,
            r.wall_time_s,
            r.measurement_time_s,
            r.link.bytes_per_s,
            r.link.dropped as u64 + r.link.corrupt_frames,
            if c.passed() { "met" } else { "MISSED" }
        );
    }
    let worst = |noisy: bool, key: &dyn Fn(&DeviceCase) -> Option<f64>| {
        cases
            .iter()
            .filter(|c| c.snr_db.is_some() == noisy)
            .filter_map(|c| key(c).map(|v| (v.abs(), c.hz)))
            .max_by(|a, b| a.0.total_cmp(&b.0))
    };
    let show = |w: Option<(f64, Option<f64>)>, scale: f64, unit: &str| {
        w.map_or("-".to_string(), |(v, hz)| {
            format!("{:.3} {unit} at {}", v * scale, hz.map_or("the rigid axis".into(), |h| format!("{h} Hz")))
        })
    };
    for (noisy, label) in [(false, "noise off"), (true, "20 dB SNR")] {
        println!("  worst, {label}:");
        println!(
            "    drive vs analytic plant: frequency {}, damping {}",
            show(worst(noisy, &|c| c.report.truth_error.map(|e| e.0)), 100.0, "%"),
            show(worst(noisy, &|c| c.report.truth_error.map(|e| e.1)), 100.0, "%")
        );
        println!(
            "    drive vs twin: anti-resonance frequency {}, damping {}; per point {}, {}, {}",
            show(worst(noisy, &|c| c.report.anti_resonance_difference.map(|e| e.0)), 100.0, "%"),
            show(worst(noisy, &|c| c.report.anti_resonance_difference.map(|e| e.1)), 100.0, "%"),
            show(worst(noisy, &|c| Some(c.report.largest_difference.0)), 1.0, "dB"),
            show(worst(noisy, &|c| Some(c.report.largest_difference.1)), 1.0, "deg"),
            show(worst(noisy, &|c| Some(c.report.largest_standard_errors)), 1.0, "standard errors")
        );
    }
    let wall = cases.iter().map(|c| c.report.wall_time_s).fold(0.0, f64::max);
    let drive_s = cases.iter().map(|c| c.report.measurement_time_s).fold(0.0, f64::max);
    let bytes = cases.iter().map(|c| c.report.link.bytes_per_s).fold(0.0, f64::max);
    let capacity = cases.first().map_or(f64::NAN, |c| c.report.link.capacity_bytes_per_s);
    let lost: u64 = cases.iter().map(|c| c.report.link.dropped as u64 + c.report.link.corrupt_frames).sum();
    println!(
        "  measurement: {drive_s:.2} s of the drive's time, at most {wall:.2} s wall in this process (the drive simulated as fast as it runs); link at most {bytes:.0} B/s of {capacity:.0} B/s ({:.0} %), {lost} samples or frames lost over all cases",
        100.0 * bytes / capacity
    );
}
