//! Signal analysis shared by the experiments.

pub mod complex_json;
pub mod polynomial;
pub mod response_point;
pub mod spectral;
