use super::*;
use crate::variables::{by_name, Value};

fn vr(name: &str) -> u32 {
    by_name(name).unwrap_or_else(|| panic!("no variable {name}")).vr
}

fn set(m: &mut AxisModel, name: &str, v: Value) -> Result<(), String> {
    m.set(vr(name), v)
}

fn initialized() -> AxisModel {
    let mut m = AxisModel::new();
    m.initialize().unwrap();
    m
}

#[test]
fn start_values_build_the_core_and_plant_defaults() {
    // By default the drive commissions at initialisation, as at power-up: it starts from the
    // core's defaults, not commissioned, the encoder's mounting unknown.
    let config = simulation_config(&Values::start()).unwrap();
    let mut plant = crate::plant::PlantParams::default();
    plant.tick = config.plant.tick;
    assert_eq!(config.plant, plant);
    assert_eq!(config.control, control_core::Params::default());
    let c = config.commissioning.expect("commissioning at start");
    assert!(!c.apply_motor);
    // Off, the drive is given the plant's own mounting: the electrical angle at count 0 is
    // pole pairs × the rotor's start angle.
    let mut values = Values::start();
    values.commissioning_at_start = false;
    let config = simulation_config(&values).unwrap();
    let offset = (plant.pole_pairs as f64 * plant.rotor_start_angle).rem_euclid(std::f64::consts::TAU) as f32;
    let mounting = control_core::params::EncoderMounting { reversed: false, electrical_offset: offset };
    assert_eq!(config.control, control_core::Params::default().commissioned_as(mounting));
    assert!(config.commissioning.is_none());
}

#[test]
fn a_drive_given_a_motor_runs_with_it_and_not_with_the_plants() {
    // A commissioned drive's measured set, given to its twin: each value replaces the plant's,
    // the plant itself unchanged.
    let mut values = Values::start();
    values.commissioning_at_start = false;
    values.ctrl_motor_pole_pairs = 5;
    values.ctrl_motor_resistance = 0.31;
    values.ctrl_motor_lq = 0.52e-3;
    values.ctrl_motor_flux_linkage = 0.017;
    let config = simulation_config(&values).unwrap();
    let m = config.control.motor;
    assert_eq!((m.pole_pairs, m.resistance, m.ld, m.lq, m.flux_linkage), (5, 0.31, 0.5e-3, 0.52e-3, 0.017));
    assert_eq!(config.plant.pole_pairs, 4);
    assert_eq!(config.plant.resistance, 0.3);
    // A drive that applies what it measures is given none: both at once is refused by name.
    values.commissioning_at_start = true;
    values.commissioning_apply_motor = true;
    let e = simulation_config(&values).unwrap_err();
    assert!(e.contains("ctrl.motor_") && e.contains("apply_motor"), "{e}");
    // Without apply_motor the given motor is the one it runs with (the measured one reported).
    values.commissioning_apply_motor = false;
    assert_eq!(simulation_config(&values).unwrap().control.motor, m);
    // Over FMI: out of its range, refused when set, the value before kept.
    let mut model = AxisModel::new();
    assert!(set(&mut model, "ctrl.motor_resistance", Value::Float64(-1.0)).is_err());
    assert!(set(&mut model, "ctrl.motor_lq", Value::Float64(f64::NAN)).is_err());
    assert_eq!(model.get(vr("ctrl.motor_resistance")).unwrap(), Value::Float64(0.0));
}

#[test]
fn step_size_must_be_a_whole_number_of_position_periods_and_bounded() {
    let mut m = initialized();
    assert!(m.do_step(0.0, 0.0003).unwrap_err().contains("whole multiple"));
    assert!(m.do_step(0.0, 1e300).unwrap_err().contains("longest step"));
    assert!(m.do_step(0.0, f64::NAN).unwrap_err().contains("positive"));
    m.do_step(0.0, 0.00025).unwrap();
    m.do_step(0.00025, 0.0005).unwrap();
    assert_eq!(m.time(), 0.00075);
}

