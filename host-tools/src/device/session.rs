//! An experiment's conversation with a drive: the handshake, the axis brought to rest, the
//! parameters and set-points given, the drive's own clock waited on. Every answer is checked
//! (a refusal is an error with the drive's reason) and every wait is bounded twice: in the
//! drive's ticks (what the experiment means) and in wall-clock time (a drive that stops
//! ticking or answering is an error, never a hang) — the same on a board and on the virtual
//! drive at any speed.

use std::time::{Duration, Instant};

use anyhow::{bail, Result};
use control_core::acquisition_stream::SampleBatch;
use control_core::axis::{Mode, Telemetry};
use control_core::protocol::{DriveTelemetry, FrameError, ParamsOrigin, Request, Response, VERSION};
use control_core::{Commands, Params};

use crate::device::answer::answer;
use crate::device::link::{DeviceLink, DrivePort};

/// A drive whose tick counter has not moved for this long has stopped.
pub const STALLED: Duration = Duration::from_secs(3);

pub struct DriveSession<T: DrivePort> {
    pub link: DeviceLink<T>,
    pub boot_params: ParamsOrigin,
    /// The drive's tick rate (its parameters' current-loop rate, once given).
    pub tick_hz: f64,
    /// Pause between two telemetry polls (the telemetry shares the line with the stream).
    pub poll: Duration,
    /// The link's baud rate (for the share of the line an experiment uses).
    pub baud: u32,
    /// The telemetry read last, while no other request has been sent since (what an order
    /// whose answer is lost is judged against: `device::answer`).
    fresh: Option<DriveTelemetry>,
    /// When the session ends, say on stderr what the line cost (corrupt frames, requests sent
    /// again, outcomes read from the telemetry), if anything.
    pub summary_on_drop: bool,
}

impl<T: DrivePort> DriveSession<T> {
    /// The handshake: the drive speaks this protocol version (and says where its parameters
    /// came from).
    pub fn open(mut link: DeviceLink<T>) -> Result<Self> {
        let boot_params = match answer(&mut link, &Request::Hello { version: VERSION }, None)? {
            Response::Hello { version, boot_params } if version == VERSION => boot_params,
            Response::FrameError(FrameError::Version { got }) => bail!(
                "the drive refused the handshake: it does not speak protocol version {got}, this host's (update the \
                 host tools or the firmware so that both speak the same version)"
            ),
            Response::FrameError(e) => {
                bail!("the drive refused the handshake: {e} (update the host tools or the firmware)")
            }
            other => bail!("unexpected answer to the handshake: {other:?}"),
        };
        Ok(Self {
            link,
            boot_params,
            tick_hz: Params::default().rates.current_loop_hz as f64,
            poll: Duration::from_millis(5),
            baud: 921_600,
            fresh: None,
            summary_on_drop: false,
        })
    }

    /// The drive's answer to `request`, sent again after a lost request or answer where that
    /// is safe (`device::answer`).
    pub fn answer(&mut self, request: &Request) -> Result<Response> {
        if *request == Request::GetTelemetry {
            return answer(&mut self.link, request, None);
        }
        answer(&mut self.link, request, self.fresh.take())
    }

    /// Send a request the drive must carry out (`Done`), or fail with its reason.
    pub fn order(&mut self, request: Request, what: &str) -> Result<()> {
        match self.answer(&request)? {
            Response::Done => Ok(()),
            Response::Refused(why) => bail!("the drive refused {what}: {why}"),
            Response::FrameError(e) => bail!("the drive could not read {what}: {e}"),
            other => bail!("unexpected answer to {what}: {other:?}"),
        }
    }

    /// Save the parameters in force to the drive's flash: the record's sequence number.
    pub fn save_params(&mut self) -> Result<u32> {
        match self.answer(&Request::SaveParams)? {
            Response::Saved { sequence } => Ok(sequence),
            Response::Refused(why) => bail!("the drive refused the parameter save: {why}"),
            Response::FrameError(e) => bail!("the drive could not read the parameter save: {e}"),
            other => bail!("unexpected answer to the parameter save: {other:?}"),
        }
    }

    /// The axis's telemetry; asked again after a lost answer (asking changes nothing in the
    /// drive).
    pub fn telemetry(&mut self) -> Result<Telemetry> {
        let t = crate::device::answer::telemetry(&mut self.link)?;
        self.fresh = Some(t);
        Ok(t.axis)
    }

    /// What the line cost so far, if anything: corrupt frames skipped, requests sent again,
    /// orders whose outcome was read from the telemetry (each by request).
    pub fn line_summary(&self) -> Option<String> {
        let l = &self.link;
        let each = |pick: fn(&(u64, u64)) -> u64| {
            let v: Vec<String> =
                l.by_request.iter().filter(|(_, n)| pick(n) > 0).map(|(k, n)| format!("{k} {}", pick(n))).collect();
            if v.is_empty() {
                String::new()
            } else {
                format!(" ({})", v.join(", "))
            }
        };
        (l.corrupt_frames + l.resent + l.verified > 0).then(|| {
            format!(
                "link: {} corrupt frame(s) skipped, {} request(s) sent again{}, {} order(s) whose answer was lost \
                 judged from the drive's telemetry{}",
                l.corrupt_frames,
                l.resent,
                each(|n| n.0),
                l.verified,
                each(|n| n.1)
            )
        })
    }

