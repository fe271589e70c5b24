//! The control core on the target ISA: closed-loop simulations record what the core was
//! given every tick (golden vectors); the host replays them through `Axis::step` and so does
//! the firmware's `core-vectors` binary on a Cortex-M4F in QEMU (netduinoplus2). The digests
//! of every output of every tick must be equal: the core computes the same bits on both.
//!
//! Needs the firmware toolchain and QEMU; `scripts/fw` installs them (apt) on first use.

use std::path::PathBuf;
use std::process::Command;

use control_core::golden_vectors::{encode_tick, preset, replay, VectorEvent, EVENT_BYTES, MAGIC, TICK_BYTES};
use control_core::stop_sequence::SequenceEvent;
use control_core::Mode;
use host_tools::paths::workspace_root;
use servo_axis::simulation::{AxisSimulation, SimulationConfig, UserInputs};

struct Recording {
    preset: u32,
    ticks: Vec<[u8; TICK_BYTES]>,
    events: Vec<(u32, VectorEvent)>,
}

/// Run a closed loop with `inputs(t)` and events at times, recording the core's inputs.
fn record(preset_id: u32, seconds: f64, inputs: impl Fn(f64) -> UserInputs, events: &[(f64, VectorEvent)]) -> Recording {
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
fn recordings() -> Vec<Recording> {
    let seq = |e| VectorEvent::Sequence(e);
    vec![
        record(0, 0.15, |t| UserInputs { position_command: if t >= 0.01 { 1.0 } else { 0.0 }, ..inputs(Mode::Position) }, &[]),
        record(0, 0.1, |t| UserInputs { velocity_command: if t < 0.05 { 100.0 } else { -50.0 }, ..inputs(Mode::Velocity) }, &[]),
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
        record(0, 0.1, |_| UserInputs { velocity_command: 50.0, ..inputs(Mode::Velocity) }, &[(0.01, VectorEvent::StartSweep)]),
        record(2, 0.15, |t| UserInputs { position_command: (std::f64::consts::TAU * 5.0 * t).sin(), ..inputs(Mode::Position) }, &[]),
        record(3, 0.1, |t| UserInputs { position_command: 3.0 * t, ..inputs(Mode::Position) }, &[]),
    ]
}

fn encode(recs: &[Recording]) -> Vec<u8> {
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

#[test]
fn the_core_gives_the_same_bits_on_a_cortex_m4_as_on_the_host() {
    let bytes = encode(&recordings());
    assert!(bytes.len() < 960 * 1024, "{} bytes of vectors do not fit the target's flash", bytes.len());
    let (ticks, host_digest) = replay(&bytes).unwrap();
    let dir = workspace_root().join("target/fw");
    std::fs::create_dir_all(&dir).unwrap();
    let file: PathBuf = dir.join("golden-vectors.bin");
    std::fs::write(&file, &bytes).unwrap();

    let build = Command::new(workspace_root().join("scripts/fw"))
        .args(["--release", "-q"])
        .env("CORE_VECTORS_FILE", &file)
        .output()
        .expect("scripts/fw runs");
    assert!(build.status.success(), "firmware build failed:\n{}", String::from_utf8_lossy(&build.stderr));
    let elf = dir.join("thumbv7em-none-eabihf/release/core-vectors");
    let run = Command::new("timeout")
        // -icount shift=0: the virtual clock advances with the instructions executed, so the
        // SysTick count the binary prints (calibrated on a loop of known length) measures them.
        .args(["120", "qemu-system-arm", "-machine", "netduinoplus2", "-nographic", "-monitor", "none", "-serial", "none"])
        .args(["-icount", "shift=0"])
        .args(["-semihosting-config", "enable=on,target=native", "-kernel"])
        .arg(&elf)
        .output()
        .expect("qemu-system-arm runs");
    // Semihosting output goes to QEMU's stderr when stdout is not a terminal.
    let text = format!("{}{}", String::from_utf8_lossy(&run.stdout), String::from_utf8_lossy(&run.stderr));
    assert!(run.status.success(), "QEMU run failed ({}): {text}", run.status);
    let expected = format!("core-vectors ticks {ticks} digest {host_digest:016x}");
    let result = text.lines().find(|l| l.contains("digest")).unwrap_or("").trim();
    eprintln!("host:   {expected}\ntarget: {result}");
    // "core-vectors clock C core D calibration K for N instructions"
    if let Some(line) = text.lines().find(|l| l.starts_with("core-vectors clock")) {
        let w: Vec<f64> = line.split_whitespace().filter_map(|x| x.parse().ok()).collect();
        if let [clock, core, calibration, instructions] = w[..] {
            let per_tick = |c: f64| c * instructions / calibration / ticks as f64;
            eprintln!(
                "Cortex-M4 (QEMU icount, instructions per 16 kHz tick, average over the vectors): {:.0} for Axis::step (input decoding subtracted), {:.0} for the whole replay with the output digest",
                per_tick(core),
                per_tick(clock)
            );
        }
    }
    assert_eq!(result, expected, "the Cortex-M4 replay differs from the host's");
}

/// (name, address, size) of the allocated sections of a 32-bit little-endian ELF file.
fn sections(elf: &[u8]) -> Vec<(String, u32, u32)> {
    let u16_at = |o: usize| u16::from_le_bytes([elf[o], elf[o + 1]]) as usize;
    let u32_at = |o: usize| u32::from_le_bytes([elf[o], elf[o + 1], elf[o + 2], elf[o + 3]]);
    assert_eq!(&elf[..5], b"\x7fELF\x01", "a 32-bit ELF file");
    let (shoff, shentsize, shnum, shstrndx) = (u32_at(0x20) as usize, u16_at(0x2E), u16_at(0x30), u16_at(0x32));
    let header = |i: usize| shoff + i * shentsize;
    let strtab = u32_at(header(shstrndx) + 0x10) as usize;
    (0..shnum)
        .filter(|&i| u32_at(header(i) + 0x08) & 0x2 != 0) // SHF_ALLOC
        .map(|i| {
            let h = header(i);
            let name_at = strtab + u32_at(h) as usize;
            let end = elf[name_at..].iter().position(|&b| b == 0).unwrap_or(0);
            (String::from_utf8_lossy(&elf[name_at..name_at + end]).into_owned(), u32_at(h + 0x0C), u32_at(h + 0x14))
        })
        .collect()
}

#[test]
fn the_drive_firmware_builds_within_its_flash_and_ram_budget() {
    let build = Command::new(workspace_root().join("scripts/fw"))
        .args(["--release", "-q", "-p", "drive-g474"])
        .output()
        .expect("scripts/fw runs");
    assert!(build.status.success(), "firmware build failed:\n{}", String::from_utf8_lossy(&build.stderr));
    let elf = std::fs::read(workspace_root().join("target/fw/thumbv7em-none-eabihf/release/drive-g474")).unwrap();
    let s = sections(&elf);
    // Flash holds everything placed there and the initial image of .data; RAM what lives there.
    let in_flash: u32 = s.iter().filter(|(_, a, _)| (0x0800_0000..0x0900_0000).contains(a)).map(|x| x.2).sum();
    let data: u32 = s.iter().filter(|(n, _, _)| n == ".data").map(|x| x.2).sum();
    let in_ram: u32 = s.iter().filter(|(_, a, _)| (0x2000_0000..0x2010_0000).contains(a)).map(|x| x.2).sum();
    let (flash, ram) = (in_flash + data, in_ram);
    eprintln!("drive-g474: flash {flash} bytes ({:.1} KiB of 128), static RAM {ram} bytes ({:.1} KiB of 48; stack not included)", flash as f64 / 1024.0, ram as f64 / 1024.0);
    assert!(flash <= 128 * 1024, "flash {flash} bytes");
    assert!(ram <= 48 * 1024, "RAM {ram} bytes");
}
