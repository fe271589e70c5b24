//! The simulated board under the drive application: the FMU's plant (motor, load, encoder)
//! behind the IHM08M1's sensing as the firmware reads it.
//!
//! - Phase currents: three low-side shunt amplifiers into the 12-bit ADC, with the board's
//!   scale (15.6 mA a count, inverting) around offsets of a few counts from mid-scale (so the
//!   drive's offset calibration has work to do). A shunt whose low side does not conduct at
//!   the sampling instant (the phase with the largest duty) reads its offset: no current
//!   flows through it then. The firmware's shunt choice picks the other two.
//! - Bus voltage: the divider into the ADC, quantised.
//! - Machine-end accelerometer (seed 001's removable instrument, on PC3 of the G474 board):
//!   the plant's accelerometer reading (its load acceleration with the noise the FMU's plant
//!   adds, `plant.acceleration_noise_std`) through a sensor of [`ACCELEROMETER_SENSITIVITY`]
//!   about a zero of [`ACCELEROMETER_ZERO_VOLTS`] into the 12-bit converter, quantised (and
//!   saturating at its rails, as the converter does).
//! - Encoder: the plant's quadrature count.
//! - Duties and gate drive: as the FMU applies them — sampled at the top of a PWM period, the
//!   duties written in a tick are in force from the next period (one tick of delay), and the
//!   gate drive off takes effect at once.
//!
//! Order within a tick (as `servo_axis::simulation::AxisSimulation`): the sample, the drive's
//! tick, then the plant advances over the period with the duties in force.

use control_core::current_sensing::SensingScales;
use drive_application::board::{PowerStage, Sample, CURRENT_CHANNELS};
use power_stage::ratings::{ACCELEROMETER_VOLTS_PER_COUNT, SCALES};
use power_stage::shunt_selection;
use servo_axis::plant::{Plant, PlantInputs};

use crate::virtual_drive::faults::{BoardFault, UNDERVOLTAGE_VOLTS};

/// The IHM08M1's PWM rate, as the firmware sets TIM1: the tick the virtual drive runs.
pub const TICK_HZ: f32 = power_stage::config::IHM08M1.pwm_hz as f32;

/// Each amplifier's output at zero current (ADC counts; mid-scale 2047.5), as a board's
/// resistor tolerances leave them.
pub const SHUNT_OFFSETS: [f64; CURRENT_CHANNELS] = [2041.0, 2053.0, 2045.0];

/// The simulated accelerometer's sensitivity (V per rad/s²): the drive's default, the sensor
/// `control_core::accelerometer::DEFAULT_SENSITIVITY` describes.
pub const ACCELEROMETER_SENSITIVITY: f64 = control_core::accelerometer::DEFAULT_SENSITIVITY as f64;
/// Its output at rest (V): half the 3.3 V supply, off by a sensor's zero-g tolerance (so the
/// drive's zero calibration has work to do).
pub const ACCELEROMETER_ZERO_VOLTS: f64 = 1.62;

pub struct SimulatedBoard {
    pub plant: Plant,
    /// Duties and gate drive in force during this PWM period, and those written this tick.
    duties_in_force: [f32; 3],
    enabled_in_force: bool,
    duties_written: [f32; 3],
    enabled_written: bool,
    /// The encoder count of this tick's sample.
    count: i32,
    /// Set by a disconnect: the count it stands at.
    encoder_stuck_at: Option<i32>,
    break_pending: bool,
    /// The bridge was switched off by the break input until the drive switches it off too.
    break_off: bool,
    pub watchdog_feeds: u64,
}

impl SimulatedBoard {
    pub fn new(plant: Plant) -> Self {
        Self {
            plant,
            duties_in_force: [0.5; 3],
            enabled_in_force: false,
            duties_written: [0.5; 3],
            enabled_written: false,
            count: 0,
            encoder_stuck_at: None,
            break_pending: false,
            break_off: false,
            watchdog_feeds: 0,
        }
    }

    /// A fault happens now.
    pub fn inject(&mut self, fault: BoardFault) {
        match fault {
            BoardFault::EncoderDisconnect => {
                let run_off = (self.plant.params().encoder_counts_per_rev / 4 * 3) as i32;
                self.encoder_stuck_at = Some(self.count.wrapping_add(run_off));
            }
            BoardFault::Break => {
                self.break_pending = true;
                self.break_off = true;
            }
            BoardFault::Undervoltage => {
                self.plant.set_bus_voltage(UNDERVOLTAGE_VOLTS).expect("a positive bus voltage is valid")
            }
        }
    }

    /// The plant over one PWM period with the duties in force (after the drive's tick).
    pub fn advance(&mut self) {
        let applied = PlantInputs {
            duties: self.duties_in_force.map(f64::from),
            // Off at once when the drive or the break switches it off; on from the next period.
            bridge_enabled: self.enabled_in_force && self.enabled_written && !self.break_off,
            disturbance_torque: 0.0,
        };
        self.plant.advance(&applied);
        self.duties_in_force = self.duties_written;
        self.enabled_in_force = self.enabled_written;
    }

