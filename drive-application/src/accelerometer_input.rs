//! The machine-end accelerometer's input (seed 001's removable measuring instrument): its
//! ADC count to rad/s².
//!
//! Its zero is taken like the phase currents' offsets: the mean of the first
//! [`CALIBRATION_SAMPLES`] conversions after start-up, with the bridge off and the axis at rest
//! (zero acceleration). Mount the sensor with the shaft vertical, or gravity's component along
//! its axis enters the zero (at rest) and the readings (at the rotation frequency while
//! turning: 3.2 Hz at the identification's 20 rad/s, below its 5 Hz band). A zero outside
//! [`OFFSET_WINDOW`] of mid-scale means no sensor on the pin (a floating or grounded input):
//! then every reading is NaN, which reaches the host in the samples of a sweep that measures
//! the acceleration (the loops never read it, so nothing else changes and no fault latches).

use control_core::accelerometer::AccelerometerParams;
use control_core::current_sensing::{CALIBRATION_SAMPLES, OFFSET_WINDOW};

/// rad/s² per count of a converter of `volts_per_count` for a sensor of `params`' sensitivity.
pub fn accelerometer_scale(volts_per_count: f32, params: &AccelerometerParams) -> f32 {
    volts_per_count / params.sensitivity
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Zero {
    Calibrating {
        sum: u32,
        n: u32,
    },
    /// The zero (counts), or None: no sensor on the pin.
    Known(Option<f32>),
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct AccelerometerInput {
    full_scale: u16,
    /// rad/s² per count: `volts_per_count / sensitivity`.
    scale: f32,
    zero: Zero,
}

impl AccelerometerInput {
    /// The input of a converter of `full_scale` counts, `volts_per_count`, for a sensor of
    /// `params`' sensitivity; calibrating.
    pub fn new(full_scale: u16, volts_per_count: f32, params: &AccelerometerParams) -> Self {
        Self {
            full_scale,
            scale: accelerometer_scale(volts_per_count, params),
            zero: Zero::Calibrating { sum: 0, n: 0 },
        }
    }

    /// The scale for a new sensitivity (found outside the critical section, by
    /// [`accelerometer_scale`]; rad/s² per count).
    pub fn set_scale(&mut self, rad_s2_per_count: f32) {
        self.scale = rad_s2_per_count;
    }

    /// One conversion while the currents calibrate (bridge off, axis at rest).
    pub fn calibrate(&mut self, count: u16) {
        let Zero::Calibrating { sum, n } = &mut self.zero else { return };
        *sum += count as u32;
        *n += 1;
        if *n >= CALIBRATION_SAMPLES {
            let zero = *sum as f32 / CALIBRATION_SAMPLES as f32;
            let mid = 0.5 * self.full_scale as f32;
            let present = (zero - mid).abs() <= OFFSET_WINDOW * self.full_scale as f32;
            self.zero = Zero::Known(present.then_some(zero));
        }
    }

    /// The zero (counts) once calibrated: Some(None) when no sensor was found.
    pub fn zero(&self) -> Option<Option<f32>> {
        match self.zero {
            Zero::Known(z) => Some(z),
            Zero::Calibrating { .. } => None,
        }
    }

    /// Machine-end angular acceleration (rad/s²): NaN without a sensor, 0 while calibrating.
    #[inline(always)]
    pub fn convert(&self, count: u16) -> f32 {
        match self.zero {
            Zero::Known(Some(zero)) => (count as f32 - zero) * self.scale,
            Zero::Known(None) => f32::NAN,
            Zero::Calibrating { .. } => 0.0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const VOLTS_PER_COUNT: f32 = 3.3 / 4095.0;

    #[test]
    fn the_zero_is_the_mean_at_rest_and_the_scale_the_sensitivity() {
        let params = AccelerometerParams { sensitivity: 2.0e-3 };
        let mut input = AccelerometerInput::new(4095, VOLTS_PER_COUNT, &params);
        for k in 0..CALIBRATION_SAMPLES {
            assert_eq!(input.zero(), None);
            input.calibrate(2040 + (k % 2) as u16);
        }
        assert_eq!(input.zero(), Some(Some(2040.5)));
        // 100 counts above the zero: 100 · 0.806 mV / 2 mV per rad/s².
        let a = input.convert(2140);
        let expected = 99.5 * VOLTS_PER_COUNT / 2.0e-3;
        assert!((a - expected).abs() < 1e-3 * expected, "{a} vs {expected}");
        input.set_scale(accelerometer_scale(VOLTS_PER_COUNT, &AccelerometerParams { sensitivity: 4.0e-3 }));
        assert!((input.convert(2140) - expected / 2.0).abs() < 1e-3 * expected);
    }

    #[test]
    fn no_sensor_on_the_pin_reads_nan() {
        let mut input = AccelerometerInput::new(4095, VOLTS_PER_COUNT, &AccelerometerParams::default());
        for _ in 0..CALIBRATION_SAMPLES {
            input.calibrate(0);
        }
        assert_eq!(input.zero(), Some(None));
        assert!(input.convert(2048).is_nan());
    }
}
