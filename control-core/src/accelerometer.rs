//! The removable machine-end accelerometer (seed 001's measuring instrument): its setting.
//!
//! An analog accelerometer mounted on the load, its sensitive axis tangential at a radius r,
//! reads the machine-end angular acceleration α as a voltage about its zero: `V − V0 = S·α`.
//! The drive's board samples it with the phase currents; the drive application takes V0 at
//! start-up with the current offsets (the axis at rest: α = 0) and converts with `S`, this
//! parameter. The core never reads the acceleration except in a sweep with the machine-end
//! acceleration measure (`SweepMeasure::MachineAcceleration`).

/// The accelerometer's sensitivity as mounted.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AccelerometerParams {
    /// Volts per rad/s² of machine-end angular acceleration: the sensor's V per m/s² times
    /// its radius (m).
    pub sensitivity: f32,
}

/// A ±3 g analog MEMS accelerometer of 330 mV/g at a 3.3 V supply (ADXL335 class,
/// ratiometric; zero g at half the supply), tangential at 50 mm: 0.33 V / 9.80665 m/s² ·
/// 0.05 m = 1.683 mV per rad/s² (on the board's 12-bit, 3.3 V converter 0.48 rad/s² a count;
/// ±3 g is ±588 rad/s²).
pub const DEFAULT_SENSITIVITY: f32 = 0.33 / 9.80665 * 0.05;

/// Bounds of [`AccelerometerParams::sensitivity`] (V per rad/s²).
pub const MIN_SENSITIVITY: f32 = 1.0e-7;
pub const MAX_SENSITIVITY: f32 = 10.0;

impl Default for AccelerometerParams {
    fn default() -> Self {
        Self { sensitivity: DEFAULT_SENSITIVITY }
    }
}
