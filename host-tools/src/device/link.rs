//! The host's side of the drive link: the core's protocol (`control_core::protocol`: postcard
//! messages, CRC-32C, COBS, zero-delimited frames, version 3; every count field checked
//! before use, `frame_stream`) over any byte stream — the drive's USART
//! through the ST-LINK virtual COM port, or a socket to a simulated drive in tests.
//!
//! Every request gets one answer. While streaming is on, the drive also sends `Samples`
//! frames unasked; they are kept aside in arrival order and handed out by
//! [`DeviceLink::take_samples`], so a request never mistakes a sample batch for its answer.

use std::io::{Read, Write};
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use control_core::acquisition_stream::SampleBatch;
use control_core::protocol::{encode, Request, Response, MAX_FRAME, VERSION};

use crate::device::frame_stream::FrameStream;

/// A drive's byte stream, and how the host lets time pass on it: a serial port sleeps; a
/// drive simulated in this process runs meanwhile (its time moves only when asked to).
pub trait DrivePort: Read + Write {
    fn pause(&mut self, d: Duration) {
        std::thread::sleep(d);
    }
}

impl DrivePort for Box<dyn serialport::SerialPort> {}
impl DrivePort for std::os::unix::net::UnixStream {}

pub struct DeviceLink<T: Read + Write> {
    port: T,
    /// Bytes read but not yet part of a complete frame.
    pending: FrameStream,
    samples: Vec<SampleBatch>,
    timeout: Duration,
    /// Bytes received from the drive so far.
    pub bytes_read: u64,
    /// Frames from the drive that did not decode (corrupted on the line, or the tail of a
    /// frame that was under way when the port was opened): skipped, counted.
    pub corrupt_frames: u64,
    /// Requests sent again after a lost request or answer (`device::answer`).
    pub resent: u64,
    /// Orders whose answer was lost and whose outcome was read from the drive's telemetry.
    pub verified: u64,
    /// The same two by request (`device::answer::request_kind`): (sent again, judged).
    pub by_request: std::collections::BTreeMap<&'static str, (u64, u64)>,
    /// The drive was told to stream (its last `Stream` request was answered `Done`): a frame
    /// that does not decode may be a sample batch. Otherwise the drive sends only answers,
    /// and a corrupt frame while an answer is awaited is that answer, lost: no use waiting
    /// out the timeout.
    streaming: bool,
    /// The last request failed (no answer, a corrupt frame): before the next one, end the
    /// drive's partial frame and drop what is in flight.
    resync: bool,
}

/// What a resynchronisation found in flight.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Drained {
    /// `FrameError` answers: the drive read a corrupt frame (a request whose end was lost
    /// ends at the lone delimiter; a request split by a byte corrupted to zero is two).
    pub frame_errors: u32,
    /// Bytes received meanwhile.
    pub bytes: u64,
}

impl<T: Read + Write> DeviceLink<T> {
    pub fn new(port: T, timeout: Duration) -> Self {
        Self {
            port,
            pending: FrameStream::default(),
            samples: Vec::new(),
            timeout,
            bytes_read: 0,
            corrupt_frames: 0,
            resent: 0,
            verified: 0,
            by_request: Default::default(),
            streaming: false,
            resync: false,
        }
    }

