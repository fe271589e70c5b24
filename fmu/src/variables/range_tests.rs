//! Every declared min and max is what the FMU accepts and refuses: a value just outside is
//! refused with the variable's name, the bound itself is accepted — by the range check and by
//! the whole validation, except where a rule between two values decides (listed below, each
//! with the rule the refusal must name). Rules that only a sweep needs (its frequencies
//! against the loop rates, its injection against the limits) decide when the sweep starts,
//! not at initialisation: an axis that never sweeps runs (listed apart, with the reason the
//! start must give).

use crate::co_simulation::AxisModel;
use crate::variables::{Causality, Kind, Value, DECLARATIONS};

/// Bounds that the core's or the plant's rules between values refuse with the other values
/// at their defaults: (variable, which bound, a word the refusal must contain).
const COUPLED: &[(&str, &str, &str)] = &[
    // The slowest loop rate: the plant's explicit friction term against its sub-step (the
    // default sweep's frequencies are held against the rate only when a sweep starts).
    ("ctrl.current_loop_hz", "min", "too fast for a sub-step"),
    // Frequencies below the Nyquist frequency of the loop that uses them.
    ("ctrl.position_divider", "max", "Nyquist"),
    ("ctrl.low_pass_hz", "max", "Nyquist"),
    ("ctrl.notch_hz", "max", "Nyquist"),
    ("ctrl.notch2_hz", "max", "Nyquist"),
    ("accdec.cutoff_hz", "max", "Nyquist"),
    ("excitation.frequency", "max", "half the loop rate"),
    // The machine-end acceleration measure needs torque- or position-command injection (the
    // default point is the velocity command).
    ("sweep.measure", "max", "needs torque-command (sweep.point 1) or position-command"),
    // Loop rates that divide each other.
    ("ctrl.velocity_divider", "max", "whole multiple"),
    ("ctrl.position_divider", "min", "whole multiple"),
    ("sweep.acquisition_divider", "min", "multiple of the velocity loop"),
    // Ordered pairs.
    ("ctrl.bus_undervoltage", "max", "below bus_overvoltage"),
    ("ctrl.bus_overvoltage", "min", "below bus_overvoltage"),
    ("seq.soft_limit_min", "max", "min must be below max"),
    ("seq.soft_limit_max", "min", "min must be below max"),
    ("sweep.start_hz", "max", "must exceed start_hz"),
    ("sweep.stop_hz", "min", "must exceed start_hz"),
    ("plant.absorber_inertia", "max", "absorber_stiffness must be > 0"),
    // The plant's explicit terms against its sub-step (plant.substeps raises the limit).
    ("plant.pole_pairs", "max", "too fast for a sub-step"),
    ("plant.lq", "min", "too fast for a sub-step"),
    ("plant.flux_linkage", "max", "too fast for a sub-step"),
    ("plant.motor_inertia", "min", "too fast for a sub-step"),
    ("plant.load_inertia", "min", "too fast for a sub-step"),
    ("plant.motor_coulomb", "max", "too fast for a sub-step"),
    ("plant.load_coulomb", "max", "too fast for a sub-step"),
    ("plant.coulomb_velocity", "min", "too fast for a sub-step"),
    // Commissioning the default machine: too little current to turn it against its friction,
    // too little voltage to drive any current, a bandwidth over a tenth of the loop rate (the
    // largest test current is lowered to the drive's own limits: accepted).
    ("commissioning.test_current", "min", "EncoderStill"),
    ("commissioning.max_voltage", "min", "OpenPhase"),
    ("commissioning.current_bandwidth", "max", "current_bandwidth_hz"),
];

/// Bounds that initialise but whose sweep cannot run with the other values at their
/// defaults: the start is refused with the reason (`Params::validate_sweep`, what
/// `Axis::start_sweep` checks first).
const SWEEP_START_COUPLED: &[(&str, &str, &str)] = &[
    // Frequencies below the Nyquist frequency of the loop the sine is injected into.
    ("sweep.stop_hz", "max", "Nyquist"),
    ("sweep.extra_hz", "max", "Nyquist"),
    // The position-command point (the largest code) sweeps below the position loop's Nyquist
    // frequency, 2 kHz at the defaults, under the default stop frequency of 3 kHz.
    ("sweep.point", "max", "Nyquist"),
    // The torque-command point (the smallest code) with the default amplitude, 2 (rad/s for the
    // velocity points): a 2 N·m sine reaches the current limit, refused by the amplitude.
    ("sweep.point", "min", "amplitude"),
    // The sweep's dither within the lower of the torque limit and the current limit's torque
    // kt·max_current (it is added after the loop's clamp; `control_core::torque_ceiling`): the
    // smallest current limit, and the smallest flux linkage (kt = 1.5·pole pairs·flux),
    // leave about 10⁻⁴ N·m of room for the default 0.003.
    ("sweep.dither", "max", "sweep dither"),
    ("ctrl.torque_limit", "min", "sweep dither"),
    ("ctrl.max_current", "min", "sweep dither"),
    ("plant.flux_linkage", "min", "sweep dither"),
    // Records too short for a sine fit: no shortest measurement (two cycles at 1.1 kHz and up
    // are fewer than 8 samples), or one acquisition sample per 62.5 s.
    ("sweep.min_measure_s", "min", "acquisition samples"),
    ("sweep.acquisition_divider", "max", "acquisition samples"),
];

