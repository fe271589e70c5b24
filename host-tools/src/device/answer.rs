//! A request's answer made sure of over a line that corrupts bytes: sent again after the
//! request was lost on its way, and after its answer was lost only where a second copy is
//! harmless or the drive's telemetry shows the first did not act (`device::repeat`).
//!
//! After a failed attempt the link resynchronises (a lone delimiter ends a partial frame in
//! the drive; what is in flight is read and dropped), and what it drains decides:
//! - the answer was `FrameError` (the drive read a corrupt frame in place of the request), or
//!   the drain brought one (the request's delimiter was lost: it ended at the lone
//!   delimiter): the drive did not act — sent again;
//! - otherwise the answer was lost (corrupt, or none within the timeout) and the drive may
//!   have acted: a harmless request is sent again; any other is judged from the telemetry
//!   just before it and just after ([`repeat::verify`]) — its answer as the drive gave it,
//!   sent again, or an error that names it and says why it was not sent again.
//!
//! At most [`RESENDS`] times a request (`SERVO_LINK_TRACE=1` prints each lost one on stderr); a drive that sends nothing at all twice running (no
//! byte within the timeout, nor while draining) has stopped, and the link itself failing
//! (closed, unreadable) is not retried: either is an error at once.

use std::io::{Read, Write};

use anyhow::{anyhow, bail, Result};
use control_core::protocol::{DriveTelemetry, FrameError, Request, Response};

use crate::device::link::{is_link_failure, DeviceLink};
use crate::device::repeat::{repeat_of, verify, Repeat, Verdict};

/// Copies of a request sent after the first, at most. With each byte corrupted with
/// probability p each way, a request and its answer of n bytes in all are hit with about
/// 1 − (1 − p)ⁿ; the parameter set (a few hundred bytes) is hit about half the time at
/// p = 2·10⁻³ (measured: sent again 0–2 times a sweep), and eight copies all hit then happen
/// at most once in 250 sweeps; a telemetry poll (114 bytes: about 1 in 5), once in 4·10⁵ polls.
/// A copy the drive could not read costs one answer's time; a lost answer, the timeout while
/// streaming (a corrupt frame may be a sample batch), else a corrupt frame's arrival.
pub const RESENDS: u32 = 7;

/// How an attempt ended.
enum Attempt {
    Answer(Response),
    /// The drive read a corrupt frame in place of the request (it did not act).
    NotRead(FrameError),
    /// No answer that decodes (why); whether anything at all arrived.
    Lost(String, bool),
}

fn attempt<T: Read + Write>(link: &mut DeviceLink<T>, request: &Request) -> Result<Attempt> {
    let bytes = link.bytes_read;
    match link.request(request) {
        Ok(Response::FrameError(e)) if !matches!(e, FrameError::Version { .. }) => {
            link.resynchronise_before_next();
            Ok(Attempt::NotRead(e))
        }
        Ok(r) => Ok(Attempt::Answer(r)),
        Err(e) if is_link_failure(&e) => Err(e),
        Err(e) => {
            let drained = link.resynchronise()?;
            if drained.frame_errors > 0 {
                return Ok(Attempt::NotRead(FrameError::Framing));
            }
            Ok(Attempt::Lost(e.to_string(), link.bytes_read > bytes))
        }
    }
}

/// The drive's telemetry, asked again after a lost answer.
pub fn telemetry<T: Read + Write>(link: &mut DeviceLink<T>) -> Result<DriveTelemetry> {
    match answer(link, &Request::GetTelemetry, None)? {
        Response::Telemetry(t) => Ok(t),
        other => bail!("unexpected answer to a telemetry request: {other:?}"),
    }
}

