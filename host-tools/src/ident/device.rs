//! `servo ident --device`: seed 001's identification over a drive, beside its FMU twin.
//!
//! The drive runs the same M-sequence as the FMU identification (degree 11, chips at 1 kHz, on
//! the torque command at 20 rad/s) as its PRBS sweep with the machine-end acceleration measure
//! (`sweep.measure` 1): each acquisition sample is U = kt·iq from the drive's measured
//! currents and Y = the removable accelerometer's machine-end acceleration, both means over
//! the acquisition period. The samples stream over the link (`sweep::device`); the host
//! averages the last 8 periods and takes the DFT ratio (`averaged_response`, shared with the
//! FMU path), finds the notch and fits the model (`identification::identify`), exactly as on
//! the FMU.
//!
//! The twin: the FMU runs the same sweep with the drive's parameters, through the same core
//! path (the FMU feeds its plant's accelerometer to the core as the drive's input does), and
//! its stream is analysed the same way. On the virtual drive the two measure the same plant
//! with the same core; they differ only by what the simulated board adds: the 12-bit
//! quantisation of the currents (15.6 mA a count, the drive's kt·iq) and of the accelerometer
//! (0.48 rad/s² a count), and that the drive's plant starts from its own state (its noise and
//! its encoder's count pattern are not the twin's). See [`GOAL_STANDARD_ERRORS`] for the
//! figure they must meet.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Result};
use control_core::phase_shifted_sweep::SweepMeasure;
use serde::Serialize;

use crate::analysis::response_point::{difference, ResponsePoint};
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::twin::DriveTwinPoint;
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::SweepRun;
use crate::fmu::trace::Trace;
use crate::ident::averaged_response::{averaged_response, Record};
use crate::ident::identification::{
    excitation, identify, period_s, samples_per_period, true_anti_resonance, AxisModel, Factor, FitRefused, Measured,
    Notch, DIVIDER, PERIODS, TRANSIENT_S,
};
use crate::ident::report::BAND;
use crate::plot::bode::plot_bode;
use crate::sweep::device::sweep_on_drive;
use crate::sweep::device_report::save_partial;

/// The figure drive and twin must meet on the virtual drive, at every frequency point of the
/// band (5–500 Hz): |H_drive − H_twin| at most this many standard errors of the difference.
/// The same core measures the same plant on both, so what separates them is noise: the
/// board's quantisation (the drive's kt·iq from 12-bit currents, 15.6 mA a count; the
/// accelerometer at 0.48 rad/s² a count), the accelerometer noise the plant adds, and the
/// plant's own state (the drive's plant starts at its power-on, its noise draws and its
/// encoder's count pattern are not the twin's). Each measurement's standard error per point
/// comes from the scatter of its 8 averaged periods (`averaged_response`); a flat figure in dB
/// would not do: the noise is largest relative to the response where the closed velocity
/// loop leaves little excitation in the torque (below about 10 Hz: 1.2 dB there on the rigid
/// axis without accelerometer noise, 15 dB at 20 dB SNR) and smallest elsewhere. For ~1000
/// points of a complex Gaussian difference the largest is about 3.4 standard errors at 99 %
/// (P(|z| > r) = e^{−r²} per point); each standard error is itself estimated from 8 periods
/// (7 degrees of freedom), which widens the tail: 6.
pub const GOAL_STANDARD_ERRORS: f64 = 6.0;
/// The identified anti-resonance, drive against twin, without accelerometer noise (`servo
/// bench ident-device`): frequency and damping, relative. The fit spreads the points' noise
/// over the whole band: measured at most 0.014 % and 0.8 % over the 15–300 Hz grid.
pub const GOAL_HZ: f64 = 0.001;
pub const GOAL_DAMPING: f64 = 0.03;

/// One measurement and what was identified from it.
#[derive(Clone, Debug, Serialize)]
pub struct IdentifiedRun {
    #[serde(skip)]
    pub measured: Measured,
    pub model: Option<AxisModel>,
    pub notch: Option<Notch>,
    /// Why the fit was refused (no model then).
    pub refusal: Option<String>,
    /// Why a clear notch gave no anti-resonance (see `Identified::undetermined`).
    pub undetermined: Option<String>,
}

