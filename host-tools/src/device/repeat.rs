//! What sending a request a second time does to a drive, and, for the requests a second copy
//! would act on again, how the drive's telemetry tells whether the first copy acted.
//!
//! On a line that corrupts bytes, a request can be lost on its way (the drive reads a corrupt
//! frame: it answers `FrameError` and does nothing) or its answer can be lost on the way back
//! (the drive acted, the host does not know). After a lost answer the host sends a request
//! again only if a second copy leaves the drive as one copy does ([`Repeat::Harmless`]);
//! otherwise it first reads the drive's telemetry and sends again only if that shows the
//! first copy did not act ([`Repeat::Verify`], [`verify`]), and fails, saying why, where the
//! telemetry cannot tell. Every request is classified here, in one `match` over the
//! protocol's requests (a new request does not compile until it is).
//!
//! Harmless, checked against `control_core::protocol::handle` and the drive application's
//! `Host::handle` (`drive-application/src/drive.rs`):
//! - `Hello`, `GetTelemetry`: answer, change nothing.
//! - `SetParams`: builds a new axis from the parameters, only at rest (torque mode, zero
//!   torque, no fault, no sweep). A second copy, sent right after the first (nothing else in
//!   between), builds the same axis again from the same rest: what the experiment sets next
//!   (commands, sweep, keys) comes after both.
//! - `SetCommands`: the commands are replaced whole (absolute set-points; a mode change acts on
//!   the change, and the second copy changes nothing).
//! - `LoadCorrection`: the same sections installed again (only while no command pulse is in
//!   flight through the filter, so its state is the same rest either way).
//! - `ClearFaults`: clears the latch again; a fault latched between the two copies is
//!   cleared unseen, as it would be had the first copy arrived a moment later (a fault that
//!   persists latches again at once).
//! - `Stream`: switches streaming on or off again; a second "on" restarts the drive's sample
//!   ring (samples not yet sent are dropped: the experiments switch streaming on before their
//!   measurement starts, and take the samples only after it).
//!
//! Not harmless:
//! - `StartSweep`: after the sweep is done, a second copy starts another.
//! - `Sequence` events: a second `RunOn`, `Stop`, … is refused and counted in the sequence's
//!   refusal count (a timeline's expectations read it); a second `MoveTo` restarts the
//!   positioning's completion; a second copy of a refused event counts twice.
//! - `SaveParams`: a second copy writes another flash record (the next sequence number, the
//!   other page erased). The telemetry carries the sequence number of the newest record in
//!   the drive's flash (protocol version 6), and a save is the only thing that changes it:
//!   the next number after it means the save wrote its record; the same number means it
//!   wrote none (never read, or refused: a second copy is refused again, or writes the one
//!   record).

use control_core::axis::Telemetry;
use control_core::phase_shifted_sweep::SweepState;
use control_core::protocol::{DriveTelemetry, RefusalReason, Request, Response};
use control_core::stop_sequence::{SequenceEvent, SequenceState};

/// What a second copy of a request does.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Repeat {
    /// Leaves the drive as one copy does: sent again after a lost answer.
    Harmless,
    /// Acts again: sent again only once the drive's telemetry shows the first did not act.
    Verify,
}

/// The classification (see the module's notes for each request).
pub fn repeat_of(request: &Request) -> Repeat {
    match request {
        Request::Hello { .. }
        | Request::SetParams(_)
        | Request::SetCommands(_)
        | Request::LoadCorrection(_)
        | Request::ClearFaults
        | Request::GetTelemetry
        | Request::Stream { .. }
        | Request::StopCommissioning
        | Request::GetParams => Repeat::Harmless,
        Request::StartSweep | Request::Sequence(_) | Request::SaveParams | Request::Commission(_) => Repeat::Verify,
    }
}

/// What the telemetry after a lost answer tells of a [`Repeat::Verify`] request.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Verdict {
    /// The drive carried it out, or refused it: the answer it gave.
    Acted(Response),
    /// It did not act (or a second copy changes nothing): send it again.
    SendAgain,
    /// The telemetry cannot tell: why.
    Unknown(&'static str),
}

/// Whether `request` acted, from the drive's telemetry just `before` it was sent and just
/// `after` its answer was lost.
pub fn verify(request: &Request, before: &DriveTelemetry, after: &DriveTelemetry) -> Verdict {
    // Only a save changes the newest record, whatever else happens meanwhile (faults too).
    if *request == Request::SaveParams {
        return save_params(before.params_record, after.params_record);
    }
    let (before, after) = (&before.axis, &after.axis);
    if after.faults.0 & !before.faults.0 != 0 {
        return Verdict::Unknown("a fault latched meanwhile, and a fault changes what the telemetry shows");
    }
    match request {
        Request::StartSweep => start_sweep(before.sweep.state, after.sweep.state),
        Request::Commission(_) => commission(before.commissioning, after.commissioning),
        Request::Sequence(e) => sequence_event(e, before, after),
        _ => Verdict::SendAgain,
    }
}

