//! A drive's telemetry as a trace with the FMU's output names, so that an experiment's checks
//! and plots read a drive's run as they read the FMU's: the quantities the drive itself has
//! (velocity estimate, following error, commands, currents, the sequence's status), converted
//! as the FMU converts them (`servo_axis::co_simulation`'s outputs). What only a simulation
//! knows (the true motor and load angles and speeds) the drive cannot report: the encoder's
//! position and the velocity estimate stand in for `motor_position` and `motor_velocity`.

use control_core::axis::Telemetry;
use control_core::Params;

use crate::fmu::trace::Trace;

pub const COLUMNS: [&str; 18] = [
    "time",
    "motor_position",
    "motor_velocity",
    "velocity_estimate",
    "following_error",
    "torque_command_out",
    "iq",
    "position_command_out",
    "seq_state",
    "seq_complete",
    "seq_deviation",
    "seq_hold_position",
    "seq_gain",
    "seq_speed_reference",
    "seq_refused",
    "seq_last_refusal",
    "sweep_state",
    "faults",
];

pub fn new_trace() -> Trace {
    Trace::new(COLUMNS.map(String::from).to_vec())
}

/// One row: `t` at `time` (s since the run's start), positions from `origin` (counts: where
/// the run started, so that a run reads as the FMU's, which starts at 0).
pub fn row(time: f64, t: &Telemetry, params: &Params, origin: i64) -> Vec<f64> {
    let rad_per_count = std::f64::consts::TAU / params.encoder_counts_per_rev as f64;
    let from_origin = |counts: i64| counts.wrapping_sub(origin) as f64 * rad_per_count;
    let q = &t.sequence;
    vec![
        time,
        from_origin(t.position),
        t.velocity_estimate as f64,
        t.velocity_estimate as f64,
        t.following_error as f64,
        t.torque_command as f64,
        t.current.q as f64,
        from_origin(t.position_command),
        q.state.code() as f64,
        q.complete as u8 as f64,
        q.deviation as f64,
        from_origin(q.target),
        params.sequence.gains.get(q.gain_index).map_or(f64::NAN, |&g| g as f64),
        q.speed_reference as f64,
        q.refused as f64,
        q.last_refusal.map_or(0, |r| r.code()) as f64,
        t.sweep.state.code() as f64,
        t.faults.0 as f64,
    ]
}

/// Largest and rms difference of `name` between a drive's trace and its twin's, the twin
/// read at each of the drive's sample times (the twin's latest sample at or before it).
pub fn difference(drive: &Trace, twin: &Trace, name: &str) -> Option<(f64, f64)> {
    let (dt, dv, tt, tv) = (drive.column("time")?, drive.column(name)?, twin.column("time")?, twin.column(name)?);
    if tt.is_empty() {
        return None;
    }
    let (mut largest, mut squares, mut n) = (0.0f64, 0.0, 0usize);
    let mut j = 0;
    for (t, v) in dt.iter().zip(&dv) {
        while j + 1 < tt.len() && tt[j + 1] <= *t + 1e-9 {
            j += 1;
        }
        let d = v - tv[j];
        largest = largest.max(d.abs());
        squares += d * d;
        n += 1;
    }
    (n > 0).then(|| (largest, (squares / n as f64).sqrt()))
}
