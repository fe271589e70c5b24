//! The state the control tick and the link share, and the two sides that use it.
//!
//! Per tick ([`Drive::tick`], in the sampling interrupt):
//! 1. take the three sampled shunt currents, the bus voltage and the accelerometer, the
//!    encoder count and the break flag;
//! 2. until the current offsets are calibrated (bridge off), feed the calibration instead
//!    (the accelerometer's zero with them); implausible current offsets latch a sensing fault
//!    and the bridge never comes on;
//! 3. of the three shunts, believe the two the board's shunt choice names under the duties
//!    that were in force when they were sampled;
//! 4. a break (the power stage's own overcurrent comparator) latches a core fault;
//! 5. `Axis::step`; the duties go to the PWM and the gate drive follows the core's `enabled`
//!    at once, so any fault the core sees switches the PWM off within the tick (and from the
//!    tick after a save starts, the gate drive stays off until it ends; the flash erase itself
//!    may start before that tick, so the board's [`ParamFlash`] switches the gate drive off
//!    around each erase and write — the G474's single bank stalls the interrupt meanwhile);
//! 6. the latest acquisition sample is offered to the link's stream;
//! 7. the watchdog is fed: a loop that stops running resets the chip.
//!
//! Parameter and correction changes (issue 16 item 2): the link side ([`Host`]) builds the
//! new axis in the spare of two axis slots, or the new correction on its own stack, outside
//! the critical section; inside it only checks that the axis is at rest (no fault latched,
//! no sweep running) and swaps the slot index, or copies the correction in (which the
//! correction filter refuses while pulses are in flight through it). Everything else the link does under the critical
//! section is a short copy (telemetry, a sample batch) or a request the core carries out in
//! a few hundred instructions at most.

use core::cell::{RefCell, UnsafeCell};
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicBool, AtomicU32, Ordering};

use control_core::acquisition_stream::{AcquisitionStream, SampleBatch};
use control_core::current_sensing::CurrentSensing;
use control_core::faults::Faults;
use control_core::params::{ParamError, Params};
use control_core::protocol::{
    handle, DefaultsReason, DriveTelemetry, FieldName, FrameError, ParamsOrigin, RefusalReason, Request, Response,
    VERSION,
};
use control_core::response_correction::ResponseCorrection;
use control_core::{Axis, AxisInputs, Commands};
use critical_section::Mutex;

use crate::accelerometer_input::{accelerometer_scale, AccelerometerInput};
use crate::board::{ParamFlash, PowerStage, CURRENT_CHANNELS};
use crate::link::FrameAssembler;
use crate::param_store::{self, StoreState};

