//! The three campaigns and their figures.

use std::cell::RefCell;
use std::fmt;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::time::Instant;

use control_core::acquisition_stream::{AcquisitionStream, SampleBatch, BATCH};
use control_core::phase_shifted_sweep::AcquisitionSample;
use control_core::protocol::{
    decode, encode, handle, DefaultsReason, DriveTelemetry, ParamsOrigin, Request, Response, MAX_FRAME, VERSION,
};
use control_core::stop_sequence::SequenceEvent;
use control_core::{Axis, AxisInputs, Commands, Mode, Params};
use fastrand::Rng;

use crate::frame_stream::{sample_rows, FrameStream};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Campaign {
    Frames,
    Requests,
    Stream,
}

impl Campaign {
    pub fn parse(s: &str) -> Option<Self> {
        match s {
            "frames" => Some(Self::Frames),
            "requests" => Some(Self::Requests),
            "stream" => Some(Self::Stream),
            _ => None,
        }
    }
    pub fn name(self) -> &'static str {
        match self {
            Self::Frames => "frames",
            Self::Requests => "requests",
            Self::Stream => "stream",
        }
    }
}

/// What one campaign found.
#[derive(Clone, Debug, Default)]
pub struct Figures {
    pub campaign: &'static str,
    pub seed: u64,
    pub overflow_checks: bool,
    /// Inputs tried (frames, requests or stream chunks).
    pub inputs: u64,
    /// Inputs that made it through the decoder (requests: and to the handler).
    pub decoded: u64,
    /// Panics of any kind, and those among them from integer overflow.
    pub crashes: u64,
    pub overflow_panics: u64,
    /// Byte-corrupted frames that decoded all the same, and those that decoded to another
    /// message than the one sent.
    pub accepted_corrupt: u64,
    pub accepted_corrupt_different: u64,
    /// requests: refusals after which the commands or parameters differed; ticks run.
    pub refusals_that_changed_state: u64,
    pub refusals: u64,
    pub ticks: u64,
    /// stream: batches whose count was above its slots and still reached the rows.
    pub bad_counts_used: u64,
    pub seconds: f64,
    /// The first few crashing inputs (hex), kept as regression tests.
    pub crash_inputs: Vec<String>,
}

impl Figures {
    pub fn goals_met(&self) -> bool {
        self.overflow_checks
            && self.crashes == 0
            && self.overflow_panics == 0
            && self.accepted_corrupt == 0
            && self.refusals_that_changed_state == 0
            && self.bad_counts_used == 0
    }

    pub fn json(&self) -> String {
        format!(
            "{{\"campaign\":\"{}\",\"seed\":{},\"overflow_checks\":{},\"inputs\":{},\"decoded\":{},\"crashes\":{},\"overflow_panics\":{},\"accepted_corrupt\":{},\"accepted_corrupt_different\":{},\"refusals\":{},\"refusals_that_changed_state\":{},\"ticks\":{},\"bad_counts_used\":{},\"seconds\":{:.2},\"crash_inputs\":[{}]}}",
            self.campaign,
            self.seed,
            self.overflow_checks,
            self.inputs,
            self.decoded,
            self.crashes,
            self.overflow_panics,
            self.accepted_corrupt,
            self.accepted_corrupt_different,
            self.refusals,
            self.refusals_that_changed_state,
            self.ticks,
            self.bad_counts_used,
            self.seconds,
            self.crash_inputs.iter().map(|h| format!("\"{h}\"")).collect::<Vec<_>>().join(",")
        )
    }
}

