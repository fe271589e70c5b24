//! Identification and correction (seed 001): `servo ident`, `servo tune`, `servo bench ident`.

pub mod anti_resonance_error;
pub mod args;
pub mod averaged_response;
pub mod axis_name;
pub mod bench;
pub mod command;
pub mod device;
pub mod device_bench;
pub mod device_check;
pub mod device_machine_end;
pub mod identification;
pub mod index;
pub mod model_file;
pub mod output_error_fit;
pub mod report;
pub mod response_model;
pub mod tune_device_bench;
pub mod tuning;
