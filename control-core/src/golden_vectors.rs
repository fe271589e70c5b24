//! Golden vectors: recorded inputs of the axis, replayed through [`Axis::step`] with a digest
//! of every output. The host records them from closed-loop simulations and replays them
//! natively; the firmware's `core-vectors` binary replays the same bytes on a Cortex-M4F
//! (QEMU). Equal digests mean the core computes the same bits on both.
//!
//! Large files (a whole commissioning) are streamed: [`replay_from`] reads them through a
//! [`VectorSource`] (on the target, semihosting's file calls) instead of a slice in flash.
//!
//! Format (little-endian): `b"SVV1"`, scenario count (u32); per scenario: parameter preset
//! (u32), tick count (u32), event count (u32), the events (tick u32, kind u8, value i64), then
//! per tick the sensor inputs and the commands ([`TICK_BYTES`] bytes).

use core::fmt;

use crate::acc_dec::AccDecKind;
use crate::axis::{Axis, AxisInputs, Commands, Mode};
use crate::commissioning::{CommissioningSettings, CommissioningStatus};
use crate::params::{EncoderMounting, Params};
use crate::response_correction::{CorrectionSection, SecondOrder};
use crate::stop_sequence::SequenceEvent;

pub const MAGIC: &[u8; 4] = b"SVV1";
pub const TICK_BYTES: usize = 41;
pub const EVENT_BYTES: usize = 13;

/// The preset with every feature on (for the per-tick cost with everything at once).
pub const ALL_FEATURES: u32 = 5;

/// Parameter sets the vectors may use (both sides build them the same way): the default
/// motor, commissioned (the vectors' encoder counts start at its electrical zero; the
/// every-feature set's electrical zero is offset).
pub fn preset(id: u32) -> Option<Params> {
    let mut p = Params::default().commissioned_as(EncoderMounting::default());
    match id {
        0 => {}
        1 => p.acc_dec.kind = AccDecKind::Butterworth,
        2 => {
            p.friction.amplitude = 0.06;
            p.friction.decay = 0.2;
        }
        3 => {
            p.correction.count = 2;
            p.correction.sections[0] = CorrectionSection {
                zeros: Some(SecondOrder { hz: 70.0, damping: 0.05 }),
                poles: SecondOrder { hz: 100.0, damping: 1.0 },
            };
            p.correction.sections[1] =
                CorrectionSection { zeros: None, poles: SecondOrder { hz: 100.0, damping: 1.0 } };
        }
        4 => p.acc_dec.kind = AccDecKind::MovingAverage,
        // Every feature at once, at its most expensive: 6th-order Butterworth acc/dec, eight
        // correction sections, friction compensation, torque low-pass and both notches, and (with a
        // sweep start event) a sweep injecting on the torque while the position loop runs.
        ALL_FEATURES => {
            p.encoder_mounting.electrical_offset = 2.0;
            p.acc_dec.kind = AccDecKind::Butterworth;
            p.acc_dec.order = 6;
            p.friction.amplitude = 0.06;
            p.friction.decay = 0.2;
            p.filters.low_pass_hz = 1500.0;
            p.filters.notch_hz = 900.0;
            p.filters.notch_q = 2.0;
            p.filters.notch_depth = 0.1;
            p.filters.notch2_hz = 2200.0;
            p.filters.notch2_q = 1.0;
            p.filters.notch2_depth = 0.2;
            p.sweep.point = crate::excitation::InjectionPoint::TorqueCommand;
            p.sweep.amplitude = 0.05;
            p.correction.count = crate::response_correction::MAX_SECTIONS;
            for (i, s) in p.correction.sections.iter_mut().enumerate() {
                *s = CorrectionSection {
                    zeros: Some(SecondOrder { hz: 40.0 + 10.0 * i as f32, damping: 0.05 }),
                    poles: SecondOrder { hz: 45.0 + 10.0 * i as f32, damping: 0.3 },
                };
            }
        }
        _ => return None,
    }
    Some(p)
}

