//! The drive's link protocol: one versioned message set, shared by the firmware and the host.
//!
//! A frame is a postcard-serialised message followed by its CRC-16/CCITT-FALSE (big-endian),
//! COBS-encoded and terminated by a zero byte. The drive answers every request; a frame that
//! does not decode (bad COBS, bad CRC, unknown message, wrong protocol version) is answered
//! with [`Response::FrameError`] and never acted upon. A request the drive cannot carry out
//! (invalid parameters, an event its state refuses, parameters while the axis is moving) is
//! answered with [`Response::Refused`] and changes nothing.

use core::fmt;

use serde::{de::DeserializeOwned, Deserialize, Serialize};

use crate::axis::{Axis, Commands, Mode, Telemetry};
use crate::params::Params;
use crate::acquisition_stream::{AcquisitionStream, SampleBatch};
use crate::response_correction::CorrectionParams;
use crate::stop_sequence::{Refusal, SequenceEvent};

pub const VERSION: u16 = 2;
/// Largest encoded frame (a full parameter set fits with room to spare).
pub const MAX_FRAME: usize = 1024;

// No allocator in the drive: the parameter-carrying variants stay inline (a request is
// decoded once per frame into one stack slot).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Request {
    /// Protocol handshake: the drive answers with its version.
    Hello { version: u16 },
    /// Replace every parameter (only while the axis stands still in torque mode at zero torque).
    SetParams(Params),
    /// Mode and set-points, used from the next tick.
    SetCommands(Commands),
    Sequence(SequenceEvent),
    StartSweep,
    /// Response-correction coefficients (seed 001; only while no command is in motion).
    LoadCorrection(CorrectionParams),
    ClearFaults,
    GetTelemetry,
    /// Stream acquisition samples (`Response::Samples` frames, unasked) or stop.
    Stream { enabled: bool },
}

/// Why a request was refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum RefusalReason {
    /// The parameters do not validate.
    InvalidParams,
    /// Parameters can only be replaced while the axis stands still in torque mode.
    Busy,
    /// The stop sequence refused the event.
    Sequence(Refusal),
    /// The sweep cannot start (injection point or mode, or already running).
    Sweep,
    /// Invalid correction sections, or a command still in motion through the filter.
    Correction,
    /// A set-point that is not a finite number.
    NotFinite,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum FrameError {
    /// No zero delimiter, or COBS that does not decode.
    Framing,
    /// The CRC does not match.
    Crc,
    /// A message that does not decode (unknown variant, truncated).
    Message,
    /// The frame does not fit the buffer.
    TooLong,
    /// The peer speaks another protocol version.
    Version { got: u16 },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Framing => write!(f, "frame not COBS-encoded or not delimited"),
            Self::Crc => write!(f, "frame CRC mismatch"),
            Self::Message => write!(f, "frame holds no valid message"),
            Self::TooLong => write!(f, "frame longer than {MAX_FRAME} bytes"),
            Self::Version { got } => write!(f, "protocol version {got}, this drive speaks {VERSION}"),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Response {
    Hello { version: u16 },
    Done,
    Refused(RefusalReason),
    Telemetry(Telemetry),
    FrameError(FrameError),
    /// Streamed acquisition samples (sent by the drive while streaming is on).
    Samples(SampleBatch),
}

/// CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF).
pub fn crc16(data: &[u8]) -> u16 {
    let mut crc = 0xFFFFu16;
    for &b in data {
        crc ^= (b as u16) << 8;
        for _ in 0..8 {
            crc = if crc & 0x8000 != 0 { (crc << 1) ^ 0x1021 } else { crc << 1 };
        }
    }
    crc
}

/// COBS-encode `data` into `out`; returns the length (without the delimiter).
fn cobs_encode(data: &[u8], out: &mut [u8]) -> Option<usize> {
    let mut code_at = 0;
    let mut w = 1;
    let mut code = 1u8;
    for &b in data {
        if b == 0 {
            *out.get_mut(code_at)? = code;
            code_at = w;
            w += 1;
            code = 1;
        } else {
            *out.get_mut(w)? = b;
            w += 1;
            code += 1;
            if code == 0xFF {
                *out.get_mut(code_at)? = code;
                code_at = w;
                w += 1;
                code = 1;
            }
        }
    }
    *out.get_mut(code_at)? = code;
    Some(w)
}

/// COBS-decode in place; returns the decoded length.
fn cobs_decode(buf: &mut [u8]) -> Option<usize> {
    let (mut r, mut w) = (0, 0);
    while r < buf.len() {
        let code = buf[r] as usize;
        if code == 0 || r + code > buf.len() {
            return None;
        }
        r += 1;
        for _ in 1..code {
            buf[w] = buf[r];
            w += 1;
            r += 1;
        }
        if code != 0xFF && r < buf.len() {
            buf[w] = 0;
            w += 1;
        }
    }
    Some(w)
}

/// Encode a message as a frame (COBS, zero-terminated) into `out`; returns its length.
pub fn encode<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_FRAME];
    let n = postcard::to_slice(msg, &mut raw[..MAX_FRAME - 2]).map_err(|_| FrameError::TooLong)?.len();
    let crc = crc16(&raw[..n]).to_be_bytes();
    raw[n..n + 2].copy_from_slice(&crc);
    let len = cobs_encode(&raw[..n + 2], out).ok_or(FrameError::TooLong)?;
    *out.get_mut(len).ok_or(FrameError::TooLong)? = 0;
    Ok(len + 1)
}

