//! The state the control tick and the link share, and the two sides that use it.
//!
//! Per tick ([`Drive::tick`], in the sampling interrupt):
//! 1. take the three sampled shunt currents and the bus voltage, the encoder count and the
//!    break flag;
//! 2. until the current offsets are calibrated (bridge off), feed the calibration instead;
//!    implausible offsets latch a sensing fault and the bridge never comes on;
//! 3. of the three shunts, believe the two the board's shunt choice names under the duties
//!    that were in force when they were sampled;
//! 4. a break (the power stage's own overcurrent comparator) latches a core fault;
//! 5. `Axis::step`; the duties go to the PWM and the gate drive follows the core's `enabled`
//!    at once, so any fault the core sees switches the PWM off within the tick (and while the
//!    parameters are being written to flash, the gate drive stays off);
//! 6. the latest acquisition sample is offered to the link's stream;
//! 7. the watchdog is fed: a loop that stops running resets the chip.
//!
//! Parameter and correction changes (issue 16 item 2): the link side ([`Host`]) builds the
//! new axis in the spare of two axis slots, or the new correction on its own stack, outside
//! the critical section; inside it only checks that the axis is at rest and swaps the slot
//! index (or copies the correction in). Everything else the link does under the critical
//! section is a short copy (telemetry, a sample batch) or a request the core carries out in
//! a few hundred instructions at most.

use core::cell::{RefCell, UnsafeCell};
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use control_core::acquisition_stream::{AcquisitionStream, SampleBatch};
use control_core::current_sensing::CurrentSensing;
use control_core::faults::Faults;
use control_core::params::Params;
use control_core::protocol::{
    handle, DefaultsReason, FieldName, FrameError, ParamsOrigin, RefusalReason, Request, Response, VERSION,
};
use control_core::response_correction::ResponseCorrection;
use control_core::{Axis, AxisInputs, Commands, Mode};
use critical_section::Mutex;

use crate::board::{ParamFlash, PowerStage, CURRENT_CHANNELS};
use crate::link::FrameAssembler;
use crate::param_store::{self, StoreState};

/// What the tick and the link share under the critical section.
pub struct Shared {
    /// The axis slot the tick steps (0 or 1).
    pub active: usize,
    pub commands: Commands,
    pub sensing: CurrentSensing<CURRENT_CHANNELS>,
    pub stream: AcquisitionStream,
    /// The duties written last tick: in force when this tick's currents were sampled.
    pub duties_in_force: [f32; 3],
    /// The bus voltage of the last tick (V), for the log.
    pub bus_voltage: f32,
    /// The parameters are being written to flash: the gate drive stays off.
    pub storing: bool,
}

struct Slot {
    installed: bool,
    value: MaybeUninit<Shared>,
}

/// The drive's state: the shared part behind the critical section, and two axis slots. Lives
/// in a `static` (uninitialised until [`Drive::install`], so its kilobytes go to `.bss`).
pub struct Drive {
    shared: Mutex<RefCell<Slot>>,
    axes: [UnsafeCell<MaybeUninit<Axis>>; 2],
    /// Ticks since start (health, the heartbeat).
    ticks: AtomicU32,
    /// [`Drive::install`] has begun (it hands out the one [`Host`]).
    claimed: AtomicBool,
}

// SAFETY: the active axis slot is touched only under the critical section (through
// `Shared::active`); the spare slot only by the one `Host` (`install` hands out one), which
// alone changes `active`, inside the critical section, after it has finished writing.
unsafe impl Sync for Drive {}

/// Why the drive did not start.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum InstallError {
    /// The defaults themselves do not validate.
    Params(&'static str),
    /// The board's ADC scales are refused.
    Scales,
    /// `install` was called before.
    Twice,
}

impl Default for Drive {
    fn default() -> Self {
        Self::new()
    }
}

impl Drive {
    pub const fn new() -> Self {
        Self {
            shared: Mutex::new(RefCell::new(Slot { installed: false, value: MaybeUninit::uninit() })),
            axes: [UnsafeCell::new(MaybeUninit::uninit()), UnsafeCell::new(MaybeUninit::uninit())],
            ticks: AtomicU32::new(0),
            claimed: AtomicBool::new(false),
        }
    }

