//! The FMI 3.0 Co-Simulation C API: every function of `fmi3Functions.h` is exported. The
//! ones this FMU has no use for (Model Exchange, Scheduled Execution, clocks, intervals,
//! derivatives) return `fmi3Error` with the reason logged; none aborts.

#![allow(non_snake_case, clippy::missing_safety_doc)]

use std::ffi::{c_char, c_int, c_void, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

use super::instance::{
    self, c_str, call, slice, slice_mut, unsupported, Instance, Logger, Phase, Status, WhenPoisoned, ANY_PHASE,
};
use super::{calls, values};
use crate::model_description;
use crate::variables::Value;

type Fmi3Instance = *mut c_void;
type Vr = u32;
type Fmi3Status = c_int;

use Phase::{InitializationMode as IM, Instantiated as I, StepMode as SM, Terminated as T};

const GET: &[Phase] = &[I, IM, SM, T];
const SET: &[Phase] = &[I, IM, SM];

#[no_mangle]
pub extern "C" fn fmi3GetVersion() -> *const c_char {
    c"3.0".as_ptr()
}

#[no_mangle]
pub unsafe extern "C" fn fmi3SetDebugLogging(
    instance: Fmi3Instance,
    logging_on: u8,
    n_categories: usize,
    categories: *const *const c_char,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3SetDebugLogging", ANY_PHASE, WhenPoisoned::Allow, |i| {
            i.set_debug_logging(logging_on != 0, n_categories, categories)
        })
    }
}

/// Report a failed instantiation through the callback the importer gave (there is no
/// instance to carry it).
unsafe fn refuse_instantiation(
    environment: *mut c_void,
    log: Option<instance::Fmi3LogMessage>,
    message: &str,
) -> Fmi3Instance {
    let text = CString::new(format!("servo_axis: {message}").replace('\0', " ")).unwrap_or_default();
    match log {
        Some(cb) => unsafe { cb(environment, Status::Error as c_int, c"logStatusError".as_ptr(), text.as_ptr()) },
        None => instance::stderr_line(&text.to_string_lossy()),
    }
    std::ptr::null_mut()
}

