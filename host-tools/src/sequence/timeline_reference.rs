//! What a timeline's expectations are written in, so that nobody does arithmetic: times
//! relative to an event (`"accepted + 50 ms"`, `"move#2"`) and angles or widths with their
//! unit (`"2 counts"`, `"0.5 mrad"`, `"35 rad"`, `"90 deg"`).
//!
//! A time is seconds from the start (a plain number, as before) or `<anchor>[#n] [± <x> s|ms]`:
//! - a key event of the timeline by name (`run`, `run_off`, `stop`, `release`, `move`,
//!   `return`, `gain`); `#n` picks the n-th of that name (1-based), required when the
//!   timeline has several;
//! - `accepted`: the stop accepted, read off the run (the sample where the sequence enters
//!   servo lock from idle, running or decelerating);
//! - `completed`: completion raised, read off the run (a rising edge of `seq_complete`).
//!
//! An angle is a plain number in the unit the field always had (counts for widths, rad for
//! positions), or a string `"<x> <unit>"` with unit `counts`, `rad`, `mrad`, `deg` or `rev`;
//! counts and angles convert through the run's `plant.encoder_counts_per_rev`.

use std::f64::consts::TAU;

use anyhow::{bail, Result};
use serde::Deserialize;

/// A time field as written: seconds, or text relative to an event.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum TimeSpec {
    Seconds(f64),
    Relative(String),
}

/// What a relative time counts from.
#[derive(Clone, Debug, PartialEq)]
pub enum Anchor {
    /// The n-th (1-based) key event of this name in the timeline.
    Key { event: String, occurrence: usize, explicit: bool },
    /// The n-th stop acceptance seen in the run.
    Accepted(usize),
    /// The n-th rising edge of the completion signal in the run.
    Completed(usize),
}

/// A parsed time: an anchor (none: the start) and an offset in seconds.
#[derive(Clone, Debug, PartialEq)]
pub struct TimeRef {
    pub anchor: Option<Anchor>,
    pub offset: f64,
}

/// Key events a timeline may name (the scenario's `event` values).
pub const KEY_EVENTS: [&str; 7] = ["run", "run_off", "stop", "release", "move", "return", "gain"];

const TIME_SYNTAX: &str =
    "write seconds from the start (0.8) or `<event>[#n] [+|- <x> s|ms]` with event one of run, run_off, stop, \
     release, move, return, gain, accepted, completed (e.g. \"accepted + 50 ms\", \"move#2\")";

impl TimeSpec {
    pub fn parse(&self) -> Result<TimeRef> {
        let text = match self {
            Self::Seconds(t) => return Ok(TimeRef { anchor: None, offset: *t }),
            Self::Relative(s) => s.trim(),
        };
        let split = text.find(['+', '-']).unwrap_or(text.len());
        let (name, rest) = (text[..split].trim(), text[split..].trim());
        let (base, occurrence, explicit) = match name.split_once('#') {
            Some((b, n)) => match n.trim().parse::<usize>() {
                Ok(n) if n >= 1 => (b.trim(), n, true),
                _ => bail!("`{text}`: `#{n}` must be a count from 1; {TIME_SYNTAX}"),
            },
            None => (name, 1, false),
        };
        let anchor = match base {
            "accepted" => Anchor::Accepted(occurrence),
            "completed" => Anchor::Completed(occurrence),
            k if KEY_EVENTS.contains(&k) => Anchor::Key { event: k.to_string(), occurrence, explicit },
            other => bail!("`{text}`: unknown event `{other}`; {TIME_SYNTAX}"),
        };
        let offset = if rest.is_empty() {
            0.0
        } else {
            let sign = if rest.starts_with('-') { -1.0 } else { 1.0 };
            let amount = rest[1..].trim();
            let (number, scale) = if let Some(n) = amount.strip_suffix("ms") {
                (n, 1e-3)
            } else if let Some(n) = amount.strip_suffix('s') {
                (n, 1.0)
            } else {
                bail!("`{text}`: the offset needs a unit, s or ms; {TIME_SYNTAX}")
            };
            match number.trim().parse::<f64>() {
                Ok(x) if x.is_finite() && x >= 0.0 => sign * x * scale,
                _ => bail!("`{text}`: `{amount}` is not a time; {TIME_SYNTAX}"),
            }
        };
        Ok(TimeRef { anchor: Some(anchor), offset })
    }
}

