//! The velocity loop's controller as the drive runs it: the PI `kp + ki·T·z/(z − 1)` at the
//! velocity rate, then the torque command's low-pass and two notches (the drive's own biquads,
//! `control_core::biquad`, their coefficients evaluated on the unit circle), and the FMU
//! parameters that set it.

use std::collections::BTreeMap;

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use control_core::biquad::Biquad;

/// The torque notch: centre (Hz), quality factor, gain at the centre (0 full, 1 none).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Notch {
    pub hz: f64,
    pub q: f64,
    pub depth: f64,
}

impl Notch {
    /// A notch switched off (the drive's parameters for no notch).
    pub const OFF: Notch = Notch { hz: 0.0, q: 1.0, depth: 0.0 };
}

/// Velocity-loop gains and torque filters (a low-pass of 0 Hz is off).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct VelocityTuning {
    /// N·m per rad/s, N·m per rad.
    pub kp: f64,
    pub ki: f64,
    pub low_pass_hz: f64,
    pub notch: Option<Notch>,
    /// The second notch, after the first: for a second resonance above the crossover, or a
    /// broad, shallow notch below it that shapes the loop's phase (`design::shaping_notches`).
    #[serde(default)]
    pub notch2: Option<Notch>,
}

impl VelocityTuning {
    /// The drive's gains and filters in `p`.
    pub fn of_params(p: &control_core::Params) -> Self {
        let f = &p.filters;
        Self {
            kp: p.velocity.kp as f64,
            ki: p.velocity.ki as f64,
            low_pass_hz: f.low_pass_hz as f64,
            notch: (f.notch_hz > 0.0).then_some(Notch {
                hz: f.notch_hz as f64,
                q: f.notch_q as f64,
                depth: f.notch_depth as f64,
            }),
            notch2: (f.notch2_hz > 0.0).then_some(Notch {
                hz: f.notch2_hz as f64,
                q: f.notch2_q as f64,
                depth: f.notch2_depth as f64,
            }),
        }
    }

    /// Torque command over velocity error at `f` Hz, the loop ticking every `period` s.
    pub fn response(&self, f: f64, period: f64) -> Complex64 {
        self.at_period(period).at(unit_circle(f, period))
    }

    /// The tuning's PI and filters designed for the loop's `period` (s), to be evaluated at
    /// many points: the biquads are designed once, not at each point.
    pub fn at_period(&self, period: f64) -> TuningAtPeriod {
        let rate = (1.0 / period) as f32;
        let low_pass = (self.low_pass_hz > 0.0).then(|| Biquad::low_pass(self.low_pass_hz as f32, rate));
        let notch = |n: &Option<Notch>| n.map(|n| Biquad::notch(n.hz as f32, n.q as f32, n.depth as f32, rate));
        TuningAtPeriod {
            kp: self.kp,
            ki: self.ki,
            period,
            filters: [low_pass, notch(&self.notch), notch(&self.notch2)],
        }
    }

    /// The FMU parameters (and `--set` names) that give this tuning.
    pub fn parameters(&self) -> BTreeMap<String, f64> {
        let n = self.notch.unwrap_or(Notch::OFF);
        let n2 = self.notch2.unwrap_or(Notch::OFF);
        [
            ("ctrl.velocity_kp", self.kp),
            ("ctrl.velocity_ki", self.ki),
            ("ctrl.low_pass_hz", self.low_pass_hz),
            ("ctrl.notch_hz", n.hz),
            ("ctrl.notch_q", n.q),
            ("ctrl.notch_depth", n.depth),
            ("ctrl.notch2_hz", n2.hz),
            ("ctrl.notch2_q", n2.q),
            ("ctrl.notch2_depth", n2.depth),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_string(), v))
        .collect()
    }

    /// The tuning written into `p` (f32, as the drive keeps it).
    pub fn apply(&self, p: &mut control_core::Params) {
        p.velocity.kp = self.kp as f32;
        p.velocity.ki = self.ki as f32;
        p.filters.low_pass_hz = self.low_pass_hz as f32;
        let n = self.notch.unwrap_or(Notch::OFF);
        p.filters.notch_hz = n.hz as f32;
        p.filters.notch_q = n.q as f32;
        p.filters.notch_depth = n.depth as f32;
        let n2 = self.notch2.unwrap_or(Notch::OFF);
        p.filters.notch2_hz = n2.hz as f32;
        p.filters.notch2_q = n2.q as f32;
        p.filters.notch2_depth = n2.depth as f32;
    }
}

/// `e^{j·2π·f·T}`: the point of the unit circle a frequency `f` (Hz) maps to at the
/// loop's `period` `T` (s).
pub fn unit_circle(f: f64, period: f64) -> Complex64 {
    Complex64::from_polar(1.0, std::f64::consts::TAU * f * period)
}

/// A tuning with its filters designed for a period ([`VelocityTuning::at_period`]).
pub struct TuningAtPeriod {
    kp: f64,
    ki: f64,
    period: f64,
    /// The low-pass, the notch and the second notch, in the drive's order.
    filters: [Option<Biquad>; 3],
}

impl TuningAtPeriod {
    /// The controller's response at `z` on the unit circle ([`unit_circle`]).
    pub fn at(&self, z: Complex64) -> Complex64 {
        let mut c = self.kp + self.ki * self.period * z / (z - 1.0);
        for b in self.filters.iter().flatten() {
            c *= biquad_at(b, z);
        }
        c
    }
}

/// A biquad's `H(z)` from its coefficients.
fn biquad_at(b: &Biquad, z: Complex64) -> Complex64 {
    let zi = 1.0 / z;
    let num = b.b0 as f64 + zi * (b.b1 as f64 + zi * b.b2 as f64);
    let den = 1.0 + zi * (b.a1 as f64 + zi * b.a2 as f64);
    num / den
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The response is the drive's: a step through the drive's own PI and biquads, its
    /// spectrum over the step's, matches `response` at a few frequencies (a sine through the
    /// running code against the formula).
    #[test]
    fn the_response_is_the_drives_own_loop() {
        let mut p = control_core::Params::default();
        let t = VelocityTuning {
            kp: 0.09,
            ki: 12.0,
            low_pass_hz: 900.0,
            notch: Some(Notch { hz: 300.0, q: 1.5, depth: 0.1 }),
            notch2: Some(Notch { hz: 1700.0, q: 1.0, depth: 0.2 }),
        };
        t.apply(&mut p);
        let period = p.rates.velocity_period() as f64;
        for f in [20.0, 300.0, 1200.0, 1700.0] {
            let mut lp = control_core::velocity_loop::VelocityLoop::new(&p.velocity, &p.filters, &p.rates);
            // A small sine (no limit reached); the last whole periods' first harmonic.
            let n = 40_000usize;
            let w = std::f64::consts::TAU * f * period;
            let (mut num, mut den) = (Complex64::new(0.0, 0.0), Complex64::new(0.0, 0.0));
            for k in 0..n {
                let e = 1e-3 * (w * k as f64).sin();
                let y = lp.step(e as f32, 0.0) as f64;
                if k >= n / 2 {
                    let basis = Complex64::from_polar(1.0, -w * k as f64);
                    num += y * basis;
                    den += e * basis;
                }
            }
            let measured = num / den;
            let model = t.response(f, period);
            assert!((measured / model - 1.0).norm() < 2e-3, "{f} Hz: {measured} vs {model}");
        }
    }
}