    /// Load the stored parameters (or take `defaults`, saying why), build the axis and the
    /// current sensing, and return the link side (once).
    pub fn install<P: PowerStage, F: ParamFlash>(
        &self,
        defaults: Params,
        flash: &mut F,
    ) -> Result<Host<'_>, InstallError> {
        if self.claimed.swap(true, Ordering::AcqRel) {
            return Err(InstallError::Twice);
        }
        let mut params = defaults;
        let (loaded, store) = param_store::load(flash, &mut params);
        let stored = match loaded {
            Ok(sequence) => match Axis::new(params) {
                Ok(axis) => Ok((axis, ParamsOrigin::Stored { sequence })),
                Err(e) => Err(DefaultsReason::Invalid(FieldName::new(e.field()))),
            },
            Err(reason) => Err(reason),
        };
        let (axis, boot_params) = match stored {
            Ok(found) => found,
            Err(reason) => {
                params = defaults;
                (Axis::new(defaults).map_err(|e| InstallError::Params(e.field()))?, ParamsOrigin::Defaults(reason))
            }
        };
        let sensing = CurrentSensing::new(P::SCALES).map_err(|_| InstallError::Scales)?;
        // SAFETY: claimed above, by this call alone, and not installed yet: nothing reads slot
        // 0 (the tick waits for `installed`, set below under the critical section).
        unsafe { (*self.axes[0].get()).write(axis) };
        let shared = Shared {
            active: 0,
            commands: Commands::default(),
            sensing,
            stream: AcquisitionStream::default(),
            duties_in_force: [0.0; 3],
            bus_voltage: 0.0,
            storing: false,
        };
        critical_section::with(|cs| {
            let mut slot = self.shared.borrow_ref_mut(cs);
            slot.value.write(shared);
            slot.installed = true;
        });
        Ok(Host { drive: self, params, boot_params, store, assembler: FrameAssembler::new() })
    }

    /// `f` on the shared state and the active axis, under the critical section (`None` before
    /// [`Drive::install`]).
    pub fn with<R>(&self, f: impl FnOnce(&mut Shared, &mut Axis) -> R) -> Option<R> {
        critical_section::with(|cs| {
            let mut slot = self.shared.borrow_ref_mut(cs);
            if !slot.installed {
                return None;
            }
            // SAFETY: installed, so the value and the active axis slot are initialised; the
            // active slot is touched only under this critical section.
            let shared = unsafe { slot.value.assume_init_mut() };
            let axis = unsafe { (*self.axes[shared.active].get()).assume_init_mut() };
            Some(f(shared, axis))
        })
    }

    /// Ticks since start.
    pub fn ticks(&self) -> u32 {
        self.ticks.load(Ordering::Relaxed)
    }

    /// One control tick (the sequence in the module's documentation); the faults on a
    /// position tick (for the housekeeping), `None` otherwise.
    pub fn tick<P: PowerStage>(&self, stage: &mut P) -> Option<Faults> {
        let sample = stage.take_sample();
        let count = stage.encoder_count();
        let broke = stage.break_tripped();
        let ticks = self.ticks.load(Ordering::Relaxed);
        let position_tick = self
            .with(|s, axis| {
                // The break flag is read (and cleared) every tick: latch it even while calibrating.
                if broke {
                    axis.latch_fault(Faults::HARDWARE_BREAK);
                }
                let Some((shunt_amps, bus_voltage)) = s.sensing.convert(sample.shunts, sample.bus) else {
                    // Calibrating with the bridge off; a failure latches a fault for good.
                    stage.set_outputs(false);
                    if s.sensing.calibrate(sample.shunts).is_err() {
                        axis.latch_fault(Faults::SENSING);
                    }
                    return None;
                };
                s.bus_voltage = bus_voltage;
                let phase_currents = stage.phase_currents(shunt_amps, s.duties_in_force);
                let inputs = AxisInputs { phase_currents, encoder_count: count, bus_voltage };
                let pwm = axis.step(&inputs, &s.commands);
                stage.write_duties(pwm.duties);
                stage.set_outputs(pwm.enabled && !s.storing);
                s.duties_in_force = pwm.duties;
                // The axis's own telemetry, read in place: no per-tick copy.
                let t = axis.telemetry();
                s.stream.offer(&t.sweep.sample);
                let divider = axis.params().rates.position_divider;
                // A u32 counter: a 64-bit modulo is a library call on the Cortex-M4.
                ticks.is_multiple_of(divider).then_some(t.faults)
            })
            .unwrap_or_else(|| {
                stage.set_outputs(false);
                None
            });
        self.ticks.store(ticks.wrapping_add(1), Ordering::Relaxed);
        stage.feed_watchdog();
        position_tick
    }

    /// The current offsets (counts) and the bus voltage, once calibrated.
    pub fn offsets(&self) -> Option<([f32; CURRENT_CHANNELS], f32)> {
        self.with(|s, _| s.sensing.offsets().map(|o| (o, s.bus_voltage))).flatten()
    }

    /// The bus voltage of the last tick (V).
    pub fn bus_voltage(&self) -> f32 {
        self.with(|s, _| s.bus_voltage).unwrap_or(0.0)
    }
}

