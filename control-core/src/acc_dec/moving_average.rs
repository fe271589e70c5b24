//! The prior art's acc/dec: one to three cascaded moving averages on pulses per tick, in
//! integer arithmetic. Each stage emits `floor((window sum + remainder) / n)` and keeps the
//! remainder, so every pulse that goes in comes out.

use super::AccDecError;

pub const MAX_MOVING_AVERAGE_STAGES: usize = 3;
/// Longest window (samples); the delay lines are fixed arrays (no allocation).
pub const MAX_MOVING_AVERAGE_LENGTH: u32 = 512;

#[derive(Clone, Copy, Debug, PartialEq)]
struct Stage {
    length: u32,
    window: [i64; MAX_MOVING_AVERAGE_LENGTH as usize],
    next: usize,
    sum: i64,
    remainder: i64,
}

impl Stage {
    fn step(&mut self, x: i64) -> i64 {
        let n = self.length as i64;
        let oldest = core::mem::replace(&mut self.window[self.next], x);
        self.next = (self.next + 1) % self.length as usize;
        // Saturating: far from the bounds for accepted commands (`crate::ranges`), and
        // never wrapping for any other.
        self.sum = self.sum.saturating_add(x.saturating_sub(oldest));
        let total = self.sum.saturating_add(self.remainder);
        self.remainder = total.rem_euclid(n);
        total.div_euclid(n)
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MovingAverageCascade {
    stages: [Stage; MAX_MOVING_AVERAGE_STAGES],
    count: usize,
}

impl MovingAverageCascade {
    /// What [`Self::new`] checks, without building the cascade (its windows are kilobytes).
    pub fn check(lengths: &[u32]) -> Result<(), AccDecError> {
        if lengths.is_empty() || lengths.len() > MAX_MOVING_AVERAGE_STAGES {
            return Err(AccDecError::Stages(lengths.len()));
        }
        for (stage, &length) in lengths.iter().enumerate() {
            if length == 0 || length > MAX_MOVING_AVERAGE_LENGTH {
                return Err(AccDecError::Length { stage: stage + 1, length });
            }
        }
        Ok(())
    }

    /// `lengths`: one window length (samples) per stage, 1 to 3 stages.
    pub fn new(lengths: &[u32]) -> Result<Self, AccDecError> {
        Self::check(lengths)?;
        let empty = Stage { length: 1, window: [0; MAX_MOVING_AVERAGE_LENGTH as usize], next: 0, sum: 0, remainder: 0 };
        let mut stages = [empty; MAX_MOVING_AVERAGE_STAGES];
        for (s, &length) in stages.iter_mut().zip(lengths) {
            s.length = length;
        }
        Ok(Self { stages, count: lengths.len() })
    }

    /// [`Self::new`] of checked `lengths`, built at `cascade` (the windows zeroed where they
    /// are, never on a stack).
    ///
    /// # Safety
    /// `cascade` is valid for writes and aligned; `lengths` passed [`Self::check`].
    #[allow(unsafe_code)]
    pub(super) unsafe fn init(cascade: *mut Self, lengths: &[u32]) {
        use core::ptr::addr_of_mut;
        // SAFETY: the caller's; every field of every stage is written (a window of zeros is
        // valid `i64`s), and the count.
        unsafe {
            let stages = addr_of_mut!((*cascade).stages).cast::<Stage>();
            for i in 0..MAX_MOVING_AVERAGE_STAGES {
                let s = stages.add(i);
                addr_of_mut!((*s).window).write_bytes(0, 1);
                write_fields!(s, Stage {
                    length: lengths.get(i).copied().unwrap_or(1),
                    next: 0,
                    sum: 0,
                    remainder: 0,
                    ; window
                });
            }
            write_fields!(cascade, MovingAverageCascade { count: lengths.len(); stages });
        }
    }

    /// Total delay to the middle of the response: Σ (n − 1)/2 samples.
    pub fn group_delay_samples(&self) -> f32 {
        self.stages[..self.count].iter().map(|s| (s.length - 1) as f32 / 2.0).sum()
    }

    /// Empty every window (no pulse inside, no remainder); lengths are kept.
    pub fn reset(&mut self) {
        for s in &mut self.stages {
            s.window = [0; MAX_MOVING_AVERAGE_LENGTH as usize];
            (s.next, s.sum, s.remainder) = (0, 0, 0);
        }
    }

    /// One tick: `pulses` in, whole pulses out.
    pub fn step(&mut self, pulses: i64) -> i64 {
        let mut v = pulses;
        for s in &mut self.stages[..self.count] {
            v = s.step(v);
        }
        v
    }
}