/// What can happen between ticks.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VectorEvent {
    Sequence(SequenceEvent),
    StartSweep,
    /// Commissioning with the default settings for the axis's encoder and tick
    /// ([`CommissioningSettings::for_params`]).
    StartCommissioning,
}

impl VectorEvent {
    pub fn encode(self) -> (u8, i64) {
        match self {
            Self::Sequence(SequenceEvent::RunOn) => (1, 0),
            Self::Sequence(SequenceEvent::RunOff) => (2, 0),
            Self::Sequence(SequenceEvent::Stop) => (3, 0),
            Self::Sequence(SequenceEvent::ReleaseBlocking) => (4, 0),
            Self::Sequence(SequenceEvent::MoveTo(t)) => (5, t),
            Self::Sequence(SequenceEvent::ReturnToStart) => (6, 0),
            Self::Sequence(SequenceEvent::SelectGain(i)) => (7, i as i64),
            Self::StartSweep => (8, 0),
            Self::StartCommissioning => (9, 0),
        }
    }

    pub fn decode(kind: u8, value: i64) -> Option<Self> {
        Some(match kind {
            1 => Self::Sequence(SequenceEvent::RunOn),
            2 => Self::Sequence(SequenceEvent::RunOff),
            3 => Self::Sequence(SequenceEvent::Stop),
            4 => Self::Sequence(SequenceEvent::ReleaseBlocking),
            5 => Self::Sequence(SequenceEvent::MoveTo(value)),
            6 => Self::Sequence(SequenceEvent::ReturnToStart),
            7 => Self::Sequence(SequenceEvent::SelectGain(usize::try_from(value).ok()?)),
            8 => Self::StartSweep,
            9 => Self::StartCommissioning,
            _ => return None,
        })
    }
}

/// One tick's inputs as bytes.
pub fn encode_tick(i: &AxisInputs, c: &Commands, out: &mut [u8; TICK_BYTES]) {
    let mut w = Writer { buf: out, at: 0 };
    w.put(&i.phase_currents[0].to_le_bytes());
    w.put(&i.phase_currents[1].to_le_bytes());
    w.put(&i.encoder_count.to_le_bytes());
    w.put(&i.bus_voltage.to_le_bytes());
    w.put(&[c.mode.code() as u8]);
    w.put(&c.position.to_le_bytes());
    w.put(&c.move_speed.to_le_bytes());
    w.put(&c.jog_velocity.to_le_bytes());
    w.put(&c.velocity.to_le_bytes());
    w.put(&c.torque.to_le_bytes());
}

struct Writer<'a> {
    buf: &'a mut [u8],
    at: usize,
}

impl Writer<'_> {
    fn put(&mut self, b: &[u8]) {
        self.buf[self.at..self.at + b.len()].copy_from_slice(b);
        self.at += b.len();
    }
}

/// Where the vector bytes come from, in order.
pub trait VectorSource {
    /// Fill `buf` with the next bytes; `false` when there are not that many left.
    fn fill(&mut self, buf: &mut [u8]) -> bool;
}

/// A vector file in memory.
pub struct SliceSource<'a> {
    bytes: &'a [u8],
    at: usize,
}

impl<'a> SliceSource<'a> {
    pub fn new(bytes: &'a [u8]) -> Self {
        Self { bytes, at: 0 }
    }
}

impl VectorSource for SliceSource<'_> {
    fn fill(&mut self, buf: &mut [u8]) -> bool {
        let Some(b) = self.bytes.get(self.at..self.at + buf.len()) else {
            return false;
        };
        buf.copy_from_slice(b);
        self.at += buf.len();
        true
    }
}

struct Reader<S> {
    source: S,
    at: usize,
}

