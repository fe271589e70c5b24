//! The FMU's C API called directly (the library the archives carry): every exported FMI 3.0
//! and FMI 2.0 function in every state of the standard's state machine, NULL instance
//! included, gives a status back (no abort); the FMU state round trip is bit-identical,
//! across instances through serialisation; foreign and corrupt states are refused with the
//! reason; the logger gets the importer's instanceEnvironment; start time, reset, call order
//! and outputs behave as the standard says.

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::ptr::null_mut;
use std::sync::Mutex;

use libloading::Library;
use servo_axis::model_description::instantiation_token;
use servo_axis::variables::by_name;

type Inst = *mut c_void;
type P = *mut c_void;

fn library() -> Library {
    let p = host_tools::paths::shipped_linux_fmu_library();
    assert!(p.exists(), "{} is missing: run scripts/platforms (scripts/test runs it first)", p.display());
    unsafe { Library::new(&p) }.expect("the FMU library loads")
}

macro_rules! sym {
    ($lib:expr, $name:literal, $t:ty) => {{
        #[allow(unused_unsafe)]
        let f = *unsafe { $lib.get::<$t>(concat!($name, "\0").as_bytes()) }
            .unwrap_or_else(|e| panic!("{} not exported: {e}", $name));
        f
    }};
}

/// Messages the logger received: (instanceEnvironment, status, category, message).
static LOG: Mutex<Vec<(usize, c_int, String, String)>> = Mutex::new(Vec::new());

unsafe extern "C" fn logger(env: *mut c_void, status: c_int, category: *const c_char, message: *const c_char) {
    let s = |p: *const c_char| {
        if p.is_null() {
            String::new()
        } else {
            unsafe { CStr::from_ptr(p) }.to_string_lossy().into_owned()
        }
    };
    LOG.lock().unwrap().push((env as usize, status, s(category), s(message)));
}

/// The messages one test's instances received (each test has its own environment value:
/// tests run in parallel threads).
fn take_log(env: usize) -> Vec<(usize, c_int, String, String)> {
    let mut log = LOG.lock().unwrap();
    let (mine, others) = std::mem::take(&mut *log).into_iter().partition(|l| l.0 == env);
    *log = others;
    mine
}

type Instantiate3 = unsafe extern "C" fn(
    *const c_char,
    *const c_char,
    *const c_char,
    bool,
    bool,
    bool,
    bool,
    *const u32,
    usize,
    *mut c_void,
    Option<unsafe extern "C" fn(*mut c_void, c_int, *const c_char, *const c_char)>,
    P,
) -> Inst;
type F0 = unsafe extern "C" fn(Inst) -> c_int;
type EnterInit = unsafe extern "C" fn(Inst, bool, f64, f64, bool, f64) -> c_int;
type DoStep = unsafe extern "C" fn(Inst, f64, f64, bool, *mut bool, *mut bool, *mut bool, *mut f64) -> c_int;
type GetSet = unsafe extern "C" fn(Inst, *const u32, usize, P, usize) -> c_int;
type Free = unsafe extern "C" fn(Inst);

struct Fmi3<'a> {
    lib: &'a Library,
    /// The instanceEnvironment this test's instances carry.
    env: usize,
}