#[test]
fn the_start_time_is_the_time_of_the_first_communication_point() {
    let mut m = AxisModel::new();
    m.set_start_time(0.1).unwrap();
    m.initialize().unwrap();
    assert!(m.do_step(0.0, 0.00025).unwrap_err().contains("does not match"));
    m.do_step(0.1, 0.00025).unwrap();
    assert_eq!(m.get(0).unwrap(), Value::Float64(0.1 + 4.0 / 16000.0));
}

#[test]
fn fixed_parameters_are_refused_after_initialisation_and_nothing_changes() {
    let mut m = initialized();
    let before = m.values().ctrl_velocity_kp;
    let err = set(&mut m, "ctrl.velocity_kp", Value::Float64(5.0)).unwrap_err();
    assert!(err.contains("ctrl.velocity_kp") && err.contains("fixed"), "{err}");
    assert_eq!(m.values().ctrl_velocity_kp, before);
    set(&mut m, "ctrl.velocity_kp", Value::Float64(before)).expect("the value it already has is accepted");
    m.reset();
    set(&mut m, "ctrl.velocity_kp", Value::Float64(5.0)).unwrap();
    m.reset();
    assert_eq!(m.values(), &Values::start(), "reset restores every start value");
}

#[test]
fn outputs_the_time_wrong_types_nan_and_out_of_range_values_are_refused() {
    let mut m = AxisModel::new();
    assert!(set(&mut m, "iq", Value::Float64(1.0)).unwrap_err().contains("output"));
    assert!(m.set(0, Value::Float64(1.0)).unwrap_err().contains("independent"));
    assert!(set(&mut m, "mode", Value::Float64(1.0)).unwrap_err().contains("Int32"));
    assert!(set(&mut m, "mode", Value::Int32(7)).unwrap_err().contains("outside its range [0, 3]"));
    assert!(set(&mut m, "velocity_command", Value::Float64(f64::NAN)).unwrap_err().contains("not a finite"));
    assert!(set(&mut m, "move_speed", Value::Float64(-1.0)).unwrap_err().contains("move_speed"));
    assert!(set(&mut m, "jog_velocity", Value::Float64(-4e30)).unwrap_err().contains("jog_velocity"));
    assert!(set(&mut m, "plant.substeps", Value::Int32(i32::MAX)).unwrap_err().contains("plant.substeps"));
    assert!(m.set(100_000, Value::Int32(1)).unwrap_err().contains("no variable"));
    assert_eq!(m.values(), &Values::start());
    // All or none.
    let items = [(vr("velocity_command"), Value::Float64(3.0)), (vr("mode"), Value::Int32(9))];
    assert!(m.set_all(items.iter().copied()).is_err());
    assert_eq!(m.values().velocity_command, 0.0);
}

#[test]
fn bad_acc_dec_settings_are_refused_with_the_reason() {
    let build = |changes: &[(&str, Value)]| -> Result<(), String> {
        let mut m = AxisModel::new();
        for (n, v) in changes {
            set(&mut m, n, *v)?;
        }
        m.initialize()
    };
    let bw = ("accdec.filter", Value::Int32(2));
    assert!(build(&[bw, ("accdec.cutoff_hz", Value::Float64(5000.0))]).unwrap_err().contains("Nyquist"));
    assert!(build(&[bw, ("accdec.order", Value::Int32(7))]).unwrap_err().contains("accdec.order"));
    assert!(build(&[bw]).is_ok());
}

#[test]
fn bad_sequence_settings_are_refused_with_the_reason() {
    let build = |changes: &[(&str, Value)]| -> Result<(), String> {
        let mut m = AxisModel::new();
        for (n, v) in changes {
            set(&mut m, n, *v)?;
        }
        m.initialize()
    };
    assert!(build(&[("seq.completion_counts", Value::Int32(-1))]).unwrap_err().contains("seq.completion_counts"));
    assert!(build(&[("seq.gain_count", Value::Int32(9))]).unwrap_err().contains("seq.gain_count"));
    assert!(build(&[("seq.gain_2", Value::Float64(-1.0))]).unwrap_err().contains("seq.gain_2"));
    let limits = [("seq.soft_limit_min", Value::Float64(10.0)), ("seq.soft_limit_max", Value::Float64(-10.0))];
    assert!(build(&limits).unwrap_err().contains("soft limits"));
    assert!(build(&[]).is_ok());
}

