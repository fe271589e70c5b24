//! Signal analysis shared by the experiments.

pub mod polynomial;
pub mod spectral;