/// Only while the axis stands still in torque mode at zero torque.
fn at_rest(commands: &Commands, axis: &Axis) -> bool {
    commands.mode == Mode::Torque && commands.torque == 0.0 && axis.telemetry().torque_command == 0.0
}

/// The link side of the drive: one exists ([`Drive::install`] hands it out). It owns the
/// spare axis slot, the parameters in force, the parameter store's state and the frame being
/// received.
pub struct Host<'d> {
    drive: &'d Drive,
    params: Params,
    boot_params: ParamsOrigin,
    store: StoreState,
    assembler: FrameAssembler,
}

impl Host<'_> {
    /// Where the parameters the drive booted with came from.
    pub fn boot_params(&self) -> ParamsOrigin {
        self.boot_params
    }

    /// The parameters in force.
    pub fn params(&self) -> &Params {
        &self.params
    }

    /// One received byte; at the end of a frame, the encoded answer in `out` (its length).
    pub fn receive<F: ParamFlash>(&mut self, byte: u8, flash: &mut F, out: &mut [u8]) -> Option<usize> {
        let response = match self.assembler.push(byte)? {
            Ok(request) => self.handle(request, flash),
            Err(e) => Response::FrameError(e),
        };
        crate::link::encode_response(&response, out)
    }

    /// The next batch of streamed samples as a frame in `out` (its length), if one is ready.
    pub fn stream_frame(&mut self, out: &mut [u8]) -> Option<usize> {
        let batch: SampleBatch = self.drive.with(|s, _| s.stream.take_batch()).flatten()?;
        crate::link::encode_response(&Response::Samples(batch), out)
    }

    /// Carry out one request.
    pub fn handle<F: ParamFlash>(&mut self, request: Request, flash: &mut F) -> Response {
        match request {
            Request::Hello { version } if version != VERSION => {
                Response::FrameError(FrameError::Version { got: version })
            }
            Request::Hello { .. } => Response::Hello { version: VERSION, boot_params: self.boot_params },
            Request::SetParams(p) => self.set_params(p),
            Request::LoadCorrection(c) => self.load_correction(&c),
            Request::SaveParams => self.save_params(flash),
            other => self
                .drive
                .with(|s, axis| handle(axis, &mut s.commands, &mut s.stream, other))
                .unwrap_or(Response::FrameError(FrameError::Message)),
        }
    }

    /// The new axis is built in the spare slot with the critical section open; inside it, the
    /// rest check and the swap of the slot index.
    fn set_params(&mut self, p: Params) -> Response {
        let Some((active, rest)) = self.drive.with(|s, axis| (s.active, at_rest(&s.commands, axis))) else {
            return Response::FrameError(FrameError::Message);
        };
        if !rest {
            return Response::Refused(RefusalReason::Busy);
        }
        let new = match Axis::new(p) {
            Ok(new) => new,
            Err(e) => return Response::Refused(RefusalReason::InvalidParams(FieldName::new(e.field()))),
        };
        let spare = 1 - active;
        // SAFETY: the spare slot is not the active one, and only this `Host` (there is one)
        // changes which is active.
        unsafe { (*self.drive.axes[spare].get()).write(new) };
        let swapped = self
            .drive
            .with(|s, axis| {
                let rest = at_rest(&s.commands, axis);
                if rest {
                    s.active = spare;
                }
                rest
            })
            .unwrap_or(false);
        if !swapped {
            return Response::Refused(RefusalReason::Busy);
        }
        self.params = p;
        Response::Done
    }

    /// The correction's sections are designed with the critical section open; inside it, the
    /// rest check and the copy.
    fn load_correction(&mut self, c: &control_core::response_correction::CorrectionParams) -> Response {
        let refused = Response::Refused(RefusalReason::Correction);
        let Ok(built) = ResponseCorrection::new(c, self.params.rates.position_period()) else {
            return refused;
        };
        match self.drive.with(|_, axis| axis.install_correction(&built, c)) {
            Some(Ok(())) => {
                self.params.correction = *c;
                Response::Done
            }
            _ => refused,
        }
    }

    /// Write the parameters in force to flash (at rest; the gate drive off meanwhile).
    fn save_params<F: ParamFlash>(&mut self, flash: &mut F) -> Response {
        let started = self.drive.with(|s, axis| {
            let rest = at_rest(&s.commands, axis);
            s.storing = rest;
            rest
        });
        if started != Some(true) {
            return Response::Refused(RefusalReason::Busy);
        }
        let result = param_store::save(flash, &mut self.store, &self.params);
        self.drive.with(|s, _| s.storing = false);
        match result {
            Ok(()) => Response::Done,
            Err(e) => Response::Refused(RefusalReason::Storage(e)),
        }
    }

    /// The parameter store's state (which page holds the newest record).
    pub fn store(&self) -> StoreState {
        self.store
    }
}
