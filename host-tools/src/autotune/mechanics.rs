//! The machine a velocity loop drives: a motor and a load on a shaft (two inertias, a spring
//! and its damper, viscous friction on each side), and where there is one an absorber on the
//! load (a third inertia on its own spring and damper: a second mode), as the torque at the
//! motor sees it. The twin's plant (`servo_axis::plant`) integrates the same equations with
//! Coulomb friction on top; the loop's design and its check use this linear part.

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// Two inertias on a shaft (SI units: kg·m², N·m/rad, N·m·s/rad), and an absorber on the
/// load where there is one.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mechanics {
    pub motor_inertia: f64,
    pub load_inertia: f64,
    pub shaft_stiffness: f64,
    pub shaft_damping: f64,
    pub motor_viscous: f64,
    pub load_viscous: f64,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub absorber: Option<AbsorberMechanics>,
}

/// A second mode on the load: an inertia on a spring and damper to it (kg·m², N·m/rad,
/// N·m·s/rad).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct AbsorberMechanics {
    pub inertia: f64,
    pub stiffness: f64,
    pub damping: f64,
}

impl AbsorberMechanics {
    /// Its own frequency `√(k/J)/2π` (Hz) and damping ratio `c/(2√(kJ))`.
    pub fn own_mode(&self) -> (f64, f64) {
        (
            (self.stiffness / self.inertia).sqrt() / std::f64::consts::TAU,
            self.damping / (2.0 * (self.stiffness * self.inertia).sqrt()),
        )
    }
}

impl Mechanics {
    /// A two-inertia machine of motor and load inertia `jm`, `jl` (kg·m²) whose shaft
    /// resonates at `fr` Hz with damping ratio `zeta` (at the load's own frequency), without
    /// friction: the tests' machines.
    #[cfg(test)]
    pub fn two_inertia(jm: f64, jl: f64, fr: f64, zeta: f64) -> Self {
        let w = std::f64::consts::TAU * fr;
        let k = w * w / (1.0 / jm + 1.0 / jl);
        Self {
            motor_inertia: jm,
            load_inertia: jl,
            shaft_stiffness: k,
            shaft_damping: 2.0 * zeta * (k * jl).sqrt(),
            motor_viscous: 0.0,
            load_viscous: 0.0,
            absorber: None,
        }
    }

    /// The twin plant's mechanics (its Coulomb friction left out).
    pub fn of_plant(p: &servo_axis::plant::PlantParams) -> Self {
        Self {
            motor_inertia: p.motor_inertia,
            load_inertia: p.load_inertia,
            shaft_stiffness: p.shaft_stiffness,
            shaft_damping: p.shaft_damping,
            motor_viscous: p.motor_viscous,
            load_viscous: p.load_viscous,
            absorber: (p.absorber_inertia > 0.0).then_some(AbsorberMechanics {
                inertia: p.absorber_inertia,
                stiffness: p.absorber_stiffness,
                damping: p.absorber_damping,
            }),
        }
    }

    /// Motor velocity over motor torque at `f` Hz:
    /// `(Z_L + S) / (Z_M·Z_L + (Z_M + Z_L)·S)` with the motor `Z_M = J_M s + b_M`, the load
    /// `Z_L = J_L s + b_L` (plus the absorber's `S_a·J_a s/(J_a s + S_a)`) and the shaft
    /// `S = (c s + k)/s`.
    pub fn motor_velocity_per_torque(&self, f: f64) -> Complex64 {
        let s = Complex64::new(0.0, std::f64::consts::TAU * f);
        let spring = (s * self.shaft_damping + self.shaft_stiffness) / s;
        let mut load = s * self.load_inertia + self.load_viscous;
        if let Some(a) = self.absorber {
            let spring_a = (s * a.damping + a.stiffness) / s;
            load += spring_a * s * a.inertia / (s * a.inertia + spring_a);
        }
        let motor = s * self.motor_inertia + self.motor_viscous;
        (load + spring) / (motor * load + (motor + load) * spring)
    }

    /// The shaft's resonance and anti-resonance (Hz): `√(k(1/J_M + 1/J_L))/2π`, `√(k/J_L)/2π`
    /// (the two-inertia part's, the absorber left out).
    pub fn resonance_hz(&self) -> (f64, f64) {
        let k = self.shaft_stiffness;
        let tau = std::f64::consts::TAU;
        ((k * (1.0 / self.motor_inertia + 1.0 / self.load_inertia)).sqrt() / tau, (k / self.load_inertia).sqrt() / tau)
    }

    /// The highest anti-resonance (Hz): the load's, or with an absorber the higher of the
    /// chain's two (where the motor's response has its zeros).
    pub fn highest_anti_resonance_hz(&self) -> f64 {
        match self.absorber {
            Some(a) => self.chain_modes_hz(&a).1[1],
            None => self.resonance_hz().1,
        }
    }