/// Decode one frame (with or without its zero terminator), in place.
pub fn decode<T: DeserializeOwned>(frame: &mut [u8]) -> Result<T, FrameError> {
    let body = match frame.iter().position(|&b| b == 0) {
        Some(end) => &mut frame[..end],
        None => frame,
    };
    if body.len() > MAX_FRAME {
        return Err(FrameError::TooLong);
    }
    let n = cobs_decode(body).ok_or(FrameError::Framing)?;
    if n < 3 {
        return Err(FrameError::Framing);
    }
    let (payload, crc) = body[..n].split_at(n - 2);
    if crc16(payload).to_be_bytes() != [crc[0], crc[1]] {
        return Err(FrameError::Crc);
    }
    postcard::from_bytes(payload).map_err(|_| FrameError::Message)
}

/// The drive's side: carry out one request on `axis` (its `commands`, its sample `stream`).
pub fn handle(axis: &mut Axis, commands: &mut Commands, stream: &mut AcquisitionStream, request: Request) -> Response {
    let refused = Response::Refused;
    match request {
        Request::Hello { version } if version != VERSION => Response::FrameError(FrameError::Version { got: version }),
        Request::Hello { .. } => Response::Hello { version: VERSION },
        Request::SetParams(p) => {
            let at_rest = commands.mode == Mode::Torque && commands.torque == 0.0 && axis.telemetry().torque_command == 0.0;
            if !at_rest {
                return refused(RefusalReason::Busy);
            }
            match Axis::new(p) {
                Ok(new) => {
                    *axis = new;
                    Response::Done
                }
                Err(_) => refused(RefusalReason::InvalidParams),
            }
        }
        Request::SetCommands(c) => {
            let finite = [c.move_speed, c.jog_velocity, c.velocity, c.torque].iter().all(|x| x.is_finite());
            if !finite {
                return refused(RefusalReason::NotFinite);
            }
            *commands = c;
            Response::Done
        }
        Request::Sequence(e) => {
            axis.apply_mode(commands);
            match axis.sequence_event(e) {
                Ok(()) => Response::Done,
                Err(r) => refused(RefusalReason::Sequence(r)),
            }
        }
        Request::StartSweep => {
            axis.apply_mode(commands);
            match axis.start_sweep() {
                Ok(()) => Response::Done,
                Err(_) => refused(RefusalReason::Sweep),
            }
        }
        Request::LoadCorrection(p) => match axis.load_correction(&p) {
            Ok(()) => Response::Done,
            Err(_) => refused(RefusalReason::Correction),
        },
        Request::ClearFaults => {
            axis.clear_faults();
            Response::Done
        }
        Request::GetTelemetry => Response::Telemetry(*axis.telemetry()),
        Request::Stream { enabled } => {
            stream.set_enabled(enabled);
            Response::Done
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn round_trip(r: Request) -> Request {
        let mut buf = [0u8; MAX_FRAME + 8];
        let n = encode(&r, &mut buf).unwrap();
        assert_eq!(buf[n - 1], 0);
        assert!(buf[..n - 1].iter().all(|&b| b != 0), "COBS leaves no zero inside the frame");
        decode(&mut buf[..n]).unwrap()
    }

    #[test]
    fn every_request_survives_a_frame() {
        let p = Params::default();
        for r in [
            Request::Hello { version: VERSION },
            Request::SetParams(p),
            Request::SetCommands(Commands { mode: Mode::Position, position: -(1 << 40), ..Default::default() }),
            Request::Sequence(SequenceEvent::MoveTo(123_456_789)),
            Request::StartSweep,
            Request::LoadCorrection(p.correction),
            Request::ClearFaults,
            Request::GetTelemetry,
        ] {
            assert_eq!(round_trip(r), r);
        }
    }

    #[test]
    fn corrupt_frames_are_refused_and_never_acted_upon() {
        let mut buf = [0u8; MAX_FRAME];
        let n = encode(&Request::ClearFaults, &mut buf).unwrap();
        // Flip one bit anywhere in the body: the CRC (or the framing) catches it.
        for i in 0..n - 1 {
            for bit in 0..8 {
                let mut f = buf;
                f[i] ^= 1 << bit;
                if f[i] == 0 {
                    continue; // a zero ends the frame early: a framing error, checked below
                }
                assert!(decode::<Request>(&mut f[..n]).is_err(), "byte {i} bit {bit}");
            }
        }
        let mut short = [0x02, 0x07, 0x00];
        assert_eq!(decode::<Request>(&mut short), Err(FrameError::Framing));
        let mut garbage = [0u8; 16];
        let m = encode(&[9u8, 9, 9], &mut garbage).unwrap();
        assert_eq!(decode::<Request>(&mut garbage[..m]), Err(FrameError::Message));
    }

    #[test]
    fn refused_requests_change_nothing() {
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands { mode: Mode::Velocity, velocity: 10.0, ..Default::default() };
        let mut stream = AcquisitionStream::default();
        let before = *axis.params();
        let mut bad = Params::default();
        bad.velocity.kp = f32::NAN;
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::SetParams(Params::default())), Response::Refused(RefusalReason::Busy));
        commands = Commands::default();
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::SetParams(bad)), Response::Refused(RefusalReason::InvalidParams));
        assert_eq!(*axis.params(), before);
        let nan = Commands { torque: f32::NAN, ..Default::default() };
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::SetCommands(nan)), Response::Refused(RefusalReason::NotFinite));
        assert_eq!(commands, Commands::default());
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::Sequence(SequenceEvent::Stop)),
            Response::Refused(RefusalReason::Sequence(Refusal::NotInSequenceMode))
        );
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::Hello { version: 7 }), Response::FrameError(FrameError::Version { got: 7 }));
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::Hello { version: VERSION }), Response::Hello { version: VERSION });
    }

    #[test]
    fn streaming_is_switched_over_the_link_and_batches_fit_a_frame() {
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands::default();
        let mut stream = AcquisitionStream::default();
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::Stream { enabled: true }), Response::Done);
        assert!(stream.enabled());
        for t in 0..64u64 {
            stream.offer(&crate::phase_shifted_sweep::AcquisitionSample { tick: t, u: 1.5, y: -2.5, phase: 3.0, measuring: true, point: 7, record: 2 });
        }
        let batch = stream.take_batch().unwrap();
        let mut buf = [0u8; MAX_FRAME + 8];
        let n = encode(&Response::Samples(batch), &mut buf).unwrap();
        assert_eq!(decode::<Response>(&mut buf[..n]), Ok(Response::Samples(batch)));
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::Stream { enabled: false }), Response::Done);
        assert!(stream.take_batch().is_none());
    }
}