/// Identify `m` as the FMU path does; a refused fit is kept with its reason.
pub fn identify_run(axis: &str, measured: Measured, parameters: &BTreeMap<String, Value>) -> Result<IdentifiedRun> {
    match identify(axis, &measured) {
        Ok(i) => {
            let mut model = i.model;
            model.fmu_parameters = parameters.iter().map(|(k, v)| (k.clone(), v.as_f64())).collect();
            Ok(IdentifiedRun {
                measured,
                model: Some(model),
                notch: i.notch,
                refusal: None,
                undetermined: i.undetermined,
            })
        }
        Err(e) => {
            let refused = e.downcast_ref::<FitRefused>().cloned().ok_or(e)?;
            Ok(IdentifiedRun {
                measured,
                model: None,
                notch: Some(refused.notch),
                refusal: Some(refused.reason),
                undetermined: None,
            })
        }
    }
}

/// One frequency point: the drive's response, the twin's, their difference.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PointDifference {
    #[serde(flatten)]
    pub response: DriveTwinPoint,
    /// |H_drive − H_twin| over the standard error of that difference (both measurements'
    /// standard errors from their periods' scatter).
    pub standard_errors: f64,
}

/// What the link carried during the measurement.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct LinkUse {
    pub samples: usize,
    /// Samples the drive could not send (its ring full).
    pub dropped: u32,
    /// Frames lost on the line.
    pub corrupt_frames: u64,
    pub bytes_per_s: f64,
    pub capacity_bytes_per_s: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct DeviceIdentification {
    pub port: String,
    pub axis: String,
    pub drive: IdentifiedRun,
    pub twin: IdentifiedRun,
    pub points: Vec<PointDifference>,
    /// Largest |drive − twin| over the points (dB, degrees).
    pub largest_difference: (f64, f64),
    /// Largest |drive − twin| in standard errors of the difference (see [`GOAL_STANDARD_ERRORS`]).
    pub largest_standard_errors: f64,
    /// Drive's anti-resonance against the twin's: relative frequency and damping differences
    /// (None when either found none).
    pub anti_resonance_difference: Option<(f64, f64)>,
    /// The plant's analytic anti-resonance (its absorber's), when it has one.
    pub truth: Option<Factor>,
    /// The drive's anti-resonance against it: relative frequency and damping errors.
    pub truth_error: Option<(f64, f64)>,
    /// The drive's time of the measurement (s) and the wall time it took here (s).
    pub measurement_time_s: f64,
    pub wall_time_s: f64,
    pub link: LinkUse,
    /// Every sample arrived, both found an anti-resonance or both none, and every point agrees
    /// within [`GOAL_STANDARD_ERRORS`]. On a board the twin's plant is the user's model of the
    /// machine: a disagreement then says the model is off, not the measurement.
    pub passed: bool,
    pub files: Vec<PathBuf>,
}

/// The identification's sweep with the machine-end acceleration measure.
pub fn device_run(parameters: &BTreeMap<String, Value>, amplitude: f64) -> Result<SweepRun> {
    let fs = configuration(parameters)?.control.rates.current_loop_hz as f64;
    let period = period_s() * control_core::Params::default().rates.current_loop_hz as f64 / fs;
    let mut run = excitation(parameters, amplitude, TRANSIENT_S + PERIODS as f64 * period);
    run.settings.measure = SweepMeasure::MachineAcceleration;
    Ok(run)
}

/// The measured samples of a stream (`acq_*` columns, the drive's or the FMU's), each once,
/// in order; a gap (a sample lost) is an error: the periods could not be averaged.
pub fn record_samples(trace: &Trace, acquisition_s: f64) -> Result<(Vec<f64>, Vec<f64>)> {
    let col = |n: &str| trace.column(n).ok_or_else(|| anyhow!("the stream has no column {n}"));
    let (time, measuring, u, y) = (col("acq_time")?, col("acq_measuring")?, col("acq_u")?, col("acq_y")?);
    let (mut us, mut ys, mut last) = (Vec::new(), Vec::new(), None::<f64>);
    let mut gaps = 0;
    for i in 0..time.len() {
        if measuring[i] == 0.0 || last == Some(time[i]) {
            continue;
        }
        if last.is_some_and(|l| (time[i] - l - acquisition_s).abs() > 0.25 * acquisition_s) {
            gaps += 1;
        }
        last = Some(time[i]);
        us.push(u[i]);
        ys.push(y[i]);
    }
    if gaps > 0 {
        bail!("{gaps} gap(s) in the measured samples: samples were lost, the periods cannot be averaged");
    }
    Ok((us, ys))
}

