//! The drive's link protocol: one versioned message set, shared by the firmware and the host.
//!
//! A frame is a postcard-serialised message followed by its CRC-32C (Castagnoli, the `crc`
//! crate's `CRC_32_ISCSI`, little-endian), COBS-encoded (the `cobs` crate, the flavour
//! postcard uses) and terminated by one zero byte. A frame is refused unless it is exactly
//! that: the COBS body (at most [`MAX_FRAME`] bytes) and at most its one terminator, a CRC that
//! matches, a message that uses every byte before the CRC. The drive answers every request; a
//! frame that does not decode (bad COBS, bad CRC, unknown message, trailing bytes, wrong
//! protocol version) is answered with [`Response::FrameError`] and never acted upon. A
//! request the drive cannot carry out (invalid parameters, a set-point outside its range, an
//! event its state refuses, parameters while the axis is moving) is answered with
//! [`Response::Refused`] and changes nothing.
//!
//! Why CRC-32C: with CRC-16 about one random multi-byte corruption in 2¹⁶ passes; CRC-32C
//! leaves one in 2³² and keeps a Hamming distance of 6 over frames of this size (up to 5 243
//! bits), where the IEEE CRC-32 has 4 or 5.

use core::fmt;

use serde::{de::DeserializeOwned, Deserialize, Serialize};

use crate::acquisition_stream::{AcquisitionStream, SampleBatch, BATCH};
use crate::axis::{Axis, Commands, CommissioningRefusal, Mode, Telemetry};
use crate::commissioning::{CommissioningSettings, CommissioningStatus};
use crate::faults::Faults;
use crate::params::Params;
use crate::ranges::{check_position, Quantity, RangeError};
use crate::response_correction::CorrectionParams;
use crate::stop_sequence::{Refusal, SequenceEvent};

/// Protocol version 15: commissioning's first stage reads the current sensors' noise
/// (`Stage::SensorNoise` in the telemetry's commissioning state). Version 14: the telemetry
/// carries every tick's torque command summed (`Telemetry::torque_command_sum`), so that a host reading it now and then gets the exact
/// mean torque between two readings. Version 13: the parameters carry a second torque-command
/// notch (`TorqueFilters::notch2_hz`, `notch2_q`, `notch2_depth`). Version 12: what commissioning measured carries the test current it drove
/// (`MeasuredMotor::test_current`). Version 11: commissioning ([`Request::Commission`], [`Request::StopCommissioning`],
/// [`Request::GetParams`],
/// the telemetry's `commissioning` state) and the parameters' encoder mounting and
/// `commissioned` flag. Version 10: the parameters carry the sweep's time budget
/// (`SweepParams::time_budget_s`). Version 9: the telemetry carries the drive's unused stack
/// ([`DriveTelemetry::stack_free_bytes`]: the bytes of its painted stack never touched since
/// boot), so that a stack about to run into the statics shows before it does. Version 8: each
/// streamed acquisition sample says whether the drive's output was limited during its
/// acquisition period (a flag bit beside `measuring`, the same byte on the
/// line: see [`crate::acquisition_stream::SAMPLE_LIMITED`]), so that the host counts every
/// result's share from the stream; the telemetry's copy of the last sample (serde's derived
/// encoding) grows by that flag's byte. Version 7: the telemetry's sweep status carries the
/// share of the last result's samples measured with the output limited
/// (`SweepStatus::last_limited`). Version 6:
/// `SaveParams` is answered with the sequence number of the record it
/// wrote ([`Response::Saved`]), and the telemetry carries the newest record in the drive's
/// flash ([`DriveTelemetry`]), so that a save whose answer is lost can be told from the
/// telemetry; the parameters carry the sweep's measure (`sweep.measure`) and the machine-end
/// accelerometer's sensitivity, and the acquisition may relate the measured torque to the
/// machine-end acceleration (version 5: parameters whose current-loop rate is not the
/// board's PWM rate are refused with that rate; version 4: `SaveParams`, and the answer to `Hello` says where the
/// drive's parameters came from at boot; version 3: CRC-32C instead of CRC-16, trailing bytes
/// refused, range refusals).
pub const VERSION: u16 = 15;
/// Largest encoded frame, COBS body without its terminator (a full parameter set fits with
/// room to spare).
pub const MAX_FRAME: usize = 1024;
/// Bytes of the check value.
pub const CRC_BYTES: usize = 4;

/// The frame check: CRC-32C (Castagnoli; reflected, init and final XOR 0xFFFFFFFF), the
/// `crc` crate's 256-entry table (1 KiB of flash).
pub const FRAME_CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISCSI);

pub fn crc32(data: &[u8]) -> u32 {
    FRAME_CRC.checksum(data)
}

