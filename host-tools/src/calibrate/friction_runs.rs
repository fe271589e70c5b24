//! The constant-speed runs friction is read from, on the FMU: the velocity loop holds each
//! speed in turn, reached by a ramp (a step would ring a soft shaft for longer than the
//! settling time), and after it settles the velocity estimate and the torque command are
//! averaged over whole mechanical revolutions (so that a ripple at any multiple of the
//! rotation, from the current sensors' errors or the magnets, averages out). Only what a
//! drive reads is used: its own velocity estimate and torque command.

use std::collections::BTreeMap;

use anyhow::{bail, Context, Result};
use control_core::axis::Mode;

use super::friction::SpeedPoint;
use crate::device::velocity_ramp::RAMP_STEP;
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::{Event, Scenario, Value};
use crate::fmu::trace::Trace;

/// How the runs are made.
#[derive(Clone, Debug)]
pub struct FrictionRuns {
    /// The speeds (rad/s), each run in both directions.
    pub speeds: Vec<f64>,
    /// Time each speed is given to settle before its window (s), from the end of its ramp.
    pub settle_s: f64,
    /// The ramps' acceleration between speeds (rad/s²).
    pub acceleration: f64,
    /// Shortest averaging window (s); the window is a whole number of revolutions, at least one.
    pub measure_s: f64,
}

impl Default for FrictionRuns {
    fn default() -> Self {
        Self { speeds: vec![20.0, 50.0, 100.0, 150.0], settle_s: 0.4, measure_s: 0.25, acceleration: 2000.0 }
    }
}

/// One run's schedule: its commanded speed, when its ramp starts, and its window [from, to) (s).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Segment {
    pub speed: f64,
    pub ramp_from: f64,
    pub from: f64,
    pub to: f64,
}

impl FrictionRuns {
    /// The speeds in the order they are run (forward, then backward) with their windows.
    pub(crate) fn segments(&self) -> Vec<Segment> {
        let (mut t, mut last) = (0.0, 0.0);
        let mut out = Vec::new();
        for sign in [1.0, -1.0] {
            for &s in &self.speeds {
                let revolution = std::f64::consts::TAU / s;
                let window = (self.measure_s / revolution).ceil().max(1.0) * revolution;
                let ramp = (sign * s - last).abs() / self.acceleration;
                let from = t + ramp + self.settle_s;
                out.push(Segment { speed: sign * s, ramp_from: t, from, to: from + window });
                t = from + window;
                last = sign * s;
            }
        }
        out
    }

    /// Drive time the runs take (s).
    pub fn duration(&self) -> f64 {
        self.segments().last().map_or(0.0, |s| s.to)
    }

    /// Checks the speeds against the drive's velocity limit in `parameters`.
    pub fn validate(&self, parameters: &BTreeMap<String, Value>) -> Result<()> {
        self.validate_within(configuration(parameters)?.control.position.velocity_limit as f64)
    }

    /// Checks the speeds against a velocity limit (rad/s).
    pub fn validate_within(&self, limit: f64) -> Result<()> {
        if self.speeds.len() < 2 {
            bail!("friction needs at least two speeds (each is run in both directions), got {}", self.speeds.len());
        }
        for &s in &self.speeds {
            if !(s.is_finite() && s > 0.0 && s <= limit) {
                bail!("a friction run's speed must be a positive number of rad/s up to the drive's velocity limit {limit} rad/s, got {s}");
            }
        }
        if !([self.settle_s, self.measure_s, self.acceleration].iter().all(|x| x.is_finite() && *x > 0.0)) {
            bail!("the friction runs' settle and measure times and their ramps' acceleration must be positive");
        }
        Ok(())
    }

    /// Run them on `fmu` with `parameters` (the twin's machine): one point per speed and
    /// direction, and the trace (time, velocity estimate, torque command, faults).
    pub fn run(&self, fmu: &Fmu, parameters: &BTreeMap<String, Value>) -> Result<(Vec<SpeedPoint>, Trace)> {
        self.validate(parameters)?;
        let rates = configuration(parameters)?.control.rates;
        let step = rates.position_divider as f64 / rates.current_loop_hz as f64;
        let segments = self.segments();
        let mode = ("mode".to_string(), Value::code(Mode::Velocity.code()));
        let mut events = vec![Event { time: 0.0, inputs: [mode].into() }];
        // Each ramp: the command stepped every RAMP_STEP from the last speed to the next.
        let mut last = 0.0;
        for s in &segments {
            let ramp = s.from - self.settle_s - s.ramp_from;
            let n = (ramp / RAMP_STEP).ceil().max(1.0) as usize;
            for k in 1..=n {
                let v = last + (s.speed - last) * k as f64 / n as f64;
                let time = ((s.ramp_from + ramp * k as f64 / n as f64) / step).round() * step;
                events.push(Event { time, inputs: [("velocity_command".to_string(), Value::Float(v))].into() });
            }
            last = s.speed;
        }
        let scenario = Scenario {
            name: "friction".into(),
            description: "constant-speed runs for friction".into(),
            stop_time: (self.duration() / step).ceil() * step,
            step: Some(step),
            parameters: parameters.clone(),
            events,
            checks: vec![],
            plot: vec![],
            record: ["velocity_estimate", "torque_command_out", "faults"].map(String::from).to_vec(),
        };
        let trace = fmu.run(&scenario, |_| {}).context("the constant-speed runs")?;
        if let Some(trip) = crate::fmu::axis_health::first_trip(&trace)? {
            bail!("the constant-speed runs tripped the drive: {}", trip.sentence());
        }
        let (time, velocity, torque) = (
            trace.column("time").context("time")?,
            trace.column("velocity_estimate").context("velocity_estimate")?,
            trace.column("torque_command_out").context("torque_command_out")?,
        );
        let points = segments
            .iter()
            .map(|s| {
                let idx: Vec<usize> = (0..time.len()).filter(|&k| time[k] >= s.from && time[k] < s.to).collect();
                let mean = |x: &[f64]| idx.iter().map(|&k| x[k]).sum::<f64>() / idx.len() as f64;
                SpeedPoint { velocity: mean(&velocity), torque: mean(&torque) }
            })
            .collect();
        Ok((points, trace))
    }
}
