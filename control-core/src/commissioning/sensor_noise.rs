//! The current sensors' noise, read while no current flows.
//!
//! A fit of a slow winding's response takes the current's changes from tick to tick, and on a
//! winding slower than a tick those are small beside the sensors' noise, which sits in the
//! regressors and the response alike: the least-squares fit is then biased (by 3 % of the
//! q inductance on a 15 µs rotor on a winding of 78 ticks under 2 mA of noise). Before any
//! voltage is applied the sequence reads both phases for [`super::SENSOR_NOISE_S`] at zero
//! voltage; their variances and covariance, carried through the Clarke and Park transforms to
//! an axis, give the fit the noise's variance on that axis to take out
//! (`FreeRotorFit::branch_less_noise`).

use crate::reference_frames::{clarke, park};
use crate::trigonometry::sin_cos;

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SensorNoise {
    samples: f32,
    /// The first reading of each phase (the sums are taken relative to it: a sensor's offset
    /// dwarfs its noise), the sums of the deviations and of their products (aa, bb, ab).
    first: Option<[f32; 2]>,
    sums: [f32; 2],
    products: [f32; 3],
}

impl SensorNoise {
    pub(super) fn add(&mut self, a: f32, b: f32) {
        let [a0, b0] = *self.first.get_or_insert([a, b]);
        let (da, db) = (a - a0, b - b0);
        self.samples += 1.0;
        self.sums[0] += da;
        self.sums[1] += db;
        self.products[0] += da * da;
        self.products[1] += db * db;
        self.products[2] += da * db;
    }

    /// The phases' covariance matrix (aa, bb, ab; A²); zero before two readings.
    fn covariance(&self) -> [f32; 3] {
        if self.samples < 2.0 {
            return [0.0; 3];
        }
        let n = self.samples;
        let [sa, sb] = self.sums;
        let [aa, bb, ab] = self.products;
        let unbiased = n / (n - 1.0);
        [
            unbiased * (aa / n - (sa / n) * (sa / n)),
            unbiased * (bb / n - (sb / n) * (sb / n)),
            unbiased * (ab / n - (sa / n) * (sb / n)),
        ]
    }

    /// The noise's variance on the q axis of the frame at `angle` (rad, electrical; A²).
    pub(super) fn q_variance(&self, angle: f32) -> f32 {
        let (sin, cos) = sin_cos(angle);
        let (ua, ub) = (park(clarke(1.0, 0.0), sin, cos).q, park(clarke(0.0, 1.0), sin, cos).q);
        let [aa, bb, ab] = self.covariance();
        (ua * ua * aa + ub * ub * bb + 2.0 * ua * ub * ab).max(0.0)
    }

    /// The noise's variance on an axis that turns through every angle (its mean over them).
    pub(super) fn turning_variance(&self) -> f32 {
        let quarter = 0.5 * core::f32::consts::PI;
        0.5 * (self.q_variance(0.0) + self.q_variance(quarter))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Independent noise of 2 mA and 3 mA on phases a and b, on offsets of tens of milliamps:
    /// the q axis at angle 0 takes β = (a + 2b)/√3, so its variance is (σa² + 4σb²)/3; at a
    /// quarter turn it takes −α = −a (σa²); turning, their mean.
    #[test]
    fn the_phases_noise_is_carried_to_an_axis() {
        let mut noise = SensorNoise::default();
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut gaussian = || {
            // Irwin–Hall: twelve uniforms less 6, unit variance.
            let mut sum = 0.0f32;
            for _ in 0..12 {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                sum += (state >> 40) as f32 / (1u64 << 24) as f32;
            }
            sum - 6.0
        };
        let (sa, sb) = (0.002f32, 0.003f32);
        for _ in 0..20_000 {
            let (a, b) = (0.03 + sa * gaussian(), -0.05 + sb * gaussian());
            noise.add(a, b);
        }
        let close = |got: f32, want: f32| assert!((got / want - 1.0).abs() < 0.05, "{got} vs {want}");
        close(noise.q_variance(0.0), (sa * sa + 4.0 * sb * sb) / 3.0);
        close(noise.q_variance(0.5 * core::f32::consts::PI), sa * sa);
        close(noise.turning_variance(), 0.5 * ((sa * sa + 4.0 * sb * sb) / 3.0 + sa * sa));
        assert_eq!(SensorNoise::default().q_variance(0.0), 0.0);
    }
}
