//! Get through the C API with its plans (`values::GetPlan`): the values are those of the
//! variables asked for, whatever was asked before, and a value reference that is unknown or of
//! another type is refused with an error status, the plan or no plan.

use std::ffi::{c_int, c_void, CString};

use super::fmi2::{fmi2GetInteger, fmi2GetReal};
use super::fmi3::*;
use super::instance::{self, Status};
use crate::model_description::instantiation_token;
use crate::variables::{by_name, Causality, Kind, Value, DECLARATIONS};

const OK: c_int = Status::Ok as c_int;
const ERROR: c_int = Status::Error as c_int;

fn vr(name: &str) -> u32 {
    by_name(name).unwrap_or_else(|| panic!("no variable {name}")).vr
}

fn vrs_of(kind: Kind, causality: Option<Causality>) -> Vec<u32> {
    DECLARATIONS.iter().filter(|d| d.kind == kind && causality.is_none_or(|c| d.causality == c)).map(|d| d.vr).collect()
}

/// An instance in Step Mode after a few steps (the plant's own mounting, no commissioning
/// at initialisation), turning: its outputs are not their start values.
fn stepped() -> *mut c_void {
    let token = CString::new(instantiation_token()).unwrap();
    unsafe {
        let i = fmi3InstantiateCoSimulation(
            c"plans".as_ptr(),
            token.as_ptr(),
            std::ptr::null(),
            0,
            0,
            0,
            0,
            std::ptr::null(),
            0,
            std::ptr::null_mut(),
            None,
            std::ptr::null(),
        );
        assert!(!i.is_null());
        assert_eq!(fmi3SetBoolean(i, &vr("commissioning.at_start"), 1, &0u8, 1), OK);
        assert_eq!(fmi3EnterInitializationMode(i, 0, 0.0, 0.0, 0, 0.0), OK);
        assert_eq!(fmi3SetInt32(i, &vr("mode"), 1, &1, 1), OK);
        assert_eq!(fmi3SetFloat64(i, &vr("velocity_command"), 1, &20.0, 1), OK);
        assert_eq!(fmi3ExitInitializationMode(i), OK);
        let (mut a, mut b, mut c, mut last) = (false, false, false, 0.0);
        for k in 0..8 {
            assert_eq!(fmi3DoStep(i, k as f64 * 0.00025, 0.00025, 1, &mut a, &mut b, &mut c, &mut last), OK);
        }
        i
    }
}

/// The model's own value of `vr`, as the Get of its type gives it.
fn value(i: *mut c_void, vr: u32) -> Value {
    unsafe { instance::instance(i) }.unwrap().model.get(vr).unwrap()
}

fn get_f64(i: *mut c_void, vrs: &[u32]) -> (c_int, Vec<f64>) {
    let mut out = vec![f64::NAN; vrs.len()];
    (unsafe { fmi3GetFloat64(i, vrs.as_ptr(), vrs.len(), out.as_mut_ptr(), out.len()) }, out)
}

fn get_i32(i: *mut c_void, vrs: &[u32]) -> (c_int, Vec<i32>) {
    let mut out = vec![-7; vrs.len()];
    (unsafe { fmi3GetInt32(i, vrs.as_ptr(), vrs.len(), out.as_mut_ptr(), out.len()) }, out)
}

fn get_bool(i: *mut c_void, vrs: &[u32]) -> (c_int, Vec<bool>) {
    let mut out = vec![false; vrs.len()];
    (unsafe { fmi3GetBoolean(i, vrs.as_ptr(), vrs.len(), out.as_mut_ptr(), out.len()) }, out)
}

fn assert_f64(i: *mut c_void, vrs: &[u32]) {
    let (status, out) = get_f64(i, vrs);
    assert_eq!(status, OK, "{vrs:?}");
    for (&vr, &x) in vrs.iter().zip(&out) {
        assert_eq!(Value::Float64(x), value(i, vr), "value reference {vr}");
    }
}

