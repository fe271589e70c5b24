//! The virtual drive: the firmware's application (`drive_application`: the tick, offset
//! calibration, fault latch, link, streaming, parameter changes and storage, housekeeping) on
//! the simulated board, tick by tick, with its serial line.
//!
//! Per tick of the board's PWM rate:
//! 1. faults due now happen (`--fault`);
//! 2. the sampling interrupt: `Drive::tick` on the board, then the housekeeping on a position
//!    tick (its notes are kept with their time);
//! 3. the plant advances over the period;
//! 4. the line moves a tick's worth of bytes each way; the link task (as the firmware's
//!    `link_task`) hands received bytes to the application and writes its answers, and every
//!    2 ms sends the sample batches that are ready — while its transmit buffer is full it waits
//!    and serves nothing else, as `write_all` does on the G474.
//!
//! The link side runs between two ticks here, where on the G474 it runs at a lower priority
//! and the tick interrupts it: what it does (build a new axis, design a correction) takes no
//! simulated time. The drive application's own tests measure what that costs in ticks.

use std::collections::VecDeque;

use anyhow::{anyhow, Result};
use control_core::protocol::ParamsOrigin;
use control_core::Params;
use drive_application::board::ParamFlash;
use drive_application::housekeeping::{Housekeeping, Note};
use drive_application::link::OUT_BYTES;
use drive_application::{Drive, Host, InstallError};
use servo_axis::plant::{Plant, PlantParams};

use crate::virtual_drive::board::{SimulatedBoard, TICK_HZ};
use crate::virtual_drive::faults::ScheduledFault;
use crate::virtual_drive::uart::{LineCounters, LineSettings, Uart, Wire};

/// The firmware's USART2 receive buffer: bytes beyond it are lost while the link task waits.
pub const RECEIVE_BUFFER: usize = 1024;
/// The link task's stream poll (the firmware's 2 ms ticker).
pub const STREAM_POLL_S: f64 = 2e-3;

/// What the virtual drive is built from.
#[derive(Clone, Debug)]
pub struct VirtualDriveSettings {
    /// The parameters it boots with when its flash holds none (the board's limits applied,
    /// as the firmware applies them to its defaults).
    pub defaults: Params,
    pub plant: PlantParams,
    pub line: LineSettings,
    pub faults: Vec<ScheduledFault>,
}

/// A note of the housekeeping and the simulated time it was made at (s).
#[derive(Clone, Copy, Debug)]
pub struct TimedNote {
    pub time: f64,
    pub note: Note,
}

pub struct VirtualDrive<F: ParamFlash> {
    drive: &'static Drive,
    host: Host<'static>,
    pub board: SimulatedBoard,
    flash: F,
    uart: Uart,
    received: VecDeque<u8>,
    /// The link task is sending sample batches (until none is ready).
    streaming_out: bool,
    housekeeping: Housekeeping,
    /// Faults still to come, latest first.
    faults: Vec<ScheduledFault>,
    ticks: u64,
    ticks_per_poll: u64,
    out: [u8; OUT_BYTES],
    notes: Vec<TimedNote>,
    /// Bytes lost because the receive buffer was full.
    pub receive_overruns: u64,
}

fn install_error(e: InstallError) -> anyhow::Error {
    match e {
        InstallError::Params(field) => anyhow!("the drive's default parameters are refused: {field}"),
        InstallError::Scales => anyhow!("the board's ADC scales are refused"),
        InstallError::Twice => anyhow!("the drive was installed twice"),
    }
}

