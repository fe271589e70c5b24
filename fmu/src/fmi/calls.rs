//! What both C APIs do, written once: the experiment's times, initialisation, reset, the
//! communication step and the FMU state calls. `fmi3` and `fmi2` wrap these in their own
//! signatures and the barrier of `instance::call`.

#![allow(clippy::missing_safety_doc)]

use std::ffi::c_void;

use super::instance::{slice, slice_mut, Instance, Phase, Status};
use crate::fmu_state::{self, Snapshot};

/// The experiment's start and stop times (fmi2SetupExperiment, fmi3EnterInitializationMode):
/// both checked before either is stored, so a refusal changes nothing.
pub fn set_experiment(i: &mut Instance, start: f64, stop: Option<f64>) -> Result<Status, String> {
    if !start.is_finite() {
        return Err(format!("start time {start} is not a finite number"));
    }
    if let Some(stop) = stop {
        if !(stop.is_finite() && stop >= start) {
            return Err(format!("stop time {stop} s must be finite and not before the start time {start} s"));
        }
    }
    i.model.set_start_time(start)?;
    i.stop_time = stop;
    Ok(Status::Ok)
}

/// Enter initialisation at `start` (both versions).
pub fn enter_initialization(i: &mut Instance, start: f64, stop: Option<f64>) -> Result<Status, String> {
    set_experiment(i, start, stop)?;
    i.phase = Phase::InitializationMode;
    Ok(Status::Ok)
}

/// Leave initialisation: the axis is built from the parameters; when they are refused, the
/// reason is logged and the instance stays in initialisation (fix and call again).
pub fn exit_initialization(i: &mut Instance) -> Result<Status, String> {
    i.model.initialize()?;
    i.phase = Phase::StepMode;
    Ok(Status::Ok)
}

/// Back to Instantiated with every variable at its start value (the logger settings stay).
pub fn reset(i: &mut Instance) -> Result<Status, String> {
    i.model.reset();
    i.phase = Phase::Instantiated;
    i.poisoned = false;
    i.stop_time = None;
    Ok(Status::Ok)
}

/// One communication step (both versions): refused before the stop time is passed, and
/// outside the model's own checks; a refused step leaves the instance as it was.
pub fn do_step(i: &mut Instance, current: f64, h: f64) -> Result<Status, String> {
    if let Some(stop) = i.stop_time {
        if current + h > stop + 1e-9 * stop.abs().max(1.0) {
            return Err(format!("the step to {} s goes past the stop time {stop} s", current + h));
        }
    }
    let result = i.model.do_step(current, h);
    if !i.model.refusals.is_empty() {
        for note in std::mem::take(&mut i.model.refusals) {
            i.log(Status::Warning, &note);
        }
    }
    result.map(|()| Status::Ok)
}

/// Save the state into `*state` (a new one when NULL, else overwrite that one).
pub unsafe fn get_fmu_state(i: &mut Instance, state: *mut *mut c_void) -> Result<Status, String> {
    if state.is_null() {
        return Err("FMUState is NULL".into());
    }
    unsafe { store(state, Snapshot::new(i.model.state.clone(), i.phase, i.stop_time)) }
}

/// Put a snapshot behind `*state`: a new one when it is NULL, else over the one it points to.
///
/// # Safety
/// `state` is non-NULL; `*state` is NULL or a state of this library.
unsafe fn store(state: *mut *mut c_void, snapshot: Snapshot) -> Result<Status, String> {
    unsafe {
        if (*state).is_null() {
            *state = Box::into_raw(Box::new(snapshot)) as *mut c_void;
        } else {
            *Snapshot::from_ptr(*state)? = snapshot;
        }
    }
    Ok(Status::Ok)
}

pub unsafe fn set_fmu_state(i: &mut Instance, state: *mut c_void) -> Result<Status, String> {
    let s = unsafe { Snapshot::from_ptr(state)? };
    i.model.state = s.model.clone();
    i.model.refusals.clear();
    i.phase = s.phase;
    i.stop_time = s.stop_time;
    i.poisoned = false;
    Ok(Status::Ok)
}

pub unsafe fn free_fmu_state(state: *mut *mut c_void) -> Result<Status, String> {
    if state.is_null() || unsafe { (*state).is_null() } {
        return Ok(Status::Ok);
    }
    unsafe {
        Snapshot::free(*state)?;
        *state = std::ptr::null_mut();
    }
    Ok(Status::Ok)
}

pub unsafe fn serialized_size(state: *mut c_void, size: *mut usize) -> Result<Status, String> {
    unsafe { Snapshot::from_ptr(state)? };
    if size.is_null() {
        return Err("size is NULL".into());
    }
    unsafe { *size = fmu_state::serialized_size() };
    Ok(Status::Ok)
}

pub unsafe fn serialize(state: *mut c_void, out: *mut u8, size: usize) -> Result<Status, String> {
    let s = unsafe { Snapshot::from_ptr(state)? };
    let out = unsafe { slice_mut(out, size, "serializedState")? };
    fmu_state::serialize(s, out)?;
    Ok(Status::Ok)
}

pub unsafe fn deserialize(bytes: *const u8, size: usize, state: *mut *mut c_void) -> Result<Status, String> {
    if state.is_null() {
        return Err("FMUState is NULL".into());
    }
    let bytes = unsafe { slice(bytes, size, "serializedState")? };
    unsafe { store(state, fmu_state::deserialize(bytes)?) }
}
