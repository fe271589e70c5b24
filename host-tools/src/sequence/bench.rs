//! `servo bench sequence`: the figures of the stop-sequence issue (seed 004), from runs of
//! the FMU in mode 3.
//!
//! - per gain multiplier: stop at speed (time to acceptance, settle time to completion for
//!   good, overshoot past the accepted position, position error at completion and at rest)
//!   and a 1 rad fine adjustment (settle time, overshoot past the target);
//! - time from the stop key to acceptance against the zero-speed level, with the analytic
//!   value of the deceleration ramp for comparison.

use anyhow::{anyhow, bail, Result};
use control_core::stop_sequence::SequenceState;
use serde::Serialize;

use crate::fmu::runner::Fmu;
use crate::fmu::scenario::{Value, DEFAULT_STEP};
use crate::fmu::trace::Trace;
use crate::sequence::timeline::SequenceScenario;
use crate::sweep::bench::PlantCase;

const RUN_SPEED: f64 = 100.0;
/// The grid's gradient (rad/s²): the default.
pub const ACCELERATION: f64 = 2000.0;
const STOP_AT: f64 = 0.3;

#[derive(Clone, Debug, Serialize)]
pub struct GainFigures {
    pub multiplier: f64,
    /// Stop key to acceptance (s).
    pub acceptance: f64,
    /// Acceptance to completion for good (s).
    pub stop_settle: f64,
    /// Largest |deviation| after acceptance (counts): how far the axis runs past the stop.
    pub stop_overshoot_counts: i64,
    /// |deviation| when completion is reached for good, and at the end (counts).
    pub stop_error_at_completion: i64,
    pub stop_error_at_rest: i64,
    /// 1 rad fine adjustment: key to completion for good (s), overshoot past the target
    /// (counts, in the direction of the move).
    pub move_settle: f64,
    pub move_overshoot_counts: i64,
}

#[derive(Clone, Debug, Serialize)]
pub struct AcceptanceFigure {
    pub zero_speed: f64,
    pub measured: f64,
    /// The ramp's own time from the run speed to the zero-speed level: (V − VH)/a.
    pub ramp: f64,
}

/// One stop of the grid: run at `speed`, run off and stop key at once, with this zero-speed
/// level, completion width and gain multiplier (completion hold and hysteresis at their
/// defaults).
#[derive(Clone, Debug, Serialize)]
pub struct GridStop {
    /// The axis: "default", or a drawn plant's label (`servo bench sequence --random`).
    pub plant: String,
    pub speed: f64,
    pub zero_speed: f64,
    pub width: u32,
    pub multiplier: f64,
    /// Measured speed at acceptance (rad/s).
    pub speed_at_acceptance: f64,
    /// Stopping distance that speed implies at the gradient, v²/(2a) (counts).
    pub stopping_counts: f64,
    /// How far the velocity loop can run behind its reference, v·J/k_p (counts): the speed at
    /// acceptance times the loop's time constant (J = J_M + J_L, k_p its proportional gain).
    pub lag_counts: f64,
    /// What one count of the speed estimate moves the stopping distance, v·δv/a (counts; δv
    /// one count per velocity period): servo lock starts its reference from the estimate.
    pub resolution_counts: f64,
    /// The shaft's wind-up under the deceleration, J_L·a/k (counts), which its end releases.
    pub windup_counts: f64,
    /// Largest |deviation| after acceptance (counts).
    pub swing_counts: i64,
    /// Largest |deviation| beyond the width once completion was first raised (counts).
    pub overshoot_counts: i64,
    /// Acceptance to the first raise of completion (s); NaN if never raised, or never
    /// accepted (then the speed at acceptance and the distances are NaN too).
    pub settle: f64,
    /// Changes of the completion signal after its first raise (goal 0).
    pub toggles: u32,
}

