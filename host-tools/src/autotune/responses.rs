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

/// How long the predicted steps are followed (s).
const SPAN_S: f64 = 0.15;
/// How long the step on the twin is followed (s): twice the prediction's span, so that a
/// measured step whose noisy estimate last leaves ±2 % a little after a prediction that settles
/// late in its span still shows when it settles (the comparison of the waveforms stays within
/// the prediction's span).
const MEASURED_SPAN_S: f64 = 2.0 * SPAN_S;
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
            measured: step_on_fmu(fmu, parameters, velocity, size, MEASURED_SPAN_S)?,
        })
    }

    /// How far the step measured on the twin lies from the predicted one: the root mean square
    /// of their difference over the span, per unit step, at the measured samples (the
    /// prediction, sampled every velocity period, interpolated between its samples). The whole
    /// waveform, where the settling time is when a noisy estimate last crosses ±2 %: on a
    /// lightly damped tail a cycle more or less inside the band moves it by a period. NaN
    /// where the prediction is unstable or no measured sample lies within it.
    pub fn step_difference(&self) -> f64 {
        let (predicted, measured) = (&self.tuned, &self.measured);
        let (t, y) = (&predicted.time, &predicted.command_step);
        if !predicted.stable || t.len() < 2 {
            return f64::NAN;
        }
        let at = |time: f64| {
            let k = t.partition_point(|&s| s <= time).clamp(1, t.len() - 1);
            let share = (time - t[k - 1]) / (t[k] - t[k - 1]);
            y[k - 1] + share * (y[k] - y[k - 1])
        };
        let last = t[t.len() - 1];
        let differences: Vec<f64> = measured
            .time
            .iter()
            .zip(&measured.response)
            .filter(|(time, _)| **time <= last)
            .map(|(time, v)| v - at(*time))
            .collect();
        if differences.is_empty() {
            return f64::NAN;
        }
        (differences.iter().map(|d| d * d).sum::<f64>() / differences.len() as f64).sqrt()
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

#[cfg(test)]
mod tests {
    use super::*;

    fn prediction(time: Vec<f64>, command_step: Vec<f64>) -> StepPrediction {
        StepPrediction {
            time,
            command_step,
            disturbance_step: vec![],
            overshoot_percent: 0.0,
            settling_time_s: 0.0,
            disturbance_peak: 0.0,
            disturbance_recovery_s: 0.0,
            stable: true,
        }
    }

    /// A measured step on a finer grid than the prediction's (a parabola sampled every 10 ms):
    /// the prediction is interpolated between its samples at the measured times (half-way
    /// between two samples, their mean), an offset of 0.1 of the step reads 0.1, the samples
    /// past the prediction's span do not count, and an unstable prediction, one of a single
    /// sample or none within its span give NaN.
    #[test]
    fn the_measured_step_is_compared_with_the_prediction_at_its_own_samples() {
        let predicted =
            prediction((0..11).map(|k| k as f64 * 0.01).collect(), (0..11).map(|k| (k * k) as f64).collect());
        // Between samples k and k + 1 the interpolated prediction is k² + (2k + 1)·share.
        let interpolated = |t: f64| {
            let k = ((t / 0.01).floor() as usize).min(9);
            let share = t / 0.01 - k as f64;
            (k * k) as f64 + (2 * k + 1) as f64 * share
        };
        let measured = |offset: f64, times: Vec<f64>| {
            let response =
                times.iter().map(|&t| if t <= 0.1 + 1e-12 { interpolated(t) + offset } else { 1e3 }).collect();
            MeasuredStep { time: times, response, overshoot_percent: 0.0, settling_time_s: 0.0, drive_time_s: 0.0 }
        };
        let fine: Vec<f64> = (0..=40).map(|k| k as f64 * 0.003).collect();
        let of = |tuned: &StepPrediction, measured: MeasuredStep| {
            Responses { tuned: tuned.clone(), before: predicted.clone(), measured }.step_difference()
        };
        assert!(of(&predicted, measured(0.0, fine.clone())) < 1e-9);
        assert!((of(&predicted, measured(0.1, fine.clone())) - 0.1).abs() < 1e-9);
        // Half-way between samples 3 and 4 (9 and 16): 12.5.
        let half_way = MeasuredStep { response: vec![12.5], ..measured(0.0, vec![0.035]) };
        assert!(of(&predicted, half_way) < 1e-9);
        assert!(of(&StepPrediction { stable: false, ..predicted.clone() }, measured(0.0, fine.clone())).is_nan());
        assert!(of(&prediction(vec![0.0], vec![0.0]), measured(0.0, fine.clone())).is_nan());
        assert!(of(&predicted, measured(0.0, vec![0.2, 0.3])).is_nan());
    }
}