impl Fmi3<'_> {
    fn instantiate(&self, logging: bool) -> Inst {
        let f: Instantiate3 = sym!(self.lib, "fmi3InstantiateCoSimulation", Instantiate3);
        let token = CString::new(instantiation_token()).unwrap();
        let inst = unsafe {
            f(
                c"axis".as_ptr(),
                token.as_ptr(),
                std::ptr::null(),
                false,
                logging,
                false,
                false,
                std::ptr::null(),
                0,
                self.env as *mut c_void,
                Some(logger),
                null_mut(),
            )
        };
        assert!(!inst.is_null());
        inst
    }
    fn call0(&self, name: &str, inst: Inst) -> c_int {
        let f: F0 = *unsafe { self.lib.get::<F0>(format!("{name}\0").as_bytes()) }.unwrap();
        unsafe { f(inst) }
    }
    fn enter_init(&self, inst: Inst, start: f64) -> c_int {
        let f: EnterInit = sym!(self.lib, "fmi3EnterInitializationMode", EnterInit);
        unsafe { f(inst, false, 0.0, start, false, 0.0) }
    }
    fn step(&self, inst: Inst, t: f64, h: f64) -> c_int {
        let f: DoStep = sym!(self.lib, "fmi3DoStep", DoStep);
        let (mut a, mut b, mut c, mut last) = (false, false, false, 0.0);
        unsafe { f(inst, t, h, true, &mut a, &mut b, &mut c, &mut last) }
    }
    fn get_f64(&self, inst: Inst, vrs: &[u32]) -> (c_int, Vec<f64>) {
        let f: GetSet = sym!(self.lib, "fmi3GetFloat64", GetSet);
        let mut out = vec![0.0; vrs.len()];
        let s = unsafe { f(inst, vrs.as_ptr(), vrs.len(), out.as_mut_ptr() as P, out.len()) };
        (s, out)
    }
    fn set_f64(&self, inst: Inst, vr: u32, v: f64) -> c_int {
        let f: GetSet = sym!(self.lib, "fmi3SetFloat64", GetSet);
        unsafe { f(inst, &vr, 1, &v as *const f64 as P, 1) }
    }
    fn free(&self, inst: Inst) {
        let f: Free = sym!(self.lib, "fmi3FreeInstance", Free);
        unsafe { f(inst) }
    }
    /// A fresh instance in the given state (0 NULL, 1 Instantiated, 2 Initialization Mode,
    /// 3 Step Mode after a step, 4 Terminated).
    fn in_state(&self, state: usize) -> Inst {
        if state == 0 {
            return null_mut();
        }
        let i = self.instantiate(true);
        if state >= 2 {
            assert_eq!(self.enter_init(i, 0.0), 0);
        }
        if state >= 3 {
            assert_eq!(self.call0("fmi3ExitInitializationMode", i), 0);
            assert_eq!(self.step(i, 0.0, 0.00025), 0);
        }
        if state >= 4 {
            assert_eq!(self.call0("fmi3Terminate", i), 0);
        }
        i
    }
}

fn vr(name: &str) -> u32 {
    by_name(name).unwrap().vr
}

