//! The options of `servo device` (clap); their `run` is in the commands.

use crate::cli::Common;

/// Talk to a real drive (drive-g474) over its serial link: the core's protocol, version
/// checked first. The NUCLEO's ST-LINK virtual COM port is usually /dev/ttyACM0.
///
/// Actions: hello (version handshake), telemetry (one record, printed as JSON),
/// clear-faults, start-sweep, load-correction FILE (an <axis>.corr.frame from
/// `servo tune`, checked to be a correction request before it is sent), stream (turn
/// acquisition streaming on for --seconds, write the samples to <out>/stream.csv, report
/// how many arrived and how many the drive had to drop).
///
/// Example: servo device --port /dev/ttyACM0 load-correction out/tune/x.corr.frame
#[derive(clap::Args)]
pub struct DeviceArgs {
    /// Serial port of the drive
    #[arg(long)]
    pub port: String,
    /// Baud rate (the firmware's USART2 runs at 921600)
    #[arg(long, default_value_t = 921_600)]
    pub baud: u32,
    /// How long to wait for each answer (ms)
    #[arg(long, default_value_t = 500)]
    pub timeout_ms: u64,
    /// Streaming time (s), for `stream`
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// hello, telemetry, clear-faults, start-sweep, load-correction FILE, stream
    #[arg(num_args = 1..=2, required = true)]
    pub action: Vec<String>,
    #[command(flatten)]
    pub common: Common,
}
