//! `servo bench firmware`: the drive image and the core on a Cortex-M4.

use anyhow::Result;

use crate::bench::args::FirmwareBenchArgs;
use crate::cli::progress_bar;

/// The image's goals: half the G474's 512 KiB flash (room for a second image), half its
/// 128 KiB RAM for statics, a worst stack path of 16 KiB with no frame over 4 KiB on it, and
/// 40 KiB of RAM the painted-stack run never touches.
const FLASH_GOAL: u32 = 256 * 1024;
const RAM_GOAL: u32 = 64 * 1024;
const STACK_GOAL: u32 = 16 * 1024;
const FRAME_GOAL: u32 = 4 * 1024;
const UNTOUCHED_GOAL: u32 = 40 * 1024;
/// Instructions per tick with every feature on: the budget, and the most the tick may take
/// to leave the margin the next features need.
const TICK_GOAL: f64 = 1000.0;
const TICK_MARGIN: f64 = 100.0;
/// Longest interrupts-off section of a parameter change (issue 16 item 2).
const INTERRUPTS_OFF_GOAL: f64 = 300.0;
/// The longest tick of a commissioning: under half the 10 625 cycles of a 16 kHz tick on the
/// G474 at 170 MHz (an instruction takes a cycle at best), the rest left to the interrupt's
/// own work and the link.
const COMMISSIONING_TICK_GOAL: f64 = 5000.0;

impl FirmwareBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_firmware(self)
    }
}