    /// The undamped chain motor –k– load –k_a– absorber: its two resonances and its two
    /// anti-resonances (Hz, each pair ascending), the roots of `ω⁴ − b·ω² + c = 0`, and of
    /// the same with the motor held for the anti-resonances (the motor's response zeros).
    fn chain_modes_hz(&self, a: &AbsorberMechanics) -> ([f64; 2], [f64; 2]) {
        let tau = std::f64::consts::TAU;
        let (jm, jl, ja, k, ka) = (self.motor_inertia, self.load_inertia, a.inertia, self.shaft_stiffness, a.stiffness);
        let roots = |b: f64, c: f64| {
            let d = (b * b - 4.0 * c).max(0.0).sqrt();
            [((b - d) / 2.0).max(0.0).sqrt() / tau, ((b + d) / 2.0).sqrt() / tau]
        };
        (
            roots(k * (1.0 / jm + 1.0 / jl) + ka * (1.0 / jl + 1.0 / ja), k * ka * (jm + jl + ja) / (jm * jl * ja)),
            roots((k + ka) / jl + ka / ja, k * ka / (jl * ja)),
        )
    }

    /// The frequencies (Hz) where the machine's response turns fastest: its resonance and
    /// anti-resonance, each with its half-power points `f·(1 ± ζ)`; with an absorber, the
    /// undamped chain's two resonances and two anti-resonances, each with the absorber's
    /// and the shaft's damping ratios either side. A design grid holds them so that a
    /// lightly damped mode is never stepped over.
    pub fn features_hz(&self) -> Vec<f64> {
        let (fr, fa) = self.resonance_hz();
        let tau = std::f64::consts::TAU;
        let c = self.shaft_damping;
        let zeta_r = c * (1.0 / self.motor_inertia + 1.0 / self.load_inertia) / (2.0 * tau * fr);
        let zeta_a = c / (2.0 * (self.shaft_stiffness * self.load_inertia).sqrt());
        let Some(a) = self.absorber else {
            return vec![fr, fr * (1.0 - zeta_r), fr * (1.0 + zeta_r), fa, fa * (1.0 - zeta_a), fa * (1.0 + zeta_a)];
        };
        let (resonances, zeros) = self.chain_modes_hz(&a);
        let zeta = zeta_r.max(zeta_a).max(a.own_mode().1);
        resonances.into_iter().chain(zeros).flat_map(|f| [f, f * (1.0 - zeta), f * (1.0 + zeta)]).collect()
    }

    /// Every inertia: the motor's, the load's and the absorber's.
    pub fn total_inertia(&self) -> f64 {
        self.motor_inertia + self.load_inertia + self.absorber.map_or(0.0, |a| a.inertia)
    }

    /// The highest resonance of the machine (Hz): the shaft's, or with an absorber the
    /// chain's upper one.
    pub fn highest_resonance_hz(&self) -> f64 {
        match self.absorber {
            Some(a) => self.chain_modes_hz(&a).0[1],
            None => self.resonance_hz().0,
        }
    }

