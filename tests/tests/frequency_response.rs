//! Frequency response with phase-shifted repeats (seed 000) on the FMU, against the oracle
//! (acquisition at the loop rate, long records, a 2^24-count encoder, no sensor noise), the
//! analytic linear loop at low frequencies, and fmpy.

use std::collections::BTreeMap;

use control_core::phase_shifted_sweep::SweepParams;
use cross_checks::{fmu_path, load_fmu};
use host_tools::fmu::fmpy::run_fmpy;
use host_tools::fmu::sweep_run::SweepRun;
use host_tools::fmu::trace::{compare_exact, Trace};
use host_tools::sweep::bench::bench;

#[test]
fn phase_shifting_measures_every_injection_point_against_the_oracle_and_single_phase_does_not() {
    let r = bench(&load_fmu(), 1, |_| {}).unwrap();
    // The default axis: every injection point, with and without sensor noise, within 0.1 dB,
    // 1 deg and 10 s of measurement against the oracle at every frequency.
    let default_rows: Vec<_> = r.grid.iter().filter(|row| row.plant.starts_with("default")).collect();
    assert_eq!(default_rows.len(), 6);
    for row in &default_rows {
        assert!(row.met, "{row:?}");
    }
    // Every plant (both inertia ratios, shaft resonance 50 and 500 Hz) meets the accuracy
    // goal at every point, with and without noise, and the time: the sweep's 9.9 s budget
    // bounds it where the low end took long (the heavy 50 Hz plant's 20 Hz anti-resonance
    // rings after each step and the settling check waits for it; noise lengthens the low end
    // of the light one).
    for row in &r.grid {
        assert!(row.gain_db <= 0.1 && row.phase_deg <= 1.0, "{row:?}");
        assert!(row.measurement_time_s <= 10.0, "{row:?}");
    }
    // The bench reports a miss as a miss.
    assert_eq!(r.goals_met(), r.grid.iter().all(|row| row.met) && r.limit_detection.iter().all(|c| c.met));
    // The oracle's own error, over every plant and point against itself with settling and
    // records twice as long at a riding speed 1 % higher, is far below the goal: a tenth of
    // it in gain. Undithered at the top, its encoder pattern locked to the excitation
    // (0.020 dB / 0.14 deg).
    assert!(r.oracle_self_check.0 <= 0.012 && r.oracle_self_check.1 <= 0.08, "{:?}", r.oracle_self_check);
    // Riding at 100 and 200 rad/s the bus runs out of voltage at the top: every result off the
    // goals is flagged as measured with the output limited, and the flags catch real errors.
    for c in &r.limit_detection {
        assert!(c.met, "{c:?}");
    }
    let fastest: Vec<_> = r.limit_detection.iter().filter(|c| c.riding_rad_s == 200.0).collect();
    assert!(fastest.iter().all(|c| c.flagged_hz.contains(&3000.0)), "{fastest:?}");
    assert!(fastest.iter().all(|c| c.flagged.0 > 0.1 || c.flagged.1 > 1.0), "{fastest:?}");
    // The drive's f32 correlator and the host's f64 fit of the same samples agree.
    assert!(r.stream_vs_online.0 <= 0.01 && r.stream_vs_online.1 <= 0.1, "{:?}", r.stream_vs_online);
    // At exactly 2 kHz a single phase sees the sine at one phase and its opposite.
    let [oracle, ours, single] = r.at_nyquist;
    assert!((ours.gain_db - oracle.gain_db).abs() < 0.1 && ours.quality > 0.99);
    assert!(single.quality < 0.01, "{single:?}");
    let single_error = (single.gain_db - oracle.gain_db).abs().max((single.phase_deg - oracle.phase_deg).abs() / 10.0);
    assert!(!single_error.is_finite() || single_error > 3.0, "single phase must visibly fail at 2 kHz: {single:?}");
    // Below the threshold both stepped sines are the same measurement.
    assert_eq!(r.single_phase.errors.below_gain_db, r.ours.errors.below_gain_db);
    // PRBS over the same time is far less accurate below 2 kHz and cannot measure above.
    assert!(r.prbs.errors.below_gain_db > 5.0 * r.ours.errors.below_gain_db, "{:?}", r.prbs.errors);
    assert_eq!(r.prbs.unmeasured.len(), 4);
    // The analytic closed loop (PI, two-inertia plant, estimate and torque delays).
    assert!(r.analytic_low_frequency.0 <= 0.1 && r.analytic_low_frequency.1 <= 1.0, "{:?}", r.analytic_low_frequency);
}

#[test]
fn a_sweep_runs_bit_identically_in_fmpy() {
    let settings = SweepParams { start_hz: 500.0, stop_hz: 3000.0, points: 4, ..Default::default() };
    let run = SweepRun { settings, parameters: BTreeMap::new(), velocity: 50.0 };
    // Run until the sweep is done (its length depends on the precision it reaches), then give
    // fmpy the same number of steps.
    let trace = run.run(&load_fmu(), |_| {}).unwrap();
    let scenario = run.scenario_as_run(&trace).unwrap();
    let dir = std::env::temp_dir().join(format!("servo-sweep-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let inputs = dir.join("sweep.toml");
    std::fs::write(&inputs, scenario.to_toml()).unwrap();
    let csv = dir.join("sweep.fmpy.csv");
    run_fmpy(&fmu_path(), &inputs, &csv).unwrap();
    match compare_exact(&trace, &Trace::read_csv(&csv).unwrap()).unwrap() {
        Ok(n) => assert_eq!(n, trace.columns.len()),
        Err(m) => panic!("{m:?}"),
    }
}
