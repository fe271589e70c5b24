//! The C APIs of the FMU, written by the project: FMI 3.0 and FMI 2.0 Co-Simulation from
//! one model. Every entry point goes through `instance::call` (pointer check, the
//! standard's state machine, panic barrier, reasons to the importer's logger).

pub mod calls;
pub mod fmi2;
pub mod fmi3;
pub mod instance;
#[cfg(test)]
mod tests;
mod values;
