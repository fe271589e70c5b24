//! The control core on the target ISA: closed-loop simulations record what the core was
//! given every tick (golden vectors); the host replays them through `Axis::step` and so does
//! the firmware's `core-vectors` binary on a Cortex-M4F in QEMU (netduinoplus2). The digests
//! of every output of every tick must be equal: the core computes the same bits on both.
//!
//! Needs the firmware toolchain and QEMU; `scripts/fw` installs them (apt) on first use.

use host_tools::bench::firmware::{
    all_features_recordings, build, commissioning_recording, commissioning_recordings, drive_image_size,
    drive_image_stack, encode, interrupts_off_on_cortex_m4, recordings, replay_on_cortex_m4,
    replay_streamed_on_cortex_m4, sections,
};
use host_tools::paths::workspace_root;

#[test]
fn the_core_gives_the_same_bits_on_a_cortex_m4_as_on_the_host() {
    let r = replay_on_cortex_m4(&encode(&recordings()), "golden-vectors").unwrap();
    eprintln!("golden vectors: {} ticks, host digest {}, target: {}", r.ticks, r.host_digest, r.target);
    eprintln!(
        "Cortex-M4 instructions per 16 kHz tick (QEMU -icount), average over the vectors: {:.0} (Axis::step)",
        r.instructions_per_tick.unwrap_or(f64::NAN)
    );
    assert!(r.ticks > 10_000, "{} ticks", r.ticks);
    assert!(r.identical, "the Cortex-M4 replay differs from the host's: {r:?}");
    assert!(r.instructions_per_tick.is_some_and(|x| x > 100.0), "the replay measured its cost: {r:?}");
}

#[test]
fn every_feature_on_at_once_gives_the_same_bits_too() {
    let recs = all_features_recordings();
    // The sweep really runs in these vectors (its start event is taken in position mode).
    let p = control_core::golden_vectors::preset(control_core::golden_vectors::ALL_FEATURES).unwrap();
    let mut axis = control_core::Axis::new(p).unwrap();
    axis.apply_mode(&control_core::Commands { mode: control_core::Mode::Position, ..Default::default() });
    assert!(axis.start_sweep().is_ok());
    let r = replay_on_cortex_m4(&encode(&recs), "all-features-vectors").unwrap();
    eprintln!(
        "every feature on: {} ticks identical: {}; Cortex-M4 instructions per tick {:.0} (goal 1000)",
        r.ticks,
        r.identical,
        r.instructions_per_tick.unwrap_or(f64::NAN)
    );
    assert!(r.identical, "{r:?}");
}

/// A whole commissioning (5.2 s of ticks, the default plant hiding its encoder's mounting):
/// every output of every tick and every bit of what it measured are the same on the
/// Cortex-M4, the vectors streamed from the host (3.4 MB, more than the target's flash).
#[test]
fn a_whole_commissioning_gives_the_same_bits_on_a_cortex_m4() {
    let (rec, status) = commissioning_recording().unwrap();
    // The recording covers the sequence to its end, and it succeeded (a digest of a failed or
    // unfinished sequence would compare less).
    let control_core::commissioning::CommissioningStatus::Done(m) = status else {
        panic!("the commissioning did not finish: {status:?}");
    };
    assert_eq!(m.alignment.pole_pairs, servo_axis::plant::PlantParams::default().pole_pairs);
    let bytes = encode(&[rec]);
    assert!(bytes.len() > 960 * 1024, "{} bytes: streamed, not in flash", bytes.len());
    let r = replay_streamed_on_cortex_m4(&bytes, "commissioning-vectors").unwrap();
    eprintln!(
        "commissioning vectors: {} ticks, host digest {}, target: {}, longest ticks {:?}",
        r.ticks, r.host_digest, r.target, r.longest_ticks
    );
    assert_eq!(r.ticks, 83_200);
    assert!(r.identical, "the Cortex-M4 replay differs from the host's: {r:?}");
    // A corrupt stream is told apart: the same bytes with a phase current's exponent bit
    // flipped mid-sequence (tick 40 000: after the file's header and its one event) give
    // another digest on the host (the comparison can fail).
    let mut flipped = bytes.clone();
    let header = 4 + 4 + 3 * 4 + control_core::golden_vectors::EVENT_BYTES;
    flipped[header + 40_000 * control_core::golden_vectors::TICK_BYTES + 3] ^= 0x01;
    let other = control_core::golden_vectors::replay(&flipped).map(|(_, d)| format!("{d:016x}"));
    assert_ne!(other.ok(), Some(r.host_digest.clone()));
}

