//! Frequency response with phase-shifted repeats (seed 000) on the FMU, against the oracle
//! (acquisition at the loop rate, long records), the analytic linear loop at low
//! frequencies, and fmpy.

use std::collections::BTreeMap;

use control_core::phase_shifted_sweep::SweepParams;
use cross_checks::{fmu_path, load_fmu};
use host_tools::fmu::fmpy::run_fmpy;
use host_tools::fmu::sweep_run::SweepRun;
use host_tools::fmu::trace::{compare_exact, Trace};
use host_tools::sweep::bench::bench;

#[test]
fn phase_shifting_measures_beyond_the_acquisition_nyquist_frequency_and_single_phase_does_not() {
    let r = bench(&load_fmu(), 0.05, |_| {}).unwrap();
    let e = &r.ours.errors;
    assert_eq!(e.points_compared, 41);
    assert!(e.below_gain_db <= 0.1 && e.above_gain_db <= 0.1, "{e:?}");
    assert!(e.below_phase_deg <= 1.0 && e.above_phase_deg <= 1.0, "{e:?}");
    assert!(r.ours.measurement_time_s <= 10.0);
    // The drive's f32 correlator and the host's f64 fit of the same samples agree.
    assert!(r.stream_vs_online.0 <= 0.01 && r.stream_vs_online.1 <= 0.1, "{:?}", r.stream_vs_online);
    // At exactly 2 kHz a single phase sees the sine at one phase and its opposite.
    let [oracle, ours, single] = r.at_nyquist;
    assert!((ours.gain_db - oracle.gain_db).abs() < 0.1 && ours.quality > 0.99);
    assert!(single.quality < 0.01, "{single:?}");
    let single_error = (single.gain_db - oracle.gain_db).abs().max((single.phase_deg - oracle.phase_deg).abs() / 10.0);
    assert!(!single_error.is_finite() || single_error > 3.0, "single phase must visibly fail at 2 kHz: {single:?}");
    // Below the threshold both stepped sines are the same measurement.
    assert_eq!(r.single_phase.errors.below_gain_db, e.below_gain_db);
    // The analytic closed loop (PI, two-inertia plant, estimate and torque delays).
    assert!(r.analytic_low_frequency.0 <= 0.1 && r.analytic_low_frequency.1 <= 1.0, "{:?}", r.analytic_low_frequency);
    // Without the quantisation the loop's encoder adds, ours and the oracle agree closely:
    // what is left above is the encoder's, not the method's.
    let f = &r.fine_encoder;
    assert!(f.below_gain_db.max(f.above_gain_db) <= 0.02 && f.below_phase_deg.max(f.above_phase_deg) <= 0.2, "{f:?}");
    // The goal holds over riding speeds (the quantisation pattern changes with the speed),
    // and lengthening the low-gain points is what makes it hold.
    assert!(r.spread_lengthened.0 <= 0.1 && r.spread_lengthened.1 <= 1.0, "{:?}", r.spread_lengthened);
    assert!(r.spread_lengthened.0 < r.spread_fixed.0, "{:?} vs {:?}", r.spread_lengthened, r.spread_fixed);
    // With noise, longer records help ours, and ours beats PRBS over the same time.
    for n in &r.noise {
        assert!(n.ours.0 < n.prbs.0 && n.ours.1 < n.prbs.1, "{n:?}");
    }
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
