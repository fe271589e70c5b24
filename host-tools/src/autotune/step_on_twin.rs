//! A velocity-command step measured on the twin (the verification's time response): the axis
//! rides at a constant speed (friction on one side), the command steps up, and the velocity
//! estimate's change per unit step is read, with its overshoot and settling time figured as
//! the prediction's are.

use std::collections::BTreeMap;

use anyhow::{bail, Context, Result};
use control_core::axis::Mode;
use serde::Serialize;

use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::{Event, Scenario, Value};

/// When the step comes (s): the axis rides steadily by then.
const STEP_AT: f64 = 0.5;

/// The measured step.
#[derive(Clone, Debug, Serialize)]
pub struct MeasuredStep {
    /// Time from the step (s).
    pub time: Vec<f64>,
    /// The velocity estimate's change per unit step.
    pub response: Vec<f64>,
    pub overshoot_percent: f64,
    /// When the response last leaves ±2 % of the step and one step of the velocity estimate
    /// (s; NaN where it had not settled by the end of the span).
    pub settling_time_s: f64,
    /// Drive time of the run: the ride to the step and the span after it (s).
    pub drive_time_s: f64,
}

/// A step of `size` rad/s from a ride at `velocity` rad/s on `fmu` with `parameters`, over
/// `span_s` s after it.
pub fn step_on_fmu(
    fmu: &Fmu,
    parameters: &BTreeMap<String, Value>,
    velocity: f64,
    size: f64,
    span_s: f64,
) -> Result<MeasuredStep> {
    if !(size.is_finite() && size != 0.0 && velocity.is_finite() && span_s > 0.0) {
        bail!("a step needs a finite, non-zero size and a finite riding speed");
    }
    let control = configuration(parameters)?.control;
    let limit = control.position.velocity_limit as f64;
    if velocity.abs().max((velocity + size).abs()) > limit {
        bail!("the step ({velocity} → {} rad/s) passes the drive's velocity limit {limit} rad/s", velocity + size);
    }
    let rates = control.rates;
    let step = rates.position_divider as f64 / rates.current_loop_hz as f64;
    let ride =
        [("mode".to_string(), Value::code(Mode::Velocity.code())), ("velocity_command".into(), Value::Float(velocity))];
    let stop_time = ((STEP_AT + span_s) / step).ceil() * step;
    let scenario = Scenario {
        name: "step".into(),
        description: "a velocity-command step on the twin".into(),
        stop_time,
        step: Some(step),
        parameters: parameters.clone(),
        events: vec![
            Event { time: 0.0, inputs: ride.into() },
            Event {
                time: (STEP_AT / step).round() * step,
                inputs: [("velocity_command".to_string(), Value::Float(velocity + size))].into(),
            },
        ],
        checks: vec![],
        plot: vec![],
        record: ["velocity_estimate", "faults"].map(String::from).to_vec(),
    };
    let trace = fmu.run(&scenario, |_| {}).context("the step on the twin")?;
    if let Some(trip) = crate::fmu::axis_health::first_trip(&trace)? {
        bail!("the step tripped the drive: {}", trip.sentence());
    }
    let (t, v) = (trace.column("time").context("time")?, trace.column("velocity_estimate").context("velocity")?);
    let at = (STEP_AT / step).round() * step;
    let mut time = Vec::new();
    let mut response = Vec::new();
    for (t, v) in t.iter().zip(&v) {
        if *t >= at - 1e-9 {
            time.push(t - at);
            response.push((v - velocity) / size);
        }
    }
    if time.len() < 2 {
        bail!("the step's trace is empty");
    }
    let overshoot_percent = 100.0 * (response.iter().copied().fold(f64::NEG_INFINITY, f64::max) - 1.0).max(0.0);
    // The estimate moves in steps of one count per velocity period: a response ringing within
    // ±2 % reads up to a step further out. The band is ±2 % and one step.
    let band = 0.02 + reading_step(&response);
    let settling_time_s = super::prediction::settled_after(&time, &response, |y| (y - 1.0).abs() > band);
    Ok(MeasuredStep { time, response, overshoot_percent, settling_time_s, drive_time_s: stop_time })
}

/// The smallest step between two of `response`'s distinct readings (readings within a
/// millionth of one another count as one; 0 where there are not two): a count of the encoder
/// per velocity period, per unit step.
fn reading_step(response: &[f64]) -> f64 {
    let mut levels: Vec<f64> = response.iter().copied().filter(|y| y.is_finite()).collect();
    levels.sort_by(f64::total_cmp);
    let step = levels.windows(2).map(|w| w[1] - w[0]).filter(|d| *d > 1e-6).fold(f64::INFINITY, f64::min);
    if step.is_finite() {
        step
    } else {
        0.0
    }
}

#[cfg(test)]
mod tests {
    use super::reading_step;

    #[test]
    fn the_reading_step_is_the_least_gap_between_distinct_readings() {
        let q = 0.0096;
        let readings: Vec<f64> = [0, 3, 1, 1, 5, 2, 2].iter().map(|k| 0.97 + q * *k as f64).collect();
        assert!((reading_step(&readings) - q).abs() < 1e-9);
        assert_eq!(reading_step(&[1.0, 1.0, f64::NAN]), 0.0);
        assert_eq!(reading_step(&[]), 0.0);
    }
}