/// Every FMI 3.0 function with arguments a careful importer might pass (a valid value
/// reference of the right type where one is needed, room for the results).
fn call_fmi3(lib: &Library, name: &str, inst: Inst) -> c_int {
    let mut buf = [0u64; 64];
    let b = buf.as_mut_ptr() as P;
    let mut state: P = null_mut();
    let mut size = 0usize;
    let f64_vr = [vr("velocity_command")];
    let i32_vr = [vr("mode")];
    let bool_vr = [vr("fault_reset")];
    let mode = [2i32];
    unsafe {
        match name {
            "fmi3GetFloat64" | "fmi3SetFloat64" => sym!(lib, "fmi3GetFloat64", GetSet)(inst, f64_vr.as_ptr(), 1, b, 1)
                .max(if name == "fmi3SetFloat64" {
                    sym!(lib, "fmi3SetFloat64", GetSet)(inst, f64_vr.as_ptr(), 1, b, 1)
                } else {
                    0
                }),
            "fmi3GetInt32" => sym!(lib, "fmi3GetInt32", GetSet)(inst, i32_vr.as_ptr(), 1, b, 1),
            "fmi3SetInt32" => sym!(lib, "fmi3SetInt32", GetSet)(inst, i32_vr.as_ptr(), 1, mode.as_ptr() as P, 1),
            "fmi3GetBoolean" | "fmi3SetBoolean" => {
                let f = *lib.get::<GetSet>(format!("{name}\0").as_bytes()).unwrap();
                f(inst, bool_vr.as_ptr(), 1, b, 1)
            }
            n if (n.starts_with("fmi3Get") || n.starts_with("fmi3Set"))
                && ["Float32", "Int8", "UInt8", "Int16", "UInt16", "UInt32", "Int64", "UInt64", "String"]
                    .iter()
                    .any(|t| n.ends_with(t)) =>
            {
                let f = *lib.get::<GetSet>(format!("{name}\0").as_bytes()).unwrap();
                f(inst, f64_vr.as_ptr(), 1, b, 1)
            }
            "fmi3GetBinary" | "fmi3SetBinary" => {
                let f = *lib
                    .get::<unsafe extern "C" fn(Inst, *const u32, usize, P, P, usize) -> c_int>(
                        format!("{name}\0").as_bytes(),
                    )
                    .unwrap();
                f(inst, f64_vr.as_ptr(), 1, b, b, 1)
            }
            "fmi3GetClock" | "fmi3SetClock" => {
                let f = *lib
                    .get::<unsafe extern "C" fn(Inst, *const u32, usize, P) -> c_int>(format!("{name}\0").as_bytes())
                    .unwrap();
                f(inst, f64_vr.as_ptr(), 1, b)
            }
            "fmi3SetDebugLogging" => {
                let cats = [c"logEvents".as_ptr()];
                sym!(lib, "fmi3SetDebugLogging", unsafe extern "C" fn(Inst, bool, usize, *const *const c_char) -> c_int)(
                    inst,
                    true,
                    1,
                    cats.as_ptr(),
                )
            }
            "fmi3EnterInitializationMode" => {
                sym!(lib, "fmi3EnterInitializationMode", EnterInit)(inst, false, 0.0, 0.0, false, 0.0)
            }
            "fmi3DoStep" => {
                let (mut a, mut c, mut d, mut t) = (false, false, false, 0.0);
                sym!(lib, "fmi3DoStep", DoStep)(inst, 0.00025, 0.00025, false, &mut a, &mut c, &mut d, &mut t)
            }
            "fmi3GetFMUState" => {
                let s = sym!(lib, "fmi3GetFMUState", unsafe extern "C" fn(Inst, *mut P) -> c_int)(inst, &mut state);
                if !state.is_null() {
                    sym!(lib, "fmi3FreeFMUState", unsafe extern "C" fn(Inst, *mut P) -> c_int)(inst, &mut state);
                }
                s
            }
            "fmi3SetFMUState" => sym!(lib, "fmi3SetFMUState", unsafe extern "C" fn(Inst, P) -> c_int)(inst, null_mut()),
            "fmi3FreeFMUState" => {
                sym!(lib, "fmi3FreeFMUState", unsafe extern "C" fn(Inst, *mut P) -> c_int)(inst, &mut state)
            }
            "fmi3SerializedFMUStateSize" => sym!(
                lib,
                "fmi3SerializedFMUStateSize",
                unsafe extern "C" fn(Inst, P, *mut usize) -> c_int
            )(inst, null_mut(), &mut size),
            "fmi3SerializeFMUState" => sym!(
                lib,
                "fmi3SerializeFMUState",
                unsafe extern "C" fn(Inst, P, P, usize) -> c_int
            )(inst, null_mut(), b, 8),
            "fmi3DeserializeFMUState" => {
                sym!(lib, "fmi3DeserializeFMUState", unsafe extern "C" fn(Inst, P, usize, *mut P) -> c_int)(
                    inst, b, 64, &mut state,
                )
            }
            "fmi3GetNumberOfVariableDependencies" => sym!(
                lib,
                "fmi3GetNumberOfVariableDependencies",
                unsafe extern "C" fn(Inst, u32, *mut usize) -> c_int
            )(inst, vr("iq"), &mut size),
            "fmi3GetVariableDependencies" => sym!(
                lib,
                "fmi3GetVariableDependencies",
                unsafe extern "C" fn(Inst, u32, P, P, P, P, usize) -> c_int
            )(inst, vr("iq"), b, b, b, b, 0),
            "fmi3GetDirectionalDerivative" | "fmi3GetAdjointDerivative" => {
                let f = *lib.get::<unsafe extern "C" fn(Inst, *const u32, usize, *const u32, usize, P, usize, P, usize) -> c_int>(format!("{name}\0").as_bytes()).unwrap();
                f(inst, f64_vr.as_ptr(), 1, f64_vr.as_ptr(), 1, b, 1, b, 1)
            }
            "fmi3GetIntervalDecimal"
            | "fmi3GetIntervalFraction"
            | "fmi3GetShiftFraction"
            | "fmi3SetIntervalFraction"
            | "fmi3SetShiftFraction" => {
                let f = *lib
                    .get::<unsafe extern "C" fn(Inst, *const u32, usize, P, P, P) -> c_int>(
                        format!("{name}\0").as_bytes(),
                    )
                    .unwrap();
                f(inst, f64_vr.as_ptr(), 1, b, b, b)
            }
            "fmi3GetShiftDecimal" | "fmi3SetIntervalDecimal" | "fmi3SetShiftDecimal" => {
                let f = *lib
                    .get::<unsafe extern "C" fn(Inst, *const u32, usize, P) -> c_int>(format!("{name}\0").as_bytes())
                    .unwrap();
                f(inst, f64_vr.as_ptr(), 1, b)
            }
            "fmi3UpdateDiscreteStates" => {
                sym!(lib, "fmi3UpdateDiscreteStates", unsafe extern "C" fn(Inst, P, P, P, P, P, P) -> c_int)(
                    inst, b, b, b, b, b, b,
                )
            }
            "fmi3GetOutputDerivatives" => sym!(
                lib,
                "fmi3GetOutputDerivatives",
                unsafe extern "C" fn(Inst, *const u32, usize, P, P, usize) -> c_int
            )(inst, f64_vr.as_ptr(), 1, b, b, 1),
            "fmi3ActivateModelPartition" => {
                sym!(lib, "fmi3ActivateModelPartition", unsafe extern "C" fn(Inst, u32, f64) -> c_int)(inst, 0, 0.0)
            }
            "fmi3CompletedIntegratorStep" => {
                sym!(lib, "fmi3CompletedIntegratorStep", unsafe extern "C" fn(Inst, bool, P, P) -> c_int)(
                    inst, true, b, b,
                )
            }
            "fmi3SetTime" => sym!(lib, "fmi3SetTime", unsafe extern "C" fn(Inst, f64) -> c_int)(inst, 0.0),
            "fmi3SetContinuousStates"
            | "fmi3GetContinuousStateDerivatives"
            | "fmi3GetEventIndicators"
            | "fmi3GetContinuousStates"
            | "fmi3GetNominalsOfContinuousStates" => {
                let f =
                    *lib.get::<unsafe extern "C" fn(Inst, P, usize) -> c_int>(format!("{name}\0").as_bytes()).unwrap();
                f(inst, b, 0)
            }
            "fmi3GetNumberOfEventIndicators" | "fmi3GetNumberOfContinuousStates" => {
                let f = *lib
                    .get::<unsafe extern "C" fn(Inst, *mut usize) -> c_int>(format!("{name}\0").as_bytes())
                    .unwrap();
                f(inst, &mut size)
            }
            _ => {
                let f = *lib
                    .get::<F0>(format!("{name}\0").as_bytes())
                    .unwrap_or_else(|e| panic!("{name} not exported: {e}"));
                f(inst)
            }
        }
    }
}

