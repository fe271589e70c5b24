//! The stack's high-water mark. cortex-m-rt's `paint-stack` feature fills the whole stack,
//! from `_stack_end` (the end of the statics, where the stack may grow to) up to
//! `_stack_start` (the top of RAM), with [`STACK_PAINT_VALUE`] in its reset handler, before any
//! Rust code runs — the sound place for it: a Rust `__pre_init` (deprecated in cortex-m-rt
//! 0.7.6) runs before RAM is initialised, and a paint from `main` could not reach what `main`'s
//! own frame and its callers already hold. What a call writes scrubs the paint; the words
//! still painted from the low end up were never touched since reset.
//!
//! Limits of the measure: a frame that reserves room and never writes its lowest words (an
//! uninitialised buffer) leaves them painted, and a word written with the paint's own value
//! reads as untouched; either makes the figure read high by that much. The static bound from
//! the image (`servo bench firmware`) has neither limit: it counts every path the code allows,
//! where this mark shows the paths the drive has taken since reset.

use cortex_m_rt::STACK_PAINT_VALUE;

extern "C" {
    /// The stack's low end (cortex-m-rt's `link.x`: just after `.uninit`).
    static _stack_end: u32;
    /// The stack's top (the initial stack pointer).
    static _stack_start: u32;
}

/// The stack's size (bytes).
pub fn stack_bytes() -> u32 {
    (core::ptr::addr_of!(_stack_start) as usize - core::ptr::addr_of!(_stack_end) as usize) as u32
}

/// Bytes of the stack never written since reset: the painted words from the stack's low end
/// up to the first word that differs. The scan reads only those (a few kilobytes while the
/// stack holds), with interrupts on: a deeper interrupt meanwhile can only lower the mark,
/// which the next call sees. Never inlined: one copy for its three callers (boot, heartbeat,
/// telemetry).
#[inline(never)]
pub fn unused_stack_bytes() -> u32 {
    let low = core::ptr::addr_of!(_stack_end) as usize;
    let top = core::ptr::addr_of!(_stack_start) as usize;
    let mut at = low;
    // SAFETY: every word between `_stack_end` and `_stack_start` is RAM (aligned: both ends
    // are multiples of 4, link.x asserts it), read with volatile loads and never written; the
    // scan stops at the first word that differs from the paint, at the top at the latest.
    while at < top && unsafe { (at as *const u32).read_volatile() } == STACK_PAINT_VALUE {
        at += 4;
    }
    (at - low) as u32
}
