//! `servo virtual-drive`: the drive firmware's application (`drive_application`) on a
//! simulated board, behind a pseudo-terminal — a drive vendor's "simulation mode" of the real
//! drive, speaking the real protocol. See `simulator.rs` for the tick, `board.rs` for what the
//! board's simulation adds to the FMU's plant, `uart.rs` for the line.

pub mod args;
pub mod board;
pub mod command;
mod critical_section;
pub mod faults;
pub mod flash;
pub mod in_process;
pub mod pseudo_terminal;
pub mod simulator;
pub mod uart;

#[cfg(test)]
mod tests;
