//! Incremental-encoder tracking: a wrapping hardware counter turned into an unbounded
//! position and the electrical angle, in the motor's direction and from its electrical zero
//! (the encoder's mounting, which commissioning measures).

use core::num::NonZeroU32;

use crate::params::EncoderMounting;
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
    /// All ones for a reversed counter (its counts negated: `(raw ^ m) − m`), else 0.
    reverse_mask: i32,
    /// The electrical offset in counts of an electrical turn (`counts_per_rev` of them).
    offset_counts: u32,
}

/// What one encoder update found.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum EncoderUpdate {
    Ok,
    /// The count moved by more than half a revolution in one tick: a lost or corrupt encoder.
    Jump,
}

impl EncoderTracker {
    /// A tracker for an encoder of `counts_per_rev` mounted as `mounting` on a motor of
    /// `pole_pairs`; its first update sets the position. The offset is kept to a count of an
    /// electrical turn (`2π/counts_per_rev`: finer than the angle's own step, `2π·p/cpr`).
    pub fn new(counts_per_rev: NonZeroU32, pole_pairs: u32, mounting: &EncoderMounting) -> Self {
        let cpr = counts_per_rev.get();
        let offset = libm::roundf(mounting.electrical_offset / TAU * cpr as f32) as u32 % cpr;
        Self {
            last_raw: 0,
            position: 0,
            within_rev: 0,
            started: false,
            counts_per_rev,
            revolution: counts_per_rev.get() as f32,
            pole_pairs,
            reverse_mask: if mounting.reversed { -1 } else { 0 },
            offset_counts: offset,
        }
    }

    /// Accumulated position in counts since the first update (the first raw value is zero).
    pub fn position(&self) -> i64 {
        self.position
    }

    /// Feed the raw (wrapping 32-bit) counter value (negated for a reversed counter).
    pub fn update(&mut self, raw: i32) -> EncoderUpdate {
        let raw = (raw ^ self.reverse_mask).wrapping_sub(self.reverse_mask);
        let counts_per_rev = self.counts_per_rev.get();
        let cpr = counts_per_rev as i64;
        if !self.started {
            self.started = true;
            self.last_raw = raw;
            self.position = raw as i64;
            self.within_rev = self.position.rem_euclid(cpr) as u32;
            return EncoderUpdate::Ok;
        }
        let delta = raw.wrapping_sub(self.last_raw);
        self.last_raw = raw;
        self.position = self.position.saturating_add(delta as i64);
        // Half a revolution or less (every tick of a working encoder), in 32-bit arithmetic:
        // `within_rev + delta` lies in (−cpr/2, 3·cpr/2), one wrap at most (cpr ≤ 2³⁰ keeps it
        // in a u32 read as wrapping). Further, a jump: the remainder of the position.
        let jump = delta.unsigned_abs() > counts_per_rev / 2;
        self.within_rev = if !jump && counts_per_rev <= 1 << 30 {
            let w = self.within_rev.wrapping_add(delta as u32);
            if delta < 0 && w > self.within_rev {
                w.wrapping_add(counts_per_rev)
            } else if w >= counts_per_rev {
                w - counts_per_rev
            } else {
                w
            }
        } else {
            self.position.rem_euclid(cpr) as u32
        };
        if jump {
            EncoderUpdate::Jump
        } else {
            EncoderUpdate::Ok
        }
    }

    /// Electrical angle in `[0, 2π)`: the mounting's offset at count 0.
    pub fn electrical_angle(&self) -> f32 {
        // (count · p + offset) mod cpr stays exact in integers: within_rev and the offset are
        // under 2²⁴ and p ≤ 64 (validated), so the sum fits 32 bits.
        let e = (self.within_rev * self.pole_pairs + self.offset_counts) % self.counts_per_rev;
        TAU * (e as f32 / self.revolution)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tracker(counts_per_rev: u32, pole_pairs: u32) -> EncoderTracker {
        EncoderTracker::new(NonZeroU32::new(counts_per_rev).unwrap(), pole_pairs, &EncoderMounting::default())
    }

    /// The revolution's count follows the position's remainder over any steps: small ones
    /// both ways, wraps of the counter, jumps of any size, on encoders of 4 to 2²⁴ counts.
    #[test]
    fn the_count_within_the_revolution_is_the_positions_remainder_for_any_steps() {
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut next = || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            state
        };
        for cpr in [4u32, 5, 1000, 4096, 10_000, 1 << 24] {
            let mut t = tracker(cpr, 1);
            let mut raw = (next() as i32).wrapping_mul(7);
            for _ in 0..20_000 {
                let r = next();
                let step = match r % 4 {
                    0 => (r >> 8) as i32 % (cpr as i32 / 2 + 1),
                    1 => -((r >> 8) as i32 % (cpr as i32 / 2 + 1)),
                    2 => (r >> 8) as i32, // anything, jumps included
                    _ => 1,
                };
                raw = raw.wrapping_add(step);
                t.update(raw);
                assert_eq!(t.within_rev as i64, t.position().rem_euclid(cpr as i64), "cpr {cpr}");
            }
        }
    }

    #[test]
    fn accumulates_across_counter_wrap() {
        let mut e = tracker(1 << 20, 4);
        e.update(i32::MAX - 5);
        assert_eq!(e.update(i32::MIN + 4), EncoderUpdate::Ok);
        assert_eq!(e.position(), i32::MAX as i64 + 5);
    }

    /// A mounting's direction and offset: the angle is `±count·p·2π/cpr + offset` (mod 2π)
    /// within the offset's step of a count of an electrical turn, the position in the motor's
    /// direction.
    #[test]
    fn a_mounting_turns_the_counts_into_the_motor_s_direction_and_electrical_zero() {
        for (cpr, p) in [(4000u32, 4u32), (1 << 20, 4), (1024, 12), (16384, 1)] {
            for reversed in [false, true] {
                for offset in [0.0f32, 0.5, 2.0, 6.2] {
                    let m = EncoderMounting { reversed, electrical_offset: offset };
                    let mut t = EncoderTracker::new(NonZeroU32::new(cpr).unwrap(), p, &m);
                    for raw in [0i32, 1, 17, -5, 1234, -99_999, 7_777_777] {
                        t.update(raw);
                        let counts = if reversed { -(raw as f64) } else { raw as f64 };
                        assert_eq!(t.position() as f64, counts);
                        let want = (counts * p as f64 / cpr as f64 * core::f64::consts::TAU + offset as f64)
                            .rem_euclid(core::f64::consts::TAU);
                        let error = libm::remainder(t.electrical_angle() as f64 - want, core::f64::consts::TAU);
                        let step = core::f64::consts::TAU / cpr as f64;
                        assert!(error.abs() <= 0.5 * step + 1e-5, "cpr {cpr} p {p} {m:?} raw {raw}: {error}");
                    }
                }
            }
        }
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
