//! Every variable of the FMU, declared once (in [`table`]): name, type, causality,
//! variability, start value, unit, range and description.
//!
//! Everything else is generated from that one table: the FMI 3.0 and FMI 2.0 model
//! descriptions, the documentation page, the value-reference dispatch of the C API (the
//! value reference is the index into [`DECLARATIONS`]: no search), the range check on every
//! `Set`, and the typed [`Values`] the model converts into the control core's and the
//! plant's parameters. Adding a parameter is one core field and one row.

#[cfg(test)]
mod range_tests;
mod table;
mod units;

pub use table::{name, Values, DECLARATIONS};
pub use units::Unit;

/// FMI base type of a variable.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Kind {
    Float64,
    Int32,
    Boolean,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Causality {
    Independent,
    Parameter,
    Input,
    Output,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Variability {
    Fixed,
    Discrete,
    Continuous,
}

/// Closed interval of accepted values (`None`: unbounded on that side).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Range {
    pub min: Option<f64>,
    pub max: Option<f64>,
}

impl Range {
    pub const ANY: Range = Range { min: None, max: None };

    pub const fn new(min: f64, max: f64) -> Self {
        Self { min: Some(min), max: Some(max) }
    }

    pub fn contains(&self, v: f64) -> bool {
        self.min.is_none_or(|m| v >= m) && self.max.is_none_or(|m| v <= m)
    }

    /// "[min, max]" for messages.
    pub fn describe(&self) -> String {
        let side = |b: Option<f64>, inf: &str| b.map_or(inf.to_string(), readable);
        format!("[{}, {}]", side(self.min, "-inf"), side(self.max, "+inf"))
    }
}

/// A number as people write it: 1e-9 rather than 0.000000001, 16777216 as it is, 1e300 rather
/// than its 301 digits.
pub fn readable(x: f64) -> String {
    let a = x.abs();
    if x != 0.0 && (!(1e-3..1e15).contains(&a) || (a >= 1e7 && x.fract() == 0.0 && a % 1e6 == 0.0)) {
        format!("{x:e}")
    } else {
        format!("{x}")
    }
}

/// One row of the table.
#[derive(Clone, Copy, Debug)]
pub struct Declaration {
    /// Value reference (equal to the row's index in [`DECLARATIONS`]).
    pub vr: u32,
    pub name: &'static str,
    pub kind: Kind,
    pub causality: Causality,
    pub variability: Variability,
    pub unit: Option<Unit>,
    /// What validation accepts for this value alone (other rules may relate several values,
    /// e.g. a filter frequency below the loop's Nyquist frequency).
    pub range: Range,
    pub description: &'static str,
}

impl Declaration {
    /// Set by the importer at all (parameters before initialisation ends, inputs any time).
    pub fn settable(&self) -> bool {
        matches!(self.causality, Causality::Parameter | Causality::Input)
    }

    /// A fixed parameter: settable only before initialisation ends.
    pub fn fixed(&self) -> bool {
        self.variability == Variability::Fixed
    }

    /// Whether the model description carries a start value (parameters and inputs).
    pub fn has_start(&self) -> bool {
        self.settable()
    }
}

/// The declaration of a value reference, by direct index.
pub fn declaration(vr: u32) -> Option<&'static Declaration> {
    DECLARATIONS.get(vr as usize)
}

/// The declaration of a variable name (for host code and tests; the C API never searches).
pub fn by_name(name: &str) -> Option<&'static Declaration> {
    DECLARATIONS.iter().find(|d| d.name == name)
}

/// A value of any of the three types, for generic code (model description, tests, host).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Value {
    Float64(f64),
    Int32(i32),
    Boolean(bool),
}

impl Value {
    pub fn as_f64(self) -> f64 {
        match self {
            Value::Float64(x) => x,
            Value::Int32(x) => x as f64,
            Value::Boolean(x) => x as i32 as f64,
        }
    }
}

/// Check a value against its declaration: finite and inside the declared range.
pub fn check(d: &Declaration, v: Value) -> Result<(), String> {
    let x = v.as_f64();
    if !x.is_finite() {
        return Err(format!("{} = {x} is not a finite number", d.name));
    }
    if !d.range.contains(x) {
        let unit = d.unit.map_or(String::new(), |u| format!(" {}", u.name()));
        return Err(format!("{} = {}{unit} is outside its range {}{unit}", d.name, readable(x), d.range.describe()));
    }
    Ok(())
}

