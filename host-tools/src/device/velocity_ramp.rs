//! The velocity command ramped over the link, and the axis brought to rest along a ramp: what
//! the constant-speed runs move between speeds with, and how a velocity-mode experiment ends
//! (a drop to zero torque at speed would leave the shaft coasting; a step to 0 rings a soft
//! shaft).

use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use control_core::axis::{Mode, Telemetry};
use control_core::protocol::Request;
use control_core::Commands;

use crate::device::link::DrivePort;
use crate::device::session::{DriveSession, STALLED};

/// Time between the velocity command's updates on a ramp (s).
pub const RAMP_STEP: f64 = 0.0025;
/// The deceleration an experiment ends with (rad/s²).
pub const STOP_ACCELERATION: f64 = 2000.0;
/// After the ramp to 0 the velocity loop holds 0 until the rotor turns slower than this (rad/s)
/// or for at most `STOP_HOLD` of the drive's time: at the end of the ramp the rotor still
/// turns by the loop's lag, and released at speed it would coast on, into whatever comes next
/// (a position-mode run that starts on a coasting rotor brakes it against its own command and
/// latches a following error).
pub const REST_SPEED: f32 = 0.5;
pub const STOP_HOLD: f64 = 0.5;
/// The rotor counts as stopped once every reading over this much of the drive's time (s) is
/// below [`REST_SPEED`] (one reading can catch a ringing shaft at a zero crossing).
pub const REST_FOR: f64 = 0.02;

impl<T: DrivePort> DriveSession<T> {
    /// The velocity command from `from` to `to` rad/s at `acceleration` rad/s², a step every
    /// `RAMP_STEP` (of the drive's time on a virtual drive in this process, of the host's on a
    /// port), timed by the drive's tick. A latched fault, a tick that stops or goes back (a
    /// drive that rebooted) ends it with an error.
    pub fn ramp_velocity(&mut self, from: f64, to: f64, acceleration: f64) -> Result<()> {
        if !(from.is_finite() && to.is_finite() && acceleration.is_finite() && acceleration > 0.0) {
            bail!("a ramp from {from} to {to} rad/s at {acceleration} rad/s² is not a ramp");
        }
        let duration = (to - from).abs() / acceleration;
        let first = without_faults(self.telemetry()?)?;
        let (start, mut last, mut moved) = (first.tick, first.tick, Instant::now());
        loop {
            let t = without_faults(self.telemetry()?)?;
            if t.tick < last {
                bail!("the drive's tick went back from {last} to {} during a ramp (did it restart?)", t.tick);
            }
            if t.tick != last {
                (last, moved) = (t.tick, Instant::now());
            } else if moved.elapsed() > STALLED {
                bail!("the drive's tick counter stopped at {} during a ramp (is it still running?)", t.tick);
            }
            let elapsed = (t.tick - start) as f64 / self.tick_hz;
            let share = if duration > 0.0 { (elapsed / duration).min(1.0) } else { 1.0 };
            let velocity = (from + (to - from) * share) as f32;
            let command = Commands { mode: Mode::Velocity, velocity, ..Commands::default() };
            self.order(Request::SetCommands(command), "a speed on the ramp")?;
            if share >= 1.0 {
                return Ok(());
            }
            self.link.pause(Duration::from_secs_f64(RAMP_STEP));
        }
    }

    /// The axis to rest: in velocity mode without a fault, first ramped from its commanded
    /// speed to 0; then torque mode at zero torque, always (a fault latched, the rest command
    /// is still sent before the fault is named).
    pub fn stop_and_rest(&mut self) -> Result<Telemetry> {
        let ramp = match self.telemetry() {
            Ok(t) if t.mode == Mode::Velocity && !t.faults.any() && t.velocity_reference != 0.0 => self
                .ramp_velocity(t.velocity_reference as f64, 0.0, STOP_ACCELERATION)
                .and_then(|_| self.hold_zero().map(|_| ())),
            _ => Ok(()),
        };
        let rest = self.rest();
        ramp?;
        rest
    }
}

impl<T: DrivePort> DriveSession<T> {
    /// Velocity 0 held until the rotor has turned slower than [`REST_SPEED`] for
    /// [`REST_FOR`], at most [`STOP_HOLD`] of the drive's time; a latched fault or a stalled
    /// drive ends it with an error. Returns the last reading.
    pub fn hold_zero(&mut self) -> Result<Telemetry> {
        let command = Commands { mode: Mode::Velocity, velocity: 0.0, ..Commands::default() };
        self.order(Request::SetCommands(command), "velocity 0")?;
        let hz = self.tick_hz;
        // The first reading's tick, the last one's, and the tick since which every reading was
        // below the rest speed (None: the last was not).
        let (mut start, mut last, mut slow_since) = (None, 0u64, None);
        // The hold's own bound ends it (a rotor still turning then is left as it is); the
        // wait's is a backstop.
        self.wait_until(2.0 * STOP_HOLD + 0.1, |t| {
            let t = without_faults(*t)?;
            let start = *start.get_or_insert(t.tick);
            if t.tick < last {
                bail!("the drive's tick went back from {last} to {} while it stopped (did it restart?)", t.tick);
            }
            last = t.tick;
            slow_since = if t.velocity_estimate.abs() < REST_SPEED { slow_since.or(Some(t.tick)) } else { None };
            let rested = slow_since.is_some_and(|s| (t.tick - s) as f64 >= REST_FOR * hz);
            Ok(rested || (t.tick - start) as f64 >= STOP_HOLD * hz)
        })
    }
}

/// A reading with no fault latched, or the fault by name.
pub fn without_faults(t: Telemetry) -> Result<Telemetry> {
    if t.faults.any() {
        bail!("the drive latched a fault: {}", t.faults);
    }
    Ok(t)
}
