//! Servo axis FMU: the drive's control core in closed loop with a motor/load plant,
//! exported as an FMI 3.0 Co-Simulation FMU.
//!
//! The crate is also an rlib so host tools and tests can run [`simulation::AxisSimulation`]
//! directly (for example for the plant step-size check).

pub mod model;
pub mod plant;
pub mod simulation;

fmi_export::export_fmu!(model::ServoAxis);
