//! The simulated machine: PMSM behind an average-model inverter, two-inertia mechanics with
//! friction, an incremental encoder and noisy sensors. Simulation only; never in the drive.
//!
//! Integration, per sub-step (default: one per base tick): the linear parts are discretised
//! exactly — the d/q windings with the electrical speed held over the sub-step (closed-form
//! 2 × 2 exponential) and the two-inertia mechanics (precomputed 4-state exponential with a
//! first-order hold on the torques); the couplings between them (speed → back-EMF, current →
//! torque) and the smoothed Coulomb friction are the only approximated terms.
//! `servo bench plant` measures the error against a ten-times-finer sub-step.

mod discretisation;
mod mechanics;
mod noise;
mod params;
mod pmsm;

pub use mechanics::{Absorber, TwoInertia};
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
    /// Load angle minus absorber angle, and the absorber's velocity (0 without absorber).
    pub absorber_twist: f64,
    pub absorber_velocity: f64,
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

#[derive(Clone, Copy, Debug)]
pub struct Plant {
    params: PlantParams,
    /// Discretised once from `params`.
    motor: Pmsm,
    mechanics: TwoInertia,
    pub state: PlantState,
    /// Motor acceleration at the end of the last tick (rad/s²).
    pub motor_acceleration: f64,
    /// Load acceleration at the end of the last tick, noise-free (rad/s²).
    pub load_acceleration: f64,
    /// Machine-end accelerometer reading at the end of the last tick (rad/s², with noise).
    pub accelerometer: f64,
    /// Electromagnetic torque at the end of the last tick (Nm).
    pub electromagnetic_torque: f64,
    current_noise: GaussianNoise,
    acceleration_noise: GaussianNoise,
    /// Coulomb friction at the end of the last tick and the velocities it is for.
    coulomb_cache: ([f64; 2], [f64; 2]),
    /// Encoder counts per radian of motor angle.
    counts_per_radian: f64,
    /// A motor angle and `(sin, cos)` of its electrical angle: the last measurement's, then
    /// the end of the tick's (that one turned by the tick's advance), which the next
    /// measurement takes when the rotor is still there.
    rotor: Option<(f64, f64, f64)>,
    /// Turns in a row since `rotor` was last computed from its angle (each adds a rounding
    /// or two: [`ROTOR_RESYNC`] of them bound the sum far below the plant's own error).
    rotor_turns: u32,
}

/// The most turns in a row of the sensed rotor's (sin, cos) (it is computed from the angle
/// again at the next tick: every 65th tick at the most).
const ROTOR_RESYNC: u32 = 64;

impl Plant {
    pub fn new(params: PlantParams) -> Result<Self, PlantError> {
        params.validate()?;
        Ok(Self {
            current_noise: GaussianNoise::new(params.noise_seed, params.current_noise_std),
            acceleration_noise: GaussianNoise::new(params.noise_seed ^ 0x9E37_79B9, params.acceleration_noise_std),
            motor: Pmsm::new(&params, params.substep()),
            mechanics: TwoInertia::new(&params, params.substep()),
            params,
            state: PlantState::default(),
            motor_acceleration: 0.0,
            load_acceleration: 0.0,
            accelerometer: 0.0,
            electromagnetic_torque: 0.0,
            coulomb_cache: ([0.0; 2], [0.0; 2]),
            counts_per_radian: params.encoder_counts_per_rev as f64 / TAU,
            rotor: None,
            rotor_turns: 0,
        })
    }

    pub fn params(&self) -> &PlantParams {
        &self.params
    }

    /// The bus supply changes to `volts` from the next tick on (a supply that sags or
    /// surges: the virtual drive's fault injection). Refused unless finite and positive.
    pub fn set_bus_voltage(&mut self, volts: f64) -> Result<(), PlantError> {
        let params = PlantParams { bus_voltage: volts, ..self.params };
        params.validate()?;
        self.params = params;
        Ok(())
    }

