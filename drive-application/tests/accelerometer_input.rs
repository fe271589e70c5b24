//! The machine-end accelerometer's input through the drive: its zero taken with the current
//! offsets at start-up (the resting stage reads mid-scale, 2048), its scale from the
//! sensitivity in force — a `SetParams` changes it, a refused one leaves it.

mod common;

use common::{RamFlash, RestingStage};
use control_core::current_sensing::CALIBRATION_SAMPLES;
use control_core::params::Params;
use control_core::protocol::{FieldName, RefusalReason, Request, Response};
use drive_application::Drive;
use power_stage::ratings::ACCELEROMETER_VOLTS_PER_COUNT;

#[test]
fn the_zero_is_taken_at_start_and_the_sensitivity_follows_set_params() {
    let mut flash = RamFlash::new();
    let drive = Box::leak(Box::new(Drive::new()));
    let mut host = drive.install::<RestingStage, _>(Params::default(), &mut flash).unwrap();
    let mut stage = RestingStage::default();
    assert_eq!(drive.accelerometer_zero(), None, "not calibrated before the first tick");
    for _ in 0..=CALIBRATION_SAMPLES {
        drive.tick(&mut stage);
    }
    assert_eq!(drive.accelerometer_zero(), Some(Some(2048.0)));
    // 100 counts above the zero, in rad/s², at a sensitivity (V per rad/s²).
    let expected = |sensitivity: f32| 100.0 * ACCELEROMETER_VOLTS_PER_COUNT / sensitivity;
    let read = |drive: &Drive| drive.with(|s, _| s.accelerometer.convert(2148)).unwrap();
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * b.abs();
    let default = Params::default().accelerometer.sensitivity;
    assert!(close(read(drive), expected(default)), "{} vs {}", read(drive), expected(default));
    let mut p = Params::default();
    p.accelerometer.sensitivity = 4.0e-3;
    assert_eq!(host.handle(Request::SetParams(p), &mut flash), Response::Done);
    assert!(close(read(drive), expected(4.0e-3)), "{} vs {}", read(drive), expected(4.0e-3));
    // A sensitivity the parameters refuse changes nothing.
    p.accelerometer.sensitivity = 0.0;
    assert_eq!(
        host.handle(Request::SetParams(p), &mut flash),
        Response::Refused(RefusalReason::InvalidParams(FieldName::new("accelerometer.sensitivity")))
    );
    assert!(close(read(drive), expected(4.0e-3)));
    assert_eq!(drive.accelerometer_zero(), Some(Some(2048.0)), "the zero is kept across parameter changes");
}