/// Worst case of the grid, and whether the figure holds everywhere: completion raised in
/// every run, no toggle, and the swing within its bound (see [`SWING_WINDUP_FACTOR`]).
#[derive(Clone, Debug, Serialize)]
pub struct GridFigures {
    pub runs: usize,
    pub never_complete: usize,
    pub max_toggles: u32,
    pub max_overshoot_counts: i64,
    pub max_settle: f64,
    /// Largest swing / its bound (see [`SWING_WINDUP_FACTOR`]); the figure holds at ≤ 1.
    pub worst_swing_ratio: f64,
    pub worst_swing: Option<GridStop>,
    pub holds: bool,
}

/// The grid: ends and interior of the ranges users set (the interior is where a 30–60-count
/// width met a creeping axis: see `StopSequence::step`'s completion).
pub const GRID_SPEEDS: [f64; 7] = [10.0, 17.0, 25.0, 50.0, 100.0, 150.0, 200.0];
pub const GRID_ZERO_SPEEDS: [f64; 7] = [0.5, 1.0, 2.0, 5.0, 10.0, 15.0, 20.0];
pub const GRID_WIDTHS: [u32; 6] = [1, 3, 8, 30, 60, 100];
/// Bound of the swing after acceptance: the stopping distance v²/(2a) of the speed v measured
/// at acceptance, plus how far the velocity loop can run behind the reference that ramps it
/// down, v·J/k_p (the speed times the loop's time constant: what a proportional loop lags by;
/// the PI loop recovers part of it, 0.6 of it on the worst stop at steep gradients), plus what
/// one count of the speed estimate moves that stopping distance, v·δv/a (servo lock starts its
/// reference from the estimate, read to δv, one count per velocity period: 214 counts at
/// 1.3 rad/s and 50 rad/s², where it decides), plus `SWING_WINDUP_FACTOR` × the shaft's
/// wind-up under the deceleration, J_L·a/k (the motion while the velocity loop lets go of the
/// deceleration torque and the compliant shaft gives back its energy), plus the width and the
/// hysteresis.
/// The wind-up's factor was measured where v²/(2a) is nil on the default axis: 500 counts
/// there, 4/3 of its 376-count wind-up (2.25 mrad). Before the loop's lag was a term the bound
/// read 1.5·v²/(2a): it held at the default 2 000 rad/s² and not at 5 000 and 10 000 (1.07 and
/// 1.18 on a 3.27:1 axis stopped from 18 rad/s, whose swing less v²/(2a) stays at 3 400–4 400
/// counts whatever the gradient, 0.6 of its v·J/k_p), where v²/(2a) shrinks and the loop's lag
/// does not. A fixed 500 counts for the wind-up held on the default axis but not on heavier
/// loads on softer shafts (3 060 counts at 0.34 rad/s on a 4.35:1, 63 Hz axis, whose wind-up
/// is 11 300 counts: `servo bench sequence --random`).
pub const SWING_WINDUP_FACTOR: f64 = 4.0 / 3.0;

#[derive(Clone, Debug, Serialize)]
pub struct SequenceBench {
    pub grid: Vec<GridStop>,
    pub grid_figures: GridFigures,
    pub gains: Vec<GainFigures>,
    pub acceptance: Vec<AcceptanceFigure>,
    /// Settle times fall as the gain rises (both the stop and the move).
    pub settle_falls_with_gain: bool,
}

fn run(fmu: &Fmu, toml_text: &str) -> Result<Trace> {
    run_scenario(fmu, &toml::from_str(toml_text)?)
}

/// A sequence scenario, validated, on the FMU.
fn run_scenario(fmu: &Fmu, s: &SequenceScenario) -> Result<Trace> {
    s.validate()?;
    fmu.run(&s.to_scenario(), |_| {})
}

fn col(t: &Trace, n: &str) -> Result<Vec<f64>> {
    t.column(n).ok_or_else(|| anyhow!("the FMU has no output {n}"))
}