impl fmt::Display for Figures {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "campaign {} (seed {}, protocol version {VERSION}, overflow checks {})",
            self.campaign,
            self.seed,
            if self.overflow_checks { "on" } else { "OFF: run it with --profile robustness" }
        )?;
        writeln!(f, "  inputs tried            {}", self.inputs)?;
        writeln!(f, "  decoded                 {}", self.decoded)?;
        writeln!(f, "  crashes/panics          {}   (goal 0)", self.crashes)?;
        writeln!(f, "  overflow panics         {}   (goal 0)", self.overflow_panics)?;
        writeln!(
            f,
            "  accepted-corrupt frames {}   (goal 0; {} decoded to another message)",
            self.accepted_corrupt, self.accepted_corrupt_different
        )?;
        if self.campaign == "requests" {
            writeln!(
                f,
                "  refusals                {} ({} changed state, goal 0)",
                self.refusals, self.refusals_that_changed_state
            )?;
            writeln!(f, "  drive ticks             {}", self.ticks)?;
        }
        if self.campaign == "stream" {
            writeln!(f, "  bad counts used         {}   (goal 0)", self.bad_counts_used)?;
        }
        for h in &self.crash_inputs {
            writeln!(f, "  crash input             {h}")?;
        }
        write!(f, "  wall time               {:.1} s", self.seconds)
    }
}

thread_local! {
    static LAST_PANIC: RefCell<Option<String>> = const { RefCell::new(None) };
    static GUARDED: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// Panics inside a guarded input are recorded, not printed (the message is kept for the
/// classification); any other panic goes to the previous hook. Installed once.
fn install_quiet_hook() {
    static ONCE: std::sync::Once = std::sync::Once::new();
    ONCE.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !GUARDED.with(|g| g.get()) {
                return previous(info);
            }
            let msg = if let Some(s) = info.payload().downcast_ref::<&str>() {
                s.to_string()
            } else if let Some(s) = info.payload().downcast_ref::<String>() {
                s.clone()
            } else {
                String::from("panic")
            };
            let at = info.location().map(|l| format!(" at {}:{}", l.file(), l.line())).unwrap_or_default();
            LAST_PANIC.with(|p| *p.borrow_mut() = Some(format!("{msg}{at}")));
        }));
    });
}

fn quietly<R>(f: impl FnOnce() -> R) -> std::thread::Result<R> {
    install_quiet_hook();
    let outer = GUARDED.with(|g| g.replace(true));
    let r = catch_unwind(AssertUnwindSafe(f));
    GUARDED.with(|g| g.set(outer));
    r
}

/// Whether this build checks integer overflow (the `robustness` profile does; release does not).
pub fn overflow_checks_on() -> bool {
    quietly(|| {
        let x = std::hint::black_box(i32::MAX);
        std::hint::black_box(x + std::hint::black_box(1))
    })
    .is_err()
}

/// Run `f` on one input; count a panic and keep the input.
fn guarded<R>(fig: &mut Figures, input: &[u8], f: impl FnOnce() -> R) -> Option<R> {
    match quietly(f) {
        Ok(r) => Some(r),
        Err(_) => {
            fig.crashes += 1;
            let msg = LAST_PANIC.with(|p| p.borrow_mut().take()).unwrap_or_default();
            if msg.contains("overflow") {
                fig.overflow_panics += 1;
            }
            if fig.crash_inputs.len() < 8 {
                fig.crash_inputs.push(format!("{} ({msg})", hex(input)));
            }
            None
        }
    }
}

pub fn hex(b: &[u8]) -> String {
    b.iter().map(|x| format!("{x:02x}")).collect()
}

pub fn run(c: Campaign, seconds: f64, seed: u64) -> Figures {
    let overflow_checks = overflow_checks_on();
    let mut fig = Figures { campaign: c.name(), seed, overflow_checks, ..Default::default() };
    let started = Instant::now();
    let mut rng = Rng::with_seed(seed);
    match c {
        Campaign::Frames => frames(&mut fig, &mut rng, started, seconds),
        Campaign::Requests => requests(&mut fig, &mut rng, started, seconds),
        Campaign::Stream => stream(&mut fig, &mut rng, started, seconds),
    }
    fig.seconds = started.elapsed().as_secs_f64();
    fig
}

// ---------------------------------------------------------------------------------------
// Inputs

