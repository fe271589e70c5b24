//! The velocity loop's tuning against references it does not compute itself: the plant model
//! the design and the calibration use (`autotune::plant_response`) against the FMU's
//! torque-point sweep on machines of the bench's ranges.

use host_tools::autotune::bench::{measure, Machine};
use host_tools::autotune::drive_dynamics::DriveDynamics;
use host_tools::autotune::mechanics::Mechanics;
use host_tools::autotune::velocity_controller::VelocityTuning;
use host_tools::autotune::{loop_plant, plant_response};
use host_tools::fmu::configuration::configuration;
use host_tools::fmu::runner::Fmu;

/// The analytic plant (the twin's mechanics through the drive's current loop and velocity
/// estimate) against the twin's measured torque-point response up to 1 kHz, on machines
/// across the bench's ranges: within 0.8 dB and 6° away from the shaft's modes, 2 dB and 10°
/// near them. The twin has what the model leaves out: measured against the model, a damping
/// of about 4·10⁻⁴ N·m·s/rad (a lag ∝ 1/f at the lowest frequencies, 2–5°) and a motor that
/// answers a few percent more than its inertia above the resonance; the calibration takes
/// them into its fit.
#[test]
fn the_plant_model_is_the_twins_measured_plant() {
    let fmu = Fmu::load(&host_tools::paths::default_fmu()).unwrap();
    for machine in [
        Machine { inertia_ratio: 2.0, resonance_hz: 150.0, damping_ratio: 0.05, absorber: None },
        Machine { inertia_ratio: 0.3, resonance_hz: 400.0, damping_ratio: 0.02, absorber: None },
        Machine { inertia_ratio: 4.5, resonance_hz: 60.0, damping_ratio: 0.08, absorber: None },
    ] {
        let parameters = machine.parameters();
        let config = configuration(&parameters).unwrap();
        let drive = DriveDynamics::on_plant(&config.control, &config.plant);
        let mechanics = Mechanics::of_plant(&config.plant);
        let readings = measure(&fmu, &parameters).unwrap();
        let during = VelocityTuning::of_params(&config.control);
        let period = config.control.rates.velocity_period() as f64;
        // Away from the shaft's modes and near them (from 0.8 of the anti-resonance to 1.25
        // of the resonance): worst gain (dB) and phase (°).
        let (fr, fa) = mechanics.resonance_hz();
        let (mut away, mut near) = ((0.0f64, 0.0f64), (0.0f64, 0.0f64));
        for p in readings.iter().filter(|p| p.frequency <= 1000.0) {
            let hz = p.frequency;
            let reading = p.to_complex();
            let model =
                drive.torque_sweep_reading(hz, plant_response(&drive, &mechanics, hz), during.response(hz, period));
            let e = (reading / model).ln();
            let (db, deg) = ((e.re * 20.0 / std::f64::consts::LN_10).abs(), e.im.to_degrees().abs());
            let w = if (0.8 * fa..=1.25 * fr).contains(&hz) { &mut near } else { &mut away };
            (w.0, w.1) = (w.0.max(db), w.1.max(deg));
        }
        assert!(away.0 <= 0.8 && away.1 <= 6.0, "{machine:?}: away from the modes {away:?}");
        assert!(near.0 <= 2.0 && near.1 <= 10.0, "{machine:?}: near the modes {near:?}");
    }
}

