//! The firmware's figures (issue 8), shared by `servo bench firmware` and the tests: golden
//! vectors recorded from closed-loop simulations and replayed bit for bit on a Cortex-M4F in
//! QEMU (netduinoplus2, `-icount shift=0`: the virtual clock counts instructions, so the
//! SysTick count the replay prints, calibrated on a loop of known length, gives instructions
//! — not cycles: QEMU does not model the M4's pipeline or flash wait states); the drive
//! image's flash and RAM use. Needs the firmware toolchain and QEMU; `scripts/fw` installs
//! them (apt) on first use.

use std::path::{Path, PathBuf};
use std::process::Command;

use anyhow::{bail, Context, Result};
use control_core::commissioning::{CommissioningSettings, CommissioningStatus};
use control_core::golden_vectors::{
    encode_tick, preset, replay, VectorEvent, ALL_FEATURES, EVENT_BYTES, MAGIC, TICK_BYTES,
};
use control_core::stop_sequence::SequenceEvent;
use control_core::Mode;
use serde::Serialize;
use servo_axis::plant::PlantParams;
use servo_axis::simulation::{AxisSimulation, SimulationConfig, UserInputs};

use crate::bench::elf_sections::{section_headers, ALLOC};
use crate::bench::stack_depth::{stack_bound, StackBound, CORE_VECTORS_IMAGE, DRIVE_IMAGE};
use crate::paths::workspace_root;

pub struct Recording {
    preset: u32,
    ticks: Vec<[u8; TICK_BYTES]>,
    events: Vec<(u32, VectorEvent)>,
}

/// Run a closed loop with `inputs(t)` and events at times, recording the core's inputs.
pub fn record(
    preset_id: u32,
    seconds: f64,
    inputs: impl Fn(f64) -> UserInputs,
    events: &[(f64, VectorEvent)],
) -> Recording {
    let config = SimulationConfig { control: preset(preset_id).unwrap(), ..Default::default() };
    let mut sim = AxisSimulation::new(&config).unwrap();
    let n = (seconds / sim.tick_period()).round() as u32;
    let mut rec = Recording { preset: preset_id, ticks: Vec::new(), events: Vec::new() };
    for k in 0..n {
        let t = k as f64 * sim.tick_period();
        let u = inputs(t);
        sim.apply_mode(&u);
        for (at, e) in events {
            if (at / sim.tick_period()).round() as u32 == k {
                rec.events.push((k, *e));
                let _ = match e {
                    VectorEvent::Sequence(s) => sim.axis.sequence_event(*s).is_ok(),
                    VectorEvent::StartSweep => sim.axis.start_sweep().is_ok(),
                    VectorEvent::StartCommissioning => {
                        let settings = CommissioningSettings::for_params(sim.axis.params());
                        sim.axis.start_commissioning(&settings).is_ok()
                    }
                };
            }
        }
        let (i, c) = sim.tick_traced(&u);
        let mut bytes = [0u8; TICK_BYTES];
        encode_tick(&i, &c, &mut bytes);
        rec.ticks.push(bytes);
    }
    rec
}

fn inputs(mode: Mode) -> UserInputs {
    UserInputs { mode, ..Default::default() }
}

