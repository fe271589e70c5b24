//! Position-tick housekeeping, at a lower priority than the tick: what the drive reports to
//! its log. The application says what happened ([`Note`]); the board's binary writes it
//! (defmt on the G474, standard error on the host).

use control_core::faults::Faults;

use crate::board::CURRENT_CHANNELS;
use crate::drive::Drive;

/// Something worth a log line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Note {
    /// The current offsets (counts, mid-scale 2047.5) and the bus voltage once calibrated: to
    /// compare with a meter at the first power-up; with the machine-end accelerometer's zero
    /// (counts; None: no sensor on its input).
    OffsetsCalibrated { offsets: [f32; CURRENT_CHANNELS], bus_voltage: f32, accelerometer_zero: Option<f32> },
    /// The latched faults changed (PWM off until ClearFaults while any is set).
    FaultsChanged { faults: Faults },
    /// Once a second: the loop runs.
    Alive { ticks: u32, faults: Faults, bus_voltage: f32 },
}

/// Position ticks between two heartbeats (4 kHz position rate: one second).
pub const ALIVE_EVERY: u32 = 4_000;

#[derive(Default)]
pub struct Housekeeping {
    last: Faults,
    position_ticks: u32,
    offsets_logged: bool,
}

impl Housekeeping {
    /// One position tick with the faults the tick saw; `note` gets what happened.
    pub fn on_position_tick(&mut self, drive: &Drive, faults: Faults, mut note: impl FnMut(Note)) {
        if !self.offsets_logged {
            if let (Some((offsets, bus_voltage)), Some(accelerometer_zero)) =
                (drive.offsets(), drive.accelerometer_zero())
            {
                note(Note::OffsetsCalibrated { offsets, bus_voltage, accelerometer_zero });
                self.offsets_logged = true;
            }
        }
        if faults != self.last {
            note(Note::FaultsChanged { faults });
            self.last = faults;
        }
        self.position_ticks = self.position_ticks.wrapping_add(1);
        if self.position_ticks.is_multiple_of(ALIVE_EVERY) {
            note(Note::Alive { ticks: drive.ticks(), faults, bus_voltage: drive.bus_voltage() });
        }
    }
}