/// The drive's answer to `request`; `before`: its telemetry since the last request, if the
/// caller has it (a request that [`Repeat::Verify`]s asks for it otherwise).
pub fn answer<T: Read + Write>(
    link: &mut DeviceLink<T>,
    request: &Request,
    before: Option<DriveTelemetry>,
) -> Result<Response> {
    let (name, kind) = (request_name(request), request_kind(request));
    let trace = std::env::var_os("SERVO_LINK_TRACE").is_some();
    let not_sent_again = |last: &str, reason: &str| {
        anyhow!(
            "the answer to {name} was lost ({last}) and it was not sent again: {reason}; it may or may not have been \
             carried out"
        )
    };
    let mut before = match repeat_of(request) {
        Repeat::Harmless => None,
        Repeat::Verify => Some(match before {
            Some(t) => t,
            None => telemetry(link).map_err(|e| {
                anyhow!(
                    "{name} was not sent: the telemetry it would be judged against, should its answer be lost, could \
                     not be read ({e:#})"
                )
            })?,
        }),
    };
    let mut silent_before = false;
    let mut last = String::new();
    for copy in 0..=RESENDS {
        if copy > 0 {
            link.resent += 1;
            link.by_request.entry(kind).or_default().0 += 1;
        }
        let a = attempt(link, request).map_err(|e| e.context(format!("{name} to the drive")))?;
        if trace {
            match &a {
                Attempt::Answer(_) => {}
                Attempt::NotRead(e) => eprintln!("TRACE {kind} not read: {e}"),
                Attempt::Lost(w, h) => eprintln!("TRACE {kind} lost (heard {h}): {w}"),
            }
        }
        match a {
            Attempt::Answer(r) => return Ok(r),
            Attempt::NotRead(e) => {
                silent_before = false;
                last = format!("the drive read a corrupt frame in its place ({e})");
            }
            Attempt::Lost(why, heard) => {
                if !heard && silent_before {
                    bail!("{name}: {why}, twice, and nothing at all from the drive meanwhile (is it still running?)");
                }
                silent_before = !heard;
                last = why;
                let Some(b) = before else { continue };
                let after = telemetry(link).map_err(|e| {
                    not_sent_again(&last, &format!("the telemetry that would tell could not be read ({e:#})"))
                })?;
                match verify(request, &b, &after) {
                    Verdict::Acted(r) => {
                        link.verified += 1;
                        link.by_request.entry(kind).or_default().1 += 1;
                        return Ok(r);
                    }
                    Verdict::SendAgain => before = Some(after),
                    Verdict::Unknown(reason) => return Err(not_sent_again(&last, reason)),
                }
            }
        }
    }
    Err(anyhow!("{name}: no answer after {} copies (last: {last})", RESENDS + 1))
}

/// The request's name in the protocol.
pub fn request_kind(request: &Request) -> &'static str {
    match request {
        Request::Hello { .. } => "Hello",
        Request::SetParams(_) => "SetParams",
        Request::SetCommands(_) => "SetCommands",
        Request::Sequence(_) => "Sequence",
        Request::StartSweep => "StartSweep",
        Request::LoadCorrection(_) => "LoadCorrection",
        Request::ClearFaults => "ClearFaults",
        Request::GetTelemetry => "GetTelemetry",
        Request::Stream { .. } => "Stream",
        Request::SaveParams => "SaveParams",
        Request::Commission(_) => "Commission",
        Request::StopCommissioning => "StopCommissioning",
        Request::GetParams => "GetParams",
    }
}

