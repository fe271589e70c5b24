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
//! completion_within = 0.2      # completion first raised within 0.2 s after `after` and,
//! after = "stop"               #   once raised, held until `until` (default: the next key
//!                              #   event or the end); `held = false` asks only that it rises
//! [[expect]]
//! state = "servo_lock"         # idle | running | decelerating | servo_lock | fine_adjust
//! at = "accepted + 50 ms"
//! [[expect]]
//! deviation = "2 counts"       # |target − position| at `at`; counts, rad, mrad, deg or rev
//! at = 1.5                     #   (`deviation_counts = 2` is the same in plain counts)
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
//! Times (`at`, `after`, `until`, `from`, `to`) are seconds from the start or relative to an
//! event: a key event by name (`"move#2 + 0.1 s"`), `"accepted"` (the stop accepted, read off
//! the run) or `"completed"` (completion raised); a `move` target and signal bounds may carry
//! an angle unit (`target = "90 deg"`, `min = "31.999 rad"`). See [`crate::sequence::timeline_reference`].
//!
//! On the FMU the keys are counter inputs (a press is an increase), the run switch and the
//! gain index are levels; the scenario is translated into those inputs, so fmpy runs the very
//! same input table.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use control_core::axis::Mode;
use control_core::stop_sequence::Refusal;
use serde::{Deserialize, Serialize};

use crate::fmu::scenario::{Check, Event, Scenario, Value, DEFAULT_STEP};
use crate::fmu::trace::Trace;
use crate::fmu::trace_budget::{check_trace_size, fmu_output_count};
use crate::sequence::timeline_reference::{key_time, Anchor, AngleSpec, PlainUnit, RunMarks, TimeSpec};