#[no_mangle]
pub unsafe extern "C" fn fmi3InstantiateCoSimulation(
    instance_name: *const c_char,
    instantiation_token: *const c_char,
    _resource_path: *const c_char,
    _visible: u8,
    logging_on: u8,
    event_mode_used: u8,
    _early_return_allowed: u8,
    _required_intermediate_variables: *const Vr,
    _n_required_intermediate_variables: usize,
    instance_environment: *mut c_void,
    log_message: Option<instance::Fmi3LogMessage>,
    _intermediate_update: *const c_void,
) -> Fmi3Instance {
    let made = catch_unwind(AssertUnwindSafe(|| -> Result<Fmi3Instance, String> {
        let name = unsafe { c_str(instance_name, "instanceName")? };
        if name.is_empty() {
            return Err("instanceName is empty".into());
        }
        let token = unsafe { c_str(instantiation_token, "instantiationToken")? };
        let ours = model_description::instantiation_token();
        if token != ours {
            return Err(format!(
                "instantiationToken {token} is not this FMU's ({ours}): the binary and modelDescription.xml differ"
            ));
        }
        if event_mode_used != 0 {
            return Err("eventModeUsed = true, but the FMU has no event mode (hasEventMode = false)".into());
        }
        let logger = Logger::Fmi3 { environment: instance_environment, callback: log_message };
        let inst = Box::new(Instance::new(CString::new(name).unwrap_or_default(), logger, logging_on != 0));
        Ok(Box::into_raw(inst) as Fmi3Instance)
    }));
    match made {
        Ok(Ok(p)) => p,
        Ok(Err(m)) => unsafe { refuse_instantiation(instance_environment, log_message, &m) },
        Err(p) => unsafe { refuse_instantiation(instance_environment, log_message, &instance::panic_message(p)) },
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3InstantiateModelExchange(
    _instance_name: *const c_char,
    _instantiation_token: *const c_char,
    _resource_path: *const c_char,
    _visible: u8,
    _logging_on: u8,
    instance_environment: *mut c_void,
    log_message: Option<instance::Fmi3LogMessage>,
) -> Fmi3Instance {
    unsafe {
        refuse_instantiation(instance_environment, log_message, "this FMU is Co-Simulation only (no Model Exchange)")
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3InstantiateScheduledExecution(
    _instance_name: *const c_char,
    _instantiation_token: *const c_char,
    _resource_path: *const c_char,
    _visible: u8,
    _logging_on: u8,
    instance_environment: *mut c_void,
    log_message: Option<instance::Fmi3LogMessage>,
    _clock_update: *const c_void,
    _lock_preemption: *const c_void,
    _unlock_preemption: *const c_void,
) -> Fmi3Instance {
    unsafe {
        refuse_instantiation(
            instance_environment,
            log_message,
            "this FMU is Co-Simulation only (no Scheduled Execution)",
        )
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3FreeInstance(instance: Fmi3Instance) {
    let _ = catch_unwind(AssertUnwindSafe(|| unsafe { instance::free(instance) }));
}

#[no_mangle]
pub unsafe extern "C" fn fmi3EnterInitializationMode(
    instance: Fmi3Instance,
    _tolerance_defined: u8,
    _tolerance: f64,
    start_time: f64,
    stop_time_defined: u8,
    stop_time: f64,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3EnterInitializationMode", &[I], WhenPoisoned::Refuse, |i| {
            calls::enter_initialization(i, start_time, (stop_time_defined != 0).then_some(stop_time))
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3ExitInitializationMode(instance: Fmi3Instance) -> Fmi3Status {
    unsafe { call(instance, "fmi3ExitInitializationMode", &[IM], WhenPoisoned::Refuse, calls::exit_initialization) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3EnterEventMode(instance: Fmi3Instance) -> Fmi3Status {
    unsafe { unsupported(instance, "fmi3EnterEventMode", "the FMU has no event mode (hasEventMode = false)") }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3Terminate(instance: Fmi3Instance) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3Terminate", &[SM], WhenPoisoned::Allow, |i| {
            i.phase = Phase::Terminated;
            Ok(Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3Reset(instance: Fmi3Instance) -> Fmi3Status {
    unsafe { call(instance, "fmi3Reset", ANY_PHASE, WhenPoisoned::Allow, calls::reset) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3DoStep(
    instance: Fmi3Instance,
    current_communication_point: f64,
    communication_step_size: f64,
    _no_set_fmu_state_prior_to_current_point: u8,
    event_handling_needed: *mut bool,
    terminate_simulation: *mut bool,
    early_return: *mut bool,
    last_successful_time: *mut f64,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3DoStep", &[SM], WhenPoisoned::Refuse, |i| {
            let status = calls::do_step(i, current_communication_point, communication_step_size);
            for (p, v) in [(event_handling_needed, false), (terminate_simulation, false), (early_return, false)] {
                if !p.is_null() {
                    *p = v;
                }
            }
            if !last_successful_time.is_null() {
                *last_successful_time = i.model.time();
            }
            status
        })
    }
}

// ---- Get / Set ----------------------------------------------------------------------------

/// Get writes `$t`; Set reads `$in` (a byte for Boolean: any non-zero byte from C is true,
/// never an invalid Rust `bool`).
macro_rules! get_set_typed {
    ($get:ident, $set:ident, $t:ty, $in:ty, $plan:ident, $wrap:expr) => {
        #[no_mangle]
        pub unsafe extern "C" fn $get(
            instance: Fmi3Instance,
            vrs: *const Vr,
            nvr: usize,
            out: *mut $t,
            n: usize,
        ) -> Fmi3Status {
            unsafe {
                call(instance, stringify!($get), GET, WhenPoisoned::Allow, |i| {
                    let vrs = slice(vrs, nvr, "valueReferences")?;
                    let out = slice_mut(out, n, "values")?;
                    values::get_planned(&i.model, &mut i.get_plans.$plan, vrs, out)?;
                    Ok(Status::Ok)
                })
            }
        }

        #[no_mangle]
        pub unsafe extern "C" fn $set(
            instance: Fmi3Instance,
            vrs: *const Vr,
            nvr: usize,
            vals: *const $in,
            n: usize,
        ) -> Fmi3Status {
            unsafe {
                call(instance, stringify!($set), SET, WhenPoisoned::Refuse, |i| {
                    let vrs = slice(vrs, nvr, "valueReferences")?;
                    let vals = slice(vals, n, "values")?;
                    values::set(&mut i.model, vrs, vals, $wrap)?;
                    Ok(Status::Ok)
                })
            }
        }
    };
}

get_set_typed!(fmi3GetFloat64, fmi3SetFloat64, f64, f64, float64, Value::Float64);
get_set_typed!(fmi3GetInt32, fmi3SetInt32, i32, i32, int32, Value::Int32);
get_set_typed!(fmi3GetBoolean, fmi3SetBoolean, bool, u8, boolean, |b: u8| Value::Boolean(b != 0));

/// Types the FMU has no variable of: zero references is fine, any reference is an error.
macro_rules! get_set_absent {
    ($get:ident, $set:ident, $t:ty, $name:literal) => {
        #[no_mangle]
        pub unsafe extern "C" fn $get(
            instance: Fmi3Instance,
            _vrs: *const Vr,
            nvr: usize,
            _out: *mut $t,
            _n: usize,
        ) -> Fmi3Status {
            unsafe {
                call(instance, stringify!($get), GET, WhenPoisoned::Allow, |_| {
                    values::no_variables_of($name, nvr).map(|()| Status::Ok)
                })
            }
        }

        #[no_mangle]
        pub unsafe extern "C" fn $set(
            instance: Fmi3Instance,
            _vrs: *const Vr,
            nvr: usize,
            _vals: *const $t,
            _n: usize,
        ) -> Fmi3Status {
            unsafe {
                call(instance, stringify!($set), SET, WhenPoisoned::Refuse, |_| {
                    values::no_variables_of($name, nvr).map(|()| Status::Ok)
                })
            }
        }
    };
}

get_set_absent!(fmi3GetFloat32, fmi3SetFloat32, f32, "Float32");
get_set_absent!(fmi3GetInt8, fmi3SetInt8, i8, "Int8");
get_set_absent!(fmi3GetUInt8, fmi3SetUInt8, u8, "UInt8");
get_set_absent!(fmi3GetInt16, fmi3SetInt16, i16, "Int16");
get_set_absent!(fmi3GetUInt16, fmi3SetUInt16, u16, "UInt16");
get_set_absent!(fmi3GetUInt32, fmi3SetUInt32, u32, "UInt32");
get_set_absent!(fmi3GetInt64, fmi3SetInt64, i64, "Int64");
get_set_absent!(fmi3GetUInt64, fmi3SetUInt64, u64, "UInt64");
get_set_absent!(fmi3GetString, fmi3SetString, *const c_char, "String");

#[no_mangle]
pub unsafe extern "C" fn fmi3GetBinary(
    instance: Fmi3Instance,
    _vrs: *const Vr,
    nvr: usize,
    _sizes: *mut usize,
    _out: *mut *const u8,
    _n: usize,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3GetBinary", GET, WhenPoisoned::Allow, |_| {
            values::no_variables_of("Binary", nvr).map(|()| Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3SetBinary(
    instance: Fmi3Instance,
    _vrs: *const Vr,
    nvr: usize,
    _sizes: *const usize,
    _vals: *const *const u8,
    _n: usize,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3SetBinary", SET, WhenPoisoned::Refuse, |_| {
            values::no_variables_of("Binary", nvr).map(|()| Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3GetClock(
    instance: Fmi3Instance,
    _vrs: *const Vr,
    nvr: usize,
    _out: *mut bool,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3GetClock", GET, WhenPoisoned::Allow, |_| {
            values::no_variables_of("Clock", nvr).map(|()| Status::Ok)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3SetClock(
    instance: Fmi3Instance,
    _vrs: *const Vr,
    nvr: usize,
    _vals: *const u8,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3SetClock", SET, WhenPoisoned::Refuse, |_| {
            values::no_variables_of("Clock", nvr).map(|()| Status::Ok)
        })
    }
}

// ---- Dependencies -------------------------------------------------------------------------

#[no_mangle]
pub unsafe extern "C" fn fmi3GetNumberOfVariableDependencies(
    instance: Fmi3Instance,
    _vr: Vr,
    _n: *mut usize,
) -> Fmi3Status {
    unsafe {
        unsupported(
            instance,
            "fmi3GetNumberOfVariableDependencies",
            "providesPerElementDependencies = false: the dependencies are in the model description's ModelStructure",
        )
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3GetVariableDependencies(
    instance: Fmi3Instance,
    _dependent: Vr,
    _element_indices_of_dependent: *mut usize,
    _independents: *mut Vr,
    _element_indices_of_independents: *mut usize,
    _dependency_kinds: *mut c_int,
    _n: usize,
) -> Fmi3Status {
    unsafe {
        unsupported(
            instance,
            "fmi3GetVariableDependencies",
            "providesPerElementDependencies = false: the dependencies are in the model description's ModelStructure",
        )
    }
}

// ---- FMU state ----------------------------------------------------------------------------

#[no_mangle]
pub unsafe extern "C" fn fmi3GetFMUState(instance: Fmi3Instance, state: *mut *mut c_void) -> Fmi3Status {
    unsafe { call(instance, "fmi3GetFMUState", ANY_PHASE, WhenPoisoned::Refuse, |i| calls::get_fmu_state(i, state)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3SetFMUState(instance: Fmi3Instance, state: *mut c_void) -> Fmi3Status {
    unsafe { call(instance, "fmi3SetFMUState", ANY_PHASE, WhenPoisoned::Allow, |i| calls::set_fmu_state(i, state)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3FreeFMUState(instance: Fmi3Instance, state: *mut *mut c_void) -> Fmi3Status {
    unsafe { call(instance, "fmi3FreeFMUState", ANY_PHASE, WhenPoisoned::Allow, |_| calls::free_fmu_state(state)) }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3SerializedFMUStateSize(
    instance: Fmi3Instance,
    state: *mut c_void,
    size: *mut usize,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3SerializedFMUStateSize", ANY_PHASE, WhenPoisoned::Allow, |_| {
            calls::serialized_size(state, size)
        })
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3SerializeFMUState(
    instance: Fmi3Instance,
    state: *mut c_void,
    out: *mut u8,
    size: usize,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3SerializeFMUState", ANY_PHASE, WhenPoisoned::Allow, |_| calls::serialize(state, out, size))
    }
}

#[no_mangle]
pub unsafe extern "C" fn fmi3DeserializeFMUState(
    instance: Fmi3Instance,
    bytes: *const u8,
    size: usize,
    state: *mut *mut c_void,
) -> Fmi3Status {
    unsafe {
        call(instance, "fmi3DeserializeFMUState", ANY_PHASE, WhenPoisoned::Allow, |_| {
            calls::deserialize(bytes, size, state)
        })
    }
}

// ---- Not supported: each returns fmi3Error with the reason logged --------------------------

macro_rules! unsupported_fn {
    ($name:ident ( $($arg:ident : $t:ty),* ), $reason:literal) => {
        #[no_mangle]
        pub unsafe extern "C" fn $name(instance: Fmi3Instance $(, $arg: $t)*) -> Fmi3Status {
            $( let _ = $arg; )*
            unsafe { unsupported(instance, stringify!($name), $reason) }
        }
    };
}

unsupported_fn!(fmi3GetDirectionalDerivative(unknowns: *const Vr, n_unknowns: usize, knowns: *const Vr, n_knowns: usize, seed: *const f64, n_seed: usize, sensitivity: *mut f64, n_sensitivity: usize),
    "providesDirectionalDerivatives = false (a sampled-data controller has no useful partial derivatives)");
unsupported_fn!(fmi3GetAdjointDerivative(unknowns: *const Vr, n_unknowns: usize, knowns: *const Vr, n_knowns: usize, seed: *const f64, n_seed: usize, sensitivity: *mut f64, n_sensitivity: usize),
    "providesAdjointDerivatives = false");
unsupported_fn!(fmi3EnterConfigurationMode(), "the FMU has no structural parameters");
unsupported_fn!(fmi3ExitConfigurationMode(), "the FMU has no structural parameters");
unsupported_fn!(fmi3GetIntervalDecimal(vrs: *const Vr, nvr: usize, intervals: *mut f64, qualifiers: *mut c_int), "the FMU has no clocks");
unsupported_fn!(fmi3GetIntervalFraction(vrs: *const Vr, nvr: usize, counters: *mut u64, resolutions: *mut u64, qualifiers: *mut c_int), "the FMU has no clocks");
unsupported_fn!(fmi3GetShiftDecimal(vrs: *const Vr, nvr: usize, shifts: *mut f64), "the FMU has no clocks");
unsupported_fn!(fmi3GetShiftFraction(vrs: *const Vr, nvr: usize, counters: *mut u64, resolutions: *mut u64), "the FMU has no clocks");
unsupported_fn!(fmi3SetIntervalDecimal(vrs: *const Vr, nvr: usize, intervals: *const f64), "the FMU has no clocks");
unsupported_fn!(fmi3SetIntervalFraction(vrs: *const Vr, nvr: usize, counters: *const u64, resolutions: *const u64), "the FMU has no clocks");
unsupported_fn!(fmi3SetShiftDecimal(vrs: *const Vr, nvr: usize, shifts: *const f64), "the FMU has no clocks");
unsupported_fn!(fmi3SetShiftFraction(vrs: *const Vr, nvr: usize, counters: *const u64, resolutions: *const u64), "the FMU has no clocks");
unsupported_fn!(fmi3EvaluateDiscreteStates(), "providesEvaluateDiscreteStates = false");
unsupported_fn!(fmi3UpdateDiscreteStates(discrete_states_need_update: *mut bool, terminate_simulation: *mut bool, nominals_changed: *mut bool, values_changed: *mut bool, next_event_time_defined: *mut bool, next_event_time: *mut f64),
    "the FMU has no event mode (hasEventMode = false)");
unsupported_fn!(fmi3EnterStepMode(), "the FMU has no event mode: ExitInitializationMode enters Step Mode");
unsupported_fn!(fmi3GetOutputDerivatives(vrs: *const Vr, nvr: usize, orders: *const i32, values: *mut f64, n: usize), "maxOutputDerivativeOrder = 0");
unsupported_fn!(fmi3ActivateModelPartition(clock_reference: Vr, activation_time: f64), "Co-Simulation only (no Scheduled Execution)");
unsupported_fn!(fmi3EnterContinuousTimeMode(), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3CompletedIntegratorStep(no_set_prior: u8, enter_event_mode: *mut bool, terminate_simulation: *mut bool), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3SetTime(time: f64), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3SetContinuousStates(x: *const f64, n: usize), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3GetContinuousStateDerivatives(dx: *mut f64, n: usize), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3GetEventIndicators(indicators: *mut f64, n: usize), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3GetContinuousStates(x: *mut f64, n: usize), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3GetNominalsOfContinuousStates(nominals: *mut f64, n: usize), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3GetNumberOfEventIndicators(n: *mut usize), "Co-Simulation only (no Model Exchange)");
unsupported_fn!(fmi3GetNumberOfContinuousStates(n: *mut usize), "Co-Simulation only (no Model Exchange)");
