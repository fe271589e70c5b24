//! What both C APIs share: the instance behind the opaque pointer, the phases of the
//! standard's state machine, the logger, and the barrier every entry point goes through
//! (NULL and foreign pointers, calls in the wrong phase, panics).

use std::ffi::{c_char, c_int, c_void, CStr, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

use super::values::GetPlans;
use crate::co_simulation::AxisModel;

/// Status codes: the same numbers in FMI 2.0 (`fmi2Status`) and FMI 3.0 (`fmi3Status`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
#[repr(i32)]
pub enum Status {
    Ok = 0,
    Warning = 1,
    Discard = 2,
    Error = 3,
    Fatal = 4,
}

/// The phases of the Co-Simulation state machine this FMU goes through (no event mode, no
/// configuration mode: it has neither clocks nor structural parameters).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    Instantiated,
    InitializationMode,
    /// FMI 3.0 Step Mode, FMI 2.0 stepComplete.
    StepMode,
    Terminated,
}

pub const ANY_PHASE: &[Phase] = &[Phase::Instantiated, Phase::InitializationMode, Phase::StepMode, Phase::Terminated];

/// Log categories (declared in the model description, switched by SetDebugLogging).
pub const LOG_CATEGORIES: [(&str, &str); 4] = [
    ("logEvents", "Sequence keys and sweep starts the axis refused, and other events"),
    ("logStatusWarning", "Messages sent with a Warning status"),
    ("logStatusError", "Messages sent with an Error status: why a call was refused"),
    ("logStatusFatal", "Messages sent with a Fatal status"),
];

pub type Fmi3LogMessage = unsafe extern "C" fn(*mut c_void, c_int, *const c_char, *const c_char);
/// The FMI 2.0 logger is a printf-like variadic function.
pub type Fmi2Logger = unsafe extern "C" fn(*mut c_void, *const c_char, c_int, *const c_char, *const c_char, ...);

#[derive(Clone, Copy)]
pub enum Logger {
    Fmi3 { environment: *mut c_void, callback: Option<Fmi3LogMessage> },
    Fmi2 { environment: *mut c_void, callback: Option<Fmi2Logger> },
}

const MAGIC: u64 = 0x5345_5256_4f41_5849; // "SERVOAXI"

/// `repr(C)` with the magic first: a pointer is checked by reading one word before any
/// reference to the instance is made.
#[repr(C)]
pub struct Instance {
    magic: u64,
    pub name: CString,
    pub model: AxisModel,
    pub phase: Phase,
    /// Set when a call panicked: the model may be half updated; only Reset, SetFMUState,
    /// getters and FreeInstance are accepted until then.
    pub poisoned: bool,
    pub logging_on: bool,
    pub categories: [bool; LOG_CATEGORIES.len()],
    pub logger: Logger,
    /// Stop time given at initialisation (steps beyond it are refused).
    pub stop_time: Option<f64>,
    /// The value references of the last Get of each type, resolved (not part of the model's
    /// state: a plan depends on nothing but the references).
    pub(crate) get_plans: GetPlans,
}

impl Instance {
    pub fn new(name: CString, logger: Logger, logging_on: bool) -> Self {
        Self {
            magic: MAGIC,
            name,
            model: AxisModel::new(),
            phase: Phase::Instantiated,
            poisoned: false,
            logging_on,
            categories: [true; LOG_CATEGORIES.len()],
            logger,
            stop_time: None,
            get_plans: GetPlans::default(),
        }
    }

    /// Send a message to the importer's logger. Warnings, errors and fatal messages always
    /// go out (a refusal never goes unexplained, whatever the debug-logging switch says);
    /// events only with logging on and their category enabled. Without a logger, warnings
    /// and errors go to stderr.
    pub fn log(&self, status: Status, message: &str) {
        let category = match status {
            Status::Ok | Status::Discard => 0,
            Status::Warning => 1,
            Status::Error => 2,
            Status::Fatal => 3,
        };
        if status < Status::Warning && !(self.logging_on && self.categories[category]) {
            return;
        }
        let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
        let cat = CString::new(LOG_CATEGORIES[category].0).unwrap_or_default();
        match self.logger {
            Logger::Fmi3 { environment, callback: Some(cb) } => unsafe {
                cb(environment, status as c_int, cat.as_ptr(), text.as_ptr());
            },
            Logger::Fmi2 { environment, callback: Some(cb) } => unsafe {
                // The message is a format string: pass it through "%s".
                cb(environment, self.name.as_ptr(), status as c_int, cat.as_ptr(), c"%s".as_ptr(), text.as_ptr());
            },
            _ => {
                if status >= Status::Warning {
                    stderr_line(&format!("servo_axis ({}): {message}", self.name.to_string_lossy()));
                }
            }
        }
    }

    /// Switch debug logging and categories (SetDebugLogging of both versions).
    ///
    /// # Safety
    /// `categories` points to `n` C strings (or is NULL with `n` = 0).
    pub unsafe fn set_debug_logging(
        &mut self,
        on: bool,
        n: usize,
        categories: *const *const c_char,
    ) -> Result<Status, String> {
        if n == 0 {
            self.logging_on = on;
            self.categories = [on; LOG_CATEGORIES.len()];
            return Ok(Status::Ok);
        }
        let names = unsafe { slice(categories, n, "categories")? };
        let mut new = self.categories;
        for &p in names {
            let name = unsafe { c_str(p, "category")? };
            let i = LOG_CATEGORIES.iter().position(|(c, _)| *c == name).ok_or_else(|| {
                format!("unknown log category `{name}` (the FMU has {:?})", LOG_CATEGORIES.map(|c| c.0))
            })?;
            new[i] = on;
        }
        self.categories = new;
        self.logging_on = on || self.logging_on;
        Ok(Status::Ok)
    }
}