    /// Advance one base tick (`params.tick`) with the inputs held.
    // Inlined into the tick so that the inputs arrive in registers: read back from memory just
    // after being stored, they stalled the load (store forwarding fails on the paired loads).
    // Always: the tick has more than one variant (with the step's means, with a sensor fault).
    #[inline(always)]
    pub fn advance(&mut self, u: &PlantInputs) {
        let mut x = self.state;
        let voltage = if u.bridge_enabled {
            let v = Pmsm::stator_voltage(u.duties, self.params.bus_voltage);
            if self.params.dead_time_voltage > 0.0 {
                self.dead_time_error(v, &x)
            } else {
                v
            }
        } else {
            // Bridge off: the windings are open, the current is gone within the tick.
            x.id = 0.0;
            x.iq = 0.0;
            (0.0, 0.0)
        };
        let mut torque = self.motor.torque(x.id, x.iq);
        let (velocities, mut coulomb) = self.coulomb_cache;
        if velocities != [x.motor_velocity, x.load_velocity] {
            coulomb = self.mechanics.coulomb(x.motor_velocity, x.load_velocity);
        }
        for substep in 0..self.params.substeps {
            let first = substep == 0;
            let torque_rate = if u.bridge_enabled {
                // The rotor's (sin, cos) the sensors took at this state's angle (computed, or the
                // last tick's turned), when the measurement saw this state.
                let start_rotor = if first { self.rotor_at(x.motor_angle) } else { None };
                self.motor.advance_currents(&mut x, voltage, self.motor_acceleration, start_rotor)
            } else {
                0.0
            };
            let torque_end = self.motor.torque(x.id, x.iq);
            let (twist, found) =
                self.mechanics.advance(&mut x, torque, torque_rate, torque_end, u.disturbance_torque, coulomb);
            torque = torque_end;
            coulomb = found.unwrap_or_else(|| self.mechanics.coulomb(x.motor_velocity, x.load_velocity));
            (self.motor_acceleration, self.load_acceleration) =
                self.mechanics.acceleration(&x, twist, torque, u.disturbance_torque, coulomb);
        }
        // The rotor at the tick's end for the next measurement: the start's turned by the
        // tick's advance (a few multiplications instead of a sine and a cosine).
        let start = self.state.motor_angle;
        self.rotor = self.rotor_at(start).and_then(|rotor| {
            let turn = self.motor.pole_pairs * (x.motor_angle - start);
            (turn.abs() < pmsm::MAX_ROTATION && self.rotor_turns < ROTOR_RESYNC).then(|| {
                self.rotor_turns += 1;
                let (s, c) = pmsm::rotate(rotor, turn);
                (x.motor_angle, s, c)
            })
        });
        self.state = x;
        self.coulomb_cache = ([x.motor_velocity, x.load_velocity], coulomb);
        self.accelerometer = self.load_acceleration + self.acceleration_noise.sample();
        self.electromagnetic_torque = torque;
    }

    /// The stator voltage `v` less the inverter's dead-time error: each phase short by
    /// `dead_time_voltage` against its current's sign at the tick's start (the common mode
    /// drops out), held over the tick.
    #[inline(never)]
    fn dead_time_error(&self, (v_alpha, v_beta): (f64, f64), x: &PlantState) -> (f64, f64) {
        let theta_e = self.params.pole_pairs as f64 * x.motor_angle + self.motor.electrical_offset;
        let (s, c) = discretisation::sin_cos(theta_e);
        let alpha = x.id * c - x.iq * s;
        let beta = x.id * s + x.iq * c;
        let (ia, ib) = (alpha, -0.5 * alpha + 0.5 * 3f64.sqrt() * beta);
        let ic = -ia - ib;
        let error = |i: f64| {
            if i > 0.0 {
                -self.params.dead_time_voltage
            } else if i < 0.0 {
                self.params.dead_time_voltage
            } else {
                0.0
            }
        };
        let (ea, eb, ec) = (error(ia), error(ib), error(ic));
        (v_alpha + (2.0 * ea - eb - ec) / 3.0, v_beta + (eb - ec) / 3f64.sqrt())
    }

    /// The largest of the three phase currents' magnitudes now (A, true values).
    pub fn phase_current_peak(&self) -> f64 {
        let theta_e = self.params.pole_pairs as f64 * self.state.motor_angle + self.motor.electrical_offset;
        let (s, c) = discretisation::sin_cos(theta_e);
        let alpha = self.state.id * c - self.state.iq * s;
        let beta = self.state.id * s + self.state.iq * c;
        let (ia, ib) = (alpha, -0.5 * alpha + 0.5 * 3f64.sqrt() * beta);
        ia.abs().max(ib.abs()).max((ia + ib).abs())
    }

    /// The encoder's counter now: from its start, in its own direction.
    pub fn encoder_count(&self) -> i32 {
        let turned = self.state.motor_angle * self.counts_per_radian;
        let counts = if self.params.encoder_reversed { -turned } else { turned };
        // floor() by truncation: the library call costs more than the rest of this function.
        let truncated = counts as i64;
        let floor = if (truncated as f64) > counts { truncated - 1 } else { truncated };
        floor as i32
    }

    /// `(sin, cos)` of the electrical angle at motor angle `angle`, where `rotor` holds it (the
    /// angle bit for bit).
    #[inline(always)]
    fn rotor_at(&self, angle: f64) -> Option<(f64, f64)> {
        self.rotor.and_then(|(at, s, c)| (at.to_bits() == angle.to_bits()).then_some((s, c)))
    }