/// The request as the errors name it.
pub fn request_name(request: &Request) -> String {
    let name = match request {
        Request::Sequence(e) => return format!("the sequence event {e:?}"),
        Request::Hello { .. } => "the handshake (Hello)",
        Request::SetParams(_) => "the parameters (SetParams)",
        Request::SetCommands(_) => "the commands (SetCommands)",
        Request::StartSweep => "the sweep's start (StartSweep)",
        Request::LoadCorrection(_) => "the correction (LoadCorrection)",
        Request::ClearFaults => "ClearFaults",
        Request::GetTelemetry => "the telemetry request",
        Request::Stream { .. } => "the streaming switch (Stream)",
        Request::SaveParams => "the parameter save (SaveParams)",
        Request::Commission(_) => "the commissioning's start (Commission)",
        Request::StopCommissioning => "the commissioning's stop (StopCommissioning)",
        Request::GetParams => "the parameters' request (GetParams)",
    };
    name.to_string()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;
    use std::time::Duration;

    use control_core::acquisition_stream::AcquisitionStream;
    use control_core::excitation::InjectionPoint;
    use control_core::protocol::{decode, encode, handle, RefusalReason, StorageError, MAX_FRAME};
    use control_core::stop_sequence::SequenceEvent;
    use control_core::{Axis, AxisInputs, Commands, Mode, Params};

    /// What the line does to one request (numbered from 0, empty frames not counted) or to
    /// its answer.
    #[derive(Clone, Copy, PartialEq)]
    enum Hit {
        /// A bit flipped inside the request: the drive answers `FrameError`.
        Request,
        /// The request's delimiter corrupted: the drive waits for the frame's end.
        RequestEnd,
        /// A bit flipped inside the answer.
        Answer,
        /// The answer's delimiter corrupted: it merges with whatever comes next.
        AnswerEnd,
    }

    /// A drive as a scripted byte stream: the core's own `handle` on an axis (stepped once per
    /// request, so that its telemetry follows), a flash that counts its records, and the line
    /// hitting the requests the script names.
    struct ScriptedDrive {
        axis: Axis,
        commands: Commands,
        stream: AcquisitionStream,
        frame: Vec<u8>,
        out: VecDeque<u8>,
        requests: usize,
        script: Vec<(usize, Hit)>,
        /// Requests carried out (answered with anything but `FrameError`), by kind.
        acted: Vec<Request>,
        records: u32,
        /// Saves still to fail (the flash refuses them: nothing written).
        flash_failures: u32,
    }

    impl ScriptedDrive {
        fn new(script: &[(usize, Hit)]) -> Self {
            let mut p = Params::default();
            p.sweep.point = InjectionPoint::TorqueCommand;
            p.sweep.amplitude = 0.2;
            Self {
                axis: Axis::new(p).unwrap(),
                commands: Commands::default(),
                stream: AcquisitionStream::default(),
                frame: Vec::new(),
                out: VecDeque::new(),
                requests: 0,
                script: script.to_vec(),
                acted: Vec::new(),
                records: 0,
                flash_failures: 0,
            }
        }

        fn hit(&self, k: usize) -> Option<Hit> {
            self.script.iter().find(|(n, _)| *n == k).map(|(_, h)| *h)
        }

        fn end_of_frame(&mut self) {
            if self.frame.is_empty() {
                return;
            }
            let k = self.requests;
            self.requests += 1;
            if self.hit(k) == Some(Hit::RequestEnd) {
                self.frame.push(0x55);
                return;
            }
            let mut frame = std::mem::take(&mut self.frame);
            if self.hit(k) == Some(Hit::Request) {
                let mid = frame.len() / 2;
                frame[mid] ^= if frame[mid] == 0x01 { 0x02 } else { 0x01 };
            }
            let response = match decode::<Request>(&mut frame) {
                Ok(Request::SaveParams) if self.flash_failures > 0 => {
                    self.flash_failures -= 1;
                    self.acted.push(Request::SaveParams);
                    Response::Refused(RefusalReason::Storage(StorageError::Flash))
                }
                Ok(Request::SaveParams) => {
                    self.records += 1;
                    self.acted.push(Request::SaveParams);
                    Response::Saved { sequence: self.records }
                }
                Ok(Request::GetTelemetry) => {
                    self.acted.push(Request::GetTelemetry);
                    let params_record = (self.records > 0).then_some(self.records);
                    Response::Telemetry(DriveTelemetry {
                        axis: self.axis.telemetry(),
                        params_record,
                        stack_free_bytes: None,
                    })
                }
                Ok(r) => {
                    self.acted.push(r);
                    handle(&mut self.axis, &mut self.commands, &mut self.stream, r)
                }
                Err(e) => Response::FrameError(e),
            };
            let inputs =
                AxisInputs { phase_currents: [0.0; 2], encoder_count: 0, bus_voltage: 48.0, load_acceleration: 0.0 };
            self.axis.step(&inputs, &self.commands);
            let mut out = vec![0u8; MAX_FRAME + 8];
            let n = encode(&response, &mut out).unwrap();
            match self.hit(k) {
                Some(Hit::Answer) => out[n / 2] ^= if out[n / 2] == 0x01 { 0x02 } else { 0x01 },
                Some(Hit::AnswerEnd) => out[n - 1] = 0x55,
                _ => {}
            }
            self.out.extend(&out[..n]);
        }

        fn count(&self, r: &Request) -> usize {
            self.acted.iter().filter(|a| std::mem::discriminant(*a) == std::mem::discriminant(r)).count()
        }
    }

    impl Read for ScriptedDrive {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.out.is_empty() {
                return Err(std::io::ErrorKind::WouldBlock.into());
            }
            let n = buf.len().min(self.out.len());
            for (d, s) in buf.iter_mut().zip(self.out.drain(..n)) {
                *d = s;
            }
            Ok(n)
        }
    }

    impl Write for ScriptedDrive {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            for &b in buf {
                if b == 0 {
                    self.end_of_frame();
                } else {
                    self.frame.push(b);
                }
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    fn link(script: &[(usize, Hit)]) -> DeviceLink<ScriptedDrive> {
        DeviceLink::new(ScriptedDrive::new(script), Duration::from_millis(30))
    }

    /// Request 0 is the telemetry before the order (the order's baseline), 1 the order.
    #[test]
    fn a_sweep_start_whose_answer_is_lost_is_read_from_the_telemetry_and_never_sent_twice() {
        for hit in [Hit::Answer, Hit::AnswerEnd] {
            let mut l = link(&[(1, hit)]);
            assert_eq!(answer(&mut l, &Request::StartSweep, None).unwrap(), Response::Done);
            assert_eq!(l.port().count(&Request::StartSweep), 1);
            assert_eq!((l.verified, l.resent), (1, 0));
            // The link is in step again: the next answers are the next requests'.
            assert!(matches!(answer(&mut l, &Request::GetTelemetry, None).unwrap(), Response::Telemetry(_)));
            assert_eq!(answer(&mut l, &Request::ClearFaults, None).unwrap(), Response::Done);
        }
    }

    #[test]
    fn a_request_the_drive_could_not_read_is_sent_again_whatever_it_is() {
        for hit in [Hit::Request, Hit::RequestEnd] {
            // Each order is preceded by its baseline telemetry (request 0).
            for (order, done) in
                [(Request::StartSweep, Response::Done), (Request::SaveParams, Response::Saved { sequence: 1 })]
            {
                let mut l = link(&[(1, hit)]);
                assert_eq!(answer(&mut l, &order, None).unwrap(), done);
                assert_eq!(l.port().count(&order), 1, "carried out once");
                assert_eq!((l.verified, l.resent), (0, 1));
            }
        }
    }

    /// A request whose delimiter was lost, with a timeout longer than the nudge: the lone
    /// delimiter sent after `NUDGE` ends it, the drive's `FrameError` comes back within the
    /// request's own wait, and the copy sent again is carried out once.
    #[test]
    fn a_request_without_its_end_is_ended_by_a_nudge_before_the_timeout() {
        let mut l = DeviceLink::new(ScriptedDrive::new(&[(1, Hit::RequestEnd)]), Duration::from_millis(1500));
        let started = std::time::Instant::now();
        assert_eq!(answer(&mut l, &Request::SaveParams, None).unwrap(), Response::Saved { sequence: 1 });
        assert!(started.elapsed() < Duration::from_millis(1000), "{:?}", started.elapsed());
        assert_eq!((l.port().records, l.resent), (1, 1));
    }

    /// Request 0: the save's baseline telemetry; 1: the save; 2: the telemetry that tells.
    #[test]
    fn a_save_whose_answer_is_lost_is_told_by_the_record_number_and_written_once() {
        for hit in [Hit::Answer, Hit::AnswerEnd] {
            // Written: its answer taken from the telemetry, not sent again.
            let mut l = link(&[(1, hit)]);
            assert_eq!(answer(&mut l, &Request::SaveParams, None).unwrap(), Response::Saved { sequence: 1 });
            assert_eq!((l.port().records, l.port().count(&Request::SaveParams)), (1, 1));
            assert_eq!((l.verified, l.resent), (1, 0));
            // The next save (requests 3–5) writes the next record, its answer lost too.
            l.port_mut().script.push((4, hit));
            assert_eq!(answer(&mut l, &Request::SaveParams, None).unwrap(), Response::Saved { sequence: 2 });
            assert_eq!((l.port().records, l.verified, l.resent), (2, 2, 0));
            // Not written (the flash refused it, and the refusal was lost): sent again, written once.
            let mut l = link(&[(1, hit)]);
            l.port_mut().flash_failures = 1;
            assert_eq!(answer(&mut l, &Request::SaveParams, None).unwrap(), Response::Saved { sequence: 1 });
            assert_eq!((l.port().records, l.port().count(&Request::SaveParams)), (1, 2));
            assert_eq!((l.verified, l.resent), (0, 1));
        }
    }

    /// The telemetry after the lost answer is lost every time too (requests 2–9): an error that
    /// names the save and says why it was not sent again; the one record stays the only one.
    #[test]
    fn a_save_whose_answer_and_telemetry_are_lost_is_an_error_that_says_why() {
        let script: Vec<(usize, Hit)> = (1..=9).map(|k| (k, Hit::Answer)).collect();
        let mut l = link(&script);
        let e = format!("{:#}", answer(&mut l, &Request::SaveParams, None).unwrap_err());
        for w in ["SaveParams", "not sent again", "telemetry that would tell could not be read", "may or may not"] {
            assert!(e.contains(w), "{w}: {e}");
        }
        assert_eq!((l.port().records, l.port().count(&Request::SaveParams)), (1, 1));
    }

    /// The telemetry before the save (its baseline) lost eight times running (requests 0–7):
    /// the save is not sent, and the error says so.
    #[test]
    fn a_save_whose_baseline_telemetry_is_lost_is_not_sent_and_the_error_says_so() {
        let script: Vec<(usize, Hit)> = (0..8).map(|k| (k, Hit::Answer)).collect();
        let mut l = link(&script);
        let e = format!("{:#}", answer(&mut l, &Request::SaveParams, None).unwrap_err());
        assert!(e.contains("SaveParams) was not sent") && e.contains("no answer after 8 copies"), "{e}");
        assert_eq!((l.port().records, l.port().count(&Request::SaveParams)), (0, 0));
    }

    #[test]
    fn harmless_orders_are_sent_again_and_sequence_refusals_are_not_counted_twice() {
        let velocity = Request::SetCommands(Commands { mode: Mode::Velocity, velocity: 5.0, ..Default::default() });
        let mut l = link(&[(0, Hit::Answer)]);
        assert_eq!(answer(&mut l, &velocity, None).unwrap(), Response::Done);
        assert_eq!((l.port().count(&velocity), l.resent, l.verified), (2, 1, 0));
        // Sequence mode (request 0), then a run-on (1: its baseline telemetry, 2: it) whose
        // answer is lost (3: the telemetry that tells), then a second run-on, refused, whose
        // baseline telemetry's answer is lost (4, asked again: 5) and then its own (6): each
        // carried out once, the refusal counted once.
        let sequence = Request::SetCommands(Commands { mode: Mode::Sequence, ..Default::default() });
        let on = Request::Sequence(SequenceEvent::RunOn);
        let mut l = link(&[(2, Hit::Answer), (4, Hit::AnswerEnd), (6, Hit::Answer)]);
        assert_eq!(answer(&mut l, &sequence, None).unwrap(), Response::Done);
        assert_eq!(answer(&mut l, &on, None).unwrap(), Response::Done);
        let refused = answer(&mut l, &on, None).unwrap();
        assert!(matches!(refused, Response::Refused(_)), "{refused:?}");
        assert_eq!(l.port().count(&on), 2, "{:?}", l.port().acted);
        assert_eq!(l.port().axis.telemetry().sequence.refused, 1);
        assert_eq!((l.verified, l.resent), (2, 1));
    }

    #[test]
    fn a_silent_drive_is_an_error_after_two_attempts_not_four() {
        struct Silent;
        impl Read for Silent {
            fn read(&mut self, _: &mut [u8]) -> std::io::Result<usize> {
                Err(std::io::ErrorKind::WouldBlock.into())
            }
        }
        impl Write for Silent {
            fn write(&mut self, b: &[u8]) -> std::io::Result<usize> {
                Ok(b.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let mut l = DeviceLink::new(Silent, Duration::from_millis(30));
        let e = answer(&mut l, &Request::ClearFaults, None).unwrap_err().to_string();
        assert!(e.contains("still running"), "{e}");
        assert_eq!(l.resent, 1);
    }
}
