//! The virtual drive's serial port: a pseudo-terminal whose slave side (`/dev/pts/N`) a host
//! program opens as it would open the board's `/dev/ttyACM0`. The master side is ours,
//! non-blocking; we keep the slave open too (raw, no echo), so the port stays usable when a
//! client closes it and opens it again.

use std::io::{ErrorKind, Read, Write};
use std::os::fd::{AsRawFd, OwnedFd};
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use nix::fcntl::{fcntl, FcntlArg, OFlag};
use nix::pty::{grantpt, posix_openpt, ptsname_r, unlockpt, PtyMaster};
use nix::sys::termios::{cfmakeraw, tcgetattr, tcsetattr, SetArg};

use crate::virtual_drive::uart::Wire;

/// What the host side may have written and we not yet taken (the kernel's own buffer holds
/// more): beyond it we leave the bytes in the pseudo-terminal.
const HOST_BACKLOG: usize = 4096;

pub struct PseudoTerminal {
    master: PtyMaster,
    slave: OwnedFd,
    path: PathBuf,
    /// Bytes the drive sent that no one read (discarded after the host stopped reading).
    pub unread_bytes_lost: u64,
}

impl PseudoTerminal {
    pub fn open() -> Result<Self> {
        let master = posix_openpt(OFlag::O_RDWR | OFlag::O_NOCTTY).context("cannot open a pseudo-terminal")?;
        grantpt(&master).context("grantpt")?;
        unlockpt(&master).context("unlockpt")?;
        let path = PathBuf::from(ptsname_r(&master).context("ptsname")?);
        let slave: OwnedFd = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(&path)
            .with_context(|| format!("cannot open {}", path.display()))?
            .into();
        let mut t = tcgetattr(slave.as_raw_fd()).context("tcgetattr")?;
        cfmakeraw(&mut t);
        tcsetattr(slave.as_raw_fd(), SetArg::TCSANOW, &t).context("tcsetattr")?;
        for fd in [master.as_raw_fd(), slave.as_raw_fd()] {
            let flags = OFlag::from_bits_truncate(fcntl(fd, FcntlArg::F_GETFL).context("fcntl")?);
            fcntl(fd, FcntlArg::F_SETFL(flags | OFlag::O_NONBLOCK)).context("fcntl")?;
        }
        Ok(Self { master, slave, path, unread_bytes_lost: 0 })
    }

    /// The port a host program opens.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// No one reads the port: what waits for the host (in the port and on the line) is
    /// discarded, so that the drive can go on.
    pub fn discard_unread(&mut self, wire: &mut Wire) {
        let mut lost = wire.from_drive.len() as u64;
        wire.from_drive.clear();
        let mut chunk = [0u8; 4096];
        while let Ok(n) = nix::unistd::read(self.slave.as_raw_fd(), &mut chunk) {
            if n == 0 {
                break;
            }
            lost += n as u64;
        }
        self.unread_bytes_lost += lost;
    }

    /// Move bytes between the pseudo-terminal and the line's ends.
    pub fn exchange(&mut self, wire: &mut Wire) -> Result<()> {
        let mut chunk = [0u8; 1024];
        while wire.to_drive.len() < HOST_BACKLOG {
            match self.master.read(&mut chunk) {
                Ok(0) => break,
                Ok(n) => wire.to_drive.extend(&chunk[..n]),
                Err(e) if e.kind() == ErrorKind::WouldBlock || e.kind() == ErrorKind::Interrupted => break,
                // EIO: no client has the port open (only our own slave): nothing to read.
                Err(e) if e.raw_os_error() == Some(nix::libc::EIO) => break,
                Err(e) => return Err(e).context("cannot read the pseudo-terminal"),
            }
        }
        while !wire.from_drive.is_empty() {
            let (a, _) = wire.from_drive.as_slices();
            match self.master.write(a) {
                Ok(n) => {
                    wire.from_drive.drain(..n);
                }
                // The port's buffer is full: the bytes wait (the caller stops the simulation
                // until the host reads, or gives up on a host that stopped reading).
                Err(e) if e.kind() == ErrorKind::WouldBlock => break,
                Err(e) if e.kind() == ErrorKind::Interrupted => {}
                Err(e) => return Err(e).context("cannot write the pseudo-terminal"),
            }
        }
        Ok(())
    }
}
