//! `servo tune --device PORT`: the correction of one axis loaded into a drive over its link
//! (the `<axis>.corr.frame` `servo tune` wrote, sent as `servo device … load-correction` sends
//! it) and checked there: the single-axis pseudo-circle (`circle::device`, motor position) run
//! on the drive without the correction and with it, each beside its FMU twin (the drive's
//! parameters, and for the second run the same `corr.*` parameters as `<axis>.corr.toml`).
//!
//! What it shows: the drive runs the correction it was sent, as the twin says it should (each
//! run within `circle::device::GOAL_COUNTS` of its twin), and what the correction does to the
//! motor's figure, on the drive and on the twin side by side. What it cannot show: that the
//! axes' machine-end responses became alike — a drive reads its motor encoder only, and one
//! drive is one axis.

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
    /// Both runs within the goal of their twin, nothing dropped or lost.
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

/// The request of the check on `axis`: its parameters but the plant's (`plant.*` is the
/// twin's picture of the machine; the drive has its own), no correction.
fn circle_request(axis: &TunedAxis) -> CircleRequest {
    let drive: BTreeMap<String, Value> = axis
        .fmu_parameters
        .iter()
        .filter(|(k, _)| !k.starts_with("plant.") && !k.starts_with("corr."))
        .map(|(k, v)| (k.clone(), Value::Float(*v)))
        .collect();
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

/// The check's request, refused before any drive is touched if the circle cannot run there.
pub fn check_request(axis: &TunedAxis) -> Result<()> {
    crate::circle::device::pseudo_circle_sweep(&circle_request(axis)).map(|_| ())
}

/// Load `axis`'s correction (`frame`) into the drive behind `session` and run the check;
/// files in `out` (`without/`, `with/`: each run's points, samples, plot and JSON).
pub fn check_on_device<T: DrivePort>(
    fmu: &Fmu,
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
        passed: without.passed && with.passed,
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
            if self.passed { "met" } else { "NOT MET" }
        );
        println!("    (motor position only: a drive has no machine-end sensor, so the axes' equalisation is the FMU check's)");
        for f in self.without.files.iter().chain(&self.with.files) {
            println!("    → {}", f.display());
        }
    }
}
