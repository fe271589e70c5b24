//! SysTick as a free-running 24-bit counter of processor clock ticks, with its wraps counted
//! by the SysTick exception. Under QEMU with `-icount shift=0` the clock advances with the
//! instructions executed, so differences of `ticks()` measure code cost.

const SYST_CSR: *mut u32 = 0xE000_E010 as *mut u32;
const SYST_RVR: *mut u32 = 0xE000_E014 as *mut u32;
const SYST_CVR: *mut u32 = 0xE000_E018 as *mut u32;

pub fn start() {
    // SAFETY: the SysTick registers of the Cortex-M system control space.
    unsafe {
        SYST_RVR.write_volatile(0x00FF_FFFF);
        SYST_CVR.write_volatile(0);
        // Enable, processor clock, exception on wrap.
        SYST_CSR.write_volatile(0b111);
        // The counter reloads from 0 at its first clock (no wrap counted): wait for it.
        while SYST_CVR.read_volatile() == 0 {}
    }
}

pub fn ticks() -> u64 {
    // SAFETY: reads of the SysTick counter and of the wrap count the exception updates.
    unsafe {
        loop {
            let w0 = core::ptr::addr_of!(crate::SYSTICK_WRAPS).read_volatile();
            let v = SYST_CVR.read_volatile();
            let w1 = core::ptr::addr_of!(crate::SYSTICK_WRAPS).read_volatile();
            if w0 == w1 {
                return w0 as u64 * 0x0100_0000 + (0x00FF_FFFF - v) as u64;
            }
        }
    }
}

/// The raw 24-bit down-counter: differences of two reads (modulo 2^24) measure sections too
/// short for a wrap and run with interrupts off, where the wrap count cannot advance.
#[inline(always)]
pub fn counter() -> u32 {
    // SAFETY: a read of the SysTick current-value register.
    unsafe { SYST_CVR.read_volatile() }
}

/// Clock ticks of a loop of `2 × passes` instructions: the calibration of clocks to
/// instructions.
pub fn calibrate(passes: u32) -> u64 {
    let c0 = ticks();
    // SAFETY: a register-only countdown loop.
    unsafe { core::arch::asm!("1:", "subs {0}, {0}, #1", "bne 1b", inout(reg) passes => _, options(nostack)) };
    ticks() - c0
}
