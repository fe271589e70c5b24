//! `servo sweep --device`: the sweep on the drive, its twin on the FMU (the same run: the
//! drive's parameters, plant and sweep settings), their difference per frequency point, and
//! what the link carried — in a table, a Bode plot with both curves, CSV and JSON.

use std::path::{Path, PathBuf};

use anyhow::Result;
use serde::Serialize;

use crate::analysis::response_point::{difference, same_frequency, ResponsePoint};
use crate::device::session::DriveSession;
use crate::fmu::runner::Fmu;
use crate::fmu::sweep_run::SweepRun;
use crate::fmu::trace::Trace;
use crate::plot::bode::plot_bode;
use crate::sweep::device::{sweep_on_drive, DeviceSweep};
use crate::sweep::measurement::stream_results;
use crate::sweep::report::{imprecise, imprecise_warning, precision_target_db};
use crate::sweep::standard_error::ResponseStandardError;

/// One frequency point: the drive's response, the twin's, and the difference.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct TwinPoint {
    pub frequency: f64,
    pub drive: ResponsePoint,
    pub twin: ResponsePoint,
    pub difference_db: f64,
    pub difference_deg: f64,
    /// Share of the drive's samples at this frequency acquired with its output limited (0..1,
    /// from the stream's flags).
    pub limited_share: f64,
    /// Standard error of the drive's result (see [`crate::sweep::standard_error`]).
    pub standard_error: ResponseStandardError,
}

