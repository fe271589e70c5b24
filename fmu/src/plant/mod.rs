//! The simulated machine: PMSM behind an average-model inverter, two-inertia mechanics with
//! friction, an incremental encoder and noisy sensors. Simulation only; never in the drive.
//!
//! Integration: classical fourth-order Runge–Kutta with a fixed number of sub-steps per base
//! tick. The inverter output is held over the tick (average model), so the right-hand side is
//! smooth inside a tick except for the friction, which is smoothed by `tanh(ω/ω_s)`.
//! `plant_step_error` in the tests and `servo bench plant` measure the error against a
//! ten-times-finer step.

mod mechanics;
mod noise;
mod params;
mod pmsm;

pub use mechanics::TwoInertia;
pub use noise::GaussianNoise;
pub use params::{PlantError, PlantParams};
pub use pmsm::Pmsm;

use std::f64::consts::TAU;

/// Continuous state.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantState {
    pub id: f64,
    pub iq: f64,
    pub motor_angle: f64,
    pub motor_velocity: f64,
    pub load_angle: f64,
    pub load_velocity: f64,
}

impl PlantState {
    fn add_scaled(&self, d: &PlantState, h: f64) -> PlantState {
        PlantState {
            id: self.id + h * d.id,
            iq: self.iq + h * d.iq,
            motor_angle: self.motor_angle + h * d.motor_angle,
            motor_velocity: self.motor_velocity + h * d.motor_velocity,
            load_angle: self.load_angle + h * d.load_angle,
            load_velocity: self.load_velocity + h * d.load_velocity,
        }
    }
}

/// What the inverter and the load see during one tick.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlantInputs {
    pub duties: [f64; 3],
    pub bridge_enabled: bool,
    /// External torque on the load (Nm).
    pub disturbance_torque: f64,
}

/// Sensor readings the drive gets at the start of a tick.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Measurements {
    pub phase_currents: [f64; 2],
    pub encoder_count: i32,
    pub bus_voltage: f64,
}

#[derive(Clone, Debug)]
pub struct Plant {
    params: PlantParams,
    /// Built once from `params`: the right-hand side runs 16 times per tick.
    motor: Pmsm,
    mechanics: TwoInertia,
    pub state: PlantState,
    /// Load acceleration at the end of the last tick, noise-free (rad/s²).
    pub load_acceleration: f64,
    /// Machine-end accelerometer reading at the end of the last tick (rad/s², with noise).
    pub accelerometer: f64,
    /// Electromagnetic torque at the end of the last tick (Nm).
    pub electromagnetic_torque: f64,
    current_noise: GaussianNoise,
    acceleration_noise: GaussianNoise,
}

impl Plant {
    pub fn new(params: PlantParams) -> Result<Self, PlantError> {
        params.validate()?;
        Ok(Self {
            current_noise: GaussianNoise::new(params.noise_seed, params.current_noise_std),
            acceleration_noise: GaussianNoise::new(params.noise_seed ^ 0x9E37_79B9, params.acceleration_noise_std),
            motor: Pmsm::from(&params),
            mechanics: TwoInertia::from(&params),
            params,
            state: PlantState::default(),
            load_acceleration: 0.0,
            accelerometer: 0.0,
            electromagnetic_torque: 0.0,
        })
    }

    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    fn derivative(&self, x: &PlantState, u: &PlantInputs) -> PlantState {
        let (did, diq, torque) = if u.bridge_enabled {
            let (did, diq) = self.motor.current_derivative(x, u.duties, self.params.bus_voltage);
            (did, diq, self.motor.torque(x.id, x.iq))
        } else {
            (0.0, 0.0, 0.0)
        };
        let (dwm, dwl) = self.mechanics.acceleration(x, torque, u.disturbance_torque);
        PlantState {
            id: did,
            iq: diq,
            motor_angle: x.motor_velocity,
            motor_velocity: dwm,
            load_angle: x.load_velocity,
            load_velocity: dwl,
        }
    }

    /// Advance by `dt` seconds in `params.substeps` RK4 steps with inputs held constant.
    pub fn advance(&mut self, u: &PlantInputs, dt: f64) {
        self.advance_with(u, dt, self.params.substeps);
    }

    /// Same as [`advance`](Self::advance) with an explicit number of sub-steps.
    pub fn advance_with(&mut self, u: &PlantInputs, dt: f64, substeps: u32) {
        if !u.bridge_enabled {
            // Bridge off: the windings are open, the current is gone within the tick.
            self.state.id = 0.0;
            self.state.iq = 0.0;
        }
        let h = dt / substeps as f64;
        let mut x = self.state;
        for _ in 0..substeps {
            let k1 = self.derivative(&x, u);
            let k2 = self.derivative(&x.add_scaled(&k1, 0.5 * h), u);
            let k3 = self.derivative(&x.add_scaled(&k2, 0.5 * h), u);
            let k4 = self.derivative(&x.add_scaled(&k3, h), u);
            x = PlantState {
                id: x.id + h / 6.0 * (k1.id + 2.0 * k2.id + 2.0 * k3.id + k4.id),
                iq: x.iq + h / 6.0 * (k1.iq + 2.0 * k2.iq + 2.0 * k3.iq + k4.iq),
                motor_angle: x.motor_angle
                    + h / 6.0 * (k1.motor_angle + 2.0 * k2.motor_angle + 2.0 * k3.motor_angle + k4.motor_angle),
                motor_velocity: x.motor_velocity
                    + h / 6.0
                        * (k1.motor_velocity + 2.0 * k2.motor_velocity + 2.0 * k3.motor_velocity + k4.motor_velocity),
                load_angle: x.load_angle
                    + h / 6.0 * (k1.load_angle + 2.0 * k2.load_angle + 2.0 * k3.load_angle + k4.load_angle),
                load_velocity: x.load_velocity
                    + h / 6.0
                        * (k1.load_velocity + 2.0 * k2.load_velocity + 2.0 * k3.load_velocity + k4.load_velocity),
            };
        }
        self.state = x;
        let d = self.derivative(&x, u);
        self.load_acceleration = d.load_velocity;
        self.accelerometer = self.load_acceleration + self.acceleration_noise.sample();
        self.electromagnetic_torque =
            if u.bridge_enabled { self.motor.torque(x.id, x.iq) } else { 0.0 };
    }

    /// Sample the sensors (advances the noise generators).
    pub fn measure(&mut self) -> Measurements {
        let p = &self.params;
        let theta_e = p.pole_pairs as f64 * self.state.motor_angle;
        let (s, c) = theta_e.sin_cos();
        let alpha = self.state.id * c - self.state.iq * s;
        let beta = self.state.id * s + self.state.iq * c;
        let ia = alpha;
        let ib = -0.5 * alpha + 0.5 * 3f64.sqrt() * beta;
        let counts = (self.state.motor_angle / TAU * p.encoder_counts_per_rev as f64).floor();
        Measurements {
            phase_currents: [ia + self.current_noise.sample(), ib + self.current_noise.sample()],
            encoder_count: (counts as i64) as i32,
            bus_voltage: p.bus_voltage,
        }
    }
}