impl std::fmt::Display for TimeSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Seconds(t) => write!(f, "{t} s"),
            Self::Relative(s) => write!(f, "{s}"),
        }
    }
}

/// Times of the key events by name, in timeline order.
pub fn key_time(events: &[(f64, &str)], event: &str, occurrence: usize, explicit: bool) -> Result<f64> {
    let times: Vec<f64> = events.iter().filter(|(_, e)| *e == event).map(|(t, _)| *t).collect();
    if times.len() > 1 && !explicit {
        bail!(
            "the timeline has {} `{event}` events: say which one with `{event}#n` (1 to {})",
            times.len(),
            times.len()
        );
    }
    times
        .get(occurrence - 1)
        .copied()
        .ok_or_else(|| anyhow::anyhow!("`{event}#{occurrence}`: the timeline has {} `{event}` event(s)", times.len()))
}

/// The sample indices where the run shows each trace anchor.
pub struct RunMarks {
    pub accepted: Vec<usize>,
    pub completed: Vec<usize>,
}

impl RunMarks {
    /// `state`: `seq_state` (3 = servo lock, 4 = fine adjust); `complete`: `seq_complete`.
    pub fn find(state: &[f64], complete: &[f64]) -> Self {
        let accepted = (1..state.len()).filter(|&i| state[i] == 3.0 && state[i - 1] < 3.0).collect();
        let completed =
            (0..complete.len()).filter(|&i| complete[i] != 0.0 && (i == 0 || complete[i - 1] == 0.0)).collect();
        Self { accepted, completed }
    }
}

/// The angle units a timeline accepts, and rad per unit (`counts` resolves through the
/// encoder).
fn rad_per_unit(unit: &str, counts_per_rev: f64) -> Option<f64> {
    Some(match unit {
        "count" | "counts" => TAU / counts_per_rev,
        "rad" => 1.0,
        "mrad" => 1e-3,
        "deg" => TAU / 360.0,
        "rev" => TAU,
        _ => return None,
    })
}

/// An angle or width as written: a plain number (the field's own unit) or `"<x> <unit>"`.
#[derive(Clone, Debug, PartialEq, Deserialize)]
#[serde(untagged)]
pub enum AngleSpec {
    Plain(f64),
    WithUnit(String),
}

/// The unit a plain number of a field is in.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PlainUnit {
    Counts,
    Rad,
}

impl AngleSpec {
    /// The value in rad (`PlainUnit` says what a bare number means).
    pub fn to_rad(&self, plain: PlainUnit, counts_per_rev: f64) -> Result<f64> {
        let per_count = TAU / counts_per_rev;
        let (x, rad_per) = match self {
            Self::Plain(x) => (*x, if plain == PlainUnit::Counts { per_count } else { 1.0 }),
            Self::WithUnit(s) => {
                let mut parts = s.split_whitespace();
                let (Some(n), Some(u), None) = (parts.next(), parts.next(), parts.next()) else {
                    bail!("`{s}`: write an angle as `<number> <unit>` with unit counts, rad, mrad, deg or rev");
                };
                let Ok(x) = n.parse::<f64>() else {
                    bail!("`{s}`: `{n}` is not a number");
                };
                let Some(r) = rad_per_unit(u, counts_per_rev) else {
                    bail!("`{s}`: unknown unit `{u}`; use counts, rad, mrad, deg or rev");
                };
                (x, r)
            }
        };
        if !x.is_finite() {
            bail!("angle {self} is not finite");
        }
        Ok(x * rad_per)
    }

    /// The value in encoder counts (not rounded). Counts given as counts stay exact (no trip
    /// through radians: 13 counts at 1000 counts per turn would come back as 12.999…).
    pub fn to_counts(&self, plain: PlainUnit, counts_per_rev: f64) -> Result<f64> {
        let rad = self.to_rad(plain, counts_per_rev)?;
        let exact = match self {
            Self::Plain(x) if plain == PlainUnit::Counts => Some(*x),
            Self::WithUnit(s) => match s.split_whitespace().collect::<Vec<_>>()[..] {
                [n, "count" | "counts"] => n.parse::<f64>().ok(),
                _ => None,
            },
            _ => None,
        };
        Ok(exact.unwrap_or(rad / (TAU / counts_per_rev)))
    }
}

impl std::fmt::Display for AngleSpec {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Plain(x) => write!(f, "{x}"),
            Self::WithUnit(s) => write!(f, "{s}"),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn rel(s: &str) -> Result<TimeRef> {
        TimeSpec::Relative(s.into()).parse()
    }

