//! Two-inertia mechanics: motor and load coupled by a shaft of stiffness k and damping c,
//! with Coulomb (smoothed) and viscous friction on both sides.
//!
//! The linear part (shaft, viscous friction, inertias) is discretised exactly over the
//! sub-step. The motor torque enters through a quadratic hold (start value, start slope, end
//! value); the Coulomb friction on each side ramps between its start and end values. The end
//! friction depends on the end velocities, so the step is a predictor (friction held)
//! followed by one corrector.

use super::discretisation::PolynomialHold;
use super::{PlantParams, PlantState};

/// Discrete state `[θm − θL, ωm, ωL, θL]`: the twist is integrated directly, so that the
/// large absolute angles never enter the shaft equations.
type MechState = [f64; 4];

const CORRECTOR_PASSES: usize = 1;

#[derive(Clone, Copy, Debug)]
pub struct TwoInertia {
    pub motor_inertia: f64,
    pub load_inertia: f64,
    pub stiffness: f64,
    pub damping: f64,
    pub motor_coulomb: f64,
    pub motor_viscous: f64,
    pub load_coulomb: f64,
    pub load_viscous: f64,
    pub coulomb_velocity: f64,
    substep: f64,
    /// Exact discretisation over one sub-step, inputs `[motor-side, load-side]` torque.
    discrete: PolynomialHold<4, 2>,
}

impl TwoInertia {
    pub fn new(p: &PlantParams, substep: f64) -> Self {
        let (jm, jl, k, c) = (p.motor_inertia, p.load_inertia, p.shaft_stiffness, p.shaft_damping);
        let a = [
            [0.0, 1.0, -1.0, 0.0],
            [-k / jm, -(c + p.motor_viscous) / jm, c / jm, 0.0],
            [k / jl, c / jl, -(c + p.load_viscous) / jl, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ];
        let b = [[0.0, 0.0], [1.0 / jm, 0.0], [0.0, 1.0 / jl], [0.0, 0.0]];
        Self {
            motor_inertia: jm,
            load_inertia: jl,
            stiffness: k,
            damping: c,
            motor_coulomb: p.motor_coulomb,
            motor_viscous: p.motor_viscous,
            load_coulomb: p.load_coulomb,
            load_viscous: p.load_viscous,
            coulomb_velocity: p.coulomb_velocity,
            substep,
            discrete: PolynomialHold::new::<10>(&a, &b, substep),
        }
    }

    /// Torque transmitted by the shaft from motor to load (Nm).
    pub fn shaft_torque(&self, x: &PlantState) -> f64 {
        self.stiffness * (x.motor_angle - x.load_angle) + self.damping * (x.motor_velocity - x.load_velocity)
    }

    /// Smoothed Coulomb friction torques `Fc·tanh(ω/ω_s)` on the motor and the load.
    pub fn coulomb(&self, motor_velocity: f64, load_velocity: f64) -> [f64; 2] {
        [
            self.motor_coulomb * (motor_velocity / self.coulomb_velocity).tanh(),
            self.load_coulomb * (load_velocity / self.coulomb_velocity).tanh(),
        ]
    }

    /// `(dω_motor/dt, dω_load/dt)` for motor torque `tm`, load disturbance `td` and the
    /// Coulomb friction torques `coulomb` at the state's velocities.
    pub fn acceleration(&self, x: &PlantState, tm: f64, td: f64, coulomb: [f64; 2]) -> (f64, f64) {
        let shaft = self.shaft_torque(x);
        let fm = coulomb[0] + self.motor_viscous * x.motor_velocity;
        let fl = coulomb[1] + self.load_viscous * x.load_velocity;
        ((tm - shaft - fm) / self.motor_inertia, (shaft - fl + td) / self.load_inertia)
    }

    /// Advance the mechanical part of `x` by one sub-step: the motor torque goes from
    /// `torque0` (rising at `torque_rate`, Nm/s) to `torque1`, the disturbance `td` is held,
    /// `coulomb0` is the Coulomb friction at the start.
    pub fn advance(&self, x: &mut PlantState, torque0: f64, torque_rate: f64, torque1: f64, td: f64, coulomb0: [f64; 2]) {
        let y: MechState = [x.motor_angle - x.load_angle, x.motor_velocity, x.load_velocity, x.load_angle];
        let u0 = [torque0 - coulomb0[0], td - coulomb0[1]];
        let rise = self.substep * torque_rate;
        // Predictor: Coulomb friction held at its start value.
        let y1 = self.discrete.step(&y, &u0, &[rise, 0.0], &[torque1 - torque0 - rise, 0.0]);
        // Corrector: friction ramps to its value at the predicted end velocities (more passes
        // were tried: they do not reduce the error, which comes from the friction's bend
        // within the step near zero speed, not from the predicted end value).
        let mut y_end = y1;
        for _ in 0..CORRECTOR_PASSES {
            let coulomb1 = self.coulomb(y_end[1], y_end[2]);
            let correction = self.discrete.slope_response(&[coulomb0[0] - coulomb1[0], coulomb0[1] - coulomb1[1]]);
            for ((v, base), c) in y_end.iter_mut().zip(y1).zip(correction) {
                *v = base + c;
            }
        }
        let y1 = y_end;
        x.load_angle = y1[3];
        x.motor_angle = y1[3] + y1[0];
        x.motor_velocity = y1[1];
        x.load_velocity = y1[2];
    }
}
