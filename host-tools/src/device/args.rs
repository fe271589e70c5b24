//! The options of `servo device` (clap); their `run` is in the commands.

use crate::cli::Common;

/// Talk to a drive (drive-g474, or `servo virtual-drive`) over its serial link: the core's protocol, version
/// checked first. The NUCLEO's ST-LINK virtual COM port is usually /dev/ttyACM0.
///
/// Actions: hello (version handshake; says where the drive's parameters came from at boot),
/// telemetry (one record, printed as JSON), params (the parameters the drive runs, as JSON), clear-faults, start-sweep, save-params (the
/// parameters in force to the drive's flash, loaded at its next boot; at rest only; prints the
/// record's sequence number),
/// load-correction FILE (an <axis>.corr.frame from
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
    #[arg(long, default_value_t = 921_600, value_parser = crate::device::link::baud_rate)]
    pub baud: u32,
    /// How long to wait for each answer (ms)
    #[arg(long, default_value_t = 500)]
    pub timeout_ms: u64,
    /// Streaming time (s), for `stream`
    #[arg(long, default_value_t = 1.0)]
    pub seconds: f64,
    /// hello, telemetry, params, clear-faults, start-sweep, save-params, load-correction FILE, stream
    #[arg(num_args = 1..=2, required = true)]
    pub action: Vec<String>,
    #[command(flatten)]
    pub common: Common,
}

/// Where an experiment runs: the FMU (default) or a drive over its serial link.
#[derive(clap::Args, Clone, Debug)]
pub struct TargetArgs {
    /// Run on a drive instead of the FMU: its serial port (a board's /dev/ttyACM0, or the port
    /// `servo virtual-drive` prints). The FMU then runs the drive's twin, with the drive's
    /// commissioned motor and current loop: beside the drive's run for an experiment (the
    /// report shows how far the two differ), or to check a tuning before the drive gets it
    /// (`servo autotune`)
    #[arg(long, value_name = "PORT")]
    pub device: Option<String>,
    /// Baud rate of the drive's link (the firmware's USART2: 921600)
    #[arg(long, default_value_t = 921_600, value_parser = crate::device::link::baud_rate)]
    pub baud: u32,
    /// How long to wait for each answer of the drive (ms)
    #[arg(long, default_value_t = 2000)]
    pub timeout_ms: u64,
}

impl TargetArgs {
    /// The drive's session over its port (handshake done), if a device was named.
    pub fn session(
        &self,
    ) -> anyhow::Result<Option<crate::device::session::DriveSession<Box<dyn serialport::SerialPort>>>> {
        let Some(port) = &self.device else {
            return Ok(None);
        };
        let link = crate::device::link::DeviceLink::new(
            crate::device::link::open_serial(port, self.baud)?,
            std::time::Duration::from_millis(self.timeout_ms),
        );
        let mut session = crate::device::session::DriveSession::open(link)?;
        session.baud = self.baud;
        session.summary_on_drop = true;
        Ok(Some(session))
    }
}