// No allocator in the drive: the parameter-carrying variants stay inline (a request is
// decoded once per frame into one stack slot).
#[allow(clippy::large_enum_variant)]
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Request {
    /// Protocol handshake: the drive answers with its version.
    Hello {
        version: u16,
    },
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
    Stream {
        enabled: bool,
    },
    /// Write the parameters in force to the drive's flash, loaded at the next boot (only while
    /// the axis stands still in torque mode at zero torque: the gate drive is off meanwhile).
    /// Answered with [`Response::Saved`].
    SaveParams,
    /// Commission the motor (`crate::commissioning`; only at rest): the sequence drives the
    /// bridge until it ends, its state in the telemetry. Its result reaches the parameters
    /// when the host sends them back (`Params::with_commissioned`, `SetParams`), and the
    /// drive's flash with `SaveParams`.
    Commission(CommissioningSettings),
    /// Stop a running commissioning sequence (the bridge off).
    StopCommissioning,
    /// The parameters in force: answered with [`Response::Params`].
    GetParams,
}

/// The answer to `GetTelemetry`: the axis's telemetry, and what the drive's parameter store
/// holds.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct DriveTelemetry {
    pub axis: Telemetry,
    /// The sequence number of the newest parameter record in the drive's flash: the one loaded
    /// at boot, or the one `SaveParams` wrote last (each save writes the next number). `None`:
    /// no record (nothing saved, only corrupt or foreign ones), or no parameter storage.
    pub params_record: Option<u32>,
    /// Bytes of the drive's stack never touched since boot (its high-water mark: the stack is
    /// painted at reset and scanned from its low end when the telemetry is asked for). `None`:
    /// the drive does not measure its stack (the core alone, the virtual drive).
    pub stack_free_bytes: Option<u32>,
}

/// Where the parameters a drive booted with came from.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum ParamsOrigin {
    /// The set saved last (`SaveParams`), with its record's sequence number.
    Stored { sequence: u32 },
    /// The defaults, and why no stored set was used.
    Defaults(DefaultsReason),
}

/// Why a drive booted with its default parameters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum DefaultsReason {
    /// This side has no parameter storage (the FMU, a test).
    NoStorage,
    /// Both pages are erased: nothing was ever saved.
    NothingStored,
    /// A page holds a record whose check value does not match (a write cut short, worn flash).
    Corrupt,
    /// A record of another format (another firmware's layout), with its format number.
    Foreign { format: u16 },
    /// A record that reads but whose parameters this firmware refuses (the first offending field).
    Invalid(FieldName),
}

impl fmt::Display for ParamsOrigin {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Stored { sequence } => write!(f, "parameters loaded from flash (record {sequence})"),
            Self::Defaults(DefaultsReason::NoStorage) => write!(f, "default parameters (no parameter storage)"),
            Self::Defaults(DefaultsReason::NothingStored) => write!(f, "default parameters (nothing saved yet)"),
            Self::Defaults(DefaultsReason::Corrupt) => {
                write!(f, "default parameters (the stored record is corrupt: check value mismatch)")
            }
            Self::Defaults(DefaultsReason::Foreign { format }) => {
                write!(f, "default parameters (the stored record has format {format}, this firmware reads another)")
            }
            Self::Defaults(DefaultsReason::Invalid(field)) => {
                write!(f, "default parameters (the stored set is refused: {})", field.as_str())
            }
        }
    }
}

/// Why the parameters could not be saved.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum StorageError {
    /// This side has no parameter storage.
    Unavailable,
    /// The flash refused an erase or a write, or read back something else.
    Flash,
    /// The parameter set does not fit a page.
    TooLarge,
}

/// A parameter's name as it crosses the link (at most 32 bytes of ASCII, zero-padded).
#[derive(Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
pub struct FieldName(pub [u8; 32]);

impl FieldName {
    pub fn new(name: &str) -> Self {
        let mut b = [0u8; 32];
        for (d, s) in b.iter_mut().zip(name.bytes()) {
            *d = s;
        }
        Self(b)
    }
    /// The name (up to the first zero; anything not UTF-8 shows as "?").
    pub fn as_str(&self) -> &str {
        let n = self.0.iter().position(|&b| b == 0).unwrap_or(32);
        core::str::from_utf8(&self.0[..n]).unwrap_or("?")
    }
}

impl fmt::Debug for FieldName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

/// Why a request was refused.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum RefusalReason {
    /// The parameters do not validate: the first offending field (`Params::validate` names
    /// it with its value and range).
    InvalidParams(FieldName),
    /// Parameters can only be replaced while the axis stands still in torque mode.
    Busy,
    /// The stop sequence refused the event.
    Sequence(Refusal),
    /// The sweep cannot start (injection point or mode, or already running).
    Sweep,
    /// Invalid correction sections, or a command still in motion through the filter.
    Correction,
    /// A set-point that is not a finite number.
    NotFinite(Quantity),
    /// A set-point outside its range (`crate::ranges`): which one, and its value.
    OutOfRange(RangeError),
    /// The parameters could not be saved.
    Storage(StorageError),
    /// The parameters' current-loop rate is not the board's: its PWM timer samples and runs
    /// the tick at `board_hz`, fixed when the drive starts.
    LoopRate { board_hz: f32 },
    /// A commissioning setting out of range or not this drive's: by name.
    CommissioningSetting(FieldName),
    /// Commissioning only at rest (no torque, no sweep, none running).
    CommissioningBusy,
}

