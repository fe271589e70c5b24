//! The drive link: `servo device`.

pub mod answer;
pub mod args;
pub mod bench;
pub mod command;
pub mod commission;
pub mod frame_stream;
pub mod index;
pub mod link;
pub mod repeat;
pub mod save_bench;
pub mod session;
pub mod telemetry_trace;
pub mod timed_run;
pub mod twin;
pub mod velocity_ramp;