/// The functions of fmi3Functions.h that take an instance and return a status.
const FMI3_WITH_INSTANCE: &[&str] = &[
    "fmi3SetDebugLogging",
    "fmi3EnterInitializationMode",
    "fmi3ExitInitializationMode",
    "fmi3EnterEventMode",
    "fmi3Terminate",
    "fmi3Reset",
    "fmi3GetFloat32",
    "fmi3GetFloat64",
    "fmi3GetInt8",
    "fmi3GetUInt8",
    "fmi3GetInt16",
    "fmi3GetUInt16",
    "fmi3GetInt32",
    "fmi3GetUInt32",
    "fmi3GetInt64",
    "fmi3GetUInt64",
    "fmi3GetBoolean",
    "fmi3GetString",
    "fmi3GetBinary",
    "fmi3GetClock",
    "fmi3SetFloat32",
    "fmi3SetFloat64",
    "fmi3SetInt8",
    "fmi3SetUInt8",
    "fmi3SetInt16",
    "fmi3SetUInt16",
    "fmi3SetInt32",
    "fmi3SetUInt32",
    "fmi3SetInt64",
    "fmi3SetUInt64",
    "fmi3SetBoolean",
    "fmi3SetString",
    "fmi3SetBinary",
    "fmi3SetClock",
    "fmi3GetNumberOfVariableDependencies",
    "fmi3GetVariableDependencies",
    "fmi3GetFMUState",
    "fmi3SetFMUState",
    "fmi3FreeFMUState",
    "fmi3SerializedFMUStateSize",
    "fmi3SerializeFMUState",
    "fmi3DeserializeFMUState",
    "fmi3GetDirectionalDerivative",
    "fmi3GetAdjointDerivative",
    "fmi3EnterConfigurationMode",
    "fmi3ExitConfigurationMode",
    "fmi3GetIntervalDecimal",
    "fmi3GetIntervalFraction",
    "fmi3GetShiftDecimal",
    "fmi3GetShiftFraction",
    "fmi3SetIntervalDecimal",
    "fmi3SetIntervalFraction",
    "fmi3SetShiftDecimal",
    "fmi3SetShiftFraction",
    "fmi3EvaluateDiscreteStates",
    "fmi3UpdateDiscreteStates",
    "fmi3EnterContinuousTimeMode",
    "fmi3CompletedIntegratorStep",
    "fmi3SetTime",
    "fmi3SetContinuousStates",
    "fmi3GetContinuousStateDerivatives",
    "fmi3GetEventIndicators",
    "fmi3GetContinuousStates",
    "fmi3GetNominalsOfContinuousStates",
    "fmi3GetNumberOfEventIndicators",
    "fmi3GetNumberOfContinuousStates",
    "fmi3EnterStepMode",
    "fmi3GetOutputDerivatives",
    "fmi3DoStep",
    "fmi3ActivateModelPartition",
];

