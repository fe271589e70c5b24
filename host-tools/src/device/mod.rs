//! The drive link: `servo device`.

pub mod command;
pub mod frame_stream;
pub mod link;
