//! One frequency of a measured or modelled frequency response: gain, phase and how clean the
//! measurement was; differences between two responses.

use serde::Serialize;

use num_complex::Complex64;

/// One frequency of a response.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct ResponsePoint {
    pub frequency: f64,
    pub gain_db: f64,
    pub phase_deg: f64,
    /// Fraction of U's AC power at the frequency (1 = a clean sine was seen).
    pub quality: f64,
}

impl ResponsePoint {
    pub fn from_complex(frequency: f64, g: Complex64, quality: f64) -> Self {
        Self { frequency, gain_db: 20.0 * g.norm().log10(), phase_deg: g.arg().to_degrees(), quality }
    }

    /// The response as a complex number (the inverse of [`Self::from_complex`]).
    pub fn to_complex(&self) -> Complex64 {
        Complex64::from_polar(10f64.powf(self.gain_db / 20.0), self.phase_deg.to_radians())
    }
}

/// Gain difference (dB) and phase difference (degrees, wrapped to ±180).
/// Two frequencies name the same point of a sweep: equal within 1e-6 relative (the drive's
/// f32 frequency against the host's f64, or two runs' f32 of the same plan).
pub fn same_frequency(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-6 * a.abs().max(b.abs())
}

pub fn difference(a: &ResponsePoint, b: &ResponsePoint) -> (f64, f64) {
    let dg = a.gain_db - b.gain_db;
    let dp = (a.phase_deg - b.phase_deg + 540.0).rem_euclid(360.0) - 180.0;
    (if dg.is_finite() { dg } else { f64::INFINITY }, if dp.is_finite() { dp } else { f64::INFINITY })
}

#[cfg(test)]
mod tests {
    use super::same_frequency;

    /// A frequency and its f32 round trip are the same point; neighbours of a plan are not.
    #[test]
    fn a_frequency_and_its_f32_copy_are_the_same_point() {
        for f in [10.0f64, 1934.5214, 2239.2, 3000.0] {
            assert!(same_frequency(f, f as f32 as f64) && same_frequency(f as f32 as f64, f));
            assert!(!same_frequency(f, f * 1.01) && !same_frequency(f, 0.0));
        }
    }
}
