//! Position P controller with velocity feed-forward, on integer encoder counts.

use crate::params::Params;
use crate::TAU;

#[derive(Clone, Copy, Debug, Default)]
pub struct PositionLoop {
    previous_command: Option<i64>,
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
    pub fn reset(&mut self) {
        self.previous_command = None;
    }

    pub fn step(&mut self, p: &Params, command: i64, feedback: i64) -> PositionLoopOutput {
        let rad_per_count = TAU / p.encoder_counts_per_rev as f32;
        let error = crate::counts_to_f32(command.saturating_sub(feedback)) * rad_per_count;
        let previous = self.previous_command.replace(command).unwrap_or(command);
        let feedforward =
            crate::counts_to_f32(command.saturating_sub(previous)) * rad_per_count / p.rates.position_period();
        let v = p.position.kp * error + p.position.velocity_feedforward * feedforward;
        let limit = p.position.velocity_limit;
        PositionLoopOutput { velocity_reference: crate::limit(v, -limit, limit), following_error: error }
    }
}
