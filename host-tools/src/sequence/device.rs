//! `servo sequence --device`: a timeline's key events sent to a drive at their times (the
//! drive's own clock, read from its telemetry), its telemetry recorded as the run's trace
//! (`device::telemetry_trace`), the timeline's expectations checked on it, and the twin: the
//! same timeline on the FMU with each key at the time the drive got it.
//!
//! The drive's axis is wherever an earlier run left it, where the FMU starts at 0: the run's
//! positions (targets sent, positions recorded) count from where the drive stood at its start.
//!
//! A key reaches the drive a little after its planned time (a telemetry round trip on the line,
//! about 2 ms at 921 600 Bd, more on a busy host): the times the drive got them are kept, the
//! expectations relative to a key use them, and the twin replays them (on the FMU's step grid).

use anyhow::{anyhow, bail, Result};
use control_core::axis::Mode;
use control_core::protocol::{RefusalReason, Request, Response};
use control_core::stop_sequence::SequenceEvent;
use control_core::Commands;
use serde::Serialize;

use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::telemetry_trace;
use crate::fmu::configuration::configuration;
use crate::fmu::scenario::DEFAULT_STEP;
use crate::fmu::trace::Trace;
use crate::sequence::timeline::{KeyEvent, SequenceScenario};
use crate::sequence::timeline_reference::PlainUnit;
use crate::virtual_drive::simulator::power_stage_limits;

/// Telemetry samples a second during a timeline (a 106-byte answer each: 55 % of the line).
const POLL_S: f64 = 2e-3;

/// A key as planned and as the drive got it: between `before` and `after` (s since the run's
/// start, the drive's telemetry just before the key was sent and just after its answer).
#[derive(Clone, Debug, Serialize)]
pub struct SentKey {
    pub event: String,
    pub planned: f64,
    pub before: f64,
    pub after: f64,
}

pub struct DeviceTimeline {
    pub trace: Trace,
    pub keys: Vec<SentKey>,
    /// The timeline with each key at the time the drive got it (on the FMU's step grid).
    pub as_run: SequenceScenario,
}

fn event_request(e: &KeyEvent, counts_per_rev: f64, origin: i64) -> Result<SequenceEvent> {
    Ok(match e.event.as_str() {
        "run" => SequenceEvent::RunOn,
        "run_off" => SequenceEvent::RunOff,
        "stop" => SequenceEvent::Stop,
        "release" => SequenceEvent::ReleaseBlocking,
        "return" => SequenceEvent::ReturnToStart,
        "move" => {
            let target = e.target.as_ref().ok_or_else(|| anyhow!("`move` at {} s has no target", e.time))?;
            let counts = target.to_counts(PlainUnit::Rad, counts_per_rev)?.round() as i64;
            SequenceEvent::MoveTo(
                origin.checked_add(counts).ok_or_else(|| anyhow!("target beyond the position range"))?,
            )
        }
        "gain" => SequenceEvent::SelectGain(e.index.unwrap_or(0).max(0) as usize),
        other => bail!("unknown event `{other}`"),
    })
}

pub fn timeline_on_drive<T: DrivePort>(
    session: &mut DriveSession<T>,
    s: &SequenceScenario,
    mut progress: impl FnMut(f64),
) -> Result<DeviceTimeline> {
    let params = power_stage_limits(configuration(&s.parameters)?.control);
    session.set_params(&params)?;
    let cpr = params.encoder_counts_per_rev as f64;
    let first = session.telemetry()?;
    let origin = first.position;
    let requests = s.events.iter().map(|e| event_request(e, cpr, origin)).collect::<Result<Vec<_>>>()?;
    let mut order: Vec<usize> = (0..s.events.len()).collect();
    order.sort_by(|&a, &b| s.events[a].time.total_cmp(&s.events[b].time));
    session.order(Request::SetCommands(Commands { mode: Mode::Sequence, ..Commands::default() }), "sequence mode")?;
    let start = session.telemetry()?.tick;
    let fs = session.tick_hz;
    let mut trace = telemetry_trace::new_trace();
    let mut keys = Vec::new();
    let mut as_run = s.clone();
    let mut next = 0;
    let stalled_limit = s.stop_time * 4.0 + 5.0;
    let wall = std::time::Instant::now();
    loop {
        let t = session.telemetry()?;
        let time = (t.tick - start) as f64 / fs;
        trace.rows.push(&telemetry_trace::row(time, &t, &params, origin));
        progress((time / s.stop_time).min(1.0));
        // The keys due (those of one planned time go together, as the FMU takes them in one
        // step), then one telemetry answer after them.
        let due: Vec<usize> = order[next..].iter().copied().take_while(|&k| s.events[k].time <= time).collect();
        if !due.is_empty() {
            for &k in &due {
                // A key the sequence refuses is part of the timeline (the drive counts it, the
                // expectations look at it); anything else is an error.
                match session.link.request(&Request::Sequence(requests[k]))? {
                    Response::Done | Response::Refused(RefusalReason::Sequence(_)) => {}
                    other => bail!("unexpected answer to the `{}` key: {other:?}", s.events[k].event),
                }
            }
            // The drive got the keys between the telemetry before them (`time`) and the one
            // after, about 1.3 ms after the first (its answer's 106 bytes on the line, then the
            // keys'): a key's time is the one before, as the FMU's outputs at a key's time show
            // the state before it acts; the twin replays it there (a step early at most).
            let after = session.telemetry()?;
            let got = (after.tick - start) as f64 / fs;
            trace.rows.push(&telemetry_trace::row(got, &after, &params, origin));
            for &k in &due {
                let e = &s.events[k];
                keys.push(SentKey { event: e.event.clone(), planned: e.time, before: time, after: got });
                as_run.events[k].time = (time / DEFAULT_STEP).floor() * DEFAULT_STEP;
            }
            next += due.len();
        }
        if time >= s.stop_time {
            break;
        }
        if wall.elapsed().as_secs_f64() > stalled_limit {
            bail!("the timeline did not finish within {stalled_limit:.0} s of wall-clock time");
        }
        let until_next = order.get(next).map_or(f64::INFINITY, |&k| s.events[k].time - time);
        session.link.pause(std::time::Duration::from_secs_f64(until_next.clamp(0.0, POLL_S)));
    }
    session.rest()?;
    // Keys sent at one time stay in their file order on the grid.
    for w in 1..as_run.events.len() {
        if as_run.events[w].time < as_run.events[w - 1].time {
            as_run.events[w].time = as_run.events[w - 1].time;
        }
    }
    as_run.stop_time = as_run.stop_time.max(as_run.events.iter().map(|e| e.time).fold(0.0, f64::max));
    Ok(DeviceTimeline { trace, keys, as_run })
}
