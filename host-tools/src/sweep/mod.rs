//! Frequency response with phase-shifted sine repeats (seed 000): `servo sweep` and `servo bench sweep`.

pub mod args;
pub mod bench;
pub mod command;
pub mod device;
pub mod device_report;
pub mod index;
pub mod limit_detection;
pub mod measurement;
pub mod report;
pub mod standard_error;
pub mod standard_error_calibration;
pub mod torque_limit;