/// The shipped scenarios' situations, and the features they do not cover, kept under the
/// 1 MB of the target's flash.
pub fn recordings() -> Vec<Recording> {
    let seq = |e| VectorEvent::Sequence(e);
    vec![
        record(
            0,
            0.15,
            |t| UserInputs { position_command: if t >= 0.01 { 1.0 } else { 0.0 }, ..inputs(Mode::Position) },
            &[],
        ),
        record(
            0,
            0.1,
            |t| UserInputs { velocity_command: if t < 0.05 { 100.0 } else { -50.0 }, ..inputs(Mode::Velocity) },
            &[],
        ),
        record(1, 0.2, |_| UserInputs { position_command: 2.0, move_speed: 50.0, ..inputs(Mode::Position) }, &[]),
        record(
            0,
            0.5,
            |_| UserInputs { position_command: 0.0, ..inputs(Mode::Sequence) },
            &[
                (0.0, seq(SequenceEvent::RunOn)),
                (0.05, seq(SequenceEvent::RunOff)),
                (0.05, seq(SequenceEvent::Stop)),
                (0.2, seq(SequenceEvent::ReleaseBlocking)),
                (0.2, seq(SequenceEvent::MoveTo(800_000))),
                (0.3, seq(SequenceEvent::SelectGain(3))),
                (0.35, seq(SequenceEvent::ReturnToStart)),
                (0.4, seq(SequenceEvent::SelectGain(9))),
            ],
        ),
        record(
            0,
            0.1,
            |_| UserInputs { velocity_command: 50.0, ..inputs(Mode::Velocity) },
            &[(0.01, VectorEvent::StartSweep)],
        ),
        record(
            2,
            0.15,
            |t| UserInputs { position_command: (std::f64::consts::TAU * 5.0 * t).sin(), ..inputs(Mode::Position) },
            &[],
        ),
        record(3, 0.1, |t| UserInputs { position_command: 3.0 * t, ..inputs(Mode::Position) }, &[]),
    ]
}

pub fn encode(recs: &[Recording]) -> Vec<u8> {
    let mut out = MAGIC.to_vec();
    out.extend((recs.len() as u32).to_le_bytes());
    for r in recs {
        out.extend(r.preset.to_le_bytes());
        out.extend((r.ticks.len() as u32).to_le_bytes());
        out.extend((r.events.len() as u32).to_le_bytes());
        for (tick, e) in &r.events {
            let (kind, value) = e.encode();
            let start = out.len();
            out.extend(tick.to_le_bytes());
            out.push(kind);
            out.extend(value.to_le_bytes());
            assert_eq!(out.len() - start, EVENT_BYTES);
        }
        for t in &r.ticks {
            out.extend(t);
        }
    }
    out
}

/// (name, address, size) of the allocated sections of a 32-bit little-endian ELF file (none
/// when it is not one).
pub fn sections(elf: &[u8]) -> Vec<(String, u32, u32)> {
    section_headers(elf).into_iter().filter(|s| s.flags & ALLOC != 0).map(|s| (s.name, s.address, s.size)).collect()
}

/// Every feature on at once: a position move and a streamed sine through the 6th-order
/// acc/dec and eight correction sections, friction compensation, torque filters, and a
/// sweep injecting on the torque.
pub fn all_features_recordings() -> Vec<Recording> {
    vec![
        record(
            ALL_FEATURES,
            0.1,
            |_| UserInputs { position_command: 2.0, move_speed: 50.0, ..inputs(Mode::Position) },
            &[(0.0, VectorEvent::StartSweep)],
        ),
        record(
            ALL_FEATURES,
            0.1,
            |t| UserInputs { position_command: (std::f64::consts::TAU * 5.0 * t).sin(), ..inputs(Mode::Position) },
            &[(0.0, VectorEvent::StartSweep)],
        ),
    ]
}

/// A whole commissioning of the default motor on the default plant (the encoder's mounting,
/// the sensors' errors and the dead time hidden in it), from its start to a little after its
/// end, and how it ended on the host: about 3 MB of vectors, streamed to the target
/// ([`replay_streamed_on_cortex_m4`]).
pub fn commissioning_recording() -> Result<(Recording, CommissioningStatus)> {
    commissioning_recording_on(&PlantParams::default())
}

/// Drawn motors of `servo bench commission` (seed, motor) whose commissioning takes the paths
/// the default motor does not: seed 17's motor 65 (a slow winding under the sensors' noise:
/// the q fit's noise matching), seed 20's motor 65 (a light rotor on a winding faster than a
/// tick: the probe run again a quarter turn on, the light ramp, the q stage run again turning
/// the rotor, the second differences' fit), seed 27's motor 14 (a winding of 1 600 ticks: the
/// q chips shaped), seed 23's motor 82 (a heavy rotor on a weak magnet that its winding barely
/// damps: the first hold's current weakened at the swing's turning points), seed 36's motor
/// 46 (a light rotor on a 0.7-tick winding: the q stage run again turning the rotor where its
/// two fits disagree).
pub const COMMISSIONED_BENCH_MOTORS: [(u64, usize); 5] = [(17, 65), (20, 65), (27, 14), (23, 82), (36, 46)];

