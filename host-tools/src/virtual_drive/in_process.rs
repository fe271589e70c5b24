//! A virtual drive inside the host's own process, as a byte stream (`Read + Write`) that the
//! host's drive link (`device::link::DeviceLink`) uses as it uses a serial port: reading
//! advances the simulation until bytes arrive. Deterministic and as fast as the machine runs:
//! the benches and tests use it; `servo virtual-drive` puts the same drive behind a
//! pseudo-terminal.

use std::io::{ErrorKind, Read, Write};

use drive_application::board::ParamFlash;

use crate::random::XorShift64Star;
use crate::virtual_drive::simulator::VirtualDrive;
use crate::virtual_drive::uart::Wire;

/// Ticks simulated per read that finds nothing (1 ms at 16 kHz).
const TICKS_PER_WAIT: usize = 16;

pub struct InProcessDrive<F: ParamFlash> {
    pub drive: VirtualDrive<F>,
    pub wire: Wire,
    /// The most ticks the drive runs on before a write from the host reaches it, and the
    /// generator the lags are drawn from (None: no lag; see [`InProcessDrive::lag_requests`]).
    request_lag: Option<(u64, XorShift64Star)>,
}

impl<F: ParamFlash> InProcessDrive<F> {
    pub fn new(drive: VirtualDrive<F>) -> Self {
        Self { drive, wire: Wire::default(), request_lag: None }
    }

    /// Let the drive run on for a drawn 0 to `max_s` of its time before each of the host's
    /// writes reaches it, the draws reproducible from `seed`. A drive behind a real line runs
    /// freely between the host's requests, so the state an experiment starts from (the
    /// rotor's angle, the tick's phase, the converter's noise, how long a ride lasted) varies
    /// from run to run; this brings that variety into a deterministic run. What the host
    /// paces by polling (a velocity ramp of tens of milliseconds) then comes in coarser steps,
    /// as it does from `servo virtual-drive --speed max`.
    pub fn lag_requests(&mut self, max_s: f64, seed: u64) {
        let ticks = (max_s * crate::virtual_drive::board::TICK_HZ as f64).round() as u64;
        self.request_lag = (ticks > 0).then(|| (ticks, XorShift64Star::from_seed(seed)));
    }

    /// Let the drive run for `seconds` with nothing read (bytes it sends are kept).
    pub fn run_for(&mut self, seconds: f64) {
        let until = self.drive.time() + seconds;
        while self.drive.time() < until {
            self.drive.tick(&mut self.wire);
        }
    }
}

impl<F: ParamFlash> crate::device::link::DrivePort for InProcessDrive<F> {
    /// The drive runs for `d` of its time.
    fn pause(&mut self, d: std::time::Duration) {
        self.run_for(d.as_secs_f64());
    }
}

impl<F: ParamFlash> Read for InProcessDrive<F> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        for _ in 0..TICKS_PER_WAIT {
            if !self.wire.from_drive.is_empty() {
                break;
            }
            self.drive.tick(&mut self.wire);
        }
        if self.wire.from_drive.is_empty() {
            return Err(ErrorKind::WouldBlock.into());
        }
        let n = buf.len().min(self.wire.from_drive.len());
        for (d, s) in buf.iter_mut().zip(self.wire.from_drive.drain(..n)) {
            *d = s;
        }
        Ok(n)
    }
}

impl<F: ParamFlash> Write for InProcessDrive<F> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        if let Some((ticks, rng)) = &mut self.request_lag {
            // The draw's high bits (the generator's best).
            let lag = (rng.next() >> 32) % (*ticks + 1);
            for _ in 0..lag {
                self.drive.tick(&mut self.wire);
            }
        }
        self.wire.to_drive.extend(buf);
        Ok(buf.len())
    }

    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

/// How long a bench waits for an in-process drive's answer (its time runs only as the host
/// reads: generous, never reached by a drive that answers).
const ANSWER_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

/// A virtual drive in this process with the plant and drive defaults of `parameters` (FMU
/// names), on `line`, its flash in memory, behind a session with its motor commissioned (as
/// a user does first, kept in its RAM).
pub fn commissioned_session(
    parameters: &std::collections::BTreeMap<String, crate::fmu::scenario::Value>,
    line: crate::virtual_drive::uart::LineSettings,
) -> anyhow::Result<crate::device::session::DriveSession<InProcessDrive<crate::virtual_drive::flash::FileFlash>>> {
    use crate::virtual_drive::simulator::VirtualDriveSettings;
    let c = crate::fmu::configuration::configuration(parameters)?;
    let baud = line.baud;
    let settings = VirtualDriveSettings { defaults: c.control, plant: c.plant, line, faults: vec![] };
    let drive = VirtualDrive::power_on(&settings, crate::virtual_drive::flash::FileFlash::in_memory())?;
    let link = crate::device::link::DeviceLink::new(InProcessDrive::new(drive), ANSWER_TIMEOUT);
    let mut session = crate::device::session::DriveSession::open(link)?;
    session.baud = baud;
    session.commission_with_defaults()?;
    Ok(session)
}

#[cfg(test)]
mod tests {
    /// The drawn start states are reproducible: the same seed lags the same requests by the
    /// same ticks (the drive's time after the same writes is the same), another seed not.
    #[test]
    fn a_lagging_drive_runs_on_reproducibly_from_its_seed() {
        use crate::virtual_drive::in_process::InProcessDrive;
        use crate::virtual_drive::simulator::{VirtualDrive, VirtualDriveSettings};
        use std::io::Write;
        let time_after_writes = |seed: Option<u64>| {
            let c = crate::fmu::configuration::configuration(&Default::default()).unwrap();
            let settings = VirtualDriveSettings {
                defaults: c.control,
                plant: c.plant,
                line: crate::virtual_drive::uart::LineSettings::default(),
                faults: vec![],
            };
            let drive = VirtualDrive::power_on(&settings, crate::virtual_drive::flash::FileFlash::in_memory()).unwrap();
            let mut port = InProcessDrive::new(drive);
            if let Some(seed) = seed {
                port.lag_requests(crate::device::bench::REQUEST_LAG_S, seed);
            }
            let mut times = Vec::new();
            for _ in 0..20 {
                port.write_all(&[0]).unwrap();
                times.push(port.drive.time());
            }
            times
        };
        assert_eq!(time_after_writes(None), vec![0.0; 20]);
        let (a, b) = (time_after_writes(Some(3)), time_after_writes(Some(3)));
        assert_eq!(a, b);
        assert_ne!(a, time_after_writes(Some(4)));
        // Each lag within half a second, and they vary (not one fixed step).
        let steps: Vec<f64> = a.windows(2).map(|w| w[1] - w[0]).collect();
        assert!(
            a[0] <= crate::device::bench::REQUEST_LAG_S + 1e-9
                && steps.iter().all(|&s| (0.0..=crate::device::bench::REQUEST_LAG_S + 1e-9).contains(&s))
        );
        assert!(
            steps.iter().any(|&s| s < 0.1 * crate::device::bench::REQUEST_LAG_S)
                && steps.iter().any(|&s| s > 0.5 * crate::device::bench::REQUEST_LAG_S)
        );
    }
}
