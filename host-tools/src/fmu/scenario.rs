//! Scenario files: parameters, input events over time, stop time and checks.
//!
//! ```toml
//! name = "position_step"
//! description = "1 rad position step on the default axis"
//! stop_time = 0.3          # s, a whole number of steps; the trace it implies must fit
//!                          # `trace_budget::MAX_TRACE_BYTES` (1 GiB)
//! step = 0.00025           # s, optional: communication step, a whole number of position-loop
//!                          # periods (default 0.25 ms: the position-loop period at 16 kHz)
//!
//! [parameters]             # FMU parameters by name
//! "ctrl.position_kp" = 125.7
//!
//! [[events]]               # inputs change at `time` and hold until the next event
//! time = 0.0
//! mode = 2
//! [[events]]
//! time = 0.01
//! position_command = 1.0
//!
//! record = ["motor_position", "iq"]   # optional: outputs to record (default: all)
//!
//! [[checks]]               # evaluated on the result; a failed check makes `servo` exit 1
//! signal = "motor_position"
//! at = 0.3                 # or `from`/`to` for a window, inside [0, stop_time]
//! min = 0.99
//! max = 1.01
//! ```

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{anyhow, bail, Context, Result};
use control_core::axis::Mode;
use serde::Deserialize;

use crate::fmu::trace_budget::{check_trace_size, fmu_output_count};

/// Value of a parameter or an input: a number, an integer or a boolean.
#[derive(Clone, Copy, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum Value {
    Bool(bool),
    Int(i64),
    Float(f64),
}

/// As a user writes it: `-1`, `1e300`, `true`.
impl std::fmt::Display for Value {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match *self {
            Value::Bool(b) => write!(f, "{b}"),
            Value::Int(i) => write!(f, "{i}"),
            Value::Float(x) => f.write_str(&servo_axis::variables::readable(x)),
        }
    }
}

impl From<servo_axis::variables::Value> for Value {
    fn from(v: servo_axis::variables::Value) -> Self {
        match v {
            servo_axis::variables::Value::Float64(x) => Value::Float(x),
            servo_axis::variables::Value::Int32(x) => Value::Int(x as i64),
            servo_axis::variables::Value::Boolean(x) => Value::Bool(x),
        }
    }
}

impl Value {
    /// A coded value (a mode, a filter kind, …): the `code()` of its enum.
    pub fn code(code: i32) -> Self {
        Value::Int(code.into())
    }

    pub fn as_f64(self) -> f64 {
        match self {
            Value::Bool(b) => b as i64 as f64,
            Value::Int(i) => i as f64,
            Value::Float(x) => x,
        }
    }
}