#[test]
fn a_planned_get_gives_the_values_asked_for_whatever_was_asked_before() {
    let i = stepped();
    let outputs = vrs_of(Kind::Float64, Some(Causality::Output));
    assert!(outputs.len() >= 16);
    assert!(value(i, vr("motor_velocity")) != Value::Float64(0.0), "the axis turns");
    // The same references twice (the second by the plan), then others of the same length:
    // one changed, two swapped, one repeated; then a parameter among them, and fewer.
    assert_f64(i, &outputs);
    assert_f64(i, &outputs);
    let mut other = outputs.clone();
    other[3] = vr("time");
    assert_f64(i, &other);
    other.swap(0, 9);
    assert_f64(i, &other);
    other[5] = other[6];
    assert_f64(i, &other);
    other[1] = vr("ctrl.current_kp");
    assert_f64(i, &other);
    assert_f64(i, &outputs[2..]);
    assert_f64(i, &outputs[..3]);
    assert_f64(i, &[]);
    assert_f64(i, &outputs);
    // Every Float64 variable, in reverse order.
    let mut all = vrs_of(Kind::Float64, None);
    all.reverse();
    assert_f64(i, &all);
    // After a step the plan reads the new values.
    let (mut a, mut b, mut c, mut last) = (false, false, false, 0.0);
    assert_eq!(unsafe { fmi3DoStep(i, 0.002, 0.00025, 1, &mut a, &mut b, &mut c, &mut last) }, OK);
    assert_f64(i, &all);
    // Int32 and Boolean likewise (a Boolean list repeated to be long enough for a plan).
    let ints = vrs_of(Kind::Int32, None);
    for vrs in [&ints[..], &ints[1..], &ints[..2]] {
        let (status, out) = get_i32(i, vrs);
        assert_eq!(status, OK);
        for (&vr, &x) in vrs.iter().zip(&out) {
            assert_eq!(Value::Int32(x), value(i, vr), "value reference {vr}");
        }
    }
    let bools: Vec<u32> = vrs_of(Kind::Boolean, None).repeat(8);
    let (status, out) = get_bool(i, &bools);
    assert_eq!(status, OK);
    for (&vr, &x) in bools.iter().zip(&out) {
        assert_eq!(Value::Boolean(x), value(i, vr), "value reference {vr}");
    }
    unsafe { fmi3FreeInstance(i) };
}

#[test]
fn a_reference_unknown_or_of_another_type_is_refused_with_or_without_a_plan() {
    let i = stepped();
    let outputs = vrs_of(Kind::Float64, Some(Causality::Output));
    assert_f64(i, &outputs);
    let unknown = DECLARATIONS.len() as u32;
    for (at, bad) in [(0, vr("faults")), (7, unknown), (outputs.len() - 1, vr("commissioning.at_start")), (4, u32::MAX)]
    {
        // In a list as long as the planned one (and the same but for one reference), and in a
        // short one (read one by one).
        let mut vrs = outputs.clone();
        vrs[at] = bad;
        assert_eq!(get_f64(i, &vrs).0, ERROR, "{bad} at {at}");
        assert_eq!(get_f64(i, &[vr("time"), bad]).0, ERROR, "{bad}");
        // The refused list left no plan behind: the list before reads as before, and an
        // empty list reads nothing.
        assert_f64(i, &outputs);
        assert_f64(i, &[]);
    }
    // More references than values, or the other way round.
    let mut out = vec![0.0; outputs.len()];
    assert_eq!(unsafe { fmi3GetFloat64(i, outputs.as_ptr(), outputs.len(), out.as_mut_ptr(), out.len() - 1) }, ERROR);
    assert_eq!(unsafe { fmi3GetFloat64(i, outputs.as_ptr(), outputs.len() - 1, out.as_mut_ptr(), out.len()) }, ERROR);
    // Int32 and Boolean: a Float64 reference among them.
    let mut ints = vrs_of(Kind::Int32, Some(Causality::Output));
    assert_eq!(get_i32(i, &ints).0, OK);
    ints[2] = vr("iq");
    assert_eq!(get_i32(i, &ints).0, ERROR);
    let mut bools = vrs_of(Kind::Boolean, None).repeat(8);
    bools[9] = vr("mode");
    assert_eq!(get_bool(i, &bools).0, ERROR);
    // A NULL array announced with references.
    assert_eq!(unsafe { fmi3GetFloat64(i, std::ptr::null(), 3, out.as_mut_ptr(), 3) }, ERROR);
    unsafe { fmi3FreeInstance(i) };
}

#[test]
fn fmi2_real_and_integer_gets_go_by_the_same_plans() {
    // The FMI 2.0 getters on the FMI 3.0 instance's model: same bits, same refusals.
    let i = stepped();
    let reals = vrs_of(Kind::Float64, Some(Causality::Output));
    let ints = vrs_of(Kind::Int32, Some(Causality::Output));
    for _ in 0..2 {
        let mut out = vec![0.0; reals.len()];
        assert_eq!(unsafe { fmi2GetReal(i, reals.as_ptr(), reals.len(), out.as_mut_ptr()) }, OK);
        for (&vr, &x) in reals.iter().zip(&out) {
            assert_eq!(Value::Float64(x), value(i, vr));
        }
        let mut out = vec![0; ints.len()];
        assert_eq!(unsafe { fmi2GetInteger(i, ints.as_ptr(), ints.len(), out.as_mut_ptr()) }, OK);
        for (&vr, &x) in ints.iter().zip(&out) {
            assert_eq!(Value::Int32(x), value(i, vr));
        }
    }
    let mut wrong = reals.clone();
    wrong[1] = ints[0];
    let mut out = vec![0.0; wrong.len()];
    assert_eq!(unsafe { fmi2GetReal(i, wrong.as_ptr(), wrong.len(), out.as_mut_ptr()) }, ERROR);
    unsafe { fmi3FreeInstance(i) };
}