#[test]
fn every_fmi3_function_returns_a_status_in_every_state_and_with_a_null_instance() {
    let lib = library();
    let fmi = Fmi3 { lib: &lib, env: 0x5eed_0001 };
    for name in [
        "fmi3GetVersion",
        "fmi3InstantiateModelExchange",
        "fmi3InstantiateCoSimulation",
        "fmi3InstantiateScheduledExecution",
        "fmi3FreeInstance",
    ] {
        assert!(unsafe { lib.get::<F0>(format!("{name}\0").as_bytes()) }.is_ok(), "{name} not exported");
    }
    assert_eq!(FMI3_WITH_INSTANCE.len() + 5, 75, "fmi3Functions.h declares 75 functions");
    let mut statuses = std::collections::BTreeMap::new();
    for state in 0..5 {
        for name in FMI3_WITH_INSTANCE {
            let inst = fmi.in_state(state);
            let status = call_fmi3(&lib, name, inst);
            assert!((0..=4).contains(&status), "{name} in state {state}: status {status}");
            if state == 0 {
                assert_eq!(status, 3, "{name} with a NULL instance must be fmi3Error");
            }
            *statuses.entry(status).or_insert(0) += 1;
            if !inst.is_null() {
                fmi.free(inst);
            }
        }
    }
    fmi.free(null_mut()); // a no-op
                          // Unsupported and wrong-state calls explain themselves through the logger.
    let log = take_log(fmi.env);
    assert!(!log.is_empty());
    assert!(
        LOG.lock().unwrap().iter().all(|l| l.0 & !0xf == 0x5eed_0000),
        "every callback gets its instance's instanceEnvironment"
    );
    assert!(log.iter().any(|(_, s, _, m)| *s == 3 && m.contains("not supported")), "no 'not supported' reason logged");
    assert!(log.iter().any(|(_, s, _, m)| *s == 3 && m.contains("not allowed in")), "no wrong-state reason logged");
    println!("statuses over {} calls: {statuses:?}", FMI3_WITH_INSTANCE.len() * 5);
}

