//! Permanent-magnet synchronous motor in the rotor (d, q) frame, fed by an average-model
//! inverter whose pole voltages are `duty · V_bus`.

use super::{PlantParams, PlantState};

#[derive(Clone, Copy, Debug)]
pub struct Pmsm {
    pub pole_pairs: f64,
    pub resistance: f64,
    pub ld: f64,
    pub lq: f64,
    pub flux_linkage: f64,
}

impl From<&PlantParams> for Pmsm {
    fn from(p: &PlantParams) -> Self {
        Self {
            pole_pairs: p.pole_pairs as f64,
            resistance: p.resistance,
            ld: p.ld,
            lq: p.lq,
            flux_linkage: p.flux_linkage,
        }
    }
}

impl Pmsm {
    /// Stator voltage in the rotor frame for the given duties and rotor angle.
    pub fn dq_voltage(&self, duties: [f64; 3], bus_voltage: f64, motor_angle: f64) -> (f64, f64) {
        let [a, b, c] = duties;
        // Line-to-line voltages only depend on duty differences: the common mode drops out.
        let v_alpha = bus_voltage * (2.0 * a - b - c) / 3.0;
        let v_beta = bus_voltage * (b - c) / 3f64.sqrt();
        let (s, co) = (self.pole_pairs * motor_angle).sin_cos();
        (v_alpha * co + v_beta * s, -v_alpha * s + v_beta * co)
    }

    /// `(did/dt, diq/dt)`.
    pub fn current_derivative(&self, x: &PlantState, duties: [f64; 3], bus_voltage: f64) -> (f64, f64) {
        let (vd, vq) = self.dq_voltage(duties, bus_voltage, x.motor_angle);
        let we = self.pole_pairs * x.motor_velocity;
        let did = (vd - self.resistance * x.id + we * self.lq * x.iq) / self.ld;
        let diq = (vq - self.resistance * x.iq - we * (self.ld * x.id + self.flux_linkage)) / self.lq;
        (did, diq)
    }

    /// Electromagnetic torque `1.5·p·(ψ·iq + (Ld − Lq)·id·iq)`.
    pub fn torque(&self, id: f64, iq: f64) -> f64 {
        1.5 * self.pole_pairs * (self.flux_linkage * iq + (self.ld - self.lq) * id * iq)
    }
}