/// The shortest decimal of an f32, as an f64: the start value that rounds back to exactly
/// that f32 when the model converts it (4.7124_f32 becomes 4.7124, not 4.712399959564209).
pub fn from_f32(x: f32) -> f64 {
    format!("{x}").parse().unwrap_or(x as f64)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn numbers_in_messages_read_as_people_write_them() {
        for (x, text) in [(1e-9, "1e-9"), (16777216.0, "16777216"), (2e7, "2e7"), (1e300, "1e300"), (-0.5, "-0.5")] {
            assert_eq!(readable(x), text);
        }
    }

    #[test]
    fn value_references_are_the_row_indices_and_names_are_unique() {
        for (i, d) in DECLARATIONS.iter().enumerate() {
            assert_eq!(d.vr as usize, i, "{}", d.name);
            assert_eq!(by_name(d.name).unwrap().vr, d.vr, "duplicate name {}", d.name);
        }
    }

    #[test]
    fn every_start_value_is_in_range_and_of_its_declared_type() {
        let v = Values::start();
        for d in DECLARATIONS {
            let x = v.get(d.vr).unwrap();
            let kind = match x {
                Value::Float64(_) => Kind::Float64,
                Value::Int32(_) => Kind::Int32,
                Value::Boolean(_) => Kind::Boolean,
            };
            assert_eq!(kind, d.kind, "{}", d.name);
            if d.has_start() {
                check(d, x).unwrap();
            }
        }
    }

    #[test]
    fn set_reaches_only_its_own_variable() {
        for d in DECLARATIONS {
            let mut v = Values::start();
            let before = v;
            let new = match d.kind {
                Kind::Float64 => Value::Float64(0.125 + v.get(d.vr).unwrap().as_f64()),
                Kind::Int32 => Value::Int32(1 + v.get(d.vr).unwrap().as_f64() as i32),
                Kind::Boolean => Value::Boolean(v.get(d.vr).unwrap().as_f64() == 0.0),
            };
            v.set(d.vr, new).unwrap();
            assert_eq!(v.get(d.vr), Some(new), "{}", d.name);
            for other in DECLARATIONS.iter().filter(|o| o.vr != d.vr) {
                assert_eq!(v.get(other.vr), before.get(other.vr), "setting {} changed {}", d.name, other.name);
            }
        }
    }

    #[test]
    fn the_typed_getters_read_the_same_field_as_get() {
        let mut v = Values::start();
        for d in DECLARATIONS {
            // A distinct value in every variable, so a wrong offset shows.
            let x = match d.kind {
                Kind::Float64 => Value::Float64(d.vr as f64 + 0.5),
                Kind::Int32 => Value::Int32(d.vr as i32 + 7),
                Kind::Boolean => Value::Boolean(d.vr % 2 == 1),
            };
            v.set(d.vr, x).unwrap();
        }
        for d in DECLARATIONS {
            let typed = match d.kind {
                Kind::Float64 => v.float64(d.vr).map(Value::Float64),
                Kind::Int32 => v.int32(d.vr).map(Value::Int32),
                Kind::Boolean => v.boolean(d.vr).map(Value::Boolean),
            };
            assert_eq!(typed, v.get(d.vr), "{}", d.name);
            assert!(d.kind == Kind::Float64 || v.float64(d.vr).is_none(), "{} read as Float64", d.name);
        }
        assert_eq!(v.float64(DECLARATIONS.len() as u32), None);
    }

    #[test]
    fn the_finite_check_covers_every_float64_output_and_nothing_else() {
        assert!(Values::start().float64_outputs_finite());
        for d in DECLARATIONS.iter().filter(|d| d.kind == Kind::Float64) {
            for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
                let mut v = Values::start();
                v.set(d.vr, Value::Float64(bad)).unwrap();
                assert_eq!(v.float64_outputs_finite(), d.causality != Causality::Output, "{} = {bad}", d.name);
            }
        }
    }

    #[test]
    fn the_shortest_decimal_rounds_back_to_the_f32() {
        for x in [4.7124_f32, 0.0942, 11.84, 1.0 / 3.0, 1.0e-5, 2827.4] {
            assert_eq!(from_f32(x) as f32, x);
            assert!(format!("{}", from_f32(x)).len() <= 10, "{}", from_f32(x));
        }
    }
}
