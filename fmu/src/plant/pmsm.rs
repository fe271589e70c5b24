//! Permanent-magnet synchronous motor in the rotor (d, q) frame, fed by an average-model
//! inverter whose pole voltages are `duty · V_bus`.
//!
//! Over a sub-step the electrical speed in the winding matrix is held at its mid-step value;
//! the stator voltage, fixed in the stator frame, turns in the rotor frame and is replaced by
//! a ramp with the right mean (the mid-step value shrunk by `sinc` of half the step's turn)
//! and the right slope. The winding equations are then linear with a ramp input and are
//! solved exactly with the closed-form 2 × 2 matrix exponential.

use super::discretisation::{cosh_sinhc, sin_cos};
use super::{PlantParams, PlantState};

#[derive(Clone, Copy, Debug)]
pub struct Pmsm {
    pub pole_pairs: f64,
    /// The rotor's electrical angle at motor angle 0 (rad): `p · rotor_start_angle`.
    pub electrical_offset: f64,
    pub resistance: f64,
    pub ld: f64,
    pub lq: f64,
    pub flux_linkage: f64,
    substep: f64,
    inverse_substep: f64,
    /// `A = m·I + N` splits the winding matrix into its mean decay rate `m` and a traceless
    /// part whose diagonal is `±n`; `e^{m·h}` does not depend on the speed.
    half_difference: f64,
    mean_decay: f64,
    /// `1/J_motor`: the rotor's own response to a torque change within a step.
    inverse_motor_inertia: f64,
    /// Reciprocals, ratios and products the per-step code multiplies by (computed once: the
    /// step is the simulation's critical path).
    inv_ld: f64,
    inv_lq: f64,
    lq_over_ld: f64,
    ld_over_lq: f64,
    /// `h/2`, `h²/8`, `h/2·p`, `(n·h)²`, `R²/(Ld·Lq)` (the winding matrix's determinant at
    /// standstill), `−R/Ld`, `−R/Lq`.
    half_step: f64,
    eighth_step_squared: f64,
    half_step_pole_pairs: f64,
    half_difference_step_squared: f64,
    standstill_determinant: f64,
    neg_r_over_ld: f64,
    neg_r_over_lq: f64,
    /// The torque `1.5·p·(ψ·iq + (Ld − Lq)·id·iq)` as `torque_flux·iq + torque_reluctance·id·iq`.
    torque_flux: f64,
    torque_reluctance: f64,
}

impl Pmsm {
    pub fn new(p: &PlantParams, substep: f64) -> Self {
        let (r, ld, lq) = (p.resistance, p.ld, p.lq);
        let mean_rate = -0.5 * (r / ld + r / lq);
        Self {
            pole_pairs: p.pole_pairs as f64,
            electrical_offset: p.pole_pairs as f64 * p.rotor_start_angle,
            resistance: r,
            ld,
            lq,
            flux_linkage: p.flux_linkage,
            substep,
            inverse_substep: 1.0 / substep,
            half_difference: 0.5 * (r / lq - r / ld),
            mean_decay: libm::exp(mean_rate * substep),
            inverse_motor_inertia: 1.0 / p.motor_inertia,
            inv_ld: 1.0 / ld,
            inv_lq: 1.0 / lq,
            lq_over_ld: lq / ld,
            ld_over_lq: ld / lq,
            half_step: 0.5 * substep,
            eighth_step_squared: 0.125 * substep * substep,
            half_step_pole_pairs: 0.5 * substep * p.pole_pairs as f64,
            half_difference_step_squared: {
                let nh = 0.5 * (r / lq - r / ld) * substep;
                nh * nh
            },
            standstill_determinant: (r / ld) * (r / lq),
            neg_r_over_ld: -r / ld,
            neg_r_over_lq: -r / lq,
            torque_flux: 1.5 * p.pole_pairs as f64 * p.flux_linkage,
            torque_reluctance: 1.5 * p.pole_pairs as f64 * (ld - lq),
        }
    }

