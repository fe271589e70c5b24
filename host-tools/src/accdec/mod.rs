//! Acc/dec after interpolation (seed 003): `servo accdec` and `servo bench accdec`.

pub mod args;
pub mod bench;
pub mod command;
pub mod deviation;
pub mod index;
pub mod report;
pub mod study;
