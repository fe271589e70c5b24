//! Stop, zero-servo and fine-adjust sequences (seed 004): `servo sequence` and `servo bench sequence`.

pub mod args;
pub mod bench;
pub mod command;
pub mod device;
pub mod device_report;
pub mod index;
pub mod timeline;
pub mod timeline_reference;