#[derive(Clone, Debug, Deserialize)]
pub struct Event {
    pub time: f64,
    #[serde(flatten)]
    pub inputs: BTreeMap<String, Value>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Check {
    pub signal: String,
    /// Evaluate at this time (the nearest sample).
    pub at: Option<f64>,
    /// Or over a window [from, to] (every sample must satisfy the bounds).
    pub from: Option<f64>,
    pub to: Option<f64>,
    pub min: Option<f64>,
    pub max: Option<f64>,
    /// Optional text for reports.
    pub description: Option<String>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    pub name: String,
    #[serde(default)]
    pub description: String,
    pub stop_time: f64,
    pub step: Option<f64>,
    #[serde(default)]
    pub parameters: BTreeMap<String, Value>,
    #[serde(default)]
    pub events: Vec<Event>,
    #[serde(default)]
    pub checks: Vec<Check>,
    /// Signals to plot (default: a standard set).
    #[serde(default)]
    pub plot: Vec<String>,
    /// Outputs to record, in this order (default: every output of the FMU). Each recorded
    /// value is one more lookup in the FMU per step: a long run that needs a few signals
    /// runs faster when it records only those.
    #[serde(default)]
    pub record: Vec<String>,
}

/// Default communication step: the position-loop period of the default parameters.
pub const DEFAULT_STEP: f64 = 4.0 / 16_000.0;

/// A parameter's value in `parameters`, or the FMU's start value (NaN for an unknown name).
pub fn parameter_or_start(parameters: &BTreeMap<String, Value>, name: &str) -> f64 {
    match parameters.get(name) {
        Some(v) => v.as_f64(),
        None => servo_axis::variables::by_name(name)
            .and_then(|d| servo_axis::variables::Values::start().get(d.vr))
            .map_or(f64::NAN, |v| Value::from(v).as_f64()),
    }
}

/// The FMU takes communication steps of whole position-loop periods
/// (`ctrl.position_divider / ctrl.current_loop_hz`): a step that is not (the default 0.25 ms
/// once the rate is lowered, say) is refused when the file is loaded, saying which period and
/// what to set, rather than by the FMU's first `do_step`. `default` says the step was not
/// written in the file. Rates the FMU itself refuses are left to it.
pub fn check_step_fits_position_loop(step: f64, default: bool, parameters: &BTreeMap<String, Value>) -> Result<()> {
    let rate = parameter_or_start(parameters, "ctrl.current_loop_hz");
    let divider = parameter_or_start(parameters, "ctrl.position_divider");
    if !(rate.is_finite() && rate > 0.0 && divider.is_finite() && divider >= 1.0) {
        return Ok(());
    }
    let period = divider / rate;
    let periods = (step / period).round();
    if periods < 1.0 || (step - periods * period).abs() > 1e-9 * period.max(step) {
        let which = if default { " (the default: the position-loop period at 16 kHz)" } else { "" };
        bail!(
            "step = {step} s{which} is not a whole multiple of the position-loop period {period} s \
             (ctrl.position_divider {divider} / ctrl.current_loop_hz {rate} Hz): set `step` to a multiple of it, \
             e.g. step = {period}"
        );
    }
    Ok(())
}

impl Scenario {
    pub fn load(path: &Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read scenario {}", path.display()))?;
        let s: Scenario = toml::from_str(&text).with_context(|| format!("scenario {} is malformed", path.display()))?;
        s.validate().with_context(|| format!("scenario {} is invalid", path.display()))?;
        Ok(s)
    }

    pub fn step(&self) -> f64 {
        self.step.unwrap_or(DEFAULT_STEP)
    }

    /// Number of communication steps (stop_time / step, which must be whole).
    pub fn steps(&self) -> usize {
        (self.stop_time / self.step()).round() as usize
    }

    pub fn validate(&self) -> Result<()> {
        let h = self.step();
        if !(h.is_finite() && h > 0.0) {
            bail!("step must be a positive number of seconds (got {h})");
        }
        if !(self.stop_time.is_finite() && self.stop_time > 0.0) {
            bail!("stop_time must be a positive number of seconds (got {})", self.stop_time);
        }
        check_step_fits_position_loop(h, self.step.is_none(), &self.parameters)?;
        check_trace_size(self.stop_time, h, self.trace_columns())
            .map_err(|e| anyhow!("{e} (record fewer outputs with `record`, or take a longer `step`)"))?;
        let n = self.stop_time / h;
        if (n - n.round()).abs() > 1e-6 {
            bail!("stop_time {} s is not a whole number of steps of {h} s", self.stop_time);
        }
        for (name, v) in &self.parameters {
            if !v.as_f64().is_finite() {
                bail!("parameter {name} is not a finite number");
            }
        }
        let mut last = f64::NEG_INFINITY;
        for e in &self.events {
            if !(e.time.is_finite() && e.time >= 0.0 && e.time <= self.stop_time) {
                bail!("event time {} s is outside [0, stop_time = {}]", e.time, self.stop_time);
            }
            if e.time < last {
                bail!("events must be in time order ({} s comes after {} s)", e.time, last);
            }
            let k = e.time / h;
            if (k - k.round()).abs() > 1e-6 {
                bail!("event time {} s is not on the communication grid (a multiple of {h} s)", e.time);
            }
            last = e.time;
            if e.inputs.is_empty() {
                bail!("event at {} s sets no input", e.time);
            }
            for (name, v) in &e.inputs {
                if !v.as_f64().is_finite() {
                    bail!("event at {} s: input {name} is not a finite number", e.time);
                }
            }
        }
        for (i, name) in self.record.iter().enumerate() {
            if self.record[..i].contains(name) {
                bail!("record lists `{name}` twice");
            }
        }
        if let Some(p) = self.plot.iter().find(|p| !self.record.is_empty() && !self.record.contains(p)) {
            bail!("plot lists {p}, which is not recorded: add it to `record`");
        }
        for (i, c) in self.checks.iter().enumerate() {
            if !self.record.is_empty() && !self.record.contains(&c.signal) {
                bail!("check on {} needs it recorded: add it to `record`", c.signal);
            }
            if c.at.is_none() && (c.from.is_none() || c.to.is_none()) {
                bail!("check on {} needs `at` or both `from` and `to`", c.signal);
            }
            if c.min.is_none() && c.max.is_none() {
                bail!("check on {} needs `min` and/or `max`", c.signal);
            }
            self.check_times_and_bounds(i, c)?;
        }
        Ok(())
    }