/// What the tick and the link share under the critical section.
pub struct Shared {
    /// The axis slot the tick steps (0 or 1). Private: only [`Host`] (one exists) changes it,
    /// and only to a slot it has built; the tick relies on that.
    active: usize,
    pub commands: Commands,
    pub sensing: CurrentSensing<CURRENT_CHANNELS>,
    /// The machine-end accelerometer's input (its scale follows the parameters in force).
    pub accelerometer: AccelerometerInput,
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
    /// The two axis slots, each built in place by `Axis::new_in` (no axis ever on a stack):
    /// the active one always holds a built axis.
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
    /// current sensing, and return the link side (once). Never inlined, nor are the parameter
    /// changes below: an axis is kilobytes, and a caller's stack frame must not keep room for
    /// one (the G474's stack and statics share 128 KiB).
    #[inline(never)]
    pub fn install<P: PowerStage, F: ParamFlash>(
        &self,
        defaults: Params,
        flash: &mut F,
    ) -> Result<Host<'_>, InstallError> {
        let board_hz = P::TICK_HZ;
        if self.claimed.swap(true, Ordering::AcqRel) {
            return Err(InstallError::Twice);
        }
        let mut params = defaults;
        let (loaded, store) = param_store::load(flash, &mut params);
        let mut boot_params = match loaded {
            Ok(sequence) => ParamsOrigin::Stored { sequence },
            Err(reason) => ParamsOrigin::Defaults(reason),
        };
        // The axis built in slot 0, where it lives: the stored set, or the defaults if it is
        // refused.
        // SAFETY: claimed above, by this call alone, and not installed yet: nothing reads slot
        // 0 (the tick waits for `installed`, set below under the critical section).
        let slot = unsafe { &mut *self.axes[0].get() };
        loop {
            let built = match at_board_rate(&params, board_hz) {
                Ok(()) => build_axis(slot, &params),
                Err(field) => Err(field),
            };
            match built {
                Ok(()) => break,
                Err(field) if matches!(boot_params, ParamsOrigin::Stored { .. }) => {
                    boot_params = ParamsOrigin::Defaults(DefaultsReason::Invalid(FieldName::new(field)));
                    params = defaults;
                }
                Err(field) => return Err(InstallError::Params(field)),
            }
        }
        let sensing = CurrentSensing::new(P::SCALES).map_err(|_| InstallError::Scales)?;
        let accelerometer =
            AccelerometerInput::new(P::SCALES.full_scale, P::ACCELEROMETER_VOLTS_PER_COUNT, &params.accelerometer);
        self.share(sensing, accelerometer);
        Ok(Host {
            drive: self,
            params,
            boot_params,
            store,
            assembler: FrameAssembler::new(),
            board_hz,
            accelerometer_volts_per_count: P::ACCELEROMETER_VOLTS_PER_COUNT,
            stack_gauge: None,
        })
    }

    /// The shared state, built in place inside the section (at boot, before the tick runs):
    /// the sample ring is kilobytes, and a `Shared` built first on the stack would be a second
    /// copy. Never inlined, so that `install`'s frame does not keep room for it while the axis
    /// is built.
    #[inline(never)]
    fn share(&self, sensing: CurrentSensing<CURRENT_CHANNELS>, accelerometer: AccelerometerInput) {
        critical_section::with(|cs| {
            let mut slot = self.shared.borrow_ref_mut(cs);
            let shared = slot.value.as_mut_ptr();
            // SAFETY: `shared` points into the slot, valid for writes and aligned (a
            // `MaybeUninit` has its type's layout); the stream is built where it is, then
            // every other field is written.
            unsafe {
                AcquisitionStream::new_in(&mut *core::ptr::addr_of_mut!((*shared).stream).cast());
                control_core::write_fields!(shared, Shared {
                    active: 0,
                    commands: Commands::default(),
                    sensing: sensing,
                    accelerometer: accelerometer,
                    duties_in_force: [0.0; 3],
                    bus_voltage: 0.0,
                    storing: false,
                    ; stream
                });
            }
            slot.installed = true;
        });
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
            Some(f(shared, unsafe { (*self.axes[shared.active].get()).assume_init_mut() }))
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
                    s.accelerometer.calibrate(sample.accelerometer);
                    if s.sensing.calibrate(sample.shunts).is_err() {
                        axis.latch_fault(Faults::SENSING);
                    }
                    return None;
                };
                s.bus_voltage = bus_voltage;
                let phase_currents = stage.phase_currents(shunt_amps, s.duties_in_force);
                let load_acceleration = s.accelerometer.convert(sample.accelerometer);
                let inputs = AxisInputs { phase_currents, encoder_count: count, bus_voltage, load_acceleration };
                let pwm = axis.step(&inputs, &s.commands);
                stage.write_duties(pwm.duties);
                stage.set_outputs(pwm.enabled && !s.storing);
                s.duties_in_force = pwm.duties;
                // The sweep's sample and the faults read in place: no per-tick record.
                s.stream.offer(&axis.sweep().status().sample);
                let divider = axis.params().rates.position_divider;
                // A u32 counter: a 64-bit modulo is a library call on the Cortex-M4.
                ticks.is_multiple_of(divider).then(|| axis.faults())
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

    /// The accelerometer's zero (counts) once calibrated: `Some(None)` when no sensor was found.
    pub fn accelerometer_zero(&self) -> Option<Option<f32>> {
        self.with(|s, _| s.accelerometer.zero()).flatten()
    }

    /// The bus voltage of the last tick (V).
    pub fn bus_voltage(&self) -> f32 {
        self.with(|s, _| s.bus_voltage).unwrap_or(0.0)
    }
}

/// The core's own request handling, for the requests the drive does not handle itself (its
/// `SetParams` arm, never taken here, rebuilds the axis in place). Never inlined, so that the
/// link task's frame does not carry the core's. The request by reference: taken by
/// value, its copy into the argument (480 bytes, part of it byte by byte) could be placed
/// inside the critical section (1 470 instructions with interrupts off on the Cortex-M4).
#[inline(never)]
fn core_handle(axis: &mut Axis, s: &mut Shared, request: &Request) -> Response {
    handle(axis, &mut s.commands, &mut s.stream, *request)
}

/// The axis of `params` built in `slot`, where it lives; the first refused field if refused.
fn build_axis(slot: &mut MaybeUninit<Axis>, params: &Params) -> Result<(), &'static str> {
    Axis::new_in(slot, params).map(|_| ()).map_err(|e| e.field())
}

/// The parameters run the tick at the board's PWM rate (the field that says otherwise).
fn at_board_rate(params: &Params, board_hz: f32) -> Result<(), &'static str> {
    if params.rates.current_loop_hz == board_hz {
        Ok(())
    } else {
        Err("rates.current_loop_hz")
    }
}