/// f32 values that break things: the issue's −4e30 and 3.4e38, the largest finite ones,
/// NaN and infinities, tiny and subnormal values, just beyond the ranges.
const INTERESTING_F32: [f32; 22] = [
    -4e30,
    3.4e38,
    -3.4e38,
    f32::MAX,
    f32::MIN,
    f32::NAN,
    f32::INFINITY,
    f32::NEG_INFINITY,
    1e-45,
    -1e-45,
    1e-38,
    0.0,
    -0.0,
    1.0,
    -1.0,
    100_000.0,
    100_000.01,
    -100_001.0,
    1e10,
    9.3e18,
    2.1e9,
    1e-3,
];

fn random_f32(rng: &mut Rng) -> f32 {
    match rng.u8(0..4) {
        0 => INTERESTING_F32[rng.usize(..INTERESTING_F32.len())],
        1 => f32::from_bits(rng.u32(..)),
        2 => (rng.f32() - 0.5) * 2e5,
        _ => (rng.f32() - 0.5) * 200.0,
    }
}

fn random_i64(rng: &mut Rng) -> i64 {
    match rng.u8(0..5) {
        0 => [i64::MIN, i64::MAX, i64::MIN + 1, -(1 << 53) - 1, 1 << 53, (1 << 53) + 1, 0, -1][rng.usize(..8)],
        1 => rng.i64(..),
        2 => rng.i64(-(1 << 40)..(1 << 40)),
        _ => rng.i64(-100_000..100_000),
    }
}

fn random_commands(rng: &mut Rng) -> Commands {
    let small = |rng: &mut Rng| if rng.bool() { 0.0 } else { (rng.f32() - 0.5) * 100.0 };
    let mut c = Commands {
        mode: [Mode::Torque, Mode::Velocity, Mode::Position, Mode::Sequence][rng.usize(..4)],
        position: rng.i64(-1_000_000..1_000_000),
        move_speed: small(rng),
        jog_velocity: if rng.u8(0..4) == 0 { small(rng) } else { 0.0 },
        velocity: small(rng),
        torque: small(rng) * 0.01,
    };
    // One or two set-points absurd.
    for _ in 0..rng.u8(0..3) {
        match rng.u8(0..5) {
            0 => c.position = random_i64(rng),
            1 => c.move_speed = random_f32(rng),
            2 => c.jog_velocity = random_f32(rng),
            3 => c.velocity = random_f32(rng),
            _ => c.torque = random_f32(rng),
        }
    }
    c
}

/// A request as a host might send it, valid or absurd.
fn random_request(rng: &mut Rng) -> Request {
    match rng.u8(0..16) {
        0 => Request::Hello { version: if rng.bool() { VERSION } else { rng.u16(..) } },
        1 | 2 => Request::SetParams(Params::default()),
        3..=6 => Request::SetCommands(random_commands(rng)),
        7 | 8 => Request::Sequence(match rng.u8(0..7) {
            0 => SequenceEvent::RunOn,
            1 => SequenceEvent::RunOff,
            2 => SequenceEvent::Stop,
            3 => SequenceEvent::ReleaseBlocking,
            4 => SequenceEvent::ReturnToStart,
            5 => SequenceEvent::SelectGain(rng.usize(0..10)),
            _ => SequenceEvent::MoveTo(random_i64(rng)),
        }),
        9 => Request::StartSweep,
        10 => Request::LoadCorrection(Params::default().correction),
        11 => Request::ClearFaults,
        12 => Request::GetTelemetry,
        13 => Request::SaveParams,
        _ => Request::Stream { enabled: rng.bool() },
    }
}