/// The response of a stream's record over [`BAND`].
fn response_of(trace: &Trace, acquisition_hz: f64) -> Result<Measured> {
    let (u, y) = record_samples(trace, 1.0 / acquisition_hz)?;
    averaged_response(&Record { u: &u, y: &y, acquisition_hz }, samples_per_period(), PERIODS, BAND)
}

/// The drive's and the twin's responses compared point by point (the same frequency grid:
/// the same record length and rate).
pub fn compare(drive: &Measured, twin: &Measured) -> (Vec<PointDifference>, (f64, f64, f64)) {
    let mut largest = (0.0f64, 0.0f64, 0.0f64);
    let points: Vec<PointDifference> = drive
        .frequencies
        .iter()
        .zip(&drive.response)
        .zip(twin.frequencies.iter().zip(&twin.response))
        .zip(drive.standard_error.iter().zip(&twin.standard_error))
        .map(|(((&f, &hd), (&ft, &ht)), (&ed, &et))| {
            let (d, t) = (ResponsePoint::from_complex(f, hd, 1.0), ResponsePoint::from_complex(ft, ht, 1.0));
            let standard_errors = (hd - ht).norm() / ed.hypot(et);
            let (dg, dp) = if (f - ft).abs() <= 1e-9 * f { difference(&d, &t) } else { (f64::INFINITY, f64::INFINITY) };
            largest = (largest.0.max(dg.abs()), largest.1.max(dp.abs()), largest.2.max(standard_errors));
            PointDifference { response: DriveTwinPoint::new(&d, &t, (dg, dp)), standard_errors }
        })
        .collect();
    if drive.frequencies.len() != twin.frequencies.len() {
        largest = (f64::INFINITY, f64::INFINITY, f64::INFINITY);
    }
    (points, largest)
}

/// Relative frequency and damping differences of `a` against `reference`.
fn relative(a: Factor, reference: Factor) -> (f64, f64) {
    ((a.hz - reference.hz) / reference.hz, (a.damping - reference.damping) / reference.damping)
}

/// The plant's analytic anti-resonance from its absorber parameters, if it has one.
pub fn plant_truth(parameters: &BTreeMap<String, Value>) -> Result<Option<Factor>> {
    let plant = configuration(parameters)?.plant;
    Ok((plant.absorber_inertia > 0.0)
        .then(|| true_anti_resonance(plant.absorber_inertia, plant.absorber_stiffness, plant.absorber_damping)))
}

/// What an identification over a drive is given.
pub struct DeviceIdentRequest<'a> {
    pub axis: &'a str,
    /// The axis's FMU parameters (the drive gets their controller part, the twin all of them).
    pub parameters: &'a BTreeMap<String, Value>,
    /// M-sequence amplitude (N·m).
    pub amplitude: f64,
}