pub const STATES: [&str; 5] = ["idle", "running", "decelerating", "servo_lock", "fine_adjust"];

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct KeyEvent {
    pub time: f64,
    pub event: String,
    /// `move`: target (a plain number is rad; or with a unit: `"2048 counts"`, `"90 deg"`).
    pub target: Option<AngleSpec>,
    /// `gain`: table index.
    pub index: Option<i64>,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Expectation {
    pub description: Option<String>,
    pub completion_within: Option<f64>,
    /// With `completion_within`: once raised, the completion must stay raised until `until`
    /// (default true: what a PLC that latches the first completion relies on).
    pub held: Option<bool>,
    pub after: Option<TimeSpec>,
    pub until: Option<TimeSpec>,
    pub state: Option<String>,
    /// Largest |deviation| at `at`: a plain number is counts, or with a unit.
    pub deviation: Option<AngleSpec>,
    pub deviation_counts: Option<i64>,
    pub refused: Option<i64>,
    pub last_refusal: Option<i64>,
    pub signal: Option<String>,
    pub at: Option<TimeSpec>,
    pub from: Option<TimeSpec>,
    pub to: Option<TimeSpec>,
    /// Bounds of a signal in its own unit; angle signals (rad) and `seq_deviation` (counts)
    /// also take a unit.
    pub min: Option<AngleSpec>,
    pub max: Option<AngleSpec>,
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

impl Outcome {
    /// Its line in a report.
    pub fn print(&self) {
        println!(
            "  [{}] {:<52} {:<48} asked: {}",
            if self.passed { "pass" } else { "FAIL" },
            self.description,
            self.observed,
            self.bound
        );
    }
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
        crate::fmu::scenario::check_step_fits_position_loop(DEFAULT_STEP, true, &self.parameters)
            .context("a timeline runs at the default step")?;
        // The run records every output of the FMU at the default step.
        check_trace_size(self.stop_time, DEFAULT_STEP, 1 + fmu_output_count())
            .map_err(|e| anyhow!("{e} (a timeline records every output at the {DEFAULT_STEP} s step)"))?;
        let cpr = self.counts_per_rev();
        if !(cpr.is_finite() && cpr >= 1.0) {
            bail!("plant.encoder_counts_per_rev {cpr} must be a positive number of counts");
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
            match (needs_target, &e.target) {
                (true, None) => bail!("`move` at {} s needs `target` (rad, or with a unit)", e.time),
                (true, Some(t)) => {
                    let rad = t
                        .to_rad(PlainUnit::Rad, self.counts_per_rev())
                        .with_context(|| format!("`move` at {} s", e.time))?;
                    if rad.abs() > 1e9 {
                        bail!("`move` at {} s: target {t} is beyond ±1e9 rad", e.time)
                    }
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
                x.deviation.is_some() || x.deviation_counts.is_some(),
                x.refused.is_some(),
                x.signal.is_some(),
            ];
            if kinds.iter().filter(|&&k| k).count() != 1 || x.deviation.is_some() && x.deviation_counts.is_some() {
                bail!("each [[expect]] needs exactly one of completion_within, state, deviation (or deviation_counts), refused, signal: {x:?}");
            }
            for t in [&x.at, &x.after, &x.until, &x.from, &x.to].into_iter().flatten() {
                self.check_time(t)?;
            }
            if let Some(w) = x.completion_within {
                if !(w.is_finite() && w >= 0.0) || x.after.is_none() {
                    bail!("completion_within needs a time >= 0 and `after`");
                }
            } else if x.held.is_some() {
                bail!("`held` goes with a `completion_within` expectation");
            }
            if let Some(d) = &x.deviation {
                let counts = d.to_counts(PlainUnit::Counts, self.counts_per_rev()).context("deviation")?;
                if counts < 0.0 || x.at.is_none() {
                    bail!("deviation needs `at` and a width >= 0 (got {d})");
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
            if let Some(n) = x.refused {
                if n < 0 {
                    bail!("refused = {n}: a count of refused events is 0 or more");
                }
            }
            if x.last_refusal.is_some() && x.refused.is_none() {
                bail!("last_refusal goes with a `refused` expectation");
            }
            if let Some(r) = x.last_refusal {
                let most = Refusal::NotInSequenceMode.code() as i64;
                if !(0..=most).contains(&r) {
                    bail!("last_refusal = {r} is not a reason code: 0 (none) to {most} (see the FMU output seq_last_refusal)");
                }
            }
            if let Some(signal) = &x.signal {
                if x.min.is_none() && x.max.is_none() || x.at.is_none() && (x.from.is_none() || x.to.is_none()) {
                    bail!("signal expectation needs min and/or max, and `at` or `from` and `to`");
                }
                self.check_signal_expectation(signal, x)?;
            }
        }
        Ok(())
    }

    /// A signal expectation names an output of the FMU, its bounds are numbers in the signal's
    /// unit that some value satisfies (min <= max) and its window, where known before the run,
    /// is not reversed.
    fn check_signal_expectation(&self, signal: &str, x: &Expectation) -> Result<()> {
        use servo_axis::variables::Causality;
        match servo_axis::variables::by_name(signal) {
            Some(d) if d.causality == Causality::Output => {}
            Some(d) => bail!("signal = {signal:?} is not an output of the FMU (its causality is {:?})", d.causality),
            None => {
                let close: Vec<&str> = servo_axis::variables::DECLARATIONS
                    .iter()
                    .filter(|d| {
                        d.causality == Causality::Output && (d.name.contains(signal) || signal.contains(d.name))
                    })
                    .map(|d| d.name)
                    .take(5)
                    .collect();
                let hint = if close.is_empty() { String::new() } else { format!(" (did you mean {close:?}?)") };
                bail!("signal = {signal:?} is not an output of the FMU{hint}");
            }
        }
        let bound = |b: &Option<AngleSpec>, field: &str| -> Result<Option<f64>> {
            let Some(b) = b else { return Ok(None) };
            let v = self.signal_bound(signal, b)?;
            if v.is_nan() {
                bail!("signal {signal}: {field} = {b} is not a number");
            }
            Ok(Some(v))
        };
        if let (Some(lo), Some(hi)) = (bound(&x.min, "min")?, bound(&x.max, "max")?) {
            if lo > hi {
                bail!(
                    "signal {signal}: min = {} is above max = {}: no value passes",
                    x.min.as_ref().expect("bound"),
                    x.max.as_ref().expect("bound")
                );
            }
        }
        if let (Some(from), Some(to)) = (&x.from, &x.to) {
            if let (Some(a), Some(b)) = (self.time_before_run(from)?, self.time_before_run(to)?) {
                if a > b {
                    bail!("signal {signal}: from = `{from}` ({a} s) is after to = `{to}` ({b} s)");
                }
            }
        }
        Ok(())
    }

    /// Seconds from the start of a time field that does not depend on the run (None for
    /// `accepted` and `completed`, read off the run).
    fn time_before_run(&self, spec: &TimeSpec) -> Result<Option<f64>> {
        let r = spec.parse()?;
        Ok(match &r.anchor {
            None => Some(r.offset),
            Some(Anchor::Key { event, occurrence, explicit }) => {
                Some(key_time(&self.key_events(), event, *occurrence, *explicit)? + r.offset)
            }
            Some(Anchor::Accepted(_) | Anchor::Completed(_)) => None,
        })
    }

    /// Encoder counts per revolution of this run (its parameter, or the FMU's default).
    pub fn counts_per_rev(&self) -> f64 {
        const NAME: &str = "plant.encoder_counts_per_rev";
        match self.parameters.get(NAME) {
            Some(Value::Int(n)) => *n as f64,
            Some(Value::Float(x)) => *x,
            _ => servo_axis::variables::by_name(NAME)
                .and_then(|d| servo_axis::variables::Values::start().get(d.vr))
                .map_or(f64::NAN, |v| Value::from(v).as_f64()),
        }
    }

    /// The key events as (time, name), in timeline order.
    fn key_events(&self) -> Vec<(f64, &str)> {
        self.events.iter().map(|e| (e.time, e.event.as_str())).collect()
    }

    /// A time field is well formed and, where it does not depend on the run, on the grid
    /// inside the run.
    fn check_time(&self, spec: &TimeSpec) -> Result<()> {
        let r = spec.parse()?;
        let base = match &r.anchor {
            None => 0.0,
            Some(Anchor::Key { event, occurrence, explicit }) => {
                key_time(&self.key_events(), event, *occurrence, *explicit)?
            }
            Some(Anchor::Accepted(_)) => {
                if !self.events.iter().any(|e| e.event == "stop") {
                    bail!("`{spec}`: the timeline has no `stop`, so nothing is accepted");
                }
                return Ok(());
            }
            Some(Anchor::Completed(_)) => return Ok(()),
        };
        on_grid(base + r.offset, &format!("expectation time `{spec}` =", spec = spec), self.stop_time)
    }

    /// A signal bound in the signal's own unit: plain numbers as they are; an angle unit for
    /// signals in rad, and for `seq_deviation` (counts).
    fn signal_bound(&self, signal: &str, bound: &AngleSpec) -> Result<f64> {
        use servo_axis::variables::Unit;
        match bound {
            AngleSpec::Plain(x) => Ok(*x),
            AngleSpec::WithUnit(_) => {
                let cpr = self.counts_per_rev();
                if signal == "seq_deviation" {
                    return bound.to_counts(PlainUnit::Counts, cpr);
                }
                match servo_axis::variables::by_name(signal).and_then(|d| d.unit) {
                    Some(Unit::Radian) => bound.to_rad(PlainUnit::Rad, cpr),
                    _ => bail!("bound {bound} of `{signal}`: only angles (rad) and seq_deviation take a unit"),
                }
            }
        }
    }

    /// Seconds from the start of a time field on this run; `Err` says why the run has no
    /// such moment (e.g. the stop was never accepted).
    fn resolve(&self, spec: &TimeSpec, marks: &RunMarks, time: &[f64]) -> Result<f64> {
        let r = spec.parse()?;
        let mark = |v: &[usize], n: usize, what: &str| {
            v.get(n - 1).map(|&i| time[i]).ok_or_else(|| anyhow!("`{spec}`: the run shows {} {what}", v.len()))
        };
        let base = match &r.anchor {
            None => 0.0,
            Some(Anchor::Key { event, occurrence, explicit }) => {
                key_time(&self.key_events(), event, *occurrence, *explicit)?
            }
            Some(Anchor::Accepted(n)) => mark(&marks.accepted, *n, "stop acceptance(s)")?,
            Some(Anchor::Completed(n)) => mark(&marks.completed, *n, "completion(s)")?,
        };
        let t = base + r.offset;
        // Judged on a sample of the run, never on the nearest end of it.
        if !(t >= -1e-12 && t <= self.stop_time + 1e-12) {
            bail!("`{spec}` is {t:.4} s, outside the run [0, {} s]", self.stop_time);
        }
        Ok(t)
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
                    let target = e.target.as_ref().expect("validated").to_rad(PlainUnit::Rad, self.counts_per_rev());
                    inputs.insert("seq_target".into(), Value::Float(target.expect("validated")));
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

    /// Evaluate every expectation on the FMU's trace. A time the run never reaches (a stop
    /// never accepted, say) fails its expectation with the reason.
    pub fn evaluate(&self, trace: &Trace) -> Result<Vec<Outcome>> {
        let col = |n: &str| trace.column(n).ok_or_else(|| anyhow!("the FMU has no output `{n}`"));
        let time = col("time")?;
        if time.is_empty() {
            bail!("the run has no samples");
        }
        let marks = RunMarks::find(&col("seq_state")?, &col("seq_complete")?);
        let mut out = Vec::new();
        for x in &self.expect {
            let (passed, observed, bound, default_text) = match self.evaluate_one(x, trace, &marks, &time) {
                Ok(r) => r,
                Err(e) => (false, format!("{e:#}"), "a run that reaches it".to_string(), "expectation".to_string()),
            };
            out.push(Outcome { description: x.description.clone().unwrap_or(default_text), passed, observed, bound });
        }
        Ok(out)
    }

    /// (passed, observed, bound, default description) of one expectation.
    fn evaluate_one(
        &self,
        x: &Expectation,
        trace: &Trace,
        marks: &RunMarks,
        time: &[f64],
    ) -> Result<(bool, String, String, String)> {
        let col = |n: &str| trace.column(n).ok_or_else(|| anyhow!("the FMU has no output `{n}`"));
        let index = |t: f64| time.iter().position(|&x| x >= t - 0.5 * DEFAULT_STEP).unwrap_or(time.len() - 1);
        let at = |spec: &Option<TimeSpec>| self.resolve(spec.as_ref().expect("validated"), marks, time);
        let span = |spec: &Option<TimeSpec>| spec.as_ref().map(|s| self.resolve(s, marks, time)).transpose();
        Ok(if let Some(w) = x.completion_within {
            let after = at(&x.after)?;
            let until = match span(&x.until)? {
                Some(t) => t,
                None => self.events.iter().map(|e| e.time).find(|&t| t > after).unwrap_or(self.stop_time),
            };
            let held = x.held.unwrap_or(true);
            let complete = col("seq_complete")?;
            let (i0, i1) = (index(after), index(until));
            // The outputs at a key's time show the state before the key acts (it is applied
            // in the step that follows), so the search starts one sample later, except from a
            // moment read off the run itself (`accepted`, `completed`).
            let read_off_run = x
                .after
                .as_ref()
                .and_then(|a| a.parse().ok())
                .is_some_and(|r| matches!(r.anchor, Some(Anchor::Accepted(_) | Anchor::Completed(_))));
            let start = if read_off_run { i0 } else { (i0 + 1).min(i1) };
            // The first sample raised from there; held: never dropped from it to `until`.
            let first = (start..=i1).find(|&i| complete[i] != 0.0);
            let dropped = first.and_then(|f| (f..=i1).find(|&i| complete[i] == 0.0));
            let observed = match (first, dropped) {
                (Some(f), None) => format!(
                    "raised at {:.4} s ({:.1} ms after {after:.4} s), held to {until} s",
                    time[f],
                    (time[f] - after) * 1e3
                ),
                (Some(f), Some(d)) => format!(
                    "raised at {:.4} s ({:.1} ms after {after:.4} s), dropped at {:.4} s",
                    time[f],
                    (time[f] - after) * 1e3,
                    time[d]
                ),
                (None, _) => format!("not raised by {until} s"),
            };
            let in_time = first.is_some_and(|f| time[f] - after <= w + 1e-9);
            let passed = in_time && (!held || dropped.is_none());
            let bound = if held {
                format!("raised within {:.1} ms, held to {until} s", w * 1e3)
            } else {
                format!("raised within {:.1} ms", w * 1e3)
            };
            (passed, observed, bound, format!("completion within {:.0} ms", w * 1e3))
        } else if let Some(s) = &x.state {
            let t = at(&x.at)?;
            let code = col("seq_state")?[index(t)] as usize;
            let seen = STATES.get(code).copied().unwrap_or("?");
            (
                seen == s,
                format!("{seen} at {t:.4} s"),
                s.clone(),
                format!("state {s} at {}", x.at.as_ref().expect("validated")),
            )
        } else if x.deviation.is_some() || x.deviation_counts.is_some() {
            let width = match (&x.deviation, x.deviation_counts) {
                (Some(d), _) => d.to_counts(PlainUnit::Counts, self.counts_per_rev())?,
                (None, d) => d.expect("validated") as f64,
            };
            let t = at(&x.at)?;
            let dev = col("seq_deviation")?[index(t)];
            (
                dev.abs() <= width,
                format!("{dev} counts at {t:.4} s"),
                format!("|deviation| <= {width} counts"),
                format!("position error <= {width} counts at {}", x.at.as_ref().expect("validated")),
            )
        } else if let Some(n) = x.refused {
            let t = at(&x.at)?;
            let i = index(t);
            let seen = col("seq_refused")?[i] as i64;
            let reason = col("seq_last_refusal")?[i] as i64;
            let passed = seen == n && x.last_refusal.is_none_or(|r| r == reason);
            let bound = match x.last_refusal {
                Some(r) => format!("{n} refused, last reason {r}"),
                None => format!("{n} refused"),
            };
            (
                passed,
                format!("{seen} refused, last reason {reason} at {t:.4} s"),
                bound,
                format!("{n} event(s) refused by {t} s"),
            )
        } else {
            let signal = x.signal.clone().expect("validated");
            let bound_value = |b: &Option<AngleSpec>| b.as_ref().map(|b| self.signal_bound(&signal, b)).transpose();
            let (min, max) = (bound_value(&x.min)?, bound_value(&x.max)?);
            let check = Check {
                signal: signal.clone(),
                at: span(&x.at)?,
                from: span(&x.from)?,
                to: span(&x.to)?,
                min,
                max,
                description: None,
            };
            let scenario = Scenario { checks: vec![check], ..self.to_scenario() };
            let r = crate::fmu::runner::evaluate_checks(&scenario, trace)?.remove(0);
            let bound = format!(
                "{} … {}",
                min.map_or("-inf".into(), |v| v.to_string()),
                max.map_or("+inf".into(), |v| v.to_string())
            );
            let observed = match &r.not_evaluated {
                Some(why) => format!("not evaluated: {why}"),
                None => format!("{} … {}", r.observed.0, r.observed.1),
            };
            (r.passed, observed, bound, format!("{signal} in bounds"))
        })
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

    /// A made-up run on the 0.25 ms grid: the stop key at 0.1 s, accepted at 0.12 s,
    /// completion raised at 0.13 s, dropped at 0.131 s (a toggle), raised again at 0.14 s;
    /// the deviation is 3 counts from 0.15 s.
    fn toggling_run() -> Trace {
        let names = ["time", "seq_state", "seq_complete", "seq_deviation", "seq_refused", "seq_last_refusal"];
        let mut t = Trace::new(names.iter().map(|s| s.to_string()).collect());
        for k in 0..=800 {
            let time = k as f64 * DEFAULT_STEP;
            let state = if time < 0.1 - 1e-9 {
                1.0
            } else if time < 0.12 - 1e-9 {
                2.0
            } else {
                3.0
            };
            let complete = ((0.13 - 1e-9..0.131 - 1e-9).contains(&time) || time >= 0.14 - 1e-9) as i32 as f64;
            let dev = if time >= 0.15 - 1e-9 { 3.0 } else { 40.0 };
            t.rows.push([time, state, complete, dev, 0.0, 0.0]);
        }
        t
    }

    fn outcomes(expect: &str) -> Vec<Outcome> {
        let s = parse(&format!(
            "name='x'\nstop_time=0.2\n[[events]]\ntime=0.0\nevent='run'\n[[events]]\ntime=0.1\nevent='run_off'\n\
             [[events]]\ntime=0.1\nevent='stop'\n{expect}"
        ))
        .unwrap();
        s.evaluate(&toggling_run()).unwrap()
    }

    #[test]
    fn a_completion_that_toggles_fails_unless_only_reaching_is_asked() {
        // Raised 30 ms after the stop, within 50 ms, but dropped once: a PLC latching the
        // first edge would move on too early.
        let o = outcomes("[[expect]]\ncompletion_within=0.05\nafter='stop'\n");
        assert!(!o[0].passed && o[0].observed.contains("dropped at 0.1310 s"), "{:?}", o[0]);
        let o = outcomes("[[expect]]\ncompletion_within=0.05\nafter='stop'\nheld=false\n");
        assert!(o[0].passed, "{:?}", o[0]);
        // Counted from the second rise, it is held.
        let o = outcomes("[[expect]]\ncompletion_within=0.001\nafter='completed#2'\n");
        assert!(o[0].passed, "{:?}", o[0]);
        // Too slow for 20 ms after the stop.
        let o = outcomes("[[expect]]\ncompletion_within=0.02\nafter='stop'\nheld=false\n");
        assert!(!o[0].passed, "{:?}", o[0]);
    }

    #[test]
    fn relative_times_and_units_give_what_the_absolute_numbers_give() {
        let relative = outcomes(
            "[[expect]]\nstate='servo_lock'\nat='accepted'\n[[expect]]\nstate='decelerating'\nat='accepted - 0.25 ms'\n\
             [[expect]]\ndeviation='3 counts'\nat='stop + 50 ms'\n[[expect]]\ndeviation='2 counts'\nat='stop + 50 ms'\n\
             [[expect]]\nsignal='seq_deviation'\nfrom='completed#2 + 10 ms'\nto=0.2\nmax='3 counts'\n",
        );
        let absolute = outcomes(
            "[[expect]]\nstate='servo_lock'\nat=0.12\n[[expect]]\nstate='decelerating'\nat=0.11975\n\
             [[expect]]\ndeviation_counts=3\nat=0.15\n[[expect]]\ndeviation_counts=2\nat=0.15\n\
             [[expect]]\nsignal='seq_deviation'\nfrom=0.15\nto=0.2\nmax=3.0\n",
        );
        let passed = |v: &[Outcome]| v.iter().map(|o| o.passed).collect::<Vec<_>>();
        assert_eq!(passed(&relative), vec![true, true, true, false, true]);
        assert_eq!(passed(&relative), passed(&absolute));
        // A time beyond the run fails with the reason, not judged on the last sample.
        let o = outcomes("[[expect]]\nstate='servo_lock'\nat='accepted + 5 s'\n");
        assert!(!o[0].passed && o[0].observed.contains("outside the run"), "{:?}", o[0]);
        // A moment the run never reaches fails its expectation with the reason.
        let o = outcomes("[[expect]]\nstate='servo_lock'\nat='accepted#2'\n");
        assert!(!o[0].passed && o[0].observed.contains("shows 1 stop acceptance"), "{:?}", o[0]);
    }

    #[test]
    fn move_targets_take_a_unit() {
        let s = parse(
            "name='x'\nstop_time=1.0\n[parameters]\n'plant.encoder_counts_per_rev'=4000\n\
             [[events]]\ntime=0.5\nevent='move'\ntarget='1000 counts'\n[[events]]\ntime=0.6\nevent='move'\ntarget='90 deg'\n",
        )
        .unwrap();
        let targets: Vec<Value> = s
            .to_scenario()
            .changes()
            .iter()
            .filter_map(|(_, c)| c.iter().find(|(n, _)| *n == "seq_target"))
            .map(|(_, v)| *v)
            .collect();
        let quarter = std::f64::consts::TAU / 4.0;
        assert!(matches!(targets[0], Value::Float(x) if (x - quarter).abs() < 1e-15), "{targets:?}");
        assert!(matches!(targets[1], Value::Float(x) if (x - quarter).abs() < 1e-15), "{targets:?}");
    }

    #[test]
    fn a_timeline_whose_trace_would_not_fit_memory_is_refused_naming_stop_time() {
        let e = format!("{:#}", parse("name='x'\nstop_time=1e9\n").unwrap_err());
        assert!(
            e.contains("stop_time = 1000000000 s") && e.contains("1 GiB") && e.contains("at most stop_time"),
            "{e}"
        );
        assert!(parse("name='x'\nstop_time=100.0\n").is_ok());
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
            ("[[expect]]\nstate='idle'\nat='stop'\n", "has 0 `stop`"),
            ("[[expect]]\nstate='idle'\nat='accepted'\n", "no `stop`"),
            ("[[expect]]\nstate='idle'\nat='soon'\n", "unknown event `soon`"),
            ("[[expect]]\ndeviation='2 inches'\nat=0.5\n", "unknown unit"),
            ("[[expect]]\nsignal='motor_velocity'\nat=0.5\nmax='3 rad'\n", "only angles"),
            ("[[expect]]\nstate='idle'\nat=0.5\nheld=true\n", "`held` goes with"),
            ("[[events]]\ntime=0.0\nevent='move'\ntarget='3 parsecs'\n", "unknown unit"),
            // Checked when the file is loaded, not after the run.
            ("[[expect]]\nsignal='motor_speed'\nat=0.5\nmax=1.0\n", "signal = \"motor_speed\" is not an output"),
            ("[[expect]]\nsignal='seq_run'\nat=0.5\nmax=1.0\n", "is not an output of the FMU (its causality is Input)"),
            ("[[expect]]\nsignal='motor_velocity'\nat=0.5\nmin=2.0\nmax=1.0\n", "min = 2 is above max = 1"),
            (
                "[[expect]]\nsignal='motor_position'\nat=0.5\nmin='2 rad'\nmax='90 deg'\n",
                "min = 2 rad is above max = 90 deg",
            ),
            ("[[expect]]\nsignal='motor_velocity'\nfrom=0.5\nto=0.2\nmax=1.0\n", "is after to"),
            ("[[expect]]\nrefused=-1\nat=0.5\n", "refused = -1"),
            ("[[expect]]\nrefused=1\nat=0.5\nlast_refusal=42\n", "last_refusal = 42 is not a reason code"),
            ("[[expect]]\nstate='idle'\nat=1.5\n", "must lie in [0, stop_time = 1]"),
        ] {
            let e = parse(&format!("name='x'\nstop_time=1.0\n{text}")).unwrap_err();
            assert!(format!("{e:#}").contains(reason), "{text}: {e:#}");
        }
    }
}
