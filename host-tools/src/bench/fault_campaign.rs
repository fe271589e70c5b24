//! `servo bench fault-campaign`: faults injected at random times into the simulated axis
//! (core + plant, the sensors as the drive reads them), many runs per kind. For each run:
//! the ticks from the moment the fault is present in what the core reads (for a runaway: the
//! first tick its following error exceeds the limit) to the first PWM command with the bridge
//! off (goal: at most 1); whether the bridge comes back on before `ClearFaults` once the
//! fault is gone (goal: never); and whether it comes back after `ClearFaults`.

use anyhow::{bail, Result};
use control_core::faults::Faults;
use control_core::{AxisInputs, Mode};
use serde::Serialize;
use servo_axis::parameters::default_config_given_mounting;
use servo_axis::simulation::{AxisSimulation, UserInputs};

/// The faults the campaign injects.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum FaultKind {
    /// A phase-current sample is NaN (a broken conversion).
    NanCurrentSample,
    /// A phase-current sample stuck at the converter's full scale (a shorted amplifier).
    SaturatedCurrentSample,
    /// The encoder counter reads garbage (a disconnected or noisy line).
    EncoderDisconnect,
    /// The bus-voltage sample falls under the under-voltage limit.
    BusUndervoltage,
    /// The bus-voltage sample rises above the over-voltage limit.
    BusOvervoltage,
    /// The power stage's break input fires (its interrupt latches the fault in the core).
    PowerStageBreak,
    /// The load jams against a torque far above the torque limit in position mode: the
    /// following error runs away.
    FollowingErrorRunaway,
}

impl FaultKind {
    pub const ALL: [FaultKind; 7] = [
        FaultKind::NanCurrentSample,
        FaultKind::SaturatedCurrentSample,
        FaultKind::EncoderDisconnect,
        FaultKind::BusUndervoltage,
        FaultKind::BusOvervoltage,
        FaultKind::PowerStageBreak,
        FaultKind::FollowingErrorRunaway,
    ];

    pub fn label(self) -> &'static str {
        match self {
            FaultKind::NanCurrentSample => "NaN current sample",
            FaultKind::SaturatedCurrentSample => "current sample stuck at full scale",
            FaultKind::EncoderDisconnect => "encoder disconnect (garbage count)",
            FaultKind::BusUndervoltage => "bus under-voltage",
            FaultKind::BusOvervoltage => "bus over-voltage",
            FaultKind::PowerStageBreak => "power-stage break",
            FaultKind::FollowingErrorRunaway => "following-error runaway (jammed load)",
        }
    }

    /// The fault bit the core must latch.
    fn bit(self) -> u32 {
        match self {
            FaultKind::NanCurrentSample => Faults::NOT_FINITE,
            FaultKind::SaturatedCurrentSample => Faults::OVERCURRENT,
            FaultKind::EncoderDisconnect => Faults::ENCODER,
            FaultKind::BusUndervoltage => Faults::BUS_UNDERVOLTAGE,
            FaultKind::BusOvervoltage => Faults::BUS_OVERVOLTAGE,
            FaultKind::PowerStageBreak => Faults::HARDWARE_BREAK,
            FaultKind::FollowingErrorRunaway => Faults::FOLLOWING_ERROR,
        }
    }
}

#[derive(Clone, Debug, Serialize)]
pub struct KindResult {
    pub kind: FaultKind,
    pub label: &'static str,
    pub runs: usize,
    /// Runs in which the bridge went off with the right fault latched.
    pub detected: usize,
    /// Largest number of ticks from detection to the bridge off (goal ≤ 1).
    pub worst_reaction_ticks: u64,
    /// Ticks with the bridge on after the fault, before ClearFaults, over all runs (goal 0).
    pub restarts_without_clear: u64,
    /// Runs in which the bridge ran again after ClearFaults once the fault was gone.
    pub recovered_after_clear: usize,
}

#[derive(Clone, Debug, Serialize)]
pub struct CampaignResult {
    pub seed: u64,
    pub runs_per_kind: usize,
    pub kinds: Vec<KindResult>,
    pub worst_reaction_ticks: u64,
    pub restarts_without_clear: u64,
    pub passed: bool,
    pub wall_seconds: f64,
}

/// Reaction goal in current-loop ticks.
pub const REACTION_GOAL_TICKS: u64 = 1;

type Rng = crate::random::XorShift64Star;

