//! Stop / zero-servo / fine-adjust sequence (seed 004) on the FMU: the shipped timelines pass
//! and run bit for bit the same in fmpy; acceptance follows the analytic deceleration ramp;
//! the hand-over to position control does not jump the torque; higher gains settle faster.

use cross_checks::{fmu_path, load_fmu};
use host_tools::fmu::fmpy::run_fmpy;
use host_tools::fmu::trace::{compare_exact, Trace};
use host_tools::paths::workspace_root;
use host_tools::sequence::bench::{bench, bench_random, grid_figures, swing_ratio, ACCELERATION};
use host_tools::sequence::timeline::SequenceScenario;

fn shipped() -> Vec<SequenceScenario> {
    let dir = workspace_root().join("scenarios/sequences");
    let mut v: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "toml"))
        .collect();
    v.sort();
    assert!(v.len() >= 4, "one timeline per embodiment and one of refused events");
    v.iter().map(|p| SequenceScenario::load(p).unwrap()).collect()
}

#[test]
fn shipped_timelines_pass_and_are_bit_identical_in_fmpy() {
    let fmu = load_fmu();
    let tmp = std::env::temp_dir().join(format!("servo-seq-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    for s in shipped() {
        let scenario = s.to_scenario();
        let trace = fmu.run(&scenario, |_| {}).unwrap();
        for o in s.evaluate(&trace).unwrap() {
            assert!(o.passed, "{}: {} — observed {}, asked {}", s.name, o.description, o.observed, o.bound);
        }
        let inputs = tmp.join(format!("{}.toml", s.name));
        std::fs::write(&inputs, scenario.to_toml()).unwrap();
        let csv = tmp.join(format!("{}.fmpy.csv", s.name));
        run_fmpy(&fmu_path(), &inputs, &csv).unwrap();
        match compare_exact(&trace, &Trace::read_csv(&csv).unwrap()).unwrap() {
            Ok(n) => assert_eq!(n, trace.columns.len()),
            Err(m) => panic!("{}: {m:?}", s.name),
        }
    }
}

#[test]
fn acceptance_follows_the_deceleration_ramp_and_settling_speeds_up_with_gain() {
    let fmu = load_fmu();
    let r = bench(&fmu, &[0.5, 5.0, 30.0], |_| {}).unwrap();
    let tick = 0.00025;
    for a in &r.acceptance {
        // The speed lags the ramp by the velocity loop and the estimate's sample: at most
        // two position ticks.
        assert!(a.measured >= a.ramp - 1e-9 && a.measured <= a.ramp + 2.0 * tick + 1e-9, "{a:?}");
    }
    assert!(r.settle_falls_with_gain, "{:?}", r.gains);
    // The grid (speeds 10-200 rad/s, levels 0.5-20 rad/s, widths 1-100 counts, every gain):
    // completion raised in every run and never toggling, the swing within its bound.
    let g = &r.grid_figures;
    assert!(g.holds, "{g:?}");
    assert_eq!((g.max_toggles, g.never_complete), (0, 0));
    for g in &r.gains {
        assert!(g.stop_error_at_rest <= 2, "stop error at rest {g:?}");
    }
}

#[test]
fn hand_over_to_position_control_does_not_jump_the_torque() {
    let fmu = load_fmu();
    let s = shipped().into_iter().find(|s| s.name == "stop_at_speed").unwrap();
    let t = fmu.run(&s.to_scenario(), |_| {}).unwrap();
    let (state, torque) = (t.column("seq_state").unwrap(), t.column("torque_command_out").unwrap());
    let k = state.iter().position(|&x| x == 3.0).unwrap();
    // Largest step-to-step torque change during the deceleration before acceptance.
    let decel_start = state.iter().position(|&x| x == 2.0).unwrap();
    let typical = (decel_start + 4..k).map(|i| (torque[i] - torque[i - 1]).abs()).fold(0.0, f64::max);
    let at_hand_over = (k..k + 4).map(|i| (torque[i] - torque[i - 1]).abs()).fold(0.0, f64::max);
    assert!(
        at_hand_over <= typical.max(0.01) * 1.5,
        "torque step {at_hand_over} N·m at the hand-over vs {typical} N·m while decelerating"
    );
}

/// Off the shipped axis (`servo bench sequence --random`): 100 stops, each on a plant drawn in
/// the ranges (inertia ratio 0.2–5, shaft 50–500 Hz) at a drawn speed, level, width and gain.
/// Completion is raised in each and never toggles, and the swing stays within its bound,
/// whose wind-up term is checked here against J_L·a/k worked from the printed plant. With the
/// bound's former fixed 500 counts instead of the wind-up, this draw's worst stop read 1.98.
#[test]
fn stops_on_drawn_plants_complete_once_and_swing_within_the_shaft_wind_up_bound() {
    let fmu = load_fmu();
    let stops = bench_random(&fmu, 100, 1, ACCELERATION, |_| {}).unwrap();
    let g = grid_figures(&stops);
    assert!(g.holds && g.max_toggles == 0 && g.never_complete == 0, "{g:?}");
    let counts_per_rad = (1u64 << 20) as f64 / std::f64::consts::TAU;
    for s in &stops {
        // "J_L/J_M 4.35, 63.2 Hz": f_r = √(k·(1/J_M + 1/J_L))/2π with J_M = 5e-5 kg·m².
        let numbers: Vec<f64> = s
            .plant
            .trim_start_matches("J_L/J_M ")
            .trim_end_matches(" Hz")
            .split(", ")
            .map(|x| x.parse().unwrap())
            .collect();
        let (jm, jl) = (5e-5, 5e-5 * numbers[0]);
        let w = std::f64::consts::TAU * numbers[1];
        let k = w * w / (1.0 / jm + 1.0 / jl);
        let windup = jl * 2000.0 / k * counts_per_rad;
        assert!((s.windup_counts - windup).abs() <= 1e-9 * windup, "{s:?}: {windup}");
        // The velocity loop's lag v·J/k_p, from the default gain 0.0942 N·m·s/rad.
        let lag = s.speed_at_acceptance * (jm + jl) / 0.0942 * counts_per_rad;
        assert!((s.lag_counts - lag).abs() <= 1e-5 * lag, "{s:?}: {lag}");
        // One count of the estimate per 125 µs velocity period (8 kHz) moves v²/(2a) by v·δv/a.
        let resolution = s.speed_at_acceptance * (1.0 / counts_per_rad / 125e-6) / 2000.0 * counts_per_rad;
        assert!((s.resolution_counts - resolution).abs() <= 1e-5 * resolution, "{s:?}: {resolution}");
        assert!(swing_ratio(s) <= 1.0, "{s:?}");
    }
}

/// At a steep gradient (10 000 rad/s², five times the default) the stopping distance shrinks
/// and the velocity loop's lag behind its reference (up to v·J/k_p, the loop's time constant
/// J/k_p being 0.6–3.2 ms over the drawn loads) does not: the bound counts it. Without that
/// term (1.5·v²/(2a) for the stopping distance, as the bound read before) the 248th of these
/// 300 drawn stops, a 3.27:1 axis stopped from 18 rad/s, swings 1.18 times it; with it every
/// stop holds.
#[test]
fn stops_at_a_steep_gradient_swing_within_the_velocity_loop_s_lag() {
    let fmu = load_fmu();
    let stops = bench_random(&fmu, 300, 1, 10_000.0, |_| {}).unwrap();
    let g = grid_figures(&stops);
    assert!(g.holds && g.max_toggles == 0 && g.never_complete == 0, "{g:?}");
    let hysteresis = control_core::Params::default().sequence.completion_hysteresis as f64;
    let without_lag = |s: &host_tools::sequence::bench::GridStop| {
        s.swing_counts as f64 / (1.5 * s.stopping_counts + 4.0 / 3.0 * s.windup_counts + s.width as f64 + hysteresis)
    };
    let worst = stops.iter().map(without_lag).fold(0.0, f64::max);
    assert!(worst > 1.1, "without the loop's lag the bound would still hold: {worst}");
}
