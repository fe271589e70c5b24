//! The machine a velocity loop drives: a motor and a load on a shaft (two inertias, a spring
//! and its damper, viscous friction on each side), as the torque at the motor sees it. The
//! twin's plant (`servo_axis::plant`) integrates the same equations with Coulomb friction and
//! an optional absorber on top; the loop's design and its check use this linear part.

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

/// Two inertias on a shaft (SI units: kg·m², N·m/rad, N·m·s/rad).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Mechanics {
    pub motor_inertia: f64,
    pub load_inertia: f64,
    pub shaft_stiffness: f64,
    pub shaft_damping: f64,
    pub motor_viscous: f64,
    pub load_viscous: f64,
}

impl Mechanics {
    /// The twin plant's mechanics (its absorber and Coulomb friction left out).
    pub fn of_plant(p: &servo_axis::plant::PlantParams) -> Self {
        Self {
            motor_inertia: p.motor_inertia,
            load_inertia: p.load_inertia,
            shaft_stiffness: p.shaft_stiffness,
            shaft_damping: p.shaft_damping,
            motor_viscous: p.motor_viscous,
            load_viscous: p.load_viscous,
        }
    }

    /// Motor velocity over motor torque at `f` Hz:
    /// `(J_L s + b_L + S) / ((J_M s + b_M)(J_L s + b_L) + (J_M s + b_M + J_L s + b_L)·S)` with
    /// the shaft `S = (c s + k)/s`.
    pub fn motor_velocity_per_torque(&self, f: f64) -> Complex64 {
        let s = Complex64::new(0.0, std::f64::consts::TAU * f);
        let spring = (s * self.shaft_damping + self.shaft_stiffness) / s;
        let load = s * self.load_inertia + self.load_viscous;
        let motor = s * self.motor_inertia + self.motor_viscous;
        (load + spring) / (motor * load + (motor + load) * spring)
    }

    /// The shaft's resonance and anti-resonance (Hz): `√(k(1/J_M + 1/J_L))/2π`, `√(k/J_L)/2π`.
    pub fn resonance_hz(&self) -> (f64, f64) {
        let k = self.shaft_stiffness;
        let tau = std::f64::consts::TAU;
        ((k * (1.0 / self.motor_inertia + 1.0 / self.load_inertia)).sqrt() / tau, (k / self.load_inertia).sqrt() / tau)
    }

    /// The frequencies (Hz) where the machine's response turns fastest: its resonance and
    /// anti-resonance, each with its half-power points `f·(1 ± ζ)`. A design grid holds
    /// them so that a lightly damped mode is never stepped over.
    pub fn features_hz(&self) -> [f64; 6] {
        let (fr, fa) = self.resonance_hz();
        let tau = std::f64::consts::TAU;
        let c = self.shaft_damping;
        let zeta_r = c * (1.0 / self.motor_inertia + 1.0 / self.load_inertia) / (2.0 * tau * fr);
        let zeta_a = c / (2.0 * (self.shaft_stiffness * self.load_inertia).sqrt());
        [fr, fr * (1.0 - zeta_r), fr * (1.0 + zeta_r), fa, fa * (1.0 - zeta_a), fa * (1.0 + zeta_a)]
    }

    pub fn total_inertia(&self) -> f64 {
        self.motor_inertia + self.load_inertia
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
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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
        };
        let (fr, fa) = m.resonance_hz();
        let rigid = |f: f64| 1.0 / (std::f64::consts::TAU * f * m.total_inertia());
        let motor_alone = |f: f64| 1.0 / (std::f64::consts::TAU * f * m.motor_inertia);
        assert!((m.motor_velocity_per_torque(fa / 20.0).norm() / rigid(fa / 20.0) - 1.0).abs() < 0.01);
        assert!((m.motor_velocity_per_torque(fr * 20.0).norm() / motor_alone(fr * 20.0) - 1.0).abs() < 0.01);
        assert!(m.motor_velocity_per_torque(fa).norm() < 0.2 * rigid(fa));
        assert!(m.motor_velocity_per_torque(fr).norm() > 5.0 * motor_alone(fr));
    }
}
