//! `servo tune --device PORT`: the correction of one axis loaded into a drive over its link
//! (the `<axis>.corr.frame` `servo tune` wrote, sent as `servo device … load-correction` sends
//! it) and checked there, without the correction and with it, each run beside its FMU twin
//! (the drive's parameters with the tuned axis's plant, and for the second run the same
//! `corr.*` parameters as `<axis>.corr.toml`):
//! - the single-axis pseudo-circle (`circle::device`, motor position);
//! - the command → machine-end position response at the FMU check's frequencies, measured with
//!   the drive's machine-end accelerometer (`device_machine_end`), and compared with the other
//!   axes' responses as the FMU check measured them, before and after.
//!
//! What it shows: the drive runs the correction it was sent, as the twin says it should (each
//! run within `circle::device::GOAL_COUNTS` of its twin on the motor, within
//! `device_machine_end::GOAL_FLOOR` of the response plus `GOAL_STANDARD_ERRORS` standard errors
//! at the machine end), what the correction does to
//! the motor's figure, and that it brings this axis's machine-end response to the other axes'
//! (one drive is one axis: the others are the FMU check's).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use control_core::protocol::Request;
use serde::Serialize;

use crate::circle::device::{difference, run_on_device_loading, DeviceCircleReport, FigureDifference, GOAL_COUNTS};
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::fmu::circle::{CircleRequest, Direction, Measure};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::ident::device_machine_end::{check_machine_end, MachineEndCheck, MachineEndRequest};
use crate::ident::tuning::{TunedAxis, Tuning};

/// The pseudo-circle of the check: the FMU check's circle (0.05 rad at 20 Hz, the
/// position-loop bandwidth, where the axes differ most in band; 30 revolutions of lead-in for
/// the lightly damped closed-loop poles), 200 samples a revolution.
pub const RADIUS: f64 = 0.05;
pub const FREQUENCY_HZ: f64 = 20.0;
pub const LEAD_IN: u32 = 30;

#[derive(Clone, Debug, Serialize)]
pub struct TuneDeviceCheck {
    pub port: String,
    pub axis: String,
    /// The frame loaded (`<axis>.corr.frame`).
    pub frame: PathBuf,
    /// The drive answered `Done` to the `LoadCorrection` and ran the corrected circle with it.
    pub correction_loaded: bool,
    pub radius: f64,
    pub frequency_hz: f64,
    pub lead_in: u32,
    /// Without the correction (the drive's parameters, `corr.count` = 0), and with it.
    pub without: DeviceCircleReport,
    pub with: DeviceCircleReport,
    /// Corrected − uncorrected feedback figure: on the drive, on the twin.
    pub change_on_drive: FigureDifference,
    pub change_on_twin: FigureDifference,
    /// Mean radius of the corrected figure − the uncorrected one (rad): drive, twin.
    pub mean_radius_change: (f64, f64),
    /// Drive vs twin goal (rad), each run: `GOAL_COUNTS` encoder counts.
    pub goal: f64,
    /// The command → machine-end position response, without and with the correction.
    pub machine_end: MachineEndCheck,
    /// Every run within the goal of its twin, nothing dropped or lost, and (with the FMU
    /// check) the corrected machine-end response closer to the other axes' than the uncorrected.
    pub passed: bool,
}

/// The tuned axis named `axis` (the first one if `None`); an error names the axes there are.
pub fn tuned_axis<'a>(tuning: &'a Tuning, axis: Option<&str>) -> Result<&'a TunedAxis> {
    let Some(name) = axis else {
        return tuning.axes.first().ok_or_else(|| anyhow!("the tuning has no axis"));
    };
    tuning.axes.iter().find(|a| a.axis == name).ok_or_else(|| {
        let names: Vec<&str> = tuning.axes.iter().map(|a| a.axis.as_str()).collect();
        anyhow!("--axis {name}: the models are of axes {} (one drive is one axis)", names.join(", "))
    })
}

/// The parameters of the check on `axis`, no correction: the drive takes their controller
/// part; the twin all of them, its plant the tuned axis's (`plant.*`: the model the
/// correction was made for; on a board, the user's picture of the machine).
fn axis_parameters(axis: &TunedAxis) -> BTreeMap<String, Value> {
    axis.fmu_parameters
        .iter()
        .filter(|(k, _)| !k.starts_with("corr."))
        .map(|(k, v)| (k.clone(), Value::Float(*v)))
        .collect()
}

/// The circle of the check on `axis`.
fn circle_request(axis: &TunedAxis) -> CircleRequest {
    let drive = axis_parameters(axis);
    CircleRequest {
        radius: RADIUS,
        feed: RADIUS * std::f64::consts::TAU * FREQUENCY_HZ,
        direction: Direction::CounterClockwise,
        lead_in: LEAD_IN,
        measure: Measure::Motor,
        x_parameters: drive.clone(),
        y_parameters: drive,
    }
}

/// The check's request, refused before any drive is touched if the circle or the machine-end
/// sweep cannot run there.
pub fn check_request(tuning: &Tuning, axis: &TunedAxis) -> Result<()> {
    crate::circle::device::pseudo_circle_sweep(&circle_request(axis))?;
    let top_hz = (2.0 * tuning.position_bandwidth_hz).round();
    crate::ident::device_machine_end::machine_end_sweep(&axis_parameters(axis), top_hz).map(|_| ())
}