    /// Every value finite and positive (the viscous terms and the damping may be 0).
    pub fn validate(&self) -> Result<(), String> {
        let positive = [
            ("motor_inertia", self.motor_inertia),
            ("load_inertia", self.load_inertia),
            ("shaft_stiffness", self.shaft_stiffness),
        ];
        for (name, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(format!("{name} = {v}: must be a positive number"));
            }
        }
        for (name, v) in [
            ("shaft_damping", self.shaft_damping),
            ("motor_viscous", self.motor_viscous),
            ("load_viscous", self.load_viscous),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(format!("{name} = {v}: must be a number ≥ 0"));
            }
        }
        if let Some(a) = self.absorber {
            if !(a.inertia.is_finite() && a.inertia > 0.0 && a.stiffness.is_finite() && a.stiffness > 0.0) {
                return Err(format!("absorber {a:?}: its inertia and stiffness must be positive numbers"));
            }
            if !(a.damping.is_finite() && a.damping >= 0.0) {
                return Err(format!("absorber damping = {}: must be a number ≥ 0", a.damping));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The highest anti-resonance is where the motor's response has its highest dip: with
    /// a lightly damped absorber the response at it lies under a fifth of the response a tenth
    /// either side, and no deeper dip lies above it.
    #[test]
    fn the_highest_anti_resonance_is_the_responses_highest_dip() {
        let mut m = Mechanics::two_inertia(1e-4, 2e-4, 90.0, 0.002);
        let response = |m: &Mechanics, f: f64| m.motor_velocity_per_torque(f).norm();
        m.absorber = Some(AbsorberMechanics {
            inertia: 2e-5,
            stiffness: 2e-5 * (std::f64::consts::TAU * 130.0f64).powi(2),
            damping: 1e-5,
        });
        let fa = m.highest_anti_resonance_hz();
        assert!(fa > m.resonance_hz().1, "{fa}");
        for side in [0.9, 1.1] {
            assert!(response(&m, fa) < 0.2 * response(&m, side * fa), "{fa} Hz against {side}");
        }
        // Above it the response only falls as the motor's alone does, with one peak and no
        // dip: sampled finely, its local minima lie at or below fa.
        let f: Vec<f64> = (0..4000).map(|k| 10.0 * 1.001f64.powi(k)).collect();
        let r: Vec<f64> = f.iter().map(|&f| response(&m, f)).collect();
        let top_dip =
            (1..f.len() - 1).filter(|&k| r[k] < r[k - 1] && r[k] < r[k + 1]).map(|k| f[k]).fold(0.0, f64::max);
        assert!((top_dip / fa - 1.0).abs() < 0.002, "{top_dip} against {fa}");
    }

    /// Far below the resonance the axis is one rigid body (1/(J s)); at the anti-resonance
    /// the motor hardly moves (a dip), at the resonance it moves most (a peak); far above it
    /// the motor alone (1/(J_M s)).
    #[test]
    fn a_two_inertia_axis_has_its_rigid_body_dip_and_peak() {
        let m = Mechanics {
            motor_inertia: 1e-4,
            load_inertia: 3e-4,
            shaft_stiffness: 400.0,
            shaft_damping: 0.002,
            motor_viscous: 0.0,
            load_viscous: 0.0,
            absorber: None,
        };
        let (fr, fa) = m.resonance_hz();
        let rigid = |f: f64| 1.0 / (std::f64::consts::TAU * f * m.total_inertia());
        let motor_alone = |f: f64| 1.0 / (std::f64::consts::TAU * f * m.motor_inertia);
        assert!((m.motor_velocity_per_torque(fa / 20.0).norm() / rigid(fa / 20.0) - 1.0).abs() < 0.01);
        assert!((m.motor_velocity_per_torque(fr * 20.0).norm() / motor_alone(fr * 20.0) - 1.0).abs() < 0.01);
        assert!(m.motor_velocity_per_torque(fa).norm() < 0.2 * rigid(fa));
        assert!(m.motor_velocity_per_torque(fr).norm() > 5.0 * motor_alone(fr));
    }

    /// With an absorber on the load, the motor's response dips at the chain's two
    /// anti-resonances and peaks at its two resonances, as `features_hz` computes them from
    /// the undamped chain; a vanishing absorber gives the two-inertia response back.
    #[test]
    fn an_absorber_adds_a_second_dip_and_peak_where_the_chain_has_them() {
        let two = Mechanics {
            motor_inertia: 1e-4,
            load_inertia: 3e-4,
            shaft_stiffness: 400.0,
            shaft_damping: 1e-4,
            motor_viscous: 0.0,
            load_viscous: 0.0,
            absorber: None,
        };
        let m =
            Mechanics { absorber: Some(AbsorberMechanics { inertia: 5e-5, stiffness: 123.0, damping: 1e-5 }), ..two };
        let f = m.features_hz();
        assert_eq!(f.len(), 12);
        let (resonances, zeros) = ([f[0], f[3]], [f[6], f[9]]);
        let rigid = |hz: f64| 1.0 / (std::f64::consts::TAU * hz * (1e-4 + 3e-4 + 5e-5));
        for hz in resonances {
            assert!(m.motor_velocity_per_torque(hz).norm() > 50.0 * rigid(hz), "{hz} Hz");
        }
        for hz in zeros {
            assert!(m.motor_velocity_per_torque(hz).norm() < 0.05 * rigid(hz), "{hz} Hz");
        }
        // Zeros and resonances interlace (a motor-driven chain), and the highest resonance is
        // the chain's upper one.
        assert!(zeros[0] < resonances[0] && resonances[0] < zeros[1] && zeros[1] < resonances[1], "{f:?}");
        assert_eq!(m.highest_resonance_hz(), resonances[1]);
        // An absorber of a thousandth of the load's inertia, tuned far above the shaft: the
        // two-inertia response within a few thousandths below its own mode.
        let small = AbsorberMechanics {
            inertia: 3e-7,
            stiffness: 3e-7 * (std::f64::consts::TAU * 8000.0).powi(2),
            damping: 0.0,
        };
        let tiny = Mechanics { absorber: Some(small), ..two };
        for hz in [10.0, 100.0, 300.0, 3000.0] {
            let (a, b) = (tiny.motor_velocity_per_torque(hz), two.motor_velocity_per_torque(hz));
            assert!((a / b - 1.0).norm() < 5e-3, "{hz} Hz: {a} vs {b}");
        }
    }
}