    /// Stator-frame voltage `(v_α, v_β)` for the given duties.
    pub fn stator_voltage(duties: [f64; 3], bus_voltage: f64) -> (f64, f64) {
        let [a, b, c] = duties;
        // Line-to-line voltages only depend on duty differences: the common mode drops out.
        const ONE_THIRD: f64 = 1.0 / 3.0;
        const ONE_OVER_SQRT_3: f64 = 0.577_350_269_189_625_8;
        (bus_voltage * (2.0 * a - b - c) * ONE_THIRD, bus_voltage * (b - c) * ONE_OVER_SQRT_3)
    }

    /// Advance `(id, iq)` of `x` by one sub-step under the stator voltage `(v_α, v_β)`;
    /// `motor_acceleration` (at the start) and the torque rise the step itself causes give
    /// the speed in the middle of the step. Returns the torque's rate of change at the start
    /// of the step (Nm/s), for the mechanics' quadratic torque hold.
    ///
    /// `start_rotor`, when given, is `(sin, cos)` of the electrical angle at the start of the
    /// step (the current sensors' angle): the mid-step angle is then that one turned by the
    /// short advance, instead of a second sine and cosine.
    pub fn advance_currents(
        &self,
        x: &mut PlantState,
        (v_alpha, v_beta): (f64, f64),
        motor_acceleration: f64,
        start_rotor: Option<(f64, f64)>,
    ) -> f64 {
        let h = self.substep;
        let (p, r, ld, lq, psi) = (self.pole_pairs, self.resistance, self.ld, self.lq, self.flux_linkage);
        let (half_h, eighth_h2) = (self.half_step, self.eighth_step_squared);
        let advance = half_h * x.motor_velocity + eighth_h2 * motor_acceleration;
        let half_turn = self.half_step_pole_pairs * (x.motor_velocity + half_h * motor_acceleration);
        let (s, c) = match start_rotor {
            Some(rotor) if (p * advance).abs() < MAX_ROTATION => rotate(rotor, p * advance),
            _ => sin_cos(p * (x.motor_angle + advance) + self.electrical_offset),
        };
        let shrink = cosh_sinhc(-half_turn * half_turn).1; // sin(x)/x
        let vd = shrink * (v_alpha * c + v_beta * s);
        let vq = shrink * (-v_alpha * s + v_beta * c);
        // The acceleration changes within the step as the current (and so the torque) moves:
        // estimate its slope from the current rates at the start, on the rotor alone (the
        // shaft passes the torque on only later).
        let we0 = p * x.motor_velocity;
        let (inv_ld, inv_lq) = (self.inv_ld, self.inv_lq);
        let (a00, a11) = (self.neg_r_over_ld, self.neg_r_over_lq);
        let did = (vd - r * x.id + we0 * lq * x.iq) * inv_ld;
        let diq = (vq - r * x.iq - we0 * (ld * x.id + psi)) * inv_lq;
        let jerk =
            (self.torque_flux * diq + self.torque_reluctance * (did * x.iq + x.id * diq)) * self.inverse_motor_inertia;
        let we = p * (x.motor_velocity + half_h * motor_acceleration + eighth_h2 * jerk);
        let mid_acceleration = motor_acceleration + half_h * jerk;
        // x' = A·x + b(t) with A = [[−R/Ld, ωe·Lq/Ld], [−ωe·Ld/Lq, −R/Lq]] and b ramping
        // through the step: the rotor-frame voltage turns at ωe (d/dt (vd, vq) = ωe·(vq, −vd))
        // and the back-EMF follows the acceleration.
        let a01 = we * self.lq_over_ld;
        let a10 = -we * self.ld_over_lq;
        let b_mid = [vd * inv_ld, (vq - we * psi) * inv_lq];
        let b_rise = [h * we * vq * inv_ld, h * (-we * vd - p * mid_acceleration * psi) * inv_lq];
        let b0 = [b_mid[0] - 0.5 * b_rise[0], b_mid[1] - 0.5 * b_rise[1]];
        // e^{A·h} = e^{m·h}·(C·I + h·S·N), N² = (n² + a01·a10)·I = (n² − ωe²)·I.
        let n = self.half_difference;
        let we_h = we * h;
        let (cz, sz) = cosh_sinhc(self.half_difference_step_squared - we_h * we_h);
        let (g, hs) = (self.mean_decay, self.mean_decay * h * sz);
        let phi = [[g * cz + hs * n, hs * a01], [hs * a10, g * cz - hs * n]];
        // det A = R²/(Ld·Lq) + ωe²; A⁻¹ = adj(A)/det, A⁻² = adj(A)²/det².
        let inv_det = 1.0 / (self.standstill_determinant + we * we);
        let adj = [[a11, -a01], [-a10, a00]];
        let adj2 =
            [[a11 * a11 + a01 * a10, -(a11 * a01 + a01 * a00)], [-(a10 * a11 + a00 * a10), a10 * a01 + a00 * a00]];
        let times = |m: [[f64; 2]; 2], v: [f64; 2]| [m[0][0] * v[0] + m[0][1] * v[1], m[1][0] * v[0] + m[1][1] * v[1]];
        let phi_minus_one =
            |v: [f64; 2]| [(phi[0][0] - 1.0) * v[0] + phi[0][1] * v[1], phi[1][0] * v[0] + (phi[1][1] - 1.0) * v[1]];
        // x(h) = Φ·x0 + Γ0·b0 + Γ1·(b1 − b0), Γ0 = A⁻¹(Φ − I), Γ1 = A⁻¹(Γ0 − h·I)/h: the input
        // terms are A⁻¹·((Φ − I)·b0 − rise) + A⁻²·(Φ − I)·rise/h, the two products side by side
        // (not one after the other: this is the simulation's critical path).
        let held = phi_minus_one(b0);
        let first = times(adj, [held[0] - b_rise[0], held[1] - b_rise[1]]);
        let second = times(adj2, phi_minus_one(b_rise));
        let second_scale = inv_det * inv_det * self.inverse_substep;
        let inputs = [first[0] * inv_det + second[0] * second_scale, first[1] * inv_det + second[1] * second_scale];
        let (id, iq) = (x.id, x.iq);
        x.id = phi[0][0] * id + phi[0][1] * iq + inputs[0];
        x.iq = phi[1][0] * id + phi[1][1] * iq + inputs[1];
        let did0 = a00 * id + a01 * iq + b0[0];
        let diq0 = a10 * id + a11 * iq + b0[1];
        self.torque_flux * diq0 + self.torque_reluctance * (did0 * iq + id * diq0)
    }