/// Overwrite, flip, insert or delete bytes of a postcard payload, or put an interesting f32
/// anywhere (parameters, commands: the floats are 4 little-endian bytes).
fn mutate_payload(rng: &mut Rng, p: &mut Vec<u8>) {
    for _ in 0..1 + rng.usize(0..4) {
        if p.is_empty() {
            p.push(rng.u8(..));
            continue;
        }
        let at = rng.usize(..p.len());
        match rng.u8(0..8) {
            0 | 1 if p.len() >= at + 4 => {
                let v = random_f32(rng).to_le_bytes();
                p[at..at + 4].copy_from_slice(&v);
            }
            2 => p[at] ^= 1 << rng.u8(0..8),
            3 => p[at] = rng.u8(..),
            4 => p[at] = [0x00, 0x7F, 0x80, 0xFF, 0x01][rng.usize(..5)],
            5 => p.insert(at, rng.u8(..)),
            6 => {
                p.remove(at);
            }
            _ => {
                // A varint run: 0xFF… (huge counts, lengths and integers).
                for b in p.iter_mut().skip(at).take(1 + rng.usize(0..9)) {
                    *b = 0xFF;
                }
            }
        }
    }
}

/// A frame of `payload` (postcard bytes) with a valid CRC, as `protocol::encode` builds it.
fn frame_of_payload(payload: &[u8]) -> Option<Vec<u8>> {
    if payload.len() + 4 > MAX_FRAME {
        return None;
    }
    let mut raw = payload.to_vec();
    raw.extend_from_slice(&control_core::protocol::crc32(payload).to_le_bytes());
    let mut out = vec![0u8; MAX_FRAME + 8];
    let n = cobs_encode(&raw, &mut out)?;
    out.truncate(n);
    out.push(0);
    Some(out)
}

fn cobs_encode(raw: &[u8], out: &mut [u8]) -> Option<usize> {
    cobs::try_encode(raw, out).ok()
}

/// Byte-level corruption of a whole frame (after its CRC was computed).
fn corrupt_frame(rng: &mut Rng, f: &mut Vec<u8>) {
    for _ in 0..1 + rng.usize(0..4) {
        if f.is_empty() {
            f.push(rng.u8(..));
            continue;
        }
        let at = rng.usize(..f.len());
        match rng.u8(0..11) {
            0 | 1 => f[at] ^= 1 << rng.u8(0..8),
            2 => {
                for _ in 0..2 + rng.usize(0..6) {
                    let i = rng.usize(..f.len());
                    f[i] ^= 1 << rng.u8(0..8);
                }
            }
            3 => f[at] = rng.u8(..),
            4 => f.insert(at, rng.u8(..)),
            5 => {
                f.remove(at);
            }
            6 => {
                let end = (at + 1 + rng.usize(0..8)).min(f.len());
                let chunk: Vec<u8> = f[at..end].to_vec();
                let to = rng.usize(..=f.len());
                f.splice(to..to, chunk);
            }
            7 => {
                let j = rng.usize(..f.len());
                f.swap(at, j);
            }
            8 => f.truncate(at),
            9 => {
                for _ in 0..1 + rng.usize(0..4) {
                    f.push(if rng.bool() { 0 } else { rng.u8(..) });
                }
            }
            _ => {
                let end = (at + 1 + rng.usize(0..8)).min(f.len());
                for b in &mut f[at..end] {
                    *b = rng.u8(..);
                }
            }
        }
    }
}

fn encode_vec<T: serde::Serialize>(msg: &T) -> Vec<u8> {
    let mut buf = vec![0u8; MAX_FRAME + 8];
    let n = encode(msg, &mut buf).expect("every message fits a frame");
    buf.truncate(n);
    buf
}

// ---------------------------------------------------------------------------------------
// Campaigns

fn frames(fig: &mut Figures, rng: &mut Rng, started: Instant, seconds: f64) {
    // A pool of valid frames, renewed as it goes.
    let mut pool: Vec<(Request, Vec<u8>)> = (0..64)
        .map(|_| {
            let r = random_request(rng);
            (r, encode_vec(&r))
        })
        .collect();
    let mut k = 0u64;
    while !k.is_multiple_of(4096) || started.elapsed().as_secs_f64() < seconds {
        k += 1;
        if k.is_multiple_of(1024) {
            let r = random_request(rng);
            let i = rng.usize(..pool.len());
            pool[i] = (r, encode_vec(&r));
        }
        let (original, frame) = &pool[rng.usize(..pool.len())];
        let mut f = if rng.u8(0..32) == 0 {
            (0..rng.usize(0..64)).map(|_| rng.u8(..)).collect()
        } else {
            let mut f = frame.clone();
            corrupt_frame(rng, &mut f);
            f
        };
        if f == *frame || f.is_empty() || (f.len() == frame.len() - 1 && f[..] == frame[..frame.len() - 1]) {
            continue; // not corrupt (unchanged, or only the terminator gone)
        }
        fig.inputs += 1;
        let input = f.clone();
        if let Some(Ok(got)) = guarded(fig, &input, || decode::<Request>(&mut f)) {
            fig.decoded += 1;
            fig.accepted_corrupt += 1;
            if got != *original {
                fig.accepted_corrupt_different += 1;
            }
            if fig.crash_inputs.len() < 8 {
                fig.crash_inputs.push(format!("{} (accepted corrupt frame)", hex(&input)));
            }
        }
    }
}