impl<S: VectorSource> Reader<S> {
    fn take<const N: usize>(&mut self) -> Result<[u8; N], VectorError> {
        let mut out = [0u8; N];
        if !self.source.fill(&mut out) {
            return Err(VectorError::Truncated(self.at));
        }
        self.at += N;
        Ok(out)
    }
    fn u32(&mut self) -> Result<u32, VectorError> {
        Ok(u32::from_le_bytes(self.take()?))
    }
    fn f32(&mut self) -> Result<f32, VectorError> {
        Ok(f32::from_le_bytes(self.take()?))
    }
}

/// The most events a scenario may carry (read ahead of its ticks).
pub const MAX_EVENTS: usize = 32;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VectorError {
    Magic,
    Truncated(usize),
    Preset(u32),
    Mode(u8),
    Event(u8),
    Events(u32),
}

impl fmt::Display for VectorError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Magic => write!(f, "not a golden-vector file (magic)"),
            Self::Truncated(at) => write!(f, "golden vectors truncated at byte {at}"),
            Self::Preset(p) => write!(f, "unknown parameter preset {p}"),
            Self::Mode(m) => write!(f, "unknown mode {m}"),
            Self::Event(e) => write!(f, "unknown event kind {e}"),
            Self::Events(n) => write!(f, "{n} events in a scenario (at most {MAX_EVENTS})"),
        }
    }
}

/// FNV-1a, 64 bit.
#[derive(Clone, Copy, Debug)]
pub struct Digest(pub u64);

impl Default for Digest {
    fn default() -> Self {
        Self(0xcbf2_9ce4_8422_2325)
    }
}

impl Digest {
    pub fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 ^= x as u64;
            self.0 = self.0.wrapping_mul(0x0000_0100_0000_01B3);
        }
    }
    fn f32(&mut self, x: f32) {
        self.bytes(&x.to_bits().to_le_bytes());
    }
}

/// Replay every scenario; returns (ticks, digest). Events apply before the tick they carry.
pub fn replay(bytes: &[u8]) -> Result<(u64, u64), VectorError> {
    replay_with(SliceSource::new(bytes), Work::StepAndDigest, None).map(|(ticks, digest, _)| (ticks, digest))
}

/// [`replay`] of the bytes `source` gives.
pub fn replay_from(source: impl VectorSource) -> Result<(u64, u64), VectorError> {
    replay_with(source, Work::StepAndDigest, None).map(|(ticks, digest, _)| (ticks, digest))
}

/// A tick of a replay: what its `Axis::step` took on the replay's clock, and which tick it was
/// (counted from the first scenario's first).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct TimedTick {
    pub clocks: u64,
    pub tick: u64,
}

/// How many of a timed replay's longest ticks it keeps.
pub const LONGEST_TICKS: usize = 4;

/// [`replay_from`] with each `Axis::step` timed on `clock` (a free-running counter read before
/// and after it; the decoding, the events and the digest are not timed): ticks, digest and the
/// [`LONGEST_TICKS`] longest ticks, longest first.
pub fn replay_timed(
    source: impl VectorSource,
    clock: &mut dyn FnMut() -> u64,
) -> Result<(u64, u64, [TimedTick; LONGEST_TICKS]), VectorError> {
    replay_with(source, Work::StepAndDigest, Some(clock))
}

/// Replay without digesting the outputs (to measure what the core itself costs).
pub fn replay_only(bytes: &[u8]) -> Result<u64, VectorError> {
    replay_with(SliceSource::new(bytes), Work::Step, None).map(|(ticks, ..)| ticks)
}

/// Decode the inputs without stepping the axis (the decoding's share of the cost).
pub fn decode_only(bytes: &[u8]) -> Result<u64, VectorError> {
    replay_with(SliceSource::new(bytes), Work::Decode, None).map(|(ticks, ..)| ticks)
}

#[derive(Clone, Copy, PartialEq, Eq)]
enum Work {
    Decode,
    Step,
    StepAndDigest,
}