/// Identify `request.axis` on the drive behind `session`, and its twin on the FMU; files in
/// `out`. A measurement that stops (refused, a fault, the link lost) leaves what arrived in
/// `ident_partial.csv`, marked incomplete in `ident.json`, and is an error.
pub fn identify_on_device<T: DrivePort>(
    fmu: &Fmu,
    request: &DeviceIdentRequest,
    (port, session): (&str, &mut DriveSession<T>),
    out: &Path,
    mut progress: impl FnMut(&str, f64),
) -> Result<DeviceIdentification> {
    let (axis, parameters) = (request.axis, request.parameters);
    crate::fmu::runner::refuse_drive_owned(parameters.keys())?;
    crate::paths::create_out_dir(out)?;
    let run = device_run(parameters, request.amplitude)?;
    let rates = run.rates()?;
    let acquisition_hz = rates.current_loop_hz as f64 / DIVIDER as f64;
    let started = std::time::Instant::now();
    let on_drive = match sweep_on_drive(session, &run, |f| progress("identification on the drive", f)) {
        Ok(d) => d,
        Err(e) => return Err(save_partial(session, out, "ident", e)),
    };
    let wall_time_s = started.elapsed().as_secs_f64();
    let stream_csv = out.join(format!("{axis}.device_stream.csv"));
    on_drive.trace.write_csv(&stream_csv)?;
    let measured = response_of(&on_drive.trace, acquisition_hz).map_err(|e| {
        let json = serde_json::json!({"complete": false, "reason": format!("{e:#}"), "samples": on_drive.samples, "stream": stream_csv});
        let _ = std::fs::write(out.join("ident.json"), serde_json::to_string_pretty(&json).unwrap_or_default());
        e.context(format!("identification incomplete: the samples are in {}", stream_csv.display()))
    })?;
    let drive = identify_run(axis, measured, parameters)?;
    progress("twin on the FMU", 0.0);
    let twin_trace = run.run(fmu, |f| progress("twin on the FMU", f))?;
    if let Some(trip) = crate::fmu::axis_health::first_trip(&twin_trace)? {
        bail!("the twin tripped during the excitation: {}; lower the amplitude", trip.sentence());
    }
    let twin = identify_run(axis, response_of(&twin_trace, acquisition_hz)?, parameters)?;
    let (points, largest) = compare(&drive.measured, &twin.measured);
    let anti = |r: &IdentifiedRun| r.model.as_ref().and_then(|m| m.anti_resonance);
    let anti_resonance_difference = anti(&drive).zip(anti(&twin)).map(|(d, t)| relative(d, t));
    let truth = plant_truth(parameters)?;
    let truth_error = anti(&drive).zip(truth).map(|(d, t)| relative(d, t));
    let link = LinkUse {
        samples: on_drive.samples,
        dropped: on_drive.dropped,
        corrupt_frames: on_drive.corrupt_frames,
        bytes_per_s: on_drive.link_bytes_per_s,
        capacity_bytes_per_s: session.baud as f64 / crate::virtual_drive::uart::BITS_PER_BYTE,
    };
    let same_verdict = anti(&drive).is_some() == anti(&twin).is_some();
    let passed = link.dropped == 0 && link.corrupt_frames == 0 && largest.2 <= GOAL_STANDARD_ERRORS && same_verdict;
    let mut report = DeviceIdentification {
        port: port.to_string(),
        axis: axis.to_string(),
        drive,
        twin,
        points,
        largest_difference: (largest.0, largest.1),
        largest_standard_errors: largest.2,
        anti_resonance_difference,
        truth,
        truth_error,
        measurement_time_s: on_drive.measurement_time_s,
        wall_time_s,
        link,
        passed,
        files: vec![stream_csv],
    };
    report.files.extend(write_files(&report, out)?);
    let json = out.join("ident.json");
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    report.files.push(json);
    Ok(report)
}

/// `<axis>.model.json` (the drive's model, editable, for `servo tune`; removed when refused),
/// `<axis>.measured.csv` (the drive's response), `<axis>.twin.csv` (both and their difference
/// per point) and `ident.svg` (both responses and the drive's model).
fn write_files(r: &DeviceIdentification, out: &Path) -> Result<Vec<PathBuf>> {
    let axis = &r.axis;
    let mut files = Vec::new();
    let model_path = out.join(format!("{axis}.model.json"));
    match &r.drive.model {
        Some(model) => {
            std::fs::write(&model_path, serde_json::to_string_pretty(model)?)?;
            files.push(model_path);
        }
        None => {
            // A stale model of an earlier run must not be taken for this one's.
            let _ = std::fs::remove_file(&model_path);
        }
    }
    let measured = out.join(format!("{axis}.measured.csv"));
    crate::ident::report::write_measured(&measured, &r.drive.measured)?;
    let twin = out.join(format!("{axis}.twin.csv"));
    let mut t = Trace::new(
        [
            "frequency",
            "gain_db",
            "phase_deg",
            "twin_gain_db",
            "twin_phase_deg",
            "diff_db",
            "diff_deg",
            "diff_standard_errors",
        ]
        .map(String::from)
        .to_vec(),
    );
    for p in &r.points {
        t.rows.push(vec![
            p.response.frequency,
            p.response.drive_db,
            p.response.drive_deg,
            p.response.twin_db,
            p.response.twin_deg,
            p.response.difference_db,
            p.response.difference_deg,
            p.standard_errors,
        ]);
    }
    t.write_csv(&twin)?;
    let svg = out.join("ident.svg");
    let (drive_points, twin_points) = (r.drive.measured.points(), r.twin.measured.points());
    let model_points =
        r.drive.model.as_ref().map(|m| crate::ident::report::model_points(m, &r.drive.measured.frequencies));
    let mut curves: Vec<(&str, &[ResponsePoint])> =
        vec![("drive: measured over the link", &drive_points), ("FMU twin: measured", &twin_points)];
    if let Some(m) = &model_points {
        curves.push(("drive: fitted model", m));
    }
    plot_bode(
        &svg,
        &format!("Torque → machine-end acceleration of axis {axis} on the drive at {}, and its twin", r.port),
        &curves,
        None,
    )?;
    files.extend([measured, twin, svg]);
    Ok(files)
}