/// A fresh drive as the firmware installs it (the core's defaults), in a random mode.
struct Drive {
    axis: Axis,
    commands: Commands,
    stream: AcquisitionStream,
    encoder: i32,
}

impl Drive {
    fn new() -> Self {
        Self {
            axis: Axis::new(Params::default()).unwrap(),
            commands: Commands::default(),
            stream: AcquisitionStream::default(),
            encoder: 0,
        }
    }
}

/// Commands and parameters bit for bit (a NaN in an unused gain-table entry is equal to itself
/// here, as it is not under `PartialEq`).
fn state_bits(d: &Drive) -> Vec<u8> {
    postcard::to_allocvec(&(d.commands, *d.axis.params())).unwrap()
}

fn requests(fig: &mut Figures, rng: &mut Rng, started: Instant, seconds: f64) {
    let mut drive = Drive::new();
    let mut k = 0u64;
    while !k.is_multiple_of(64) || started.elapsed().as_secs_f64() < seconds {
        k += 1;
        if k.is_multiple_of(512) {
            drive = Drive::new();
        }
        let request = random_request(rng);
        // Valid frame, payload mutated under a valid CRC (reaches the handler), or a
        // byte-corrupted frame (stops at the decoder unless the CRC is fooled).
        let mut frame = match rng.u8(0..8) {
            0..=1 => encode_vec(&request),
            2..=6 => {
                let mut p = postcard::to_allocvec(&request).unwrap();
                mutate_payload(rng, &mut p);
                match frame_of_payload(&p) {
                    Some(f) => f,
                    None => continue,
                }
            }
            _ => {
                let mut f = encode_vec(&request);
                corrupt_frame(rng, &mut f);
                f
            }
        };
        fig.inputs += 1;
        let input = frame.clone();
        let before = state_bits(&drive);
        let d = &mut drive;
        let ticks = 1 + rng.usize(0..48);
        let jitter: i32 = rng.i32(-3..=3);
        let jump = rng.u8(0..64) == 0;
        // Now and then the set-points go straight to the loop, unchecked (the FMU's way in).
        let direct = (rng.u8(0..8) == 0).then(|| random_commands(rng));
        let outcome = guarded(fig, &input, move || {
            let answer = match decode::<Request>(&mut frame) {
                Ok(r) => Some(handle(&mut d.axis, &mut d.commands, &mut d.stream, r)),
                Err(_) => None,
            };
            // The loop runs on: sensors of an axis at rest (or an encoder jump now and then).
            for t in 0..ticks {
                d.encoder = d.encoder.wrapping_add(if jump && t == 0 { i32::MAX / 3 } else { jitter });
                let inputs = AxisInputs {
                    phase_currents: [0.01, -0.02],
                    encoder_count: d.encoder,
                    bus_voltage: 48.0,
                    load_acceleration: 0.0,
                };
                d.axis.step(&inputs, direct.as_ref().unwrap_or(&d.commands));
                let _ = d.stream.take_batch();
            }
            answer
        });
        match outcome {
            Some(Some(Response::Refused(_))) => {
                fig.decoded += 1;
                fig.refusals += 1;
                if state_bits(&drive) != before {
                    fig.refusals_that_changed_state += 1;
                    if fig.crash_inputs.len() < 8 {
                        fig.crash_inputs.push(format!("{} (refusal changed state)", hex(&input)));
                    }
                }
            }
            Some(Some(_)) => fig.decoded += 1,
            Some(None) => {}
            None => drive = Drive::new(),
        }
        fig.ticks += ticks as u64;
    }
}

