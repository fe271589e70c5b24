//! The options of `servo virtual-drive` (clap); their `run` is in `command.rs`.

use std::path::PathBuf;

use crate::virtual_drive::faults::ScheduledFault;

/// Run the drive firmware's application on a simulated board, behind a pseudo-terminal.
///
/// The same code the G474 runs around the control core (offset calibration, fault latch,
/// the link, streaming, parameter changes and storage) on the board's simulation: the FMU's
/// motor and load, the IHM08M1's 12-bit current and bus sensing, the encoder, the break input,
/// and a serial line that moves bytes at the baud rate. Its port is printed on the first line
/// (and written to --port-file, linked at --link); every `servo device` action and every
/// experiment with --device works on it as on a board.
///
/// Example: `servo virtual-drive --link /tmp/servo-drive &`, then `servo device --port
/// /tmp/servo-drive hello` or `servo sweep --device /tmp/servo-drive`.
///
/// Example: `servo virtual-drive --speed max --fault break@2.5 --set plant.load_inertia=3e-4`.
#[derive(clap::Args)]
pub struct VirtualDriveArgs {
    /// Pace: `realtime` (default), `max` (as fast as the machine runs: CI), or a factor (0.5: half speed)
    #[arg(long, default_value = "realtime")]
    pub speed: String,
    /// Plant and drive parameters (FMU variable names: plant.*, ctrl.*), NAME=VALUE, repeatable.
    /// The drive boots with the ctrl.* values when its flash holds no saved set.
    #[arg(long = "set")]
    pub set: Vec<String>,
    /// Baud rate of the simulated line (10 bits a byte)
    #[arg(long, default_value_t = 921_600, value_parser = crate::device::link::baud_rate)]
    pub baud: u32,
    /// The drive's parameter flash (two 2 KiB pages), kept across restarts (default: out/virtual-drive/flash.bin)
    #[arg(long)]
    pub flash: Option<PathBuf>,
    /// Inject a fault at a time (s since start): encoder-disconnect@T, break@T, undervoltage@T. Repeatable.
    #[arg(long = "fault")]
    pub faults: Vec<ScheduledFault>,
    /// Probability that a byte on the line is corrupted (one bit flipped), each way: 0 to 0.1
    #[arg(long, default_value_t = 0.0)]
    pub corrupt_rate: f64,
    /// Seed of the line's corruption
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Stop after this many simulated seconds (default: run until stopped)
    #[arg(long)]
    pub seconds: Option<f64>,
    /// Write the port's path to this file once it is open
    #[arg(long)]
    pub port_file: Option<PathBuf>,
    /// Make this path a symbolic link to the port (a fixed name for scripts)
    #[arg(long)]
    pub link: Option<PathBuf>,
}
