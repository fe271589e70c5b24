//! The constant-speed runs on a drive over its link (`servo calibrate --device`), on the
//! schedule the FMU's runs follow (`FrictionRuns::segments`): the velocity command ramped
//! (`DriveSession::ramp_velocity`), each speed left to settle, then a window (whole
//! revolutions, or more: it ends at the first reading past them) between two telemetry
//! readings. Its mean torque is the difference of the drive's torque-command sums
//! (`Telemetry::torque_command_sum`) and its mean speed the difference of the encoder's
//! positions, each over the ticks between: the mean of every tick, however few readings a
//! host gets in (a virtual drive running far faster than real time may give one a window; a
//! reading's torque jitters by the velocity loop's gain times one count of speed). The axis
//! ramps back to 0 and rests at the end; on a fault the rest command is still sent and the
//! fault named.

use anyhow::{bail, Result};
use control_core::axis::{Telemetry, TORQUE_SUM_UNIT};
use control_core::Params;

use super::friction::SpeedPoint;
use super::friction_runs::FrictionRuns;
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::velocity_ramp::without_faults;

/// How often the window's telemetry is read (the drive's time).
const POLL: std::time::Duration = std::time::Duration::from_millis(1);

/// `runs` on the drive behind `session` with `params` (the drive's, commissioned): one point
/// per speed and direction, and the drive time from the first ramp to rest (s).
pub fn run_on_drive<T: DrivePort>(
    session: &mut DriveSession<T>,
    runs: &FrictionRuns,
    params: &Params,
) -> Result<(Vec<SpeedPoint>, f64)> {
    runs.validate_within(params.position.velocity_limit as f64)?;
    session.set_params(params)?;
    let start = session.telemetry()?.tick;
    let rad_per_count = std::f64::consts::TAU / params.encoder_counts_per_rev as f64;
    let result = measure(session, runs, rad_per_count);
    // Whatever happened: back to 0 along a ramp where it can, then at rest (the rest command
    // sent even with a fault latched).
    let stop = session.stop_and_rest();
    let points = result?;
    let end = stop?.tick;
    Ok((points, end.saturating_sub(start) as f64 / session.tick_hz))
}

fn measure<T: DrivePort>(
    session: &mut DriveSession<T>,
    runs: &FrictionRuns,
    rad_per_count: f64,
) -> Result<Vec<SpeedPoint>> {
    // From the speed the axis has (a sweep before may have left it coasting).
    let mut last = without_faults(session.telemetry()?).map_err(in_the_runs)?.velocity_estimate as f64;
    let mut points = Vec::new();
    for s in runs.segments() {
        session.ramp_velocity(last, s.speed, runs.acceleration).map_err(in_the_runs)?;
        last = s.speed;
        session.wait(runs.settle_s)?;
        let (opening, closing) = window(session, s.to - s.from)?;
        points.push(mean_between(&opening, &closing, rad_per_count, session.tick_hz));
    }
    Ok(points)
}

fn in_the_runs(e: anyhow::Error) -> anyhow::Error {
    e.context("during the constant-speed runs")
}

/// The readings that open and close a window of at least `seconds` of the drive's time,
/// each checked for faults on the way (a poll every [`POLL`]).
fn window<T: DrivePort>(session: &mut DriveSession<T>, seconds: f64) -> Result<(Telemetry, Telemetry)> {
    let first = without_faults(session.telemetry()?).map_err(in_the_runs)?;
    let end = first.tick + (seconds * session.tick_hz).round().max(1.0) as u64;
    let (mut held, mut moved) = (first.tick, std::time::Instant::now());
    loop {
        session.link.pause(POLL);
        let t = without_faults(session.telemetry()?).map_err(in_the_runs)?;
        if t.tick < held {
            bail!("the drive's tick went back from {held} to {} (did it restart?)", t.tick);
        }
        if t.tick >= end {
            return Ok((first, t));
        }
        if t.tick != held {
            (held, moved) = (t.tick, std::time::Instant::now());
        } else if moved.elapsed() > std::time::Duration::from_secs(5) {
            bail!("the drive's tick counter stopped at {held} (is it still running?)");
        }
    }
}

/// The mean speed (rad/s, from the encoder's counts) and torque command (N·m, from the
/// drive's sums) over the ticks from `first` to `last` (`last` later).
fn mean_between(first: &Telemetry, last: &Telemetry, rad_per_count: f64, tick_hz: f64) -> SpeedPoint {
    let ticks = (last.tick - first.tick) as f64;
    let counts = last.position.wrapping_sub(first.position) as f64;
    let torque = last.torque_command_sum.wrapping_sub(first.torque_command_sum) as f64 * TORQUE_SUM_UNIT as f64;
    SpeedPoint { velocity: counts * rad_per_count * tick_hz / ticks, torque: torque / ticks }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two readings 8 000 ticks apart at 16 kHz: the mean speed from the counts and the mean
    /// torque from the sums, across the sum's wrap either way and a negative speed alike.
    #[test]
    fn the_window_s_means_come_from_the_counts_and_sums_between_its_readings() {
        let unit = TORQUE_SUM_UNIT as f64;
        let rad_per_count = std::f64::consts::TAU / 4096.0;
        for (start_sum, torque, speed) in
            [(0i64, 0.03, 20.0), (i64::MAX - 5_000, 0.047, 150.0), (i64::MIN + 5_000, -0.047, -150.0)]
        {
            let ticks = 8_000u64;
            let counts = (speed / rad_per_count * ticks as f64 / 16_000.0).round() as i64;
            let per_tick = (torque / unit).round() as i64;
            let first = Telemetry { tick: 1_000, position: -77, torque_command_sum: start_sum, ..Default::default() };
            let last = Telemetry {
                tick: 1_000 + ticks,
                position: -77 + counts,
                torque_command_sum: start_sum.wrapping_add(per_tick * ticks as i64),
                ..Default::default()
            };
            let p = mean_between(&first, &last, rad_per_count, 16_000.0);
            assert!((p.velocity - speed).abs() < rad_per_count * 2.0, "{p:?}");
            assert!((p.torque - torque).abs() < 2.0 * unit, "{p:?}");
        }
    }
}
