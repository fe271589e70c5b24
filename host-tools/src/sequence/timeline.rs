//! Stop-sequence scenarios (seed 004): a timeline of key events and expectations, run on the
//! FMU in mode 3.
//!
//! ```toml
//! name = "stop_at_speed"
//! description = "run at 100 rad/s, switch off and press stop at speed"
//! stop_time = 1.5
//!
//! [parameters]                 # FMU parameters (seq.*, ctrl.*, plant.*)
//! "seq.zero_speed" = 2.0
//!
//! [[events]]                   # run | run_off | stop | release | move | return | gain
//! time = 0.0
//! event = "run"
//! [[events]]
//! time = 0.3
//! event = "run_off"
//! [[events]]
//! time = 0.3
//! event = "stop"               # held pending until |speed| <= seq.zero_speed
//! [[events]]
//! time = 0.8
//! event = "move"
//! target = 35.0                # rad (fine adjust only)
//! [[events]]
//! time = 1.0
//! event = "gain"
//! index = 3                    # gain-table entry, 0-based
//!
//! [[expect]]                   # one kind per entry:
//! completion_within = 0.2      # completion reached within 0.2 s after `after` and held
//! after = 0.3                  #   until `until` (default: the next event or the end)
//! [[expect]]
//! state = "servo_lock"         # idle | running | decelerating | servo_lock | fine_adjust
//! at = 0.5
//! [[expect]]
//! deviation_counts = 2         # |target − position| <= 2 counts at `at`
//! at = 1.5
//! [[expect]]
//! refused = 1                  # refused events so far, at `at`
//! at = 0.4
//! last_refusal = 3             # optional with `refused`: reason code (see the FMU output)
//! [[expect]]
//! signal = "motor_velocity"    # or any FMU output with min/max at `at` or over from/to
//! at = 0.2
//! min = 99.0
//! ```
//!
//! On the FMU the keys are counter inputs (a press is an increase), the run switch and the
//! gain index are levels; the scenario is translated into those inputs, so fmpy runs the very
//! same input table.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use control_core::axis::Mode;
use serde::{Deserialize, Serialize};

use crate::fmu::scenario::{Check, Event, Scenario, Value, DEFAULT_STEP};
use crate::fmu::trace::Trace;

