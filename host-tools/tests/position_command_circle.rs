//! The position-command injection point (issue 16 item 5, seed 002): the pseudo-circle the
//! core's own sweep draws on the FMU equals the one the host draws by streaming the sine, and
//! its radius is the closed loop's gain the core's correlator measures.

use std::collections::BTreeMap;
use std::f64::consts::TAU;

use host_tools::circle::device::{pseudo_circle_of_samples, pseudo_circle_sweep};
use host_tools::fmu::circle::{radial_differences, single_axis, CircleRequest, Direction, Measure};
use host_tools::fmu::runner::Fmu;
use host_tools::fmu::scenario::Value;
use host_tools::paths::default_fmu;

#[test]
fn the_drive_generated_sine_draws_the_streamed_pseudo_circle() {
    let fmu = Fmu::load(&default_fmu()).unwrap();
    // A friction-free axis (no protrusions), 20 Hz on 0.05 rad: the closed loop's gain there
    // is well away from 1, so the radius tells the loop's response, not the command.
    let parameters: BTreeMap<String, Value> =
        ["plant.motor_coulomb", "plant.load_coulomb"].iter().map(|k| (k.to_string(), Value::Float(0.0))).collect();
    let radius = 0.05;
    let r = CircleRequest {
        radius,
        feed: TAU * radius * 20.0,
        direction: Direction::CounterClockwise,
        lead_in: 10,
        measure: Measure::Motor,
        x_parameters: parameters.clone(),
        y_parameters: parameters,
    };
    let run = pseudo_circle_sweep(&r).unwrap();
    let trace = run.run(&fmu, |_| {}).unwrap();
    let generated = pseudo_circle_of_samples(&trace, &r).unwrap();
    let count = TAU / run.drive_params().unwrap().encoder_counts_per_rev as f64;

    // The command: R·sin in whole counts, once per position tick; a sample is the mean over
    // the period's two velocity ticks, which straddle two position ticks: the mean of
    // R·sin θ and R·sin(θ − ωT) is R·cos(ωT/2)·sin(θ − ωT/2). So a circle of radius
    // R·cos(ωT/2) within the counts' rounding.
    let omega = r.feed / radius;
    let position_period = run.rates().unwrap().position_period() as f64;
    let expected = radius * (0.5 * omega * position_period).cos();
    let command = generated.command.roundness(expected);
    assert!(command.roundness <= 2.0 * count, "command roundness {:e} rad", command.roundness);
    assert!(
        command.mean_radius_error.abs() <= 0.5 * count,
        "command radius off R·cos(ωT/2) by {:e} rad",
        command.mean_radius_error
    );

    // The feedback: the figure the host draws by streaming the same sine (an independent
    // path: the FMU's position_command input every step), point for point within a few counts
    // (the two sample the position at slightly different instants of the period).
    let streamed = single_axis(&fmu, &r).unwrap();
    let (largest, rms) = radial_differences(&generated.feedback, &streamed.feedback);
    assert!(largest <= 4.0 * count && rms <= 2.0 * count, "generated vs streamed: {largest:e}, rms {rms:e} rad");
    let mean = generated.feedback.roundness(radius).mean_radius_error;
    assert!(mean.abs() > 100.0 * count, "the radius ({mean:e} rad off) should show the loop's gain at 20 Hz");

    // Its radius over the command's is |G(j2π·20 Hz)|, G the closed position loop the core's
    // correlator measured on the same run (on-line, from u and y: the same period means).
    let gain_db = trace.column("sweep_last_gain_db").unwrap();
    let gain = 10f64.powf(gain_db[gain_db.len() - 1] / 20.0);
    let ratio = (radius + mean) / (expected + command.mean_radius_error);
    eprintln!(
        "generated vs streamed: largest {:.2} counts, rms {:.2}; radius ratio {ratio:.6} vs gain {gain:.6}",
        largest / count,
        rms / count
    );
    assert!((ratio / gain - 1.0).abs() < 1e-4, "radius ratio {ratio}, correlator's gain {gain}");
}

#[test]
fn the_position_command_point_is_refused_outside_position_mode() {
    use control_core::excitation::InjectionPoint;
    use control_core::phase_shifted_sweep::SweepError;
    use control_core::{Axis, Commands, Mode, Params};
    let mut p = Params::default();
    p.sweep.point = InjectionPoint::PositionCommand;
    // Below the position loop's Nyquist frequency (2 kHz at the defaults).
    (p.sweep.stop_hz, p.sweep.extra_hz) = (100.0, 0.0);
    let mut axis = Axis::new(p).unwrap();
    let inputs = control_core::AxisInputs { bus_voltage: 24.0, ..Default::default() };
    for mode in [Mode::Torque, Mode::Velocity] {
        axis.step(&inputs, &Commands { mode, ..Commands::default() });
        assert_eq!(axis.start_sweep(), Err(SweepError::NeedsPositionMode), "{mode:?}");
        assert!(!axis.sweep().running());
    }
    axis.step(&inputs, &Commands { mode: Mode::Position, ..Commands::default() });
    assert_eq!(axis.start_sweep(), Ok(()));
    assert!(axis.sweep().running());
}

#[test]
fn a_position_command_sweep_starts_its_sine_on_a_position_tick() {
    // Whichever tick the start request falls before, the sine's first tick is a position
    // tick (the drive's figure then samples the sine as its FMU twin does).
    use control_core::excitation::InjectionPoint;
    use control_core::{Axis, Commands, Mode, Params};
    let mut p = Params::default();
    p.sweep.point = InjectionPoint::PositionCommand;
    // Below the position loop's Nyquist frequency (2 kHz at the defaults).
    (p.sweep.stop_hz, p.sweep.extra_hz) = (100.0, 0.0);
    p.sweep.amplitude = 0.01;
    let divider = p.rates.position_divider as u64;
    let inputs = control_core::AxisInputs { bus_voltage: 24.0, ..Default::default() };
    let hold = Commands { mode: Mode::Position, ..Commands::default() };
    for before in 1..=2 * divider {
        let mut axis = Axis::new(p).unwrap();
        for _ in 0..before {
            axis.step(&inputs, &hold);
        }
        axis.start_sweep().unwrap();
        // The tick the sweep's first frequency begins on: the next one once its point is 0.
        let mut first = axis.telemetry().tick + 1;
        while axis.sweep().status().point != 0 {
            axis.step(&inputs, &hold);
            first = axis.telemetry().tick + 1;
            assert!(first < before + 2 * divider, "no start after {before} ticks");
        }
        assert!(axis.sweep().running());
        assert_eq!(first % divider, 0, "started {before} ticks in: the sine begins on tick {first}");
    }
}