/// One run: settle, inject at a random tick, watch the bridge, remove the fault, watch it stay
/// off, clear, watch it come back.
fn run_one(kind: FaultKind, rng: &mut Rng) -> Result<(bool, u64, u64, bool)> {
    // A commissioned drive (the plant's mounting given): the campaign is about the faults.
    let config = default_config_given_mounting().map_err(anyhow::Error::msg)?;
    let limits = config.control.limits;
    let mut sim = AxisSimulation::new(&config).map_err(|e| anyhow::anyhow!("{e}"))?;
    // Position mode with a jog: the loops are working (currents flow) when the fault comes.
    let jog = [-40.0, -10.0, 10.0, 40.0][rng.below(4) as usize];
    let running = UserInputs { mode: Mode::Position, jog_velocity: jog, ..Default::default() };
    sim.apply_mode(&running);
    let settle = 800 + rng.below(3200);
    for _ in 0..settle {
        if !sim.tick_with_sensor_fault(&running, |_| {}).enabled {
            bail!("{}: the axis tripped before the fault was injected (faults {:?})", kind.label(), sim.axis.faults());
        }
    }
    let garbage = rng.next() as i32;
    let full_scale = 31.9_f32.copysign(if rng.below(2) == 0 { 1.0 } else { -1.0 });
    let phase = rng.below(2) as usize;
    let inject = |i: &mut AxisInputs| match kind {
        FaultKind::NanCurrentSample => i.phase_currents[phase] = f32::NAN,
        FaultKind::SaturatedCurrentSample => i.phase_currents[phase] = full_scale,
        // A jump of a quarter of the counter's range or more: far over half a revolution.
        FaultKind::EncoderDisconnect => {
            i.encoder_count = i.encoder_count.wrapping_add(0x4000_0000 ^ (garbage & 0x0FFF_FFFF))
        }
        FaultKind::BusUndervoltage => i.bus_voltage = 0.5 * limits.bus_undervoltage,
        FaultKind::BusOvervoltage => i.bus_voltage = 1.2 * limits.bus_overvoltage,
        FaultKind::PowerStageBreak | FaultKind::FollowingErrorRunaway => {}
    };
    // Three times what the motor can hold: the load is driven back, slowly enough that the
    // following error (not the current) is what trips.
    let jammed = UserInputs { disturbance_torque: -jog.signum() * 3.0 * limits_torque(&config), ..running };
    let faulty = if kind == FaultKind::FollowingErrorRunaway { jammed } else { running };
    if kind == FaultKind::PowerStageBreak {
        // What the break interrupt does on the drive, between two control ticks.
        sim.axis.latch_fault(Faults::HARDWARE_BREAK);
    }
    // Detection tick: the fault is in what the core reads from the first faulty tick on; a
    // runaway is detectable once the following error exceeds the limit.
    let mut detected_at = if kind == FaultKind::FollowingErrorRunaway { None } else { Some(0u64) };
    let mut off_at = None;
    let max_ticks = 200_000u64;
    for k in 0..max_ticks {
        let pwm = sim.tick_with_sensor_fault(&faulty, inject);
        if detected_at.is_none() && sim.telemetry().following_error.abs() > limits.following_error {
            detected_at = Some(k);
        }
        if !pwm.enabled {
            off_at = Some(k);
            // Another protection may have tripped first: detected then, at no later tick.
            detected_at.get_or_insert(k);
            break;
        }
    }
    let (Some(detected), Some(off)) = (detected_at, off_at) else {
        return Ok((false, u64::MAX, 0, false));
    };
    // Counted as not detected when another fault took the bridge off instead.
    let right_fault = sim.axis.faults().contains(kind.bit());
    let reaction = off.saturating_sub(detected);
    // The fault is gone: nothing may restart the bridge before ClearFaults.
    let mut restarts = 0;
    let calm = UserInputs { jog_velocity: 0.0, ..running };
    for _ in 0..4000 {
        if sim.tick_with_sensor_fault(&calm, |_| {}).enabled {
            restarts += 1;
        }
    }
    sim.axis.clear_faults();
    let mut recovered = false;
    for _ in 0..800 {
        recovered |= sim.tick_with_sensor_fault(&calm, |_| {}).enabled;
    }
    Ok((right_fault, reaction, restarts, recovered))
}

fn limits_torque(config: &servo_axis::simulation::SimulationConfig) -> f64 {
    config.control.velocity.torque_limit as f64
}

/// The campaign: `runs` runs of every kind, with random settle times, jog directions and
/// phases, from `seed`.
pub fn run(runs: usize, seed: u64, mut progress: impl FnMut(f64)) -> Result<CampaignResult> {
    let start = std::time::Instant::now();
    let mut rng = crate::random::XorShift64Star(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1);
    let mut kinds = Vec::new();
    for (i, kind) in FaultKind::ALL.into_iter().enumerate() {
        let mut r = KindResult {
            kind,
            label: kind.label(),
            runs,
            detected: 0,
            worst_reaction_ticks: 0,
            restarts_without_clear: 0,
            recovered_after_clear: 0,
        };
        for n in 0..runs {
            let (right, reaction, restarts, recovered) = run_one(kind, &mut rng)?;
            r.detected += right as usize;
            r.worst_reaction_ticks = r.worst_reaction_ticks.max(reaction);
            r.restarts_without_clear += restarts;
            r.recovered_after_clear += recovered as usize;
            progress((i * runs + n + 1) as f64 / (FaultKind::ALL.len() * runs) as f64);
        }
        kinds.push(r);
    }
    let worst = kinds.iter().map(|k| k.worst_reaction_ticks).max().unwrap_or(0);
    let restarts = kinds.iter().map(|k| k.restarts_without_clear).sum();
    let passed = worst <= REACTION_GOAL_TICKS && restarts == 0 && kinds.iter().all(|k| k.detected == k.runs);
    Ok(CampaignResult {
        seed,
        runs_per_kind: runs,
        kinds,
        worst_reaction_ticks: worst,
        restarts_without_clear: restarts,
        passed,
        wall_seconds: start.elapsed().as_secs_f64(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_injected_fault_switches_the_bridge_off_within_a_tick_and_it_stays_off_until_cleared() {
        let r = run(3, 7, |_| {}).unwrap();
        for k in &r.kinds {
            assert_eq!(k.detected, k.runs, "{}: not detected with its own fault bit", k.label);
            assert!(k.worst_reaction_ticks <= REACTION_GOAL_TICKS, "{}: {} ticks", k.label, k.worst_reaction_ticks);
            assert_eq!(k.restarts_without_clear, 0, "{}", k.label);
        }
        assert!(r.passed);
    }
}