/// [`commissioning_recording`] on the default plant and on each of
/// [`COMMISSIONED_BENCH_MOTORS`]: a name for each, its recording and how it ended.
pub fn commissioning_recordings() -> Result<Vec<(String, Recording, CommissioningStatus)>> {
    let mut out = Vec::new();
    let (rec, status) = commissioning_recording()?;
    out.push(("the default motor".to_string(), rec, status));
    for (seed, motor) in COMMISSIONED_BENCH_MOTORS {
        let plant = crate::bench::commission_bench::drawn_motor(seed, motor);
        let (rec, status) = commissioning_recording_on(&plant)?;
        out.push((format!("seed {seed}'s motor {motor} of servo bench commission"), rec, status));
    }
    Ok(out)
}

/// [`commissioning_recording`] on `plant` (its encoder's counts per revolution the preset's).
pub fn commissioning_recording_on(plant: &PlantParams) -> Result<(Recording, CommissioningStatus)> {
    const SECONDS: f64 = 5.2;
    let control = preset(0).unwrap();
    let plant = PlantParams { encoder_counts_per_rev: control.encoder_counts_per_rev, ..*plant };
    let config = SimulationConfig { control, plant, ..Default::default() };
    let mut sim = AxisSimulation::new(&config).map_err(|e| anyhow::anyhow!("{e}"))?;
    let rest = inputs(Mode::Torque);
    sim.apply_mode(&rest);
    let settings = CommissioningSettings::for_params(sim.axis.params());
    sim.axis.start_commissioning(&settings).map_err(|e| anyhow::anyhow!("{e:?}"))?;
    let mut rec = Recording { preset: 0, ticks: Vec::new(), events: vec![(0, VectorEvent::StartCommissioning)] };
    for _ in 0..(SECONDS / sim.tick_period()).round() as u32 {
        let (i, c) = sim.tick_traced(&rest);
        let mut bytes = [0u8; TICK_BYTES];
        encode_tick(&i, &c, &mut bytes);
        rec.ticks.push(bytes);
    }
    let status = sim.axis.commissioning().context("no commissioning")?;
    Ok((rec, status))
}

/// Run `scripts/fw` with these cargo arguments (and environment).
pub fn build(args: &[&str], env: &[(&str, &Path)]) -> Result<()> {
    let mut cmd = Command::new(workspace_root().join("scripts/fw"));
    cmd.args(args);
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().context("cannot run scripts/fw")?;
    if !out.status.success() {
        bail!("firmware build ({}) failed:\n{}", args.join(" "), String::from_utf8_lossy(&out.stderr));
    }
    Ok(())
}

/// One replay of a vector set on both sides.
#[derive(Clone, Debug, Serialize)]
pub struct CoreReplay {
    pub ticks: u64,
    pub host_digest: String,
    /// The target's line, `core-vectors ticks N digest D`.
    pub target: String,
    pub identical: bool,
    /// Instructions per tick for `Axis::step` (input decoding subtracted) and for the whole
    /// replay with the output digest.
    pub instructions_per_tick: Option<f64>,
    pub instructions_per_tick_with_digest: Option<f64>,
    /// The streamed replay's longest ticks, longest first: each one's index and the
    /// instructions `Axis::step` took on it (empty for a replay from flash).
    pub longest_ticks: Vec<LongTick>,
}

/// A long tick of a streamed replay on the Cortex-M4.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct LongTick {
    pub tick: u64,
    pub instructions: f64,
}

/// One vector file is built into the binary at a time: callers in parallel (tests) take turns
/// from the build to the end of the run.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// Replay `bytes` on the host and on the Cortex-M4 in QEMU (`name` keeps the files apart).
pub fn replay_on_cortex_m4(bytes: &[u8], name: &str) -> Result<CoreReplay> {
    if bytes.len() >= 960 * 1024 {
        bail!("{} bytes of vectors do not fit the target's flash", bytes.len());
    }
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let file = vector_file(bytes, name)?;
    build(&["--release", "-q", "-p", "core-vectors"], &[("CORE_VECTORS_FILE", &file)])?;
    run_replay(bytes)
}

