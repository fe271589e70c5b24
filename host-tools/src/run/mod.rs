//! Scenario runs: `servo run`, its report, `servo bench fmu` and `servo bench plant`.

pub mod args;
pub mod command;
pub mod device;
pub mod device_report;
pub mod index;
pub mod report;
