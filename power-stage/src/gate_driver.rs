//! Model of the L6398 half-bridge gate driver (one per leg on the IHM08M1), from its
//! datasheet: HIN active high with an internal pull-down, LIN active low with an internal
//! pull-up, and the input truth table
//!
//! | HIN | LIN | high-side gate (HVG) | low-side gate (LVG) |
//! |---|---|---|---|
//! | 0 | 0 | off | on |
//! | 0 | 1 | off | off |
//! | 1 | 0 | off | off (interlock) |
//! | 1 | 1 | on | off |
//!
//! plus the driver's own dead time (about 320 ns): one gate turns on only once the other has
//! been off that long, whatever the inputs do. Propagation delays are taken as equal on both
//! sides and left out; the datasheet's dead-time spread (minimum and maximum) was not at hand,
//! so the model uses the typical figure.

use crate::Pin;

/// The L6398's built-in dead time, ns (typical).
pub const DEAD_TIME_NS: u32 = 320;

/// The two gates of a leg.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Gates {
    pub high: bool,
    pub low: bool,
}

/// Logic level of HIN: an undriven pin is pulled down inside the driver.
pub const fn hin_level(pin: Pin) -> bool {
    matches!(pin, Pin::High)
}

/// Logic level of LIN: an undriven pin is pulled up inside the driver.
pub const fn lin_level(pin: Pin) -> bool {
    !matches!(pin, Pin::Low)
}

/// The truth table: which gate the inputs ask for.
pub const fn demand(hin: bool, lin: bool) -> Gates {
    Gates { high: hin && lin, low: !hin && !lin }
}

/// One driver between timer clocks: how long each gate has been off.
#[derive(Clone, Copy, Debug)]
pub struct GateDriver {
    dead_ticks: u32,
    high_off_for: u32,
    low_off_for: u32,
}

impl GateDriver {
    /// Powered and at rest for a long time; `dead_ticks` is [`DEAD_TIME_NS`] in model clocks.
    pub const fn new(dead_ticks: u32) -> Self {
        Self { dead_ticks, high_off_for: u32::MAX, low_off_for: u32::MAX }
    }

    /// One clock: the gates for these input pins.
    pub fn step(&mut self, hin: Pin, lin: Pin) -> Gates {
        let want = demand(hin_level(hin), lin_level(lin));
        let g = Gates {
            high: want.high && self.low_off_for >= self.dead_ticks,
            low: want.low && self.high_off_for >= self.dead_ticks,
        };
        self.high_off_for = if g.high { 0 } else { self.high_off_for.saturating_add(1) };
        self.low_off_for = if g.low { 0 } else { self.low_off_for.saturating_add(1) };
        g
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_truth_table_and_the_input_pulls() {
        let l = Pin::Low;
        let h = Pin::High;
        let f = Pin::Floating;
        let on = |hin, lin| {
            let mut d = GateDriver::new(0);
            d.step(hin, lin)
        };
        assert_eq!(on(l, l), Gates { high: false, low: true });
        assert_eq!(on(l, h), Gates { high: false, low: false });
        assert_eq!(on(h, l), Gates { high: false, low: false }, "interlock");
        assert_eq!(on(h, h), Gates { high: true, low: false });
        assert_eq!(on(f, f), Gates { high: false, low: false }, "undriven inputs: both off");
    }

    #[test]
    fn the_driver_waits_its_dead_time_after_the_other_gate() {
        let mut d = GateDriver::new(4);
        assert!(d.step(Pin::High, Pin::High).high);
        // Inputs swap at once to "low side on": the low gate waits 4 clocks after the high one.
        let lows: [bool; 6] = core::array::from_fn(|_| d.step(Pin::Low, Pin::Low).low);
        assert_eq!(lows, [false, false, false, false, true, true]);
    }
}
