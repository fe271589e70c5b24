//! The model descriptions (FMI 3.0 and FMI 2.0) and the documentation page, generated from
//! the variable table; the instantiation token (FMI 2.0 GUID) both the XML and the binary
//! compute from it.

use std::fmt::Write;

use crate::variables::{Causality, Declaration, Kind, Unit, Value, Values, Variability, DECLARATIONS};

pub const MODEL_IDENTIFIER: &str = "servo_axis";
const MODEL_NAME: &str = "servo_axis";
const DESCRIPTION: &str =
    "Servo axis: the drive's control core (current, velocity and position loops, acc/dec filter, \
stop sequences, frequency-response sweep, response correction) in closed loop with a PMSM, a two-inertia load, \
friction and an encoder";
const COPYRIGHT: &str = "Copyright (c) the servo-drive toolkit developers";
const LICENSE: &str = "MIT OR Apache-2.0";
/// Communication steps are whole multiples of the position-loop period (default 0.25 ms).
pub const STEP: f64 = 0.00025;
const GENERATION_TOOL: &str = concat!("servo-drive toolkit ", env!("CARGO_PKG_VERSION"));

/// The instantiation token (FMI 2.0: GUID): a hash of every declaration and the version, so
/// a binary only loads with the model description it was built with.
pub fn instantiation_token() -> &'static str {
    static TOKEN: std::sync::OnceLock<String> = std::sync::OnceLock::new();
    TOKEN.get_or_init(compute_token)
}

fn compute_token() -> String {
    fn feed(h: &mut u64, s: &str) {
        for b in s.bytes().chain([0]) {
            *h ^= b as u64;
            *h = h.wrapping_mul(0x100_0000_01b3);
        }
    }
    let mut h = 0xcbf2_9ce4_8422_2325u64;
    feed(&mut h, env!("CARGO_PKG_VERSION"));
    let start = Values::start();
    for d in DECLARATIONS {
        feed(&mut h, &format!("{d:?}{:?}", start.get(d.vr)));
    }
    let a = h;
    feed(&mut h, "second half");
    let b = h;
    format!(
        "{{{:08x}-{:04x}-{:04x}-{:04x}-{:012x}}}",
        a >> 32,
        (a >> 16) & 0xffff,
        a & 0xffff,
        b >> 48,
        b & 0xffff_ffff_ffff
    )
}

fn xml_escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

fn number(d: &Declaration, x: f64) -> String {
    match d.kind {
        Kind::Float64 => format!("{x:?}"),
        _ => format!("{}", x as i64),
    }
}

fn start_text(v: Value) -> String {
    match v {
        Value::Float64(x) => format!("{x:?}"),
        Value::Int32(x) => x.to_string(),
        Value::Boolean(x) => x.to_string(),
    }
}

fn units_used() -> Vec<Unit> {
    Unit::ALL.into_iter().filter(|u| DECLARATIONS.iter().any(|d| d.unit == Some(*u))).collect()
}

fn unit_definitions(out: &mut String) {
    out.push_str("  <UnitDefinitions>\n");
    for u in units_used() {
        let b = u.base();
        let mut attrs = String::new();
        for (name, e) in [("kg", b.kg), ("m", b.m), ("s", b.s), ("A", b.a), ("rad", b.rad)] {
            if e != 0 {
                let _ = write!(attrs, " {name}=\"{e}\"");
            }
        }
        if b.factor != 1.0 {
            let _ = write!(attrs, " factor=\"{:?}\"", b.factor);
        }
        let _ = writeln!(out, "    <Unit name=\"{}\">\n      <BaseUnit{attrs}/>\n    </Unit>", xml_escape(u.name()));
    }
    out.push_str("  </UnitDefinitions>\n");
}

fn log_categories(out: &mut String) {
    out.push_str("  <LogCategories>\n");
    for (name, description) in crate::fmi::instance::LOG_CATEGORIES {
        let _ = writeln!(out, "    <Category name=\"{name}\" description=\"{}\"/>", xml_escape(description));
    }
    out.push_str("  </LogCategories>\n");
}

