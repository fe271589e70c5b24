//! Running the FMU: the runner (fmi crate), scenarios, traces, the FMU's log, the circle path.

pub mod assignment;
pub mod axis_health;
pub mod circle;
pub mod configuration;
pub mod fmpy;
pub mod log;
pub mod plant_file;
pub mod runner;
pub mod scenario;
pub mod sweep_run;
pub mod trace;
pub mod trace_budget;
