//! What `servo autotune` shows of a tuned loop beside its margins: the predicted step and
//! load-step responses (tuned and with the gains it had), the step measured on the twin, and
//! the plots of them (step.svg, disturbance.svg), of the open loop in the Nyquist plane
//! (nyquist.svg: designed and measured, the Ms circle, the crossover) and of the closed loop
//! (closed-loop.svg: `L/(1 + L)` designed and from the measured open loop).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use num_complex::Complex64;
use serde::Serialize;

use super::margins::{log_grid, Margins};
use super::prediction::{predict, StepPrediction};
use super::step_on_twin::{step_on_fmu, MeasuredStep};
use super::velocity_controller::VelocityTuning;
use crate::analysis::response_point::ResponsePoint;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::trace::Trace;

/// How long the steps are followed (s).
const SPAN_S: f64 = 0.15;
/// The measured step's size, as a share of the riding speed (at least 1 rad/s).
const STEP_SHARE: f64 = 0.1;

/// The calibrated model a prediction runs on: the plant the velocity loop drives, the path of
/// a torque at the motor to the velocity estimate, the velocity loop's period (s).
pub struct LoopModel<'a> {
    pub plant: &'a dyn Fn(f64) -> Complex64,
    pub disturbance: &'a dyn Fn(f64) -> Complex64,
    pub period: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct Responses {
    pub tuned: StepPrediction,
    pub before: StepPrediction,
    pub measured: MeasuredStep,
}

impl Responses {
    /// The predictions of `tuned` and `before` on `model`, and the step of `tuned` measured on
    /// the twin (`parameters` with the tuning in them) riding at `velocity`.
    pub fn of(
        fmu: &Fmu,
        parameters: &BTreeMap<String, Value>,
        tuned: &VelocityTuning,
        before: &VelocityTuning,
        model: &LoopModel,
        velocity: f64,
    ) -> Result<Self> {
        let (plant, disturbance, period) = (model.plant, model.disturbance, model.period);
        let size = (STEP_SHARE * velocity.abs()).max(1.0);
        Ok(Self {
            tuned: predict(tuned, plant, disturbance, period, SPAN_S),
            before: predict(before, plant, disturbance, period, SPAN_S),
            measured: step_on_fmu(fmu, parameters, velocity, size, SPAN_S)?,
        })
    }

    /// step.svg and disturbance.svg in `out`.
    pub fn plot(&self, out: &Path) -> Result<()> {
        let trace = |t: &[f64], y: &[f64], name: &str| {
            let mut tr = Trace::new(vec!["time".into(), name.into()]);
            for (t, y) in t.iter().zip(y) {
                tr.rows.push([*t * 1e3, *y]);
            }
            tr
        };
        let (tuned, before, measured) = (
            trace(&self.tuned.time, &self.tuned.command_step, "velocity per unit step"),
            trace(&self.before.time, &self.before.command_step, "velocity per unit step"),
            trace(&self.measured.time, &self.measured.response, "velocity per unit step"),
        );
        crate::plot::signals::plot_against(
            &out.join("step.svg"),
            &format!(
                "velocity step: overshoot {:.0} %, settles in {:.0} ms predicted; {:.0} %, {:.0} ms on the twin",
                self.tuned.overshoot_percent,
                1e3 * self.tuned.settling_time_s,
                self.measured.overshoot_percent,
                1e3 * self.measured.settling_time_s
            ),
            &[("predicted, tuned", &tuned), ("measured on the twin, tuned", &measured), ("predicted, before", &before)],
            "time",
            "time from the step (ms)",
            &["velocity per unit step".to_string()],
        )?;
        let name = "velocity per N·m (rad/s)";
        let (tuned, before) = (
            trace(&self.tuned.time, &self.tuned.disturbance_step, name),
            trace(&self.before.time, &self.before.disturbance_step, name),
        );
        crate::plot::signals::plot_against(
            &out.join("disturbance.svg"),
            &format!(
                "load step at the motor (predicted): peak {:.3} rad/s per N·m tuned, {:.3} before",
                self.tuned.disturbance_peak, self.before.disturbance_peak
            ),
            &[("tuned", &tuned), ("before", &before)],
            "time",
            "time from the step (ms)",
            &[name.to_string()],
        )
    }
}

/// nyquist.svg and closed-loop.svg in `out`: the designed loop (`designed` at frequency f)
/// and the measured open loop (`measured`), with the goal's Ms circle and the designed
/// crossover marked.
pub fn plot_loops(
    out: &Path,
    designed: &dyn Fn(f64) -> Complex64,
    measured: &[ResponsePoint],
    margins: &Margins,
    goal_ms: f64,
    period: f64,
) -> Result<()> {
    let dense = log_grid(0.5, 0.999 * 0.5 / period, 2000);
    let designed_l: Vec<Complex64> = dense.iter().map(|&f| designed(f)).collect();
    let measured_l: Vec<Complex64> = measured.iter().map(ResponsePoint::to_complex).collect();
    let crossover = designed(margins.crossover_hz);
    crate::plot::nyquist::plot_nyquist(
        &out.join("nyquist.svg"),
        &format!(
            "open loop near −1: phase margin {:.0}°, gain margin {:.1} dB, Ms {:.2} (designed)",
            margins.phase_margin_deg, margins.gain_margin_db, margins.sensitivity_peak
        ),
        &[("designed", &designed_l), ("measured on the twin (feedback-point sweep)", &measured_l)],
        Some(goal_ms),
        Some((crossover, &format!("crossover {:.0} Hz", margins.crossover_hz))),
    )?;
    let closed = |l: Complex64| l / (1.0 + l);
    let designed_t: Vec<ResponsePoint> =
        dense.iter().zip(&designed_l).map(|(&f, &l)| ResponsePoint::from_complex(f, closed(l), 1.0)).collect();
    let measured_t: Vec<ResponsePoint> = measured
        .iter()
        .zip(&measured_l)
        .map(|(p, &l)| ResponsePoint::from_complex(p.frequency, closed(l), 1.0))
        .collect();
    crate::plot::bode::plot_bode(
        &out.join("closed-loop.svg"),
        &format!("closed loop L/(1 + L): bandwidth {:.0} Hz designed", margins.bandwidth_hz),
        &[("designed", &designed_t), ("from the open loop measured on the twin", &measured_t)],
        Some((margins.bandwidth_hz, "bandwidth")),
    )
}