fn causality(d: &Declaration) -> &'static str {
    match d.causality {
        Causality::Independent => "independent",
        Causality::Parameter => "parameter",
        Causality::Input => "input",
        Causality::Output => "output",
    }
}

fn variability(d: &Declaration) -> &'static str {
    match d.variability {
        Variability::Fixed => "fixed",
        Variability::Discrete => "discrete",
        Variability::Continuous => "continuous",
    }
}

/// `declaredType`, `min`, `max` and `start` attributes.
fn value_attributes(d: &Declaration, start: &Values) -> String {
    let mut a = String::new();
    if let Some(u) = d.unit {
        let _ = write!(a, " declaredType=\"{}\"", u.type_name());
    }
    // Outputs too: their declared range is what the FMU guarantees (tests/tests/output_ranges.rs).
    if d.kind != Kind::Boolean && d.causality != Causality::Independent {
        if let Some(m) = d.range.min {
            let _ = write!(a, " min=\"{}\"", number(d, m));
        }
        if let Some(m) = d.range.max {
            let _ = write!(a, " max=\"{}\"", number(d, m));
        }
    }
    if d.has_start() {
        let _ = write!(a, " start=\"{}\"", start_text(start.get(d.vr).expect("every row has a value")));
    }
    a
}

fn header(out: &mut String, version: &str, token_attribute: &str) {
    let _ = writeln!(
        out,
        "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<fmiModelDescription fmiVersion=\"{version}\" modelName=\"{MODEL_NAME}\" \
         {token_attribute}=\"{}\" description=\"{}\" version=\"{}\" generationTool=\"{GENERATION_TOOL}\" \
         copyright=\"{COPYRIGHT}\" license=\"{LICENSE}\">",
        instantiation_token(),
        xml_escape(DESCRIPTION),
        env!("CARGO_PKG_VERSION"),
    );
}

/// modelDescription.xml for FMI 3.0.
pub fn fmi3() -> String {
    let start = Values::start();
    let mut out = String::with_capacity(64 * 1024);
    header(&mut out, "3.0", "instantiationToken");
    let _ = writeln!(
        out,
        "  <CoSimulation modelIdentifier=\"{MODEL_IDENTIFIER}\" canHandleVariableCommunicationStepSize=\"true\" \
         fixedInternalStepSize=\"{STEP:?}\" canGetAndSetFMUState=\"true\" canSerializeFMUState=\"true\" hasEventMode=\"false\"/>"
    );
    unit_definitions(&mut out);
    out.push_str("  <TypeDefinitions>\n");
    for u in units_used() {
        let _ = writeln!(
            out,
            "    <Float64Type name=\"{}\" quantity=\"{}\" unit=\"{}\"/>",
            u.type_name(),
            u.quantity(),
            xml_escape(u.name())
        );
    }
    out.push_str("  </TypeDefinitions>\n");
    log_categories(&mut out);
    let _ = writeln!(out, "  <DefaultExperiment startTime=\"0.0\" stopTime=\"1.0\" stepSize=\"{STEP:?}\"/>");
    out.push_str("  <ModelVariables>\n");
    for d in DECLARATIONS {
        let element = match d.kind {
            Kind::Float64 => "Float64",
            Kind::Int32 => "Int32",
            Kind::Boolean => "Boolean",
        };
        let _ = writeln!(
            out,
            "    <{element} name=\"{}\" valueReference=\"{}\" causality=\"{}\" variability=\"{}\" description=\"{}\"{}/>",
            d.name,
            d.vr,
            causality(d),
            variability(d),
            xml_escape(d.description),
            value_attributes(d, &start)
        );
    }
    out.push_str("  </ModelVariables>\n  <ModelStructure>\n");
    // Outputs change only in DoStep: none depends on an input at the same instant.
    for d in outputs() {
        let _ = writeln!(out, "    <Output valueReference=\"{}\" dependencies=\"\"/>", d.vr);
    }
    for d in outputs() {
        let _ = writeln!(out, "    <InitialUnknown valueReference=\"{}\"/>", d.vr);
    }
    out.push_str("  </ModelStructure>\n</fmiModelDescription>\n");
    out
}

