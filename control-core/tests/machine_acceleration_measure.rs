//! The sweep's machine-end acceleration measure (seed 001 over a drive): each acquisition
//! sample's U is the mean of kt·iq (the q current the current loop measured on each of four
//! ticks, as its telemetry records it) and Y the mean of the accelerometer inputs of the same
//! ticks (the four before the acquisition tick: the axis takes both one tick late, from the
//! same sampling instant); the measure is refused where it makes no sense.

use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::{SweepError, SweepMeasure, SweepSignal};
use control_core::{Axis, AxisInputs, Commands, Mode, ParamError, Params};

fn identification_params() -> Params {
    let mut p = Params::default();
    p.sweep.point = InjectionPoint::TorqueCommand;
    p.sweep.signal = SweepSignal::Prbs;
    p.sweep.measure = SweepMeasure::MachineAcceleration;
    p.sweep.amplitude = 0.05;
    p.sweep.prbs_degree = 11;
    p.sweep.prbs_divider = 16;
    p.sweep.acquisition_divider = 4;
    p.sweep.prbs_seconds = 0.05;
    p.sweep.min_settle_s = 0.0;
    p
}

/// Inputs that change every tick: phase currents with a q component, an encoder turning, a
/// machine-end acceleration unrelated to either.
fn inputs(k: u32) -> AxisInputs {
    let x = k as f32;
    AxisInputs {
        phase_currents: [0.3 * libm::sinf(0.37 * x), 0.2 * libm::cosf(0.11 * x) - 0.1],
        encoder_count: (k * 37) as i32,
        bus_voltage: 48.0,
        load_acceleration: 50.0 * libm::sinf(0.05 * x) + 3.0 * (k % 3) as f32,
    }
}

#[test]
fn u_is_the_mean_of_kt_iq_and_y_the_mean_acceleration_over_each_acquisition_period() {
    let params = identification_params();
    let kt = params.motor.torque_constant();
    let mut axis = Axis::new(params).unwrap();
    let commands = Commands { mode: Mode::Torque, ..Commands::default() };
    axis.step(&inputs(0), &commands);
    axis.start_sweep().unwrap();
    // Per tick: kt·iq as the telemetry records the measured current, and the acceleration given.
    let mut ticks: Vec<(f64, f64)> = Vec::new();
    let mut compared = 0;
    let d = params.sweep.acquisition_divider as usize;
    for k in 1..400 {
        let i = inputs(k);
        axis.step(&i, &commands);
        let t = axis.telemetry();
        ticks.push(((kt * t.current.q) as f64, i.load_acceleration as f64));
        // The first samples after the start hold fewer ticks.
        if t.tick.is_multiple_of(d as u64) && axis.sweep().running() && ticks.len() > d + 1 {
            let s = t.sweep.sample;
            assert_eq!(s.tick, t.tick);
            let period = &ticks[ticks.len() - 1 - d..ticks.len() - 1];
            let u = period.iter().map(|p| p.0).sum::<f64>() / d as f64;
            let y = period.iter().map(|p| p.1).sum::<f64>() / d as f64;
            assert!((s.u as f64 - u).abs() <= 1e-5 * u.abs().max(1e-3), "tick {}: u {} vs kt·iq mean {u}", t.tick, s.u);
            assert!((s.y as f64 - y).abs() <= 1e-5 * y.abs().max(1.0), "tick {}: y {} vs mean {y}", t.tick, s.y);
            compared += 1;
        }
    }
    assert!(compared > 50, "{compared} samples compared");
}

#[test]
fn the_loop_measure_ignores_the_accelerometer() {
    // The default measure: the sweep's samples do not change with the acceleration input.
    let mut params = identification_params();
    params.sweep.measure = SweepMeasure::Loop;
    let run = |scale: f32| {
        let mut axis = Axis::new(params).unwrap();
        let commands = Commands { mode: Mode::Torque, ..Commands::default() };
        axis.start_sweep().unwrap();
        let mut samples = Vec::new();
        for k in 0..200 {
            let mut i = inputs(k);
            i.load_acceleration *= scale;
            axis.step(&i, &commands);
            samples.push(axis.telemetry().sweep.sample);
        }
        samples
    };
    assert_eq!(run(1.0), run(-7.0));
}