#[test]
fn sequence_keys_are_presses_and_refusals_are_counted_not_errors() {
    let mut m = initialized();
    set(&mut m, "mode", Value::Int32(3)).unwrap();
    set(&mut m, "seq_release", Value::Int32(1)).unwrap(); // no accepted stop yet: refused, counted
    m.do_step(0.0, 0.00025).unwrap();
    let v = m.values();
    assert_eq!((v.seq_refused, v.seq_last_refusal, v.seq_state), (1, 5, 0));
    m.do_step(0.00025, 0.00025).unwrap(); // unchanged counter: no second press
    assert_eq!(m.values().seq_refused, 1);
    set(&mut m, "seq_stop", Value::Int32(1)).unwrap(); // at rest: accepted at the next position tick
    m.do_step(0.0005, 0.00025).unwrap();
    assert_eq!(m.values().seq_state, 3);
    set(&mut m, "seq_gain_index", Value::Int32(-1)).unwrap();
    m.do_step(0.00075, 0.00025).unwrap();
    let v = m.values();
    assert_eq!((v.seq_refused, v.seq_last_refusal, v.seq_gain), (2, 8, 1.0));
    assert_eq!(m.refusals.len(), 2, "both refusals wait for the C API to log them");
}

#[test]
fn a_sweep_start_the_mode_cannot_take_is_a_logged_refusal() {
    let mut m = initialized();
    set(&mut m, "mode", Value::Int32(0)).unwrap(); // torque mode: no velocity loop to inject into
    set(&mut m, "sweep_start", Value::Int32(1)).unwrap();
    m.do_step(0.0, 0.00025).unwrap();
    assert_eq!(m.values().sweep_state, 0);
    assert!(m.refusals.iter().any(|r| r.contains("sweep_start refused")), "{:?}", m.refusals);
    set(&mut m, "mode", Value::Int32(1)).unwrap();
    set(&mut m, "sweep_start", Value::Int32(2)).unwrap();
    m.do_step(0.00025, 0.00025).unwrap();
    assert_eq!(m.values().sweep_state, 1, "settling after a start in velocity mode");
}

/// A lowered loop rate (in its documented range) with the default sweep settings: the FMU
/// initialises and runs; a sweep start is refused with the reason (3 kHz above the velocity
/// loop's 2 kHz Nyquist frequency at 8 kHz), nothing else changes, and a sweep that fits the
/// rate starts.
#[test]
fn a_lowered_rate_runs_with_the_default_sweep_settings_and_refuses_only_their_start() {
    let lowered = || {
        let mut m = AxisModel::new();
        set(&mut m, "ctrl.current_loop_hz", Value::Float64(8000.0)).unwrap();
        m
    };
    let mut m = lowered();
    m.initialize().unwrap();
    set(&mut m, "mode", Value::Int32(1)).unwrap();
    set(&mut m, "sweep_start", Value::Int32(1)).unwrap();
    m.do_step(0.0, 0.0005).unwrap();
    assert_eq!(m.values().sweep_state, 0);
    assert!(
        m.refusals.iter().any(|r| r.contains("sweep_start refused") && r.contains("sweep stop_hz = 3000 Hz")),
        "{:?}",
        m.refusals
    );
    let mut m = lowered();
    set(&mut m, "sweep.stop_hz", Value::Float64(1500.0)).unwrap();
    set(&mut m, "sweep.extra_hz", Value::Float64(0.0)).unwrap();
    m.initialize().unwrap();
    set(&mut m, "mode", Value::Int32(1)).unwrap();
    set(&mut m, "sweep_start", Value::Int32(1)).unwrap();
    m.do_step(0.0, 0.0005).unwrap();
    assert_eq!(m.values().sweep_state, 1, "settling: {:?}", m.refusals);
}

