//! Host side of the servo toolkit: scenarios run against the FMU through FMI 3.0, traces,
//! plots, reports and benchmarks. The `servo` binary is a thin CLI over this library.

pub mod acc_dec_report;
pub mod acc_dec_study;
pub mod bench;
pub mod bench_accdec;
pub mod bench_circle;
pub mod bench_ident;
pub mod bench_plant;
pub mod bench_sequence;
pub mod bench_sweep;
pub mod bode_plot;
pub mod circle_plot;
pub mod circle_report;
pub mod circle_test;
pub mod device_link;
pub mod fault_campaign;
pub mod firmware;
pub mod fmi_campaign;
pub mod fmu_log;
pub mod fmu_runner;
pub mod frame_stream;
pub mod frequency_response;
pub mod ident_report;
pub mod identification;
pub mod paths;
pub mod plot;
pub mod polynomial;
pub mod random;
pub mod report;
pub mod response_model;
pub mod scenario;
pub mod sequence_scenario;
pub mod spectral;
pub mod sweep_report;
pub mod trace;
pub mod tuning;