/// The back-EMF path in the drive's model against the twin: on a machine whose motor moves
/// alone above its shaft's modes, the FMU's torque-point sweep without current noise between
/// 250 Hz and 1 kHz reads the model with the path within 0.25 % on every point and 0.1 % on
/// average (0.06 % but at 1 kHz, 0.18 %), where the model without it (a feed-forward that
/// takes all of the back-EMF off) reads 0.4 % or more over the sweep on average (0.5 %).
#[test]
fn the_back_emf_path_is_in_the_twins_measured_plant() {
    let fmu = Fmu::load(&host_tools::paths::default_fmu()).unwrap();
    let machine = Machine { inertia_ratio: 2.0, resonance_hz: 60.0, damping_ratio: 0.05, absorber: None };
    let mut parameters = machine.parameters();
    parameters.insert(
        servo_axis::variables::name::plant_current_noise_std.to_string(),
        host_tools::fmu::scenario::Value::Float(0.0),
    );
    let config = configuration(&parameters).unwrap();
    let drive = DriveDynamics::on_plant(&config.control, &config.plant);
    let without = DriveDynamics { back_emf: 0.0, back_emf_feedforward: 0.0, ..drive };
    let mechanics = Mechanics::of_plant(&config.plant);
    let during = VelocityTuning::of_params(&config.control);
    let period = config.control.rates.velocity_period() as f64;
    let readings = measure(&fmu, &parameters).unwrap();
    let (mut with_path, mut without_path) = (Vec::new(), Vec::new());
    for p in readings.iter().filter(|p| (250.0..=1000.0).contains(&p.frequency)) {
        let (hz, reading) = (p.frequency, p.to_complex());
        let c = during.response(hz, period);
        let gain =
            |d: &DriveDynamics| (reading / d.torque_sweep_reading(hz, plant_response(d, &mechanics, hz), c)).norm();
        with_path.push(gain(&drive));
        without_path.push(gain(&without));
    }
    assert!(with_path.len() >= 8, "{} points", with_path.len());
    let mean = |g: &[f64]| g.iter().sum::<f64>() / g.len() as f64;
    assert!(
        (mean(&with_path) - 1.0).abs() < 0.001 && with_path.iter().all(|g| (g - 1.0).abs() < 0.0025),
        "with the path: {with_path:?}"
    );
    assert!(mean(&without_path) < 0.996, "without the path: {without_path:?}");
}

#[allow(dead_code)] // the helpers other tests use
mod common;

use common::{servo, tmp, OnTheFmu};

/// `servo autotune` on a machine it does not ship (a load three times the motor's on a 90 Hz
/// shaft, sensor noise on): exit 0, its files, the step measured on the twin matching the
/// predicted one, the calibrated mechanics within 5 % of the twin's, and its gains checked
/// on the **true** analytic plant (not the fit): stable, phase margin ≥ 44°, gain margin
/// ≥ 6 dB, Ms ≤ 1.7. A bad --margin is refused by name.
#[test]
fn autotune_tunes_a_machine_it_does_not_ship_and_the_true_plant_keeps_the_margins() {
    let machine = Machine { inertia_ratio: 3.0, resonance_hz: 90.0, damping_ratio: 0.03, absorber: None };
    let parameters = machine.parameters();
    let out = tmp("autotune");
    let mut c = servo();
    c.arg("autotune").on_fmu(&out).arg("--json");
    for (k, v) in &parameters {
        c.arg("--set").arg(format!("{k}={v}"));
    }
    let o = c.output().unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(0), "{stderr}");
    for f in [
        "autotune.toml",
        "calibrated-plant.toml",
        "autotune.json",
        "plant.svg",
        "open-loop.svg",
        "nyquist.svg",
        "closed-loop.svg",
        "step.svg",
        "disturbance.svg",
    ] {
        assert!(out.join(f).exists(), "{f}");
    }
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    // The step measured on the twin is the predicted one: overshoot within 5 points, the
    // waveform within 5 % of the step (RMS over the prediction's 150 ms; the twin's step is
    // followed for 300 ms), and both settled, the prediction within its 150 ms and the
    // measured one within 100 ms of the prediction (here a loop that lifts the
    // anti-resonance's dip with its integrator, whose tail rings for a hundred milliseconds:
    // the settling time, when a noisy estimate last leaves ±2 %, moves by a period of that
    // ring with a cycle more or less inside the band; the waveform's RMS above is the
    // tighter check). The search's design on this machine measures 0.228 s against 0.148 s
    // predicted, its waveform 3.2 % of the step from the prediction.
    let r = &j["responses"];
    let f = |a: &str, b: &str| r[a][b].as_f64().unwrap_or(f64::NAN);
    assert!((f("measured_step", "overshoot_percent") - f("tuned", "overshoot_percent")).abs() <= 5.0, "{r}");
    assert!(f("measured_step", "rms_difference_from_predicted") <= 0.05, "{r}");
    let (settle, predicted) = (f("measured_step", "settling_time_s"), f("tuned", "settling_time_s"));
    assert!(predicted < 0.15 && settle <= predicted + 0.1, "{r}");
    let config = configuration(&parameters).unwrap();
    let truth = Mechanics::of_plant(&config.plant);
    let fitted: Mechanics = serde_json::from_value(j["calibration"]["mechanics"].clone()).unwrap();
    for (got, want) in [
        (fitted.motor_inertia, truth.motor_inertia),
        (fitted.load_inertia, truth.load_inertia),
        (fitted.shaft_stiffness, truth.shaft_stiffness),
    ] {
        assert!((got / want - 1.0).abs() < 0.05, "{fitted:?} vs {truth:?}");
    }
    let tuning: host_tools::autotune::velocity_controller::VelocityTuning =
        serde_json::from_value(j["design"]["tuning"].clone()).unwrap();
    let m = margins_on_truth(&tuning, &config, &truth);
    assert!(m.stable && m.phase_margin_deg >= 44.0 && m.gain_margin_db >= 6.0 && m.sensitivity_peak <= 1.7, "{m:?}");
    let o = servo().arg("autotune").on_fmu(&out).args(["--margin", "reckless"]).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--margin must be conservative, standard or aggressive"));
}

