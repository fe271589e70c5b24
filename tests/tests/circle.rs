//! Circle tests (seed 002) on the FMU: the pseudo-circle of one friction-free axis coincides
//! with the two-axis circle of two identical axes; friction compensation shrinks the quadrant
//! protrusions; fmpy gives the same single-axis feedback trace.

use cross_checks::{fmu_path, load_fmu};
use host_tools::circle::bench::{bench, demo_request};
use host_tools::fmu::circle::single_axis;
use host_tools::fmu::fmpy::run_fmpy;
use host_tools::fmu::trace::{compare_exact, Trace};

#[test]
fn pseudo_circle_equals_the_two_axis_circle_and_compensation_shrinks_protrusions() {
    let r = bench(&load_fmu()).unwrap();
    assert!(r.pseudo_vs_two_axis_relative <= 1e-3, "{r:?}");
    // Friction leaves protrusions well above the encoder's resolution (6 µrad)...
    assert!(r.protrusion_off > 1e-4, "{r:?}");
    // ...and the reversal pulse removes most of them.
    assert!(r.protrusion_ratio < 0.3, "{r:?}");
}

#[test]
fn protrusions_sit_just_after_the_axis_reversals() {
    let run = host_tools::fmu::circle::two_axis(&load_fmu(), &demo_request(Default::default())).unwrap();
    let f = run.feedback.roundness(1.0);
    let largest = f.max_protrusion.expect("every quadrant measured");
    for (p, quadrant) in f.protrusions.iter().zip([0.0, 90.0, 180.0, 270.0]) {
        let (angle, height) = p.expect("every quadrant measured");
        let after = (angle - quadrant + 540.0f64).rem_euclid(360.0) - 180.0;
        assert!((0.0..=15.0).contains(&after), "peak at {angle}° for the reversal at {quadrant}°");
        assert!(height > 0.5 * largest, "all four quadrants alike: {:?}", f.protrusions);
    }
}

#[test]
fn single_axis_feedback_is_bit_identical_in_fmpy() {
    let run = single_axis(&load_fmu(), &demo_request(Default::default())).unwrap();
    let dir = std::env::temp_dir().join(format!("servo-circle-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let inputs = dir.join("pseudo.toml");
    std::fs::write(&inputs, run.scenario.to_toml()).unwrap();
    let csv = dir.join("pseudo.fmpy.csv");
    run_fmpy(&fmu_path(), &inputs, &csv).unwrap();
    match compare_exact(&run.trace, &Trace::read_csv(&csv).unwrap()).unwrap() {
        Ok(n) => assert_eq!(n, run.trace.columns.len()),
        Err(m) => panic!("{m:?}"),
    }
}
