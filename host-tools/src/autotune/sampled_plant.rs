//! A plant sampled once on the design grid, and the open loops of tunings on it: what the
//! design's ladder, its refinements and the margins of a tuning all evaluate.

use num_complex::Complex64;

use super::design::design_grid;
use super::margins::{margins, Margins};
use super::velocity_controller::{unit_circle, VelocityTuning};

pub struct SampledPlant {
    /// The grid (Hz) and the plant on it.
    pub hz: Vec<f64>,
    pub response: Vec<Complex64>,
    /// The velocity loop's period (s).
    pub period: f64,
    /// The grid's points on the unit circle (`e^{j·2π·f·T}`).
    pub z: Vec<Complex64>,
}

impl SampledPlant {
    /// `plant` on the design grid of `points` points with `features` (Hz) in it.
    pub fn new(plant: &dyn Fn(f64) -> Complex64, period: f64, points: usize, features: &[f64]) -> Self {
        let hz = design_grid(period, points, features);
        let response = hz.iter().map(|&f| plant(f)).collect();
        let z = hz.iter().map(|&f| unit_circle(f, period)).collect();
        Self { hz, response, period, z }
    }

    /// The open loop `L = C·P` of `tuning` on the grid.
    pub fn loop_of(&self, tuning: &VelocityTuning) -> Vec<Complex64> {
        let c = tuning.at_period(self.period);
        self.z.iter().zip(&self.response).map(|(&z, p)| c.at(z) * p).collect()
    }

    /// The margins of `tuning` on the grid.
    pub fn margins_of(&self, tuning: &VelocityTuning) -> Option<Margins> {
        margins(&self.hz, &self.loop_of(tuning))
    }
}