    /// Sample the sensors (advances the noise generators): the currents through the sensors'
    /// offsets and gains, the encoder's counter from its start in its own direction.
    #[inline(always)]
    pub fn measure(&mut self) -> Measurements {
        let p = &self.params;
        let (s, c) = self.rotor_at(self.state.motor_angle).unwrap_or_else(|| {
            self.rotor_turns = 0;
            discretisation::sin_cos(p.pole_pairs as f64 * self.state.motor_angle + self.motor.electrical_offset)
        });
        self.rotor = Some((self.state.motor_angle, s, c));
        let alpha = self.state.id * c - self.state.iq * s;
        let beta = self.state.id * s + self.state.iq * c;
        let ia = alpha;
        let ib = -0.5 * alpha + 0.5 * 3f64.sqrt() * beta;
        let encoder_count = self.encoder_count();
        Measurements {
            phase_currents: [
                ia * p.current_gain[0] + p.current_offset[0] + self.current_noise.sample(),
                ib * p.current_gain[1] + p.current_offset[1] + self.current_noise.sample(),
            ],
            encoder_count,
            bus_voltage: p.bus_voltage,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sensed rotor angle turned from tick to tick stays on the angle's own sine and
    /// cosine and on the unit circle, through the resyncs, through a reversal, and where the
    /// rotor turns too far in a tick to be turned (computed from the angle at every tick), and
    /// after its angle is set from outside.
    #[test]
    fn the_rotor_turned_tick_by_tick_keeps_the_sine_and_cosine_of_its_angle() {
        let params = PlantParams { rotor_start_angle: 0.7, ..PlantParams::default() };
        let mut plant = Plant::new(params).unwrap();
        let (mut worst, mut worst_norm) = (0.0f64, 0.0f64);
        let (mut turned, mut computed, mut fast_computed) = (0u32, 0u32, 0u32);
        let ticks = 200_000u32;
        for tick in 0..ticks {
            // A voltage vector turning at 300 rad/s electrical, reversed half-way; then the
            // bridge off and the machine set spinning at 300 rad/s (1200 electrical: 0.075 rad
            // a tick).
            let t = tick as f64 * params.tick;
            let angle = if tick < 100_000 { 300.0 * t } else { 300.0 * (2.0 * 100_000.0 * params.tick - t) };
            let duties = [0.0, 1.0, 2.0].map(|k: f64| 0.5 + 0.1 * (angle - k * TAU / 3.0).cos());
            let fast = tick >= 180_000;
            if tick == 180_000 {
                (plant.state.motor_angle, plant.state.load_angle) = (-3.1, -3.1);
            }
            if fast {
                (plant.state.motor_velocity, plant.state.load_velocity) = (300.0, 300.0);
            }
            plant.measure();
            assert!(plant.rotor_turns <= ROTOR_RESYNC, "tick {tick}: {} turns in a row", plant.rotor_turns);
            computed += (plant.rotor_turns == 0) as u32;
            fast_computed += (fast && plant.rotor_turns == 0) as u32;
            turned += (plant.rotor_turns > 0) as u32;
            let (a, s, c) = plant.rotor.unwrap();
            let theta = params.pole_pairs as f64 * a + plant.motor.electrical_offset;
            let (ws, wc) = discretisation::sin_cos(theta);
            // In units of the electrical angle's own rounding (the reference's uncertainty)
            // or of 1e-16, whichever is larger.
            let unit = (theta.abs() * f64::EPSILON).max(1e-16);
            worst = worst.max((s - ws).abs() / unit).max((c - wc).abs() / unit);
            worst_norm = worst_norm.max((s * s + c * c - 1.0).abs());
            plant.advance(&PlantInputs { duties, bridge_enabled: !fast, disturbance_torque: 0.0 });
        }
        assert!(turned > 150_000, "most ticks turned the rotor ({turned})");
        // A recompute after every ROTOR_RESYNC turns (and at every fast tick).
        let slow_ticks = 180_000 / (ROTOR_RESYNC + 1);
        assert!(
            computed >= slow_ticks + 20_000 && computed <= slow_ticks + 20_100,
            "{computed} recomputes, {fast_computed} fast"
        );
        assert_eq!(fast_computed, 20_000, "a tick that turns 0.075 rad is computed from its angle");
        // Up to 64 turns of a few roundings each, against the reference's rounding of the angle.
        assert!(worst < 8.0, "worst difference {worst:.1} units");
        // At most an epsilon a turn (18 of them measured).
        assert!(worst_norm < ROTOR_RESYNC as f64 * f64::EPSILON, "sin² + cos² off 1 by {worst_norm:e}");
    }
}