fn outputs() -> impl Iterator<Item = &'static Declaration> {
    DECLARATIONS.iter().filter(|d| d.causality == Causality::Output)
}

/// modelDescription.xml for FMI 2.0.
pub fn fmi2() -> String {
    let start = Values::start();
    let mut out = String::with_capacity(64 * 1024);
    header(&mut out, "2.0", "guid");
    let _ = writeln!(
        out,
        "  <CoSimulation modelIdentifier=\"{MODEL_IDENTIFIER}\" canHandleVariableCommunicationStepSize=\"true\" \
         canGetAndSetFMUstate=\"true\" canSerializeFMUstate=\"true\" canNotUseMemoryManagementFunctions=\"true\"/>"
    );
    unit_definitions(&mut out);
    out.push_str("  <TypeDefinitions>\n");
    for u in units_used() {
        let _ = writeln!(
            out,
            "    <SimpleType name=\"{}\">\n      <Real quantity=\"{}\" unit=\"{}\"/>\n    </SimpleType>",
            u.type_name(),
            u.quantity(),
            xml_escape(u.name())
        );
    }
    out.push_str("  </TypeDefinitions>\n");
    log_categories(&mut out);
    let _ = writeln!(out, "  <DefaultExperiment startTime=\"0.0\" stopTime=\"1.0\" stepSize=\"{STEP:?}\"/>");
    out.push_str("  <ModelVariables>\n");
    for d in DECLARATIONS {
        let element = match d.kind {
            Kind::Float64 => "Real",
            Kind::Int32 => "Integer",
            Kind::Boolean => "Boolean",
        };
        let initial = match d.causality {
            Causality::Parameter => " initial=\"exact\"",
            _ => "",
        };
        let _ = writeln!(
            out,
            "    <!-- index {} -->\n    <ScalarVariable name=\"{}\" valueReference=\"{}\" causality=\"{}\" variability=\"{}\"{initial} description=\"{}\">\n      <{element}{}/>\n    </ScalarVariable>",
            d.vr + 1,
            d.name,
            d.vr,
            causality(d),
            variability(d),
            xml_escape(d.description),
            value_attributes(d, &start)
        );
    }
    out.push_str("  </ModelVariables>\n  <ModelStructure>\n    <Outputs>\n");
    // ScalarVariable indices are 1-based: the value reference + 1.
    for d in outputs() {
        let _ = writeln!(out, "      <Unknown index=\"{}\" dependencies=\"\"/>", d.vr + 1);
    }
    out.push_str("    </Outputs>\n    <InitialUnknowns>\n");
    for d in outputs() {
        let _ = writeln!(out, "      <Unknown index=\"{}\"/>", d.vr + 1);
    }
    out.push_str("    </InitialUnknowns>\n  </ModelStructure>\n</fmiModelDescription>\n");
    out
}

fn range_text(d: &Declaration) -> String {
    if d.kind == Kind::Boolean || (d.range.min.is_none() && d.range.max.is_none()) {
        // An output without a declared range: any finite value (a step that would give
        // another ends with an error, never OK).
        return match (d.causality, d.kind) {
            (Causality::Output | Causality::Independent, Kind::Float64) => "finite".to_string(),
            (Causality::Output, Kind::Int32) => "Int32".to_string(),
            _ => String::new(),
        };
    }
    let side = |b: Option<f64>| b.map_or("…".to_string(), crate::variables::readable);
    format!("{} … {}", side(d.range.min), side(d.range.max))
}

/// The parameter and input table (Markdown) the README carries.
pub fn markdown_table() -> String {
    let start = Values::start();
    let mut out = String::from(
        "| variable | causality | unit | start | range | description |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for d in DECLARATIONS.iter().filter(|d| d.settable()) {
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} |",
            d.name,
            causality(d),
            d.unit.map_or("", |u| u.name()),
            start_text(start.get(d.vr).unwrap()),
            range_text(d),
            d.description.replace('|', "\\|")
        );
    }
    out
}

