//! Streaming of acquisition samples to the host: the control interrupt offers the sweep's
//! latest sample every tick, the link takes them out in batches. A fixed ring (no allocator);
//! when the link falls behind, the newest samples are dropped and counted, never the order
//! changed, so the host sees a gap it can detect (the tick numbers) and a drop count.

use crate::phase_shifted_sweep::AcquisitionSample;
use core::mem::MaybeUninit;

/// Samples per link frame.
pub const BATCH: usize = 16;
/// Samples held between two batches (64 ms at the 4 kHz acquisition rate).
pub const CAPACITY: usize = 256;

/// One frame's worth of samples.
///
/// On the link (protocol version 5 and on) a batch is `dropped`, then a sequence of its `count`
/// samples only, each tick sent as the (signed) difference from the one before (the first
/// from 0),
/// the record and the half block as two varints, `measuring` and (version 8) `limited` as
/// two bits of one byte: about 17 bytes a sample, nothing for an empty slot. Version 4 sent
/// all 16 slots and whole ticks: at the link task's 2 ms poll a 4 kHz stream went out 8
/// samples a frame at 37 bytes each, more than a 921 600 Bd line carries.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SampleBatch {
    pub count: u8,
    pub samples: [AcquisitionSample; BATCH],
    /// Samples dropped since streaming was switched on (link too slow).
    pub dropped: u32,
}

/// Flag bits of a sample on the link: it belongs to a measured record; the drive's output
/// was limited during its acquisition period (see [`AcquisitionSample::limited`]). Other
/// bits are refused.
pub const SAMPLE_MEASURING: u8 = 1;
pub const SAMPLE_LIMITED: u8 = 2;

/// A sample as it crosses the link.
#[derive(serde::Serialize, serde::Deserialize)]
struct WireSample {
    /// Ticks since the batch's previous sample (the first: since tick 0); signed, so that a
    /// batch that straddles a new axis (its ticks restart at 0 after `SetParams`) still goes
    /// out whole.
    tick_step: i64,
    u: f32,
    y: f32,
    phase: f32,
    /// [`SAMPLE_MEASURING`] and [`SAMPLE_LIMITED`]: one byte, as the `measuring` flag alone
    /// took up to version 7 (the stream's size on the line is unchanged).
    flags: u8,
    point: u32,
    /// The two halves of [`AcquisitionSample::segment`], each a short varint.
    record: u32,
    half_block: u32,
}

impl serde::Serialize for SampleBatch {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        use serde::ser::{Error, SerializeSeq, SerializeTuple};
        struct Samples<'a>(&'a [AcquisitionSample]);
        impl serde::Serialize for Samples<'_> {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                let mut seq = s.serialize_seq(Some(self.0.len()))?;
                let mut previous = 0u64;
                for x in self.0 {
                    // Two's complement: the step is exact for any two ticks below 2⁶³.
                    let tick_step = x.tick.wrapping_sub(previous) as i64;
                    previous = x.tick;
                    let w = WireSample {
                        tick_step,
                        u: x.u,
                        y: x.y,
                        phase: x.phase,
                        flags: if x.measuring { SAMPLE_MEASURING } else { 0 }
                            | if x.limited { SAMPLE_LIMITED } else { 0 },
                        point: x.point,
                        record: x.record(),
                        half_block: x.half_block(),
                    };
                    seq.serialize_element(&w)?;
                }
                seq.end()
            }
        }
        let samples =
            self.samples.get(..self.count as usize).ok_or_else(|| S::Error::custom("count above the batch"))?;
        let mut t = s.serialize_tuple(2)?;
        t.serialize_element(&self.dropped)?;
        t.serialize_element(&Samples(samples))?;
        t.end()
    }
}

impl<'de> serde::Deserialize<'de> for SampleBatch {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        use serde::de::{Error, SeqAccess, Visitor};
        /// The samples of a batch: at most [`BATCH`] (a longer sequence is refused).
        struct Samples(SampleBatch);
        impl<'de> serde::Deserialize<'de> for Samples {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                struct V;
                impl<'de> Visitor<'de> for V {
                    type Value = Samples;
                    fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                        write!(f, "at most {BATCH} samples")
                    }
                    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Samples, A::Error> {
                        let mut b = SampleBatch::default();
                        let mut tick = 0u64;
                        while let Some(w) = seq.next_element::<WireSample>()? {
                            let slot = b
                                .samples
                                .get_mut(b.count as usize)
                                .ok_or_else(|| A::Error::invalid_length(BATCH + 1, &self))?;
                            tick = tick
                                .checked_add_signed(w.tick_step)
                                .ok_or_else(|| A::Error::custom("tick out of range"))?;
                            if w.flags & !(SAMPLE_MEASURING | SAMPLE_LIMITED) != 0 {
                                return Err(A::Error::custom("unknown sample flags"));
                            }
                            *slot = AcquisitionSample {
                                tick,
                                u: w.u,
                                y: w.y,
                                phase: w.phase,
                                measuring: w.flags & SAMPLE_MEASURING != 0,
                                limited: w.flags & SAMPLE_LIMITED != 0,
                                point: w.point,
                                segment: AcquisitionSample::segment_of(w.record, w.half_block),
                            };
                            b.count += 1;
                        }
                        Ok(Samples(b))
                    }
                }
                d.deserialize_seq(V)
            }
        }
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = SampleBatch;
            fn expecting(&self, f: &mut core::fmt::Formatter) -> core::fmt::Result {
                write!(f, "a sample batch")
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<SampleBatch, A::Error> {
                let dropped: u32 = seq.next_element()?.ok_or_else(|| A::Error::invalid_length(0, &self))?;
                let Samples(b) = seq.next_element()?.ok_or_else(|| A::Error::invalid_length(1, &self))?;
                Ok(SampleBatch { dropped, ..b })
            }
        }
        d.deserialize_tuple(2, V)
    }
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
    /// [`Self::default`] built in `slot`, where it lives (the ring is kilobytes: a drive never
    /// holds one on a stack).
    #[allow(unsafe_code)]
    pub fn new_in(slot: &mut MaybeUninit<Self>) -> &mut Self {
        let stream = slot.as_mut_ptr();
        // SAFETY: `slot` is valid for writes and aligned; every sample of the ring and every
        // other field is written.
        unsafe {
            let ring = core::ptr::addr_of_mut!((*stream).ring).cast::<AcquisitionSample>();
            for i in 0..CAPACITY {
                ring.add(i).write(AcquisitionSample::default());
            }
            write_fields!(stream, AcquisitionStream {
                head: 0,
                len: 0,
                dropped: 0,
                last_tick: None,
                enabled: false,
                ; ring
            });
            slot.assume_init_mut()
        }
    }

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