    /// Electromagnetic torque `1.5·p·(ψ·iq + (Ld − Lq)·id·iq)`.
    #[inline(always)]
    pub fn torque(&self, id: f64, iq: f64) -> f64 {
        self.torque_flux * iq + self.torque_reluctance * id * iq
    }
}

/// Largest turn [`rotate`] takes (rad): its series then leave less than 0.05⁹/9! ≈ 5e-18.
pub const MAX_ROTATION: f64 = 0.05;

/// `(sin, cos)` of an angle turned by `delta` (|delta| < [`MAX_ROTATION`]), from `(sin, cos)`
/// of the angle: the angle-sum formulas with Taylor series of `sin delta` and `cos delta`.
#[inline(always)]
pub fn rotate((s, c): (f64, f64), delta: f64) -> (f64, f64) {
    // Estrin's scheme (a shallow tree: the mid-step angle is on the simulation's critical path).
    let d2 = delta * delta;
    let d4 = d2 * d2;
    let sin_d = delta * ((1.0 - d2 * (1.0 / 6.0)) + d4 * (1.0 / 120.0 - d2 * (1.0 / 5040.0)));
    let cos_d = (1.0 - d2 * 0.5) + d4 * ((1.0 / 24.0 - d2 * (1.0 / 720.0)) + d4 * (1.0 / 40_320.0));
    (s * cos_d + c * sin_d, c * cos_d - s * sin_d)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One step of the winding against two thousand sub-steps of it, at a constant speed (the
    /// rotor's inertia too large for the step's own torque to move it), over windings from
    /// much slower to much faster than the tick, salient and not, at rest and fast. The step's
    /// error grows with the square of the voltage's turn within it, and with the winding's
    /// speed up to a tick's: the bound is `0.03·(ωe·h)²·min(1, R·h/L) + 1e-8` of the current's
    /// scale (the ramp of the turning voltage left out would miss it on every winding at
    /// speed). The acceleration's terms are not exercised here.
    #[test]
    fn one_step_of_the_winding_matches_many_small_ones_from_slow_to_stiff_windings() {
        let tick = 62.5e-6;
        let acceleration = 0.0;
        for (r, ld, lq) in
            [(0.05, 10e-3, 10e-3), (0.3, 1e-3, 1.6e-3), (1.0, 1e-3, 1e-3), (10.0, 20e-6, 30e-6), (5.0, 60e-6, 40e-6)]
        {
            for speed in [0.0, 40.0, -150.0, 400.0] {
                let p = PlantParams { resistance: r, ld, lq, motor_inertia: 1e9, ..PlantParams::default() };
                let run = |n: usize| {
                    let motor = Pmsm::new(&p, tick / n as f64);
                    let h = tick / n as f64;
                    let mut x = PlantState {
                        id: 0.3,
                        iq: -1.2,
                        motor_velocity: speed,
                        motor_angle: 0.4,
                        ..PlantState::default()
                    };
                    for _ in 0..n {
                        motor.advance_currents(&mut x, (3.0, -1.5), acceleration, None);
                        x.motor_angle += x.motor_velocity * h + 0.5 * acceleration * h * h;
                        x.motor_velocity += acceleration * h;
                    }
                    (x.id, x.iq)
                };
                let (one, many) = (run(1), run(2000));
                let scale = 0.3f64.hypot(1.2).max(3.0f64.hypot(1.5) / r);
                let error = (one.0 - many.0).abs().max((one.1 - many.1).abs()) / scale;
                let turn = p.pole_pairs as f64 * (speed + 0.5 * acceleration * tick).abs() * tick;
                let bound = 0.03 * turn * turn * (r * tick / ld.max(lq)).min(1.0) + 1e-8;
                assert!(
                    error < bound,
                    "R {r} Ld {ld} Lq {lq} at {speed} rad/s: {one:?} vs {many:?} ({error:e} > {bound:e})"
                );
            }
        }
    }

    #[test]
    fn a_turned_angle_matches_the_angle_sum_formulas() {
        // Against the formulas with the library's sin and cos of delta: checks the series.
        let mut worst: f64 = 0.0;
        for i in 0..2_000 {
            let (s, c) = (i as f64 * 0.37 - 300.0).sin_cos();
            for delta in [-0.049_9, -0.012_5, -1e-7, 0.0, 3e-6, 0.006_25, 0.031, 0.049_9] {
                let (got_s, got_c) = rotate((s, c), delta);
                let (sd, cd) = delta.sin_cos();
                worst = worst.max((got_s - (s * cd + c * sd)).abs()).max((got_c - (c * cd - s * sd)).abs());
            }
        }
        assert!(worst < 1e-15, "worst difference {worst:e}");
        // And against the sine and cosine of the sum where the sum itself is exact enough.
        for angle in [-2.9f64, -0.3, 0.0, 0.8, 2.2] {
            let (s, c) = rotate(angle.sin_cos(), 0.031);
            let (ws, wc) = (angle + 0.031f64).sin_cos();
            assert!((s - ws).abs() < 2e-15 && (c - wc).abs() < 2e-15, "{angle}: {s} {c} vs {ws} {wc}");
        }
    }
}