impl<F: ParamFlash> VirtualDrive<F> {
    /// Power on: the drive loads its parameters from `flash` (or boots with the defaults and
    /// says why), the plant stands still.
    pub fn power_on(settings: &VirtualDriveSettings, mut flash: F) -> Result<Self> {
        let period = 1.0 / TICK_HZ as f64;
        if (settings.plant.tick - period).abs() > 1e-12 * period {
            return Err(anyhow!(
                "the virtual drive runs at the board's PWM rate, {TICK_HZ} Hz: the plant's tick must be 1/{TICK_HZ} s \
                 (leave ctrl.current_loop_hz at {TICK_HZ})"
            ));
        }
        let plant = Plant::new(settings.plant).map_err(|e| anyhow!("plant: {e}"))?;
        // One drive per power-on, for the life of the process (the firmware's is a `static`):
        // a few tens of kilobytes.
        let drive: &'static Drive = Box::leak(Box::new(Drive::new()));
        // A drive boots with nothing measured: its motor is commissioned over the link
        // (`servo commission --device`), or loaded from a set it saved.
        let defaults = power_stage::ratings::with_board_limits(Params {
            commissioned: false,
            encoder_mounting: Default::default(),
            ..settings.defaults
        });
        let host = drive.install::<SimulatedBoard, F>(defaults, &mut flash).map_err(install_error)?;
        let mut faults = settings.faults.clone();
        faults.sort_by(|a, b| b.at.total_cmp(&a.at));
        Ok(Self {
            drive,
            host,
            board: SimulatedBoard::new(plant),
            flash,
            uart: Uart::new(settings.line),
            received: VecDeque::new(),
            streaming_out: false,
            housekeeping: Housekeeping::default(),
            faults,
            ticks: 0,
            ticks_per_poll: (STREAM_POLL_S * TICK_HZ as f64).round() as u64,
            out: [0; OUT_BYTES],
            notes: Vec::new(),
            receive_overruns: 0,
        })
    }

    /// Schedule one more fault (its time from power-on, as the settings' are).
    pub fn schedule_fault(&mut self, fault: ScheduledFault) {
        self.faults.push(fault);
        self.faults.sort_by(|a, b| b.at.total_cmp(&a.at));
    }

    /// Power off: the flash, to power on again with.
    pub fn power_off(self) -> F {
        self.flash
    }

    /// The parameter flash, as it is now (to read what a save wrote).
    pub fn flash_mut(&mut self) -> &mut F {
        &mut self.flash
    }

    pub fn boot_params(&self) -> ParamsOrigin {
        self.host.boot_params()
    }

    /// The parameters in force.
    pub fn params(&self) -> &Params {
        self.host.params()
    }

    pub fn tick_period(&self) -> f64 {
        1.0 / TICK_HZ as f64
    }

    /// Simulated time since power-on (s).
    pub fn time(&self) -> f64 {
        self.ticks as f64 * self.tick_period()
    }

    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    pub fn line(&self) -> LineCounters {
        self.uart.counters
    }

    /// The line corrupts each byte, each way, with probability `rate` from now on.
    pub fn set_line_corrupt_rate(&mut self, rate: f64) {
        self.uart.set_corrupt_rate(rate);
    }

    pub fn line_capacity(&self) -> f64 {
        self.uart.capacity()
    }

    /// The housekeeping's notes since the last call.
    pub fn take_notes(&mut self) -> Vec<TimedNote> {
        std::mem::take(&mut self.notes)
    }

    /// `f` on the drive's axis, as the link side sees it (tests, the twin comparison).
    pub fn with_axis<R>(&self, f: impl FnOnce(&control_core::Axis) -> R) -> Option<R> {
        self.drive.with(|_, axis| f(axis))
    }

    /// One tick of the board (see the module's documentation).
    pub fn tick(&mut self, wire: &mut Wire) {
        let now = self.time();
        while self.faults.last().is_some_and(|f| f.at <= now) {
            let f = self.faults.pop().expect("checked above");
            self.board.inject(f.fault);
        }
        if let Some(faults) = self.drive.tick(&mut self.board) {
            let notes = &mut self.notes;
            self.housekeeping.on_position_tick(self.drive, faults, |note| notes.push(TimedNote { time: now, note }));
        }
        self.board.advance();
        let dt = self.tick_period();
        let (received, overruns) = (&mut self.received, &mut self.receive_overruns);
        self.uart.receive(wire, dt, |b| {
            if received.len() < RECEIVE_BUFFER {
                received.push_back(b);
            } else {
                *overruns += 1;
            }
        });
        self.link_task();
        self.uart.send(wire, dt);
        self.ticks += 1;
    }

    /// The firmware's link task for one tick.
    fn link_task(&mut self) {
        if self.ticks.is_multiple_of(self.ticks_per_poll) {
            self.streaming_out = true;
        }
        while self.streaming_out && self.uart.may_write() {
            match self.host.stream_frame(&mut self.out) {
                Some(n) => self.uart.write(&self.out[..n]),
                None => self.streaming_out = false,
            }
        }
        while !self.streaming_out && self.uart.may_write() {
            let Some(b) = self.received.pop_front() else {
                break;
            };
            if let Some(n) = self.host.receive(b, &mut self.flash, &mut self.out) {
                self.uart.write(&self.out[..n]);
            }
        }
    }
}