/// See [`control_core::protocol::parameters_may_change`]: at rest, no fault latched (a new
/// axis must not clear one), no sweep running.
fn at_rest(commands: &Commands, axis: &Axis) -> bool {
    control_core::protocol::parameters_may_change(commands, axis)
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
    /// The board's PWM rate: the only current-loop rate the drive accepts.
    board_hz: f32,
    /// The board's accelerometer input: volts per count.
    accelerometer_volts_per_count: f32,
    /// The board's measure of its unused stack (bytes), if it has one: see
    /// [`Host::report_stack_with`].
    stack_gauge: Option<StackGauge>,
}

/// A board's measure of its stack: the bytes never touched since boot (see
/// `DriveTelemetry::stack_free_bytes`).
pub type StackGauge = fn() -> u32;

impl Host<'_> {
    /// Where the parameters the drive booted with came from.
    pub fn boot_params(&self) -> ParamsOrigin {
        self.boot_params
    }

    /// The telemetry reports `gauge`'s unused stack from now on (a board that paints its stack
    /// gives it; without one the telemetry says `None`).
    pub fn report_stack_with(&mut self, gauge: StackGauge) {
        self.stack_gauge = Some(gauge);
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
            // The link side's copy: no section.
            Request::GetParams => Response::Params(self.params),
            // One copy of the telemetry inside the section; the answer is built outside, with the
            // newest record of the parameter store (the link side's own state) and the stack's
            // measure (a scan with interrupts on).
            Request::GetTelemetry => match self.drive.with(|_, axis| axis.telemetry()) {
                Some(axis) => Response::Telemetry(DriveTelemetry {
                    axis,
                    params_record: self.params_record(),
                    stack_free_bytes: self.stack_gauge.map(|gauge| gauge()),
                }),
                None => Response::FrameError(FrameError::Message),
            },
            other => self
                .drive
                .with(|s, axis| core_handle(axis, s, &other))
                .unwrap_or(Response::FrameError(FrameError::Message)),
        }
    }

    /// The new axis is built in the spare slot with the critical section open; inside it, the
    /// rest check and the swap of the slot index.
    #[inline(never)]
    fn set_params(&mut self, p: Params) -> Response {
        let Some((active, rest)) = self.drive.with(|s, axis| (s.active, at_rest(&s.commands, axis))) else {
            return Response::FrameError(FrameError::Message);
        };
        if !rest {
            return Response::Refused(RefusalReason::Busy);
        }
        if at_board_rate(&p, self.board_hz).is_err() {
            return Response::Refused(RefusalReason::LoopRate { board_hz: self.board_hz });
        }
        let spare = 1 - active;
        // The accelerometer's scale for the new sensitivity, found here; stored with the swap.
        let accelerometer_scale = accelerometer_scale(self.accelerometer_volts_per_count, &p.accelerometer);
        // SAFETY: the spare slot is not the active one, and only this `Host` (there is one)
        // changes which is active.
        let slot = unsafe { &mut *self.drive.axes[spare].get() };
        if let Err(field) = build_axis(slot, &p) {
            return Response::Refused(RefusalReason::InvalidParams(FieldName::new(field)));
        }
        // The board's rate is fixed: a sweep these parameters cannot run is refused now, by
        // name (an axis that is only built checks it when the sweep starts).
        if let Err(e) = p.validate_sweep() {
            return Response::Refused(RefusalReason::InvalidParams(FieldName::new(ParamError::Sweep(e).field())));
        }
        let swapped = self
            .drive
            .with(|s, axis| {
                let rest = at_rest(&s.commands, axis);
                if rest {
                    s.active = spare;
                    s.accelerometer.set_scale(accelerometer_scale);
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
    /// rest check and the copy of the sections in use; in a second one, the record of it in
    /// the axis's parameters.
    #[inline(never)]
    fn load_correction(&mut self, c: &control_core::response_correction::CorrectionParams) -> Response {
        let refused = Response::Refused(RefusalReason::Correction);
        let Ok(built) = ResponseCorrection::new(c, self.params.rates.position_period()) else {
            return refused;
        };
        match self.drive.with(|_, axis| axis.install_correction(&built)) {
            Some(Ok(())) => {
                // A second section: the tick never reads the parameters' correction.
                self.drive.with(|_, axis| axis.record_correction(c));
                self.params.correction = *c;
                Response::Done
            }
            _ => refused,
        }
    }

    /// Write the parameters in force to flash (at rest; the gate drive off meanwhile).
    #[inline(never)]
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
            Ok(sequence) => Response::Saved { sequence },
            Err(e) => Response::Refused(RefusalReason::Storage(e)),
        }
    }

    /// The parameter store's state (which page holds the newest record).
    pub fn store(&self) -> StoreState {
        self.store
    }

    /// The sequence number of the newest record in flash (loaded at boot or written since),
    /// as the telemetry reports it.
    pub fn params_record(&self) -> Option<u32> {
        self.store.newest.map(|(_, sequence)| sequence)
    }
}
