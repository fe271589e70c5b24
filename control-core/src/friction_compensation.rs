//! Friction compensation at velocity reversal (for the circle test's quadrant glitches, seed
//! 002): when the *commanded* velocity changes sign, a torque pulse in the new direction,
//! `A·e^{−t/τ}`, is added to the velocity loop's output. It supplies at once the swing of
//! Coulomb friction from one side to the other that the velocity integrator would otherwise
//! build up while the axis sticks — the protrusion at each quadrant of a circle.
//!
//! The commanded velocity (the filtered position command's increments, the velocity command,
//! or the sequence's speed reference) is used rather than the feedback, so measurement noise
//! near zero speed cannot fire a train of pulses.

use core::fmt;

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FrictionCompensationParams {
    /// Pulse amplitude (Nm, ≥ 0; 0 switches the compensation off).
    pub amplitude: f32,
    /// Decay time constant (s, > 0).
    pub decay: f32,
}

impl Default for FrictionCompensationParams {
    fn default() -> Self {
        Self { amplitude: 0.0, decay: 0.01 }
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FrictionCompensationError {
    Amplitude(f32),
    Decay(f32),
}

impl fmt::Display for FrictionCompensationError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Amplitude(a) => write!(f, "friction compensation amplitude {a} N·m must be a finite number >= 0"),
            Self::Decay(d) => write!(f, "friction compensation decay {d} s must be a finite number > 0"),
        }
    }
}

impl FrictionCompensationParams {
    pub fn validate(&self) -> Result<(), FrictionCompensationError> {
        if !(self.amplitude.is_finite() && self.amplitude >= 0.0) {
            return Err(FrictionCompensationError::Amplitude(self.amplitude));
        }
        if !(self.decay.is_finite() && self.decay > 0.0) {
            return Err(FrictionCompensationError::Decay(self.decay));
        }
        Ok(())
    }
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FrictionCompensation {
    /// Sign of the last non-zero commanded velocity (0 before the first).
    direction: i8,
    /// Present pulse (Nm).
    pulse: f32,
    /// Decay per update: e^{−dt/τ}.
    factor: f32,
    amplitude: f32,
}

impl FrictionCompensation {
    /// For updates every `dt` seconds.
    pub fn new(p: &FrictionCompensationParams, dt: f32) -> Self {
        Self { direction: 0, pulse: 0.0, factor: libm::expf(-dt / p.decay), amplitude: p.amplitude }
    }

    pub fn reset(&mut self) {
        self.direction = 0;
        self.pulse = 0.0;
    }

    /// One velocity-loop update with the commanded velocity; returns the torque to add (Nm).
    pub fn step(&mut self, commanded_velocity: f32) -> f32 {
        let sign = if commanded_velocity > 0.0 {
            1
        } else if commanded_velocity < 0.0 {
            -1
        } else {
            self.direction
        };
        if sign != self.direction && sign != 0 {
            self.direction = sign;
            self.pulse = self.amplitude * sign as f32;
        }
        let out = self.pulse;
        self.pulse *= self.factor;
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_decaying_pulse_in_the_new_direction_at_each_reversal() {
        let p = FrictionCompensationParams { amplitude: 0.05, decay: 0.002 };
        let dt = 0.000125;
        let mut f = FrictionCompensation::new(&p, dt);
        assert_eq!(f.step(0.0), 0.0, "nothing before the first motion");
        assert_eq!(f.step(1.0), 0.05);
        // After 16 updates (2 ms = one time constant) the pulse is down to 1/e.
        let mut last = 0.0;
        for _ in 0..16 {
            last = f.step(1.0);
        }
        assert!((last - 0.05 * libm::expf(-1.0)).abs() < 1e-4, "{last}");
        assert_eq!(f.step(0.0), last * libm::expf(-dt / p.decay), "zero keeps the direction");
        assert_eq!(f.step(-2.0), -0.05);
    }

    #[test]
    fn off_by_default_and_bad_values_named() {
        let mut f = FrictionCompensation::new(&FrictionCompensationParams::default(), 0.000125);
        assert_eq!((f.step(1.0), f.step(-1.0)), (0.0, 0.0));
        let p = FrictionCompensationParams { amplitude: -1.0, decay: 0.01 };
        assert_eq!(p.validate(), Err(FrictionCompensationError::Amplitude(-1.0)));
        let p = FrictionCompensationParams { amplitude: 0.1, decay: 0.0 };
        assert_eq!(p.validate(), Err(FrictionCompensationError::Decay(0.0)));
    }
}
