//! Running the FMU: the runner (fmi crate), scenarios, traces, the FMU's log, the circle path.

pub mod circle;
pub mod log;
pub mod runner;
pub mod scenario;
pub mod trace;