/// `servo autotune` on a machine with an absorber on its load (a 350 Hz mode beside a 477 Hz
/// shaft, both above the loop's reach): the calibration finds the absorber (its inertia and
/// stiffness within 3 % of the twin's), the design puts a notch on each resonance, the twin's
/// verification holds, and the true analytic plant with the absorber keeps the margins.
#[test]
fn autotune_finds_an_absorber_and_gives_it_the_second_notch() {
    let out = tmp("autotune-absorber");
    let parameters = [
        ("plant.shaft_stiffness", 300.0),
        ("plant.absorber_inertia", 2e-5),
        ("plant.absorber_stiffness", 96.7),
        ("plant.absorber_damping", 1.76e-3),
    ];
    let mut c = servo();
    c.arg("autotune").on_fmu(&out).arg("--json");
    for (k, v) in parameters {
        c.arg("--set").arg(format!("{k}={v}"));
    }
    let o = c.output().unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let fitted: Mechanics = serde_json::from_value(j["calibration"]["mechanics"].clone()).unwrap();
    let named: std::collections::BTreeMap<String, host_tools::fmu::scenario::Value> =
        parameters.iter().map(|(k, v)| (k.to_string(), host_tools::fmu::scenario::Value::Float(*v))).collect();
    let config = configuration(&named).unwrap();
    let truth = Mechanics::of_plant(&config.plant);
    let (a, t) = (fitted.absorber.expect("an absorber fitted"), truth.absorber.unwrap());
    assert!((a.inertia / t.inertia - 1.0).abs() < 0.03 && (a.stiffness / t.stiffness - 1.0).abs() < 0.03, "{a:?}");
    let tuning: VelocityTuning = serde_json::from_value(j["design"]["tuning"].clone()).unwrap();
    let (n1, n2) = (tuning.notch.expect("a notch"), tuning.notch2.expect("a second notch"));
    // A notch on each of the chain's resonances (the features' first and fourth).
    let modes = truth.features_hz();
    let near = |n: host_tools::autotune::velocity_controller::Notch, hz: f64| (n.hz / hz).ln().abs() < 0.15;
    assert!(
        near(n1, modes[0]) && near(n2, modes[3]) || near(n1, modes[3]) && near(n2, modes[0]),
        "{tuning:?} against the resonances {} and {} Hz",
        modes[0],
        modes[3]
    );
    assert_eq!(j["verification"]["passed"], true, "{}", j["verification"]);
    let m = margins_on_truth(&tuning, &config, &truth);
    assert!(m.stable && m.phase_margin_deg >= 45.0 && m.gain_margin_db >= 6.0 && m.sensitivity_peak <= 1.7, "{m:?}");
}

