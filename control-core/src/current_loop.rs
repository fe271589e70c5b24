//! Field-oriented current loop: Clarke/Park, d/q PI with decoupling, voltage limiting to the
//! DC-bus circle, inverse Park and space-vector PWM.

use crate::params::Params;
use crate::pi_controller::PiController;
use crate::reference_frames::{clarke, inverse_park, park, space_vector_duties, voltage_circle_radius, Dq};

#[derive(Clone, Copy, Debug, Default)]
pub struct CurrentLoop {
    d: PiController,
    q: PiController,
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
    pub fn new(p: &Params) -> Self {
        Self { d: PiController::new(p.current.kp, p.current.ki), q: PiController::new(p.current.kp, p.current.ki) }
    }

    pub fn reset(&mut self) {
        self.d.reset();
        self.q.reset();
    }

    /// One update.
    ///
    /// `phase_currents` are phases a and b (A); `theta_e` the electrical angle at sampling;
    /// `omega_e` the electrical speed (rad/s) for decoupling and angle advance.
    pub fn step(
        &mut self,
        p: &Params,
        phase_currents: [f32; 2],
        theta_e: f32,
        omega_e: f32,
        reference: Dq,
        bus_voltage: f32,
    ) -> CurrentLoopOutput {
        let dt = p.rates.tick_period();
        let (s, c) = crate::trigonometry::sin_cos(theta_e);
        let i = park(clarke(phase_currents[0], phase_currents[1]), s, c);

        let ed = reference.d - i.d;
        let eq = reference.q - i.q;
        let (vd_pi, id_int) = self.d.propose(ed, dt);
        let (vq_pi, iq_int) = self.q.propose(eq, dt);

        let m = &p.motor;
        let (ff_d, ff_q) = if p.current.decoupling {
            (-omega_e * m.lq * i.q, omega_e * (m.ld * i.d + m.flux_linkage))
        } else {
            (0.0, 0.0)
        };
        let vd_total = vd_pi + ff_d;
        let vq_total = vq_pi + ff_q;

        // d-axis has priority inside the circle; q gets what is left.
        let vmax = voltage_circle_radius(bus_voltage);
        let vd = crate::limit(vd_total, -vmax, vmax);
        let vq_max = crate::square_root::sqrt((vmax * vmax - vd * vd).max(0.0));
        let vq = crate::limit(vq_total, -vq_max, vq_max);
        let sat_d = vd != vd_total;
        let sat_q = vq != vq_total;
        if !(sat_d && (vd_total > 0.0) == (ed > 0.0)) {
            self.d.commit(crate::limit(id_int, -vmax, vmax));
        }
        if !(sat_q && (vq_total > 0.0) == (eq > 0.0)) {
            self.q.commit(crate::limit(iq_int, -vmax, vmax));
        }

        let theta_out = theta_e + omega_e * dt * p.current.angle_advance_ticks;
        let (so, co) = crate::trigonometry::sin_cos(theta_out);
        let v = Dq { d: vd, q: vq };
        let duties = space_vector_duties(inverse_park(v, so, co), bus_voltage);
        CurrentLoopOutput { current: i, voltage: v, duties, saturated: sat_d || sat_q }
    }
}