impl TwinPoint {
    /// Hz, the drive's dB, degrees, quality and standard errors (dB, degrees), the twin's dB
    /// and degrees, the differences, the drive's limited share.
    pub fn values(&self) -> [f64; 11] {
        let (d, t) = (&self.drive, &self.twin);
        [
            self.frequency,
            d.gain_db,
            d.phase_deg,
            d.quality,
            self.standard_error.gain_db,
            self.standard_error.phase_deg,
            t.gain_db,
            t.phase_deg,
            self.difference_db,
            self.difference_deg,
            self.limited_share,
        ]
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct DeviceSweepReport {
    pub port: String,
    pub drive: DeviceSweep,
    pub twin_measurement_time_s: f64,
    pub points: Vec<TwinPoint>,
    /// Largest |drive − twin| over the points: (dB, degrees).
    pub largest_difference: (f64, f64),
    /// The largest difference as a share of its point's bound: (gain, phase), and the
    /// frequencies beyond it (see [`crate::device::bench::difference_bound`]).
    pub largest_share_of_bound: (f64, f64),
    pub beyond_bound_hz: Vec<f64>,
    /// Frequencies measured by only one of the two (Hz).
    pub missing: Vec<f64>,
    /// The precision (dB) the drive's standard errors are held against and the frequencies
    /// whose error exceeds twice it (see [`crate::sweep::report::imprecise`]).
    pub precision_target_db: f64,
    pub imprecise_hz: Vec<f64>,
    /// Every sample arrived (none dropped by the drive, no frame lost on the line), every
    /// frequency is in both, and they agree within each point's bound (the current converter's
    /// `device::bench::QUANTISATION` plus `GOAL_DB`, `GOAL_DEG` where the drive measured the
    /// point to the precision target; at most a quarter of the points measured less precisely,
    /// see `device::bench::difference_bound`).
    pub passed: bool,
    /// The line's capacity at the baud rate (bytes/s), and the share the sweep used.
    pub line_capacity_bytes_per_s: f64,
    pub line_use: f64,
    pub files: Vec<PathBuf>,
}

/// The drive's sweep and its twin's, compared at each frequency both measured; a frequency
/// only one of them has makes the largest difference infinite (and is listed by `missing`).
pub fn compare_with_twin(drive: &DeviceSweep, twin: &[ResponsePoint]) -> (Vec<TwinPoint>, (f64, f64)) {
    let mut largest = (0.0f64, 0.0f64);
    let points: Vec<TwinPoint> = drive
        .stream
        .iter()
        .enumerate()
        .filter_map(|(k, d)| {
            let t = twin.iter().find(|t| same_frequency(t.frequency, d.frequency))?;
            let (dg, dp) = difference(d, t);
            largest = (largest.0.max(dg.abs()), largest.1.max(dp.abs()));
            // `limited_share` and `standard_error` pair with `stream` by index.
            let limited_share = drive.limited_share.get(k).copied().unwrap_or(0.0);
            let standard_error = drive.standard_error.get(k).copied().unwrap_or(ResponseStandardError::unknown());
            Some(TwinPoint {
                frequency: d.frequency,
                drive: *d,
                twin: *t,
                difference_db: dg,
                difference_deg: dp,
                limited_share,
                standard_error,
            })
        })
        .collect();
    if points.len() != drive.stream.len() || points.len() != twin.len() {
        largest = (f64::INFINITY, f64::INFINITY);
    }
    (points, largest)
}

/// The largest drive–twin difference as a share of its point's bound
/// ([`crate::device::bench::difference_bound`]): (gain, phase); at most 1 where every point
/// agrees.
pub fn largest_share_of_bound(points: &[TwinPoint]) -> (f64, f64) {
    points.iter().fold((0.0f64, 0.0f64), |w, p| {
        let (db, deg) = crate::device::bench::difference_bound(&p.standard_error);
        // NaN (a difference that is not a number) counts as beyond any bound.
        let share = |d: f64, b: f64| if (d / b).is_nan() { f64::INFINITY } else { d.abs() / b };
        (w.0.max(share(p.difference_db, db)), w.1.max(share(p.difference_deg, deg)))
    })
}

/// The frequencies whose drive–twin difference exceeds its bound.
pub fn beyond_bound_hz(points: &[TwinPoint]) -> Vec<f64> {
    points
        .iter()
        .filter(|p| {
            let (db, deg) = largest_share_of_bound(std::slice::from_ref(p));
            !(db <= 1.0 && deg <= 1.0)
        })
        .map(|p| p.frequency)
        .collect()
}

/// Frequencies one of the two sweeps has and the other has not.
pub fn missing(drive: &DeviceSweep, twin: &[ResponsePoint]) -> Vec<f64> {
    let has = |v: &[ResponsePoint], f: f64| v.iter().any(|p| same_frequency(p.frequency, f));
    let mut m: Vec<f64> = drive.stream.iter().map(|p| p.frequency).filter(|&f| !has(twin, f)).collect();
    m.extend(twin.iter().map(|p| p.frequency).filter(|&f| !has(&drive.stream, f)));
    m
}

/// The twin: the same sweep on the FMU, its response from the stream as the drive's is.
pub fn twin_sweep(fmu: &Fmu, run: &SweepRun, progress: impl FnMut(f64)) -> Result<(Vec<ResponsePoint>, f64)> {
    let trace = run.run(fmu, progress)?;
    let time = crate::sweep::measurement::measured_time(&trace)?;
    Ok((stream_results(&trace, &run.settings)?, time))
}

pub fn run_on_device<T: crate::device::link::DrivePort>(
    fmu: &Fmu,
    run: &SweepRun,
    (port, session): (&str, &mut DriveSession<T>),
    out: &Path,
    mut progress: impl FnMut(&str, f64),
) -> Result<DeviceSweepReport> {
    crate::fmu::runner::refuse_drive_owned(run.parameters.keys())?;
    crate::paths::create_out_dir(out)?;
    let drive = match sweep_on_drive(session, run, |f| progress("sweep on the drive", f)) {
        Ok(d) => d,
        Err(e) => return Err(save_partial(session, out, "sweep", e)),
    };
    let mut files = vec![out.join("device_stream.csv")];
    drive.trace.write_csv(&files[0])?;
    let (twin, twin_time) = twin_sweep(fmu, run, |f| progress("twin on the FMU", f))?;
    let (points, largest) = compare_with_twin(&drive, &twin);
    let csv = out.join("sweep.csv");
    let mut t = Trace::new(
        [
            "frequency",
            "gain_db",
            "phase_deg",
            "quality",
            "gain_se_db",
            "phase_se_deg",
            "twin_gain_db",
            "twin_phase_deg",
            "diff_db",
            "diff_deg",
            "limited_share",
        ]
        .map(String::from)
        .to_vec(),
    );
    for p in &points {
        t.rows.push(p.values());
    }
    t.write_csv(&csv)?;
    let svg = out.join("bode.svg");
    plot_bode(
        &svg,
        &format!("Frequency response on the drive at {port}, and its FMU twin"),
        &[("drive (stream over the link)", &drive.stream), ("FMU twin", &twin)],
        None,
    )?;
    files.extend([csv, svg]);
    let capacity = session_capacity(session);
    let beyond_bound_hz = beyond_bound_hz(&points);
    let largest_share_of_bound = largest_share_of_bound(&points);
    let imprecise_points =
        points.iter().filter(|p| !crate::device::bench::measured_to_target(&p.standard_error)).count();
    let mostly_precise = imprecise_points as f64 <= crate::device::bench::IMPRECISE_SHARE * points.len() as f64;
    // Something compared: a drive and a twin that both measured nothing have not agreed.
    let passed = !points.is_empty()
        && drive.dropped == 0
        && drive.corrupt_frames == 0
        && largest.0.is_finite()
        && beyond_bound_hz.is_empty()
        && mostly_precise;
    let precision_target_db = precision_target_db(&run.settings);
    let imprecise_hz = imprecise(&drive.stream, &drive.standard_error, precision_target_db);
    let report = DeviceSweepReport {
        port: port.to_string(),
        precision_target_db,
        imprecise_hz,
        line_use: drive.link_bytes_per_s / capacity,
        missing: missing(&drive, &twin),
        drive,
        twin_measurement_time_s: twin_time,
        points,
        largest_difference: largest,
        largest_share_of_bound,
        beyond_bound_hz,
        passed,
        line_capacity_bytes_per_s: capacity,
        files: files.clone(),
    };
    let json = out.join("sweep.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    files.push(json);
    Ok(DeviceSweepReport { files, ..report })
}

/// The sweep stopped: what the drive streamed so far goes to `<name>_partial.csv`, marked
/// incomplete in `<name>.json` with the reason; the error says where.
pub fn save_partial<T: crate::device::link::DrivePort>(
    session: &mut DriveSession<T>,
    out: &Path,
    name: &str,
    e: anyhow::Error,
) -> anyhow::Error {
    let batches = session.take_samples();
    let rows = crate::device::frame_stream::sample_rows(&batches).unwrap_or_default();
    let csv = out.join(format!("{name}_partial.csv"));
    let mut t = Trace::new(crate::device::frame_stream::SAMPLE_COLUMNS.map(String::from).to_vec());
    for r in &rows {
        t.rows.push(r);
    }
    let json =
        serde_json::json!({"complete": false, "reason": format!("{e:#}"), "samples": rows.len(), "partial": csv});
    let saved = t.write_csv(&csv).is_ok()
        && std::fs::write(out.join(format!("{name}.json")), serde_json::to_string_pretty(&json).unwrap_or_default())
            .is_ok();
    if saved {
        e.context(format!("{name} incomplete: {} samples saved in {}", rows.len(), csv.display()))
    } else {
        e.context(format!("{name} incomplete"))
    }
}

fn session_capacity<T: crate::device::link::DrivePort>(session: &DriveSession<T>) -> f64 {
    session.baud as f64 / crate::virtual_drive::uart::BITS_PER_BYTE
}

impl DeviceSweepReport {
    pub fn print(&self) {
        let d = &self.drive;
        println!(
            "servo sweep on the drive at {} — {} frequencies, {:.3} s of the drive's time (twin {:.3} s)",
            self.port,
            d.stream.len(),
            d.measurement_time_s,
            self.twin_measurement_time_s
        );
        println!(
            "  {:>10} {:>10} {:>10} {:>8} {:>8} {:>8} {:>10} {:>10} {:>9} {:>9} {:>9}",
            "Hz",
            "gain dB",
            "phase deg",
            "quality",
            "± dB",
            "± deg",
            "twin dB",
            "twin deg",
            "diff dB",
            "diff deg",
            "limited %"
        );
        for p in &self.points {
            let [f, g, ph, q, sg, sp, tg, tp, dg, dp, l] = p.values();
            let limited = if l > 0.0 { format!("{:.1}", 100.0 * l) } else { String::new() };
            println!(
                "  {f:>10.2} {g:>10.3} {ph:>10.2} {q:>8.4} {sg:>8.3} {sp:>8.2} {tg:>10.3} {tp:>10.2} {dg:>9.3} {dp:>9.2} {limited:>9}"
            );
        }
        println!(
            "  drive vs twin: largest difference {:.3} dB, {:.2} deg (the current converter's {} dB, {} deg plus {} dB, {} deg, or plus 5 standard \
             errors, at most 5 times that, at a point the drive measured less precisely than {} dB / {} deg: {:.2} / {:.2} of that bound){}{}",
            self.largest_difference.0,
            self.largest_difference.1,
            crate::device::bench::QUANTISATION.0,
            crate::device::bench::QUANTISATION.1,
            crate::device::bench::GOAL_DB,
            crate::device::bench::GOAL_DEG,
            crate::device::bench::PRECISION.0,
            crate::device::bench::PRECISION.1,
            self.largest_share_of_bound.0,
            self.largest_share_of_bound.1,
            if self.beyond_bound_hz.is_empty() {
                String::new()
            } else {
                format!("; beyond it at {:?} Hz", self.beyond_bound_hz)
            },
            if self.missing.is_empty() {
                String::new()
            } else {
                format!("; measured by one only: {:?} Hz", self.missing)
            }
        );
        if !d.limited_hz.is_empty() {
            println!("  WARNING: {}", crate::sweep::measurement::limited_warning(&d.limited_hz));
        }
        if !self.imprecise_hz.is_empty() {
            println!("  WARNING: {}", imprecise_warning(&self.imprecise_hz, self.precision_target_db));
        }
        println!(
            "  link: {} samples, {} dropped by the drive, {} frame(s) lost on the line; {:.0} B/s of {:.0} B/s ({:.0} % of the line)",
            d.samples,
            d.dropped,
            d.corrupt_frames,
            d.link_bytes_per_s,
            self.line_capacity_bytes_per_s,
            100.0 * self.line_use
        );
        for f in &self.files {
            println!("  → {}", f.display());
        }
    }
}