/// Where a sample batch's count sits in its postcard payload (see `stream`).
const SAMPLE_COUNT_AT: usize = 2;

/// A stream of the drive's responses: sample batches (counts 0 to 16, sometimes absurd
/// under a valid CRC), telemetry and answers.
fn random_response(rng: &mut Rng, tick: &mut u64) -> Response {
    match rng.u8(0..8) {
        0..=4 => {
            let mut b = SampleBatch { count: rng.u8(0..=BATCH as u8), dropped: rng.u32(0..10), ..Default::default() };
            for s in &mut b.samples[..b.count as usize] {
                *s = AcquisitionSample {
                    tick: *tick,
                    u: rng.f32(),
                    y: rng.f32(),
                    phase: rng.f32() * std::f32::consts::TAU,
                    measuring: rng.bool(),
                    limited: rng.bool(),
                    point: rng.u32(0..128),
                    segment: AcquisitionSample::segment_of(rng.u32(0..16), rng.u32(0..32)),
                };
                *tick += 4;
            }
            Response::Samples(b)
        }
        5 => Response::Telemetry(DriveTelemetry {
            params_record: rng.bool().then(|| rng.u32(..)),
            stack_free_bytes: rng.bool().then(|| rng.u32(..)),
            ..Default::default()
        }),
        6 if rng.bool() => Response::Saved { sequence: rng.u32(..) },
        6 => Response::Done,
        _ => Response::Hello {
            version: VERSION,
            boot_params: match rng.u8(0..4) {
                0 => ParamsOrigin::Stored { sequence: rng.u32(..) },
                1 => ParamsOrigin::Defaults(DefaultsReason::Corrupt),
                2 => ParamsOrigin::Defaults(DefaultsReason::Foreign { format: rng.u16(..) }),
                _ => ParamsOrigin::Defaults(DefaultsReason::NothingStored),
            },
        },
    }
}