    /// The gate drive is on.
    pub fn bridge_on(&self) -> bool {
        self.enabled_written && !self.break_off
    }
}

fn adc_count(volts_or_amps: f64, offset: f64, per_count: f32, full_scale: u16) -> u16 {
    // The converter saturates at its rails: that is the hardware, not a clamp of an input.
    (offset + volts_or_amps / per_count as f64).round().clamp(0.0, full_scale as f64) as u16
}

impl PowerStage for SimulatedBoard {
    const SCALES: SensingScales = SCALES;
    const TICK_HZ: f32 = TICK_HZ;
    const ACCELEROMETER_VOLTS_PER_COUNT: f32 = ACCELEROMETER_VOLTS_PER_COUNT;

    fn take_sample(&mut self) -> Sample {
        let m = self.plant.measure();
        self.count = self.encoder_stuck_at.unwrap_or(m.encoder_count);
        let [ia, ib] = m.phase_currents;
        let currents = [ia, ib, -(ia + ib)];
        let not_read = shunt_selection::phase_not_read(self.duties_in_force);
        let mut shunts = [0u16; CURRENT_CHANNELS];
        for (k, s) in shunts.iter_mut().enumerate() {
            let i = if k == not_read { 0.0 } else { currents[k] };
            *s = adc_count(i, SHUNT_OFFSETS[k], SCALES.amps_per_count, SCALES.full_scale);
        }
        let bus = adc_count(m.bus_voltage, 0.0, SCALES.volts_per_count, SCALES.full_scale);
        // Sampled at the same instant as the currents: the reading at the end of the last
        // period, as the FMU gives the core (`servo_axis::simulation`).
        let volts_per_count = ACCELEROMETER_VOLTS_PER_COUNT;
        let accelerometer = adc_count(
            self.plant.accelerometer * ACCELEROMETER_SENSITIVITY,
            ACCELEROMETER_ZERO_VOLTS / volts_per_count as f64,
            volts_per_count,
            SCALES.full_scale,
        );
        Sample { shunts, bus, accelerometer }
    }

    fn encoder_count(&mut self) -> i32 {
        self.count
    }

    fn break_tripped(&mut self) -> bool {
        std::mem::take(&mut self.break_pending)
    }

    fn phase_currents(&self, shunt_amps: [f32; CURRENT_CHANNELS], duties_in_force: [f32; 3]) -> [f32; 2] {
        shunt_selection::phase_currents(shunt_amps, duties_in_force)
    }

    fn write_duties(&mut self, duties: [f32; 3]) {
        self.duties_written = duties;
    }

    fn set_outputs(&mut self, on: bool) {
        self.enabled_written = on;
        if !on {
            // The drive has switched off too: the break's own hold ends (the timer's MOE is
            // set again only by the drive, once the fault is cleared).
            self.break_off = false;
        }
    }

    fn feed_watchdog(&mut self) {
        self.watchdog_feeds += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use control_core::accelerometer::AccelerometerParams;
    use control_core::current_sensing::CALIBRATION_SAMPLES;
    use drive_application::accelerometer_input::AccelerometerInput;
    use servo_axis::plant::PlantParams;

    /// The plant's accelerometer reading through the simulated sensor and converter, and back
    /// through the drive's input at the default sensitivity: the acceleration within half a
    /// count (0.24 rad/s²), the zero found at rest.
    #[test]
    fn the_accelerometer_reads_the_plants_acceleration_through_the_converter() {
        let mut board = SimulatedBoard::new(Plant::new(PlantParams::default()).unwrap());
        let mut input =
            AccelerometerInput::new(SCALES.full_scale, ACCELEROMETER_VOLTS_PER_COUNT, &AccelerometerParams::default());
        for _ in 0..CALIBRATION_SAMPLES {
            input.calibrate(board.take_sample().accelerometer);
        }
        let zero = input.zero().flatten().expect("a sensor at mid-scale");
        assert!((zero as f64 - ACCELEROMETER_ZERO_VOLTS / ACCELEROMETER_VOLTS_PER_COUNT as f64).abs() <= 0.5);
        let half_count = 0.5 * ACCELEROMETER_VOLTS_PER_COUNT as f64 / ACCELEROMETER_SENSITIVITY;
        for a in [-400.0, -3.3, 0.1, 57.0, 500.0] {
            board.plant.accelerometer = a;
            let read = input.convert(board.take_sample().accelerometer) as f64;
            assert!((read - a).abs() <= half_count + 1e-3, "{a} rad/s² read as {read}");
        }
        // Beyond the converter's range (±980 rad/s² about this zero) the count saturates.
        board.plant.accelerometer = 5000.0;
        assert_eq!(board.take_sample().accelerometer, SCALES.full_scale);
    }
}