/// Load `axis`'s correction (`frame`) into the drive behind `session` and run the check;
/// files in `out` (`without/`, `with/`: each circle's points, samples, plot and JSON;
/// `machine_end_without/`, `machine_end_with/`: the machine-end sweeps' samples).
pub fn check_on_device<T: DrivePort>(
    fmu: &Fmu,
    tuning: &Tuning,
    axis: &TunedAxis,
    (port, session): (&str, &mut DriveSession<T>),
    frame: &Path,
    out: &Path,
    mut progress: impl FnMut(&str, f64),
) -> Result<TuneDeviceCheck> {
    let mut bytes = std::fs::read(frame).with_context(|| format!("cannot read {}", frame.display()))?;
    let correction =
        match crate::device::link::correction_request(&mut bytes).with_context(|| frame.display().to_string())? {
            Request::LoadCorrection(c) => c,
            other => bail!("{}: a {other:?} request, not a correction", frame.display()),
        };
    let mut request = circle_request(axis);
    let without = run_on_device_loading(fmu, &request, (port, &mut *session), None, &out.join("without"), |l, f| {
        progress(&format!("without correction: {l}"), f)
    })?;
    request.x_parameters.extend(axis.correction.parameters());
    let with =
        run_on_device_loading(fmu, &request, (port, &mut *session), Some(&correction), &out.join("with"), |l, f| {
            progress(&format!("with correction: {l}"), f)
        })?;
    let parameters = axis_parameters(axis);
    let machine_end_request = MachineEndRequest {
        tuning,
        axis: &axis.axis,
        parameters: &parameters,
        correction: (axis.correction.parameters(), &correction),
    };
    let machine_end =
        check_machine_end(fmu, &machine_end_request, session, out, |l, f| progress(&format!("machine end {l}"), f))?;
    let change = |i: usize| difference(&with.feedback[i], &without.feedback[i]);
    let mean_change = |i: usize| with.runs[i].feedback.mean_radius_error - without.runs[i].feedback.mean_radius_error;
    Ok(TuneDeviceCheck {
        port: port.to_string(),
        axis: axis.axis.clone(),
        frame: frame.to_path_buf(),
        correction_loaded: true,
        radius: RADIUS,
        frequency_hz: FREQUENCY_HZ,
        lead_in: LEAD_IN,
        change_on_drive: change(0),
        change_on_twin: change(1),
        mean_radius_change: (mean_change(0), mean_change(1)),
        goal: with.goal,
        passed: without.passed && with.passed && machine_end.matches_twin && machine_end.equalised != Some(false),
        machine_end,
        without,
        with,
    })
}

impl TuneDeviceCheck {
    pub fn print(&self) {
        let count = self.goal / GOAL_COUNTS;
        println!(
            "  over the drive at {} — axis {}: correction {} loaded (LoadCorrection); pseudo-circle of the motor position, radius {} rad at {} Hz, {} revolutions of lead-in",
            self.port,
            self.axis,
            self.frame.display(),
            self.radius,
            self.frequency_hz,
            self.lead_in
        );
        println!(
            "    {:<20} {:>14} {:>14} {:>14} {:>14} {:>16} {:>16}",
            "run", "drive round.", "twin round.", "drive mean r.", "twin mean r.", "drive−twin max", "drive−twin rms"
        );
        for (label, r) in [("without correction", &self.without), ("with correction", &self.with)] {
            let (d, t) = (&r.runs[0].feedback, &r.runs[1].feedback);
            println!(
                "    {label:<20} {:>14.3e} {:>14.3e} {:>+14.3e} {:>+14.3e} {:>10.3e} ({:.2}) {:>10.3e} ({:.2})",
                d.roundness,
                t.roundness,
                d.mean_radius_error,
                t.mean_radius_error,
                r.difference.largest,
                r.difference.largest / count,
                r.difference.rms,
                r.difference.rms / count
            );
        }
        println!("    (rad; in brackets: encoder counts; goal drive − twin ≤ {GOAL_COUNTS} counts each run)");
        println!(
            "    what the correction changes (corrected − uncorrected figure): drive largest {:.3e} rad, rms {:.3e} rad, mean radius {:+.3e} rad; twin largest {:.3e} rad, rms {:.3e} rad, mean radius {:+.3e} rad",
            self.change_on_drive.largest,
            self.change_on_drive.rms,
            self.mean_radius_change.0,
            self.change_on_twin.largest,
            self.change_on_twin.rms,
            self.mean_radius_change.1
        );
        println!(
            "    link: {} + {} samples, {} + {} dropped, {} + {} frame(s) lost; drive vs twin: {}",
            self.without.samples,
            self.with.samples,
            self.without.dropped,
            self.with.dropped,
            self.without.corrupt_frames,
            self.with.corrupt_frames,
            if self.without.passed && self.with.passed { "met" } else { "NOT MET" }
        );
        self.machine_end.print();
        for f in self.without.files.iter().chain(&self.with.files) {
            println!("    → {}", f.display());
        }
    }
}