#[test]
fn the_standards_call_order_is_enforced_and_refusals_leave_the_instance_intact() {
    let lib = library();
    let fmi = Fmi3 { lib: &lib, env: 0x5eed_0002 };
    let i = fmi.instantiate(false);
    take_log(fmi.env);
    assert_eq!(fmi.call0("fmi3ExitInitializationMode", i), 3, "exit without enter");
    assert_eq!(fmi.step(i, 0.0, 0.00025), 3, "a step before initialisation");
    assert_eq!(fmi.set_f64(i, vr("iq"), 1.0), 3, "an output is not settable");
    assert_eq!(fmi.get_f64(i, &[vr("iq")]).1, vec![0.0]);
    // Parameters set before Reset go back to their start values.
    let kp = vr("ctrl.velocity_kp");
    let start = fmi.get_f64(i, &[kp]).1[0];
    assert_eq!(fmi.set_f64(i, kp, 0.5), 0);
    assert_eq!(fmi.call0("fmi3Reset", i), 0);
    assert_eq!(fmi.get_f64(i, &[kp]).1[0], start);
    // Errors reach the logger even with logging off, with the importer's environment.
    let log = take_log(fmi.env);
    assert!(
        log.iter().any(|(_, s, c, m)| *s == 3 && c == "logStatusError" && m.contains("fmi3ExitInitializationMode")),
        "{log:?}"
    );
    // startTime is honoured.
    assert_eq!(fmi.enter_init(i, 0.1), 0);
    assert_eq!(fmi.call0("fmi3ExitInitializationMode", i), 0);
    assert_eq!(fmi.set_f64(i, kp, 0.5), 3, "a fixed parameter after initialisation");
    assert_eq!(fmi.step(i, 0.0, 0.00025), 3, "the first step starts at the start time");
    assert_eq!(fmi.step(i, 0.1, 0.00025), 0);
    assert_eq!(fmi.get_f64(i, &[0]).1[0], 0.1 + 0.00025);
    fmi.free(i);
}

fn run_steps(fmi: &Fmi3, i: Inst, from: usize, n: usize, outputs: &[u32]) -> Vec<u64> {
    let mut bits = Vec::new();
    for k in from..from + n {
        if k == 40 {
            assert_eq!(fmi.set_f64(i, vr("position_command"), 1.0), 0);
        }
        assert_eq!(fmi.step(i, k as f64 * 0.00025, 0.00025), 0);
        bits.extend(fmi.get_f64(i, outputs).1.iter().map(|x| x.to_bits()));
    }
    bits
}

