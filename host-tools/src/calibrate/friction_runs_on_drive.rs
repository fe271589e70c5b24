//! The constant-speed runs on a drive over its link (`servo calibrate --device`), on the
//! schedule the FMU's runs follow (`FrictionRuns::segments`): the velocity command ramped
//! (`DriveSession::ramp_velocity`), each speed left to settle, then the drive's velocity
//! estimate and torque command read from its telemetry through the window (whole
//! revolutions) and averaged over the drive's time (each reading held until the next, by
//! the drive's tick stamps: a poll is not periodic). The readings are a few hundred a second,
//! not the FMU's every sample: a ripple at the rotation's multiples is sampled, not averaged
//! out, and the fit's standard errors are the larger for it. The axis ramps back to 0 and
//! rests at the end; on a fault the rest command is still sent and the fault named.

use anyhow::{bail, Result};
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
    let result = measure(session, runs);
    // Whatever happened: back to 0 along a ramp where it can, then at rest (the rest command
    // sent even with a fault latched).
    let stop = session.stop_and_rest();
    let points = result?;
    let end = stop?.tick;
    Ok((points, end.saturating_sub(start) as f64 / session.tick_hz))
}

fn measure<T: DrivePort>(session: &mut DriveSession<T>, runs: &FrictionRuns) -> Result<Vec<SpeedPoint>> {
    // From the speed the axis has (a sweep before may have left it coasting).
    let mut last = without_faults(session.telemetry()?).map_err(in_the_runs)?.velocity_estimate as f64;
    let mut points = Vec::new();
    for s in runs.segments() {
        session.ramp_velocity(last, s.speed, runs.acceleration).map_err(in_the_runs)?;
        last = s.speed;
        session.wait(runs.settle_s)?;
        points.push(window(session, s.to - s.from)?);
    }
    Ok(points)
}

fn in_the_runs(e: anyhow::Error) -> anyhow::Error {
    e.context("during the constant-speed runs")
}

/// The velocity estimate and torque command averaged over `seconds` of the drive's time.
fn window<T: DrivePort>(session: &mut DriveSession<T>, seconds: f64) -> Result<SpeedPoint> {
    let first = without_faults(session.telemetry()?).map_err(in_the_runs)?;
    let end = first.tick + (seconds * session.tick_hz).round() as u64;
    let (mut sums, mut held) = ((0.0, 0.0, 0.0), first);
    let mut moved = std::time::Instant::now();
    loop {
        session.link.pause(POLL);
        let t = without_faults(session.telemetry()?).map_err(in_the_runs)?;
        if t.tick < held.tick {
            bail!("the drive's tick went back from {} to {} (did it restart?)", held.tick, t.tick);
        }
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
