//! Velocity PI with anti-windup and torque limit, followed by the optional torque-command
//! low-pass and two notches.

use crate::biquad::Biquad;
use crate::params::{Rates, TorqueFilters, VelocityLoopGains};
use crate::pi_controller::{PiController, PiGains};

/// The loop's gains and filters, designed for its rate once by [`VelocityLoop::new`].
#[derive(Clone, Copy, Debug)]
pub struct VelocityLoop {
    pi: PiController,
    low_pass: Option<Biquad>,
    notch: Option<Biquad>,
    notch2: Option<Biquad>,
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
            notch2: (f.notch2_hz > 0.0).then(|| Biquad::notch(f.notch2_hz, f.notch2_q, f.notch2_depth, rate)),
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
        if let Some(n) = self.notch2.as_mut() {
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
        if let Some(n) = self.notch2.as_mut() {
            torque = n.process(torque);
        }
        self.limit_torque(torque)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::Params;

    /// The loop's gain (proportional only) at `hz` on its own output, by a sine fit over whole
    /// periods after the transient.
    fn measured_gain(filters: &TorqueFilters, hz: f64) -> f64 {
        let rates = Params::default().rates;
        let gains = VelocityLoopGains { kp: 1.0, ki: 0.0, torque_limit: 1e6 };
        let mut l = VelocityLoop::new(&gains, filters, &rates);
        let fs = (rates.current_loop_hz / rates.velocity_divider as f32) as f64;
        let (mut s, mut c, mut n) = (0.0, 0.0, 0.0);
        let settle = (fs * 0.2) as usize;
        let periods = ((fs * 0.2) * hz / fs).floor().max(1.0);
        let measure = (periods * fs / hz).round() as usize;
        for k in 0..settle + measure {
            let phase = core::f64::consts::TAU * hz * k as f64 / fs;
            let y = l.step(libm::sin(phase) as f32, 0.0) as f64;
            if k >= settle {
                s += y * libm::sin(phase);
                c += y * libm::cos(phase);
                n += 1.0;
            }
        }
        2.0 * libm::sqrt(s * s + c * c) / n
    }

    /// `|N(f)|` of the pre-warped bilinear notch, from its analog prototype in f64.
    fn notch_gain(centre: f64, q: f64, depth: f64, hz: f64, fs: f64) -> f64 {
        let u = libm::tan(core::f64::consts::PI * hz / fs) / libm::tan(core::f64::consts::PI * centre / fs);
        let zeta = 0.5 / q;
        let re = 1.0 - u * u;
        libm::sqrt((re * re + (2.0 * depth * zeta * u).powi(2)) / (re * re + (2.0 * zeta * u).powi(2)))
    }

    #[test]
    fn two_notches_each_cut_their_resonance_as_their_analog_prototypes_do() {
        let rates = Params::default().rates;
        let fs = (rates.current_loop_hz / rates.velocity_divider as f32) as f64;
        let mut filters = Params::default().filters;
        (filters.notch_hz, filters.notch_q, filters.notch_depth) = (400.0, 2.0, 0.1);
        (filters.notch2_hz, filters.notch2_q, filters.notch2_depth) = (1500.0, 1.0, 0.3);
        let only_first = TorqueFilters { notch2_hz: 0.0, ..filters };
        for hz in [100.0, 400.0, 700.0, 1500.0, 2500.0] {
            let want = notch_gain(400.0, 2.0, 0.1, hz, fs) * notch_gain(1500.0, 1.0, 0.3, hz, fs);
            let got = measured_gain(&filters, hz);
            assert!((got / want - 1.0).abs() < 0.01, "{hz} Hz: {got} against {want}");
            let first = measured_gain(&only_first, hz);
            let want_first = notch_gain(400.0, 2.0, 0.1, hz, fs);
            assert!((first / want_first - 1.0).abs() < 0.01, "{hz} Hz, first alone: {first} against {want_first}");
        }
        // At the second's centre the pair cuts to its depth times what the first leaves.
        let at_second = measured_gain(&filters, 1500.0) / measured_gain(&only_first, 1500.0);
        assert!((at_second - 0.3).abs() < 0.005, "{at_second}");
    }
}
