//! The current sensors' noise and offsets, read while no current flows.
//!
//! A fit of a slow winding's response takes the current's changes from tick to tick, and on a
//! winding slower than a tick those are small beside the sensors' noise, which sits in the
//! regressors and the response alike: the least-squares fit is then biased (by 3 % of the
//! q inductance on a 15 µs rotor on a winding of 78 ticks under 2 mA of noise). Before any
//! voltage is applied the sequence reads both phases for [`super::SENSOR_NOISE_S`] at zero
//! voltage: their noise's variances and covariance (from the readings' changes from tick to
//! tick, which a current still decaying from before or a sensor's offset hardly moves),
//! carried through the Clarke and Park transforms to an axis, give the fit the noise's variance
//! on that axis to take out (`FreeRotorFit::branch_less_noise`).
//!
//! The readings' means are the sensors' offsets, which the sequence takes off every reading
//! after: it starts from a drive at rest, so at zero voltage no current flows but what the
//! current loop held against the offsets before it, a few milliamps decaying over the winding's
//! time constant (on a winding slower than the readings, less of the offsets is taken off).
//! Left in, an offset `o` on a winding of resistance `R` reads as a voltage `R·o` in the holds,
//! beside the inverter's dead-time voltage that the holds give the q fits: 5 mA on 7.3 Ω is
//! 37 mV, three quarters of the twin's dead time, and the q fits of a winding faster than a tick
//! then read its inductance 3 % off.

use crate::reference_frames::{clarke, park};
use crate::trigonometry::sin_cos;

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SensorNoise {
    /// The readings' changes from one tick to the next: white noise of variance σ² changes by
    /// 2σ² a tick, where a current the loop left flowing, decaying over the winding's time
    /// constant, or a sensor's offset changes by next to nothing.
    differences: f32,
    last: Option<[f32; 2]>,
    /// The sums of the changes' products (aa, bb, ab).
    products: [f32; 3],
    /// The readings' sums (a, b); their count is one more than the changes' once one is in.
    sums: [f32; 2],
}

impl SensorNoise {
    pub(super) fn add(&mut self, a: f32, b: f32) {
        self.sums[0] += a;
        self.sums[1] += b;
        if let Some([a0, b0]) = self.last.replace([a, b]) {
            let (da, db) = (a - a0, b - b0);
            self.differences += 1.0;
            self.products[0] += da * da;
            self.products[1] += db * db;
            self.products[2] += da * db;
        }
    }

    /// The phases' noise covariance matrix (aa, bb, ab; A²): half the changes' mean products;
    /// zero before two readings.
    fn covariance(&self) -> [f32; 3] {
        if self.differences < 1.0 {
            return [0.0; 3];
        }
        self.products.map(|p| 0.5 * p / self.differences)
    }

    /// The sensors' offsets (a, b; A): the readings' means; zero before any reading.
    pub(super) fn offsets(&self) -> [f32; 2] {
        if self.last.is_none() {
            return [0.0; 2];
        }
        let readings = self.differences + 1.0;
        self.sums.map(|sum| sum / readings)
    }

    /// The noise's variance on the q axis of the frame at `angle` (rad, electrical; A²).
    pub(super) fn q_variance(&self, angle: f32) -> f32 {
        let (sin, cos) = sin_cos(angle);
        let (ua, ub) = (park(clarke(1.0, 0.0), sin, cos).q, park(clarke(0.0, 1.0), sin, cos).q);
        let [aa, bb, ab] = self.covariance();
        (ua * ua * aa + ub * ub * bb + 2.0 * ua * ub * ab).max(0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Noise of 2 mA on phase a and 3 mA on phase b, with half of a's noise also in b (a
    /// covariance), read on offsets of tens of milliamps and a current of 5 mA on phase a
    /// decaying over 2 000 ticks (left by a loop before): the variance on the q axis of frames at
    /// several angles is the variance of the noise alone carried there (the sample variance of
    /// its q components), within 5 %.
    #[test]
    fn the_phases_noise_is_carried_to_an_axis() {
        let mut noise = super::super::motor_model::Gaussian::new(0x2545_F491_4F6C_DD1D);
        let mut gaussian = || noise.next() as f32;
        let (sa, sb) = (0.002f32, 0.003f32);
        let angles = [0.0f32, 0.5 * core::f32::consts::PI, 1.0, 2.5];
        let mut noise = SensorNoise::default();
        let (mut sums, mut squares) = ([0.0f64; 4], [0.0f64; 4]);
        let samples = 20_000;
        for k in 0..samples {
            let (na, nb) = (sa * gaussian(), sb * gaussian());
            let (na, nb) = (na, nb + 0.5 * na);
            let decaying = 0.005 * libm::expf(-(k as f32) / 2000.0);
            noise.add(0.03 + decaying + na, -0.05 + nb);
            for (j, &angle) in angles.iter().enumerate() {
                let (sin, cos) = sin_cos(angle);
                let q = park(clarke(na, nb), sin, cos).q as f64;
                sums[j] += q;
                squares[j] += q * q;
            }
        }
        for (j, &angle) in angles.iter().enumerate() {
            let n = samples as f64;
            let want = squares[j] / n - (sums[j] / n) * (sums[j] / n);
            let got = noise.q_variance(angle) as f64;
            assert!((got / want - 1.0).abs() < 0.05, "angle {angle}: {got} vs {want}");
        }
        assert_eq!(SensorNoise::default().q_variance(0.0), 0.0);
    }

    /// The offsets are the readings' means: within a few standard errors of the noise's
    /// (2 mA over 256 readings: 0.125 mA) of the offsets put in, and none before any reading.
    #[test]
    fn the_sensors_offsets_are_the_readings_means() {
        let mut noise = super::super::motor_model::Gaussian::new(0x9E37_79B9_7F4A_7C15);
        let mut sensors = SensorNoise::default();
        assert_eq!(sensors.offsets(), [0.0; 2]);
        let offsets = [0.005f32, -0.0045];
        for _ in 0..256 {
            sensors.add(offsets[0] + 0.002 * noise.next() as f32, offsets[1] + 0.002 * noise.next() as f32);
        }
        let got = sensors.offsets();
        for (g, want) in got.iter().zip(offsets) {
            assert!((g - want).abs() < 4.0 * 0.002 / 16.0, "offsets {got:?} vs {offsets:?}");
        }
    }
}
