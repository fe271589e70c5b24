//! The drive application's critical sections on a Cortex-M4F (issue 16 item 2): the drive
//! (`drive-application`) on a board without registers (a power stage at rest, RAM flash),
//! its tick and its link side taking turns, every request of the protocol carried out,
//! parameter sets and corrections swapped in. The critical section is this binary's own
//! (`critical-section`): interrupts off as on the G474 (`cortex-m`'s single-core one), and
//! the SysTick counter read at entry and exit. Prints, over semihosting, the longest section
//! the link side held, per request, in instructions (QEMU `-icount`: the clock counts
//! instructions; the cost of the reads themselves, measured on empty sections, subtracted),
//! and the stack the run left untouched (painted at the start, read at the end).

#![no_std]
#![no_main]

use control_core::current_sensing::SensingScales;
use control_core::golden_vectors::{preset, ALL_FEATURES};
use control_core::params::Params;
use control_core::protocol::{Request, Response, VERSION};
use control_core::stop_sequence::SequenceEvent;
use control_core::{Commands, Mode};
use core_vectors::semihosting::print;
use core_vectors::{clock, semihosting};
use drive_application::board::{FlashError, ParamFlash, PowerStage, Sample};
use drive_application::Drive;

/// A power stage at rest: mid-scale shunts, 24 V on the bus, a still encoder.
struct RestingStage;

impl PowerStage for RestingStage {
    const SCALES: SensingScales = power_stage::ratings::SCALES;
    const TICK_HZ: f32 = power_stage::config::IHM08M1.pwm_hz as f32;
    const ACCELEROMETER_VOLTS_PER_COUNT: f32 = power_stage::ratings::ACCELEROMETER_VOLTS_PER_COUNT;
    fn take_sample(&mut self) -> Sample {
        Sample { shunts: [2048; 3], bus: 1365, accelerometer: 2048 }
    }
    fn encoder_count(&mut self) -> i32 {
        0
    }
    fn break_tripped(&mut self) -> bool {
        false
    }
    fn phase_currents(&self, shunt_amps: [f32; 3], duties_in_force: [f32; 3]) -> [f32; 2] {
        power_stage::shunt_selection::phase_currents(shunt_amps, duties_in_force)
    }
    fn write_duties(&mut self, _: [f32; 3]) {}
    fn set_outputs(&mut self, _: bool) {}
    fn feed_watchdog(&mut self) {}
}

const PAGE: usize = 2048;

/// Two pages of RAM.
struct RamFlash {
    pages: [[u8; PAGE]; 2],
}

impl ParamFlash for RamFlash {
    const PAGE_BYTES: usize = PAGE;
    const WRITE_BYTES: usize = 8;
    fn read(&mut self, page: usize, offset: usize, bytes: &mut [u8]) -> Result<(), FlashError> {
        let src = self.pages.get(page).and_then(|p| p.get(offset..offset + bytes.len()));
        bytes.copy_from_slice(src.ok_or(FlashError::Alignment)?);
        Ok(())
    }
    fn erase(&mut self, page: usize) -> Result<(), FlashError> {
        self.pages.get_mut(page).ok_or(FlashError::Alignment)?.fill(0xFF);
        Ok(())
    }
    fn program(&mut self, page: usize, offset: usize, bytes: &[u8]) -> Result<(), FlashError> {
        let dst = self.pages.get_mut(page).and_then(|p| p.get_mut(offset..offset + bytes.len()));
        for (d, s) in dst.ok_or(FlashError::Alignment)?.iter_mut().zip(bytes) {
            *d &= s;
        }
        Ok(())
    }
}

/// Clock ticks the current section has lasted, and the longest since the last [`take`].
static mut ENTERED: u32 = 0;
static mut LONGEST: u32 = 0;

struct MeasuredSection;
critical_section::set_impl!(MeasuredSection);

unsafe impl critical_section::Impl for MeasuredSection {
    unsafe fn acquire() -> critical_section::RawRestoreState {
        let primask: u32;
        core::arch::asm!("mrs {}, PRIMASK", "cpsid i", out(reg) primask, options(nomem, nostack, preserves_flags));
        if primask & 1 == 0 {
            ENTERED = clock::counter();
        }
        primask
    }
    unsafe fn release(primask: critical_section::RawRestoreState) {
        if primask & 1 == 0 {
            // The counter counts down.
            let held = ENTERED.wrapping_sub(clock::counter()) & 0x00FF_FFFF;
            if held > LONGEST {
                LONGEST = held;
            }
            core::arch::asm!("cpsie i", options(nomem, nostack, preserves_flags));
        }
    }
}

/// The longest section since the last call (clock ticks).
fn take() -> u32 {
    // SAFETY: single-threaded; the sections have ended.
    unsafe { core::mem::replace(&mut *core::ptr::addr_of_mut!(LONGEST), 0) }
}

static DRIVE: Drive = Drive::new();
static mut FLASH: RamFlash = RamFlash { pages: [[0xFF; PAGE]; 2] };

extern "C" {
    static mut _ebss: u32;
}

