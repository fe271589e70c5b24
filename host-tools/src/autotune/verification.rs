//! A tuning verified where it is to run: the open loop measured with the new gains by a
//! feedback-point sweep on a [`AxisUnderTest`] (the twin, or the drive), and the margins a
//! sparse measured grid can show — the phase margin at its gain crossovers and the
//! sensitivity peak over its points (the stability and the gain margin need the model's
//! dense grid). A sweep that measured no crossover has not shown a margin: it fails.

use std::collections::BTreeMap;

use anyhow::{Context, Result};
use control_core::excitation::InjectionPoint;
use num_complex::Complex64;
use serde::Serialize;

use super::axis_under_test::AxisUnderTest;
use super::design::MarginGoal;
use super::margins::crossover_margins;
use crate::analysis::response_point::ResponsePoint;
use crate::fmu::scenario::Value;

/// Amplitude of the verification's feedback-point sweep (rad/s).
pub const FEEDBACK_AMPLITUDE: f64 = 2.0;

#[derive(Clone, Debug, Serialize)]
pub struct Verification {
    /// Where it was measured ("the FMU", "the drive at …").
    pub on: String,
    #[serde(skip)]
    pub open_loop: Vec<ResponsePoint>,
    /// NaN where no gain crossover was measured.
    pub phase_margin_deg: f64,
    pub sensitivity_peak: f64,
    /// Frequencies measured with the output at a limit (the drive's voltage circle, or the
    /// torque limit): not the linear loop's response, so the verification fails.
    pub limited_points: usize,
    pub passed: bool,
    pub drive_time_s: f64,
}

/// The open loop of `tuned` (the run's parameters with the tuning in them) measured on
/// `target` riding at `velocity` rad/s, held to `goal`'s phase margin and Ms.
pub fn verify(
    target: &mut dyn AxisUnderTest,
    tuned: &BTreeMap<String, Value>,
    velocity: f64,
    goal: &MarginGoal,
) -> Result<Verification> {
    let sweep = target
        .sweep(InjectionPoint::VelocityFeedback, FEEDBACK_AMPLITUDE, tuned, velocity)
        .with_context(|| format!("the feedback-point sweep with the new gains on {}", target.name()))?;
    let hz: Vec<f64> = sweep.points.iter().map(|p| p.frequency).collect();
    let l: Vec<Complex64> = sweep.points.iter().map(ResponsePoint::to_complex).collect();
    let (phase_margin_deg, sensitivity_peak) = crossover_margins(&hz, &l);
    let limited_points = sweep.voltage_limited + sweep.torque_limited;
    // NaN compares false: no crossover measured, not passed.
    let passed =
        phase_margin_deg >= goal.phase_margin_deg && sensitivity_peak <= goal.sensitivity_peak && limited_points == 0;
    Ok(Verification {
        on: target.name(),
        open_loop: sweep.points,
        phase_margin_deg,
        sensitivity_peak,
        limited_points,
        passed,
        drive_time_s: sweep.drive_time_s,
    })
}

/// `parameters` with the velocity loop's `tuning` and the position loop's (where designed)
/// in them.
pub fn with_tuning(
    parameters: &BTreeMap<String, Value>,
    tuning: &super::velocity_controller::VelocityTuning,
    position: Option<&super::position_loop_design::PositionTuning>,
) -> BTreeMap<String, Value> {
    let mut tuned = parameters.clone();
    for (k, v) in tuning.parameters() {
        tuned.insert(k, Value::Float(v));
    }
    for (k, v) in position.map(|p| p.parameters()).into_iter().flatten() {
        tuned.insert(k, Value::Float(v));
    }
    tuned
}
