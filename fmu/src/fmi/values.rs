//! Get and Set over arrays of value references, shared by both C APIs: a direct index per
//! value reference, the type checked, and a Set that stores all of its values or none. A Get
//! of many references goes by its [`GetPlan`]: an importer reads the same references at every
//! communication point, so they are resolved and checked once, not at every step.

use std::mem::size_of;

use crate::co_simulation::AxisModel;
use crate::variables::{self, Kind, Value, Values};

/// The Rust type of a variable type's fields in [`Values`] (and of its FMI 3.0 values).
pub trait Field: Copy {
    const KIND: Kind;
}

impl Field for f64 {
    const KIND: Kind = Kind::Float64;
}

impl Field for i32 {
    const KIND: Kind = Kind::Int32;
}

impl Field for bool {
    const KIND: Kind = Kind::Boolean;
}

/// A Get's value references as last resolved (all valid, of the plan's type), and the runs of
/// them whose fields lie one after the other in [`Values`]: the next Get of the same references
/// compares them (one `memcmp`) and copies each run in one piece, instead of resolving and
/// checking every reference again. The fields' places never change, so a plan never goes
/// stale; a Get of other references makes a new one.
#[derive(Clone, Debug, Default)]
pub struct GetPlan {
    vrs: Vec<u32>,
    runs: Vec<Run>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Run {
    /// Index of the run's first value in the Get's values.
    first: usize,
    /// Byte offset of its first field in `Values`.
    at: usize,
    len: usize,
}

/// One plan per variable type (the Gets of each type an importer makes at every step).
#[derive(Clone, Debug, Default)]
pub struct GetPlans {
    pub float64: GetPlan,
    pub int32: GetPlan,
    pub boolean: GetPlan,
}

/// Gets of fewer references are resolved one by one: a plan does not pay for them (and an
/// importer that reads one variable at a time does not rebuild a plan at every call).
const PLANNED_FROM: usize = 8;

impl GetPlan {
    /// Resolve `vrs` (fields of `T`). A reference that is unknown or of another type is
    /// refused and leaves the plan empty (it matches no Get but an empty one, which copies
    /// nothing).
    fn build<T: Field>(&mut self, vrs: &[u32]) -> Result<(), String> {
        self.vrs.clear();
        self.runs.clear();
        for (i, &vr) in vrs.iter().enumerate() {
            let Some(at) = Values::offset_of(T::KIND, vr) else {
                self.runs.clear();
                return Err(kind_error(vr, T::KIND));
            };
            match self.runs.last_mut() {
                Some(r) if r.at + r.len * size_of::<T>() == at => r.len += 1,
                _ => self.runs.push(Run { first: i, at, len: 1 }),
            }
        }
        self.vrs.extend_from_slice(vrs);
        Ok(())
    }
}

/// Read `vrs` into `out` (as many values as references), the fields' own type: by `plan` when
/// there are many references, else one by one.
pub fn get_planned<T: Field>(model: &AxisModel, plan: &mut GetPlan, vrs: &[u32], out: &mut [T]) -> Result<(), String> {
    if vrs.len() != out.len() {
        return Err(count_error(vrs.len(), out.len()));
    }
    let base = model.values() as *const Values as *const u8;
    if plan.vrs != vrs {
        if vrs.len() < PLANNED_FROM {
            for (o, &vr) in out.iter_mut().zip(vrs) {
                let at = Values::offset_of(T::KIND, vr).ok_or_else(|| kind_error(vr, T::KIND))?;
                // SAFETY: `at` is the offset of a field of `T::KIND`, whose Rust type is `T`.
                *o = unsafe { *(base.add(at) as *const T) };
            }
            return Ok(());
        }
        plan.build::<T>(vrs)?;
    }
    for r in &plan.runs {
        // SAFETY: the plan was built from these references: the run's fields are `r.len`
        // adjacent fields of type `T` in `Values` from byte `r.at` (each of `T::KIND`), and its
        // values `out[r.first..r.first + r.len]`, inside `out` (as long as `vrs`); `out` is the
        // importer's array, not the instance's memory.
        unsafe {
            let (from, to) = (base.add(r.at) as *const T, out.as_mut_ptr().add(r.first));
            match r.len {
                // A lone field (most runs of a few) without the call to `memcpy`.
                1 => *to = *from,
                2 => *(to as *mut [T; 2]) = *(from as *const [T; 2]),
                len => std::ptr::copy_nonoverlapping(from, to, len),
            }
        }
    }
    Ok(())
}

fn count_error(vrs: usize, values: usize) -> String {
    format!("{vrs} value references but room for {values} values (every variable is a scalar)")
}

fn kind_error(vr: u32, wanted: Kind) -> String {
    match variables::declaration(vr) {
        Some(d) => format!("{} (value reference {vr}) is a {:?} variable, not {wanted:?}", d.name, d.kind),
        None => format!("no variable has value reference {vr}"),
    }
}

/// Read `vrs` into `out` (as many values as references) with a typed getter of `Values` (a
/// value converted on the way, such as FMI 2.0's Boolean as an int).
pub fn get<T>(
    model: &AxisModel,
    vrs: &[u32],
    out: &mut [T],
    wanted: Kind,
    read: impl Fn(&Values, u32) -> Option<T>,
) -> Result<(), String> {
    if vrs.len() != out.len() {
        return Err(count_error(vrs.len(), out.len()));
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