impl fmt::Display for RefusalReason {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::InvalidParams(field) => write!(f, "invalid parameters: {}", field.as_str()),
            Self::Busy => write!(
                f,
                "parameters only while the axis stands still in torque mode at zero torque, with no fault latched (ClearFaults first) and no sweep running"
            ),
            Self::Sequence(r) => write!(f, "the stop sequence refused the event: {r}"),
            Self::Sweep => write!(
                f,
                "the sweep cannot start (injection point, mode: velocity-loop points need the velocity loop, the position-command point position mode; or already running)"
            ),
            Self::Correction => write!(f, "invalid correction, or a command still in motion through the filter"),
            Self::NotFinite(q) => write!(f, "{} is not a finite number", q.name()),
            Self::OutOfRange(e) => write!(f, "{e}"),
            Self::Storage(StorageError::Unavailable) => write!(f, "this drive has no parameter storage"),
            Self::Storage(StorageError::Flash) => write!(f, "the flash refused the write or read back something else"),
            Self::Storage(StorageError::TooLarge) => write!(f, "the parameter set does not fit a flash page"),
            Self::CommissioningSetting(field) => write!(f, "commissioning setting refused: {}", field.as_str()),
            Self::CommissioningBusy => write!(
                f,
                "commissioning only at rest: torque mode at zero torque, no sweep and no commissioning running"
            ),
            Self::LoopRate { board_hz } => write!(
                f,
                "rates.current_loop_hz must be the board's PWM rate, {board_hz} Hz (the tick runs at the timer's rate)"
            ),
        }
    }
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
    /// Bytes after the message (before the CRC) or after the frame's terminator.
    Trailing,
    /// A count field larger than what it counts (a sample batch's `count` above its 16 slots).
    Count { got: u32, max: u32 },
}

impl fmt::Display for FrameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Framing => write!(f, "frame not COBS-encoded or not delimited"),
            Self::Crc => write!(f, "frame CRC-32 mismatch"),
            Self::Message => write!(f, "frame holds no valid message"),
            Self::TooLong => write!(f, "frame longer than {MAX_FRAME} bytes"),
            Self::Version { got } => write!(f, "protocol version {got}, this side speaks {VERSION}"),
            Self::Trailing => write!(f, "bytes after the message or after the frame's end"),
            Self::Count { got, max } => write!(f, "count field {got} above its maximum {max}"),
        }
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Response {
    Hello {
        version: u16,
        /// Where the parameters the drive booted with came from.
        boot_params: ParamsOrigin,
    },
    Done,
    Refused(RefusalReason),
    Telemetry(DriveTelemetry),
    FrameError(FrameError),
    /// Streamed acquisition samples (sent by the drive while streaming is on).
    Samples(SampleBatch),
    /// `SaveParams` carried out: the sequence number of the record written (the telemetry's
    /// `params_record` from now on).
    Saved {
        sequence: u32,
    },
    /// The parameters in force (the answer to `GetParams`).
    Params(Params),
}

impl Response {
    /// Every count and length field within what it counts (the host checks this before it
    /// uses one; [`decode_response`] does it).
    pub fn check(&self) -> Result<(), FrameError> {
        match self {
            Self::Samples(b) if b.count as usize > BATCH => {
                Err(FrameError::Count { got: b.count as u32, max: BATCH as u32 })
            }
            _ => Ok(()),
        }
    }
}

/// Encode a message as a frame (COBS, zero-terminated) into `out`; returns its length
/// (terminator included). The COBS body is at most [`MAX_FRAME`] bytes.
pub fn encode<T: Serialize>(msg: &T, out: &mut [u8]) -> Result<usize, FrameError> {
    let mut raw = [0u8; MAX_FRAME];
    let n = postcard::to_slice(msg, &mut raw[..MAX_FRAME - CRC_BYTES]).map_err(|_| FrameError::TooLong)?.len();
    let crc = crc32(&raw[..n]).to_le_bytes();
    raw[n..n + CRC_BYTES].copy_from_slice(&crc);
    let room = out.len().min(MAX_FRAME);
    let len = cobs::try_encode(&raw[..n + CRC_BYTES], &mut out[..room]).map_err(|_| FrameError::TooLong)?;
    *out.get_mut(len).ok_or(FrameError::TooLong)? = 0;
    Ok(len + 1)
}

