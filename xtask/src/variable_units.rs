//! Units, min and max of every FMU variable, written into modelDescription.xml.
//!
//! Every Float64 and Int32 variable of the model must appear here: the bundler fails on a
//! variable without an entry, so a new variable cannot ship without its unit and range.

use anyhow::{bail, Result};

/// (unit name, SI base-unit exponents as XML attributes, declared type carrying the unit)
///
/// Variables reference their unit through a `Float64Type` (`declaredType`), the form both
/// fmpy and the Rust importer (fmi-schema 0.8, which has no `unit` attribute on variables) read.
const UNITS: &[(&str, &str, &str)] = &[
    ("rad", r#"rad="1""#, "Angle"),
    ("rad/s", r#"s="-1" rad="1""#, "AngularVelocity"),
    ("rad/s2", r#"s="-2" rad="1""#, "AngularAcceleration"),
    ("N.m", r#"kg="1" m="2" s="-2""#, "Torque"),
    ("A", r#"A="1""#, "Current"),
    ("V", r#"kg="1" m="2" s="-3" A="-1""#, "Voltage"),
    ("Ohm", r#"kg="1" m="2" s="-3" A="-2""#, "Resistance"),
    ("V/(A.s)", r#"kg="1" m="2" s="-4" A="-2""#, "CurrentIntegralGain"),
    ("H", r#"kg="1" m="2" s="-2" A="-2""#, "Inductance"),
    ("Wb", r#"kg="1" m="2" s="-2" A="-1""#, "MagneticFlux"),
    ("kg.m2", r#"kg="1" m="2""#, "Inertia"),
    ("N.m/rad", r#"kg="1" m="2" s="-2" rad="-1""#, "RotationalStiffness"),
    ("N.m.s/rad", r#"kg="1" m="2" s="-1" rad="-1""#, "RotationalDamping"),
    ("Hz", r#"s="-1""#, "Frequency"),
    ("1/s", r#"s="-1""#, "Rate"),
    ("s", r#"s="1""#, "Time"),
];

/// (variable, unit or "" for none, min, max); None = unbounded.
type Row = (&'static str, &'static str, Option<f64>, Option<f64>);

const POS: Option<f64> = Some(0.0);

const VARIABLES: &[Row] = &[
    ("time", "s", None, None),
    ("ctrl.current_loop_hz", "Hz", Some(1000.0), Some(200_000.0)),
    ("ctrl.velocity_divider", "", Some(1.0), Some(1000.0)),
    ("ctrl.position_divider", "", Some(1.0), Some(1000.0)),
    ("ctrl.current_kp", "Ohm", POS, None),
    ("ctrl.current_ki", "V/(A.s)", POS, None),
    ("ctrl.angle_advance_ticks", "", POS, Some(4.0)),
    ("ctrl.max_current", "A", POS, None),
    ("ctrl.velocity_kp", "N.m.s/rad", POS, None),
    ("ctrl.velocity_ki", "N.m/rad", POS, None),
    ("ctrl.torque_limit", "N.m", POS, None),
    ("ctrl.position_kp", "1/s", POS, None),
    ("ctrl.velocity_feedforward", "", POS, Some(1.0)),
    ("ctrl.velocity_limit", "rad/s", POS, None),
    ("ctrl.low_pass_hz", "Hz", POS, None),
    ("ctrl.notch_hz", "Hz", POS, None),
    ("ctrl.notch_q", "", POS, None),
    ("ctrl.notch_depth", "", POS, Some(1.0)),
    ("ctrl.overcurrent", "A", POS, None),
    ("ctrl.bus_undervoltage", "V", POS, None),
    ("ctrl.bus_overvoltage", "V", POS, None),
    ("ctrl.following_error_limit", "rad", POS, None),
    ("ctrl.friction_comp_amplitude", "N.m", POS, None),
    ("ctrl.friction_comp_decay", "s", POS, None),
    ("plant.pole_pairs", "", Some(1.0), Some(64.0)),
    ("plant.resistance", "Ohm", POS, None),
    ("plant.ld", "H", POS, None),
    ("plant.lq", "H", POS, None),
    ("plant.flux_linkage", "Wb", POS, None),
    ("plant.bus_voltage", "V", POS, None),
    ("plant.motor_inertia", "kg.m2", POS, None),
    ("plant.load_inertia", "kg.m2", POS, None),
    ("plant.shaft_stiffness", "N.m/rad", POS, None),
    ("plant.shaft_damping", "N.m.s/rad", POS, None),
    ("plant.motor_coulomb", "N.m", POS, None),
    ("plant.motor_viscous", "N.m.s/rad", POS, None),
    ("plant.load_coulomb", "N.m", POS, None),
    ("plant.load_viscous", "N.m.s/rad", POS, None),
    ("plant.absorber_inertia", "kg.m2", POS, None),
    ("plant.absorber_stiffness", "N.m/rad", POS, None),
    ("plant.absorber_damping", "N.m.s/rad", POS, None),
    ("plant.coulomb_velocity", "rad/s", POS, None),
    ("plant.encoder_counts_per_rev", "", Some(4.0), Some(16_777_216.0)),
    ("plant.current_noise_std", "A", POS, None),
    ("plant.acceleration_noise_std", "rad/s2", POS, None),
    ("plant.noise_seed", "", None, None),
    ("plant.substeps", "", Some(1.0), Some(1000.0)),
    ("excitation.point", "", Some(0.0), Some(2.0)),
    ("excitation.amplitude", "", None, None),
    ("excitation.frequency", "Hz", POS, None),
    ("accdec.filter", "", Some(0.0), Some(2.0)),
    ("accdec.order", "", Some(1.0), Some(6.0)),
    ("accdec.cutoff_hz", "Hz", POS, None),
    ("accdec.ma_stages", "", Some(1.0), Some(3.0)),
    ("accdec.ma_length_1", "", Some(1.0), Some(512.0)),
    ("accdec.ma_length_2", "", Some(1.0), Some(512.0)),
    ("accdec.ma_length_3", "", Some(1.0), Some(512.0)),
    ("seq.target_speed", "rad/s", POS, None),
    ("seq.acceleration", "rad/s2", POS, None),
    ("seq.zero_speed", "rad/s", POS, None),
    ("seq.position_gain", "1/s", POS, None),
    ("seq.completion_counts", "", Some(0.0), None),
    ("seq.gain_count", "", Some(1.0), Some(8.0)),
    ("seq.gain_1", "", POS, None),
    ("seq.gain_2", "", POS, None),
    ("seq.gain_3", "", POS, None),
    ("seq.gain_4", "", POS, None),
    ("seq.gain_5", "", POS, None),
    ("seq.gain_6", "", POS, None),
    ("seq.gain_7", "", POS, None),
    ("seq.gain_8", "", POS, None),
    ("seq.soft_limit_min", "rad", Some(-1.0e9), Some(1.0e9)),
    ("seq.soft_limit_max", "rad", Some(-1.0e9), Some(1.0e9)),
    ("sweep.point", "", Some(1.0), Some(3.0)),
    ("sweep.signal", "", Some(0.0), Some(1.0)),
    ("sweep.amplitude", "", POS, None),
    ("sweep.start_hz", "Hz", POS, None),
    ("sweep.stop_hz", "Hz", POS, None),
    ("sweep.points", "", Some(2.0), Some(127.0)),
    ("sweep.logarithmic", "", Some(0.0), Some(1.0)),
    ("sweep.extra_hz", "Hz", POS, None),
    ("sweep.settle_cycles", "", POS, None),
    ("sweep.min_settle_s", "s", POS, None),
    ("sweep.measure_cycles", "", POS, None),
    ("sweep.min_measure_s", "s", POS, None),
    ("sweep.shifts", "", Some(1.0), Some(16.0)),
    ("sweep.repeats", "", Some(1.0), Some(16.0)),
    ("sweep.threshold_hz", "Hz", POS, None),
    ("sweep.acquisition_divider", "", Some(1.0), None),
    ("sweep.prbs_degree", "", Some(2.0), Some(20.0)),
    ("sweep.prbs_divider", "", Some(1.0), None),
    ("sweep.prbs_seconds", "s", POS, None),
    ("sweep.precision_db", "", POS, None),
    ("sweep.max_extensions", "", Some(0.0), Some(64.0)),
    ("sweep_start", "", None, None),
    ("corr.count", "", Some(0.0), Some(8.0)),
    ("corr.zero_hz_1", "Hz", POS, None),
    ("corr.zero_damping_1", "", POS, None),
    ("corr.pole_hz_1", "Hz", POS, None),
    ("corr.pole_damping_1", "", POS, None),
    ("corr.zero_hz_2", "Hz", POS, None),
    ("corr.zero_damping_2", "", POS, None),
    ("corr.pole_hz_2", "Hz", POS, None),
    ("corr.pole_damping_2", "", POS, None),
    ("corr.zero_hz_3", "Hz", POS, None),
    ("corr.zero_damping_3", "", POS, None),
    ("corr.pole_hz_3", "Hz", POS, None),
    ("corr.pole_damping_3", "", POS, None),
    ("corr.zero_hz_4", "Hz", POS, None),
    ("corr.zero_damping_4", "", POS, None),
    ("corr.pole_hz_4", "Hz", POS, None),
    ("corr.pole_damping_4", "", POS, None),
    ("corr.zero_hz_5", "Hz", POS, None),
    ("corr.zero_damping_5", "", POS, None),
    ("corr.pole_hz_5", "Hz", POS, None),
    ("corr.pole_damping_5", "", POS, None),
    ("corr.zero_hz_6", "Hz", POS, None),
    ("corr.zero_damping_6", "", POS, None),
    ("corr.pole_hz_6", "Hz", POS, None),
    ("corr.pole_damping_6", "", POS, None),
    ("corr.zero_hz_7", "Hz", POS, None),
    ("corr.zero_damping_7", "", POS, None),
    ("corr.pole_hz_7", "Hz", POS, None),
    ("corr.pole_damping_7", "", POS, None),
    ("corr.zero_hz_8", "Hz", POS, None),
    ("corr.zero_damping_8", "", POS, None),
    ("corr.pole_hz_8", "Hz", POS, None),
    ("corr.pole_damping_8", "", POS, None),
    ("mode", "", Some(0.0), Some(3.0)),
    ("seq_run", "", Some(0.0), Some(1.0)),
    ("seq_stop", "", None, None),
    ("seq_release", "", None, None),
    ("seq_move", "", None, None),
    ("seq_return", "", None, None),
    ("seq_target", "rad", Some(-1.0e9), Some(1.0e9)),
    ("seq_gain_index", "", None, None),
    ("position_command", "rad", Some(-1.0e9), Some(1.0e9)),
    ("velocity_command", "rad/s", None, None),
    ("move_speed", "rad/s", POS, None),
    ("jog_velocity", "rad/s", None, None),
    ("torque_command", "N.m", None, None),
    ("disturbance_torque", "N.m", None, None),
    ("motor_position", "rad", None, None),
    ("motor_velocity", "rad/s", None, None),
    ("load_position", "rad", None, None),
    ("load_velocity", "rad/s", None, None),
    ("load_acceleration", "rad/s2", None, None),
    ("iq", "A", None, None),
    ("id", "A", None, None),
    ("torque_command_out", "N.m", None, None),
    ("electromagnetic_torque", "N.m", None, None),
    ("velocity_estimate", "rad/s", None, None),
    ("following_error", "rad", None, None),
    ("position_command_out", "rad", None, None),
    ("command_velocity", "rad/s", None, None),
    ("seq_state", "", Some(0.0), Some(4.0)),
    ("seq_complete", "", Some(0.0), Some(1.0)),
    ("seq_deviation", "", None, None),
    ("seq_hold_position", "rad", None, None),
    ("seq_speed_reference", "rad/s", None, None),
    ("seq_gain", "", None, None),
    ("seq_refused", "", Some(0.0), None),
    ("seq_last_refusal", "", Some(0.0), Some(9.0)),
    ("sweep_state", "", Some(0.0), Some(3.0)),
    ("sweep_point", "", Some(0.0), None),
    ("sweep_record", "", Some(0.0), None),
    ("sweep_frequency", "Hz", POS, None),
    ("sweep_done_points", "", Some(0.0), None),
    ("sweep_last_frequency", "Hz", POS, None),
    ("sweep_last_gain_db", "", None, None),
    ("sweep_last_phase_deg", "", None, None),
    ("sweep_last_quality", "", None, None),
    ("acq_time", "s", POS, None),
    ("acq_u", "", None, None),
    ("acq_y", "rad/s", None, None),
    ("acq_phase", "rad", None, None),
    ("acq_measuring", "", Some(0.0), Some(1.0)),
    ("acq_point", "", Some(0.0), None),
    ("acq_record", "", Some(0.0), None),
    ("faults", "", Some(0.0), None),
];

fn number(x: f64) -> String {
    if x.fract() == 0.0 && x.abs() < 1e15 { format!("{}", x as i64) } else { format!("{x:e}") }
}

/// Add the unit definitions and per-variable unit/min/max attributes.
pub fn annotate(xml: &str) -> Result<String> {
    let mut out = String::with_capacity(xml.len() + 8192);
    let mut rest = xml;
    let mut seen = Vec::new();
    let mut used_units = Vec::new();
    // Walk every variable element: <Float64 name="..." / <Int32 name="...".
    while let Some(pos) = find_variable(rest) {
        let (kind, start) = pos;
        out.push_str(&rest[..start]);
        let tail = &rest[start..];
        let name_at = tail.find("name=\"").map(|i| i + 6);
        let Some(name_at) = name_at else { bail!("variable element without a name") };
        let name_end = name_at + tail[name_at..].find('"').unwrap_or(0);
        let name = &tail[name_at..name_end];
        let Some(&(_, unit, min, max)) = VARIABLES.iter().find(|r| r.0 == name) else {
            bail!("{kind} variable `{name}` has no entry in xtask/src/variable_units.rs: add its unit and range");
        };
        seen.push(name.to_string());
        out.push_str(&tail[..name_end + 1]);
        let is_float = kind == "Float64";
        if is_float && !unit.is_empty() {
            let Some(&(_, _, ty)) = UNITS.iter().find(|u| u.0 == unit) else { bail!("unit {unit} of {name} is not in UNITS") };
            out.push_str(&format!(r#" declaredType="{ty}""#));
            if !used_units.contains(&unit) {
                used_units.push(unit);
            }
        }
        if let Some(m) = min {
            out.push_str(&format!(r#" min="{}""#, number(m)));
        }
        if let Some(m) = max {
            out.push_str(&format!(r#" max="{}""#, number(m)));
        }
        rest = &tail[name_end + 1..];
    }
    out.push_str(rest);

    let missing: Vec<_> = VARIABLES.iter().filter(|r| !seen.iter().any(|s| s == r.0)).map(|r| r.0).collect();
    if !missing.is_empty() {
        bail!("variable_units.rs lists variables the model does not have: {missing:?}");
    }

    let mut defs = String::from("  <UnitDefinitions>\n");
    let mut types = String::from("<TypeDefinitions>\n");
    for (name, base, ty) in UNITS.iter().filter(|u| used_units.contains(&u.0)) {
        types.push_str(&format!("    <Float64Type name=\"{ty}\" unit=\"{}\"/>\n", xml_escape(name)));
        if base.contains("A=") {
            // fmi-schema 0.8 (the Rust importer) spells the ampere exponent `a` and rejects the
            // standard's `A`; BaseUnit is optional, so these units are declared by name only.
            defs.push_str(&format!("    <Unit name=\"{}\"/>\n", xml_escape(name)));
        } else {
            defs.push_str(&format!("    <Unit name=\"{}\">\n      <BaseUnit {base}/>\n    </Unit>\n", xml_escape(name)));
        }
    }
    defs.push_str("  </UnitDefinitions>\n  ");
    types.push_str("  </TypeDefinitions>\n  ");
    defs.push_str(&types);
    if out.contains("<TypeDefinitions") {
        bail!("modelDescription.xml already has TypeDefinitions; merging is not implemented");
    }
    let anchor = ["<LogCategories", "<DefaultExperiment", "<ModelVariables"]
        .iter()
        .filter_map(|a| out.find(a))
        .min();
    let Some(anchor) = anchor else { bail!("modelDescription.xml has no <ModelVariables>") };
    out.insert_str(anchor, &defs);
    add_initial_unknowns(&out)
}

/// FMI 3.0 requires every output to be listed as an InitialUnknown as well (fmpy validate
/// checks it; rust-fmi 0.3 writes only the Output elements).
fn add_initial_unknowns(xml: &str) -> Result<String> {
    let Some(end) = xml.find("</ModelStructure>") else { bail!("modelDescription.xml has no ModelStructure") };
    if xml.contains("<InitialUnknown") {
        return Ok(xml.to_string());
    }
    let structure_start = xml.find("<ModelStructure>").unwrap_or(end);
    let mut unknowns = String::new();
    for part in xml[structure_start..end].split("<Output ").skip(1) {
        let vr = part.split('"').nth(1).unwrap_or_default();
        unknowns.push_str(&format!(r#"<InitialUnknown valueReference="{vr}"/>"#));
    }
    let mut out = xml.to_string();
    out.insert_str(end, &unknowns);
    Ok(out)
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('"', "&quot;")
}

/// Next `<Float64 ` or `<Int32 ` element: (kind, byte offset).
fn find_variable(s: &str) -> Option<(&'static str, usize)> {
    ["Float64", "Int32"]
        .iter()
        .filter_map(|k| s.find(&format!("<{k} ")).map(|i| (*k, i)))
        .min_by_key(|(_, i)| *i)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn refuses_a_variable_without_an_entry() {
        let xml = r#"<ModelVariables><Float64 name="mystery" valueReference="1"/></ModelVariables>"#;
        assert!(annotate(xml).unwrap_err().to_string().contains("mystery"));
    }
}