#[test]
fn a_restored_or_deserialized_state_continues_bit_for_bit_and_foreign_states_are_refused() {
    let lib = library();
    let fmi = Fmi3 { lib: &lib, env: 0x5eed_0003 };
    let get_state = sym!(lib, "fmi3GetFMUState", unsafe extern "C" fn(Inst, *mut P) -> c_int);
    let set_state = sym!(lib, "fmi3SetFMUState", unsafe extern "C" fn(Inst, P) -> c_int);
    let free_state = sym!(lib, "fmi3FreeFMUState", unsafe extern "C" fn(Inst, *mut P) -> c_int);
    let size_of = sym!(lib, "fmi3SerializedFMUStateSize", unsafe extern "C" fn(Inst, P, *mut usize) -> c_int);
    let serialize = sym!(lib, "fmi3SerializeFMUState", unsafe extern "C" fn(Inst, P, *mut u8, usize) -> c_int);
    let deserialize =
        sym!(lib, "fmi3DeserializeFMUState", unsafe extern "C" fn(Inst, *const u8, usize, *mut P) -> c_int);
    let outputs: Vec<u32> = servo_axis::variables::DECLARATIONS
        .iter()
        .filter(|d| {
            d.causality == servo_axis::variables::Causality::Output && d.kind == servo_axis::variables::Kind::Float64
        })
        .map(|d| d.vr)
        .collect();

    let i = fmi.in_state(2);
    assert_eq!(fmi.call0("fmi3ExitInitializationMode", i), 0);
    let uninterrupted = {
        let j = fmi.in_state(2);
        assert_eq!(fmi.call0("fmi3ExitInitializationMode", j), 0);
        let bits = run_steps(&fmi, j, 0, 400, &outputs);
        fmi.free(j);
        bits
    };
    let before = run_steps(&fmi, i, 0, 30, &outputs);
    let mut state: P = null_mut();
    assert_eq!(unsafe { get_state(i, &mut state) }, 0);
    let after = run_steps(&fmi, i, 30, 370, &outputs);
    assert_eq!([before.clone(), after.clone()].concat(), uninterrupted, "saving a state does not disturb the run");
    assert_eq!(unsafe { set_state(i, state) }, 0);
    assert_eq!(run_steps(&fmi, i, 30, 370, &outputs), after, "restored: the same bits");

    // Serialized, into a new instance.
    let mut n = 0usize;
    assert_eq!(unsafe { size_of(i, state, &mut n) }, 0);
    let mut bytes = vec![0u8; n];
    assert_eq!(unsafe { serialize(i, state, bytes.as_mut_ptr(), n) }, 0);
    let k = fmi.instantiate(false);
    let mut restored: P = null_mut();
    assert_eq!(unsafe { deserialize(k, bytes.as_ptr(), n, &mut restored) }, 0);
    assert_eq!(unsafe { set_state(k, restored) }, 0);
    assert_eq!(run_steps(&fmi, k, 30, 370, &outputs), after, "deserialized in another instance: the same bits");

    // Corrupt, truncated and foreign buffers are refused with the reason.
    take_log(fmi.env);
    let mut corrupt = bytes.clone();
    corrupt[n / 2] ^= 0x40;
    let mut other: P = null_mut();
    assert_eq!(unsafe { deserialize(k, corrupt.as_ptr(), n, &mut other) }, 3);
    assert_eq!(unsafe { deserialize(k, bytes.as_ptr(), n - 1, &mut other) }, 3);
    let mut foreign = bytes.clone();
    foreign[9] ^= 1; // the build fingerprint
    assert_eq!(unsafe { deserialize(k, foreign.as_ptr(), n, &mut other) }, 3);
    assert!(other.is_null());
    let log: Vec<String> = take_log(fmi.env).into_iter().map(|l| l.3).collect();
    assert!(log.iter().any(|m| m.contains("corrupt")), "{log:?}");
    assert!(log.iter().any(|m| m.contains("another build")), "{log:?}");
    for s in [&mut state, &mut restored] {
        assert_eq!(unsafe { free_state(i, s) }, 0);
        assert!(s.is_null());
    }
    fmi.free(i);
    fmi.free(k);
}

