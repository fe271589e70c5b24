//! Servo control core: everything that runs inside the drive.
//!
//! `#![no_std]`, no allocation, `f32` arithmetic and `libm` for every transcendental
//! function, so the host build (FMU, tests) and the Cortex-M4 build produce the same bits.
//!
//! The entry point is [`Axis::step`], called once per base tick (the current-loop period).
//! The velocity loop runs every `velocity_divider` ticks and the position loop every
//! `position_divider` ticks (defaults 16 kHz / 8 kHz / 4 kHz).
#![no_std]
#![cfg_attr(feature = "fpu-sqrt", feature(core_float_math))]
// Unsafe code only where a drive's state is built in place (`Axis::new_in` and the parts it
// builds where they live: kilobytes never pass through a stack), each use allowed by name.
#![deny(unsafe_code)]

/// Write every field of the struct at `$at` (a `*mut $ty`, valid for writes and aligned) in
/// place: `$field: value` pairs, then, after `;`, the fields the caller has written itself.
/// A struct pattern without `..` names every field, so a field left out (or added to the
/// struct later and not written here) fails to compile instead of staying uninitialised.
/// Expands to unsafe code: use it inside the caller's `unsafe` block (the drive application
/// builds its shared state with it too).
#[macro_export]
macro_rules! write_fields {
    ($at:expr, $ty:ident { $($field:ident: $value:expr),* $(,)? ; $($written:ident),* $(,)? }) => {{
        let at: *mut $ty = $at;
        $(core::ptr::addr_of_mut!((*at).$field).write($value);)*
        #[allow(unreachable_code, clippy::diverging_sub_expression)]
        if false {
            let $ty { $($field: _,)* $($written: _,)* } = &*at;
        }
    }};
}

pub mod acc_dec;
pub mod accelerometer;
pub mod acquisition_stream;
pub mod axis;
pub mod biquad;
pub mod command_path;
pub mod commissioning;
pub mod current_loop;
pub mod current_sensing;
pub mod encoder;
pub mod excitation;
pub mod faults;
pub mod friction_compensation;
pub mod golden_vectors;
pub mod m_sequence;
pub mod params;
pub mod phase_shifted_sweep;
pub mod pi_controller;
pub mod position_loop;
pub mod protocol;
pub mod ranges;
pub mod reference_frames;
pub mod response_correction;
pub mod square_root;
pub mod stop_sequence;
pub mod torque_ceiling;
pub mod trigonometry;
pub mod velocity_loop;

pub use axis::{Axis, AxisInputs, Commands, Mode, PwmOutput, Telemetry};
pub use faults::Faults;
pub use params::{ParamError, Params};

/// 2π in f32.
pub const TAU: f32 = core::f32::consts::TAU;

/// `x` limited to `[lo, hi]`: what `f32::clamp` returns for ordered bounds (NaN passes
/// through), without its panic path. `f32::clamp` asserts `lo <= hi` and its panic message
/// formats both floats, which links core's float formatting into the drive's image (about
/// 15 KiB of flash) and costs a compare per call in the tick.
#[inline]
pub fn limit(x: f32, lo: f32, hi: f32) -> f32 {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

/// `x as f32` for encoder counts, through 32 bits when they fit: the same rounding (one
/// exact integer rounded to f32 either way), but an i64 → f32 conversion is a library call on
/// a Cortex-M4 and an i32 → f32 one is one instruction.
#[inline]
pub fn counts_to_f32(x: i64) -> f32 {
    match i32::try_from(x) {
        Ok(v) => v as f32,
        // Opaque to the optimiser: both arms give the same value, and without this LLVM
        // merged them into the 64-bit conversion on every call (3.5 library calls per tick,
        // about 90 instructions, seen in a QEMU instruction trace).
        Err(_) => core::hint::black_box(x) as f32,
    }
}

/// Whole-pulse output of a filter on pulses: keep exactly `keep` pulses inside (`stock`; the
/// filter's rounded pending output) and give out the rest of what came in, so the sum out
/// equals the sum in.
#[inline]
pub(crate) fn release_whole_pulses(stock: &mut i64, pulses: i64, keep: i64) -> i64 {
    // Saturating: bounded for every accepted command (see `ranges`), never wrapping otherwise.
    let out = stock.saturating_add(pulses).saturating_sub(keep);
    *stock = keep;
    out
}

/// Below this magnitude an f32 converts through 32 bits (one instruction on a Cortex-M4;
/// f32 → i64 is a library call) and `x − trunc(x)` is exact.
const I32_SAFE: f32 = 2_147_483_520.0; // the largest f32 below 2³¹

/// `libm::roundf(x) as i64` (half away from zero), bit for bit, without the library calls
/// for the usual magnitudes.
#[inline]
pub fn round_to_counts(x: f32) -> i64 {
    if x.abs() < 8_388_608.0 {
        // |x| < 2²³: the fraction is exact.
        let t = x as i32;
        let frac = x - t as f32;
        (if frac >= 0.5 {
            t + 1
        } else if frac <= -0.5 {
            t - 1
        } else {
            t
        }) as i64
    } else {
        libm::roundf(x) as i64
    }
}

/// `(libm::floorf(x), libm::floorf(x) as i64)`, bit for bit, without the library calls for
/// the usual magnitudes.
#[inline]
pub fn floor_to_counts(x: f32) -> (f32, i64) {
    if x.abs() < I32_SAFE {
        let t = x as i32;
        let t = if (t as f32) > x { t - 1 } else { t };
        // floor(−0) is −0: keep the zero's sign as the library does.
        (if x == 0.0 { x } else { t as f32 }, t as i64)
    } else {
        let f = libm::floorf(x);
        (f, f as i64)
    }
}

#[cfg(test)]
mod conversion_tests {
    extern crate std;
    use std::vec::Vec;

    /// The fast conversions equal the library's on every kind of value: ties, negatives,
    /// integers, both sides of 2²³ and 2³¹, huge, infinite and NaN.
    #[test]
    fn fast_conversions_equal_libm() {
        let mut values: Vec<f32> = [
            0.0f32,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.49999997,
            -0.49999997,
            8_388_607.5,
            -8_388_607.5,
            8_388_608.0,
            16_777_217.0,
            2_147_483_520.0,
            -2_147_483_520.0,
            2_147_483_648.0,
            -2_147_483_648.0,
            1.0e12,
            -1.0e12,
            f32::MAX,
            f32::MIN,
            f32::INFINITY,
            f32::NEG_INFINITY,
            f32::NAN,
        ]
        .to_vec();
        let mut x = 1.0e-3f32;
        while x < 1.0e11 {
            values.extend([x, -x, x + 0.5, -x - 0.5]);
            x *= 1.013;
        }
        for v in values {
            assert_eq!(super::round_to_counts(v), libm::roundf(v) as i64, "round {v}");
            let (f, c) = super::floor_to_counts(v);
            assert_eq!((f.to_bits(), c), (libm::floorf(v).to_bits(), libm::floorf(v) as i64), "floor {v}");
        }
    }
}