/// A sequence running now that was not before: the start acted (a second copy would be refused
/// as busy). Not running: it did not start (or ended within the lost answer's time, which a
/// sequence of seconds does not).
fn commission(
    before: Option<control_core::commissioning::CommissioningStatus>,
    after: Option<control_core::commissioning::CommissioningStatus>,
) -> Verdict {
    use control_core::commissioning::CommissioningStatus::Running;
    match (before, after) {
        (Some(Running(_)), _) => Verdict::Unknown("a commissioning sequence was already running"),
        (_, Some(Running(_))) => Verdict::Acted(Response::Done),
        _ => Verdict::SendAgain,
    }
}

/// A save writes the record after the newest (the first is 1; the numbers wrap around); nothing
/// else changes the newest record while the drive runs.
fn save_params(before: Option<u32>, after: Option<u32>) -> Verdict {
    let next = before.map_or(1, |s| s.wrapping_add(1));
    match after {
        Some(s) if s == next => Verdict::Acted(Response::Saved { sequence: s }),
        a if a == before => Verdict::SendAgain,
        None => Verdict::Unknown("the drive reports no parameter record any more (was it restarted?)"),
        Some(_) => Verdict::Unknown("the drive's newest parameter record moved by more than one save"),
    }
}

fn running(s: SweepState) -> bool {
    matches!(s, SweepState::Settling | SweepState::Measuring)
}

/// A sweep starts from idle or done into settling; it goes back to idle only with a new axis.
fn start_sweep(before: SweepState, after: SweepState) -> Verdict {
    let refused = Verdict::Acted(Response::Refused(RefusalReason::Sweep));
    match (before, after) {
        // A sweep already running refuses the start, whatever became of it.
        (b, _) if running(b) => refused,
        (_, a) if running(a) => Verdict::Acted(Response::Done),
        (SweepState::Idle, SweepState::Done) => Verdict::Acted(Response::Done),
        // Still idle: not started (or refused for its injection point or mode: a second copy
        // is refused again, changing nothing).
        (_, SweepState::Idle) => Verdict::SendAgain,
        _ => Verdict::Unknown("a sweep had finished before it, and another that finished looks the same"),
    }
}

