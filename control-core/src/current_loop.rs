//! Field-oriented current loop: Clarke/Park, d/q PI with decoupling, voltage limiting to the
//! DC-bus circle, inverse Park and space-vector PWM.

use crate::params::{CurrentLoopGains, MotorModel};
use crate::pi_controller::PiGains;
use crate::reference_frames::{clarke, inverse_park, park, space_vector_duties, voltage_circle_radius, Dq};

/// The loop's gains and the motor data it uses, with what its tick derives from them
/// computed once by [`CurrentLoop::new`].
#[derive(Clone, Copy, Debug)]
pub struct CurrentLoop {
    /// The d and q PIs' gains (one set for both) and period: the base tick.
    gains: PiGains,
    /// The d and q PIs' integrators (V).
    integral: Dq,
    /// Voltage-angle advance in base ticks (the tick forms `ω·period·ticks` in that order).
    angle_advance_ticks: f32,
    decoupling: bool,
    ld: f32,
    lq: f32,
    flux_linkage: f32,
    /// Pole pairs as a factor (mechanical to electrical speed).
    pole_pairs: f32,
    /// Torque per q-axis ampere (Nm/A).
    torque_constant: f32,
    max_current: f32,
}

/// What one current-loop update produced.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CurrentLoopOutput {
    /// Measured current in the rotor frame (A).
    pub current: Dq,
    /// Voltage command after limiting (V).
    pub voltage: Dq,
    pub duties: [f32; 3],
    /// True when the voltage circle limited the output.
    pub saturated: bool,
}

impl CurrentLoop {
    /// The loop for `gains` and `motor`, run every `period` seconds (the base tick).
    pub fn new(gains: &CurrentLoopGains, motor: &MotorModel, period: f32) -> Self {
        Self {
            gains: PiGains { kp: gains.kp, ki: gains.ki, period },
            integral: Dq::default(),
            angle_advance_ticks: gains.angle_advance_ticks,
            decoupling: gains.decoupling,
            ld: motor.ld,
            lq: motor.lq,
            flux_linkage: motor.flux_linkage,
            pole_pairs: motor.pole_pairs as f32,
            torque_constant: motor.torque_constant(),
            max_current: gains.max_current,
        }
    }

    /// The current reference for a torque (Nm): q current within ±`max_current`, no d current.
    #[inline(always)]
    pub fn reference(&self, torque: f32) -> Dq {
        Dq { d: 0.0, q: crate::limit(torque / self.torque_constant, -self.max_current, self.max_current) }
    }

    pub fn reset(&mut self) {
        self.integral = Dq::default();
    }

    /// One update.
    ///
    /// `phase_currents` are phases a and b (A); `theta_e` the electrical angle at sampling;
    /// `speed` the mechanical speed (rad/s) for decoupling and angle advance.
    ///
    /// Inlined into `Axis::step` on hosts (the FMU, the host tools): returned through memory,
    /// the current was read back as one 8-byte load of two 4-byte stores, which do not forward
    /// (about 5 % of the simulated axis's time). The drive's image (`target_os = "none"`) is
    /// left to its own link-time choices.
    #[cfg_attr(not(target_os = "none"), inline)]
    pub fn step(
        &mut self,
        phase_currents: [f32; 2],
        theta_e: f32,
        speed: f32,
        reference: Dq,
        bus_voltage: f32,
    ) -> CurrentLoopOutput {
        let omega_e = speed * self.pole_pairs;
        let (s, c) = crate::trigonometry::sin_cos(theta_e);
        let i = park(clarke(phase_currents[0], phase_currents[1]), s, c);

        let ed = reference.d - i.d;
        let eq = reference.q - i.q;
        let (vd_pi, id_int) = self.gains.propose(self.integral.d, ed);
        let (vq_pi, iq_int) = self.gains.propose(self.integral.q, eq);

        let (ff_d, ff_q) = if self.decoupling {
            (-omega_e * self.lq * i.q, omega_e * (self.ld * i.d + self.flux_linkage))
        } else {
            (0.0, 0.0)
        };
        let vd_total = vd_pi + ff_d;
        let vq_total = vq_pi + ff_q;

        // d-axis has priority inside the circle; q gets what is left.
        let vmax = voltage_circle_radius(bus_voltage);
        let vd = crate::limit(vd_total, -vmax, vmax);
        // What the circle leaves for q, never below 0 (nor NaN: `f32::max`'s result, without
        // its NaN handling's instructions).
        let room = vmax * vmax - vd * vd;
        let vq_max = crate::square_root::sqrt(if room > 0.0 { room } else { 0.0 });
        let vq = crate::limit(vq_total, -vq_max, vq_max);
        let sat_d = vd != vd_total;
        let sat_q = vq != vq_total;
        // Anti-windup: an integrator is kept unless its axis saturated in the error's direction.
        if !(sat_d && (vd_total > 0.0) == (ed > 0.0)) {
            self.integral.d = crate::limit(id_int, -vmax, vmax);
        }
        if !(sat_q && (vq_total > 0.0) == (eq > 0.0)) {
            self.integral.q = crate::limit(iq_int, -vmax, vmax);
        }

        let theta_out = theta_e + omega_e * self.gains.period * self.angle_advance_ticks;
        let (so, co) = crate::trigonometry::sin_cos(theta_out);
        let v = Dq { d: vd, q: vq };
        let duties = space_vector_duties(inverse_park(v, so, co), bus_voltage);
        CurrentLoopOutput { current: i, voltage: v, duties, saturated: sat_d || sat_q }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;

    #[test]
    fn a_torque_becomes_q_current_through_the_torque_constant_within_the_current_limit() {
        let p = Params::default();
        let l = CurrentLoop::new(&p.current, &p.motor, p.rates.tick_period());
        // Kt = 1.5 · pole pairs · flux linkage.
        let kt = 1.5 * p.motor.pole_pairs as f64 * p.motor.flux_linkage as f64;
        let r = l.reference(0.5);
        assert_eq!(r.d, 0.0);
        assert!((r.q as f64 - 0.5 / kt).abs() < 1e-5, "{r:?}");
        let max = p.current.max_current;
        assert_eq!(l.reference(1e3).q, max);
        assert_eq!(l.reference(-1e3).q, -max);
    }
}