#[test]
fn no_output_is_infinite_or_nan_after_initialisation() {
    let m = initialized();
    for d in crate::variables::DECLARATIONS {
        assert!(m.get(d.vr).unwrap().as_f64().is_finite(), "{}", d.name);
    }
}

#[test]
fn a_restored_state_continues_bit_for_bit_like_the_uninterrupted_run() {
    let run = |m: &mut AxisModel, from: usize, n: usize| -> Vec<Values> {
        (from..from + n)
            .map(|k| {
                if k == 40 {
                    set(m, "position_command", Value::Float64(1.0)).unwrap();
                }
                m.do_step(k as f64 * 0.00025, 0.00025).unwrap();
                *m.values()
            })
            .collect()
    };
    let mut m = initialized();
    run(&mut m, 0, 30);
    let saved = m.state.clone();
    let first = run(&mut m, 30, 200);
    m.state = saved;
    let second = run(&mut m, 30, 200);
    assert_eq!(first, second);
    assert!(first.last().unwrap().motor_position > 0.5, "the axis moved");
}

#[test]
fn a_non_finite_output_is_an_error_and_latches_the_fault() {
    let mut m = initialized();
    m.do_step(0.0, 0.00025).unwrap();
    // A plant that has blown up (no accepted parameter set does this: the state is forced).
    m.state.sim.as_mut().unwrap().plant.state.load_velocity = f64::NAN;
    let err = m.do_step(0.00025, 0.00025).unwrap_err();
    assert!(err.contains("is NaN") && err.contains("latched"), "{err}");
    assert_ne!(m.values().faults & control_core::faults::Faults::NOT_FINITE as i32, 0);
    assert!(m.state.sim.as_ref().unwrap().axis.faults().contains(control_core::faults::Faults::NOT_FINITE));
}

/// Every parameter at each end of its declared range (the others at their defaults), and
/// every input at each end of its range during a run: initialisation refuses the setting with
/// a reason, or every step ends with finite outputs (a non-finite one would be an error with
/// the fault latched, never an OK step).
#[test]
fn range_extremes_never_give_a_non_finite_output_with_an_ok_step() {
    use crate::variables::{Causality, Kind, DECLARATIONS};
    let value = |kind: Kind, x: f64| match kind {
        Kind::Float64 => Value::Float64(x),
        Kind::Int32 => Value::Int32(x as i32),
        Kind::Boolean => Value::Boolean(x != 0.0),
    };
    let (mut runs, mut refused, mut stopped_by_error) = (0, 0, 0);
    for d in DECLARATIONS.iter().filter(|d| d.settable() && d.kind != Kind::Boolean) {
        for bound in [d.range.min, d.range.max].into_iter().flatten() {
            let mut m = AxisModel::new();
            set(&mut m, "mode", Value::Int32(2)).unwrap();
            m.set(d.vr, value(d.kind, bound)).unwrap();
            if d.causality == Causality::Parameter && m.initialize().is_err() {
                refused += 1;
                continue;
            }
            if d.causality == Causality::Input {
                m.initialize().unwrap();
            }
            runs += 1;
            let v = m.values();
            let period = v.ctrl_position_divider as f64 / v.ctrl_current_loop_hz;
            let h = period * (0.00025 / period).round().max(1.0);
            for k in 0..200 {
                if k == 20 {
                    let _ = set(&mut m, "position_command", Value::Float64(1.0));
                }
                match m.do_step(m.time(), h) {
                    Ok(()) => {
                        for o in DECLARATIONS.iter().filter(|o| o.causality == Causality::Output) {
                            let x = m.get(o.vr).unwrap().as_f64();
                            assert!(x.is_finite(), "{} = {bound}: {} = {x} after an OK step {k}", d.name, o.name);
                        }
                    }
                    Err(e) => {
                        assert!(e.contains("latched") || e.contains("mode"), "{} = {bound}: {e}", d.name);
                        stopped_by_error += 1;
                        println!("stopped: {} = {bound}: {e}", d.name);
                        break;
                    }
                }
            }
        }
    }
    assert!(runs > 150, "{runs} runs, {refused} refused");
    println!("{runs} runs at range ends, {refused} refused at initialisation, {stopped_by_error} stopped by a latched non-finite fault");
}

