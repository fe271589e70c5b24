//! The PRBS mode (seed 001's identification excitation): an M-sequence of ±amplitude chips,
//! one every `prbs_divider` base ticks, measured as one record of `prbs_seconds` after
//! `min_settle_s`. It feeds the same acquisition as the stepped sine; the drive fits nothing
//! (the host identifies the response from the samples).

use super::{PhaseShiftedSweep, SweepParams};

impl SweepParams {
    /// PRBS: settling ticks (a whole number of acquisition periods, at least `min_settle_s`).
    pub(super) fn prbs_settle_ticks(&self, base_rate_hz: f32) -> u64 {
        let d = self.acquisition_divider as u64;
        (libm::ceilf(self.min_settle_s * base_rate_hz / d as f32) as u64).saturating_mul(d)
    }

    /// PRBS: acquisition samples of the measured record (`prbs_seconds`).
    pub(super) fn prbs_samples(&self, base_rate_hz: f32) -> u64 {
        libm::roundf(self.prbs_seconds * base_rate_hz / self.acquisition_divider as f32) as u64
    }
}

impl PhaseShiftedSweep {
    /// The PRBS record starts settling: no frequency, no dither; samples are values, or period
    /// means for the machine-end acceleration measure (whose signals are sampled every base
    /// tick: a point sample would fold the loops' high-frequency torque onto the lowest
    /// frequencies, see `SweepMeasure`).
    // Once per sweep, from `begin_record` (out of line).
    #[inline]
    pub(super) fn begin_prbs_record(&mut self) {
        let ticks = self.params.prbs_settle_ticks(self.base_rate_hz);
        self.set_left(ticks);
        self.status.frequency = 0.0;
        self.averaging = self.params.measure == super::SweepMeasure::MachineAcceleration;
        self.dithering = false;
    }

    /// This tick's PRBS value (a new chip when `chip_due`); the phase is 0.
    // Every tick while the PRBS runs: inlined into `excitation`, as it was written there.
    #[inline(always)]
    pub(super) fn prbs_excitation(&mut self, chip_due: bool) {
        if chip_due {
            self.chip = self.params.amplitude * self.sequence.next_chip() as f32;
        }
        self.value = self.chip;
        self.phase_word = 0;
    }
}
