//! Velocity PI with anti-windup and torque limit, followed by the optional torque-command
//! low-pass and notch.

use crate::biquad::Biquad;
use crate::params::Params;
use crate::pi_controller::PiController;

#[derive(Clone, Copy, Debug, Default)]
pub struct VelocityLoop {
    pi: PiController,
    low_pass: Option<Biquad>,
    notch: Option<Biquad>,
}

impl VelocityLoop {
    pub fn new(p: &Params) -> Self {
        let rate = p.rates.current_loop_hz / p.rates.velocity_divider as f32;
        let f = &p.filters;
        Self {
            pi: PiController::new(p.velocity.kp, p.velocity.ki),
            low_pass: (f.low_pass_hz > 0.0).then(|| Biquad::low_pass(f.low_pass_hz, rate)),
            notch: (f.notch_hz > 0.0).then(|| Biquad::notch(f.notch_hz, f.notch_q, f.notch_depth, rate)),
        }
    }

    /// Take over from torque control without a jump: the loop output starts at `torque`.
    pub fn preset(&mut self, torque: f32) {
        self.pi.preset(torque);
        if let Some(lp) = self.low_pass.as_mut() {
            lp.preset(torque);
        }
        if let Some(n) = self.notch.as_mut() {
            n.preset(torque);
        }
    }

    /// The PI's integrator (Nm, before the torque filters).
    pub fn integral(&self) -> f32 {
        self.pi.integral()
    }

    /// Set the PI's integrator alone (the filters keep their state).
    pub fn set_integral(&mut self, torque: f32) {
        self.pi.preset(torque);
    }

    pub fn reset(&mut self) {
        self.preset(0.0);
    }

    /// One update: velocity reference and estimate in rad/s, returns the torque command (Nm).
    pub fn step(&mut self, p: &Params, reference: f32, estimate: f32) -> f32 {
        let dt = p.rates.velocity_period();
        let mut torque = self.pi.update(reference - estimate, dt, p.velocity.torque_limit).value;
        if let Some(lp) = self.low_pass.as_mut() {
            torque = lp.process(torque);
        }
        if let Some(n) = self.notch.as_mut() {
            torque = n.process(torque);
        }
        crate::limit(torque, -p.velocity.torque_limit, p.velocity.torque_limit)
    }
}
