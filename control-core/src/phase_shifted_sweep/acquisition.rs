//! The acquisition sample: u, y and the excitation's phase on an acquisition tick, with the
//! point, record and half block it belongs to (what the drive streams to the host).

/// The last acquisition sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct AcquisitionSample {
    /// Base tick of the sample.
    pub tick: u64,
    pub u: f32,
    pub y: f32,
    /// Excitation phase at the sample (rad, [0, 2π)); 0 in PRBS mode.
    pub phase: f32,
    /// The sample belongs to a measured record.
    pub measuring: bool,
    /// The drive's output was limited on a tick of this sample's acquisition period (the
    /// voltage circle cut what the current loop asked for; see
    /// [`PhaseShiftedSweep::end_tick`](super::PhaseShiftedSweep::end_tick)): a host fitting
    /// the stream counts each result's share of them itself, as the drive's correlator does.
    pub limited: bool,
    pub point: u32,
    /// The record (phase-shifted repeat, low 16 bits) and the half block (high 16 bits) the
    /// sample belongs to: see [`Self::record`] and [`Self::half_block`]. One word, as the
    /// record alone was: the sample stays as it was on the tick and on the link.
    pub segment: u32,
}

impl AcquisitionSample {
    /// The word of [`Self::segment`].
    pub fn segment_of(record: u32, half_block: u32) -> u32 {
        (record & 0xFFFF) | (half_block.min(0xFFFF) << 16)
    }

    /// Record (phase-shifted repeat) the sample belongs to.
    pub fn record(&self) -> u32 {
        self.segment & 0xFFFF
    }

    /// Half block of the frequency's first record the sample belongs to (see
    /// `PhaseShiftedSweep::settled`; later samples keep the last index). The response is
    /// fitted to the samples from the frequency's last index minus one up.
    pub fn half_block(&self) -> u32 {
        self.segment >> 16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_acquisition_sample_stays_32_bytes() {
        // The acquisition stream buffers 256 of them.
        assert!(core::mem::size_of::<AcquisitionSample>() <= 32);
    }
}
