//! Response correction (seed 001, measured form) on the FMU: the corrected axes' command →
//! machine-end responses coincide, each corrected axis answers its own measured response
//! times the other axes' fitted models (the core's filter realises the models), and the XY
//! circle gets rounder by the factor.

use cross_checks::load_fmu;
use host_tools::ident::identification::{absorber_parameters, AxisModel, Factor};
use host_tools::ident::tuning::{circle_check, tune, Method};

const LOAD: f64 = 1.0e-4;

fn axis(name: &str, hz: f64) -> AxisModel {
    AxisModel {
        axis: name.into(),
        anti_resonance: Some(Factor { hz, damping: 0.05 }),
        resonance: None,
        gain: 4000.0,
        band: (1.0, 300.0),
        fit_error: 0.0,
        anti_resonance_error: None,
        fmu_parameters: absorber_parameters(hz, 0.05, LOAD).into_iter().map(|(k, v)| (k, v.as_f64())).collect(),
    }
}

#[test]
fn corrected_axes_coincide_and_the_circle_gets_rounder() {
    let fmu = load_fmu();
    let t = tune(&fmu, &[axis("x", 40.0), axis("y", 70.0)], Method::Response, true, |_| {}).unwrap();
    let (before, after) = (t.spread_before.unwrap(), t.spread_after.unwrap());
    assert!(before.0 > 0.1, "the axes differ before: {before:?}");
    assert!(after.0 < before.0 / 20.0 && after.1 < before.1 / 3.0, "before {before:?}, after {after:?}");

    // Each corrected axis = its measured response × the other axis's fitted model, evaluated
    // from the model's factors (not from the FMU).
    for (i, a) in t.axes.iter().enumerate() {
        let other = t.axes.iter().find(|o| o.axis != a.axis).unwrap().response_model.as_ref().unwrap();
        for (&(f, b), &(_, c)) in t.before[i].iter().zip(&t.after[i]).filter(|(p, _)| p.0 <= 20.0) {
            let r = c / (b * other.at(f));
            assert!(
                (20.0 * r.norm().log10()).abs() < 0.01 && r.arg().to_degrees().abs() < 0.05,
                "axis {} at {f} Hz: {:?}",
                a.axis,
                r
            );
        }
    }

    let c = circle_check(&fmu, &t, 0.05, 20.0, 30).unwrap();
    assert!(c.roundness_without / c.roundness_with >= 20.0, "{c:?}");
}

#[test]
fn the_seed_as_written_is_kept_and_reported_for_what_it_does() {
    // F·Π N_other on axes whose closed-loop denominators differ: measured, not assumed.
    let t = tune(&load_fmu(), &[axis("x", 40.0), axis("y", 70.0)], Method::Zeros, true, |_| {}).unwrap();
    assert!(t.f_pole_hz.is_some());
    assert_eq!(t.axes[0].correction.sections.len(), 2);
    assert!(t.spread_after.unwrap().0 > t.spread_before.unwrap().0, "{:?}", (t.spread_before, t.spread_after));
}

#[test]
fn bad_tuning_requests_are_refused_with_the_reason() {
    let fmu = load_fmu();
    let e = tune(&fmu, &[axis("x", 40.0)], Method::Response, true, |_| {}).unwrap_err().to_string();
    assert!(e.contains("at least two"), "{e}");
    let e = tune(&fmu, &[axis("x", 40.0), axis("x", 70.0)], Method::Response, true, |_| {}).unwrap_err().to_string();
    assert!(e.contains("twice"), "{e}");
    // An axis that cannot follow (current limit far too low) is not measured as if it could.
    let mut weak = axis("y", 70.0);
    weak.fmu_parameters.insert("ctrl.max_current".into(), 0.05);
    let e = tune(&fmu, &[axis("x", 40.0), weak], Method::Response, true, |_| {}).unwrap_err().to_string();
    assert!(e.contains("limit") || e.contains("tripped"), "{e}");
    // Integer parameters come back from model files as numbers: whole ones are taken,
    // others refused with the name.
    let mut odd = axis("y", 70.0);
    odd.fmu_parameters.insert("ctrl.position_divider".into(), 4.5);
    let e = format!("{:#}", tune(&fmu, &[axis("x", 40.0), odd], Method::Response, false, |_| {}).unwrap_err());
    assert!(e.contains("ctrl.position_divider"), "{e}");
    let mut whole = axis("y", 70.0);
    whole.fmu_parameters.insert("ctrl.position_divider".into(), 4.0);
    assert!(tune(&fmu, &[axis("x", 40.0), whole], Method::Response, false, |_| {}).is_ok());
    let e = host_tools::correction::tuned_axes(std::path::Path::new("/nonexistent/tune")).unwrap_err().to_string();
    assert!(e.contains("servo tune"), "{e}");
}

#[test]
fn the_drive_accepts_the_correction_frame_the_fmu_runs() {
    use control_core::protocol::{decode, handle, Request, Response};
    let t = tune(&load_fmu(), &[axis("x", 40.0), axis("y", 70.0)], Method::Response, false, |_| {}).unwrap();
    let dir = std::env::temp_dir().join(format!("servo-tune-frame-{}", std::process::id()));
    let files = host_tools::ident::tuning::write(&t, &dir).unwrap();
    for a in &t.axes {
        let path = dir.join(format!("{}.corr.frame", a.axis));
        assert!(files.contains(&path));
        let mut frame = std::fs::read(&path).unwrap();
        let request: Request = decode(&mut frame).unwrap();
        let Request::LoadCorrection(p) = request else { panic!("{request:?}") };
        // The same sections as the FMU parameters in <axis>.corr.toml, at f32.
        assert_eq!(p.count, a.correction.sections.len());
        for (s, q) in p.sections.iter().zip(&a.correction.sections) {
            assert_eq!(s.poles.hz, q.pole_hz as f32);
            assert_eq!(s.poles.damping, q.pole_damping as f32);
            assert_eq!(s.zeros.map(|z| (z.hz, z.damping)), q.zeros.map(|(h, d)| (h as f32, d as f32)));
        }
        let params = control_core::Params::default();
        let mut drive = control_core::Axis::new(params).unwrap();
        let mut commands = control_core::Commands::default();
        let mut stream = control_core::acquisition_stream::AcquisitionStream::default();
        assert_eq!(handle(&mut drive, &mut commands, &mut stream, Request::LoadCorrection(p)), Response::Done);
        // A corrupted frame is refused before anything is acted on.
        let mut bad = std::fs::read(&path).unwrap();
        bad[3] ^= 0x40;
        assert!(decode::<Request>(&mut bad).is_err());
    }
}