fn value(kind: Kind, x: f64) -> Value {
    match kind {
        Kind::Float64 => Value::Float64(x),
        Kind::Int32 => Value::Int32(x as i32),
        Kind::Boolean => Value::Boolean(x != 0.0),
    }
}

#[test]
fn declared_ranges_are_what_validation_accepts_and_refuses() {
    let mut problems = Vec::new();
    let mut coupled_seen = Vec::new();
    for d in DECLARATIONS.iter().filter(|d| d.settable() && d.kind != Kind::Boolean) {
        for (side, bound, outside) in [
            ("min", d.range.min, d.range.min.map(|m| if d.kind == Kind::Int32 { m - 1.0 } else { m.next_down() })),
            ("max", d.range.max, d.range.max.map(|m| if d.kind == Kind::Int32 { m + 1.0 } else { m.next_up() })),
        ] {
            let (Some(bound), Some(outside)) = (bound, outside) else { continue };
            let representable = d.kind == Kind::Float64 || (i32::MIN as f64..=i32::MAX as f64).contains(&outside);
            if representable {
                let mut m = AxisModel::new();
                match m.set(d.vr, value(d.kind, outside)) {
                    Ok(()) => problems.push(format!("{} = {outside} (outside its {side}) was accepted", d.name)),
                    Err(e) if !e.contains(d.name) => {
                        problems.push(format!("{}: refusal does not name it: {e}", d.name))
                    }
                    Err(_) => {}
                }
            }
            let mut m = AxisModel::new();
            // The plant's and the loops' ranges are the model's: whether a drive can commission
            // a machine at their extremes is the commissioning's business (its own parameters
            // are held here with it on, and its refusals in `control_core::commissioning`'s
            // tests). So the others run with the given set, its own with it on.
            let at_start = DECLARATIONS.iter().find(|v| v.name == "commissioning.at_start").unwrap();
            m.set(at_start.vr, Value::Boolean(d.name.starts_with("commissioning."))).unwrap();
            if let Err(e) = m.set(d.vr, value(d.kind, bound)) {
                problems.push(format!("{} = {bound} (its {side}) refused by the range check: {e}", d.name));
                continue;
            }
            if d.causality != Causality::Parameter {
                continue;
            }
            let result = m.initialize();
            let coupled = COUPLED.iter().find(|(n, s, _)| *n == d.name && *s == side);
            let sweep_start = m.state.sim.as_ref().map(|sim| sim.axis.params().validate_sweep());
            let sweep_coupled = SWEEP_START_COUPLED.iter().find(|(n, s, _)| *n == d.name && *s == side);
            match (sweep_start, sweep_coupled) {
                (Some(Ok(())), Some(_)) => {
                    problems.push(format!("{} {side}: listed as refused at the sweep start but accepted", d.name))
                }
                (Some(Err(e)), Some((_, _, word))) if e.to_string().contains(word) => {
                    coupled_seen.push(format!("{} {side}: sweep start: {e}", d.name))
                }
                (Some(Err(e)), _) => {
                    problems.push(format!("{} = {bound} (its {side}): sweep start refused: {e}", d.name))
                }
                (None, Some(_)) => {
                    problems.push(format!("{} {side}: listed for the sweep start, not initialised", d.name))
                }
                _ => {}
            }
            match (result, coupled) {
                (Ok(()), None) => {}
                (Ok(()), Some(_)) => problems.push(format!("{} {side}: listed as coupled but accepted", d.name)),
                (Err(e), Some((_, _, word))) if e.contains(word) => {
                    coupled_seen.push(format!("{} {side}: {e}", d.name))
                }
                (Err(e), _) => problems.push(format!("{} = {bound} (its {side}) refused by validation: {e}", d.name)),
            }
        }
    }
    for c in &coupled_seen {
        println!("coupled: {c}");
    }
    assert!(problems.is_empty(), "{} problem(s):\n{}", problems.len(), problems.join("\n"));
}