    #[test]
    fn relative_times_parse_to_an_anchor_and_an_offset() {
        let key = |e: &str, n, explicit| Some(Anchor::Key { event: e.into(), occurrence: n, explicit });
        assert_eq!(rel("stop").unwrap(), TimeRef { anchor: key("stop", 1, false), offset: 0.0 });
        assert_eq!(rel(" move#2 + 0.1 s").unwrap(), TimeRef { anchor: key("move", 2, true), offset: 0.1 });
        assert_eq!(rel("accepted+50ms").unwrap(), TimeRef { anchor: Some(Anchor::Accepted(1)), offset: 0.05 });
        assert_eq!(rel("completed#3 - 2 ms").unwrap().offset, -0.002);
        assert_eq!(rel("run_off").unwrap().anchor, key("run_off", 1, false));
        assert_eq!(TimeSpec::Seconds(0.8).parse().unwrap(), TimeRef { anchor: None, offset: 0.8 });
        for (bad, reason) in [
            ("jump", "unknown event `jump`"),
            ("stop + 5", "needs a unit"),
            ("stop + x ms", "is not a time"),
            ("move#0", "count from 1"),
            ("stop + inf s", "is not a time"),
        ] {
            let e = rel(bad).unwrap_err().to_string();
            assert!(e.contains(reason), "{bad}: {e}");
        }
    }

    #[test]
    fn angles_convert_through_the_encoder() {
        let cpr = 4096.0;
        let a = |s: &str| AngleSpec::WithUnit(s.into());
        assert_eq!(a("4096 counts").to_rad(PlainUnit::Counts, cpr).unwrap(), TAU);
        assert_eq!(a("1 rev").to_counts(PlainUnit::Rad, cpr).unwrap(), cpr);
        assert!((a("90 deg").to_rad(PlainUnit::Counts, cpr).unwrap() - TAU / 4.0).abs() < 1e-15);
        assert!((a("1.5 mrad").to_rad(PlainUnit::Rad, cpr).unwrap() - 1.5e-3).abs() < 1e-18);
        assert_eq!(AngleSpec::Plain(2.0).to_counts(PlainUnit::Counts, cpr).unwrap(), 2.0);
        // Counts stay exact whatever the encoder (through radians 13 would be 12.999…).
        assert_eq!(AngleSpec::Plain(13.0).to_counts(PlainUnit::Counts, 1000.0).unwrap(), 13.0);
        assert_eq!(a("13 counts").to_counts(PlainUnit::Rad, 1000.0).unwrap(), 13.0);
        assert_eq!(AngleSpec::Plain(TAU).to_counts(PlainUnit::Rad, cpr).unwrap(), cpr);
        for (bad, reason) in [("2", "<number> <unit>"), ("2 furlongs", "unknown unit"), ("x rad", "not a number")] {
            let e = a(bad).to_rad(PlainUnit::Rad, cpr).unwrap_err().to_string();
            assert!(e.contains(reason), "{bad}: {e}");
        }
    }

    #[test]
    fn key_events_need_their_number_when_repeated() {
        let ev = [(0.0, "run"), (0.6, "move"), (1.3, "move")];
        assert_eq!(key_time(&ev, "run", 1, false).unwrap(), 0.0);
        assert_eq!(key_time(&ev, "move", 2, true).unwrap(), 1.3);
        assert!(key_time(&ev, "move", 1, false).unwrap_err().to_string().contains("say which one"));
        assert!(key_time(&ev, "move", 3, true).unwrap_err().to_string().contains("has 2"));
        assert!(key_time(&ev, "stop", 1, false).unwrap_err().to_string().contains("has 0"));
    }

    #[test]
    fn run_marks_are_entries_into_servo_lock_and_rising_completion_edges() {
        let state = [1.0, 2.0, 2.0, 3.0, 3.0, 4.0, 3.0, 0.0, 3.0];
        let complete = [1.0, 0.0, 0.0, 0.0, 1.0, 1.0, 0.0, 1.0, 1.0];
        let m = RunMarks::find(&state, &complete);
        // 4 → 3 (a fine adjustment ending) is not a stop acceptance; 0 → 3 is.
        assert_eq!(m.accepted, vec![3, 8]);
        assert_eq!(m.completed, vec![0, 4, 7]);
    }
}
