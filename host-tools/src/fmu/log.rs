//! The FMU's log messages as the host sees them. The `fmi` crate hands every message of the
//! FMU's logger to the `log` crate; this logger keeps the warnings and errors of the calling
//! thread, so an FMI error the host reports carries the FMU's own reason ("ctrl.velocity_kp =
//! -1 is outside its range …") instead of a bare status.

use std::cell::RefCell;
use std::sync::Once;

thread_local! {
    static MESSAGES: RefCell<Vec<String>> = const { RefCell::new(Vec::new()) };
}

struct FmuLog;

impl log::Log for FmuLog {
    fn enabled(&self, metadata: &log::Metadata) -> bool {
        metadata.level() <= log::Level::Warn
    }

    fn log(&self, record: &log::Record) {
        if record.module_path() == Some("fmu") && self.enabled(record.metadata()) {
            MESSAGES.with(|m| {
                let mut m = m.borrow_mut();
                // Bounded: a long run of refused keys must not grow without end.
                if m.len() >= 64 {
                    m.remove(0);
                }
                m.push(record.args().to_string());
            });
        }
    }

    fn flush(&self) {}
}

static LOGGER: FmuLog = FmuLog;

/// Install the logger (once per process; a no-op if another logger was installed first).
pub fn install() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        if log::set_logger(&LOGGER).is_ok() {
            log::set_max_level(log::LevelFilter::Warn);
        }
    });
}

/// Forget what this thread's FMU calls logged so far.
pub fn clear() {
    MESSAGES.with(|m| m.borrow_mut().clear());
}

/// What this thread's FMU calls logged since the last `clear`/`reasons`, as one line.
pub fn reasons() -> String {
    let all = MESSAGES.with(|m| std::mem::take(&mut *m.borrow_mut()));
    if all.is_empty() {
        "no reason logged".into()
    } else {
        all.join("; ")
    }
}

/// What this thread's FMU calls logged since the last `clear`/`reasons`/`take`, one message
/// each (a run's warnings: a refused `sweep_start`, a refused sequence key).
pub fn take() -> Vec<String> {
    MESSAGES.with(|m| std::mem::take(&mut *m.borrow_mut()))
}
