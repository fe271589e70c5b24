//! `servo virtual-drive`: the virtual drive behind a pseudo-terminal, paced.

use std::collections::BTreeMap;
use std::io::Write;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};

use crate::fmu::assignment::parse_assignment;
use crate::fmu::configuration::configuration;
use crate::paths::default_out;
use crate::virtual_drive::args::VirtualDriveArgs;
use crate::virtual_drive::flash::FileFlash;
use crate::virtual_drive::pseudo_terminal::PseudoTerminal;
use crate::virtual_drive::simulator::{TimedNote, VirtualDrive, VirtualDriveSettings};
use crate::virtual_drive::uart::{LineSettings, Wire};
use drive_application::housekeeping::Note;

/// Bytes the drive may have sent ahead of the host's reading before the simulation waits.
const HOST_READ_BACKLOG: usize = 16 * 1024;
/// A host that has not read for this long has stopped reading: its bytes are discarded.
const HOST_GONE: Duration = Duration::from_secs(1);

/// Ticks between two exchanges with the pseudo-terminal and two looks at the clock (0.5 ms).
const TICKS_PER_EXCHANGE: usize = 8;

/// How fast simulated time runs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Pace {
    /// Simulated seconds per wall-clock second.
    Factor(f64),
    /// As fast as the machine runs.
    Max,
}

pub fn parse_pace(s: &str) -> Result<Pace> {
    match s {
        "realtime" => Ok(Pace::Factor(1.0)),
        "max" => Ok(Pace::Max),
        other => match other.parse::<f64>() {
            Ok(f) if f.is_finite() && (0.01..=100.0).contains(&f) => Ok(Pace::Factor(f)),
            _ => bail!("--speed is realtime, max, or a factor from 0.01 to 100 (got `{other}`)"),
        },
    }
}

impl VirtualDriveArgs {
    /// The settings, every value checked before anything starts.
    pub fn settings(&self) -> Result<VirtualDriveSettings> {
        let mut parameters = BTreeMap::new();
        for s in &self.set {
            let (k, v) = parse_assignment(s)?;
            parameters.insert(k, v);
        }
        let config = configuration(&parameters)?;
        if !(self.corrupt_rate.is_finite() && (0.0..=0.1).contains(&self.corrupt_rate)) {
            bail!("--corrupt-rate is a probability from 0 to 0.1 (got {})", self.corrupt_rate);
        }
        if let Some(s) = self.seconds {
            if !(s.is_finite() && s > 0.0) {
                bail!("--seconds must be a positive number (got {s})");
            }
        }
        Ok(VirtualDriveSettings {
            defaults: config.control,
            plant: config.plant,
            line: LineSettings { baud: self.baud, corrupt_rate: self.corrupt_rate, seed: self.seed },
            faults: self.faults.clone(),
        })
    }

    pub fn run(&self) -> Result<bool> {
        let pace = parse_pace(&self.speed)?;
        let settings = self.settings()?;
        let flash_path = self.flash.clone().unwrap_or_else(|| default_out("virtual-drive").join("flash.bin"));
        if let Some(dir) = flash_path.parent().filter(|d| !d.as_os_str().is_empty()) {
            std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
        }
        let flash = FileFlash::open(&flash_path)?;
        let mut drive = VirtualDrive::power_on(&settings, flash)?;
        let mut port = PseudoTerminal::open()?;
        announce(self, &port, &drive, &flash_path, pace)?;
        let mut wire = Wire::default();
        let started = Instant::now();
        let mut behind_said = false;
        loop {
            for _ in 0..TICKS_PER_EXCHANGE {
                drive.tick(&mut wire);
            }
            port.exchange(&mut wire)?;
            wait_for_the_host(&mut port, &mut wire)?;
            for n in drive.take_notes() {
                eprintln!("{}", note_line(&n));
            }
            let simulated = drive.time();
            if self.seconds.is_some_and(|s| simulated >= s) {
                break;
            }
            if let Pace::Factor(f) = pace {
                let due = Duration::from_secs_f64(simulated / f);
                let elapsed = started.elapsed();
                if due > elapsed {
                    std::thread::sleep(due - elapsed);
                } else if !behind_said && elapsed - due > Duration::from_millis(500) {
                    eprintln!(
                        "virtual drive: this machine runs the simulation slower than asked (--speed); time stretches"
                    );
                    behind_said = true;
                }
            }
        }
        let line = drive.line();
        eprintln!(
            "virtual drive stopped after {:.3} s: {} bytes in, {} out, {} corrupted, {} lost unread",
            drive.time(),
            line.bytes_to_drive,
            line.bytes_from_drive,
            line.corrupted,
            port.unread_bytes_lost
        );
        Ok(true)
    }
}

/// The host reads slower than the drive sends (at `--speed max`, or a busy machine): the
/// simulation waits rather than lose bytes, unless no one reads at all.
fn wait_for_the_host(port: &mut PseudoTerminal, wire: &mut Wire) -> Result<()> {
    let since = Instant::now();
    while wire.from_drive.len() > HOST_READ_BACKLOG {
        if since.elapsed() > HOST_GONE {
            port.discard_unread(wire);
            eprintln!("virtual drive: the host stopped reading the port; what it did not read is discarded");
            break;
        }
        std::thread::sleep(Duration::from_millis(1));
        port.exchange(wire)?;
    }
    Ok(())
}

fn announce(
    args: &VirtualDriveArgs,
    port: &PseudoTerminal,
    drive: &VirtualDrive<FileFlash>,
    flash: &std::path::Path,
    pace: Pace,
) -> Result<()> {
    let path = port.path();
    if let Some(f) = &args.port_file {
        std::fs::write(f, path.as_os_str().as_encoded_bytes())
            .with_context(|| format!("cannot write the port's path to {}", f.display()))?;
    }
    if let Some(l) = &args.link {
        if l.symlink_metadata().is_ok() {
            std::fs::remove_file(l).with_context(|| format!("cannot replace {}", l.display()))?;
        }
        std::os::unix::fs::symlink(path, l).with_context(|| format!("cannot link {} to the port", l.display()))?;
    }
    let pace = match pace {
        Pace::Max => "as fast as it runs".to_string(),
        Pace::Factor(1.0) => "real time".to_string(),
        Pace::Factor(f) => format!("{f}× real time"),
    };
    println!("{}", path.display());
    eprintln!(
        "virtual drive on {} ({} Bd, {pace}); {}; flash {}",
        path.display(),
        args.baud,
        drive.boot_params(),
        flash.display()
    );
    std::io::stdout().flush().ok();
    Ok(())
}

/// A housekeeping note as the firmware's log line, with its simulated time.
fn note_line(n: &TimedNote) -> String {
    let what = match n.note {
        Note::OffsetsCalibrated { offsets, bus_voltage, accelerometer_zero } => format!(
            "current offsets {:.1} {:.1} {:.1} counts, bus {bus_voltage:.2} V, accelerometer {}",
            offsets[0],
            offsets[1],
            offsets[2],
            accelerometer_zero
                .map_or("not connected (no zero near mid-scale)".to_string(), |z| format!("zero {z:.1} counts"))
        ),
        Note::FaultsChanged { faults } => format!("faults: {faults}"),
        Note::Alive { ticks, faults, bus_voltage } => {
            format!("alive: {ticks} ticks, faults: {faults}, bus {bus_voltage:.2} V")
        }
    };
    format!("[{:9.4} s] {what}", n.time)
}