/// Every refusal of the stop sequence is counted: with the count unchanged, the event was
/// accepted or never read. An accepted event changes the sequence's state, target or gain in a
/// way the tick alone never does; where the state before would have refused it (a refusal the
/// count would show), it was never read.
fn sequence_event(e: &SequenceEvent, before: &Telemetry, after: &Telemetry) -> Verdict {
    use SequenceState::*;
    let (b, a) = (&before.sequence, &after.sequence);
    if a.refused > b.refused {
        return match a.last_refusal {
            Some(r) if a.refused == b.refused + 1 => Verdict::Acted(Response::Refused(RefusalReason::Sequence(r))),
            _ => Verdict::Unknown("the sequence counted more than one refusal"),
        };
    }
    if a.refused < b.refused {
        return Verdict::Unknown("the sequence's refusal count went back (a new axis?)");
    }
    let position_control = |s: SequenceState| matches!(s, ServoLock | FineAdjust);
    let acted = match *e {
        // Only a run-on enters running; only a run-off leaves it.
        SequenceEvent::RunOn => b.state != Running && a.state == Running,
        SequenceEvent::RunOff => b.state == Running && a.state != Running,
        // A stop already pending: a second copy sets it again (harmless while it is pending;
        // once the axis is stopped a second copy is refused and counted).
        SequenceEvent::Stop if b.stop_pending && position_control(a.state) => {
            return Verdict::Unknown("a stop was pending before it, and the axis has stopped since")
        }
        SequenceEvent::Stop if b.stop_pending => false,
        // Accepted only from idle or decelerating: pending until the speed is down, then servo
        // lock (the only way into position control).
        SequenceEvent::Stop => a.stop_pending || (!position_control(b.state) && position_control(a.state)),
        // Only a release turns servo lock into fine adjust.
        SequenceEvent::ReleaseBlocking => b.state == ServoLock && a.state == FineAdjust,
        // In fine adjust only events move the target.
        SequenceEvent::MoveTo(t) if b.state == FineAdjust && b.target == t => {
            return Verdict::Unknown("the target was already there (a second copy restarts the completion)")
        }
        SequenceEvent::MoveTo(t) => b.state == FineAdjust && a.target == t,
        SequenceEvent::ReturnToStart if position_control(b.state) && a.target == b.target => {
            return Verdict::Unknown("the target did not move (the start may be where it was)")
        }
        SequenceEvent::ReturnToStart => position_control(b.state),
        // The same gain again changes nothing: a gain index that did not move may be sent again.
        SequenceEvent::SelectGain(i) => a.gain_index == i && b.gain_index != i,
    };
    if acted {
        Verdict::Acted(Response::Done)
    } else {
        Verdict::SendAgain
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control_core::protocol::VERSION;
    use control_core::stop_sequence::Refusal;
    use control_core::{Commands, Params};

    #[test]
    fn only_the_requests_that_act_again_are_verified() {
        let p = Params::default();
        for (r, want) in [
            (Request::Hello { version: VERSION }, Repeat::Harmless),
            (Request::SetParams(p), Repeat::Harmless),
            (Request::SetCommands(Commands::default()), Repeat::Harmless),
            (Request::LoadCorrection(p.correction), Repeat::Harmless),
            (Request::ClearFaults, Repeat::Harmless),
            (Request::GetTelemetry, Repeat::Harmless),
            (Request::Stream { enabled: true }, Repeat::Harmless),
            (Request::StartSweep, Repeat::Verify),
            (Request::Sequence(SequenceEvent::RunOn), Repeat::Verify),
            (Request::SaveParams, Repeat::Verify),
        ] {
            assert_eq!(repeat_of(&r), want, "{r:?}");
        }
    }

    fn with_sweep(s: SweepState) -> DriveTelemetry {
        let mut t = DriveTelemetry::default();
        t.axis.sweep.state = s;
        t
    }

    #[test]
    fn a_sweep_start_is_told_by_the_sweep_state() {
        use SweepState::*;
        let v = |b, a| verify(&Request::StartSweep, &with_sweep(b), &with_sweep(a));
        assert_eq!(v(Idle, Settling), Verdict::Acted(Response::Done));
        assert_eq!(v(Idle, Done), Verdict::Acted(Response::Done));
        assert_eq!(v(Done, Measuring), Verdict::Acted(Response::Done));
        assert_eq!(v(Idle, Idle), Verdict::SendAgain);
        assert_eq!(v(Settling, Measuring), Verdict::Acted(Response::Refused(RefusalReason::Sweep)));
        assert!(matches!(v(Done, Done), Verdict::Unknown(_)));
        let mut faulted = with_sweep(Idle);
        faulted.axis.faults.0 = 1;
        assert!(matches!(verify(&Request::StartSweep, &with_sweep(Idle), &faulted), Verdict::Unknown(_)));
    }

    #[test]
    fn a_sequence_event_is_told_by_the_state_or_the_refusal_count() {
        let at = |state, refused| {
            let mut t = DriveTelemetry::default();
            t.axis.sequence.state = state;
            t.axis.sequence.refused = refused;
            t
        };
        let on = Request::Sequence(SequenceEvent::RunOn);
        let (idle, running) = (at(SequenceState::Idle, 0), at(SequenceState::Running, 0));
        assert_eq!(verify(&on, &idle, &running), Verdict::Acted(Response::Done));
        assert_eq!(verify(&on, &idle, &idle), Verdict::SendAgain);
        let mut refused = at(SequenceState::Running, 1);
        refused.axis.sequence.last_refusal = Some(Refusal::AlreadyRunning);
        assert_eq!(
            verify(&on, &running, &refused),
            Verdict::Acted(Response::Refused(RefusalReason::Sequence(Refusal::AlreadyRunning)))
        );
        let off = Request::Sequence(SequenceEvent::RunOff);
        assert_eq!(verify(&off, &running, &at(SequenceState::Decelerating, 0)), Verdict::Acted(Response::Done));
        let mut fine = at(SequenceState::FineAdjust, 0);
        fine.axis.sequence.target = 5;
        let mv = Request::Sequence(SequenceEvent::MoveTo(7));
        assert_eq!(verify(&mv, &fine, &fine), Verdict::SendAgain);
        let mut moved = fine;
        moved.axis.sequence.target = 7;
        assert_eq!(verify(&mv, &fine, &moved), Verdict::Acted(Response::Done));
        assert!(matches!(verify(&mv, &moved, &moved), Verdict::Unknown(_)));
    }

    fn with_record(r: Option<u32>) -> DriveTelemetry {
        DriveTelemetry { params_record: r, ..Default::default() }
    }

    /// A save is told by the newest record's number: the next one (written), the same (not
    /// written: send again), anything else (the telemetry cannot tell).
    #[test]
    fn a_save_is_told_by_the_newest_record_number() {
        let v = |b, a| verify(&Request::SaveParams, &with_record(b), &with_record(a));
        // Written: the first record on an empty flash, the next one, across the wrap-around.
        assert_eq!(v(None, Some(1)), Verdict::Acted(Response::Saved { sequence: 1 }));
        assert_eq!(v(Some(41), Some(42)), Verdict::Acted(Response::Saved { sequence: 42 }));
        assert_eq!(v(Some(u32::MAX), Some(0)), Verdict::Acted(Response::Saved { sequence: 0 }));
        // Not written (not read, refused as busy, a flash error): send it again.
        assert_eq!(v(None, None), Verdict::SendAgain);
        assert_eq!(v(Some(41), Some(41)), Verdict::SendAgain);
        // The telemetry cannot tell: two records written, a record number gone or gone back.
        for (b, a) in [(Some(41), Some(43)), (Some(41), None), (Some(41), Some(40)), (None, Some(2))] {
            assert!(matches!(v(b, a), Verdict::Unknown(_)), "{b:?} → {a:?}");
        }
        // A fault latched meanwhile does not touch the record: the save is still told.
        let mut faulted = with_record(Some(2));
        faulted.axis.faults.0 = 1;
        assert_eq!(
            verify(&Request::SaveParams, &with_record(Some(1)), &faulted),
            Verdict::Acted(Response::Saved { sequence: 2 })
        );
    }
}