fn bench_firmware(args: &FirmwareBenchArgs) -> Result<bool> {
    let common = &args.common;
    use crate::bench::firmware::{
        all_features_recordings, commissioning_recordings, drive_image_size, drive_image_stack, encode,
        interrupts_off_on_cortex_m4, recordings, replay_on_cortex_m4, replay_streamed_on_cortex_m4,
    };
    let pb = progress_bar("firmware bench", common.json);
    pb.set_position(50);
    let size = drive_image_size()?;
    let stack = drive_image_stack()?;
    pb.set_position(300);
    let vectors = replay_on_cortex_m4(&encode(&recordings()), "golden-vectors")?;
    pb.set_position(700);
    let all = replay_on_cortex_m4(&encode(&all_features_recordings()), "all-features-vectors")?;
    pb.set_position(800);
    // Whole commissionings, each streamed from the host: the default motor and drawn motors
    // whose sequences take the paths it does not.
    let mut commissionings = Vec::new();
    for (name, recording, status) in commissioning_recordings()? {
        let finished = matches!(status, control_core::commissioning::CommissioningStatus::Done(_));
        let replay = replay_streamed_on_cortex_m4(&encode(&[recording]), "commissioning-vectors")?;
        commissionings.push((name, finished, replay));
    }
    let commissioned = commissionings.iter().all(|(_, finished, _)| *finished);
    // A tick not measured (or a calibration that gives no number) fails the goal.
    let longest = |r: &crate::bench::firmware::CoreReplay| {
        r.longest_ticks.first().map(|t| t.instructions).filter(|x| x.is_finite()).unwrap_or(f64::INFINITY)
    };
    let commissioning_tick = commissionings.iter().map(|(_, _, r)| longest(r)).fold(0.0, f64::max);
    let commissioning_tick_goal = commissioning_tick <= COMMISSIONING_TICK_GOAL;
    pb.set_position(900);
    let off = interrupts_off_on_cortex_m4()?;
    pb.finish_and_clear();
    let off_goal = off.parameter_changes <= INTERRUPTS_OFF_GOAL;
    let per_tick_all = all.instructions_per_tick.unwrap_or(f64::INFINITY);
    // The analysis checked against a run: on the interrupts-off image the thread's path and
    // the handler that can fire there (SysTick, with its exception frame) must cover the
    // deepest the painted stack went (not the whole bound: its fault handlers' paths and
    // frames would leave some 370 bytes of slack for a thread's frame the analysis missed).
    let bound_holds = off.stack_bound.running_bound("systick") >= off.stack_used;
    let largest_frame = stack.thread.functions.iter().map(|(_, b)| *b).max().unwrap_or(0);
    let stack_goal = stack.worst <= STACK_GOAL && largest_frame <= FRAME_GOAL;
    let untouched_goal = off.untouched_ram >= UNTOUCHED_GOAL;
    let ok = vectors.identical
        && all.identical
        && commissionings.iter().all(|(_, _, r)| r.identical)
        && commissioned
        && commissioning_tick_goal
        && size.flash <= FLASH_GOAL
        && size.ram <= RAM_GOAL
        && stack.fits()
        && stack_goal
        && untouched_goal
        && bound_holds;
    let tick_goal = per_tick_all <= TICK_GOAL - TICK_MARGIN;
    let kib = |b: u32| b as f64 / 1024.0;
    crate::bench::figures::Recorder::new("firmware")
        .at_most("drive image: flash", kib(size.flash), kib(FLASH_GOAL), "KiB")
        .at_most("drive image: static RAM", kib(size.ram), kib(RAM_GOAL), "KiB")
        .at_most("stack, worst path from the image", stack.worst as f64, STACK_GOAL as f64, "bytes")
        .at_most("the largest frame on the thread's path", largest_frame as f64, FRAME_GOAL as f64, "bytes")
        .at_least(
            "RAM never touched in the painted-stack run (128 KiB)",
            kib(off.untouched_ram),
            kib(UNTOUCHED_GOAL),
            "KiB",
        )
        .equal(
            "golden vectors, the every-feature run and six whole commissionings, Cortex-M4 (QEMU) vs host: runs that differ",
            ([&vectors, &all].iter().filter(|r| !r.identical).count()
                + commissionings.iter().filter(|(_, _, r)| !r.identical).count()) as f64,
            0.0,
            "",
        )
        .at_most(
            "the longest tick of a commissioning (default motor and five drawn ones), instructions",
            commissioning_tick,
            COMMISSIONING_TICK_GOAL,
            "",
        )
        .at_most(
            "instructions per 16 kHz tick, every feature on (1 000 with 100 kept as margin)",
            per_tick_all,
            TICK_GOAL - TICK_MARGIN,
            "",
        )
        .at_most(
            "longest interrupts-off section during parameter changes",
            off.parameter_changes,
            INTERRUPTS_OFF_GOAL,
            "instructions",
        )
        .equal("the analysed stack bound below the painted-stack run", if bound_holds { 0.0 } else { 1.0 }, 0.0, "")
        .write(common.out.as_deref(), ok)?;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({
                "bench": "firmware", "image": size, "stack": stack, "golden_vectors": vectors, "all_features": all,
                "commissionings": commissionings.iter().map(|(name, finished, r)| serde_json::json!({"motor": name, "finished": finished, "replay": r})).collect::<Vec<_>>(),
                "commissioning_finished": commissioned, "commissioning_longest_tick": commissioning_tick,
                "commissioning_tick_goal_met": commissioning_tick_goal,
                "largest_frame": largest_frame, "stack_goal_met": stack_goal, "untouched_ram_goal_met": untouched_goal,
                "goals": {"flash": FLASH_GOAL, "static_ram": RAM_GOAL, "stack": STACK_GOAL, "frame": FRAME_GOAL,
                          "untouched_ram": UNTOUCHED_GOAL, "instructions_per_tick": TICK_GOAL - TICK_MARGIN,
                          "commissioning_longest_tick": COMMISSIONING_TICK_GOAL},
                "tick_goal_met": tick_goal, "interrupts_off": off, "stack_bound_holds": bound_holds, "interrupts_off_goal_met": off_goal, "passed": ok
            }))?
        );
        return Ok(ok);
    }
    println!(
        "servo bench firmware — drive-g474 (STM32G474RE) and the control core on a Cortex-M4F (QEMU netduinoplus2)"
    );
    let verdict = |met: bool| if met { "met" } else { "NOT met" };
    println!(
        "  drive image: flash {} bytes ({:.1} KiB, goal ≤ {:.0} KiB: {}), static RAM {} bytes ({:.1} KiB, goal ≤ {:.0} KiB: {}; stack not included)",
        size.flash,
        kib(size.flash),
        kib(FLASH_GOAL),
        verdict(size.flash <= FLASH_GOAL),
        size.ram,
        kib(size.ram),
        kib(RAM_GOAL),
        verdict(size.ram <= RAM_GOAL)
    );
    print_stack(&stack);
    println!(
        "  goal: worst stack path ≤ {:.0} KiB ({} bytes) with no frame over {:.0} KiB on the thread's path (largest {largest_frame} bytes): {}",
        kib(STACK_GOAL),
        stack.worst,
        kib(FRAME_GOAL),
        verdict(stack_goal)
    );
    for (name, r) in
        [("golden vectors (the shipped scenarios' situations)", &vectors), ("every feature on at once", &all)]
    {
        println!(
            "  {name}: {} ticks compared bit for bit, host digest {}, target: {} → {}",
            r.ticks,
            r.host_digest,
            r.target,
            if r.identical { "identical" } else { "DIFFERENT" }
        );
        println!(
            "    instructions per 16 kHz tick on the Cortex-M4 (QEMU -icount, average): {:.0} for Axis::step, {:.0} with the output digest",
            r.instructions_per_tick.unwrap_or(f64::NAN),
            r.instructions_per_tick_with_digest.unwrap_or(f64::NAN)
        );
    }
    for (name, finished, r) in &commissionings {
        println!(
            "  a whole commissioning of {name} ({} ticks, {}, streamed from the host): host digest {}, target: {} → {}",
            r.ticks,
            if *finished { "finished" } else { "NOT finished" },
            r.host_digest,
            r.target,
            if r.identical { "identical" } else { "DIFFERENT" }
        );
        let ticks: Vec<String> =
            r.longest_ticks.iter().map(|t| format!("{:.0} (tick {})", t.instructions, t.tick)).collect();
        println!("    its longest ticks on the Cortex-M4 (QEMU -icount, instructions): {}", ticks.join(", "));
    }
    println!(
        "  goal: the longest tick of a commissioning ≤ {COMMISSIONING_TICK_GOAL:.0} instructions (under half a 16 kHz tick's 10 625 cycles at 170 MHz): {} ({commissioning_tick:.0})",
        verdict(commissioning_tick_goal)
    );
    println!(
        "  goal: at most {TICK_GOAL:.0} instructions per tick with every feature on, {TICK_MARGIN:.0} of them kept as margin (≤ {:.0}): {} ({per_tick_all:.0}, {:.0} left)",
        TICK_GOAL - TICK_MARGIN,
        verdict(tick_goal),
        TICK_GOAL - per_tick_all
    );
    println!(
        "  interrupts off (drive application on a board without registers, QEMU -icount, instructions): longest during a parameter change (SetParams, LoadCorrection with 8 sections, SaveParams) {:.0}, goal ≤ {INTERRUPTS_OFF_GOAL:.0}: {}; longest over every request {:.0} ({}); the tick's own {:.0}",
        off.parameter_changes,
        if off_goal { "met" } else { "NOT met" },
        off.longest,
        off.longest_request,
        off.tick
    );
    println!(
        "  RAM never touched in the painted-stack run (the drive's install, ticks and every request, 128 KiB of RAM): {} bytes ({:.1} KiB), goal ≥ {:.0} KiB: {}",
        off.untouched_ram,
        kib(off.untouched_ram),
        kib(UNTOUCHED_GOAL),
        verdict(untouched_goal)
    );
    println!(
        "  stack bound checked on the interrupts-off run (its stack painted): the deepest it went {} bytes, the bound of its thread and SysTick {} (thread {}; every handler {}) → {}",
        off.stack_used,
        off.stack_bound.running_bound("systick"),
        off.stack_bound.thread.bytes,
        off.stack_bound.worst,
        if bound_holds { "the bound holds" } else { "the bound is BELOW the run: the analysis misses frames" }
    );
    for line in &off.requests {
        println!("    {}", line.trim_start_matches("interrupts-off request "));
    }
    Ok(ok)
}

