//! Velocity PI with anti-windup and torque limit, followed by the optional torque-command
//! low-pass and notch.

use crate::biquad::Biquad;
use crate::params::{Rates, TorqueFilters, VelocityLoopGains};
use crate::pi_controller::{PiController, PiGains};

/// The loop's gains and filters, designed for its rate once by [`VelocityLoop::new`].
#[derive(Clone, Copy, Debug)]
pub struct VelocityLoop {
    pi: PiController,
    low_pass: Option<Biquad>,
    notch: Option<Biquad>,
    /// Torque limit (Nm).
    torque_limit: f32,
}

impl VelocityLoop {
    /// The loop for `gains` and `filters` at the velocity rate of `rates`.
    pub fn new(gains: &VelocityLoopGains, filters: &TorqueFilters, rates: &Rates) -> Self {
        let rate = rates.current_loop_hz / rates.velocity_divider as f32;
        let f = filters;
        Self {
            pi: PiController::new(PiGains { kp: gains.kp, ki: gains.ki, period: rates.velocity_period() }),
            low_pass: (f.low_pass_hz > 0.0).then(|| Biquad::low_pass(f.low_pass_hz, rate)),
            notch: (f.notch_hz > 0.0).then(|| Biquad::notch(f.notch_hz, f.notch_q, f.notch_depth, rate)),
            torque_limit: gains.torque_limit,
        }
    }

    /// `torque` within the torque limit.
    #[inline(always)]
    pub fn limit_torque(&self, torque: f32) -> f32 {
        crate::limit(torque, -self.torque_limit, self.torque_limit)
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
    pub fn step(&mut self, reference: f32, estimate: f32) -> f32 {
        let mut torque = self.pi.update(reference - estimate, self.torque_limit).value;
        if let Some(lp) = self.low_pass.as_mut() {
            torque = lp.process(torque);
        }
        if let Some(n) = self.notch.as_mut() {
            torque = n.process(torque);
        }
        self.limit_torque(torque)
    }
}