/// First index at or after time `t`.
fn at(time: &[f64], t: f64) -> usize {
    time.iter().position(|&x| x >= t - 0.5 * DEFAULT_STEP).unwrap_or(time.len() - 1)
}

/// Index from which `complete` stays set until `end` (exclusive of nothing): None if unset at `end`.
fn settled_from(complete: &[f64], from: usize, end: usize) -> Option<usize> {
    (from..=end).rev().take_while(|&i| complete[i] != 0.0).last()
}

/// Whether a `seq_state` output value says the stop was accepted (servo lock).
fn is_servo_lock(seq_state: f64) -> bool {
    SequenceState::from_code(seq_state as i32) == Some(SequenceState::ServoLock)
}

fn stop_and_move(fmu: &Fmu, index: usize, multiplier: f64) -> Result<GainFigures> {
    // Phase 1: stop at speed with this gain; the move target is 1 rad past the lock.
    let stop_text = format!(
        "name='bench_stop'\nstop_time=1.5\n[[events]]\ntime=0.0\nevent='run'\n[[events]]\ntime=0.0\nevent='gain'\nindex={index}\n\
         [[events]]\ntime={STOP_AT}\nevent='run_off'\n[[events]]\ntime={STOP_AT}\nevent='stop'\n"
    );
    let t = run(fmu, &stop_text)?;
    let (time, state, complete, dev) =
        (col(&t, "time")?, col(&t, "seq_state")?, col(&t, "seq_complete")?, col(&t, "seq_deviation")?);
    let accepted =
        state.iter().position(|&s| is_servo_lock(s)).ok_or_else(|| anyhow!("the stop was never accepted"))?;
    let end = time.len() - 1;
    let settled = settled_from(&complete, accepted, end)
        .ok_or_else(|| anyhow!("no completion after the stop at gain {multiplier}"))?;
    let hold = col(&t, "seq_hold_position")?[end];
    let overshoot = dev[accepted..].iter().fold(0.0f64, |m, d| m.max(d.abs())) as i64;

    // Phase 2: from the lock, release and move 1 rad forward.
    let target = hold + 1.0;
    let move_at = 1.0;
    let move_text = format!(
        "{stop_text}[[events]]\ntime={move_at}\nevent='release'\n[[events]]\ntime={move_at}\nevent='move'\ntarget={target:?}\n"
    )
    .replace("stop_time=1.5", "stop_time=2.5");
    let m = run(fmu, &move_text)?;
    let (mtime, mcomplete, mpos) = (col(&m, "time")?, col(&m, "seq_complete")?, col(&m, "motor_position")?);
    let k = at(&mtime, move_at);
    let mend = mtime.len() - 1;
    let msettled = settled_from(&mcomplete, k + 1, mend)
        .ok_or_else(|| anyhow!("no completion after the move at gain {multiplier}"))?;
    let counts_per_rad =
        servo_axis::plant::PlantParams::default().encoder_counts_per_rev as f64 / std::f64::consts::TAU;
    let past = mpos[k..].iter().fold(0.0f64, |m, p| m.max(p - target));
    Ok(GainFigures {
        multiplier,
        acceptance: time[accepted] - STOP_AT,
        stop_settle: time[settled] - time[accepted],
        stop_overshoot_counts: overshoot,
        stop_error_at_completion: dev[settled].abs() as i64,
        stop_error_at_rest: dev[end].abs() as i64,
        move_settle: mtime[msettled] - move_at,
        move_overshoot_counts: (past * counts_per_rad).round() as i64,
    })
}

/// Time a grid stop's run leaves for completion after the deceleration (s; the deceleration
/// counted as at least 0.1 s, 200 rad/s at 2 000 rad/s², so that every grid run lasts 2.5 s):
/// about twice the longest settle seen (1.05 s, a 1-count width on a 4.3:1 load and a 151 Hz
/// shaft). A stop that completes later counts as never complete, and a toggle up to the end
/// counts.
const COMPLETION_WINDOW: f64 = 2.1;

