//! Two-inertia mechanics: motor and load coupled by a shaft of stiffness k and damping c,
//! with Coulomb (smoothed) and viscous friction on both sides; optionally a second mode on the
//! load: an absorber inertia `Ja` on a spring `ka` (damping `ca`), which puts anti-resonance
//! zeros `Ja·s² + ca·s + ka` into the torque → machine-end transfer function (seed 001).
//!
//! The linear part (shaft, viscous friction, inertias) is discretised exactly over the
//! sub-step. The motor torque enters through a quadratic hold (start value, start slope, end
//! value); the Coulomb friction on each side ramps between its start and end values. The end
//! friction depends on the end velocities, so the step is a predictor (friction held)
//! followed by one corrector.

use super::discretisation::PolynomialHold;
use super::{PlantParams, PlantState};

/// Discrete state `[θm − θL, ωm, ωL, θL]` (and `θL − θa, ωa` with the absorber): the twists
/// are integrated directly over a sub-step, so that the large absolute angles do not enter
/// the spring equations within it (a sub-step starts from the state's angles' difference),
/// and the step's end accelerations take the twist it integrated. Velocities are at indices 1
/// and 2 in both layouts.
const CORRECTOR_PASSES: usize = 1;

/// The smallest |x| for which `libm::tanh` takes its saturated branch (the high word of |x|
/// above 0x4034_0000, |x| > 20): there it returns `±(1 − 0/|x|)`, exactly ±1.
const TANH_SATURATED: f64 = f64::from_bits(0x4034_0001_0000_0000);

/// `libm::tanh`, bit for bit, without its call and its division where it is ±1 (the
/// friction's argument at any working speed: ω/ω_s > 20 above 1 rad/s by default).
#[inline(always)]
fn tanh(x: f64) -> f64 {
    if x.abs() >= TANH_SATURATED {
        1.0f64.copysign(x)
    } else {
        libm::tanh(x)
    }
}

/// The optional second mode on the load.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Absorber {
    pub inertia: f64,
    pub stiffness: f64,
    pub damping: f64,
}

