//! SVG plots: signals against time, Bode and Nyquist diagrams.

pub mod bode;
pub mod nyquist;
pub mod signals;
