//! What the host tests share: a test board (a power stage that samples a motor at rest, RAM
//! flash that can lose power after a given number of bytes), and a critical section for the
//! host (a spin lock, re-entrant per thread) that measures how long the link side holds it.

#![allow(dead_code)]

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};

use control_core::current_sensing::SensingScales;
use drive_application::board::{FlashError, ParamFlash, PowerStage, Sample, CURRENT_CHANNELS};

/// A power stage at rest: mid-scale shunts, 24 V on the bus, a still encoder.
#[derive(Default)]
pub struct RestingStage {
    pub outputs_on: bool,
    pub duties: [f32; 3],
    pub watchdog_feeds: u64,
    pub break_pending: bool,
}

impl PowerStage for RestingStage {
    const SCALES: SensingScales = power_stage_scales();
    const TICK_HZ: f32 = power_stage::config::IHM08M1.pwm_hz as f32;
    const ACCELEROMETER_VOLTS_PER_COUNT: f32 = power_stage::ratings::ACCELEROMETER_VOLTS_PER_COUNT;
    fn take_sample(&mut self) -> Sample {
        Sample { shunts: [2048; 3], bus: 1365, accelerometer: 2048 }
    }
    fn encoder_count(&mut self) -> i32 {
        0
    }
    fn break_tripped(&mut self) -> bool {
        core::mem::take(&mut self.break_pending)
    }
    fn phase_currents(&self, shunt_amps: [f32; CURRENT_CHANNELS], _duties: [f32; 3]) -> [f32; 2] {
        [shunt_amps[0], shunt_amps[1]]
    }
    fn write_duties(&mut self, duties: [f32; 3]) {
        self.duties = duties;
    }
    fn set_outputs(&mut self, on: bool) {
        self.outputs_on = on;
    }
    fn feed_watchdog(&mut self) {
        self.watchdog_feeds += 1;
    }
}

const fn power_stage_scales() -> SensingScales {
    power_stage::ratings::SCALES
}

/// Two pages of RAM flash. Programming only clears bits (flash semantics: a write over a
/// written byte ANDs); after `budget` bytes (erase counts one per byte, from the start of the
/// page) nothing more changes: the power is gone.
#[derive(Clone)]
pub struct RamFlash {
    pub pages: [Vec<u8>; 2],
    pub budget: Option<usize>,
}

pub const PAGE: usize = 2048;

impl RamFlash {
    pub fn new() -> Self {
        Self { pages: [vec![0xFF; PAGE], vec![0xFF; PAGE]], budget: None }
    }
    fn spend(&mut self) -> bool {
        match &mut self.budget {
            None => true,
            Some(0) => false,
            Some(n) => {
                *n -= 1;
                true
            }
        }
    }
}

impl ParamFlash for RamFlash {
    const PAGE_BYTES: usize = PAGE;
    const WRITE_BYTES: usize = 8;
    fn read(&mut self, page: usize, offset: usize, bytes: &mut [u8]) -> Result<(), FlashError> {
        let p = self.pages.get(page).ok_or(FlashError::Alignment)?;
        let src = p.get(offset..offset + bytes.len()).ok_or(FlashError::Alignment)?;
        bytes.copy_from_slice(src);
        Ok(())
    }
    fn erase(&mut self, page: usize) -> Result<(), FlashError> {
        if page > 1 {
            return Err(FlashError::Alignment);
        }
        for i in 0..PAGE {
            if !self.spend() {
                return Ok(());
            }
            self.pages[page][i] = 0xFF;
        }
        Ok(())
    }
    fn program(&mut self, page: usize, offset: usize, bytes: &[u8]) -> Result<(), FlashError> {
        if page > 1 || !offset.is_multiple_of(8) || !bytes.len().is_multiple_of(8) || offset + bytes.len() > PAGE {
            return Err(FlashError::Alignment);
        }
        for (i, b) in bytes.iter().enumerate() {
            if !self.spend() {
                return Ok(());
            }
            self.pages[page][offset + i] &= b;
        }
        Ok(())
    }
}

/// The critical section on the host: a spin lock, re-entrant within a thread. For every
/// outermost section taken by a thread marked as the link's ([`mark_link_thread`]), the
/// processor time it held the lock (the thread's own clock: a preemption does not count)
/// goes into that thread's [`take_longest`]; one of at least [`TICK_NS`] would have made the
/// control interrupt miss a tick.
struct SpinSection;
critical_section::set_impl!(SpinSection);

static LOCKED: AtomicBool = AtomicBool::new(false);
static OWNER: AtomicUsize = AtomicUsize::new(0);
/// Sections the host's kernel entered (a page fault, a context switch: nothing the drive's
/// code does on the target), left out of [`take_longest`].
pub static DISTURBED_SECTIONS: std::sync::atomic::AtomicU64 = std::sync::atomic::AtomicU64::new(0);

/// The longest section this (link) thread held since the last call, in processor time (ns),
/// and how many it held.
pub fn take_longest() -> (u64, u64) {
    LONGEST.with(|l| l.replace((0, 0)))
}
/// The G474's base tick: 16 kHz.
pub const TICK_NS: u64 = 62_500;

thread_local! {
    static IS_LINK: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
    static STARTED: std::cell::Cell<(u64, i64)> = const { std::cell::Cell::new((0, 0)) };
    static LONGEST: std::cell::Cell<(u64, u64)> = const { std::cell::Cell::new((0, 0)) };
}

pub fn mark_link_thread() {
    IS_LINK.with(|l| l.set(true));
}

fn thread_id() -> usize {
    thread_local! { static ID: u8 = const { 0 }; }
    ID.with(|x| x as *const u8 as usize)
}

/// Page faults and context switches of this thread so far.
fn kernel_entries() -> i64 {
    // SAFETY: a plain read into a zeroed local.
    let mut u: libc::rusage = unsafe { std::mem::zeroed() };
    unsafe { libc::getrusage(libc::RUSAGE_THREAD, &mut u) };
    u.ru_minflt + u.ru_majflt + u.ru_nvcsw + u.ru_nivcsw
}

pub fn thread_cpu_ns() -> u64 {
    let mut t = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: a plain clock read into a local.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut t) };
    t.tv_sec as u64 * 1_000_000_000 + t.tv_nsec as u64
}

unsafe impl critical_section::Impl for SpinSection {
    unsafe fn acquire() -> critical_section::RawRestoreState {
        let me = thread_id();
        if OWNER.load(Ordering::Acquire) == me && LOCKED.load(Ordering::Acquire) {
            return false; // nested
        }
        while LOCKED.compare_exchange_weak(false, true, Ordering::Acquire, Ordering::Relaxed).is_err() {
            std::hint::spin_loop();
        }
        OWNER.store(me, Ordering::Release);
        if IS_LINK.with(|l| l.get()) {
            STARTED.with(|s| s.set((thread_cpu_ns(), kernel_entries())));
        }
        true
    }
    unsafe fn release(outermost: critical_section::RawRestoreState) {
        if !outermost {
            return;
        }
        if IS_LINK.with(|l| l.get()) {
            let held = thread_cpu_ns();
            let (started, entries) = STARTED.with(|s| s.get());
            if kernel_entries() != entries {
                DISTURBED_SECTIONS.fetch_add(1, Ordering::Relaxed);
            } else {
                let held = held.saturating_sub(started);
                LONGEST.with(|l| {
                    let (longest, n) = l.get();
                    l.set((longest.max(held), n + 1));
                });
            }
        }
        OWNER.store(0, Ordering::Release);
        LOCKED.store(false, Ordering::Release);
    }
}