/// Whole commissionings of drawn motors whose sequences take the paths the default motor's
/// does not (the q fit's noise matching on a slow winding under the sensors' noise; the
/// probe's retry, the light ramp, the q stage turning the rotor and the second differences'
/// fit on a light rotor; the shaped q chips of a winding of 1 600 ticks): the same bits on the
/// Cortex-M4, and no tick of any commissioning (the default motor's too) over 5 000
/// instructions, under half a 16 kHz tick's cycles on the G474 at 170 MHz (the stage ends'
/// fits and the noise matching's bisection spread over ticks, sines and cosines in f32 only,
/// the encoder's angle in 32-bit arithmetic: the step analysis's sines and cosines in `libm`'s
/// f64 kernels took 253 000 instructions in one tick).
#[test]
fn drawn_motors_commission_with_the_same_bits_and_no_tick_over_5000_instructions_on_a_cortex_m4() {
    for (name, rec, status) in commissioning_recordings().unwrap() {
        assert!(
            matches!(status, control_core::commissioning::CommissioningStatus::Done(_)),
            "{name}: the commissioning did not finish: {status:?}"
        );
        let r = replay_streamed_on_cortex_m4(&encode(&[rec]), "commissioning-vectors").unwrap();
        eprintln!("{name}: host digest {}, target: {}, longest ticks {:?}", r.host_digest, r.target, r.longest_ticks);
        assert!(r.identical, "{name}: the Cortex-M4 replay differs from the host's: {r:?}");
        let longest = r.longest_ticks.first().expect("the replay's longest tick");
        assert!(longest.instructions <= 5000.0, "{name}: {longest:?}");
        // Every tick timed: more than one long tick is seen (the stage ends), and none is
        // free.
        assert!(r.longest_ticks.len() == 4 && r.longest_ticks[3].instructions > 500.0, "{name}: {r:?}");
    }
}

#[test]
fn the_drive_firmware_builds_within_its_flash_and_ram_budget() {
    let size = drive_image_size().unwrap();
    eprintln!("drive-g474: flash {} bytes, static RAM {} bytes", size.flash, size.ram);
    assert!(size.flash > 16 * 1024, "an image with the core in it: {size:?}");
    assert!(size.flash <= 256 * 1024, "flash {} bytes", size.flash);
    assert!(size.ram <= 64 * 1024, "RAM {} bytes", size.ram);
}

/// The drive image's worst-case stack (read from its ELF) fits its stack and its goal (16 KiB,
/// no frame over 4 KiB: the axis is built in its slot, never on a stack), and the path it finds
/// is the boot's. The same analysis of the interrupts-off image must cover how deep that
/// program's painted stack went in QEMU (an analysis that missed frames would read below the
/// run), and that run leaves 40 KiB of RAM untouched.
#[test]
fn the_drive_images_stack_bound_fits_and_covers_a_painted_run() {
    drive_image_size().unwrap();
    let bound = drive_image_stack().unwrap();
    eprintln!("drive-g474 stack: worst path {} of {} bytes (thread {})", bound.worst, bound.stack, bound.thread.bytes);
    assert!(bound.fits(), "{bound:?}");
    let names: Vec<&str> = bound.thread.functions.iter().map(|(n, _)| n.as_str()).collect();
    assert!(names.iter().any(|n| n.contains("Drive>::install")), "{names:?}");
    assert!(bound.worst <= 16 * 1024, "{bound:?}");
    assert!(bound.thread.functions.iter().all(|(_, b)| *b <= 4 * 1024), "{:?}", bound.thread);
    assert!(!bound.handlers.is_empty(), "the interrupt handlers are counted: {bound:?}");
    let off = interrupts_off_on_cortex_m4().unwrap();
    let running = off.stack_bound.running_bound("systick");
    eprintln!("interrupts-off: the deepest the run went {} bytes, the bound {running}", off.stack_used);
    assert!(off.stack_used > 1024, "a run that used its stack: {} bytes", off.stack_used);
    assert!(off.untouched_ram >= 40 * 1024, "{} bytes untouched", off.untouched_ram);
    // The thread and the one handler that fires there (SysTick), not the whole bound.
    assert!(running < off.stack_bound.worst, "SysTick is one of several handlers: {:?}", off.stack_bound.handlers);
    assert!(running >= off.stack_used, "{running} < {}", off.stack_used);
}

/// The on-target tests (defmt-test) build for the board in CI; they run with probe-rs when a
/// board is attached (`cd fw && cargo test -p board-tests --release`).
#[test]
fn the_on_target_tests_build_with_the_defmt_test_harness() {
    build(&["--release", "-q", "-p", "board-tests", "--tests"], &[]).unwrap();
    let deps = workspace_root().join("target/fw/thumbv7em-none-eabihf/release/deps");
    let newest = std::fs::read_dir(&deps)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with("on_target-") && e.path().extension().is_none())
        .max_by_key(|e| e.metadata().and_then(|m| m.modified()).ok())
        .expect("an on_target test binary");
    let elf = std::fs::read(newest.path()).unwrap();
    let s = sections(&elf);
    assert!(
        s.iter().any(|(n, a, _)| n == ".vector_table" && *a == 0x0800_0000),
        "a Cortex-M image at the G474's flash: {s:?}"
    );
    // defmt keeps its strings in symbol names of a non-allocated .defmt section: the three
    // tests' names are there.
    assert!(elf.windows(7).any(|w| w == b".defmt\0"), "a .defmt section");
    for name in ["pwm_is_centre_aligned", "injected_conversions_come_once_per_period", "the_quadrature_counter_follows"]
    {
        assert!(elf.windows(name.len()).any(|w| w == name.as_bytes()), "test {name} in the binary");
    }
}