pub const STATES: [&str; 5] = ["idle", "running", "decelerating", "servo_lock", "fine_adjust"];

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyEvent {
    pub time: f64,
    pub event: String,
    /// `move`: target (rad).
    pub target: Option<f64>,
    /// `gain`: table index.
    pub index: Option<i64>,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Expectation {
    pub description: Option<String>,
    pub completion_within: Option<f64>,
    pub after: Option<f64>,
    pub until: Option<f64>,
    pub state: Option<String>,
    pub deviation_counts: Option<i64>,
    pub refused: Option<i64>,
    pub last_refusal: Option<i64>,
    pub signal: Option<String>,
    pub at: Option<f64>,
    pub from: Option<f64>,
    pub to: Option<f64>,
    pub min: Option<f64>,
    pub max: Option<f64>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SequenceScenario {
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub stop_time: f64,
    #[serde(default)]
    pub parameters: BTreeMap<String, Value>,
    #[serde(default)]
    pub events: Vec<KeyEvent>,
    #[serde(default)]
    pub expect: Vec<Expectation>,
}

/// The result of one expectation.
#[derive(Clone, Debug, Serialize)]
pub struct Outcome {
    pub description: String,
    pub passed: bool,
    /// What was seen, in words and numbers.
    pub observed: String,
    /// What was asked.
    pub bound: String,
}

fn on_grid(t: f64, what: &str, stop: f64) -> Result<()> {
    let k = t / DEFAULT_STEP;
    if !(t.is_finite() && t >= 0.0 && t <= stop + 1e-12) || (k - k.round()).abs() > 1e-6 {
        bail!("{what} {t} s must lie in [0, stop_time = {stop}] on the {DEFAULT_STEP} s grid");
    }
    Ok(())
}

impl SequenceScenario {
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let s: Self =
            toml::from_str(&text).with_context(|| format!("sequence scenario {} is malformed", path.display()))?;
        s.validate().with_context(|| format!("sequence scenario {} is invalid", path.display()))?;
        Ok(s)
    }

    pub fn validate(&self) -> Result<()> {
        if !(self.stop_time.is_finite() && self.stop_time > 0.0) {
            bail!("stop_time must be a positive number of seconds");
        }
        on_grid(self.stop_time, "stop_time", self.stop_time)?;
        let mut last = 0.0;
        let mut seen_at_time: Vec<(f64, &str)> = Vec::new();
        for e in &self.events {
            on_grid(e.time, &format!("event `{}` at", e.event), self.stop_time)?;
            if e.time < last {
                bail!("events must be in time order ({} s comes after {last} s)", e.time);
            }
            last = e.time;
            if seen_at_time.iter().any(|(t, n)| *t == e.time && *n == e.event) {
                bail!("two `{}` events at {} s: the FMU sees one press per key and step", e.event, e.time);
            }
            seen_at_time.push((e.time, &e.event));
            let (needs_target, needs_index) = match e.event.as_str() {
                "run" | "run_off" | "stop" | "release" | "return" => (false, false),
                "move" => (true, false),
                "gain" => (false, true),
                other => bail!(
                    "unknown event `{other}` at {} s: use run, run_off, stop, release, move, return or gain",
                    e.time
                ),
            };
            match (needs_target, e.target) {
                (true, None) => bail!("`move` at {} s needs `target` (rad)", e.time),
                (true, Some(t)) if !(t.is_finite() && t.abs() <= 1e9) => {
                    bail!("`move` at {} s: target {t} is not a finite angle", e.time)
                }
                (false, Some(_)) => bail!("`{}` at {} s takes no `target`", e.event, e.time),
                _ => {}
            }
            match (needs_index, e.index) {
                (true, None) => bail!("`gain` at {} s needs `index`", e.time),
                (true, Some(i)) if i32::try_from(i).is_err() => {
                    bail!("`gain` at {} s: index {i} is out of range", e.time)
                }
                (false, Some(_)) => bail!("`{}` at {} s takes no `index`", e.event, e.time),
                _ => {}
            }
        }
        for x in &self.expect {
            let kinds = [
                x.completion_within.is_some(),
                x.state.is_some(),
                x.deviation_counts.is_some(),
                x.refused.is_some(),
                x.signal.is_some(),
            ];
            if kinds.iter().filter(|&&k| k).count() != 1 {
                bail!("each [[expect]] needs exactly one of completion_within, state, deviation_counts, refused, signal: {x:?}");
            }
            for t in [x.at, x.after, x.until, x.from, x.to].into_iter().flatten() {
                on_grid(t, "expectation time", self.stop_time)?;
            }
            if let Some(w) = x.completion_within {
                if !(w.is_finite() && w >= 0.0) || x.after.is_none() {
                    bail!("completion_within needs a time >= 0 and `after`");
                }
            }
            if let Some(s) = &x.state {
                if !STATES.contains(&s.as_str()) || x.at.is_none() {
                    bail!("state expectation needs `at` and one of {STATES:?} (got {s:?})");
                }
            }
            if let Some(d) = x.deviation_counts {
                if d < 0 || x.at.is_none() {
                    bail!("deviation_counts needs `at` and a width >= 0 (got {d})");
                }
            }
            if x.refused.is_some() && x.at.is_none() {
                bail!("refused expectation needs `at`");
            }
            if x.last_refusal.is_some() && x.refused.is_none() {
                bail!("last_refusal goes with a `refused` expectation");
            }
            if x.signal.is_some()
                && (x.min.is_none() && x.max.is_none() || x.at.is_none() && (x.from.is_none() || x.to.is_none()))
            {
                bail!("signal expectation needs min and/or max, and `at` or `from` and `to`");
            }
        }
        Ok(())
    }

    /// The FMU input table: mode 3 from the start; keys become counter increases, the run
    /// switch and the gain index levels.
    pub fn to_scenario(&self) -> Scenario {
        let mut counters: BTreeMap<&str, i64> = BTreeMap::new();
        let mut events: Vec<Event> = vec![Event {
            time: 0.0,
            inputs: [("mode".to_string(), Value::code(Mode::Sequence.code()))].into_iter().collect(),
        }];
        for e in &self.events {
            if events.last().is_none_or(|last| last.time != e.time) {
                events.push(Event { time: e.time, inputs: BTreeMap::new() });
            }
            let inputs = &mut events.last_mut().expect("pushed above").inputs;
            let mut press = |name: &'static str| {
                let c = counters.entry(name).or_insert(0);
                *c += 1;
                inputs.insert(name.to_string(), Value::Int(*c));
            };
            match e.event.as_str() {
                "run" => {
                    inputs.insert("seq_run".into(), Value::Int(1));
                }
                "run_off" => {
                    inputs.insert("seq_run".into(), Value::Int(0));
                }
                "stop" => press("seq_stop"),
                "release" => press("seq_release"),
                "return" => press("seq_return"),
                "move" => {
                    press("seq_move");
                    inputs.insert("seq_target".into(), Value::Float(e.target.unwrap_or(0.0)));
                }
                "gain" => {
                    inputs.insert("seq_gain_index".into(), Value::Int(e.index.unwrap_or(0)));
                }
                _ => unreachable!("validated"),
            }
        }
        Scenario {
            name: self.name.clone(),
            description: self.description.clone(),
            stop_time: self.stop_time,
            step: Some(DEFAULT_STEP),
            parameters: self.parameters.clone(),
            events,
            checks: vec![],
            plot: vec![],
            record: vec![],
        }
    }

    /// Evaluate every expectation on the FMU's trace.
    pub fn evaluate(&self, trace: &Trace) -> Result<Vec<Outcome>> {
        let col = |n: &str| trace.column(n).ok_or_else(|| anyhow!("the FMU has no output `{n}`"));
        let time = col("time")?;
        let index = |t: f64| time.iter().position(|&x| x >= t - 0.5 * DEFAULT_STEP).unwrap_or(time.len() - 1);
        let mut out = Vec::new();
        for x in &self.expect {
            let (passed, observed, bound, default_text) = if let Some(w) = x.completion_within {
                let after = x.after.expect("validated");
                let until = x.until.unwrap_or_else(|| {
                    self.events.iter().map(|e| e.time).find(|&t| t > after).unwrap_or(self.stop_time)
                });
                let complete = col("seq_complete")?;
                let (i0, i1) = (index(after), index(until));
                // Completion for good: the first sample after which the flag stays set to `until`.
                let settled = (i0..=i1).rev().take_while(|&i| complete[i] != 0.0).last();
                let observed = match settled {
                    Some(i) => {
                        format!("complete from {:.4} s ({:.1} ms after {after} s)", time[i], (time[i] - after) * 1e3)
                    }
                    None => format!("not complete at {until} s"),
                };
                let passed = settled.is_some_and(|i| time[i] - after <= w + 1e-9);
                (
                    passed,
                    observed,
                    format!("within {:.1} ms, held to {until} s", w * 1e3),
                    format!("completion within {:.0} ms", w * 1e3),
                )
            } else if let Some(s) = &x.state {
                let at = x.at.expect("validated");
                let code = col("seq_state")?[index(at)] as usize;
                let seen = STATES.get(code).copied().unwrap_or("?");
                (seen == s, format!("{seen} at {at} s"), s.clone(), format!("state {s} at {at} s"))
            } else if let Some(d) = x.deviation_counts {
                let at = x.at.expect("validated");
                let dev = col("seq_deviation")?[index(at)];
                (
                    dev.abs() <= d as f64,
                    format!("{dev} counts at {at} s"),
                    format!("|deviation| <= {d} counts"),
                    format!("position error <= {d} counts at {at} s"),
                )
            } else if let Some(n) = x.refused {
                let at = x.at.expect("validated");
                let i = index(at);
                let seen = col("seq_refused")?[i] as i64;
                let reason = col("seq_last_refusal")?[i] as i64;
                let passed = seen == n && x.last_refusal.is_none_or(|r| r == reason);
                let bound = match x.last_refusal {
                    Some(r) => format!("{n} refused, last reason {r}"),
                    None => format!("{n} refused"),
                };
                (
                    passed,
                    format!("{seen} refused, last reason {reason} at {at} s"),
                    bound,
                    format!("{n} event(s) refused by {at} s"),
                )
            } else {
                let signal = x.signal.clone().expect("validated");
                let check = Check {
                    signal: signal.clone(),
                    at: x.at,
                    from: x.from,
                    to: x.to,
                    min: x.min,
                    max: x.max,
                    description: None,
                };
                let scenario = Scenario { checks: vec![check], ..self.to_scenario() };
                let r = crate::fmu::runner::evaluate_checks(&scenario, trace)?.remove(0);
                let bound = format!(
                    "{} … {}",
                    x.min.map_or("-inf".into(), |v| v.to_string()),
                    x.max.map_or("+inf".into(), |v| v.to_string())
                );
                (r.passed, format!("{} … {}", r.observed.0, r.observed.1), bound, format!("{signal} in bounds"))
            };
            out.push(Outcome { description: x.description.clone().unwrap_or(default_text), passed, observed, bound });
        }
        Ok(out)
    }
}