/// The drive image's worst-case stack: the figure, the thread's path and each handler's.
fn print_stack(stack: &crate::bench::stack_depth::StackBound) {
    use crate::bench::stack_depth::EXCEPTION_FRAME_BYTES;
    println!(
        "  drive-g474 stack: worst path {} of {} bytes → {} ({} bytes left; from the ELF: the thread's deepest path, every interrupt handler's nested on it, {} bytes of exception frame each)",
        stack.worst,
        stack.stack,
        if stack.fits() { "fits" } else { "DOES NOT FIT" },
        stack.stack as i64 - stack.worst as i64,
        EXCEPTION_FRAME_BYTES
    );
    // Generic arguments inside generic arguments elided: `<A<B<C>>>::poll` reads `<A<…>>::poll`.
    let short = |name: &str| -> String {
        let (mut depth, mut out) = (0, String::new());
        for c in name.chars() {
            match c {
                '<' => {
                    depth += 1;
                    if depth <= 2 {
                        out.push('<');
                    }
                    if depth == 2 {
                        out.push('…');
                    }
                }
                '>' => {
                    if depth <= 2 {
                        out.push('>');
                    }
                    depth -= 1;
                }
                _ if depth <= 1 => out.push(c),
                _ => {}
            }
        }
        out
    };
    let frames = |p: &crate::bench::stack_depth::StackPath| -> String {
        p.functions
            .iter()
            .filter(|(_, b)| *b >= 512)
            .map(|(n, b)| format!("{} {b}", short(n)))
            .collect::<Vec<_>>()
            .join(" → ")
    };
    println!(
        "    thread (reset, main, tasks) {} bytes; frames of 512 bytes and more: {}",
        stack.thread.bytes,
        frames(&stack.thread)
    );
    for (name, p) in &stack.handlers {
        println!("    {name} {} bytes", p.bytes);
    }
    if !stack.cycles.is_empty() {
        println!(
            "    recursion cut (paths counted without repeating a function): {} group(s), {} functions",
            stack.cycles.len(),
            stack.cycles.iter().map(Vec::len).sum::<usize>()
        );
    }
}