/// FMI 2.0: the functions a Co-Simulation FMU exports, and one run through them equal, bit
/// for bit, to the same run through FMI 3.0.
#[test]
fn fmi2_gives_the_fmi3_bits_and_every_function_is_exported() {
    let lib = library();
    for name in [
        "fmi2GetTypesPlatform",
        "fmi2GetVersion",
        "fmi2SetDebugLogging",
        "fmi2Instantiate",
        "fmi2FreeInstance",
        "fmi2SetupExperiment",
        "fmi2EnterInitializationMode",
        "fmi2ExitInitializationMode",
        "fmi2Terminate",
        "fmi2Reset",
        "fmi2GetReal",
        "fmi2GetInteger",
        "fmi2GetBoolean",
        "fmi2GetString",
        "fmi2SetReal",
        "fmi2SetInteger",
        "fmi2SetBoolean",
        "fmi2SetString",
        "fmi2GetFMUstate",
        "fmi2SetFMUstate",
        "fmi2FreeFMUstate",
        "fmi2SerializedFMUstateSize",
        "fmi2SerializeFMUstate",
        "fmi2DeSerializeFMUstate",
        "fmi2GetDirectionalDerivative",
        "fmi2SetRealInputDerivatives",
        "fmi2GetRealOutputDerivatives",
        "fmi2DoStep",
        "fmi2CancelStep",
        "fmi2GetStatus",
        "fmi2GetRealStatus",
        "fmi2GetIntegerStatus",
        "fmi2GetBooleanStatus",
        "fmi2GetStringStatus",
    ] {
        assert!(unsafe { lib.get::<F0>(format!("{name}\0").as_bytes()) }.is_ok(), "{name} not exported");
    }
    #[repr(C)]
    struct Callbacks {
        logger: P,
        allocate: P,
        free: P,
        step_finished: P,
        env: P,
    }
    let callbacks = Callbacks {
        logger: null_mut(),
        allocate: null_mut(),
        free: null_mut(),
        step_finished: null_mut(),
        env: null_mut(),
    };
    let instantiate = sym!(
        lib,
        "fmi2Instantiate",
        unsafe extern "C" fn(
            *const c_char,
            c_int,
            *const c_char,
            *const c_char,
            *const Callbacks,
            c_int,
            c_int,
        ) -> Inst
    );
    let setup = sym!(lib, "fmi2SetupExperiment", unsafe extern "C" fn(Inst, c_int, f64, f64, c_int, f64) -> c_int);
    let do_step = sym!(lib, "fmi2DoStep", unsafe extern "C" fn(Inst, f64, f64, c_int) -> c_int);
    let get_real = sym!(lib, "fmi2GetReal", unsafe extern "C" fn(Inst, *const u32, usize, *mut f64) -> c_int);
    let set_real = sym!(lib, "fmi2SetReal", unsafe extern "C" fn(Inst, *const u32, usize, *const f64) -> c_int);
    let call = |name: &str, i: Inst| unsafe { (*lib.get::<F0>(format!("{name}\0").as_bytes()).unwrap())(i) };
    let token = CString::new(instantiation_token()).unwrap();
    let wrong = unsafe { instantiate(c"axis".as_ptr(), 1, c"{not-ours}".as_ptr(), std::ptr::null(), &callbacks, 0, 0) };
    assert!(wrong.is_null(), "a foreign GUID is refused");
    let i = unsafe { instantiate(c"axis".as_ptr(), 1, token.as_ptr(), std::ptr::null(), &callbacks, 0, 0) };
    assert!(!i.is_null());
    assert_eq!(call("fmi2ExitInitializationMode", i), 3, "exit without enter");
    assert_eq!(unsafe { setup(i, 0, 0.0, 0.0, 0, 0.0) }, 0);
    assert_eq!(call("fmi2EnterInitializationMode", i), 0);
    assert_eq!(call("fmi2ExitInitializationMode", i), 0);
    let outputs = [vr("motor_position"), vr("iq"), vr("load_acceleration")];
    let mut bits2 = Vec::new();
    for k in 0..400 {
        if k == 40 {
            assert_eq!(unsafe { set_real(i, &vr("position_command"), 1, &1.0) }, 0);
        }
        assert_eq!(unsafe { do_step(i, k as f64 * 0.00025, 0.00025, 1) }, 0);
        let mut out = [0.0; 3];
        assert_eq!(unsafe { get_real(i, outputs.as_ptr(), 3, out.as_mut_ptr()) }, 0);
        bits2.extend(out.map(f64::to_bits));
    }
    unsafe { (*lib.get::<Free>(b"fmi2FreeInstance\0").unwrap())(i) };
    let fmi = Fmi3 { lib: &lib, env: 0x5eed_0004 };
    let j = fmi.in_state(2);
    assert_eq!(fmi.call0("fmi3ExitInitializationMode", j), 0);
    assert_eq!(run_steps(&fmi, j, 0, 400, &outputs), bits2);
    fmi.free(j);
}
