//! Circle tests (seed 002): `servo circle` and `servo bench circle`.

pub mod args;
pub mod bench;
pub mod command;
pub mod device;
pub mod index;
pub mod plot;
pub mod report;