fn kind_text(d: &Declaration) -> &'static str {
    match d.kind {
        Kind::Float64 => "Float64",
        Kind::Int32 => "Int32",
        Kind::Boolean => "Boolean",
    }
}

/// The output table (Markdown) of the book's FMU variables reference: every output (and the
/// independent variable `time`) with its value reference, type, unit, range and description.
pub fn markdown_outputs_table() -> String {
    let mut out = String::from(
        "| variable | value reference | type | unit | range | description |\n| --- | --- | --- | --- | --- | --- |\n",
    );
    for d in DECLARATIONS.iter().filter(|d| !d.settable()) {
        let _ = writeln!(
            out,
            "| `{}` | {} | {} | {} | {} | {} |",
            d.name,
            d.vr,
            kind_text(d),
            d.unit.map_or("", |u| u.name()),
            range_text(d),
            d.description.replace('|', "\\|")
        );
    }
    out
}

/// Counts for the book's FMU variables reference: (parameters, inputs, outputs).
pub fn variable_counts() -> (usize, usize, usize) {
    let count = |c: Causality| DECLARATIONS.iter().filter(|d| d.causality == c).count();
    (count(Causality::Parameter), count(Causality::Input), count(Causality::Output))
}

/// documentation/index.html: quick start and every variable with unit and range.
pub fn documentation_html() -> String {
    let start = Values::start();
    let mut rows = String::new();
    for d in DECLARATIONS {
        let _ = writeln!(
            rows,
            "<tr><td><code>{}</code></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>",
            d.name,
            d.vr,
            causality(d),
            d.unit.map_or("", |u| u.name()),
            if d.has_start() { start_text(start.get(d.vr).unwrap()) } else { String::new() },
            xml_escape(&range_text(d)),
            xml_escape(d.description)
        );
    }
    format!(
        r#"<!DOCTYPE html>
<html lang="en"><head><meta charset="utf-8"><title>servo_axis FMU</title>
<style>body{{font-family:sans-serif;max-width:70em;margin:2em auto;line-height:1.4}}table{{border-collapse:collapse}}td,th{{border:1px solid #ccc;padding:2px 6px;text-align:left;vertical-align:top}}code,pre{{background:#f4f4f4}}</style>
</head><body>
<h1>servo_axis — one servo axis as a Co-Simulation FMU</h1>
<p>{description}.</p>
<h2>Quick start</h2>
<ul>
<li>Communication steps are whole multiples of the position-loop period: 0.25 ms with the default
<code>ctrl.current_loop_hz</code> = 16 kHz and <code>ctrl.position_divider</code> = 4 (a step of another size is refused with the reason).</li>
<li>With no inputs the axis stands still in position mode and every output is 0. Give it a position command, for example in fmpy:
<pre>import numpy as np, fmpy
inputs = np.array([(0.0, 0.0), (0.01, 1.0)], dtype=[('time', float), ('position_command', float)])
result = fmpy.simulate_fmu('servo_axis.fmu', stop_time=0.3, output_interval=0.00025, input=inputs,
                           output=['motor_position', 'load_position', 'iq'])</pre></li>
<li>Parameters are fixed: set them before the end of initialisation (or after Reset). A value outside its range below is refused with the reason in the log.</li>
<li>Modes (input <code>mode</code>): 0 torque, 1 velocity, 2 position, 3 stop sequence (the <code>seq_*</code> keys are counters: each increase is one press).</li>
<li>The FMU can save, restore and serialize its state (roll back a step, or start many runs from one settled state).</li>
</ul>
<h2>Variables</h2>
<table><tr><th>name</th><th>value reference</th><th>causality</th><th>unit</th><th>start</th><th>range</th><th>description</th></tr>
{rows}</table>
<p>{copyright}. Licence: {license}. Instantiation token {token}.</p>
</body></html>
"#,
        description = xml_escape(DESCRIPTION),
        copyright = COPYRIGHT,
        license = LICENSE,
        token = instantiation_token(),
    )
}