    /// Send one request and wait for its answer (once: `device::answer` sends again after a
    /// lost request or answer).
    pub fn request(&mut self, request: &Request) -> Result<Response> {
        let mut buf = vec![0u8; MAX_FRAME + 8];
        let n = encode(request, &mut buf).map_err(|e| anyhow::anyhow!("cannot encode the request: {e}"))?;
        if self.resync {
            self.resynchronise()?;
        }
        self.port.write_all(&buf[..n]).context("cannot write to the drive")?;
        self.port.flush().ok();
        let deadline = Instant::now() + self.timeout;
        let mut nudge = Some(Instant::now() + NUDGE);
        loop {
            // A request whose delimiter was corrupted waits in the drive for its end: a lone
            // delimiter ends it (the drive answers `FrameError`), or is an empty frame the
            // drive ignores if the request had ended.
            let until = nudge.map_or(deadline, |n| n.min(deadline));
            let frame = self.next_frame(until, !self.streaming);
            if let (Err(e), Some(n)) = (&frame, nudge) {
                if e.is::<NoAnswer>() && Instant::now() >= n && Instant::now() < deadline && !self.pending.has_bytes() {
                    nudge = None;
                    self.port.write_all(&[0]).context("cannot write to the drive")?;
                    self.port.flush().ok();
                    continue;
                }
            }
            match frame {
                Ok(Response::Samples(b)) => self.samples.push(b),
                Ok(other) => {
                    if let (Request::Stream { enabled }, Response::Done) = (request, &other) {
                        self.streaming = *enabled;
                    }
                    return Ok(other);
                }
                Err(e) => {
                    self.resync = true;
                    return Err(e);
                }
            }
        }
    }

    /// Before the next request, resynchronise (a request answered by `FrameError` may have
    /// been cut in two by a byte corrupted to zero: the second half's answer is in flight).
    pub fn resynchronise_before_next(&mut self) {
        self.resync = true;
    }

    /// After a failed request: a lone delimiter ends any partial frame the drive holds (a
    /// corrupted terminator merges a request with the next; the drive ignores an empty
    /// frame), then whatever arrives within a tenth of the timeout, at most [`DRAIN`], is dropped (an answer to
    /// the failed request, a frame error for the merged bytes); sample batches are kept. The
    /// bytes of a frame still without its end are dropped too (an answer whose delimiter
    /// was corrupted would otherwise swallow the next one), counted as a corrupt frame.
    pub fn resynchronise(&mut self) -> Result<Drained> {
        self.resync = false;
        let bytes_before = self.bytes_read;
        let mut frame_errors = 0;
        self.port.write_all(&[0]).context("cannot write to the drive")?;
        self.port.flush().ok();
        let until = Instant::now() + (self.timeout / 10).min(DRAIN);
        while Instant::now() < until {
            match self.next_frame(until, false) {
                Ok(Response::Samples(b)) => self.samples.push(b),
                Ok(Response::FrameError(_)) => frame_errors += 1,
                Ok(_) => {}
                Err(_) if Instant::now() >= until => break,
                Err(e) if is_link_failure(&e) => return Err(e),
                Err(_) => {}
            }
        }
        if self.pending.discard() {
            self.corrupt_frames += 1;
        }
        Ok(Drained { frame_errors, bytes: self.bytes_read - bytes_before })
    }

    /// Let `d` pass (see [`DrivePort::pause`]).
    pub fn pause(&mut self, d: Duration)
    where
        T: DrivePort,
    {
        self.port.pause(d);
    }

    /// The byte stream underneath.
    pub fn port(&self) -> &T {
        &self.port
    }

    /// The byte stream underneath.
    pub fn port_mut(&mut self) -> &mut T {
        &mut self.port
    }

    /// The byte stream underneath.
    pub fn into_port(self) -> T {
        self.port
    }

    /// Sample batches received so far (streaming), oldest first.
    pub fn take_samples(&mut self) -> Vec<SampleBatch> {
        std::mem::take(&mut self.samples)
    }

    /// Read frames for `duration`, keeping sample batches.
    pub fn listen(&mut self, duration: Duration) -> Result<()> {
        let until = Instant::now() + duration;
        while Instant::now() < until {
            match self.next_frame(until, false) {
                Ok(Response::Samples(b)) => self.samples.push(b),
                Ok(other) => bail!("unasked frame from the drive: {other:?}"),
                Err(_) if Instant::now() >= until => break,
                Err(e) => return Err(e),
            }
        }
        Ok(())
    }