#[test]
fn the_acceleration_measure_is_refused_with_another_injection_point() {
    for point in [InjectionPoint::VelocityCommand, InjectionPoint::VelocityFeedback] {
        let mut p = identification_params();
        p.sweep.point = point;
        match Axis::new(p) {
            Err(ParamError::Sweep(SweepError::MeasureNeedsTorqueOrPositionInjection)) => {}
            other => panic!("{point:?}: {:?}", other.map(|_| ())),
        }
    }
    // Refusal names the field group and says why.
    let e = ParamError::Sweep(SweepError::MeasureNeedsTorqueOrPositionInjection);
    assert_eq!(e.field(), "sweep");
}

#[test]
fn the_accelerometer_sensitivity_is_validated() {
    for bad in [0.0, -1.0e-3, f32::NAN, f32::INFINITY, 100.0] {
        let mut p = Params::default();
        p.accelerometer.sensitivity = bad;
        let e = Axis::new(p).err().map(|e| e.field());
        assert_eq!(e, Some("accelerometer.sensitivity"), "{bad}");
    }
}

/// With position-command injection (`servo tune --device`'s machine-end check) U is the mean
/// of the injected position (rad) and Y the mean of the accelerometer inputs of the same ticks,
/// this tick's included: the acceleration is read with the encoder count, as the position
/// measure reads the position (no tick of delay, unlike the torque measure's).
#[test]
fn with_position_injection_u_is_the_mean_injection_and_y_the_mean_acceleration_of_the_same_ticks() {
    let mut params = Params::default();
    params.sweep.point = InjectionPoint::PositionCommand;
    params.sweep.measure = SweepMeasure::MachineAcceleration;
    params.sweep.amplitude = 0.01;
    params.sweep.start_hz = 20.0;
    params.sweep.stop_hz = 30.0;
    params.sweep.points = 2;
    params.sweep.extra_hz = 0.0;
    params.sweep.acquisition_divider = 4;
    params.sweep.min_settle_s = 0.0;
    let rad_per_count = core::f32::consts::TAU / params.encoder_counts_per_rev as f32;
    let mut axis = Axis::new(params).unwrap();
    let hold = 1000;
    let commands = Commands { mode: Mode::Position, position: hold, ..Commands::default() };
    let rest = AxisInputs { encoder_count: hold as i32, ..inputs(0) };
    axis.step(&rest, &commands);
    axis.start_sweep().unwrap();
    let mut ticks: Vec<(f64, f64)> = Vec::new();
    let (mut compared, mut moving) = (0, 0);
    let d = params.sweep.acquisition_divider as usize;
    for k in 1..4000 {
        let i = AxisInputs { encoder_count: hold as i32, ..inputs(k) };
        axis.step(&i, &commands);
        let t = axis.telemetry();
        // The command path (no acc/dec, no correction) passes the injected position through.
        ticks.push(((t.position_command - hold) as f64 * rad_per_count as f64, i.load_acceleration as f64));
        if t.tick.is_multiple_of(d as u64) && axis.sweep().running() && ticks.len() > d {
            let s = t.sweep.sample;
            let period = &ticks[ticks.len() - d..];
            let u = period.iter().map(|p| p.0).sum::<f64>() / d as f64;
            let y = period.iter().map(|p| p.1).sum::<f64>() / d as f64;
            assert!((s.u as f64 - u).abs() <= 1e-5 * u.abs().max(1e-3), "tick {}: u {} vs mean {u}", t.tick, s.u);
            assert!((s.y as f64 - y).abs() <= 1e-5 * y.abs().max(1.0), "tick {}: y {} vs mean {y}", t.tick, s.y);
            compared += 1;
            moving += (u.abs() > 1e-3) as usize;
        }
    }
    assert!(compared > 500 && moving > 100, "{compared} samples compared, {moving} with the injection away from 0");
}
