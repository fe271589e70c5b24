//! Two-inertia mechanics: motor and load coupled by a shaft of stiffness k and damping c,
//! with Coulomb (smoothed) and viscous friction on both sides.

use super::{PlantParams, PlantState};

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
}

impl From<&PlantParams> for TwoInertia {
    fn from(p: &PlantParams) -> Self {
        Self {
            motor_inertia: p.motor_inertia,
            load_inertia: p.load_inertia,
            stiffness: p.shaft_stiffness,
            damping: p.shaft_damping,
            motor_coulomb: p.motor_coulomb,
            motor_viscous: p.motor_viscous,
            load_coulomb: p.load_coulomb,
            load_viscous: p.load_viscous,
            coulomb_velocity: p.coulomb_velocity,
        }
    }
}

impl TwoInertia {
    /// Torque transmitted by the shaft from motor to load (Nm).
    pub fn shaft_torque(&self, x: &PlantState) -> f64 {
        self.stiffness * (x.motor_angle - x.load_angle) + self.damping * (x.motor_velocity - x.load_velocity)
    }

    /// `(dω_motor/dt, dω_load/dt)` for motor torque `tm` and load disturbance `td`.
    pub fn acceleration(&self, x: &PlantState, tm: f64, td: f64) -> (f64, f64) {
        let shaft = self.shaft_torque(x);
        let fm = self.motor_coulomb * (x.motor_velocity / self.coulomb_velocity).tanh()
            + self.motor_viscous * x.motor_velocity;
        let fl = self.load_coulomb * (x.load_velocity / self.coulomb_velocity).tanh()
            + self.load_viscous * x.load_velocity;
        ((tm - shaft - fm) / self.motor_inertia, (shaft - fl + td) / self.load_inertia)
    }
}
