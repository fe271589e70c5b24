//! PI controller with output limit and conditional-integration anti-windup.

/// A PI's settings: gains and sample period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PiGains {
    pub kp: f32,
    pub ki: f32,
    /// Sample period (s).
    pub period: f32,
}

impl PiGains {
    /// For error `e` from the integrator `integral`: the output before limiting and the
    /// integrator's next value (the caller decides whether to keep it).
    #[inline(always)]
    pub fn propose(&self, integral: f32, e: f32) -> (f32, f32) {
        let candidate = integral + self.ki * e * self.period;
        (self.kp * e + candidate, candidate)
    }
}

/// `u = kp·e + ki·∫e dt`, clamped to `±limit`, at a fixed sample period.
///
/// Anti-windup: the integrator is frozen while the output is saturated and the error would
/// drive it further into saturation; it keeps integrating when the error pulls it back.
#[derive(Clone, Copy, Debug, Default)]
pub struct PiController {
    gains: PiGains,
    integral: f32,
}

/// Result of one PI update.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PiOutput {
    /// Output after limiting.
    pub value: f32,
    /// Output before limiting.
    pub unlimited: f32,
    pub saturated: bool,
}

impl PiController {
    pub const fn new(gains: PiGains) -> Self {
        Self { gains, integral: 0.0 }
    }

    pub fn integral(&self) -> f32 {
        self.integral
    }

    /// Set the integrator so that the output equals `output` for zero error (bumpless transfer).
    pub fn preset(&mut self, output: f32) {
        self.integral = output;
    }

    pub fn reset(&mut self) {
        self.integral = 0.0;
    }

    /// One update with error `e` and symmetric limit `limit`.
    pub fn update(&mut self, e: f32, limit: f32) -> PiOutput {
        let (unlimited, candidate) = self.gains.propose(self.integral, e);
        let value = crate::limit(unlimited, -limit, limit);
        let saturated = value != unlimited;
        let winding_up = saturated && (unlimited > 0.0) == (e > 0.0);
        if !winding_up {
            self.integral = crate::limit(candidate, -limit, limit);
        }
        PiOutput { value, unlimited, saturated }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn integrates_a_constant_error_linearly() {
        let mut pi = PiController::new(PiGains { kp: 2.0, ki: 10.0, period: 0.001 });
        let mut out = PiOutput::default();
        for _ in 0..100 {
            out = pi.update(1.0, 100.0);
        }
        // kp·e + ki·e·t = 2 + 10·0.1 = 3
        assert!((out.value - 3.0).abs() < 1e-5);
    }

    #[test]
    fn does_not_wind_up_in_saturation_and_recovers_at_once() {
        let mut pi = PiController::new(PiGains { kp: 1.0, ki: 100.0, period: 0.001 });
        for _ in 0..10_000 {
            let o = pi.update(5.0, 2.0);
            assert_eq!(o.value, 2.0);
        }
        assert!(pi.integral() <= 2.0);
        // Reversing the error leaves saturation within one sample.
        let o = pi.update(-5.0, 2.0);
        assert!(o.value < 0.0, "got {}", o.value);
    }

    #[test]
    fn preset_gives_bumpless_output() {
        let mut pi = PiController::new(PiGains { kp: 3.0, ki: 50.0, period: 0.001 });
        pi.preset(0.7);
        assert_eq!(pi.update(0.0, 10.0).value, 0.7);
    }
}
