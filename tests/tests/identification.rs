//! Anti-resonance identification (seed 001) on the FMU against the plant's truth (the
//! absorber's √(ka/Ja) and ca/(2√(ka·Ja))), with and without accelerometer noise, and the
//! refusals of unusable data.

use std::collections::BTreeMap;

use cross_checks::load_fmu;
use host_tools::fmu::scenario::Value;
use host_tools::ident::identification::{absorber_parameters, identify, measure, true_anti_resonance};
use host_tools::ident::report::identify_axis;

const LOAD: f64 = 1.0e-4;

fn truth(hz: f64) -> host_tools::ident::identification::Factor {
    let w = std::f64::consts::TAU * hz;
    true_anti_resonance(LOAD, LOAD * w * w, 2.0 * 0.05 * LOAD * w)
}

#[test]
fn anti_resonances_are_found_within_one_percent_at_20_db_snr() {
    let fmu = load_fmu();
    let out = std::env::temp_dir().join(format!("servo-ident-{}", std::process::id()));
    // The grid's ends and its hardest cases: 15 Hz (the closed loop cuts the torque there),
    // 200 Hz (a shallow notch next to the shaft's resonance), and the demo's 40 Hz.
    for hz in [15.0, 40.0, 200.0] {
        let r = identify_axis(&fmu, "x", &absorber_parameters(hz, 0.05, LOAD), 0.05, Some(20.0), &out).unwrap();
        assert_eq!(r.refusal, None, "{hz} Hz");
        let model = r.model.expect("a model");
        let (z, t) = (model.anti_resonance.expect("an anti-resonance"), truth(hz));
        assert!(((z.hz - t.hz) / t.hz).abs() <= 0.01, "{hz} Hz: found {z:?}, truth {t:?}");
        assert!(((z.damping - t.damping) / t.damping).abs() <= 0.2, "{hz} Hz: found {z:?}, truth {t:?}");
    }
}

#[test]
fn a_rigid_axis_has_no_anti_resonance() {
    let m = measure(&load_fmu(), &BTreeMap::new(), 0.05, 5.0, 500.0).unwrap();
    let identified = identify("w", &m).unwrap();
    assert_eq!(identified.model.anti_resonance, None, "{identified:?}");
    // The reason: the deepest dip is too shallow to count.
    let notch = identified.notch.expect("searched");
    assert!(!notch.is_clear(), "{notch:?}");
}

#[test]
fn saturated_torque_is_refused_with_the_reason() {
    let mut p = absorber_parameters(40.0, 0.05, LOAD);
    p.insert("plant.motor_coulomb".into(), Value::Float(0.01));
    // An M-sequence of ±3 N·m reaches the current limit's 2 N·m (kt·max_current; it is added
    // after the loop's clamp, and the PRBS adds no dither beside it): the drive refuses it
    // before it starts, naming the amplitude and the largest it takes.
    let e = measure(&load_fmu(), &p, 3.0, 5.0, 500.0).unwrap_err();
    assert!(format!("{e:#}").contains("sweep amplitude = 3 is outside [0, 2.0000"), "{e:#}");
    // Below the limit but with the friction's riding torque on top, the excitation is cut at
    // the limit during the measurement: the host refuses the data.
    let e = measure(&load_fmu(), &p, 1.995, 5.0, 500.0).unwrap_err();
    assert!(format!("{e:#}").contains("saturated"), "{e:#}");
}

/// Absorbers tuned next to the axis's own mode (208–215 Hz on this axis): the resonance masks
/// the zero and the notch is 2–3 dB deep at 20 dB SNR. The identification finds the zero
/// within the goals, says it cannot (undetermined, with the refits' spread, refused because
/// the fitted zero lies outside the notch, or no clear notch at all), and never reports a
/// value off the truth: once, a 208 Hz absorber was reported at 362 Hz and a 218 Hz one at
/// 265 Hz, both with exit status 0. The output-error fit finds the zero on some of these
/// cases (checked against the truth: the test fails where none is found).
#[test]
fn a_masked_anti_resonance_is_reported_as_such_never_as_a_wrong_value() {
    let fmu = load_fmu();
    let out = std::env::temp_dir().join(format!("servo-ident-masked-{}", std::process::id()));
    let mut told = (0, 0);
    let mut found = 0;
    for (hz, seed) in [(205.0, 1), (208.0, 1), (208.0, 3), (218.0, 1), (218.0, 2), (220.0, 3)] {
        let mut p = absorber_parameters(hz, 0.05, LOAD);
        p.insert("plant.noise_seed".into(), Value::Int(seed));
        let r = identify_axis(&fmu, "x", &p, 0.05, Some(20.0), &out).unwrap();
        match (r.model.as_ref().and_then(|m| m.anti_resonance), &r.refusal, &r.undetermined) {
            (Some(z), _, _) => {
                let t = truth(hz);
                assert!(((z.hz - t.hz) / t.hz).abs() <= 0.01, "{hz} Hz: reported {z:?}, truth {t:?}");
                assert!(((z.damping - t.damping) / t.damping).abs() <= 0.2, "{hz} Hz: reported {z:?}, truth {t:?}");
                found += 1;
            }
            (None, Some(why), _) => {
                assert!(why.contains("does not explain the notch"), "{hz} Hz: {why}");
                told.0 += 1;
            }
            (None, None, Some(why)) => {
                assert!(why.contains("does not determine") && why.contains("masks it"), "{hz} Hz: {why}");
                told.1 += 1;
            }
            // A notch at the clarity threshold (2–3 dB deep under 20 dB SNR) may also be
            // read as no clear notch: a statement, not a wrong value.
            (None, None, None) => {
                assert!(r.notch.is_none_or(|n| !n.is_clear()), "{hz} Hz: a clear notch with no outcome: {:?}", r.notch);
            }
        }
    }
    assert!(found >= 1, "no masked zero found (refused, undetermined: {told:?}): the value checks did not run");
}
