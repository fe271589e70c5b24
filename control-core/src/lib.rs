//! Servo control core: everything that runs inside the drive.
//!
//! `#![no_std]`, no allocation, `f32` arithmetic and `libm` for every transcendental
//! function, so the host build (FMU, tests) and the Cortex-M4 build produce the same bits.
//!
//! The entry point is [`Axis::step`], called once per base tick (the current-loop period).
//! The velocity loop runs every `velocity_divider` ticks and the position loop every
//! `position_divider` ticks (defaults 16 kHz / 8 kHz / 4 kHz).
#![no_std]
#![forbid(unsafe_code)]

pub mod acc_dec;
pub mod acquisition_stream;
pub mod axis;
pub mod biquad;
pub mod command_path;
pub mod current_loop;
pub mod current_sensing;
pub mod encoder;
pub mod excitation;
pub mod faults;
pub mod m_sequence;
pub mod friction_compensation;
pub mod golden_vectors;
pub mod params;
pub mod phase_shifted_sweep;
pub mod pi_controller;
pub mod position_loop;
pub mod protocol;
pub mod reference_frames;
pub mod response_correction;
pub mod stop_sequence;
pub mod trigonometry;
pub mod velocity_loop;

pub use axis::{Axis, AxisInputs, Commands, Mode, PwmOutput, Telemetry};
pub use faults::Faults;
pub use params::{ParamError, Params};

/// 2π in f32.
pub const TAU: f32 = core::f32::consts::TAU;

/// `x as f32` for encoder counts, through 32 bits when they fit: the same rounding (one
/// exact integer rounded to f32 either way), but an i64 → f32 conversion is a library call on
/// a Cortex-M4 and an i32 → f32 one is one instruction.
#[inline]
pub fn counts_to_f32(x: i64) -> f32 {
    match i32::try_from(x) {
        Ok(v) => v as f32,
        Err(_) => x as f32,
    }
}
