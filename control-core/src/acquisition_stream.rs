//! Streaming of acquisition samples to the host: the control interrupt offers the sweep's
//! latest sample every tick, the link takes them out in batches. A fixed ring (no allocator);
//! when the link falls behind, the newest samples are dropped and counted, never the order
//! changed, so the host sees a gap it can detect (the tick numbers) and a drop count.

use crate::phase_shifted_sweep::AcquisitionSample;

/// Samples per link frame.
pub const BATCH: usize = 16;
/// Samples held between two batches (64 ms at the 4 kHz acquisition rate).
pub const CAPACITY: usize = 256;

/// One frame's worth of samples.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SampleBatch {
    pub count: u8,
    pub samples: [AcquisitionSample; BATCH],
    /// Samples dropped since streaming was switched on (link too slow).
    pub dropped: u32,
}

#[derive(Clone, Copy, Debug)]
pub struct AcquisitionStream {
    ring: [AcquisitionSample; CAPACITY],
    head: usize,
    len: usize,
    dropped: u32,
    last_tick: Option<u64>,
    enabled: bool,
}

impl Default for AcquisitionStream {
    fn default() -> Self {
        Self {
            ring: [AcquisitionSample::default(); CAPACITY],
            head: 0,
            len: 0,
            dropped: 0,
            last_tick: None,
            enabled: false,
        }
    }
}

impl AcquisitionStream {
    /// Switch streaming on (clears what was held and the drop count) or off.
    pub fn set_enabled(&mut self, on: bool) {
        // The ring's contents are left as they are (only `len` samples from `head` are ever
        // read): the drive does this with interrupts off, where clearing the ring took
        // some 12 000 instructions on the Cortex-M4.
        self.head = 0;
        self.len = 0;
        self.dropped = 0;
        self.enabled = on;
    }

    pub fn enabled(&self) -> bool {
        self.enabled
    }

    /// Offer the latest sample (called every tick): kept once per new acquisition tick.
    pub fn offer(&mut self, sample: &AcquisitionSample) {
        if !self.enabled || self.last_tick == Some(sample.tick) {
            return;
        }
        self.last_tick = Some(sample.tick);
        if self.len == CAPACITY {
            self.dropped = self.dropped.saturating_add(1);
            return;
        }
        self.ring[(self.head + self.len) % CAPACITY] = *sample;
        self.len += 1;
    }

    /// The oldest samples, up to one batch; None when nothing is held.
    pub fn take_batch(&mut self) -> Option<SampleBatch> {
        if self.len == 0 {
            return None;
        }
        let mut b = SampleBatch { dropped: self.dropped, ..SampleBatch::default() };
        let n = self.len.min(BATCH);
        for (i, s) in b.samples[..n].iter_mut().enumerate() {
            *s = self.ring[(self.head + i) % CAPACITY];
        }
        b.count = n as u8;
        self.head = (self.head + n) % CAPACITY;
        self.len -= n;
        Some(b)
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use std::vec::Vec;

    fn sample(tick: u64) -> AcquisitionSample {
        AcquisitionSample { tick, u: tick as f32, ..Default::default() }
    }

    #[test]
    fn samples_come_out_once_in_order_and_overflow_is_counted() {
        let mut s = AcquisitionStream::default();
        s.offer(&sample(1));
        assert_eq!(s.take_batch(), None, "off by default");
        s.set_enabled(true);
        // Every tick offers the latest sample; a new one arrives every 4 ticks.
        for t in 0..4 * (CAPACITY as u64 + 10) {
            s.offer(&sample(t / 4 * 4));
        }
        let mut ticks = Vec::new();
        let mut dropped = 0;
        while let Some(b) = s.take_batch() {
            ticks.extend(b.samples[..b.count as usize].iter().map(|x| x.tick));
            dropped = b.dropped;
        }
        assert_eq!(ticks.len(), CAPACITY);
        assert!(ticks.windows(2).all(|w| w[1] == w[0] + 4), "in order, each once");
        assert_eq!(ticks[0], 0);
        assert_eq!(dropped, 10, "the newest ten did not fit");
        s.set_enabled(false);
        s.offer(&sample(10_000));
        assert_eq!(s.take_batch(), None);
    }
}