fn replay_with(
    source: impl VectorSource,
    work: Work,
    mut clock: Option<&mut dyn FnMut() -> u64>,
) -> Result<(u64, u64, [TimedTick; LONGEST_TICKS]), VectorError> {
    let mut longest = [TimedTick::default(); LONGEST_TICKS];
    let mut r = Reader { source, at: 0 };
    if &r.take::<4>()? != MAGIC {
        return Err(VectorError::Magic);
    }
    let scenarios = r.u32()?;
    let mut digest = Digest::default();
    let mut total = 0u64;
    for _ in 0..scenarios {
        let id = r.u32()?;
        let params = preset(id).ok_or(VectorError::Preset(id))?;
        let mut axis = Axis::new(params).map_err(|_| VectorError::Preset(id))?;
        let ticks = r.u32()?;
        let events = r.u32()?;
        if events as usize > MAX_EVENTS {
            return Err(VectorError::Events(events));
        }
        let mut scheduled = [(0u32, 0u8, 0i64); MAX_EVENTS];
        for e in scheduled.iter_mut().take(events as usize) {
            *e = (r.u32()?, r.take::<1>()?[0], i64::from_le_bytes(r.take()?));
        }
        let mut next_event = 0u32;
        for tick in 0..ticks {
            let inputs = AxisInputs {
                phase_currents: [r.f32()?, r.f32()?],
                encoder_count: i32::from_le_bytes(r.take()?),
                bus_voltage: r.f32()?,
                // Not recorded: no vector uses the machine-end acceleration measure (the loops
                // never read it).
                load_acceleration: 0.0,
            };
            let code = r.take::<1>()?[0];
            let mode = Mode::from_code(code as i32).ok_or(VectorError::Mode(code))?;
            let commands = Commands {
                mode,
                position: i64::from_le_bytes(r.take()?),
                move_speed: r.f32()?,
                jog_velocity: r.f32()?,
                velocity: r.f32()?,
                torque: r.f32()?,
            };
            axis.apply_mode(&commands);
            while next_event < events {
                let (at, kind, value) = scheduled[next_event as usize];
                if at != tick {
                    break;
                }
                // A refused event is part of the behaviour being compared, not an error.
                let result = match VectorEvent::decode(kind, value).ok_or(VectorError::Event(kind))? {
                    VectorEvent::Sequence(s) => axis.sequence_event(s).is_ok(),
                    VectorEvent::StartSweep => axis.start_sweep().is_ok(),
                    VectorEvent::StartCommissioning => {
                        axis.start_commissioning(&CommissioningSettings::for_params(axis.params())).is_ok()
                    }
                };
                digest.bytes(&[result as u8]);
                next_event += 1;
            }
            if work == Work::Decode {
                // Keep the decoded values alive so the decoding is not optimised away.
                digest.bytes(&inputs.encoder_count.to_le_bytes());
                digest.f32(inputs.phase_currents[0] + commands.velocity);
                continue;
            }
            let started = clock.as_mut().map(|c| c());
            let pwm = axis.step(&inputs, &commands);
            if let (Some(c), Some(started)) = (clock.as_mut(), started) {
                let timed = TimedTick { clocks: c().wrapping_sub(started), tick: total + tick as u64 };
                // Into its place among the longest (the shortest of them drops out).
                if let Some(at) = longest.iter().position(|t| timed.clocks > t.clocks) {
                    longest.copy_within(at..LONGEST_TICKS - 1, at + 1);
                    longest[at] = timed;
                }
            }
            if work == Work::Step {
                digest.bytes(&[pwm.enabled as u8]);
                continue;
            }
            let t = axis.telemetry();
            for d in pwm.duties {
                digest.f32(d);
            }
            digest.bytes(&[pwm.enabled as u8]);
            digest.bytes(&t.position.to_le_bytes());
            digest.bytes(&t.position_command.to_le_bytes());
            digest.bytes(&t.torque_command_sum.to_le_bytes());
            for x in [
                t.velocity_estimate,
                t.velocity_reference,
                t.following_error,
                t.torque_command,
                t.current.d,
                t.current.q,
                t.voltage.d,
                t.voltage.q,
            ] {
                digest.f32(x);
            }
            digest.bytes(&t.faults.0.to_le_bytes());
            digest.bytes(&t.sequence.deviation.to_le_bytes());
            digest.bytes(&[t.sequence.state.code() as u8, t.sweep.state.code() as u8]);
            for x in [t.sequence.speed_reference, t.sweep.last.re, t.sweep.last.im, t.sweep.sample.u, t.sweep.sample.y]
            {
                digest.f32(x);
            }
        }
        // What a commissioning measured (or why it stopped), every bit of it.
        match axis.commissioning() {
            Some(CommissioningStatus::Done(m)) => {
                for x in [
                    m.resistance,
                    m.ld,
                    m.lq,
                    m.flux_linkage,
                    m.alignment.offset,
                    m.current_kp,
                    m.current_ki,
                    m.test_current,
                ] {
                    digest.f32(x);
                }
                digest.bytes(&[m.alignment.pole_pairs as u8, m.alignment.reversed as u8]);
                digest.f32(m.current_step.bandwidth_hz);
            }
            Some(CommissioningStatus::Failed(_)) => digest.bytes(&[0xFF]),
            Some(CommissioningStatus::Running(_)) => digest.bytes(&[0xFE]),
            None => {}
        }
        total += ticks as u64;
    }
    Ok((total, digest.0, longest))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_tick_round_trips_and_bad_files_are_refused() {
        let i = AxisInputs {
            phase_currents: [1.5, -0.25],
            encoder_count: -12345,
            bus_voltage: 48.0,
            load_acceleration: 0.0,
        };
        let c = Commands {
            mode: Mode::Position,
            position: -1 << 40,
            move_speed: 3.0,
            jog_velocity: 0.0,
            velocity: 1.0,
            torque: -0.5,
        };
        let mut tick = [0u8; TICK_BYTES];
        encode_tick(&i, &c, &mut tick);
        let mut file = [0u8; 4 + 4 + 12 + TICK_BYTES];
        file[..4].copy_from_slice(MAGIC);
        file[4..8].copy_from_slice(&1u32.to_le_bytes());
        file[12..16].copy_from_slice(&1u32.to_le_bytes());
        file[20..].copy_from_slice(&tick);
        let (n, d1) = replay(&file).unwrap();
        assert_eq!(n, 1);
        // The same bytes give the same digest; one changed input bit changes it.
        assert_eq!(replay(&file).unwrap().1, d1);
        file[20] ^= 1;
        assert_ne!(replay(&file).unwrap().1, d1);
        assert_eq!(replay(&file[..30]), Err(VectorError::Truncated(28)));
        assert_eq!(replay(b"XXXX"), Err(VectorError::Magic));
        file[8..12].copy_from_slice(&9u32.to_le_bytes());
        assert_eq!(replay(&file), Err(VectorError::Preset(9)));
    }
}

#[cfg(test)]
mod all_features_tests {
    use super::*;
    use crate::phase_shifted_sweep::SweepState;

    #[test]
    fn the_all_features_preset_runs_its_sweep_in_position_mode() {
        let mut axis = Axis::new(preset(ALL_FEATURES).unwrap()).unwrap();
        let c = Commands { mode: Mode::Position, position: 1000, move_speed: 50.0, ..Default::default() };
        axis.apply_mode(&c);
        assert!(axis.start_sweep().is_ok());
        let i = AxisInputs { phase_currents: [0.0, 0.0], encoder_count: 0, bus_voltage: 48.0, load_acceleration: 0.0 };
        for _ in 0..1000 {
            axis.step(&i, &c);
        }
        assert_ne!(axis.telemetry().sweep.state, SweepState::Idle, "{:?}", axis.telemetry().sweep);
    }
}