/// [`replay_on_cortex_m4`] for a vector file larger than the target's flash: the target reads
/// it from the host through semihosting as it replays (the digest and the longest tick, each
/// tick's step timed apart from the reading).
pub fn replay_streamed_on_cortex_m4(bytes: &[u8], name: &str) -> Result<CoreReplay> {
    let _turn = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let file = vector_file(bytes, name)?;
    // The binary's built-in vectors: none (a file of no scenarios).
    let empty = vector_file(&encode(&[]), "no-vectors")?;
    build(
        &["--release", "-q", "-p", "core-vectors"],
        &[("CORE_VECTORS_FILE", &empty), ("CORE_VECTORS_STREAM", &file)],
    )?;
    // (The next embedded replay builds without the stream: its variable is unset there.)
    run_replay(bytes)
}

/// `bytes` written to `target/fw/<name>.bin` (its absolute path).
fn vector_file(bytes: &[u8], name: &str) -> Result<PathBuf> {
    let dir = workspace_root().join("target/fw");
    std::fs::create_dir_all(&dir)?;
    let file: PathBuf = dir.join(format!("{name}.bin"));
    std::fs::write(&file, bytes)?;
    Ok(std::path::absolute(&file)?)
}

/// The host's replay of `bytes`, and the core-vectors binary just built run in QEMU.
fn run_replay(bytes: &[u8]) -> Result<CoreReplay> {
    let (ticks, digest) = replay(bytes).map_err(|e| anyhow::anyhow!("host replay: {e}"))?;
    let dir = workspace_root().join("target/fw");
    let elf = dir.join("thumbv7em-none-eabihf/release/core-vectors");
    let run = Command::new("timeout")
        .args([
            "300",
            "qemu-system-arm",
            "-machine",
            "netduinoplus2",
            "-nographic",
            "-monitor",
            "none",
            "-serial",
            "none",
        ])
        .args(["-icount", "shift=0"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(&elf)
        .output()
        .context("cannot run qemu-system-arm (scripts/fw installs it)")?;
    // Semihosting output goes to QEMU's stderr when stdout is not a terminal.
    let text = format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    if !run.status.success() {
        bail!("QEMU run failed ({}): {text}", run.status);
    }
    let expected = format!("core-vectors ticks {ticks} digest {digest:016x}");
    let target = text.lines().find(|l| l.contains("digest")).unwrap_or("").trim().to_string();
    let (mut core, mut whole, mut longest_ticks) = (None, None, Vec::new());
    let numbers = |line: &str| -> Vec<f64> { line.split_whitespace().filter_map(|x| x.parse().ok()).collect() };
    for line in text.lines().filter(|l| l.contains("calibration")) {
        match numbers(line)[..] {
            [tick, clocks, calibration, instructions] if line.contains("longest tick") => {
                longest_ticks.push(LongTick { tick: tick as u64, instructions: clocks * instructions / calibration });
            }
            [clock, core_clocks, calibration, instructions] => {
                let per_tick = |c: f64| c * instructions / calibration / ticks as f64;
                core = Some(per_tick(core_clocks));
                whole = Some(per_tick(clock));
            }
            _ => {}
        }
    }
    Ok(CoreReplay {
        ticks,
        host_digest: format!("{digest:016x}"),
        identical: target == expected,
        target,
        instructions_per_tick: core,
        instructions_per_tick_with_digest: whole,
        longest_ticks,
    })
}

/// Flash and static RAM of the drive image (bytes).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ImageSize {
    pub flash: u32,
    pub ram: u32,
}

pub fn drive_image_size() -> Result<ImageSize> {
    build(&["--release", "-q", "-p", "drive-g474"], &[])?;
    let elf = std::fs::read(workspace_root().join("target/fw/thumbv7em-none-eabihf/release/drive-g474"))?;
    let s = sections(&elf);
    // Flash holds everything placed there and the initial image of .data; RAM what lives there.
    let in_flash: u32 = s.iter().filter(|(_, a, _)| (0x0800_0000..0x0900_0000).contains(a)).map(|x| x.2).sum();
    let data: u32 = s.iter().filter(|(n, _, _)| n == ".data").map(|x| x.2).sum();
    let in_ram: u32 = s.iter().filter(|(_, a, _)| (0x2000_0000..0x2010_0000).contains(a)).map(|x| x.2).sum();
    Ok(ImageSize { flash: in_flash + data, ram: in_ram })
}

/// The drive image's worst-case stack, read from the image `drive_image_size` built.
pub fn drive_image_stack() -> Result<StackBound> {
    stack_bound(&workspace_root().join("target/fw/thumbv7em-none-eabihf/release/drive-g474"), DRIVE_IMAGE)
}

/// The drive application's critical sections on the Cortex-M4 (QEMU, instructions): the
/// longest during a parameter change (SetParams, LoadCorrection, SaveParams), the longest
/// over every request and which, the tick's own section; and the RAM the run never touched.
#[derive(Clone, Debug, Serialize)]
pub struct InterruptsOff {
    pub parameter_changes: f64,
    pub longest: f64,
    pub longest_request: String,
    pub tick: f64,
    /// The deepest the run's stack went (bytes, from its paint), and the bound the image's
    /// analysis gives (`stack_depth`): a bound below the measured depth would be wrong.
    pub stack_used: u32,
    /// Bytes of the RAM (128 KiB, as the G474's) the run never touched: the paint left
    /// between the end of the statics and the deepest the stack went.
    pub untouched_ram: u32,
    pub stack_bound: StackBound,
    /// The program's line per request.
    pub requests: Vec<String>,
}

pub fn interrupts_off_on_cortex_m4() -> Result<InterruptsOff> {
    build(&["--release", "-q", "-p", "core-vectors", "--bin", "interrupts-off"], &[])?;
    let elf = workspace_root().join("target/fw/thumbv7em-none-eabihf/release/interrupts-off");
    let run = Command::new("timeout")
        .args(["300", "qemu-system-arm", "-machine", "netduinoplus2", "-nographic", "-monitor", "none"])
        .args(["-serial", "none", "-icount", "shift=0", "-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(&elf)
        .output()
        .context("cannot run qemu-system-arm (scripts/fw installs it)")?;
    let text = format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    if !run.status.success() {
        bail!("QEMU run of interrupts-off failed ({}): {text}", run.status);
    }
    let Some(summary) = text.lines().find(|l| l.starts_with("interrupts-off summary")) else {
        bail!("interrupts-off printed no summary: {text}");
    };
    // The stack paint below the statics: none left means the stack ran into them (the
    // section lengths read from statics it overwrote are then meaningless).
    let free_stack = text
        .lines()
        .find_map(|l| l.strip_prefix("stack: ")?.split_whitespace().next()?.parse::<u32>().ok())
        .with_context(|| format!("interrupts-off printed no stack figure: {text}"))?;
    if free_stack == 0 {
        bail!("interrupts-off: the stack overflowed into .bss (0 bytes free); its figures are not valid:\n{text}");
    }
    let bound = stack_bound(&elf, CORE_VECTORS_IMAGE)?;
    let w: Vec<&str> = summary.split_whitespace().collect();
    let number = |key: &str| -> Result<f64> {
        let at = w.iter().position(|x| *x == key).with_context(|| format!("no {key} in {summary}"))?;
        w.get(at + 1).and_then(|v| v.parse().ok()).with_context(|| format!("no number after {key} in {summary}"))
    };
    let longest_at = w.iter().position(|x| *x == "longest").context("no longest")?;
    Ok(InterruptsOff {
        parameter_changes: number("changes")?,
        longest: number("longest")?,
        longest_request: w.get(longest_at + 2).unwrap_or(&"?").to_string(),
        tick: number("tick")?,
        stack_used: bound.stack - free_stack,
        untouched_ram: free_stack,
        stack_bound: bound,
        requests: text.lines().filter(|l| l.starts_with("interrupts-off request")).map(String::from).collect(),
    })
}
