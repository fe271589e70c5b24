//! SVG plots: signals against time, Bode diagrams.

pub mod bode;
pub mod signals;
