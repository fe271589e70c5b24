//! A run with requests at given times on a drive's own clock (read from its telemetry), the
//! telemetry recorded as the run's trace (`telemetry_trace`): what `servo run --device` and
//! `servo sequence --device` share.
//!
//! Requests of one time go together (the FMU takes one time's inputs in one step), then one
//! telemetry answer after them. They reach the drive a little after their time (a telemetry
//! answer, then the requests, on the line: about 1.3–3 ms at 921 600 Bd, more on a busy
//! host). The checks read the drive's trace with each group at the telemetry sample just
//! before it (the FMU's outputs at an input's time show the state before it acts); the twin
//! replays each group when the drive acted on it: the telemetry after it, less the bytes on
//! the line between the two ([`SentAt::acted`]).

use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use control_core::protocol::{Request, Response};
use control_core::Params;
use serde::Serialize;

use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::telemetry_trace;
use crate::fmu::trace::Trace;

/// Telemetry samples during a run: every 2 ms (an answer of about 107 bytes each: 58 % of a 921 600 Bd line).
pub const POLL_S: f64 = 2e-3;

/// Requests due at one time.
pub struct TimedRequests {
    pub time: f64,
    pub label: String,
    pub requests: Vec<Request>,
}

/// A group as planned and as the drive got it: between `before` and `after` (s since the run's
/// start: the telemetry just before the group was sent and just after its answers).
#[derive(Clone, Debug, Serialize)]
pub struct SentAt {
    pub label: String,
    pub planned: f64,
    pub before: f64,
    pub after: f64,
}

/// The time from a drive acting on a request to its tick in the telemetry asked after the
/// answer: the answer (`Done`, 7 bytes) and the telemetry request (8 bytes) on the line.
pub const AFTER_ACTING_S: f64 = 15.0 * 10.0 / 921_600.0;

impl SentAt {
    /// When the drive acted on the group (s): the telemetry after it less the bytes on the
    /// line between the two; within [`Self::before`, `Self::after`].
    pub fn acted(&self) -> f64 {
        (self.after - AFTER_ACTING_S).max(self.before)
    }
}

/// `time` on the FMU's communication grid (`step`), at or before it and not beyond `stop`.
pub fn on_grid(time: f64, step: f64, stop: f64) -> f64 {
    ((time / step).floor() * step).min(stop)
}

pub struct TimedRun {
    pub trace: Trace,
    pub sent: Vec<SentAt>,
}

/// Run `groups` (in time order) on the drive until `stop_time`; `accept` says which answers
/// other than `Done` are part of the run (a refused key of a timeline), the rest are errors.
/// Positions in the trace count from `origin` (counts).
pub fn run_timed<T: DrivePort>(
    session: &mut DriveSession<T>,
    (params, origin): (&Params, i64),
    stop_time: f64,
    groups: &[TimedRequests],
    accept: impl Fn(&Response) -> bool,
    mut progress: impl FnMut(f64),
) -> Result<TimedRun> {
    let start = session.telemetry()?.tick;
    let fs = session.tick_hz;
    let mut trace = telemetry_trace::new_trace();
    let mut sent = Vec::new();
    let mut next = 0;
    let wall_limit = stop_time * 4.0 + 5.0;
    let wall = Instant::now();
    loop {
        let t = session.telemetry()?;
        let time = (t.tick - start) as f64 / fs;
        trace.rows.push(telemetry_trace::row(time, &t, params, origin));
        progress((time / stop_time).min(1.0));
        let due = groups[next..].iter().take_while(|g| g.time <= time).count();
        if due > 0 {
            for g in &groups[next..next + due] {
                for r in &g.requests {
                    match session.answer(r)? {
                        Response::Done => {}
                        answer if accept(&answer) => {}
                        other => bail!("unexpected answer to {} at {} s: {other:?}", g.label, g.time),
                    }
                }
            }
            let after = session.telemetry()?;
            let got = (after.tick - start) as f64 / fs;
            trace.rows.push(telemetry_trace::row(got, &after, params, origin));
            for g in &groups[next..next + due] {
                sent.push(SentAt { label: g.label.clone(), planned: g.time, before: time, after: got });
            }
            next += due;
        }
        if time >= stop_time {
            break;
        }
        if wall.elapsed().as_secs_f64() > wall_limit {
            bail!("the run did not finish within {wall_limit:.0} s of wall-clock time");
        }
        let until_next = groups.get(next).map_or(f64::INFINITY, |g| g.time - time);
        session.link.pause(Duration::from_secs_f64(until_next.clamp(0.0, POLL_S)));
    }
    Ok(TimedRun { trace, sent })
}