/// The stop key of a run at `speed` with the gradient `acceleration`: at 0.3 s, or once the
/// ramp has reached the speed (and 50 ms more) where it takes longer; on the step grid.
fn stop_key_time(speed: f64, acceleration: f64) -> f64 {
    on_step_grid(STOP_AT.max(speed / acceleration + 0.05))
}

/// `t` rounded up to a whole number of the scenario's steps.
fn on_step_grid(t: f64) -> f64 {
    (t / DEFAULT_STEP - 1e-9).ceil() * DEFAULT_STEP
}

/// One stop (see [`GridStop`]) on the default axis, or on `plant` where given.
fn grid_stop(
    fmu: &Fmu,
    plant: Option<&PlantCase>,
    (speed, vh, width): (f64, f64, u32),
    index: usize,
    multiplier: f64,
    acceleration: f64,
) -> Result<GridStop> {
    let key = stop_key_time(speed, acceleration);
    let decelerating = speed / acceleration;
    let stop_time = on_step_grid(key + decelerating.max(0.1) + COMPLETION_WINDOW);
    let text = format!(
        "name='bench_grid'\nstop_time={stop_time:?}\n[parameters]\n\"seq.target_speed\"={speed:?}\n\"seq.zero_speed\"={vh:?}\n\"seq.completion_counts\"={width}\n\
         [[events]]\ntime=0.0\nevent='run'\n[[events]]\ntime=0.0\nevent='gain'\nindex={index}\n\
         [[events]]\ntime={key:?}\nevent='run_off'\n[[events]]\ntime={key:?}\nevent='stop'\n"
    );
    let mut scenario: SequenceScenario = toml::from_str(&text)?;
    scenario.parameters.extend(plant.map(PlantCase::parameters).unwrap_or_default());
    scenario.parameters.insert("seq.acceleration".into(), Value::Float(acceleration));
    let t = run_scenario(fmu, &scenario)?;
    let (state, complete, dev, time, v) = (
        col(&t, "seq_state")?,
        col(&t, "seq_complete")?,
        col(&t, "seq_deviation")?,
        col(&t, "time")?,
        col(&t, "velocity_estimate")?,
    );
    let defaults = servo_axis::plant::PlantParams::default();
    let label = plant.map_or("default".to_string(), PlantCase::label);
    let Some(accepted) = state.iter().position(|&s| is_servo_lock(s)) else {
        // Never accepted: a miss of the figure (never complete), not an error of the run.
        return Ok(GridStop {
            plant: label,
            speed,
            zero_speed: vh,
            width,
            multiplier,
            speed_at_acceptance: f64::NAN,
            stopping_counts: f64::NAN,
            lag_counts: f64::NAN,
            resolution_counts: f64::NAN,
            windup_counts: f64::NAN,
            swing_counts: 0,
            overshoot_counts: 0,
            settle: f64::NAN,
            toggles: 0,
        });
    };
    let counts_per_rad = defaults.encoder_counts_per_rev as f64 / std::f64::consts::TAU;
    let (jl, k) =
        plant.map_or((defaults.load_inertia, defaults.shaft_stiffness), PlantCase::load_inertia_and_stiffness);
    let params = control_core::Params::default();
    let loop_time_constant = (defaults.motor_inertia + jl) / params.velocity.kp as f64;
    let velocity_period = params.rates.velocity_period() as f64;
    let va = v[accepted].abs();
    let first = (accepted..complete.len()).find(|&i| complete[i] != 0.0);
    let toggles = first.map_or(0, |f| complete[f..].windows(2).filter(|w| w[0] != w[1]).count() as u32);
    Ok(GridStop {
        plant: label,
        speed,
        zero_speed: vh,
        width,
        multiplier,
        speed_at_acceptance: va,
        stopping_counts: va * va / (2.0 * acceleration) * counts_per_rad,
        lag_counts: va * loop_time_constant * counts_per_rad,
        resolution_counts: va / (acceleration * velocity_period),
        windup_counts: jl * acceleration / k * counts_per_rad,
        swing_counts: dev[accepted..].iter().fold(0.0f64, |m, d| m.max(d.abs())) as i64,
        overshoot_counts: first
            .map_or(0, |f| dev[f..].iter().fold(0.0f64, |m, d| m.max(d.abs() - width as f64)) as i64),
        settle: first.map_or(f64::NAN, |f| time[f] - time[accepted]),
        toggles,
    })
}