/// Fill the free stack below the caller's frame with a pattern; [`stack_used`] finds how far
/// it was overwritten.
#[inline(never)]
fn paint_stack() {
    let here = 0u32;
    let top = core::ptr::addr_of!(here) as usize - 512;
    let mut p = core::ptr::addr_of_mut!(_ebss) as usize;
    while p < top {
        // SAFETY: free stack between the end of .bss and below this frame.
        unsafe { (p as *mut u32).write_volatile(0xDEAD_BEEF) };
        p += 4;
    }
}

/// The lowest address written below the painted stack.
fn stack_low_water() -> usize {
    let mut p = core::ptr::addr_of_mut!(_ebss) as usize;
    // SAFETY: reads of the painted region.
    while unsafe { (p as *const u32).read_volatile() } == 0xDEAD_BEEF {
        p += 4;
    }
    p
}

/// The requests in turn (built one at a time: an array of them would be kilobytes of stack).
#[inline(never)]
fn request(i: usize, heavy: &Params) -> Option<(&'static str, Request)> {
    let position = Commands { mode: Mode::Position, ..Default::default() };
    let velocity = Commands { mode: Mode::Velocity, velocity: 10.0, ..Default::default() };
    Some(match i {
        0 => ("Hello", Request::Hello { version: VERSION }),
        1 => ("GetTelemetry", Request::GetTelemetry),
        2 => ("SetParams", Request::SetParams(*heavy)),
        3 => ("LoadCorrection", Request::LoadCorrection(heavy.correction)),
        4 => ("SetParams", Request::SetParams(Params::default())),
        5 => ("LoadCorrection", Request::LoadCorrection(heavy.correction)),
        6 => ("SaveParams", Request::SaveParams),
        7 => ("Stream", Request::Stream { enabled: true }),
        8 => ("SetCommands", Request::SetCommands(velocity)),
        9 => ("StartSweep", Request::StartSweep),
        10 => ("ClearFaults", Request::ClearFaults),
        11 => ("SetCommands", Request::SetCommands(position)),
        12 => ("Sequence", Request::Sequence(SequenceEvent::MoveTo(1000))),
        13 => ("SetCommands", Request::SetCommands(Commands { mode: Mode::Sequence, ..Default::default() })),
        14 => ("Sequence", Request::Sequence(SequenceEvent::RunOn)),
        15 => ("SetCommands", Request::SetCommands(Commands::default())),
        _ => return None,
    })
}

#[no_mangle]
fn program() -> bool {
    paint_stack();
    clock::start();
    let passes = 100_000u32;
    let calibration = clock::calibrate(passes);
    let to_instructions = |clocks: u32| clocks as f64 * (2 * passes) as f64 / calibration as f64;
    // SAFETY: single-threaded; `FLASH` is used through this one reference.
    let flash = unsafe { &mut *core::ptr::addr_of_mut!(FLASH) };
    let mut stage = RestingStage;
    let Ok(mut host) = DRIVE.install::<RestingStage, _>(Params::default(), flash) else {
        print(format_args!("interrupts-off: install failed\n"));
        return false;
    };
    let _ = take(); // install's
                    // The measurement's own cost: empty sections.
    for _ in 0..16 {
        critical_section::with(|_| ());
    }
    let empty = take();
    // The offsets calibrate over 1 024 ticks; the tick's own sections are not the link's.
    for _ in 0..1_100 {
        DRIVE.tick(&mut stage);
    }
    let tick_section = take();
    // Every feature's state (6th-order acc/dec, eight correction sections, torque filters, a
    // sweep) but friction compensation, whose torque at standstill would keep the axis from
    // being at rest (parameters change only at rest).
    let mut heavy = preset(ALL_FEATURES).unwrap();
    heavy.friction.amplitude = 0.0;
    let mut longest = (0u32, "");
    // The parameter changes: SetParams, LoadCorrection, SaveParams.
    let mut changes = 0u32;
    for i in 0.. {
        let Some((name, request)) = request(i, &heavy) else { break };
        let response = host.handle(request, flash);
        let held = take();
        let outcome = match response {
            Response::Done | Response::Hello { .. } | Response::Telemetry(_) | Response::Saved { .. } => "carried out",
            Response::Refused(_) => "refused",
            _ => "frame error",
        };
        print(format_args!(
            "interrupts-off request {name} {:.0} instructions ({outcome})\n",
            to_instructions(held.saturating_sub(empty))
        ));
        if held > longest.0 {
            longest = (held, name);
        }
        if matches!(name, "SetParams" | "LoadCorrection" | "SaveParams") {
            changes = changes.max(held);
        }
        for _ in 0..64 {
            DRIVE.tick(&mut stage);
        }
        let _ = take();
        let mut out = [0u8; drive_application::link::OUT_BYTES];
        while host.stream_frame(&mut out).is_some() {}
        let batch = take();
        if batch > longest.0 {
            longest = (batch, "stream batch");
        }
    }
    print(format_args!(
        "stack: {} bytes free at the deepest, .bss ends at {:#x}\n",
        stack_low_water() - core::ptr::addr_of_mut!(_ebss) as usize,
        core::ptr::addr_of_mut!(_ebss) as usize
    ));
    let instructions = |clocks: u32| to_instructions(clocks.saturating_sub(empty));
    print(format_args!(
        "interrupts-off summary changes {:.0} longest {:.0} {} tick {:.0} empty {:.0}\n",
        instructions(changes),
        instructions(longest.0),
        longest.1,
        instructions(tick_section),
        to_instructions(empty)
    ));
    true
}