    /// Torque mode at zero torque; refuses to go on with faults latched (they are the
    /// user's to look at and clear, never an experiment's).
    pub fn rest(&mut self) -> Result<Telemetry> {
        let t = self.rest_allowing_no_commissioning()?;
        if t.faults.0 == control_core::faults::Faults::NOT_COMMISSIONED {
            bail!(
                "the drive's motor is not commissioned: it refuses every mode until it is (run `servo commission \
                 --device PORT`; --save keeps the result in the drive's flash)"
            );
        }
        Ok(t)
    }

    /// The drive's parameters, for its twin ([`crate::fmu::runner::Fmu::as_twin_of`]), the
    /// drive put at rest: latched faults are named first (they say what is wrong with the
    /// drive), then a motor that is not commissioned.
    pub fn params_for_twin(&mut self) -> Result<Params> {
        self.rest()?;
        self.params()
    }

    /// [`DriveSession::rest`], a drive whose only fault is that its motor is not commissioned
    /// accepted (what commissioning it, or a commissioned set saved in its flash at its next boot,
    /// lifts).
    pub fn rest_allowing_no_commissioning(&mut self) -> Result<Telemetry> {
        self.order(Request::SetCommands(Commands { mode: Mode::Torque, ..Commands::default() }), "the rest command")?;
        let t = self.telemetry()?;
        let faults = control_core::faults::Faults(t.faults.0 & !control_core::faults::Faults::NOT_COMMISSIONED);
        if faults.any() {
            bail!("the drive has faults latched: {faults} (look at them, then `servo device --port … clear-faults`)");
        }
        Ok(t)
    }

    /// Give the drive `params` (at rest), with the drive's own commissioned motor, encoder
    /// mounting, current-loop gains and feed-forward's choice in place of theirs
    /// (`DriveSession::with_drive_commissioning`).
    pub fn set_params(&mut self, params: &Params) -> Result<()> {
        // Faults first (they name what is wrong with the drive), then its commissioning.
        self.rest()?;
        let params = &self.with_drive_commissioning(params)?;
        self.order(Request::SetParams(*params), "the parameters")?;
        self.tick_hz = params.rates.current_loop_hz as f64;
        Ok(())
    }

    /// Poll the telemetry until `done` says so; a bound on the drive's time
    /// (`max_s` seconds of its ticks from now) and on a drive that stops ticking.
    pub fn wait_until(&mut self, max_s: f64, mut done: impl FnMut(&Telemetry) -> Result<bool>) -> Result<Telemetry> {
        let first = self.telemetry()?;
        if !(max_s.is_finite() && max_s > 0.0) {
            bail!("a wait of {max_s} s is not a positive number of seconds");
        }
        let limit = first.tick.saturating_add((max_s * self.tick_hz).ceil() as u64);
        let (mut last_tick, mut moved) = (first.tick, Instant::now());
        let mut t = first;
        loop {
            if done(&t)? {
                return Ok(t);
            }
            if t.tick >= limit {
                bail!("the drive did not get there within {max_s:.1} s of its time");
            }
            if t.tick != last_tick {
                (last_tick, moved) = (t.tick, Instant::now());
            } else if moved.elapsed() > STALLED {
                bail!("the drive's tick counter stopped at {} (is it still running?)", t.tick);
            }
            self.link.pause(self.poll);
            t = self.telemetry()?;
        }
    }

    /// Let `seconds` of the drive's time pass.
    pub fn wait(&mut self, seconds: f64) -> Result<Telemetry> {
        let ticks = (seconds * self.tick_hz).round() as u64;
        // From the first telemetry `wait_until` reads: no poll of its own.
        let mut target = None;
        self.wait_until(seconds * 2.0 + 0.1, |t| Ok(t.tick >= *target.get_or_insert(t.tick.saturating_add(ticks))))
    }

    pub fn take_samples(&mut self) -> Vec<SampleBatch> {
        self.link.take_samples()
    }
}

impl<T: DrivePort> Drop for DriveSession<T> {
    fn drop(&mut self) {
        if self.summary_on_drop {
            if let Some(s) = self.line_summary() {
                eprintln!("{s}");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;
    use std::io::{Read, Write};

    /// A drive of another protocol version: it answers every frame as a drive answers a
    /// handshake in a version it does not speak.
    struct OtherVersion(VecDeque<u8>);

    impl Read for OtherVersion {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            if self.0.is_empty() {
                return Err(std::io::ErrorKind::WouldBlock.into());
            }
            let n = buf.len().min(self.0.len());
            for (d, s) in buf.iter_mut().zip(self.0.drain(..n)) {
                *d = s;
            }
            Ok(n)
        }
    }

    impl Write for OtherVersion {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            for _ in buf.iter().filter(|&&b| b == 0) {
                let mut out = [0u8; 32];
                let refusal = Response::FrameError(FrameError::Version { got: VERSION });
                let n = control_core::protocol::encode(&refusal, &mut out).unwrap();
                self.0.extend(&out[..n]);
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl DrivePort for OtherVersion {}

    #[test]
    fn a_drive_of_another_protocol_version_is_refused_with_the_version() {
        let link = DeviceLink::new(OtherVersion(VecDeque::new()), Duration::from_millis(30));
        let e = DriveSession::open(link).err().unwrap().to_string();
        assert!(e.contains(&format!("does not speak protocol version {VERSION}")) && e.contains("update"), "{e}");
    }
}
