//! Precision control: how many half blocks every record of a frequency adds for its
//! response to meet `precision_db` (see [`PhaseShiftedSweep::halves_needed`]).

use super::PhaseShiftedSweep;
use crate::TAU;

impl PhaseShiftedSweep {
    /// Extra half blocks per record (at most
    /// [`SweepParams::half_block_cap`](super::SweepParams::half_block_cap): `2·max_extensions`
    /// of the full block) for the standard errors of the response, gain's and phase's, to reach
    /// `precision_db` (the phase's: the same relative size, `precision_db·ln10/20`
    /// rad, 0.2° at 0.03 dB) over all `records`, predicted from the first base block (error ∝
    /// 1/√samples).
    // Once per record or frequency: kept out of line so that the every-tick path stays small.
    #[inline(never)]
    pub(super) fn halves_needed(&self, records: u32) -> u32 {
        let p = &self.params;
        if !(p.precision_db > 0.0) || p.max_extensions == 0 {
            return 0;
        }
        let turns = self.status.frequency * p.acquisition_divider as f32 / self.base_rate_hz;
        let step = TAU * (turns - libm::floorf(turns));
        let Some(error) = self.acc.response_error(step) else { return 0 };
        let target = p.precision_db * (core::f32::consts::LN_10 / 20.0);
        let ratio = error.gain.max(error.phase) / target;
        // Half blocks per record (the base block is two).
        let halves = libm::ceilf(2.0 * ratio * ratio / records as f32);
        let cap = p.half_block_cap(self.status.frequency, self.base_rate_hz);
        // Compared as floats: a huge ratio must not wrap in the conversion.
        if halves <= 2.0 {
            0
        } else if halves > (cap + 2) as f32 {
            cap
        } else {
            halves as u32 - 2
        }
    }
}