/// A C array argument as a slice; NULL is accepted only for an empty array.
///
/// # Safety
/// A non-NULL `p` points to `n` valid elements.
pub unsafe fn slice<'a, T>(p: *const T, n: usize, what: &str) -> Result<&'a [T], String> {
    if n == 0 {
        return Ok(&[]);
    }
    if p.is_null() {
        return Err(format!("{what} is NULL but {n} elements were announced"));
    }
    Ok(unsafe { std::slice::from_raw_parts(p, n) })
}

/// # Safety
/// A non-NULL `p` points to `n` writable elements.
pub unsafe fn slice_mut<'a, T>(p: *mut T, n: usize, what: &str) -> Result<&'a mut [T], String> {
    if n == 0 {
        return Ok(&mut []);
    }
    if p.is_null() {
        return Err(format!("{what} is NULL but {n} elements were announced"));
    }
    Ok(unsafe { std::slice::from_raw_parts_mut(p, n) })
}

/// # Safety
/// A non-NULL `p` is a NUL-terminated string.
pub unsafe fn c_str<'a>(p: *const c_char, what: &str) -> Result<&'a str, String> {
    if p.is_null() {
        return Err(format!("{what} is NULL"));
    }
    unsafe { CStr::from_ptr(p) }.to_str().map_err(|_| format!("{what} is not UTF-8"))
}

/// A line on stderr that never panics (eprintln! does when stderr is a closed pipe).
pub fn stderr_line(text: &str) {
    use std::io::Write;
    let _ = writeln!(std::io::stderr(), "{text}");
}

pub fn panic_message(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

/// The instance behind an opaque pointer, if it is one of ours.
///
/// # Safety
/// A non-NULL pointer must come from this library's Instantiate (and not be freed).
pub unsafe fn instance<'a>(p: *mut c_void) -> Option<&'a mut Instance> {
    if p.is_null() || unsafe { std::ptr::read(p as *const u64) } != MAGIC {
        return None;
    }
    Some(unsafe { &mut *(p as *mut Instance) })
}

/// Free an instance made by Instantiate; its magic is cleared first, so a second free of the
/// same pointer is recognised and ignored instead of freeing twice.
///
/// # Safety
/// `p` is NULL or a pointer from this library's Instantiate.
pub unsafe fn free(p: *mut c_void) {
    if unsafe { instance(p) }.is_some() {
        unsafe {
            std::ptr::write_volatile(p as *mut u64, 0);
            drop(Box::from_raw(p as *mut Instance));
        }
    }
}

/// Whether a call may run on a poisoned instance (one that panicked).
#[derive(Clone, Copy, PartialEq, Eq)]
pub enum WhenPoisoned {
    Refuse,
    Allow,
}

/// The barrier of every entry point that takes an instance: NULL or foreign pointer →
/// Error; a phase the standard does not allow the call in → Error with the reason logged;
/// the call's own refusal → Error with its reason logged, nothing changed; a panic → Error,
/// the instance poisoned. Never unwinds into the importer.
///
/// # Safety
/// `p` is NULL or a pointer from this library's Instantiate.
pub unsafe fn call(
    p: *mut c_void,
    function: &str,
    allowed: &[Phase],
    poisoned: WhenPoisoned,
    body: impl FnOnce(&mut Instance) -> Result<Status, String>,
) -> c_int {
    let result = catch_unwind(AssertUnwindSafe(|| {
        let Some(inst) = (unsafe { instance(p) }) else {
            if !p.is_null() {
                stderr_line(&format!(
                    "servo_axis: {function} called with a pointer that is not an instance of this FMU"
                ));
            }
            return Status::Error;
        };
        if inst.poisoned && poisoned == WhenPoisoned::Refuse {
            inst.log(
                Status::Error,
                &format!("{function}: the instance failed internally; call Reset (or SetFMUState) first"),
            );
            return Status::Error;
        }
        if !allowed.contains(&inst.phase) {
            inst.log(
                Status::Error,
                &format!("{function} is not allowed in {:?} (allowed in {:?})", inst.phase, allowed),
            );
            return Status::Error;
        }
        let inner = catch_unwind(AssertUnwindSafe(|| body(inst)));
        match inner {
            Ok(Ok(status)) => status,
            Ok(Err(message)) => {
                inst.log(Status::Error, &format!("{function}: {message}"));
                Status::Error
            }
            Err(panic) => {
                inst.poisoned = true;
                inst.log(
                    Status::Error,
                    &format!("{function}: internal error, instance disabled until Reset: {}", panic_message(panic)),
                );
                Status::Error
            }
        }
    }));
    result.unwrap_or(Status::Error) as c_int
}

/// An entry point the FMU does not support: Error with the reason logged (never an abort).
///
/// # Safety
/// As [`call`].
pub unsafe fn unsupported(p: *mut c_void, function: &str, reason: &str) -> c_int {
    unsafe { call(p, function, ANY_PHASE, WhenPoisoned::Allow, |_| Err(format!("not supported: {reason}"))) }
}