fn stream(fig: &mut Figures, rng: &mut Rng, started: Instant, seconds: f64) {
    let mut tick = 0u64;
    let mut k = 0u64;
    while !k.is_multiple_of(64) || started.elapsed().as_secs_f64() < seconds {
        k += 1;
        // One stretch of traffic: a few frames, some with mutated payloads under a valid
        // CRC (absurd counts), some byte-corrupted, random garbage between them.
        let mut bytes = Vec::new();
        let mut corrupted = 0usize;
        for _ in 0..1 + rng.usize(0..6) {
            let r = random_response(rng, &mut tick);
            match rng.u8(0..8) {
                0 | 1 => {
                    let mut p = postcard::to_allocvec(&r).unwrap();
                    if let Response::Samples(_) = r {
                        // The samples' count is the third byte: the variant (5), `dropped` (one
                        // byte below 128), then the count, a one-byte varint up to 127.
                        if rng.bool() && p.len() > 2 {
                            p[SAMPLE_COUNT_AT] = rng.u8(17..=127);
                        } else {
                            mutate_payload(rng, &mut p);
                        }
                    } else {
                        mutate_payload(rng, &mut p);
                    }
                    if let Some(f) = frame_of_payload(&p) {
                        bytes.extend_from_slice(&f);
                    }
                }
                2 => {
                    let mut f = encode_vec(&r);
                    corrupt_frame(rng, &mut f);
                    corrupted += 1;
                    bytes.extend_from_slice(&f);
                }
                3 => bytes.extend((0..rng.usize(0..40)).map(|_| rng.u8(..))),
                _ => bytes.extend_from_slice(&encode_vec(&r)),
            }
        }
        fig.inputs += 1;
        let input = bytes.clone();
        let chunks: Vec<usize> = (0..8).map(|_| 1 + rng.usize(0..300)).collect();
        let result = guarded(fig, &input, move || {
            let mut s = FrameStream::default();
            let (mut batches, mut decoded, mut bad_counts) = (Vec::new(), 0u64, 0u64);
            let mut at = 0;
            let mut c = 0;
            while at < bytes.len() {
                let n = chunks[c % chunks.len()].min(bytes.len() - at);
                c += 1;
                s.push(&bytes[at..at + n]);
                at += n;
                while let Some(frame) = s.next_frame() {
                    if let Ok(r) = frame {
                        decoded += 1;
                        if let Response::Samples(b) = r {
                            bad_counts += (b.count as usize > BATCH) as u64;
                            batches.push(b);
                        }
                    }
                }
            }
            let rows = sample_rows(&batches);
            (decoded, bad_counts, rows.map(|r| r.len()).unwrap_or(0))
        });
        if let Some((decoded, bad_counts, _rows)) = result {
            fig.decoded += decoded;
            fig.bad_counts_used += bad_counts;
        }
        let _ = corrupted;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The campaigns' own framing of raw payloads is the protocol's: a frame built by hand
    /// decodes to the message, and equals what `encode` gives.
    #[test]
    fn frames_and_payload_frames_agree() {
        let mut rng = Rng::with_seed(1);
        for _ in 0..2000 {
            let r = random_request(&mut rng);
            let p = postcard::to_allocvec(&r).unwrap();
            let f = frame_of_payload(&p).unwrap();
            assert_eq!(f, encode_vec(&r));
            // Compared as bytes: a NaN set-point is not equal to itself.
            let back = decode::<Request>(&mut f.clone()).unwrap();
            assert_eq!(postcard::to_allocvec(&back).unwrap(), p);
        }
    }

    /// The stream campaign's count mutation hits the count: a batch whose count byte says 17
    /// to 127 under a valid CRC is refused, the same batch as sent decodes.
    #[test]
    fn the_count_mutation_reaches_the_samples_count() {
        let mut rng = Rng::with_seed(3);
        let mut tick = 0;
        let mut tried = 0;
        while tried < 200 {
            let r = random_response(&mut rng, &mut tick);
            let Response::Samples(b) = r else { continue };
            tried += 1;
            let mut p = postcard::to_allocvec(&r).unwrap();
            assert_eq!(p[SAMPLE_COUNT_AT], b.count, "{p:?}");
            assert!(decode::<Response>(&mut frame_of_payload(&p).unwrap()).is_ok());
            p[SAMPLE_COUNT_AT] = rng.u8(17..=127);
            assert!(decode::<Response>(&mut frame_of_payload(&p).unwrap()).is_err(), "{p:?}");
        }
    }

    /// A short run of each campaign meets every goal (the full runs: `servo bench robustness`).
    #[test]
    fn short_campaigns_meet_their_goals() {
        for c in [Campaign::Frames, Campaign::Requests, Campaign::Stream] {
            let f = run(c, 0.5, 18);
            assert!(f.inputs > 100, "{f}");
            assert_eq!(
                (f.crashes, f.overflow_panics, f.accepted_corrupt, f.refusals_that_changed_state, f.bad_counts_used),
                (0, 0, 0, 0, 0),
                "{f}"
            );
        }
    }

    /// The guard counts a panic and classifies an overflow, so a campaign can fail.
    #[test]
    fn the_guard_sees_panics_and_overflows() {
        let mut f = Figures::default();
        guarded(&mut f, &[1], || panic!("boom"));
        let x = std::hint::black_box(i64::MAX);
        guarded(&mut f, &[2], || {
            if overflow_checks_on_quiet() {
                std::hint::black_box(x + std::hint::black_box(1))
            } else {
                panic!("attempt to add with overflow (simulated: this build has no overflow checks)")
            }
        });
        assert_eq!((f.crashes, f.overflow_panics), (2, 1));
    }

    fn overflow_checks_on_quiet() -> bool {
        overflow_checks_on()
    }
}
