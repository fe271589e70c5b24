//! A bare Cortex-M4F program under QEMU (netduinoplus2): no runtime crate — a vector table, a
//! reset handler that copies `.data`, clears `.bss`, enables the FPU and calls the binary's
//! `program` (its result is the exit status), semihosting calls (`bkpt 0xAB`) and SysTick as
//! an instruction clock (`-icount shift=0`) are all the two binaries need:
//! `core-vectors` (the control core over golden vectors) and `interrupts-off` (the drive
//! application's critical sections).

#![no_std]

pub mod clock;
pub mod semihosting;

use core::panic::PanicInfo;

extern "Rust" {
    /// The binary's program; `true`: success.
    fn program() -> bool;
}

extern "C" {
    static mut _sdata: u32;
    static mut _edata: u32;
    static _sidata: u32;
    static mut _sbss: u32;
    static mut _ebss: u32;
    static _stack_top: u32;
}

#[repr(C)]
#[derive(Clone, Copy)]
pub union Vector {
    handler: unsafe extern "C" fn() -> !,
    /// An exception handler that returns (Cortex-M stacks the caller-saved registers, so a
    /// plain AAPCS function can be one).
    exception: unsafe extern "C" fn(),
    stack: *const u32,
    reserved: usize,
}

unsafe impl Sync for Vector {}

#[link_section = ".vector_table"]
#[no_mangle]
#[used]
pub static VECTORS: [Vector; 16] = {
    let fault = Vector { handler: fault };
    [
        Vector { stack: core::ptr::addr_of!(_stack_top) },
        Vector { handler: reset },
        fault,
        fault,
        fault,
        fault,
        fault,
        Vector { reserved: 0 },
        Vector { reserved: 0 },
        Vector { reserved: 0 },
        Vector { reserved: 0 },
        fault,
        fault,
        Vector { reserved: 0 },
        fault,
        Vector { exception: systick },
    ]
};

/// SysTick wraps (every 2^24 clock ticks), counted for `clock::ticks`.
pub static mut SYSTICK_WRAPS: u32 = 0;

unsafe extern "C" fn systick() {
    let wraps = core::ptr::addr_of_mut!(SYSTICK_WRAPS);
    wraps.write_volatile(wraps.read_volatile().wrapping_add(1));
}

unsafe extern "C" fn fault() -> ! {
    semihosting::write("fault\n");
    semihosting::exit(false)
}

#[no_mangle]
pub unsafe extern "C" fn reset() -> ! {
    // .data from flash, .bss to zero.
    let mut src = core::ptr::addr_of!(_sidata);
    let mut dst = core::ptr::addr_of_mut!(_sdata);
    while dst < core::ptr::addr_of_mut!(_edata) {
        dst.write_volatile(src.read());
        dst = dst.add(1);
        src = src.add(1);
    }
    let mut b = core::ptr::addr_of_mut!(_sbss);
    while b < core::ptr::addr_of_mut!(_ebss) {
        b.write_volatile(0);
        b = b.add(1);
    }
    // Full access to CP10 and CP11 (the FPU), then synchronise.
    let cpacr = 0xE000_ED88 as *mut u32;
    cpacr.write_volatile(cpacr.read_volatile() | (0xF << 20));
    core::arch::asm!("dsb", "isb");
    let ok = program();
    semihosting::exit(ok)
}

#[panic_handler]
fn panic(_: &PanicInfo) -> ! {
    semihosting::write("panic\n");
    semihosting::exit(false)
}
