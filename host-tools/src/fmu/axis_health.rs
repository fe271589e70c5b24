//! What a run's trace says about the drive beyond the positions it followed: whether it
//! tripped (the first step with a latched fault: when, and which), and on how many steps its
//! torque command sat at its limit (the loop ran out of torque there: what was measured
//! through it is not the linear loop's response).

use std::collections::BTreeMap;
use std::ops::Range;

use anyhow::{anyhow, bail, Result};
use control_core::torque_ceiling::{ExcitationEntry, TorqueCeiling};
use control_core::Faults;
use serde::Serialize;

use crate::fmu::configuration::configuration;
use crate::fmu::scenario::Value;
use crate::fmu::trace::Trace;

/// The drive latched a fault: its PWM went off, and the axis stopped following its command.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Trip {
    /// Simulated time of the first recorded step with a fault latched (s).
    pub time_s: f64,
    /// The faults latched then, by name ("following error").
    pub faults: String,
    /// The same as the drive's bit set (`control_core::Faults`).
    pub bits: u32,
}

impl Trip {
    /// What a user reads: what happened, and what it means for a run's results.
    pub fn sentence(&self) -> String {
        format!(
            "the drive latched a fault at t = {:.4} s ({}) and switched its bridge off: nothing measured from there on is the loop's response",
            self.time_s, self.faults
        )
    }
}

/// The first recorded step of `trace` with a fault latched (its `faults` output), if any.
pub fn first_trip(trace: &Trace) -> Result<Option<Trip>> {
    let (time, faults) = (column(trace, "time")?, column(trace, "faults")?);
    Ok(faults.iter().position(|&f| f != 0.0).map(|i| {
        let bits = faults[i] as u32;
        Trip { time_s: time[i], faults: Faults(bits).to_string(), bits }
    }))
}

/// The largest torque the drive commands with `parameters` without a clamp cutting it, for a
/// run with no injection and no dither (a circle, tune's streamed multisine): its torque
/// limit, or the current limit's torque (kt·max_current) where that is lower
/// ([`TorqueCeiling`]).
pub fn torque_ceiling(parameters: &BTreeMap<String, Value>) -> Result<TorqueCeiling> {
    let c = configuration(parameters)?.control;
    Ok(TorqueCeiling::of(&c, ExcitationEntry::BeforeTheLoopClamp, 0.0))
}

/// How many of some steps had the torque command at its limit.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct LimitedSteps {
    pub limited: usize,
    pub steps: usize,
    /// `limited / steps` (0..1).
    pub share: f64,
}

/// The steps `rows` of `trace` (row indices) whose torque command (`torque_command_out`, after
/// the limits) sits at `ceiling` N·m either way. The core clamps to the limit exactly, so a
/// step at the limit reads the limit itself (up to the f32 rounding of kt·max_current).
pub fn torque_limited(trace: &Trace, rows: Range<usize>, ceiling: f64) -> Result<LimitedSteps> {
    let torque = column(trace, "torque_command_out")?;
    let Some(torque) = torque.get(rows.clone()) else {
        bail!("the trace has {} rows, not the {} to {} asked for", torque.len(), rows.start, rows.end);
    };
    let at_limit = ceiling * (1.0 - f32::EPSILON as f64);
    let limited = torque.iter().filter(|t| t.abs() >= at_limit).count();
    Ok(LimitedSteps { limited, steps: torque.len(), share: limited as f64 / torque.len().max(1) as f64 })
}

/// Share of the torque ceiling's current a measured q current may reach before a response
/// measured through it counts as near the clamp: the measured current overshoots the clamped
/// reference and rides on the current loop's ripple, so an exact comparison would miss it.
pub const NEAR_CEILING: f64 = 0.9;

/// The largest |q current| (A) of `trace` where it reaches [`NEAR_CEILING`] of `ceiling`'s
/// current (the current limit's own, or the torque limit's as a current, `torque_limit / kt`,
/// whichever binds), else None.
pub fn current_near_ceiling(trace: &Trace, ceiling: &TorqueCeiling) -> Result<Option<f64>> {
    let largest = column(trace, "iq")?.iter().fold(0.0f64, |a, x| a.max(x.abs()));
    Ok((largest >= NEAR_CEILING * ceiling.current as f64).then_some(largest))
}

fn column(trace: &Trace, name: &str) -> Result<Vec<f64>> {
    trace.column(name).ok_or_else(|| anyhow!("the trace has no {name} (an FMU without that output?)"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn trace(rows: &[[f64; 3]]) -> Trace {
        let mut t = Trace::new(["time", "torque_command_out", "faults"].map(String::from).to_vec());
        for r in rows {
            t.rows.push(r);
        }
        t
    }

    #[test]
    fn the_first_latched_fault_is_the_trip_with_its_time_and_names() {
        let t = trace(&[[0.0, 0.0, 0.0], [0.1, 1.0, 0.0], [0.2, 2.0, 8.0], [0.3, 0.0, 9.0]]);
        let trip = first_trip(&t).unwrap().unwrap();
        assert_eq!(trip, Trip { time_s: 0.2, faults: "following error".into(), bits: Faults::FOLLOWING_ERROR });
        assert!(trip.sentence().contains("at t = 0.2000 s (following error)"), "{}", trip.sentence());
        assert_eq!(first_trip(&trace(&[[0.0, 0.0, 0.0], [0.1, 1.0, 0.0]])).unwrap(), None);
    }

    #[test]
    fn steps_at_the_torque_limit_either_way_are_counted_in_the_rows_asked() {
        let t = trace(&[[0.0, 2.0, 0.0], [0.1, 1.999, 0.0], [0.2, -2.0, 0.0], [0.3, 0.5, 0.0], [0.4, 2.0, 0.0]]);
        let all = torque_limited(&t, 0..5, 2.0).unwrap();
        assert_eq!((all.limited, all.steps, all.share), (3, 5, 0.6));
        assert_eq!(torque_limited(&t, 1..4, 2.0).unwrap().limited, 1);
        assert!(torque_limited(&t, 3..9, 2.0).is_err());
    }

    #[test]
    fn the_ceiling_is_the_lower_of_the_torque_and_current_limits() {
        let one = |k: &str, v: f64| [(k.to_string(), Value::Float(v))].into_iter().collect();
        let default = configuration(&BTreeMap::new()).unwrap().control;
        let kt = default.motor.torque_constant() as f64;
        let low_torque = torque_ceiling(&one("ctrl.torque_limit", 0.5)).unwrap();
        assert_eq!((low_torque.torque, low_torque.clamp.parameter()), (0.5, "velocity.torque_limit"));
        let low_current = torque_ceiling(&one("ctrl.max_current", 1.0)).unwrap();
        assert_eq!(low_current.clamp.parameter(), "current.max_current");
        let low_current = low_current.torque as f64;
        assert!((low_current - kt).abs() < 1e-6 * kt, "{low_current} vs kt {kt}");
    }
}
