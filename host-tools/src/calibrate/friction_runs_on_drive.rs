//! The constant-speed runs on a drive over its link (`servo calibrate --device`), on the
//! schedule the FMU's runs follow (`FrictionRuns::segments`): the velocity command ramped in
//! steps of `RAMP_STEP` of the drive's time, each speed left to settle, then the drive's
//! velocity estimate and torque command read from its telemetry through the window (whole
//! revolutions) and averaged over the drive's time (each reading held until the next, by
//! the drive's tick stamps: a poll is not periodic). The axis ramps back to 0 and rests at
//! the end, and on a fault the run stops naming it.

use anyhow::{bail, Result};
use control_core::protocol::Request;
use control_core::{Commands, Mode, Params};

use super::friction::SpeedPoint;
use super::friction_runs::{FrictionRuns, RAMP_STEP};
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;

/// How often the window's telemetry is read (the drive's time).
const POLL: std::time::Duration = std::time::Duration::from_millis(2);

/// `runs` on the drive behind `session` with `params` (the drive's, commissioned): one point
/// per speed and direction.
pub fn run_on_drive<T: DrivePort>(
    session: &mut DriveSession<T>,
    runs: &FrictionRuns,
    params: &Params,
) -> Result<Vec<SpeedPoint>> {
    runs.validate_within(params.position.velocity_limit as f64)?;
    session.set_params(params)?;
    let result = measure(session, runs);
    // Whatever happened: back to 0 along a ramp (from where the axis is), then at rest.
    let stop = ramp_down(session, runs.acceleration).and_then(|()| session.rest().map(|_| ()));
    let points = result?;
    stop?;
    Ok(points)
}

fn measure<T: DrivePort>(session: &mut DriveSession<T>, runs: &FrictionRuns) -> Result<Vec<SpeedPoint>> {
    let mut last = 0.0;
    let mut points = Vec::new();
    for s in runs.segments() {
        ramp(session, last, s.speed, runs.acceleration)?;
        last = s.speed;
        session.wait(runs.settle_s)?;
        points.push(window(session, s.to - s.from)?);
    }
    Ok(points)
}

/// The velocity command from `from` to `to` rad/s at `acceleration` rad/s², a step every
/// `RAMP_STEP` of the drive's time.
fn ramp<T: DrivePort>(session: &mut DriveSession<T>, from: f64, to: f64, acceleration: f64) -> Result<()> {
    let duration = (to - from).abs() / acceleration;
    let start = checked(session.telemetry()?)?.tick;
    loop {
        let t = checked(session.telemetry()?)?;
        let elapsed = t.tick.saturating_sub(start) as f64 / session.tick_hz;
        let share = if duration > 0.0 { (elapsed / duration).min(1.0) } else { 1.0 };
        let velocity = (from + (to - from) * share) as f32;
        session.order(
            Request::SetCommands(Commands { mode: Mode::Velocity, velocity, ..Commands::default() }),
            "a speed",
        )?;
        if share >= 1.0 {
            return Ok(());
        }
        session.link.pause(std::time::Duration::from_secs_f64(RAMP_STEP));
    }
}

/// From the axis's present speed to 0.
fn ramp_down<T: DrivePort>(session: &mut DriveSession<T>, acceleration: f64) -> Result<()> {
    let now = session.telemetry()?.velocity_reference as f64;
    ramp(session, if now.is_finite() { now } else { 0.0 }, 0.0, acceleration)
}

/// The velocity estimate and torque command averaged over `seconds` of the drive's time.
fn window<T: DrivePort>(session: &mut DriveSession<T>, seconds: f64) -> Result<SpeedPoint> {
    let first = checked(session.telemetry()?)?;
    let end = first.tick + (seconds * session.tick_hz).round() as u64;
    let (mut sums, mut held) = ((0.0, 0.0, 0.0), first);
    let mut moved = std::time::Instant::now();
    loop {
        session.link.pause(POLL);
        let t = checked(session.telemetry()?)?;
        // The reading held from its tick to the next one's (or the window's end).
        let until = t.tick.min(end);
        let span = until.saturating_sub(held.tick) as f64;
        sums.0 += span * held.velocity_estimate as f64;
        sums.1 += span * held.torque_command as f64;
        sums.2 += span;
        if t.tick >= end {
            break;
        }
        if t.tick != held.tick {
            moved = std::time::Instant::now();
        } else if moved.elapsed() > std::time::Duration::from_secs(5) {
            bail!("the drive's tick counter stopped at {} (is it still running?)", t.tick);
        }
        held = t;
    }
    if !(sums.2 > 0.0) {
        bail!("no telemetry arrived during a friction run's window");
    }
    Ok(SpeedPoint { velocity: sums.0 / sums.2, torque: sums.1 / sums.2 })
}

/// A reading with no fault latched, or the fault by name.
fn checked(t: control_core::axis::Telemetry) -> Result<control_core::axis::Telemetry> {
    if t.faults.any() {
        bail!("the drive latched a fault during the constant-speed runs: {}", t.faults);
    }
    Ok(t)
}
