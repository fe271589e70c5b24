//! The servo drive's application apart from its board (issue 16 item 1): what runs in the
//! drive around the control core, written once against a small board interface ([`board`])
//! so that the G474 firmware (`fw/drive-g474`) and the host (tests here; later the virtual
//! drive) build the same code — as mjbots/moteus keeps `BldcServoControl` generic over its
//! hardware and quartiq/stabilizer keeps `src/hardware/` apart from its processing.
//!
//! - [`drive`]: the state the control tick and the link share, the tick sequence (offset
//!   calibration, shunt choice, fault latch → gate drive off, `Axis::step`, streaming,
//!   watchdog), and parameter and correction changes built outside the critical section and
//!   swapped in (item 2);
//! - [`accelerometer_input`]: the removable machine-end accelerometer's count to rad/s²
//!   (its zero taken with the current offsets);
//! - [`link`]: the host protocol's frames, byte by byte in, encoded frames out;
//! - [`param_store`]: the parameter set in two alternating flash pages (item 3);
//! - [`housekeeping`]: what the position tick reports (offsets, fault changes, heartbeat) as
//!   notes the board's binary logs (defmt on the G474).
//!
//! Contexts: [`drive::Drive::tick`] runs in the sampling interrupt (the most urgent); the
//! link side ([`drive::Host`]) in a task of lower priority. They share one critical section
//! (the `critical-section` crate: interrupts off on the Cortex-M4), held only for short
//! copies and swaps.

#![no_std]

pub mod accelerometer_input;
pub mod board;
pub mod drive;
pub mod housekeeping;
pub mod link;
pub mod param_store;

pub use board::{FlashError, ParamFlash, PowerStage, Sample};
pub use drive::{Drive, Host, InstallError, StackGauge};
