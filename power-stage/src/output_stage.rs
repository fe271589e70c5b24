//! Model of one TIM1 channel's output stage: OCxREF through the dead-time generator, the
//! enables and polarities, and the master output enable with its off-state selection — RM0440's
//! table "Output control bits for complementary OCx and OCxN channels with break feature",
//! read row by row:
//!
//! | MOE | OSSI | OSSR | CCxE | CCxNE | OCx | OCxN |
//! |---|---|---|---|---|---|---|
//! | 1 | x | x | 0 | 0 | not driven | not driven |
//! | 1 | x | 0 | 1 | 0 | OCxREF ⊕ CCxP | not driven |
//! | 1 | x | 0 | 0 | 1 | not driven | OCxREF ⊕ CCxNP |
//! | 1 | x | 1 | 1 | 0 | OCxREF ⊕ CCxP | inactive (CCxNP) |
//! | 1 | x | 1 | 0 | 1 | inactive (CCxP) | OCxREF ⊕ CCxNP |
//! | 1 | x | x | 1 | 1 | OCxREF delayed by the dead time ⊕ CCxP | complement of OCxREF delayed by the dead time ⊕ CCxNP |
//! | 0 | 0 | x | any | any | not driven | not driven |
//! | 0 | 1 | x | 0 | 0 | not driven | not driven |
//! | 0 | 1 | x | else | | CCxP at once, OISx after a dead time | CCxNP at once, OISxN after a dead time |
//!
//! "Not driven" leaves the pin to whatever pulls it (the gate driver's own input resistors).
//! Dead time: OCx rises only once OCxREF has been high for longer than the dead time, OCxN
//! only once it has been low that long; a pulse shorter than the dead time is lost.

use crate::tim1_words::{ccer_e, ccer_ne, ccer_np, ccer_p, cr2_ois, cr2_oisn, BDTR_OSSI, BDTR_OSSR};
use crate::Pin;

/// The bits of one channel (0-based) that decide its two outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ChannelBits {
    pub enable: bool,
    pub polarity: bool,
    pub n_enable: bool,
    pub n_polarity: bool,
    pub idle: bool,
    pub n_idle: bool,
    pub ossi: bool,
    pub ossr: bool,
}

impl ChannelBits {
    pub const fn from_words(ccer: u32, cr2: u32, bdtr: u32, ch: usize) -> ChannelBits {
        ChannelBits {
            enable: ccer & ccer_e(ch) != 0,
            polarity: ccer & ccer_p(ch) != 0,
            n_enable: ccer & ccer_ne(ch) != 0,
            n_polarity: ccer & ccer_np(ch) != 0,
            idle: cr2 & cr2_ois(ch) != 0,
            n_idle: cr2 & cr2_oisn(ch) != 0,
            ossi: bdtr & BDTR_OSSI != 0,
            ossr: bdtr & BDTR_OSSR != 0,
        }
    }
}

/// One channel's state between timer clocks: how long OCxREF has been high or low, how long
/// MOE has been 0.
#[derive(Clone, Copy, Debug)]
pub struct ChannelOutput {
    ref_high_for: u32,
    ref_low_for: u32,
    off_for: u32,
}

impl Default for ChannelOutput {
    fn default() -> Self {
        Self::new()
    }
}

impl ChannelOutput {
    /// At rest: OCxREF low and MOE 0 for a long time.
    pub const fn new() -> Self {
        Self { ref_high_for: 0, ref_low_for: u32::MAX, off_for: u32::MAX }
    }

    /// One timer clock: the pin levels of OCx and OCxN.
    pub fn step(&mut self, ocref: bool, moe: bool, b: ChannelBits, dead_ticks: u32) -> (Pin, Pin) {
        if ocref {
            self.ref_high_for = self.ref_high_for.saturating_add(1);
            self.ref_low_for = 0;
        } else {
            self.ref_low_for = self.ref_low_for.saturating_add(1);
            self.ref_high_for = 0;
        }
        self.off_for = if moe { 0 } else { self.off_for.saturating_add(1) };
        let level = Pin::from_level;
        if moe {
            match (b.enable, b.n_enable) {
                (false, false) => (Pin::Floating, Pin::Floating),
                (true, true) => {
                    let oc = self.ref_high_for > dead_ticks;
                    let ocn = self.ref_low_for > dead_ticks;
                    (level(oc != b.polarity), level(ocn != b.n_polarity))
                }
                (true, false) => {
                    let n = if b.ossr { level(b.n_polarity) } else { Pin::Floating };
                    (level(ocref != b.polarity), n)
                }
                (false, true) => {
                    let p = if b.ossr { level(b.polarity) } else { Pin::Floating };
                    (p, level(ocref != b.n_polarity))
                }
            }
        } else if !b.ossi || (!b.enable && !b.n_enable) {
            (Pin::Floating, Pin::Floating)
        } else if self.off_for > dead_ticks {
            (level(b.idle), level(b.n_idle))
        } else {
            (level(b.polarity), level(b.n_polarity))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn both(polarity: bool, n_polarity: bool) -> ChannelBits {
        ChannelBits {
            enable: true,
            polarity,
            n_enable: true,
            n_polarity,
            idle: false,
            n_idle: true,
            ossi: true,
            ossr: true,
        }
    }

    #[test]
    fn complementary_outputs_with_dead_time_at_both_edges() {
        let mut c = ChannelOutput::new();
        let b = both(false, false);
        let mut trace = [(Pin::Floating, Pin::Floating); 20];
        for (k, t) in trace.iter_mut().enumerate() {
            *t = c.step((5..12).contains(&k), true, b, 3);
        }
        // REF high at 5..12: OCx high at 8..12 (3 clocks late), OCxN low from 5 to 14.
        for (k, (p, n)) in trace.iter().enumerate() {
            assert_eq!(*p == Pin::High, (8..12).contains(&k), "OCx at {k}");
            assert_eq!(*n == Pin::High, !(5..15).contains(&k), "OCxN at {k}");
        }
    }

    #[test]
    fn a_pulse_shorter_than_the_dead_time_is_lost() {
        let mut c = ChannelOutput::new();
        for k in 0..10 {
            let (p, _) = c.step(k == 4 || k == 5, true, both(false, false), 3);
            assert_eq!(p, Pin::Low);
        }
    }

    #[test]
    fn with_moe_0_the_off_state_follows_ossi() {
        let mut c = ChannelOutput::new();
        let b = ChannelBits { idle: true, n_idle: false, ..both(false, true) };
        // Inactive levels at once, idle levels after the dead time.
        assert_eq!(c.step(true, false, b, 2), (Pin::High, Pin::Low), "long off: idle levels");
        let mut c = ChannelOutput::new();
        c.step(true, true, b, 2);
        assert_eq!(c.step(true, false, b, 2), (Pin::Low, Pin::High), "inactive levels first");
        c.step(true, false, b, 2);
        assert_eq!(c.step(true, false, b, 2), (Pin::High, Pin::Low), "then OISx / OISxN");
        let not_driven = ChannelBits { ossi: false, ..b };
        assert_eq!(c.step(true, false, not_driven, 2), (Pin::Floating, Pin::Floating));
    }
}