/// With `commissioning.at_start`, the FMU commissions its motor at initialisation as a drive at
/// power-up: the plant hides
/// where its rotor stands, the encoder's direction, sensor offsets and gain errors and the
/// inverter's dead time; the outputs report what was measured (within 3 % and 1° of the
/// plant's truth) and the axis then follows a velocity command forward.
#[test]
fn the_axis_commissions_a_hidden_mounting_at_initialisation_and_then_runs() {
    for (start, reversed) in [(0.7, false), (2.9, true), (-1.3, true)] {
        let mut m = AxisModel::new();
        set(&mut m, "commissioning.at_start", Value::Boolean(true)).unwrap();
        set(&mut m, "plant.rotor_start_angle", Value::Float64(start)).unwrap();
        set(&mut m, "plant.encoder_reversed", Value::Boolean(reversed)).unwrap();
        set(&mut m, "plant.current_offset_a", Value::Float64(0.004)).unwrap();
        set(&mut m, "plant.current_gain_b", Value::Float64(0.995)).unwrap();
        set(&mut m, "plant.dead_time_voltage", Value::Float64(0.2)).unwrap();
        set(&mut m, "plant.current_noise_std", Value::Float64(0.002)).unwrap();
        m.initialize().unwrap();
        let o = *m.values();
        let plant = crate::plant::PlantParams::default();
        let close = |got: f64, want: f64, what: &str| {
            assert!((got / want - 1.0).abs() < 0.03, "{what}: {got} vs {want} (start {start}, reversed {reversed})")
        };
        close(o.commissioned_resistance, plant.resistance, "R");
        close(o.commissioned_ld, plant.ld, "Ld");
        close(o.commissioned_lq, plant.lq, "Lq");
        close(o.commissioned_flux_linkage, plant.flux_linkage, "flux linkage");
        assert_eq!(o.commissioned_pole_pairs, plant.pole_pairs as i32);
        assert_eq!(o.commissioned_encoder_reversed, reversed as i32);
        let truth = (plant.pole_pairs as f64 * start).rem_euclid(std::f64::consts::TAU);
        let error = (o.commissioned_encoder_offset - truth + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        assert!(error.abs() < 1f64.to_radians(), "offset {} vs {truth}", o.commissioned_encoder_offset);
        assert!(o.commissioning_time > 0.5 && o.commissioning_time < 5.0, "{} s", o.commissioning_time);
        // Then a velocity command: the motor turns forward at it, no fault.
        set(&mut m, "mode", Value::Int32(1)).unwrap();
        set(&mut m, "velocity_command", Value::Float64(20.0)).unwrap();
        for k in 0..200 {
            m.do_step(k as f64 * 0.001, 0.001).unwrap();
        }
        let o = m.values();
        assert_eq!(o.faults, 0);
        assert!((o.motor_velocity - 20.0).abs() < 1.0, "{} rad/s", o.motor_velocity);
    }
}

/// A machine the drive cannot commission (too little test current to turn it against its
/// friction) is refused at initialisation by the fault's name, and nothing is built.
#[test]
fn a_failed_commissioning_refuses_the_initialisation_by_name() {
    let mut m = AxisModel::new();
    set(&mut m, "commissioning.at_start", Value::Boolean(true)).unwrap();
    set(&mut m, "commissioning.test_current", Value::Float64(0.01)).unwrap();
    let e = m.initialize().unwrap_err();
    assert!(e.contains("commissioning the motor failed") && e.contains("EncoderStill"), "{e}");
    assert!(!m.initialized());
}
