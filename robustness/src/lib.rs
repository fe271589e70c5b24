//! Robustness campaigns of the drive link, re-runnable and time-bounded (`servo bench
//! robustness --campaign frames|requests|stream [--seconds N]`, or `cargo run --profile
//! robustness -p robustness -- …`): a seeded mutation harness on the stable toolchain.
//!
//! - `frames`: valid frames of every request and response, mutated at the byte level (bit
//!   flips, overwritten, inserted, deleted, duplicated and swapped bytes, truncation, bytes
//!   and zeros appended, random frames), fed to `protocol::decode`. A mutated frame that
//!   still decodes is an accepted-corrupt frame.
//! - `requests`: the drive's whole request path, decode → `protocol::handle` → ticks of
//!   `Axis::step`: requests whose postcard payload was mutated (absurd floats, extreme
//!   integers, random bits) and re-framed with a valid CRC so they reach the handler, and
//!   byte-mutated frames; every refusal must leave the commands and parameters as they were.
//! - `stream`: the host's parsing of the drive's bytes (`host-tools/src/device/frame_stream.rs`,
//!   compiled here from the same file), mutated streams of responses in random chunks.
//!
//! Each input runs under `catch_unwind`; a panic is a crash, one whose message says
//! "overflow" an overflow panic. The campaigns are meant to run with overflow checks on
//! (the workspace's `robustness` profile); the figures say whether they were.

#[path = "../../host-tools/src/device/frame_stream.rs"]
pub mod frame_stream;

pub mod campaigns;