/// A stop's swing after acceptance over its bound (see [`SWING_WINDUP_FACTOR`]).
pub fn swing_ratio(g: &GridStop) -> f64 {
    let hysteresis = control_core::Params::default().sequence.completion_hysteresis as f64;
    g.swing_counts as f64
        / (g.stopping_counts
            + g.lag_counts
            + g.resolution_counts
            + SWING_WINDUP_FACTOR * g.windup_counts
            + g.width as f64
            + hysteresis)
}

/// The stop meets the figure: completion raised, never toggled, the swing within its bound.
pub fn stop_holds(g: &GridStop) -> bool {
    !g.settle.is_nan() && g.toggles == 0 && swing_ratio(g) <= 1.0
}

pub fn grid_figures(grid: &[GridStop]) -> GridFigures {
    let worst = grid.iter().max_by(|a, b| swing_ratio(a).total_cmp(&swing_ratio(b))).cloned();
    let never_complete = grid.iter().filter(|g| g.settle.is_nan()).count();
    let max_toggles = grid.iter().map(|g| g.toggles).max().unwrap_or(0);
    let worst_swing_ratio = worst.as_ref().map_or(0.0, swing_ratio);
    GridFigures {
        runs: grid.len(),
        never_complete,
        max_toggles,
        max_overshoot_counts: grid.iter().map(|g| g.overshoot_counts).max().unwrap_or(0),
        max_settle: grid.iter().map(|g| g.settle).filter(|s| !s.is_nan()).fold(0.0, f64::max),
        worst_swing_ratio,
        worst_swing: worst,
        holds: grid.iter().all(stop_holds),
    }
}

/// The grid alone: every speed, zero-speed level, width and gain of the default table.
pub fn bench_grid(fmu: &Fmu, mut progress: impl FnMut(f64)) -> Result<Vec<GridStop>> {
    let defaults = control_core::Params::default().sequence;
    let total = GRID_SPEEDS.len() * GRID_ZERO_SPEEDS.len() * GRID_WIDTHS.len() * defaults.gain_count;
    let mut grid = Vec::with_capacity(total);
    for &speed in &GRID_SPEEDS {
        for &vh in &GRID_ZERO_SPEEDS {
            for &width in &GRID_WIDTHS {
                for i in 0..defaults.gain_count {
                    progress(grid.len() as f64 / total as f64);
                    grid.push(grid_stop(fmu, None, (speed, vh, width), i, defaults.gains[i] as f64, ACCELERATION)?);
                }
            }
        }
    }
    Ok(grid)
}

/// `n` stops drawn with `seed`, each on its own plant (inertia ratio and shaft resonance as
/// `servo bench sweep --random` draws them: 0.2–5, 50–500 Hz), with a run speed, zero-speed
/// level and completion width each log-uniform over the grid's range (10–200 rad/s,
/// 0.5–20 rad/s, 1–100 counts) and a gain of the table: cases the project does not ship.
pub fn random_stops(n: u32, seed: u64) -> Vec<(PlantCase, (f64, f64, u32), usize)> {
    let plants = crate::sweep::bench::random_plants(n, seed);
    let mut rng = crate::random::XorShift64Star(seed.wrapping_mul(0xD1B5_4A32_D192_ED03) | 1);
    let gains = control_core::Params::default().sequence.gain_count as u64;
    let range = |values: &[f64]| (values[0], values[values.len() - 1]);
    let ((v0, v1), (h0, h1)) = (range(&GRID_SPEEDS), range(&GRID_ZERO_SPEEDS));
    let (w0, w1) = (GRID_WIDTHS[0] as f64, GRID_WIDTHS[GRID_WIDTHS.len() - 1] as f64);
    plants
        .into_iter()
        .map(|plant| {
            let speed = rng.log_uniform_3_digits(v0, v1);
            let level = rng.log_uniform_3_digits(h0, h1);
            let width = rng.log_uniform_3_digits(w0, w1).round() as u32;
            (plant, (speed, level, width), rng.below(gains) as usize)
        })
        .collect()
}