#[derive(Clone, Copy, Debug)]
enum Discrete {
    TwoInertia(PolynomialHold<4, 2>),
    WithAbsorber(PolynomialHold<6, 2>),
}

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
    pub absorber: Option<Absorber>,
    substep: f64,
    /// Reciprocals the per-step code multiplies by (a division costs several multiplications).
    inverse_motor_inertia: f64,
    inverse_load_inertia: f64,
    inverse_coulomb_velocity: f64,
    /// Exact discretisation over one sub-step, inputs `[motor-side, load-side]` torque.
    discrete: Discrete,
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
        let absorber = (p.absorber_inertia > 0.0).then_some(Absorber {
            inertia: p.absorber_inertia,
            stiffness: p.absorber_stiffness,
            damping: p.absorber_damping,
        });
        let discrete = match absorber {
            None => Discrete::TwoInertia(PolynomialHold::new::<10>(&a, &b, substep)),
            Some(ab) => {
                let (ja, ka, ca) = (ab.inertia, ab.stiffness, ab.damping);
                let mut a6 = [[0.0; 6]; 6];
                for (row, src) in a6.iter_mut().zip(a) {
                    row[..4].copy_from_slice(&src);
                }
                // The absorber pulls on the load: −ka·(θL − θa) − ca·(ωL − ωa).
                a6[2][4] = -ka / jl;
                a6[2][2] -= ca / jl;
                a6[2][5] = ca / jl;
                a6[4] = [0.0, 0.0, 1.0, 0.0, 0.0, -1.0];
                a6[5] = [0.0, 0.0, ca / ja, 0.0, ka / ja, -ca / ja];
                let mut b6 = [[0.0; 2]; 6];
                b6[..4].copy_from_slice(&b);
                Discrete::WithAbsorber(PolynomialHold::new::<12>(&a6, &b6, substep))
            }
        };
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
            absorber,
            substep,
            inverse_motor_inertia: 1.0 / jm,
            inverse_load_inertia: 1.0 / jl,
            inverse_coulomb_velocity: 1.0 / p.coulomb_velocity,
            discrete,
        }
    }

    /// Smoothed Coulomb friction torques `Fc·tanh(ω/ω_s)` on the motor and the load.
    pub fn coulomb(&self, motor_velocity: f64, load_velocity: f64) -> [f64; 2] {
        [
            self.motor_coulomb * tanh(motor_velocity * self.inverse_coulomb_velocity),
            self.load_coulomb * tanh(load_velocity * self.inverse_coulomb_velocity),
        ]
    }

    /// `(dω_motor/dt, dω_load/dt)` for motor torque `tm`, load disturbance `td` and the
    /// Coulomb friction torques `coulomb` at the state's velocities; `twist` is the shaft's
    /// (motor angle less load angle, as the step integrated it: not recomputed from the two
    /// angles, which are large beside it and known later).
    pub fn acceleration(&self, x: &PlantState, twist: f64, tm: f64, td: f64, coulomb: [f64; 2]) -> (f64, f64) {
        let shaft = self.stiffness * twist + self.damping * (x.motor_velocity - x.load_velocity);
        let fm = coulomb[0] + self.motor_viscous * x.motor_velocity;
        let fl = coulomb[1] + self.load_viscous * x.load_velocity;
        let absorber = self
            .absorber
            .map_or(0.0, |a| a.stiffness * x.absorber_twist + a.damping * (x.load_velocity - x.absorber_velocity));
        ((tm - shaft - fm) * self.inverse_motor_inertia, (shaft - fl + td - absorber) * self.inverse_load_inertia)
    }

    /// Advance the mechanical part of `x` by one sub-step: the motor torque goes from
    /// `torque0` (rising at `torque_rate`, Nm/s) to `torque1`, the disturbance `td` is held,
    /// `coulomb0` is the Coulomb friction at the start. Returns the shaft's twist at the end,
    /// and the Coulomb friction at the end velocities where the step found it (the friction
    /// did not change over the step), None where the caller has to compute it.
    pub fn advance(
        &self,
        x: &mut PlantState,
        torque0: f64,
        torque_rate: f64,
        torque1: f64,
        td: f64,
        coulomb0: [f64; 2],
    ) -> (f64, Option<[f64; 2]>) {
        let base = [x.motor_angle - x.load_angle, x.motor_velocity, x.load_velocity, x.load_angle];
        let inputs = (torque0, torque_rate, torque1, td, coulomb0);
        let (y, coulomb1) = match &self.discrete {
            Discrete::TwoInertia(hold) => {
                let (y, coulomb1) = self.linear_step(hold, base, inputs);
                ([y[0], y[1], y[2], y[3], 0.0, 0.0], coulomb1)
            }
            Discrete::WithAbsorber(hold) => {
                let full = [base[0], base[1], base[2], base[3], x.absorber_twist, x.absorber_velocity];
                self.linear_step(hold, full, inputs)
            }
        };
        x.load_angle = y[3];
        x.motor_angle = y[3] + y[0];
        x.motor_velocity = y[1];
        x.load_velocity = y[2];
        x.absorber_twist = y[4];
        x.absorber_velocity = y[5];
        (y[0], coulomb1)
    }

    /// One sub-step of the linear part with the torque held as a quadratic and the Coulomb
    /// friction as a ramp: predictor (friction held), then one corrector; with the friction
    /// at the end where the corrector left the predictor's velocities.
    fn linear_step<const N: usize>(
        &self,
        hold: &PolynomialHold<N, 2>,
        y: [f64; N],
        (torque0, torque_rate, torque1, td, coulomb0): (f64, f64, f64, f64, [f64; 2]),
    ) -> ([f64; N], Option<[f64; 2]>) {
        let u0 = [torque0 - coulomb0[0], td - coulomb0[1]];
        let rise = self.substep * torque_rate;
        // Predictor: Coulomb friction held at its start value.
        let y1 = hold.step_shaping_first(&y, &u0, rise, torque1 - (torque0 + rise));
        // Corrector: friction ramps to its value at the predicted end velocities (more passes
        // were tried: they do not reduce the error, which comes from the friction's bend
        // within the step near zero speed, not from the predicted end value). Where that
        // value is the start's (both sides saturated at any working speed, or no friction),
        // the ramp is flat and the predictor stands: the step's result then does not wait for
        // the friction.
        let mut y_end = y1;
        let mut coulomb_end = None;
        for _ in 0..CORRECTOR_PASSES {
            let coulomb1 = self.coulomb(y_end[1], y_end[2]);
            if coulomb1 == coulomb0 {
                coulomb_end = Some(coulomb1);
                break;
            }
            let correction = hold.slope_response(&[coulomb0[0] - coulomb1[0], coulomb0[1] - coulomb1[1]]);
            for ((v, base), c) in y_end.iter_mut().zip(y1).zip(correction) {
                *v = base + c;
            }
        }
        (y_end, coulomb_end)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_saturated_tanh_is_libm_tanh_bit_for_bit() {
        let edge = TANH_SATURATED;
        let mut cases = vec![
            0.0,
            -0.0,
            1e-300,
            0.3,
            0.6,
            19.999,
            20.0,
            f64::from_bits(0x4034_0000_ffff_ffff),
            edge,
            f64::from_bits(edge.to_bits() + 1),
            f64::from_bits(edge.to_bits() - 1),
            21.0,
            1e3,
            1e300,
            f64::MAX,
            f64::INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
        ];
        cases.extend((0..200_000).map(|i| (i as f64 - 100_000.0) * 3.7e-4));
        for x in cases {
            for x in [x, -x] {
                assert_eq!(tanh(x).to_bits(), libm::tanh(x).to_bits(), "{x:e}");
            }
        }
    }
}