/// Decode one frame in place: its COBS body, with or without its one zero terminator, and
/// nothing else (a zero inside, or anything after the terminator, is refused).
pub fn decode<T: DeserializeOwned>(frame: &mut [u8]) -> Result<T, FrameError> {
    let body = match frame.split_last_mut() {
        Some((0, body)) => body,
        _ => frame,
    };
    if body.len() > MAX_FRAME {
        return Err(FrameError::TooLong);
    }
    if body.is_empty() {
        return Err(FrameError::Framing);
    }
    if body.contains(&0) {
        return Err(FrameError::Trailing);
    }
    let report = cobs::decode_in_place_report(body).map_err(|_| FrameError::Framing)?;
    let n = report.dst_used;
    if report.src_used != body.len() || n < CRC_BYTES + 1 {
        return Err(FrameError::Framing);
    }
    let (payload, crc) = body[..n].split_at(n - CRC_BYTES);
    if crc32(payload).to_le_bytes() != [crc[0], crc[1], crc[2], crc[3]] {
        return Err(FrameError::Crc);
    }
    match postcard::take_from_bytes(payload) {
        Ok((msg, [])) => Ok(msg),
        Ok(_) => Err(FrameError::Trailing),
        Err(_) => Err(FrameError::Message),
    }
}

/// The host's side: decode a frame from the drive and check every count field.
pub fn decode_response(frame: &mut [u8]) -> Result<Response, FrameError> {
    let r: Response = decode(frame)?;
    r.check()?;
    Ok(r)
}

/// Parameters (and the parameter store) may change only while the axis stands still in torque
/// mode at zero torque, with no fault latched and no sweep running: a new axis starts without
/// faults (a latched fault must be cleared by `ClearFaults`, never by a parameter change) and
/// without the sweep's results.
pub fn parameters_may_change(commands: &Commands, axis: &Axis) -> bool {
    // An axis not yet commissioned has that fault latched from its first tick: parameters
    // (a commissioned set among them) are what lifts it.
    let faults = axis.faults().0 & !Faults::NOT_COMMISSIONED;
    commands.mode == Mode::Torque
        && commands.torque == 0.0
        && axis.applied_torque() == 0.0
        && faults == 0
        && !axis.sweep().running()
        && !matches!(axis.commissioning(), Some(CommissioningStatus::Running(_)))
}

