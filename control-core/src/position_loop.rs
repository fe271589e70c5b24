//! Position P controller with velocity feed-forward, on integer encoder counts.

use crate::params::PositionLoopGains;
use crate::TAU;

/// The loop's gains and the scales its tick uses, derived once by [`PositionLoop::new`].
#[derive(Clone, Copy, Debug)]
pub struct PositionLoop {
    previous_command: Option<i64>,
    /// Encoder count to rad.
    rad_per_count: f32,
    /// Position-loop period (s).
    period: f32,
    kp: f32,
    velocity_feedforward: f32,
    velocity_limit: f32,
}

/// One position-loop result.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PositionLoopOutput {
    /// Velocity reference for the velocity loop (rad/s).
    pub velocity_reference: f32,
    /// Command minus feedback (rad).
    pub following_error: f32,
}

impl PositionLoop {
    /// The loop for `gains` on an encoder of `counts_per_rev`, run every `period` seconds.
    pub fn new(gains: &PositionLoopGains, counts_per_rev: u32, period: f32) -> Self {
        Self {
            previous_command: None,
            rad_per_count: TAU / counts_per_rev as f32,
            period,
            kp: gains.kp,
            velocity_feedforward: gains.velocity_feedforward,
            velocity_limit: gains.velocity_limit,
        }
    }

    pub fn reset(&mut self) {
        self.previous_command = None;
    }

    pub fn step(&mut self, command: i64, feedback: i64) -> PositionLoopOutput {
        let rad_per_count = self.rad_per_count;
        let error = crate::counts_to_f32(command.saturating_sub(feedback)) * rad_per_count;
        let previous = self.previous_command.replace(command).unwrap_or(command);
        let feedforward = crate::counts_to_f32(command.saturating_sub(previous)) * rad_per_count / self.period;
        let v = self.kp * error + self.velocity_feedforward * feedforward;
        let limit = self.velocity_limit;
        PositionLoopOutput { velocity_reference: crate::limit(v, -limit, limit), following_error: error }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn velocity_reference_is_gain_times_error_plus_the_command_speed_within_the_limit() {
        let gains = PositionLoopGains { kp: 100.0, velocity_feedforward: 0.5, velocity_limit: 50.0 };
        let (cpr, period) = (1u32 << 20, 0.00025f32);
        let mut l = PositionLoop::new(&gains, cpr, period);
        let rad = |counts: f64| counts * core::f64::consts::TAU / cpr as f64;
        // First tick: no previous command, no feed-forward; the error is 1000 counts.
        let out = l.step(1000, 0);
        assert!((out.following_error as f64 - rad(1000.0)).abs() < 1e-9, "{out:?}");
        assert!((out.velocity_reference as f64 - 100.0 * rad(1000.0)).abs() < 1e-4, "{out:?}");
        // The command moves 2000 counts in a period: half of its speed is fed forward.
        let out = l.step(3000, 2900);
        let expected = 100.0 * rad(100.0) + 0.5 * rad(2000.0) / period as f64;
        assert!((out.velocity_reference as f64 - expected).abs() < 1e-3, "{} vs {expected}", out.velocity_reference);
        // A large error is limited; after a reset the feed-forward starts again from zero.
        assert_eq!(l.step(1 << 30, 0).velocity_reference, 50.0);
        l.reset();
        assert_eq!(l.step(-(1 << 30), 0).velocity_reference, -50.0);
    }
}
