//! `servo sequence --device`: a timeline's key events sent to a drive at their times
//! (`device::timed_run`: the drive's own clock), its telemetry as the run's trace, the
//! timeline's expectations checked on it, and the twin: the same timeline on the FMU with each
//! key at the time the drive got it.
//!
//! The drive's axis is wherever an earlier run left it, where the FMU starts at 0: the run's
//! positions (targets sent, positions recorded) count from where the drive stood at its start.

use anyhow::{anyhow, bail, Result};
use control_core::axis::Mode;
use control_core::protocol::{RefusalReason, Request, Response};
use control_core::stop_sequence::SequenceEvent;
use control_core::Commands;

use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::timed_run::{on_grid, run_timed, SentAt, TimedRequests};
use crate::fmu::configuration::configuration;
use crate::fmu::scenario::DEFAULT_STEP;
use crate::fmu::trace::Trace;
use crate::sequence::timeline::{KeyEvent, SequenceScenario};
use crate::sequence::timeline_reference::PlainUnit;
use power_stage::ratings::with_board_limits;

pub struct DeviceTimeline {
    pub trace: Trace,
    pub keys: Vec<SentAt>,
    /// The timeline with each key at the telemetry sample just before the drive got it (on
    /// the FMU's step grid): the expectations read the drive's trace with it.
    pub as_run: SequenceScenario,
    /// The timeline with each key when the drive acted on it: what the twin replays.
    pub twin: SequenceScenario,
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
    progress: impl FnMut(f64),
) -> Result<DeviceTimeline> {
    let params = with_board_limits(configuration(&s.parameters)?.control);
    session.set_params(&params)?;
    let origin = session.telemetry()?.position;
    let cpr = params.encoder_counts_per_rev as f64;
    let mut order: Vec<usize> = (0..s.events.len()).collect();
    order.sort_by(|&a, &b| s.events[a].time.total_cmp(&s.events[b].time));
    // One group per key (keys of one time are sent together by the runner).
    let groups = order
        .iter()
        .map(|&k| {
            let e = &s.events[k];
            Ok(TimedRequests {
                time: e.time,
                label: format!("the `{}` key", e.event),
                requests: vec![Request::Sequence(event_request(e, cpr, origin)?)],
            })
        })
        .collect::<Result<Vec<_>>>()?;
    session.order(Request::SetCommands(Commands { mode: Mode::Sequence, ..Commands::default() }), "sequence mode")?;
    // A key the sequence refuses is part of the timeline (the drive counts it, the
    // expectations look at it).
    let refused_key = |r: &Response| matches!(r, Response::Refused(RefusalReason::Sequence(_)));
    let run = run_timed(session, (&params, origin), s.stop_time, &groups, refused_key, progress)?;
    session.rest()?;
    let (mut as_run, mut twin) = (s.clone(), s.clone());
    for (&k, sent) in order.iter().zip(&run.sent) {
        as_run.events[k].time = on_grid(sent.before, DEFAULT_STEP, s.stop_time);
        twin.events[k].time = on_grid(sent.acted(), DEFAULT_STEP, s.stop_time);
    }
    Ok(DeviceTimeline { trace: run.trace, keys: run.sent, as_run, twin })
}
