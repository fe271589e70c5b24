//! Sweep settings that only a sweep uses are held against the loop rates and limits when the
//! sweep starts: an axis whose rate was lowered runs with the default sweep settings, and a
//! start of a sweep it cannot run is refused with the reason, changing nothing. A drive (its
//! rate is its board's) refuses such parameters when they are given, by name.

use control_core::acquisition_stream::AcquisitionStream;
use control_core::phase_shifted_sweep::{SweepError, SweepState};
use control_core::protocol::{handle, FieldName, RefusalReason, Request, Response};
use control_core::{Axis, AxisInputs, Commands, Mode, Params};

fn lowered_rate() -> Params {
    let mut p = Params::default();
    p.rates.current_loop_hz = 8000.0;
    p
}

fn inputs(k: u32) -> AxisInputs {
    AxisInputs { phase_currents: [0.0, 0.0], encoder_count: (k * 3) as i32, bus_voltage: 48.0, load_acceleration: 0.0 }
}

#[test]
fn a_lowered_rate_runs_and_refuses_only_the_start_of_a_sweep_it_cannot_run() {
    // Default sweep settings: 3 kHz, above the velocity loop's 2 kHz Nyquist frequency at 8 kHz.
    let mut asked = Axis::new(lowered_rate()).expect("the axis builds at a lowered rate");
    let mut never_asked = Axis::new(lowered_rate()).unwrap();
    let commands = Commands { mode: Mode::Velocity, velocity: 5.0, ..Commands::default() };
    for k in 0..100 {
        asked.step(&inputs(k), &commands);
        never_asked.step(&inputs(k), &commands);
    }
    let before = *asked.sweep().status();
    let e = asked.start_sweep().unwrap_err();
    assert_eq!(
        e,
        SweepError::AboveLoopNyquist {
            field: "stop_hz",
            frequency: 3000.0,
            nyquist: 2000.0,
            rate: "current_loop_hz / velocity_divider"
        }
    );
    assert!(e.to_string().contains("sweep stop_hz = 3000 Hz"), "{e}");
    // Nothing changed: no sweep, the same status, and the axis runs on as one never asked.
    assert!(!asked.sweep().running());
    assert_eq!(*asked.sweep().status(), before);
    assert_eq!(before.state, SweepState::Idle);
    for k in 100..400 {
        let a = asked.step(&inputs(k), &commands);
        let b = never_asked.step(&inputs(k), &commands);
        assert_eq!(a, b, "tick {k}");
    }
    assert_eq!(asked.telemetry(), never_asked.telemetry());

    // The sweep settings that fit the lowered rate start.
    let mut p = lowered_rate();
    (p.sweep.stop_hz, p.sweep.extra_hz) = (1500.0, 0.0);
    let mut axis = Axis::new(p).unwrap();
    axis.step(&inputs(0), &commands);
    assert_eq!(axis.start_sweep(), Ok(()));
    assert!(axis.sweep().running());
}

#[test]
fn a_drive_refuses_parameters_whose_sweep_cannot_run_at_its_rate_by_name() {
    let mut axis = Axis::new(Params::default()).unwrap();
    let mut commands = Commands::default();
    let mut stream = AcquisitionStream::default();
    assert_eq!(
        handle(&mut axis, &mut commands, &mut stream, Request::SetParams(lowered_rate())),
        Response::Refused(RefusalReason::InvalidParams(FieldName::new("stop_hz")))
    );
    assert_eq!(*axis.params(), Params::default());
    let mut p = lowered_rate();
    (p.sweep.stop_hz, p.sweep.extra_hz) = (1500.0, 0.0);
    assert_eq!(handle(&mut axis, &mut commands, &mut stream, Request::SetParams(p)), Response::Done);
}
