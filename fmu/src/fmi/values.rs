//! Get and Set over arrays of value references, shared by both C APIs: a direct index per
//! value reference, the type checked, and a Set that stores all of its values or none.

use crate::co_simulation::AxisModel;
use crate::variables::{self, Kind, Value, Values};

fn kind_error(vr: u32, wanted: Kind) -> String {
    match variables::declaration(vr) {
        Some(d) => format!("{} (value reference {vr}) is a {:?} variable, not {wanted:?}", d.name, d.kind),
        None => format!("no variable has value reference {vr}"),
    }
}

/// Read `vrs` into `out` (as many values as references) with a typed getter of `Values`.
pub fn get<T>(
    model: &AxisModel,
    vrs: &[u32],
    out: &mut [T],
    wanted: Kind,
    read: impl Fn(&Values, u32) -> Option<T>,
) -> Result<(), String> {
    if vrs.len() != out.len() {
        return Err(format!(
            "{} value references but room for {} values (every variable is a scalar)",
            vrs.len(),
            out.len()
        ));
    }
    let values = model.values();
    for (o, &vr) in out.iter_mut().zip(vrs) {
        *o = read(values, vr).ok_or_else(|| kind_error(vr, wanted))?;
    }
    Ok(())
}

/// Set `vrs` from `values`: all or none.
pub fn set<T: Copy>(
    model: &mut AxisModel,
    vrs: &[u32],
    values: &[T],
    wrap: impl Fn(T) -> Value + Clone,
) -> Result<(), String> {
    if vrs.len() != values.len() {
        return Err(format!("{} value references but {} values (every variable is a scalar)", vrs.len(), values.len()));
    }
    model.set_all(vrs.iter().copied().zip(values.iter().map(move |v| wrap(*v))))
}

/// A Get or Set of a type the FMU has no variable of: fine for zero references.
pub fn no_variables_of(kind: &str, vrs: usize) -> Result<(), String> {
    if vrs == 0 {
        Ok(())
    } else {
        Err(format!("the FMU has no {kind} variables"))
    }
}
