//! Servo axis FMU: the drive's control core in closed loop with a motor/load plant,
//! exported as a Co-Simulation FMU for FMI 3.0 and FMI 2.0 from one binary.
//!
//! - [`variables`]: every variable declared once; everything below is generated from it.
//! - [`co_simulation`]: the axis as the FMI functions see it (no C types).
//! - [`fmi`]: the C APIs (state machine, logger, panic barrier), [`fmu_state`]: saved states.
//! - [`model_description`]: modelDescription.xml (both versions) and the documentation page.
//!
//! The crate is a Rust library: host tools and tests run [`simulation::AxisSimulation`]
//! directly (for example for the plant step-size check) and read the declarations. The FMU's
//! shared library is built from it by `fmu/library/` (a cdylib of its own, optimised as one
//! module with the `fmu-library` profile).

pub mod co_simulation;
pub mod fmi;
pub mod fmu_state;
pub mod model_description;
pub mod parameters;
pub mod plant;
pub mod simulation;
pub mod variables;