/// The drawn stops of [`random_stops`], each run once at the gradient `acceleration`
/// (rad/s²; the grid's is [`ACCELERATION`], the default).
pub fn bench_random(
    fmu: &Fmu,
    n: u32,
    seed: u64,
    acceleration: f64,
    mut progress: impl FnMut(f64),
) -> Result<Vec<GridStop>> {
    let gains = control_core::Params::default().sequence.gains;
    let stops = random_stops(n, seed);
    let mut grid = Vec::with_capacity(stops.len());
    for (k, (plant, stop, gain)) in stops.iter().enumerate() {
        progress(k as f64 / stops.len() as f64);
        grid.push(grid_stop(fmu, Some(plant), *stop, *gain, gains[*gain] as f64, acceleration)?);
    }
    Ok(grid)
}

pub fn bench(fmu: &Fmu, zero_speeds: &[f64], mut progress: impl FnMut(f64)) -> Result<SequenceBench> {
    let grid = bench_grid(fmu, |f| progress(0.8 * f))?;
    let grid_figures = grid_figures(&grid);
    let mut progress = |f: f64| progress(0.8 + 0.2 * f);
    let defaults = control_core::Params::default().sequence;
    if defaults.target_speed as f64 != RUN_SPEED || defaults.acceleration as f64 != ACCELERATION {
        bail!("the bench assumes the default run speed and gradient");
    }
    let mut gains = Vec::new();
    let total = defaults.gain_count + zero_speeds.len();
    for i in 0..defaults.gain_count {
        progress(i as f64 / total as f64);
        gains.push(stop_and_move(fmu, i, defaults.gains[i] as f64)?);
    }
    let mut acceptance = Vec::new();
    for (j, &vh) in zero_speeds.iter().enumerate() {
        progress((defaults.gain_count + j) as f64 / total as f64);
        if !(vh.is_finite() && vh > 0.0 && vh < RUN_SPEED) {
            bail!("zero-speed level {vh} rad/s must lie between 0 and the run speed {RUN_SPEED}");
        }
        let text = format!(
            "name='bench_zero_speed'\nstop_time=0.5\n[parameters]\n\"seq.zero_speed\"={vh:?}\n[[events]]\ntime=0.0\nevent='run'\n\
             [[events]]\ntime={STOP_AT}\nevent='run_off'\n[[events]]\ntime={STOP_AT}\nevent='stop'\n"
        );
        let t = run(fmu, &text)?;
        let (time, state) = (col(&t, "time")?, col(&t, "seq_state")?);
        let accepted =
            state.iter().position(|&s| is_servo_lock(s)).ok_or_else(|| anyhow!("no acceptance at {vh} rad/s"))?;
        acceptance.push(AcceptanceFigure {
            zero_speed: vh,
            measured: time[accepted] - STOP_AT,
            ramp: (RUN_SPEED - vh) / ACCELERATION,
        });
    }
    progress(1.0);
    let falls = gains.windows(2).all(|w| w[1].move_settle < w[0].move_settle && w[1].stop_settle < w[0].stop_settle);
    Ok(SequenceBench { grid, grid_figures, gains, acceptance, settle_falls_with_gain: falls })
}
