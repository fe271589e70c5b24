//! The FMI 2.0 Co-Simulation C API from the same model: same variables and value
//! references, same numbers (the FMI 3.0 functions and these call the same code).

#![allow(non_snake_case, clippy::missing_safety_doc)]

use std::ffi::{c_char, c_int, c_void, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

use super::instance::{
    self, c_str, call, slice, slice_mut, unsupported, Instance, Logger, Phase, Status, WhenPoisoned, ANY_PHASE,
};
use super::values;
use super::{calls, fmi3};
use crate::model_description;
use crate::variables::{Kind, Value};

type Component = *mut c_void;
type Vr = u32;
type Fmi2Status = c_int;
type Fmi2Boolean = c_int;

use Phase::{InitializationMode as IM, Instantiated as I, StepMode as SM, Terminated as T};

const GET: &[Phase] = &[IM, SM, T];
const SET: &[Phase] = &[I, IM, SM];

/// `fmi2CallbackFunctions`.
#[repr(C)]
pub struct CallbackFunctions {
    pub logger: Option<instance::Fmi2Logger>,
    pub allocate_memory: *const c_void,
    pub free_memory: *const c_void,
    pub step_finished: *const c_void,
    pub component_environment: *mut c_void,
}

#[no_mangle]
pub extern "C" fn fmi2GetTypesPlatform() -> *const c_char {
    c"default".as_ptr()
}

#[no_mangle]
pub extern "C" fn fmi2GetVersion() -> *const c_char {
    c"2.0".as_ptr()
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetDebugLogging(
    c: Component,
    logging_on: Fmi2Boolean,
    n: usize,
    categories: *const *const c_char,
) -> Fmi2Status {
    unsafe {
        call(c, "fmi2SetDebugLogging", ANY_PHASE, WhenPoisoned::Allow, |i| {
            i.set_debug_logging(logging_on != 0, n, categories)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Instantiate(
    instance_name: *const c_char,
    fmu_type: c_int,
    guid: *const c_char,
    _resource_location: *const c_char,
    functions: *const CallbackFunctions,
    _visible: Fmi2Boolean,
    logging_on: Fmi2Boolean,
) -> Component {
    let made = catch_unwind(AssertUnwindSafe(|| {
        let (environment, logger) = if functions.is_null() {
            (std::ptr::null_mut(), None)
        } else {
            let f = unsafe { &*functions };
            (f.component_environment, f.logger)
        };
        let name = unsafe { c_str(instance_name, "instanceName") }.unwrap_or("servo_axis").to_string();
        let inst = Instance::new(
            CString::new(name).unwrap_or_default(),
            Logger::Fmi2 { environment, callback: logger },
            logging_on != 0,
        );
        let check = || -> Result<(), String> {
            if fmu_type != 1 {
                return Err("this FMU is Co-Simulation only (fmuType must be fmi2CoSimulation)".into());
            }
            let token = unsafe { c_str(guid, "fmuGUID")? };
            let ours = model_description::instantiation_token();
            if token != ours {
                return Err(format!(
                    "fmuGUID {token} is not this FMU's ({ours}): the binary and modelDescription.xml differ"
                ));
            }
            Ok(())
        };
        match check() {
            Ok(()) => Box::into_raw(Box::new(inst)) as Component,
            Err(m) => {
                inst.log(Status::Error, &format!("fmi2Instantiate: {m}"));
                std::ptr::null_mut()
            }
        }
    }));
    made.unwrap_or(std::ptr::null_mut())
}

#[no_mangle]
pub unsafe extern "C" fn fmi2FreeInstance(c: Component) {
    unsafe { fmi3::fmi3FreeInstance(c) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetupExperiment(
    c: Component,
    _tolerance_defined: Fmi2Boolean,
    _tolerance: f64,
    start_time: f64,
    stop_time_defined: Fmi2Boolean,
    stop_time: f64,
) -> Fmi2Status {
    unsafe {
        call(c, "fmi2SetupExperiment", &[I], WhenPoisoned::Refuse, |i| {
            calls::set_experiment(i, start_time, (stop_time_defined != 0).then_some(stop_time))
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2EnterInitializationMode(c: Component) -> Fmi2Status {
    unsafe {
        call(c, "fmi2EnterInitializationMode", &[I], WhenPoisoned::Refuse, |i| {
            let (start, stop) = (i.model.time(), i.stop_time);
            calls::enter_initialization(i, start, stop)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2ExitInitializationMode(c: Component) -> Fmi2Status {
    unsafe { call(c, "fmi2ExitInitializationMode", &[IM], WhenPoisoned::Refuse, calls::exit_initialization) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Terminate(c: Component) -> Fmi2Status {
    unsafe {
        call(c, "fmi2Terminate", &[SM], WhenPoisoned::Allow, |i| {
            i.phase = Phase::Terminated;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2Reset(c: Component) -> Fmi2Status {
    unsafe { call(c, "fmi2Reset", ANY_PHASE, WhenPoisoned::Allow, calls::reset) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2DoStep(c: Component, current: f64, h: f64, _no_set_prior: Fmi2Boolean) -> Fmi2Status {
    unsafe { call(c, "fmi2DoStep", &[SM], WhenPoisoned::Refuse, |i| calls::do_step(i, current, h)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2CancelStep(c: Component) -> Fmi2Status {
    unsafe {
        unsupported(
            c,
            "fmi2CancelStep",
            "DoStep is synchronous (canRunAsynchronuously = false): there is nothing to cancel",
        )
    }
}

// ---- Get / Set ----------------------------------------------------------------------------

#[no_mangle]
pub unsafe extern "C" fn fmi2GetReal(c: Component, vrs: *const Vr, n: usize, out: *mut f64) -> Fmi2Status {
    unsafe {
        call(c, "fmi2GetReal", GET, WhenPoisoned::Allow, |i| {
            values::get_planned(&i.model, &mut i.get_plans.float64, slice(vrs, n, "vr")?, slice_mut(out, n, "value")?)?;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetInteger(c: Component, vrs: *const Vr, n: usize, out: *mut c_int) -> Fmi2Status {
    unsafe {
        call(c, "fmi2GetInteger", GET, WhenPoisoned::Allow, |i| {
            values::get_planned(&i.model, &mut i.get_plans.int32, slice(vrs, n, "vr")?, slice_mut(out, n, "value")?)?;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetBoolean(c: Component, vrs: *const Vr, n: usize, out: *mut Fmi2Boolean) -> Fmi2Status {
    unsafe {
        call(c, "fmi2GetBoolean", GET, WhenPoisoned::Allow, |i| {
            values::get(&i.model, slice(vrs, n, "vr")?, slice_mut(out, n, "value")?, Kind::Boolean, |v, vr| {
                v.boolean(vr).map(c_int::from)
            })?;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetString(
    c: Component,
    _vrs: *const Vr,
    n: usize,
    _out: *mut *const c_char,
) -> Fmi2Status {
    unsafe {
        call(c, "fmi2GetString", GET, WhenPoisoned::Allow, |_| {
            values::no_variables_of("String", n).map(|()| Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetReal(c: Component, vrs: *const Vr, n: usize, vals: *const f64) -> Fmi2Status {
    unsafe {
        call(c, "fmi2SetReal", SET, WhenPoisoned::Refuse, |i| {
            values::set(&mut i.model, slice(vrs, n, "vr")?, slice(vals, n, "value")?, Value::Float64)?;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetInteger(c: Component, vrs: *const Vr, n: usize, vals: *const c_int) -> Fmi2Status {
    unsafe {
        call(c, "fmi2SetInteger", SET, WhenPoisoned::Refuse, |i| {
            values::set(&mut i.model, slice(vrs, n, "vr")?, slice(vals, n, "value")?, Value::Int32)?;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetBoolean(
    c: Component,
    vrs: *const Vr,
    n: usize,
    vals: *const Fmi2Boolean,
) -> Fmi2Status {
    unsafe {
        call(c, "fmi2SetBoolean", SET, WhenPoisoned::Refuse, |i| {
            values::set(&mut i.model, slice(vrs, n, "vr")?, slice(vals, n, "value")?, |b: c_int| {
                Value::Boolean(b != 0)
            })?;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetString(
    c: Component,
    _vrs: *const Vr,
    n: usize,
    _vals: *const *const c_char,
) -> Fmi2Status {
    unsafe {
        call(c, "fmi2SetString", SET, WhenPoisoned::Refuse, |_| {
            values::no_variables_of("String", n).map(|()| Status::Ok)
        })
    }
}

// ---- FMU state ----------------------------------------------------------------------------

#[no_mangle]
pub unsafe extern "C" fn fmi2GetFMUstate(c: Component, state: *mut *mut c_void) -> Fmi2Status {
    unsafe { call(c, "fmi2GetFMUstate", ANY_PHASE, WhenPoisoned::Refuse, |i| calls::get_fmu_state(i, state)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetFMUstate(c: Component, state: *mut c_void) -> Fmi2Status {
    unsafe { call(c, "fmi2SetFMUstate", ANY_PHASE, WhenPoisoned::Allow, |i| calls::set_fmu_state(i, state)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2FreeFMUstate(c: Component, state: *mut *mut c_void) -> Fmi2Status {
    unsafe { call(c, "fmi2FreeFMUstate", ANY_PHASE, WhenPoisoned::Allow, |_| calls::free_fmu_state(state)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SerializedFMUstateSize(c: Component, state: *mut c_void, size: *mut usize) -> Fmi2Status {
    unsafe {
        call(c, "fmi2SerializedFMUstateSize", ANY_PHASE, WhenPoisoned::Allow, |_| calls::serialized_size(state, size))
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SerializeFMUstate(
    c: Component,
    state: *mut c_void,
    out: *mut u8,
    size: usize,
) -> Fmi2Status {
    unsafe { call(c, "fmi2SerializeFMUstate", ANY_PHASE, WhenPoisoned::Allow, |_| calls::serialize(state, out, size)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2DeSerializeFMUstate(
    c: Component,
    bytes: *const u8,
    size: usize,
    state: *mut *mut c_void,
) -> Fmi2Status {
    unsafe {
        call(c, "fmi2DeSerializeFMUstate", ANY_PHASE, WhenPoisoned::Allow, |_| calls::deserialize(bytes, size, state))
    }
}

// ---- Status and derivatives ---------------------------------------------------------------

const STATUS: &[Phase] = &[SM, T];

#[no_mangle]
pub unsafe extern "C" fn fmi2GetStatus(c: Component, _kind: c_int, _value: *mut c_int) -> Fmi2Status {
    unsafe { call(c, "fmi2GetStatus", STATUS, WhenPoisoned::Allow, |_| Ok(Status::Discard)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealStatus(c: Component, kind: c_int, value: *mut f64) -> Fmi2Status {
    unsafe {
        call(c, "fmi2GetRealStatus", STATUS, WhenPoisoned::Allow, |i| {
            // fmi2LastSuccessfulTime = 2
            if kind != 2 || value.is_null() {
                return Ok(Status::Discard);
            }
            *value = i.model.time();
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetIntegerStatus(c: Component, _kind: c_int, _value: *mut c_int) -> Fmi2Status {
    unsafe { call(c, "fmi2GetIntegerStatus", STATUS, WhenPoisoned::Allow, |_| Ok(Status::Discard)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetBooleanStatus(c: Component, kind: c_int, value: *mut Fmi2Boolean) -> Fmi2Status {
    unsafe {
        call(c, "fmi2GetBooleanStatus", STATUS, WhenPoisoned::Allow, |_| {
            // fmi2Terminated = 3: the FMU never asks to end the simulation.
            if kind != 3 || value.is_null() {
                return Ok(Status::Discard);
            }
            *value = 0;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetStringStatus(c: Component, _kind: c_int, _value: *mut *const c_char) -> Fmi2Status {
    unsafe { call(c, "fmi2GetStringStatus", STATUS, WhenPoisoned::Allow, |_| Ok(Status::Discard)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetDirectionalDerivative(
    c: Component,
    _unknowns: *const Vr,
    _n_unknowns: usize,
    _knowns: *const Vr,
    _n_knowns: usize,
    _dv_known: *const f64,
    _dv_unknown: *mut f64,
) -> Fmi2Status {
    unsafe { unsupported(c, "fmi2GetDirectionalDerivative", "providesDirectionalDerivative = false") }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2SetRealInputDerivatives(
    c: Component,
    _vrs: *const Vr,
    _n: usize,
    _order: *const c_int,
    _vals: *const f64,
) -> Fmi2Status {
    unsafe { unsupported(c, "fmi2SetRealInputDerivatives", "canInterpolateInputs = false") }
}

#[no_mangle]
pub unsafe extern "C" fn fmi2GetRealOutputDerivatives(
    c: Component,
    _vrs: *const Vr,
    _n: usize,
    _order: *const c_int,
    _vals: *mut f64,
) -> Fmi2Status {
    unsafe { unsupported(c, "fmi2GetRealOutputDerivatives", "maxOutputDerivativeOrder = 0") }
}