/// The drive's side: carry out one request on `axis` (its `commands`, its sample `stream`).
/// Every value is checked here, where it enters the drive: parameters by `Params::validate`,
/// set-points and targets against their ranges (`crate::ranges`); a refusal changes nothing.
pub fn handle(axis: &mut Axis, commands: &mut Commands, stream: &mut AcquisitionStream, request: Request) -> Response {
    let refused = Response::Refused;
    match request {
        Request::Hello { version } if version != VERSION => Response::FrameError(FrameError::Version { got: version }),
        Request::Hello { .. } => {
            Response::Hello { version: VERSION, boot_params: ParamsOrigin::Defaults(DefaultsReason::NoStorage) }
        }
        Request::SetParams(p) => {
            if !parameters_may_change(commands, axis) {
                return refused(RefusalReason::Busy);
            }
            // A drive's rate is its board's: a sweep its parameters cannot run is refused now.
            // Built again in place (no second axis on the stack); a refusal changes nothing.
            match p.validate_for_drive().and_then(|()| axis.rebuild(&p)) {
                Ok(()) => Response::Done,
                Err(e) => refused(RefusalReason::InvalidParams(FieldName::new(e.field()))),
            }
        }
        Request::SetCommands(c) => match c.validate() {
            Ok(()) => {
                *commands = c;
                Response::Done
            }
            Err(e) if !e.value.is_finite() => refused(RefusalReason::NotFinite(e.quantity)),
            Err(e) => refused(RefusalReason::OutOfRange(e)),
        },
        Request::Sequence(e) => {
            if let SequenceEvent::MoveTo(target) = e {
                if let Err(r) = check_position(Quantity::MoveTarget, target) {
                    return refused(RefusalReason::OutOfRange(r));
                }
            }
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
        Request::GetTelemetry => {
            Response::Telemetry(DriveTelemetry { axis: axis.telemetry(), params_record: None, stack_free_bytes: None })
        }
        Request::Stream { enabled } => {
            stream.set_enabled(enabled);
            Response::Done
        }
        // The drive's application saves (it owns the flash); here there is nothing to save to.
        Request::SaveParams => refused(RefusalReason::Storage(StorageError::Unavailable)),
        Request::Commission(settings) => {
            if !(commands.mode == Mode::Torque && commands.torque == 0.0) {
                return refused(RefusalReason::CommissioningBusy);
            }
            match axis.start_commissioning(&settings) {
                Ok(()) => Response::Done,
                Err(CommissioningRefusal::Setting(field)) => {
                    refused(RefusalReason::CommissioningSetting(FieldName::new(field)))
                }
                Err(CommissioningRefusal::Busy) => refused(RefusalReason::CommissioningBusy),
            }
        }
        Request::StopCommissioning => {
            axis.stop_commissioning();
            Response::Done
        }
        Request::GetParams => Response::Params(*axis.params()),
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
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
            Request::SaveParams,
        ] {
            assert_eq!(round_trip(r), r);
        }
    }

    /// A default axis and the core's answer to `GetTelemetry`.
    fn core_telemetry() -> (Axis, DriveTelemetry) {
        let mut axis = Axis::new(Params::default()).unwrap();
        let (mut commands, mut stream) = (Commands::default(), AcquisitionStream::default());
        let Response::Telemetry(t) = handle(&mut axis, &mut commands, &mut stream, Request::GetTelemetry) else {
            panic!("no telemetry")
        };
        (axis, t)
    }

    /// Version 6: the save's answer and the telemetry carry the record number through a frame,
    /// and the core (no parameter storage) reports none.
    #[test]
    fn the_record_number_survives_a_frame_and_the_core_has_none() {
        let (axis, t) = core_telemetry();
        assert_eq!((t.axis, t.params_record), (axis.telemetry(), None));
        for r in [
            Response::Saved { sequence: u32::MAX },
            Response::Telemetry(DriveTelemetry { params_record: Some(7), ..t }),
            Response::Telemetry(t),
        ] {
            let mut buf = [0u8; MAX_FRAME + 8];
            let n = encode(&r, &mut buf).unwrap();
            assert_eq!(decode_response(&mut buf[..n]), Ok(r));
        }
    }

    /// Version 9: the unused stack crosses the link at its extremes, the core (which does not
    /// measure a stack) reports none, and the field costs its postcard bytes only: `None` its
    /// one tag byte, a value the varint's one to five bytes more.
    #[test]
    fn the_unused_stack_survives_a_frame_and_the_core_has_none() {
        let (_, t) = core_telemetry();
        assert_eq!(t.stack_free_bytes, None);
        let body = |r: &Response| postcard::to_slice(r, &mut [0u8; MAX_FRAME]).unwrap().len();
        let none = body(&Response::Telemetry(t));
        for (free, extra) in [(0u32, 1), (127, 1), (128, 2), (82_040, 3), (u32::MAX, 5)] {
            let r = Response::Telemetry(DriveTelemetry { stack_free_bytes: Some(free), ..t });
            assert_eq!(body(&r), none + extra, "{free}");
            let mut buf = [0u8; MAX_FRAME + 8];
            let n = encode(&r, &mut buf).unwrap();
            assert!(n <= MAX_FRAME + 1);
            assert_eq!(decode_response(&mut buf[..n]), Ok(r));
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
        let mut short = [0x02, 0x07, 0x01, 0x01, 0x01, 0x00];
        assert_eq!(decode::<Request>(&mut short), Err(FrameError::Framing));
        let mut garbage = [0u8; 16];
        let m = encode(&[42u8, 9, 9], &mut garbage).unwrap(); // variant 42: no request
        assert_eq!(decode::<Request>(&mut garbage[..m]), Err(FrameError::Message));
    }

    /// The frame check against independent references: the CRC-32C catalogue's check value
    /// (RFC 3720, "123456789" → 0xE3069283) and COBS's example from Cheshire and Baker's paper.
    #[test]
    fn crc_and_cobs_match_their_references() {
        assert_eq!(crc32(b"123456789"), 0xE306_9283);
        let mut out = [0u8; 8];
        let n = cobs::try_encode(&[0x11, 0x22, 0x00, 0x33], &mut out).unwrap();
        assert_eq!(&out[..n], &[0x03, 0x11, 0x22, 0x02, 0x33]);
        // A frame by hand: postcard's ClearFaults (variant 6), its CRC-32C little-endian, COBS.
        let mut raw = [6u8, 0, 0, 0, 0];
        raw[1..].copy_from_slice(&crc32(&[6]).to_le_bytes());
        let mut frame = [0u8; 16];
        let n = encode(&Request::ClearFaults, &mut frame).unwrap();
        let mut by_hand = [0u8; 16];
        let m = cobs::try_encode(&raw, &mut by_hand).unwrap();
        assert_eq!(&frame[..n], &[&by_hand[..m], &[0][..]].concat()[..]);
    }

    /// Issue 18: anything after the frame's end, extra zeros, or bytes after the message
    /// inside a frame with a valid CRC are refused.
    #[test]
    fn anything_after_a_frame_or_its_message_is_refused() {
        let mut buf = [0u8; 64];
        let n = encode(&Request::GetTelemetry, &mut buf).unwrap();
        let good = buf;
        assert_eq!(decode::<Request>(&mut buf[..n]), Ok(Request::GetTelemetry));
        let mut without_terminator = good;
        assert_eq!(decode::<Request>(&mut without_terminator[..n - 1]), Ok(Request::GetTelemetry));
        for extra in [&[0u8][..], &[0, 0], &[7], &[0x01, 0x00], &[0x03, 0x41, 0x42]] {
            let mut f = [&good[..n], extra].concat();
            assert!(decode::<Request>(&mut f).is_err(), "{extra:?} after the frame");
        }
        // A message followed by a byte, with a CRC over both: the message does not use it.
        let raw = [7u8, 0x55];
        let mut body = [0u8; 6];
        body[..2].copy_from_slice(&raw);
        body[2..].copy_from_slice(&crc32(&raw).to_le_bytes());
        let mut f = [0u8; 16];
        let m = cobs::try_encode(&body, &mut f).unwrap();
        assert_eq!(decode::<Request>(&mut f[..m]), Err(FrameError::Trailing));
        // The same message alone is accepted (so the refusal above is for the extra byte).
        let mut body = [7u8, 0, 0, 0, 0];
        body[1..].copy_from_slice(&crc32(&[7]).to_le_bytes());
        let m = cobs::try_encode(&body, &mut f).unwrap();
        assert_eq!(decode::<Request>(&mut f[..m]), Ok(Request::GetTelemetry));
    }

    fn decode_hex(hex: &str) -> [u8; 64] {
        let mut out = [0u8; 64];
        for (i, o) in out.iter_mut().take(hex.len() / 2).enumerate() {
            *o = u8::from_str_radix(&hex[2 * i..2 * i + 2], 16).unwrap();
        }
        out
    }

    /// Issue 18's reproducer: `SetCommands` with `jog_velocity = −4e30` in position mode (a
    /// version-2 frame, which version 3 refuses by its check value), and the same request in
    /// a version-3 frame: refused with the value and its range, the commands untouched, and
    /// the axis, stepped on, never moves its position command.
    #[test]
    fn issue_18_absurd_jog_is_refused_with_its_range() {
        let hex = "0302020101010105caf249f20101010101010103920f00";
        let mut old = decode_hex(hex);
        assert_eq!(decode::<Request>(&mut old[..hex.len() / 2]), Err(FrameError::Crc));
        let c = Commands { mode: Mode::Position, jog_velocity: -4e30, ..Default::default() };
        let mut buf = [0u8; 64];
        let n = encode(&Request::SetCommands(c), &mut buf).unwrap();
        let request = decode::<Request>(&mut buf[..n]).unwrap();
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands::default();
        let mut stream = AcquisitionStream::default();
        let answer = handle(&mut axis, &mut commands, &mut stream, request);
        let Response::Refused(RefusalReason::OutOfRange(e)) = answer else { panic!("{answer:?}") };
        assert_eq!(e.quantity, Quantity::JogVelocity);
        assert_eq!(e.value, -4e30f32 as f64);
        assert_eq!(e.quantity.range(), (-100_000.0, 100_000.0));
        extern crate std;
        let text = std::format!("{}", RefusalReason::OutOfRange(e));
        assert!(text.contains("commands.jog_velocity") && text.contains("100000"), "{text}");
        assert_eq!(commands, Commands::default());
        // Stepped directly (the FMU's way in): a range fault, the command path holds still.
        let inputs =
            crate::AxisInputs { phase_currents: [0.0; 2], encoder_count: 0, bus_voltage: 48.0, load_acceleration: 0.0 };
        for _ in 0..64 {
            axis.step(&inputs, &c);
        }
        assert!(axis.faults().contains(crate::Faults::COMMAND_RANGE));
        assert!(!axis.faults().contains(crate::Faults::FOLLOWING_ERROR));
        assert_eq!(axis.telemetry().position_command, 0);
        // The largest accepted jog runs without overflow (saturating sums, in range).
        let fast = Commands { mode: Mode::Position, jog_velocity: -crate::ranges::MAX_SPEED, ..Default::default() };
        assert_eq!(fast.validate(), Ok(()));
        let mut axis = Axis::new(Params::default()).unwrap();
        for _ in 0..64 {
            axis.step(&inputs, &fast);
        }
        assert!(axis.telemetry().position_command < 0);
    }

    /// Issue 18: `sweep.min_settle_s = 3.4e38` passed validation and overflowed at
    /// `StartSweep`; now the parameters are refused by name.
    #[test]
    fn issue_18_absurd_sweep_settling_is_refused_by_name() {
        let mut p = Params::default();
        p.sweep.min_settle_s = 3.4e38;
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands::default();
        let mut stream = AcquisitionStream::default();
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::SetParams(p)),
            Response::Refused(RefusalReason::InvalidParams(FieldName::new("min_settle_s")))
        );
        extern crate std;
        let e = p.validate().unwrap_err();
        assert_eq!(
            std::format!("{e}"),
            "sweep min_settle_s = 340000000000000000000000000000000000000 is outside [0, 10000]"
        );
        assert_eq!(*axis.params(), Params::default());
        // The longest settling accepted: the sweep's tick counts stay exact.
        p.sweep.min_settle_s = 10_000.0;
        p.sweep.settle_cycles = 10_000.0;
        p.sweep.start_hz = 0.001;
        assert_eq!(p.validate(), Ok(()));
        assert!(p.sweep.max_total_ticks(p.rates.current_loop_hz) < 1 << 60);
    }

    #[test]
    fn targets_beyond_the_position_range_are_refused_before_anything_changes() {
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands { mode: Mode::Sequence, ..Default::default() };
        let mut stream = AcquisitionStream::default();
        let far = SequenceEvent::MoveTo(i64::MIN);
        let answer = handle(&mut axis, &mut commands, &mut stream, Request::Sequence(far));
        assert!(
            matches!(
                answer,
                Response::Refused(RefusalReason::OutOfRange(RangeError { quantity: Quantity::MoveTarget, .. }))
            ),
            "{answer:?}"
        );
        let c = Commands { position: (1 << 53) + 1, ..Default::default() };
        let answer = handle(&mut axis, &mut commands, &mut stream, Request::SetCommands(c));
        assert!(
            matches!(
                answer,
                Response::Refused(RefusalReason::OutOfRange(RangeError { quantity: Quantity::Position, .. }))
            ),
            "{answer:?}"
        );
        let c = Commands { position: 1 << 53, ..Default::default() };
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::SetCommands(c)), Response::Done);
    }

    #[test]
    fn a_sample_count_beyond_the_batch_is_refused_on_both_sides() {
        let mut b = SampleBatch { count: 200, ..Default::default() };
        let mut buf = [0u8; MAX_FRAME + 8];
        assert!(encode(&Response::Samples(b), &mut buf).is_err(), "a batch that claims 200 samples is not sent");
        b.count = 16;
        // Ticks 4, 8, …: every sample encodes to the same length (a one-byte step).
        for (k, s) in b.samples.iter_mut().enumerate() {
            s.tick = 4 * (k as u64 + 1);
            s.u = k as f32;
        }
        let n = encode(&Response::Samples(b), &mut buf).unwrap();
        assert_eq!(decode_response(&mut buf[..n]), Ok(Response::Samples(b)));
        // A batch whose ticks go back (one straddling a new axis) goes out whole.
        let mut back = b;
        back.samples[8].tick = 1;
        let n = encode(&Response::Samples(back), &mut buf).unwrap();
        assert_eq!(decode_response(&mut buf[..n]), Ok(Response::Samples(back)));
        // 17 samples under a valid CRC (a sequence length the drive never sends) do not decode.
        let mut payload = [0u8; 600];
        let body = postcard::to_slice(&Response::Samples(b), &mut payload).unwrap().len();
        // The variant tag, `dropped`, then the sequence's length: 16 → 17 with one more sample.
        assert_eq!(payload[2], 16);
        payload[2] = 17;
        let sample_bytes = (body - 3) / 16;
        assert_eq!((body - 3) % 16, 0, "samples of one length");
        payload.copy_within(body - sample_bytes..body, body);
        let raw = &mut payload[..body + sample_bytes];
        let crc = crc32(raw).to_le_bytes();
        let mut framed = [0u8; 700];
        let mut with_crc = [0u8; 700];
        with_crc[..raw.len()].copy_from_slice(raw);
        with_crc[raw.len()..raw.len() + 4].copy_from_slice(&crc);
        let m = cobs::encode(&with_crc[..raw.len() + 4], &mut framed);
        assert_eq!(decode_response(&mut framed[..m]), Err(FrameError::Message));
        // The same bytes with the length left at 16 decode: it is the limit that refuses the
        // frame above, not a truncated sample.
        payload[2] = 16;
        let raw = &payload[..body];
        let crc = crc32(raw).to_le_bytes();
        with_crc[..raw.len()].copy_from_slice(raw);
        with_crc[raw.len()..raw.len() + 4].copy_from_slice(&crc);
        let m = cobs::encode(&with_crc[..raw.len() + 4], &mut framed);
        assert_eq!(decode_response(&mut framed[..m]), Ok(Response::Samples(b)));
    }

    #[test]
    fn a_parameter_change_never_clears_a_latched_fault_nor_drops_a_running_sweep() {
        let mut stream = AcquisitionStream::default();
        let mut commands = Commands::default();
        let mut axis = Axis::new(Params::default()).unwrap();
        axis.latch_fault(crate::faults::Faults::OVERCURRENT);
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::SetParams(Params::default())),
            Response::Refused(RefusalReason::Busy)
        );
        assert!(axis.faults().contains(crate::faults::Faults::OVERCURRENT), "the fault stays latched");
        axis.clear_faults();
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::SetParams(Params::default())),
            Response::Done
        );
        // A torque-command sweep at rest: torque mode, zero set-point.
        let mut p = Params::default();
        p.sweep.point = crate::excitation::InjectionPoint::TorqueCommand;
        p.sweep.amplitude = 0.2;
        let mut axis = Axis::new(p).unwrap();
        axis.start_sweep().unwrap();
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::SetParams(Params::default())),
            Response::Refused(RefusalReason::Busy)
        );
        assert!(axis.sweep().running());
    }

    #[test]
    fn refused_requests_change_nothing() {
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands { mode: Mode::Velocity, velocity: 10.0, ..Default::default() };
        let mut stream = AcquisitionStream::default();
        let before = *axis.params();
        let mut bad = Params::default();
        bad.velocity.kp = f32::NAN;
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::SetParams(Params::default())),
            Response::Refused(RefusalReason::Busy)
        );
        commands = Commands::default();
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::SetParams(bad)),
            Response::Refused(RefusalReason::InvalidParams(FieldName::new("velocity.kp")))
        );
        assert_eq!(*axis.params(), before);
        let nan = Commands { torque: f32::NAN, ..Default::default() };
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::SetCommands(nan)),
            Response::Refused(RefusalReason::NotFinite(Quantity::Torque))
        );
        assert_eq!(commands, Commands::default());
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::Sequence(SequenceEvent::Stop)),
            Response::Refused(RefusalReason::Sequence(Refusal::NotInSequenceMode))
        );
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::Hello { version: VERSION + 1 }),
            Response::FrameError(FrameError::Version { got: VERSION + 1 })
        );
        assert_eq!(
            handle(&mut axis, &mut commands, &mut stream, Request::Hello { version: VERSION }),
            Response::Hello { version: VERSION, boot_params: ParamsOrigin::Defaults(DefaultsReason::NoStorage) }
        );
    }

    /// `measuring` and `limited` cross the link as two bits of one byte, in every combination,
    /// at the size one flag took; a byte with another bit set is a corrupt frame, not a sample.
    #[test]
    fn a_samples_flags_cross_the_link_in_one_byte_and_unknown_bits_are_refused() {
        let mut b = SampleBatch { count: 4, ..Default::default() };
        for (k, s) in b.samples[..4].iter_mut().enumerate() {
            s.tick = 4 * (k as u64 + 1);
            s.u = 1.5;
            s.measuring = k & 1 == 0;
            s.limited = k & 2 == 0;
        }
        let mut buf = [0u8; MAX_FRAME + 8];
        let n = encode(&Response::Samples(b), &mut buf).unwrap();
        assert_eq!(decode_response(&mut buf[..n]), Ok(Response::Samples(b)));
        let mut payload = [0u8; 200];
        let body = postcard::to_slice(&Response::Samples(b), &mut payload).unwrap().len();
        // The variant tag, `dropped`, the length; then each sample: tick step, u, y, phase
        // (4 bytes each), the flags byte, point, record, half block (one byte each here): 17
        // bytes, as version 7's sample with `measuring` alone.
        assert_eq!(body, 3 + 4 * 17);
        let flags_at = 3 + 1 + 12;
        use crate::acquisition_stream::{SAMPLE_LIMITED, SAMPLE_MEASURING};
        assert_eq!(payload[flags_at], SAMPLE_MEASURING | SAMPLE_LIMITED, "sample 0 has both");
        assert_eq!(payload[flags_at + 17], SAMPLE_LIMITED, "sample 1 is limited only");
        for bad in [4u8, 0x80, 0xFF] {
            payload[flags_at] = bad;
            let raw = &payload[..body];
            let mut with_crc = [0u8; 260];
            with_crc[..body].copy_from_slice(raw);
            with_crc[body..body + 4].copy_from_slice(&crc32(raw).to_le_bytes());
            let mut framed = [0u8; 300];
            let m = cobs::encode(&with_crc[..body + 4], &mut framed);
            assert_eq!(decode_response(&mut framed[..m]), Err(FrameError::Message), "flags {bad:#x}");
        }
    }

    #[test]
    fn streaming_is_switched_over_the_link_and_batches_fit_a_frame() {
        let mut axis = Axis::new(Params::default()).unwrap();
        let mut commands = Commands::default();
        let mut stream = AcquisitionStream::default();
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::Stream { enabled: true }), Response::Done);
        assert!(stream.enabled());
        for t in 0..64u64 {
            stream.offer(&crate::phase_shifted_sweep::AcquisitionSample {
                tick: t,
                u: 1.5,
                y: -2.5,
                phase: 3.0,
                measuring: true,
                limited: t % 3 == 0,
                point: 7,
                segment: crate::phase_shifted_sweep::AcquisitionSample::segment_of(2, 3),
            });
        }
        let batch = stream.take_batch().unwrap();
        let mut buf = [0u8; MAX_FRAME + 8];
        let n = encode(&Response::Samples(batch), &mut buf).unwrap();
        assert_eq!(decode::<Response>(&mut buf[..n]), Ok(Response::Samples(batch)));
        assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::Stream { enabled: false }), Response::Done);
        assert!(stream.take_batch().is_none());
    }
}
