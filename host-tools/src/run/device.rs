//! `servo run --device`: a scenario's input events sent to a drive as set-points at their times
//! (`device::timed_run`), its telemetry as the run's trace, the scenario's checks on it, and
//! the twin: the scenario on the FMU with each event at the time the drive got it.
//!
//! The inputs a drive has are its set-points: `mode`, `position_command` (rad, counted from
//! where the drive stood at the run's start, as the FMU's axis starts at 0), `move_speed`,
//! `jog_velocity`, `velocity_command`, `torque_command`. A scenario that sets anything else at
//! an event (a disturbance torque, a sweep start) is refused with the input's name. The
//! scenario's `ctrl.*` parameters go to the drive; `plant.*` ones describe the FMU's plant and
//! reach the twin only (the drive's plant is the machine, or the virtual drive's `--set`).

use anyhow::{anyhow, bail, Result};
use control_core::axis::Mode;
use control_core::protocol::Request;
use control_core::Commands;

use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::device::timed_run::{on_grid, run_timed, SentAt, TimedRequests};
use crate::device::velocity_ramp::{REST_SPEED, STOP_HOLD};
use crate::fmu::configuration::configuration;
use crate::fmu::scenario::{Scenario, Value, DEFAULT_STEP};
use crate::fmu::trace::Trace;
use power_stage::ratings::with_board_limits;

/// The scenario inputs a drive takes.
pub const DRIVE_INPUTS: [&str; 6] =
    ["mode", "position_command", "move_speed", "jog_velocity", "velocity_command", "torque_command"];

pub struct DeviceScenario {
    pub trace: Trace,
    pub sent: Vec<SentAt>,
    /// The scenario with each event at the telemetry sample just before the drive got it
    /// (on the FMU's step grid): the checks read the drive's trace with it (the FMU's outputs
    /// at an input's time show the state before the input acts).
    pub as_run: Scenario,
    /// The scenario with each event when the drive acted on it: what the twin replays.
    pub twin: Scenario,
}

/// Why a scenario cannot run on a drive (an input a drive does not have), if it cannot.
pub fn not_for_a_drive(scenario: &Scenario) -> Option<String> {
    scenario.events.iter().find_map(|e| {
        e.inputs.keys().find(|n| !DRIVE_INPUTS.contains(&n.as_str())).map(|n| {
            format!(
                "it sets `{n}` at {} s, which a drive has no input for (a drive takes {})",
                e.time,
                DRIVE_INPUTS.join(", ")
            )
        })
    })
}

/// The set-points after `inputs` on top of `c`.
fn apply(c: &mut Commands, inputs: &std::collections::BTreeMap<String, Value>, origin: i64, cpr: f64) -> Result<()> {
    for (name, &v) in inputs {
        let x = v.as_f64();
        match name.as_str() {
            "mode" => {
                let code = (x.fract() == 0.0 && x.abs() <= 3.0).then_some(x as i32);
                c.mode = code.and_then(Mode::from_code).ok_or_else(|| anyhow!("mode {x} is not a mode code (0–3)"))?
            }
            "position_command" => {
                let counts = (x / std::f64::consts::TAU * cpr).round();
                if !counts.is_finite() || counts.abs() > 2f64.powi(53) {
                    bail!("position_command {x} rad is outside the position range");
                }
                c.position = origin.saturating_add(counts as i64);
            }
            "move_speed" => c.move_speed = x as f32,
            "jog_velocity" => c.jog_velocity = x as f32,
            "velocity_command" => c.velocity = x as f32,
            "torque_command" => c.torque = x as f32,
            other => bail!(
                "the scenario sets `{other}`, which a drive has no input for (a drive takes {})",
                DRIVE_INPUTS.join(", ")
            ),
        }
    }
    Ok(())
}

pub fn scenario_on_drive<T: DrivePort>(
    session: &mut DriveSession<T>,
    scenario: &Scenario,
    progress: impl FnMut(f64),
) -> Result<DeviceScenario> {
    let params = with_board_limits(configuration(&scenario.parameters)?.control);
    session.set_params(&params)?;
    // The run starts from rest, as its twin does: a rotor still turning (left coasting by
    // whatever ran before) is stopped first, or the run is refused.
    let now = session.telemetry()?;
    if now.velocity_estimate.abs() >= REST_SPEED {
        let held = session.hold_zero()?;
        session.rest()?;
        if held.velocity_estimate.abs() >= REST_SPEED {
            bail!(
                "the rotor still turns at {:.2} rad/s after {STOP_HOLD} s at velocity 0: a run starts from rest",
                held.velocity_estimate
            );
        }
    }
    let origin = session.telemetry()?.position;
    let cpr = params.encoder_counts_per_rev as f64;
    // The set-points accumulate event by event, as the FMU's inputs keep their values.
    let mut commands = Commands { mode: Mode::Torque, position: origin, ..Commands::default() };
    let mut groups = Vec::new();
    for e in &scenario.events {
        apply(&mut commands, &e.inputs, origin, cpr).map_err(|err| anyhow!("event at {} s: {err}", e.time))?;
        commands.validate().map_err(|err| anyhow!("event at {} s: {err}", e.time))?;
        groups.push(TimedRequests {
            time: e.time,
            label: format!("the set-points at {} s", e.time),
            requests: vec![Request::SetCommands(commands)],
        });
    }
    let run = run_timed(session, (&params, origin), scenario.stop_time, &groups, |_| false, progress)?;
    session.rest()?;
    let (mut as_run, mut twin) = (scenario.clone(), scenario.clone());
    for ((e, t), sent) in as_run.events.iter_mut().zip(&mut twin.events).zip(&run.sent) {
        e.time = on_grid(sent.before, DEFAULT_STEP, scenario.stop_time);
        t.time = on_grid(sent.acted(), DEFAULT_STEP, scenario.stop_time);
    }
    Ok(DeviceScenario { trace: run.trace, sent: run.sent, as_run, twin })
}
