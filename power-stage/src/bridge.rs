//! The three legs clock by clock: TIM1's centre-aligned counter and PWM modes, each channel's
//! output stage ([`crate::output_stage`]) and each leg's L6398 ([`crate::gate_driver`]), from
//! the register words the firmware writes. One step is one timer clock.

use crate::gate_driver::{GateDriver, Gates, DEAD_TIME_NS};
use crate::output_stage::{ChannelBits, ChannelOutput};
use crate::tim1_words::{bdtr_with_moe, compare_value, ocm_of, Tim1Words, BDTR_DTG_MASK, BDTR_MOE, OCM_PWM1, OCM_PWM2};
use crate::{dead_time, Pin};

/// What one clock produced.
#[derive(Clone, Copy, Debug)]
pub struct Tick {
    pub counter: u32,
    pub counting_up: bool,
    /// OC4REF rose: TRGO2, the ADCs' trigger.
    pub trigger: bool,
    /// (OCx, OCxN) pins of channels 1–3.
    pub pins: [(Pin, Pin); 3],
    pub gates: [Gates; 3],
}

/// TIM1 and the three gate drivers.
#[derive(Clone, Debug)]
pub struct BridgeModel {
    pub words: Tim1Words,
    pub ccr: [u32; 3],
    /// BDTR as it is now (MOE included).
    pub bdtr: u32,
    counter: u32,
    up: bool,
    oc4ref: bool,
    channels: [ChannelOutput; 3],
    drivers: [GateDriver; 3],
    timer_dead_ticks: u32,
}

impl BridgeModel {
    /// Just after the firmware wrote `words` (bridge off, duties 0); `timer_clock_hz` sets the
    /// driver's dead time in clocks.
    pub fn new(words: Tim1Words, timer_clock_hz: u32) -> Self {
        let driver_dead = ((DEAD_TIME_NS as u64 * timer_clock_hz as u64 + 500_000_000) / 1_000_000_000) as u32;
        Self {
            words,
            ccr: [0; 3],
            bdtr: words.bdtr,
            counter: 0,
            up: true,
            oc4ref: false,
            channels: [ChannelOutput::new(); 3],
            drivers: [GateDriver::new(driver_dead); 3],
            timer_dead_ticks: dead_time::decode((words.bdtr & BDTR_DTG_MASK) as u8),
        }
    }

    /// As `board::write_duties`.
    pub fn set_duties(&mut self, duties: [f32; 3]) {
        self.ccr = duties.map(|d| compare_value(d, self.words.arr));
    }

    /// As `board::set_outputs`.
    pub fn set_moe(&mut self, on: bool) {
        self.bdtr = bdtr_with_moe(self.bdtr, on);
    }

    /// The break input or a software break: MOE cleared by hardware (AOE = 0: it stays 0).
    pub fn trip_break(&mut self) {
        self.bdtr &= !BDTR_MOE;
    }

    pub fn moe(&self) -> bool {
        self.bdtr & BDTR_MOE != 0
    }

    pub fn timer_dead_ticks(&self) -> u32 {
        self.timer_dead_ticks
    }

    /// Clocks per PWM period.
    pub fn period_ticks(&self) -> u32 {
        2 * self.words.arr
    }

    /// PWM modes 1 and 2 (RM0440): mode 1 is active while CNT < CCR counting up and while
    /// CNT ≤ CCR counting down; mode 2 is its complement.
    fn reference(ocm: u32, counter: u32, up: bool, ccr: u32) -> bool {
        let mode1 = if up { counter < ccr } else { counter <= ccr };
        match ocm {
            OCM_PWM1 => mode1,
            OCM_PWM2 => !mode1,
            _ => false, // frozen / forced modes are not used
        }
    }

    pub fn step(&mut self) -> Tick {
        let (counter, up) = (self.counter, self.up);
        let moe = self.moe();
        let mut pins = [(Pin::Floating, Pin::Floating); 3];
        let mut gates = [Gates::default(); 3];
        for ch in 0..3 {
            let r = Self::reference(ocm_of(&self.words, ch), counter, up, self.ccr[ch]);
            let bits = ChannelBits::from_words(self.words.ccer, self.words.cr2, self.bdtr, ch);
            pins[ch] = self.channels[ch].step(r, moe, bits, self.timer_dead_ticks);
            gates[ch] = self.drivers[ch].step(pins[ch].0, pins[ch].1);
        }
        let oc4 = Self::reference(ocm_of(&self.words, 3), counter, up, self.words.ccr4);
        let trigger = oc4 && !self.oc4ref;
        self.oc4ref = oc4;
        // Centre-aligned: 0 → ARR counting up, ARR → 0 counting down.
        let arr = self.words.arr;
        if up {
            self.counter += 1;
            if self.counter == arr {
                self.up = false;
            }
        } else {
            self.counter -= 1;
            if self.counter == 0 {
                self.up = true;
            }
        }
        Tick { counter, counting_up: up, trigger, pins, gates }
    }
}

/// The voltage of a leg's output node (to the negative bus rail) for its gates and its phase
/// current (positive into the motor): the conducting FET, or with both off the body diode
/// the current forces on (the low side's for a current out of the leg).
pub fn leg_voltage(g: Gates, current: f32, bus: f32) -> f32 {
    match (g.high, g.low) {
        (true, _) => bus,
        (false, true) => 0.0,
        (false, false) if current > 0.0 => 0.0,
        (false, false) => bus,
    }
}

/// Current through a leg's shunt (in the low side's source), in the phase current's sense:
/// the phase current while the low-side FET or its body diode carries it, otherwise 0.
pub fn shunt_current(g: Gates, current: f32) -> f32 {
    let low_conducts = g.low || (!g.high && current > 0.0);
    if low_conducts {
        current
    } else {
        0.0
    }
}