/// `servo bench autotune` on a small draw of its own seed, measured on the FMU and on a
/// virtual drive: one row per machine, none unstable on its true plant, the tuning verified
/// where it was measured, the calibration within the 3 %, the workflow within 60 s
/// of drive time, the figures written, the exit status the figures' verdict.
#[test]
fn the_autotune_bench_runs_a_small_draw_on_the_fmu_and_on_a_virtual_drive() {
    for (arm, plants, extra) in [("fmu", "3", None), ("virtual-drive", "2", Some("--virtual-drive"))] {
        let out = tmp(&format!("autotune-bench-{arm}"));
        let mut c = servo();
        c.args(["bench", "autotune", "--plants", plants, "--seed", "2026", "--json"]).on_fmu(&out);
        c.args(extra);
        let o = c.output().unwrap();
        let stderr = String::from_utf8_lossy(&o.stderr);
        assert!(matches!(o.status.code(), Some(0 | 1)), "{stderr}");
        let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let rows = j["rows"].as_array().unwrap();
        assert_eq!(rows.len(), plants.parse::<usize>().unwrap());
        for r in rows {
            assert!(r["failed"].is_null(), "{arm}: {r}");
            assert_eq!(r["stable"], true, "{arm}: {r}");
            assert_eq!(r["verified"], true, "{arm}: {r}");
            assert!(r["phase_margin_deg"].as_f64().unwrap() >= 45.0, "{arm}: {r}");
            assert!(r["verified_phase_margin_deg"].as_f64().unwrap() >= 45.0, "{arm}: {r}");
            assert!(r["drive_time_s"].as_f64().unwrap() <= 60.0, "{arm}: {r}");
            let p = &r["position_on_truth"];
            assert_eq!(p["stable"], true, "{arm}: {r}");
            assert!(p["phase_margin_deg"].as_f64().unwrap() >= 45.0, "{arm}: {r}");
            assert!(p["sensitivity_peak"].as_f64().unwrap() <= 1.7, "{arm}: {r}");
            for e in &r["calibration_errors"].as_array().unwrap()[..3] {
                assert!(e.as_f64().unwrap() <= 0.03, "{arm}: {r}");
            }
        }
        // Figures with a goal (an information figure's `met` is null).
        let all_met = j["figures"]["figures"].as_array().unwrap().iter().all(|g| g["met"] != false);
        assert_eq!(o.status.code(), Some(if all_met { 0 } else { 1 }), "{stderr}");
        let name = if extra.is_some() { "autotune-virtual-drive.json" } else { "autotune.json" };
        assert!(out.join(name).exists(), "{arm}: no {name}");
    }
}

/// A measurement that cannot carry a design is refused with its reason, and nothing is
/// designed: a sweep into the torque limit, a resonance above the measured band, a response
/// too noisy to determine the inertias.
#[test]
fn autotune_refuses_a_measurement_that_cannot_carry_a_design() {
    let out = tmp("autotune-refusals");
    for (args, says) in [
        (&["--amplitude", "1.99"][..], "into its"),
        (&["--set", "plant.shaft_stiffness=20000"][..], "near or above the top of the measured band"),
        (&["--set", "plant.current_noise_std=0.1", "--amplitude", "0.002"][..], "does not determine"),
    ] {
        let _ = std::fs::remove_file(out.join("autotune.toml"));
        let o = servo().arg("autotune").on_fmu(&out).args(args).output().unwrap();
        let e = String::from_utf8_lossy(&o.stderr);
        assert_ne!(o.status.code(), Some(0), "{args:?}");
        assert!(e.contains(says), "{args:?}: {e}");
        assert!(!out.join("autotune.toml").exists(), "{args:?}: a design was written");
    }
}

/// The margins of `tuning` on the true analytic plant: `truth` behind the drive `config`
/// configures.
fn margins_on_truth(
    tuning: &VelocityTuning,
    config: &servo_axis::simulation::SimulationConfig,
    truth: &Mechanics,
) -> host_tools::autotune::margins::Margins {
    let drive = DriveDynamics::on_plant(&config.control, &config.plant);
    let period = config.control.rates.velocity_period() as f64;
    host_tools::autotune::design::margins_of(
        tuning,
        &|f| loop_plant(&drive, truth, f),
        period,
        4000,
        &truth.features_hz(),
    )
    .unwrap()
}