impl DeviceIdentification {
    pub fn print(&self) {
        println!(
            "servo ident on the drive at {} — axis {}: M-sequence degree {} at 1 kHz on the torque at {} rad/s, U = kt·iq (measured), Y = machine-end accelerometer; {:.2} s of the drive's time ({:.2} s wall)",
            self.port,
            self.axis,
            crate::ident::identification::DEGREE,
            crate::ident::identification::SPEED,
            self.measurement_time_s,
            self.wall_time_s
        );
        for (label, r) in [("drive", &self.drive), ("twin ", &self.twin)] {
            let notch = r.notch.map_or("band too narrow to search for a notch".to_string(), |n| n.verdict());
            match (&r.model, &r.refusal) {
                (_, Some(why)) => println!("  {label}: REFUSED: {why}; {notch}"),
                (Some(m), None) => match m.anti_resonance {
                    Some(z) => println!(
                        "  {label}: anti-resonance {:.3} Hz, damping {:.4}; resonance {}; gain {:.4e}; rms fit error {:.1} %; {notch}",
                        z.hz,
                        z.damping,
                        m.resonance.map_or("-".into(), |p| format!("{:.2} Hz, damping {:.4}", p.hz, p.damping)),
                        m.gain,
                        m.fit_error * 100.0
                    ),
                    None => println!(
                        "  {label}: {} (rigid axis, N = 1): {}; gain {:.4e}",
                        r.notch.filter(|_| r.undetermined.is_none()).map_or("no clear anti-resonance".to_string(), |n| n.none_clear()),
                        r.undetermined.as_deref().unwrap_or(&notch),
                        m.gain
                    ),
                },
                (None, None) => {}
            }
        }
        if let (Some(t), Some((f, d))) = (self.truth, self.truth_error) {
            println!(
                "  the plant's analytic anti-resonance {:.3} Hz, damping {:.4}: drive {:+.3} % in frequency, {:+.2} % in damping",
                t.hz,
                t.damping,
                100.0 * f,
                100.0 * d
            );
        }
        if let Some((f, d)) = self.anti_resonance_difference {
            println!(
                "  drive vs twin: anti-resonance {:+.3} % in frequency, {:+.2} % in damping (without accelerometer noise the virtual drive keeps within {} % and {} %)",
                100.0 * f,
                100.0 * d,
                100.0 * GOAL_HZ,
                100.0 * GOAL_DAMPING
            );
        }
        println!(
            "  drive vs twin per frequency point ({} points, {}–{} Hz): largest {:.3} dB, {:.2} deg, {:.2} standard errors of the difference (goal {GOAL_STANDARD_ERRORS})",
            self.points.len(),
            BAND.0,
            BAND.1,
            self.largest_difference.0,
            self.largest_difference.1,
            self.largest_standard_errors
        );
        let l = &self.link;
        println!(
            "  link: {} samples, {} dropped by the drive, {} frame(s) lost on the line; {:.0} B/s of {:.0} B/s ({:.0} % of the line)",
            l.samples,
            l.dropped,
            l.corrupt_frames,
            l.bytes_per_s,
            l.capacity_bytes_per_s,
            100.0 * l.bytes_per_s / l.capacity_bytes_per_s
        );
        for f in &self.files {
            println!("  → {}", f.display());
        }
        println!(
            "  {}",
            if self.passed {
                "drive and twin agree within the goals"
            } else {
                "drive and twin do NOT agree within the goals"
            }
        );
    }
}