    /// The next complete frame that decodes; frames that do not are skipped and counted (the
    /// answer may still follow: a streamed batch may be what the line corrupted), or, with
    /// `answer_only` (the drive sends nothing but answers), end the wait as a lost answer.
    fn next_frame(&mut self, deadline: Instant, answer_only: bool) -> Result<Response> {
        let mut chunk = [0u8; 4096];
        let mut skipped: Option<(u64, control_core::protocol::FrameError)> = None;
        let mut last_byte = Instant::now();
        loop {
            match self.pending.next_frame() {
                Some(Ok(r)) => return Ok(r),
                Some(Err(e)) => {
                    self.corrupt_frames += 1;
                    if answer_only {
                        bail!("the answer from the drive arrived corrupt ({e})");
                    }
                    skipped = Some((skipped.map_or(0, |(n, _)| n) + 1, e));
                    continue;
                }
                None => {}
            }
            // An answer whose delimiter was corrupted never ends: with only answers coming,
            // bytes that stopped arriving without one are that answer, lost.
            if answer_only && last_byte.elapsed() >= DRAIN && self.pending.discard() {
                self.corrupt_frames += 1;
                bail!("the answer from the drive arrived without its end (its delimiter corrupted)");
            }
            if Instant::now() >= deadline {
                return Err(anyhow::Error::new(NoAnswer(match skipped {
                    Some((n, e)) => format!(
                        "no answer from the drive within {:?}: {n} corrupt frame(s) from the drive instead (last: {e})",
                        self.timeout
                    ),
                    None => format!("no answer from the drive within {:?}", self.timeout),
                })));
            }
            match self.port.read(&mut chunk) {
                Ok(0) => bail!(CLOSED),
                Ok(n) => {
                    self.bytes_read += n as u64;
                    self.pending.push(&chunk[..n]);
                    last_byte = Instant::now();
                }
                Err(e)
                    if matches!(
                        e.kind(),
                        std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock | std::io::ErrorKind::Interrupted
                    ) => {}
                Err(e) => return Err(e).context("cannot read from the drive"),
            }
        }
    }
}

/// The longest a resynchronisation waits for what is in flight: a drive answers within its
/// link task's poll (2 ms on the G474) plus what its transmit buffer holds (1 KiB, 11 ms at
/// 921 600 Bd). A frame error that comes later is taken for the next request's answer, which
/// is then sent again after another resynchronisation (`device::answer`): slower, never wrong.
pub const DRAIN: Duration = Duration::from_millis(50);

/// Nothing that decodes arrived before the deadline.
#[derive(Debug)]
struct NoAnswer(String);

impl std::fmt::Display for NoAnswer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.0)
    }
}

impl std::error::Error for NoAnswer {}

/// How long an answer is awaited before a lone delimiter is sent after the request (a drive
/// answers within a few milliseconds, after at most its transmit buffer and stream ring).
pub const NUDGE: Duration = Duration::from_millis(100);

/// The link itself failed (the drive closed it, the port cannot be read or written): sending
/// again cannot help, unlike a lost answer.
pub fn is_link_failure(e: &anyhow::Error) -> bool {
    e.downcast_ref::<std::io::Error>().is_some() || e.to_string().contains(CLOSED)
}

const CLOSED: &str = "the drive closed the link";

/// A `LoadCorrection` frame (`servo tune`'s `<axis>.corr.frame`), checked as the drive would
/// check it (`CorrectionParams::validate` through `Axis::load_correction`) at the
/// position-loop period of the parameters the firmware installs (`Params::default` rates).
pub fn correction_request(frame: &mut [u8]) -> Result<Request> {
    match control_core::protocol::decode::<Request>(frame) {
        Ok(r @ Request::LoadCorrection(c)) => {
            let period = control_core::Params::default().rates.position_period();
            c.validate(period).map_err(|e| anyhow::anyhow!("the drive would refuse this correction: {e}"))?;
            Ok(r)
        }
        Ok(other) => bail!("a {other:?} request, not a correction"),
        Err(e) => bail!("not a frame of protocol version {VERSION}: {e}"),
    }
}

/// The baud rates a serial link takes (a clap value parser for every `--baud`): 1 200 to
/// 12 000 000, the range of USB serial adapters; 0 or a stray digit would open a port that
/// moves nothing.
pub fn baud_rate(text: &str) -> std::result::Result<u32, String> {
    const RANGE: std::ops::RangeInclusive<u32> = 1_200..=12_000_000;
    match text.parse::<u32>() {
        Ok(baud) if RANGE.contains(&baud) => Ok(baud),
        _ => Err(format!("a baud rate is a whole number from 1 200 to 12 000 000 (got `{text}`)")),
    }
}