/// Signals of the sequence plot, on one timeline.
pub const PLOT: [&str; 6] =
    ["motor_velocity", "motor_position", "seq_deviation", "seq_state", "seq_complete", "seq_refused"];

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<SequenceScenario> {
        let sc: SequenceScenario = toml::from_str(s)?;
        sc.validate()?;
        Ok(sc)
    }

    #[test]
    fn keys_become_counter_increases_and_levels() {
        let s = parse(
            "name='x'\nstop_time=1.0\n[[events]]\ntime=0.0\nevent='run'\n[[events]]\ntime=0.5\nevent='run_off'\n\
             [[events]]\ntime=0.5\nevent='stop'\n[[events]]\ntime=0.6\nevent='stop'\n[[events]]\ntime=0.7\nevent='move'\ntarget=3.5\n\
             [[events]]\ntime=0.8\nevent='gain'\nindex=2\n",
        )
        .unwrap();
        let sc = s.to_scenario();
        let changes = sc.changes();
        assert_eq!(changes[0], (0, vec![("mode", Value::Int(3)), ("seq_run", Value::Int(1))]));
        assert_eq!(changes[1], (2000, vec![("seq_run", Value::Int(0)), ("seq_stop", Value::Int(1))]));
        assert_eq!(changes[2], (2400, vec![("seq_stop", Value::Int(2))]));
        assert_eq!(changes[3], (2800, vec![("seq_move", Value::Int(1)), ("seq_target", Value::Float(3.5))]));
        assert_eq!(changes[4], (3200, vec![("seq_gain_index", Value::Int(2))]));
    }

    #[test]
    fn malformed_timelines_are_refused_with_the_reason() {
        for (text, reason) in [
            ("[[events]]\ntime=0.0\nevent='jump'\n", "unknown event"),
            ("[[events]]\ntime=0.0\nevent='move'\n", "needs `target`"),
            ("[[events]]\ntime=0.0\nevent='gain'\n", "needs `index`"),
            ("[[events]]\ntime=0.0\nevent='stop'\n[[events]]\ntime=0.0\nevent='stop'\n", "two `stop`"),
            ("[[events]]\ntime=0.00001\nevent='stop'\n", "grid"),
            ("[[expect]]\nstate='flying'\nat=0.5\n", "state expectation"),
            ("[[expect]]\ndeviation_counts=-1\nat=0.5\n", "width >= 0"),
            ("[[expect]]\nrefused=1\nstate='idle'\nat=0.5\n", "exactly one"),
        ] {
            let e = parse(&format!("name='x'\nstop_time=1.0\n{text}")).unwrap_err();
            assert!(format!("{e:#}").contains(reason), "{text}: {e:#}");
        }
    }
}