    /// Columns of the run's trace: time and the recorded outputs (every output of the FMU
    /// when `record` is empty).
    pub fn trace_columns(&self) -> usize {
        1 + if self.record.is_empty() { fmu_output_count() } else { self.record.len() }
    }

    /// A check's times lie in the run, its window is not reversed and its bounds are numbers
    /// that some value satisfies: a check is judged on samples the run has, never on the
    /// nearest end of it.
    fn check_times_and_bounds(&self, index: usize, c: &Check) -> Result<()> {
        let name = match &c.description {
            Some(d) => format!("check {} on {} ({d})", index + 1, c.signal),
            None => format!("check {} on {}", index + 1, c.signal),
        };
        for (field, t) in [("at", c.at), ("from", c.from), ("to", c.to)] {
            let Some(t) = t else { continue };
            if !t.is_finite() {
                bail!("{name}: {field} = {t} is not a time");
            }
            if t < 0.0 || t > self.stop_time + 1e-9 {
                bail!("{name}: {field} = {t} s is outside the run [0, stop_time = {} s]", self.stop_time);
            }
        }
        if let (Some(from), Some(to)) = (c.from, c.to) {
            if from > to {
                bail!("{name}: from = {from} s is after to = {to} s");
            }
        }
        for (field, b) in [("min", c.min), ("max", c.max)] {
            if b.is_some_and(f64::is_nan) {
                bail!("{name}: {field} is not a number");
            }
        }
        if let (Some(lo), Some(hi)) = (c.min, c.max) {
            if lo > hi {
                bail!("{name}: min = {lo} is above max = {hi}: no value passes");
            }
        }
        Ok(())
    }

    /// Every input any event sets, sorted by name.
    pub fn input_names(&self) -> Vec<String> {
        let mut names: Vec<String> = self.events.iter().flat_map(|e| e.inputs.keys().cloned()).collect();
        names.sort();
        names.dedup();
        names
    }

    /// Input changes by step index: the events at time `k·h`, in file order (a later event at
    /// the same time wins). Inputs hold between changes.
    pub fn changes(&self) -> Vec<(usize, Vec<(&str, Value)>)> {
        let h = self.step();
        let mut out: Vec<(usize, Vec<(&str, Value)>)> = Vec::new();
        for e in &self.events {
            let k = (e.time / h).round() as usize;
            if out.last().map(|(j, _)| *j) != Some(k) {
                out.push((k, Vec::new()));
            }
            let group = &mut out.last_mut().expect("pushed above").1;
            for (name, v) in &e.inputs {
                group.retain(|(n, _)| n != name);
                group.push((name.as_str(), *v));
            }
        }
        out
    }

    /// Position mode with the position command streamed: `commands[k]` (rad) for the step
    /// starting at `k·DEFAULT_STEP`, no acc/dec move (`move_speed` 0).
    pub fn streamed_position(name: &str, parameters: &BTreeMap<String, Value>, commands: &[f64]) -> Self {
        let events = commands
            .iter()
            .enumerate()
            .map(|(k, &c)| {
                let mut inputs: BTreeMap<String, Value> =
                    [("position_command".to_string(), Value::Float(c))].into_iter().collect();
                if k == 0 {
                    inputs.insert("mode".into(), Value::code(Mode::Position.code()));
                    inputs.insert("move_speed".into(), Value::Float(0.0));
                }
                Event { time: k as f64 * DEFAULT_STEP, inputs }
            })
            .collect();
        Self {
            name: name.into(),
            description: String::new(),
            stop_time: commands.len() as f64 * DEFAULT_STEP,
            step: Some(DEFAULT_STEP),
            parameters: parameters.clone(),
            events,
            checks: vec![],
            plot: vec![],
            record: vec![],
        }
    }