/// Open the drive's serial port (8N1, no flow control).
pub fn open_serial(path: &str, baud: u32) -> Result<Box<dyn serialport::SerialPort>> {
    let port = serialport::new(path, baud).timeout(Duration::from_millis(50)).open().with_context(|| {
        format!("cannot open the serial port {path} (is the board attached, or the virtual drive running, and may you use the port?)")
    })?;
    // Whatever an earlier session left unread is not an answer to this one.
    port.clear(serialport::ClearBuffer::Input).ok();
    Ok(port)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_baud_rate_is_refused_outside_what_a_link_takes() {
        assert_eq!(baud_rate("921600"), Ok(921_600));
        assert_eq!(baud_rate("1200"), Ok(1_200));
        for bad in ["0", "1199", "12000001", "-1", "9600.5", "fast"] {
            assert!(baud_rate(bad).unwrap_err().contains(&format!("`{bad}`")), "{bad}");
        }
    }
    use control_core::acquisition_stream::AcquisitionStream;
    use control_core::phase_shifted_sweep::AcquisitionSample;
    use control_core::protocol::{decode, handle};
    use control_core::{Axis, Commands, Params};
    use std::os::unix::net::UnixStream;

    /// A drive in a thread: the core's own `handle` on an axis, over a socket, sending sample
    /// batches between answers while streaming — as the firmware's link task does.
    fn simulated_drive(mut s: UnixStream) {
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands::default();
        let mut stream = AcquisitionStream::default();
        let mut frame = Vec::new();
        let mut byte = [0u8; 1];
        let mut tick = 0u64;
        while s.read(&mut byte).map(|n| n == 1).unwrap_or(false) {
            if byte[0] != 0 {
                frame.push(byte[0]);
                continue;
            }
            let response = match decode::<Request>(&mut frame) {
                Ok(r) => handle(&mut axis, &mut commands, &mut stream, r),
                Err(e) => Response::FrameError(e),
            };
            frame.clear();
            // Some samples arrive before the answer, as they would from a running drive.
            for _ in 0..20 {
                stream.offer(&AcquisitionSample { tick, u: tick as f32, ..Default::default() });
                tick += 4;
            }
            let mut out = vec![0u8; MAX_FRAME + 8];
            while let Some(b) = stream.take_batch() {
                let n = encode(&Response::Samples(b), &mut out).unwrap();
                s.write_all(&out[..n]).unwrap();
            }
            let n = encode(&response, &mut out).unwrap();
            s.write_all(&out[..n]).unwrap();
        }
    }

    #[test]
    fn requests_get_their_answers_and_streamed_samples_are_kept_aside_in_order() {
        let (host, drive) = UnixStream::pair().unwrap();
        let t = std::thread::spawn(move || simulated_drive(drive));
        host.set_read_timeout(Some(Duration::from_millis(50))).unwrap();
        let mut link = DeviceLink::new(host, Duration::from_secs(2));
        assert!(matches!(link.request(&Request::Hello { version: VERSION }).unwrap(), Response::Hello { .. }));
        assert_eq!(link.request(&Request::Stream { enabled: true }).unwrap(), Response::Done);
        assert!(matches!(link.request(&Request::GetTelemetry).unwrap(), Response::Telemetry(_)));
        assert_eq!(link.request(&Request::ClearFaults).unwrap(), Response::Done);
        let ticks: Vec<u64> = link
            .take_samples()
            .iter()
            .flat_map(|b| {
                crate::device::frame_stream::batch_samples(b).unwrap().iter().map(|s| s.tick).collect::<Vec<_>>()
            })
            .collect();
        assert!(ticks.len() >= 40, "{} samples", ticks.len());
        assert!(ticks.windows(2).all(|w| w[1] == w[0] + 4), "in order, none lost: {ticks:?}");
        // A version the drive does not speak is an error with the reason.
        let e = match link.request(&Request::Hello { version: VERSION + 1 }).unwrap() {
            Response::FrameError(e) => e.to_string(),
            other => panic!("{other:?}"),
        };
        assert!(e.contains("version"), "{e}");
        drop(link);
        t.join().unwrap();
    }

    /// Issue 18: a correction with a NaN pole or 99 sections is refused before it is sent.
    #[test]
    fn corrections_are_checked_as_the_drive_checks_them() {
        let good = control_core::Params::default().correction;
        let frame = |c| {
            let mut buf = vec![0u8; MAX_FRAME + 8];
            let n = encode(&Request::LoadCorrection(c), &mut buf).unwrap();
            buf.truncate(n);
            buf
        };
        assert!(correction_request(&mut frame(good)).is_ok());
        let mut nan = good;
        nan.count = 1;
        nan.sections[0].poles.hz = f32::NAN;
        let e = correction_request(&mut frame(nan)).unwrap_err().to_string();
        assert!(e.contains("would refuse"), "{e}");
        let many = control_core::response_correction::CorrectionParams { count: 99, ..good };
        let e = correction_request(&mut frame(many)).unwrap_err().to_string();
        assert!(e.contains("would refuse"), "{e}");
        // And the drive does refuse both (the host's check is the drive's).
        let mut axis = Axis::new(control_core::Params::default()).unwrap();
        for c in [nan, many] {
            assert!(axis.load_correction(&c).is_err());
        }
    }

    /// Issue 18: a batch whose count says 200 is an error, not a panic (the drive cannot send
    /// one: its encoding refuses it; a longer sample sequence does not decode, see
    /// `control_core::protocol`'s tests).
    #[test]
    fn a_sample_count_beyond_its_slots_is_an_error() {
        let b = SampleBatch { count: 200, ..Default::default() };
        let mut buf = vec![0u8; MAX_FRAME + 8];
        assert!(encode(&Response::Samples(b), &mut buf).is_err());
        assert!(crate::device::frame_stream::sample_rows(&[b]).is_err());
    }

    #[test]
    fn a_silent_or_garbling_drive_is_an_error_not_a_hang() {
        let (host, mut drive) = UnixStream::pair().unwrap();
        host.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        let mut link = DeviceLink::new(host, Duration::from_millis(200));
        let e = link.request(&Request::GetTelemetry).unwrap_err().to_string();
        assert!(e.contains("no answer"), "{e}");
        // Garbage in flight after a failure is dropped by the resynchronisation (which ends
        // with a lone delimiter to the drive); a garbled answer to a request is an error.
        drive.write_all(&[0x05, 0x11, 0x22, 0x33, 0x44, 0x00]).unwrap();
        let e = link.request(&Request::GetTelemetry).unwrap_err().to_string();
        assert!(e.contains("no answer"), "{e}");
        let (host, mut drive) = UnixStream::pair().unwrap();
        host.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        let mut link = DeviceLink::new(host, Duration::from_millis(200));
        drive.write_all(&[0x05, 0x11, 0x22, 0x33, 0x44, 0x00]).unwrap();
        let e = link.request(&Request::GetTelemetry).unwrap_err().to_string();
        // Not streaming: the drive sends only answers, so a corrupt frame is the answer, lost.
        assert!(e.contains("arrived corrupt"), "{e}");
        assert_eq!(link.corrupt_frames, 1);
        // The next request first sends the lone delimiter: the drive reads the first request,
        // an empty frame, then the second request.
        let _ = link.request(&Request::GetTelemetry);
        drive.set_read_timeout(Some(Duration::from_millis(20))).unwrap();
        let mut got = [0u8; 64];
        let n = drive.read(&mut got).unwrap();
        let first = got.iter().position(|&b| b == 0).unwrap();
        assert_eq!(got[first + 1], 0, "{:?}", &got[..n]);
        assert_eq!(&got[..first], &got[first + 2..2 * first + 2], "the same request again");
    }
}
