//! Whether each phase's sample was taken while its shunt carried the phase current: the ADC
//! samples phase k from `adc_words::sampling_window` clocks after the trigger, and the reading
//! is good only if the low side had been on for the amplifier to settle before that and
//! stayed on to the end of the sampling.
//!
//! The amplifier's settling time after the low side turns on is an assumption
//! ([`AMPLIFIER_SETTLING_NS`], 1 µs): the IHM08M1's documentation at hand gives no figure.
//! The faults the tests look for do not depend on it: at the linear limit the phase with the
//! largest duty has no low-side window at all.

use crate::adc_words::{phase_slot, sampling_window};
use crate::gate_driver::Gates;

pub const AMPLIFIER_SETTLING_NS: u32 = 1_000;

/// Follows the gates clock by clock and judges the three samples of each trigger.
#[derive(Clone, Copy, Debug)]
pub struct SampleValidity {
    settle_ticks: u32,
    low_on_for: [u32; 3],
    since_trigger: Option<u32>,
    valid: [bool; 3],
}

impl SampleValidity {
    pub const fn new(settle_ticks: u32) -> Self {
        Self { settle_ticks, low_on_for: [0; 3], since_trigger: None, valid: [false; 3] }
    }

    /// One clock (after the bridge's step of the same clock). Returns the verdicts once the
    /// last sampling window after a trigger has closed.
    pub fn step(&mut self, trigger: bool, gates: [Gates; 3]) -> Option<[bool; 3]> {
        for k in 0..3 {
            self.low_on_for[k] = if gates[k].low { self.low_on_for[k] + 1 } else { 0 };
        }
        if trigger {
            self.since_trigger = Some(0);
        }
        let t = self.since_trigger?;
        let mut last_end = 0;
        for k in 0..3 {
            let (start, end) = sampling_window(phase_slot(k).1);
            last_end = last_end.max(end);
            if t == end {
                self.valid[k] = self.low_on_for[k] > end - start + self.settle_ticks;
            }
        }
        if t == last_end {
            self.since_trigger = None;
            return Some(self.valid);
        }
        self.since_trigger = Some(t + 1);
        None
    }
}