    /// The scenario as TOML (name, step, stop time, parameters, events; not checks or plot):
    /// what the fmpy runner reads when a scenario was built in code.
    pub fn to_toml(&self) -> String {
        let value = |v: &Value| match v {
            Value::Bool(b) => b.to_string(),
            Value::Int(i) => i.to_string(),
            // `{:?}` is the shortest text that reads back to the same bits.
            Value::Float(x) => format!("{x:?}"),
        };
        let mut t = format!("name = {:?}\nstop_time = {:?}\n", self.name, self.stop_time);
        if let Some(h) = self.step {
            t += &format!("step = {h:?}\n");
        }
        if !self.record.is_empty() {
            t += &format!("record = {:?}\n", self.record);
        }
        t += "\n[parameters]\n";
        for (k, v) in &self.parameters {
            t += &format!("{k:?} = {}\n", value(v));
        }
        for e in &self.events {
            t += &format!("\n[[events]]\ntime = {:?}\n", e.time);
            for (k, v) in &e.inputs {
                t += &format!("{k} = {}\n", value(v));
            }
        }
        t
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(s: &str) -> Result<Scenario> {
        let sc: Scenario = toml::from_str(s)?;
        sc.validate()?;
        Ok(sc)
    }

    #[test]
    fn events_become_changes_at_their_step() {
        let s = parse(
            "name='x'\nstop_time=0.01\n[[events]]\ntime=0.0\nmode=1\n[[events]]\ntime=0.005\nvelocity_command=3.0\n",
        )
        .unwrap();
        assert_eq!(s.input_names(), vec!["mode", "velocity_command"]);
        assert_eq!(
            s.changes(),
            vec![(0, vec![("mode", Value::Int(1))]), (20, vec![("velocity_command", Value::Float(3.0))])]
        );
    }

    #[test]
    fn toml_round_trip_keeps_every_bit() {
        let s = parse(
            "name='x'\nstop_time=0.01\nrecord=['iq','motor_position']\n[parameters]\n\"ctrl.velocity_kp\"=0.1\n[[events]]\ntime=0.0\nmode=3\nseq_target=0.30000000000000004\n",
        )
        .unwrap();
        let back = parse(&s.to_toml()).unwrap();
        assert_eq!(back.parameters, s.parameters);
        assert_eq!(back.changes(), s.changes());
        assert_eq!(back.record, s.record);
        assert_eq!(back.stop_time.to_bits(), s.stop_time.to_bits());
    }

    #[test]
    fn refuses_a_record_list_with_twins_or_without_a_checked_signal() {
        let e = parse("name='x'\nstop_time=0.01\nrecord=['iq','iq']\n").unwrap_err();
        assert!(e.to_string().contains("twice"), "{e}");
        let e =
            parse("name='x'\nstop_time=0.01\nrecord=['iq']\n[[checks]]\nsignal='id'\nat=0.01\nmax=1.0\n").unwrap_err();
        assert!(e.to_string().contains("add it to `record`"), "{e}");
        assert!(parse("name='x'\nstop_time=0.01\nrecord=['iq']\n[[checks]]\nsignal='iq'\nat=0.01\nmax=1.0\n").is_ok());
        let e = parse("name='x'\nstop_time=0.01\nrecord=['iq']\nplot=['iq','id']\n").unwrap_err();
        assert!(e.to_string().contains("plot lists id"), "{e}");
    }

    #[test]
    fn refuses_a_run_whose_trace_would_not_fit_memory_naming_stop_time_and_the_limit() {
        let e = format!("{:#}", parse("name='x'\nstop_time=1e9\n").unwrap_err());
        assert!(
            e.contains("stop_time = 1000000000 s") && e.contains("1 GiB") && e.contains("at most stop_time"),
            "{e}"
        );
        // A tiny step is refused (shorter than the position-loop period), and at the fastest
        // rate (200 kHz, every tick a position tick: 5 µs steps) the memory names the limit.
        let e = format!("{:#}", parse("name='x'\nstop_time=0.3\nstep=1e-12\n").unwrap_err());
        assert!(e.contains("step = 0.000000000001 s"), "{e}");
        let fastest = |stop: f64| {
            parse(&format!(
                "name='x'\nstop_time={stop:?}\nstep=5e-6\n[parameters]\n'ctrl.current_loop_hz'=200000.0\n\
                 'ctrl.velocity_divider'=1\n'ctrl.position_divider'=1\n"
            ))
        };
        assert!(fastest(10.0).is_ok());
        let e = format!("{:#}", fastest(100.0).unwrap_err());
        assert!(e.contains("step = 0.000005 s") && e.contains("1 GiB"), "{e}");
        // Recording fewer outputs makes room for a longer run: 1000 s of 3 columns is 96 MB.
        assert!(parse("name='x'\nstop_time=1000.0\n").is_err());
        assert!(parse("name='x'\nstop_time=1000.0\nrecord=['iq','id']\n").is_ok());
    }

    #[test]
    fn a_step_off_the_position_loop_period_is_refused_at_load_saying_what_to_set() {
        let lowered =
            |step: &str| format!("name='x'\nstop_time=0.01\n{step}\n[parameters]\n'ctrl.current_loop_hz'=8000.0\n");
        let e = format!("{:#}", parse(&lowered("")).unwrap_err());
        assert!(
            e.contains("step = 0.00025 s (the default")
                && e.contains("position-loop period 0.0005 s")
                && e.contains("step = 0.0005"),
            "{e}"
        );
        assert!(parse(&lowered("step=0.0005")).is_ok());
        assert!(parse(&lowered("step=0.001")).is_ok());
        let e = format!("{:#}", parse(&lowered("step=0.00075")).unwrap_err());
        assert!(e.contains("step = 0.00075 s is not a whole multiple"), "{e}");
        // A higher rate: the default step is 8 periods at 32 kHz, and a divider the same way.
        assert!(parse("name='x'\nstop_time=0.01\n[parameters]\n'ctrl.current_loop_hz'=32000.0\n").is_ok());
        assert!(parse("name='x'\nstop_time=0.01\n[parameters]\n'ctrl.position_divider'=8\n").is_err());
    }

    #[test]
    fn refuses_checks_outside_the_run_or_that_nothing_passes() {
        let with_check = |c: &str| parse(&format!("name='x'\nstop_time=0.3\n[[checks]]\nsignal='iq'\n{c}\n"));
        for (check, reason) in [
            ("at=7.0\nmax=1.0", "at = 7 s is outside the run [0, stop_time = 0.3 s]"),
            ("at=-0.1\nmax=1.0", "at = -0.1 s is outside the run"),
            ("from=0.0\nto=0.5\nmax=1.0", "to = 0.5 s is outside the run"),
            ("from=0.2\nto=0.1\nmax=1.0", "from = 0.2 s is after to = 0.1 s"),
            ("at=0.1\nmin=2.0\nmax=1.0", "min = 2 is above max = 1"),
            ("at=nan\nmax=1.0", "at = NaN is not a time"),
            ("at=0.1\nmax=nan", "max is not a number"),
        ] {
            let e = format!("{:#}", with_check(check).unwrap_err());
            assert!(e.contains("check 1 on iq") && e.contains(reason), "{check}: {e}");
        }
        assert!(with_check("at=0.3\nmin=1.0\nmax=1.0").is_ok());
        assert!(with_check("from=0.0\nto=0.3\nmax=1.0").is_ok());
    }

    #[test]
    fn refuses_off_grid_events_and_fractional_stop_times() {
        assert!(parse("name='x'\nstop_time=0.0101\n").is_err());
        let e = parse("name='x'\nstop_time=0.01\n[[events]]\ntime=0.0001\nmode=1\n").unwrap_err();
        assert!(e.to_string().contains("grid"), "{e}");
        assert!(parse("name='x'\nstop_time=0.01\n[[events]]\ntime=0.02\nmode=1\n").is_err());
        assert!(parse("name='x'\nstop_time=0.01\nbogus=1\n").is_err());
    }
}
