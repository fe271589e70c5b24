//! Incremental-encoder tracking: a wrapping hardware counter turned into an unbounded
//! position and the electrical angle.

use core::num::NonZeroU32;

use crate::TAU;

#[derive(Clone, Copy, Debug)]
pub struct EncoderTracker {
    last_raw: i32,
    position: i64,
    /// `position` modulo the counts per revolution, kept up to date with the small per-tick
    /// steps (a 64-bit remainder every tick is software on a Cortex-M4).
    within_rev: u32,
    started: bool,
    /// Non-zero: the remainders need no check for a zero divisor.
    counts_per_rev: NonZeroU32,
    /// `counts_per_rev` as f32 (for the electrical angle).
    revolution: f32,
    pole_pairs: u32,
}

/// What one encoder update found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncoderUpdate {
    Ok,
    /// The count moved by more than half a revolution in one tick: a lost or corrupt encoder.
    Jump,
}

impl EncoderTracker {
    /// A tracker for an encoder of `counts_per_rev` on a motor of `pole_pairs`; its first
    /// update sets the position.
    pub fn new(counts_per_rev: NonZeroU32, pole_pairs: u32) -> Self {
        Self {
            last_raw: 0,
            position: 0,
            within_rev: 0,
            started: false,
            counts_per_rev,
            revolution: counts_per_rev.get() as f32,
            pole_pairs,
        }
    }

    /// Accumulated position in counts since the first update (the first raw value is zero).
    pub fn position(&self) -> i64 {
        self.position
    }

    /// Feed the raw (wrapping 32-bit) counter value.
    pub fn update(&mut self, raw: i32) -> EncoderUpdate {
        let counts_per_rev = self.counts_per_rev.get();
        let cpr = counts_per_rev as i64;
        if !self.started {
            self.started = true;
            self.last_raw = raw;
            self.position = raw as i64;
            self.within_rev = self.position.rem_euclid(cpr) as u32;
            return EncoderUpdate::Ok;
        }
        let delta = raw.wrapping_sub(self.last_raw) as i64;
        self.last_raw = raw;
        self.position = self.position.saturating_add(delta);
        let w = self.within_rev as i64 + delta;
        self.within_rev = if (0..cpr).contains(&w) {
            w as u32
        } else if (-cpr..0).contains(&w) {
            (w + cpr) as u32
        } else if (cpr..2 * cpr).contains(&w) {
            (w - cpr) as u32
        } else {
            self.position.rem_euclid(cpr) as u32
        };
        if delta.unsigned_abs() > (counts_per_rev / 2) as u64 {
            EncoderUpdate::Jump
        } else {
            EncoderUpdate::Ok
        }
    }

    /// Electrical angle in `[0, 2π)`, assuming count 0 is electrical zero.
    pub fn electrical_angle(&self) -> f32 {
        // (count · p) mod cpr stays exact in integers: within_rev < 2²⁴ and p ≤ 64 (validated),
        // so the product fits 32 bits.
        let e = (self.within_rev * self.pole_pairs) % self.counts_per_rev;
        TAU * (e as f32 / self.revolution)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tracker(counts_per_rev: u32, pole_pairs: u32) -> EncoderTracker {
        EncoderTracker::new(NonZeroU32::new(counts_per_rev).unwrap(), pole_pairs)
    }

    #[test]
    fn accumulates_across_counter_wrap() {
        let mut e = tracker(1 << 20, 4);
        e.update(i32::MAX - 5);
        assert_eq!(e.update(i32::MIN + 4), EncoderUpdate::Ok);
        assert_eq!(e.position(), i32::MAX as i64 + 5);
    }

    #[test]
    fn flags_jumps_over_half_a_revolution() {
        let mut e = tracker(1000, 4);
        e.update(0);
        assert_eq!(e.update(600), EncoderUpdate::Jump);
    }

    #[test]
    fn electrical_angle_turns_pole_pairs_times_per_revolution() {
        let mut e = tracker(1000, 4);
        e.update(0);
        e.update(125); // 1/8 rev, 4 pole pairs → half an electrical turn
        assert!((e.electrical_angle() - core::f32::consts::PI).abs() < 1e-6);
    }
}
