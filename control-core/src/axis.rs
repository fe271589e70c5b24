//! One servo axis: the three cascaded loops, called once per base tick.

use core::mem::MaybeUninit;
use core::num::NonZeroU32;

use crate::command_path::{CommandPath, Move};
use crate::commissioning::{
    Commissioning, CommissioningFault, CommissioningInputs, CommissioningSettings, CommissioningStatus,
};
use crate::current_loop::{CurrentLoop, CurrentLoopOutput};
use crate::encoder::{EncoderTracker, EncoderUpdate};
use crate::excitation::{InjectionPoint, SineGenerator};
use crate::faults::Faults;
use crate::friction_compensation::FrictionCompensation;
use crate::params::{Limits, ParamError, Params};
use crate::phase_shifted_sweep::{PhaseShiftedSweep, SweepError, SweepMeasure, SweepStatus};
use crate::position_loop::PositionLoop;
use crate::ranges::{check_f32, check_position, Quantity, RangeError, MAX_SPEED};
use crate::reference_frames::Dq;
use crate::response_correction::{CorrectionError, CorrectionParams, ResponseCorrection};
use crate::stop_sequence::{Refusal, SequenceEvent, SequenceStatus, StopSequence};
use crate::velocity_loop::VelocityLoop;
use crate::TAU;

/// Control mode.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Mode {
    /// Torque command drives the current loop directly.
    #[default]
    Torque,
    /// Velocity command drives the velocity loop.
    Velocity,
    /// Position command drives the position loop.
    Position,
    /// The stop / zero-servo / fine-adjust sequence drives the velocity loop (seed 004).
    Sequence,
}

impl Mode {
    /// The mode of a `mode` input code: 0 torque, 1 velocity, 2 position, 3 stop sequence.
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(Self::Torque),
            1 => Some(Self::Velocity),
            2 => Some(Self::Position),
            3 => Some(Self::Sequence),
            _ => None,
        }
    }

    /// The inverse of [`Self::from_code`].
    pub fn code(self) -> i32 {
        match self {
            Self::Torque => 0,
            Self::Velocity => 1,
            Self::Position => 2,
            Self::Sequence => 3,
        }
    }
}

/// Sensor readings for one tick.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AxisInputs {
    /// Phase currents a and b (A).
    pub phase_currents: [f32; 2],
    /// Raw, wrapping encoder counter.
    pub encoder_count: i32,
    /// DC-bus voltage (V).
    pub bus_voltage: f32,
    /// Machine-end angular acceleration from a removable accelerometer (rad/s², 0 without
    /// one): read only by a sweep with the machine-end acceleration measure (seed 001's
    /// identification), never by the loops, so a missing or faulty instrument cannot move the
    /// axis (a non-finite reading latches nothing; it reaches the host in the samples).
    pub load_acceleration: f32,
}

/// Set-points; which one is used depends on `mode`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Commands {
    pub mode: Mode,
    /// Position input in encoder counts: streamed (its increments are followed) when
    /// `move_speed` is 0, else the target of a positioning move.
    pub position: i64,
    /// Positioning speed (rad/s, motor side; the sign is ignored); 0 streams `position`.
    pub move_speed: f32,
    /// Jog speed (rad/s, signed); non-zero overrides `position`.
    pub jog_velocity: f32,
    /// Velocity command (rad/s, motor side).
    pub velocity: f32,
    /// Torque command (Nm).
    pub torque: f32,
}

impl Commands {
    /// Every set-point within its range (`crate::ranges`); the first one outside is named.
    pub fn validate(&self) -> Result<(), RangeError> {
        check_position(Quantity::Position, self.position)?;
        check_f32(Quantity::MoveSpeed, self.move_speed)?;
        check_f32(Quantity::JogVelocity, self.jog_velocity)?;
        check_f32(Quantity::Velocity, self.velocity)?;
        check_f32(Quantity::Torque, self.torque)
    }
}

/// Inverter command for the next PWM period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PwmOutput {
    pub duties: [f32; 3],
    /// False when a fault has switched the bridge off.
    pub enabled: bool,
}

/// N·m per unit of [`Telemetry::torque_command_sum`]: 2⁻¹⁶ (a power of two, so that the
/// scaling is exact; each tick's count truncated toward zero, a bias under 1.6·10⁻⁵ N·m, and
/// converted as an `i32`, one instruction on the Cortex-M4: a torque beyond ±32 768 N·m
/// counts as that). 10 N·m held wraps the sum after about 28 years at 16 kHz.
pub const TORQUE_SUM_UNIT: f32 = 1.0 / 65_536.0;

/// Everything worth recording about one tick.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Telemetry {
    pub tick: u64,
    pub mode: Mode,
    pub position: i64,
    /// Position command after interpolation and acc/dec filter (counts).
    pub position_command: i64,
    /// Its pulses in the last position tick.
    pub command_pulses: i64,
    pub velocity_estimate: f32,
    pub velocity_reference: f32,
    pub following_error: f32,
    pub torque_command: f32,
    /// Every tick's torque command summed since the axis was built, in units of
    /// [`TORQUE_SUM_UNIT`] (wrapping): the mean torque command between two records is the
    /// (wrapping) difference of their sums over the difference of their ticks, however rarely
    /// the records are read (a host's polls cannot average a 16 kHz signal; this can, exactly).
    pub torque_command_sum: i64,
    pub current_reference: Dq,
    pub current: Dq,
    pub voltage: Dq,
    pub voltage_saturated: bool,
    pub faults: Faults,
    /// Stop sequence status (meaningful in [`Mode::Sequence`]).
    pub sequence: SequenceStatus,
    /// Frequency-response sweep status and last acquisition sample.
    pub sweep: SweepStatus,
    /// The commissioning sequence's state, from its start until the axis is built again.
    pub commissioning: Option<CommissioningStatus>,
}

/// What the tick needs of the parameters outside the loops, derived once by [`Axis::new`].
#[derive(Clone, Copy, Debug)]
#[repr(C)]
struct TickSettings {
    /// Base ticks per velocity, position, acquisition and PRBS-chip tick.
    dividers: [u32; 4],
    /// Every divider a power of two (the defaults: 2, 4, 4, 1): each slower tick is due when
    /// the tick count's low bits under its mask (`divider − 1`) are zero, and no phase is
    /// counted. Otherwise the phases are counted (`counted_phases`).
    due_masks: [u32; 4],
    counted_phases: bool,
    /// Encoder count to rad.
    rad_per_count: f32,
    /// Velocity-loop period (s).
    velocity_period: f32,
    /// Encoder counts per position tick at 1 rad/s (speeds to the interpolator's pulses).
    counts_per_position_tick: f32,
    limits: Limits,
    /// The sweep measures the machine-end acceleration (`SweepMeasure::MachineAcceleration`):
    /// with torque-command injection it relates the torque from the measured q current (this,
    /// N·m/A, times iq) to it, with position-command injection the injection; 0 when it
    /// measures the loop's signals (one field for both: the every-tick test stays one compare).
    measured_torque_constant: f32,
}

impl TickSettings {
    fn new(p: &Params) -> Self {
        let dividers =
            [p.rates.velocity_divider, p.rates.position_divider, p.sweep.acquisition_divider, p.sweep.prbs_divider];
        Self {
            dividers,
            due_masks: dividers.map(|d| d.wrapping_sub(1)),
            counted_phases: !dividers.iter().all(|d| d.is_power_of_two()),
            rad_per_count: TAU / p.encoder_counts_per_rev as f32,
            velocity_period: p.rates.velocity_period(),
            counts_per_position_tick: p.counts_per_position_tick(),
            limits: p.limits,
            measured_torque_constant: if p.sweep.measure == SweepMeasure::MachineAcceleration {
                p.motor.torque_constant()
            } else {
                0.0
            },
        }
    }
}

/// Which of the slower ticks fall on this base tick.
#[derive(Clone, Copy)]
struct Due {
    velocity: bool,
    position: bool,
    acquisition: bool,
    prbs_chip: bool,
}

/// What the inner loop applied on the last tick: the telemetry's per-tick part.
#[derive(Clone, Copy, Debug, Default)]
struct Applied {
    /// Torque command with the injections (Nm).
    torque_command: f32,
    current_reference: Dq,
    current: Dq,
    voltage: Dq,
    voltage_saturated: bool,
}

/// What sensing found on this tick.
struct Sensed {
    faults: Faults,
    /// The motion speeds within their range (a command that is not has latched a fault and
    /// must not reach the interpolator's carry).
    speeds_in_range: bool,
    /// Encoder position (counts).
    position: i64,
}

/// The position set-point within its range (`crate::ranges`).
#[inline(always)]
fn position_in_range(commands: &Commands) -> bool {
    // −MAX ≤ x ≤ MAX as one unsigned compare of x + MAX (every value outside wraps above
    // 2·MAX, far below 2⁶³): fewer instructions than the 64-bit absolute value.
    const MAX: i64 = crate::ranges::MAX_POSITION_COUNTS;
    commands.position.wrapping_add(MAX) as u64 <= 2 * MAX as u64
}

/// What the inner loop produced on this tick.
struct InnerLoop {
    /// Torque command with the injections (Nm).
    torque: f32,
    current_reference: Dq,
    out: CurrentLoopOutput,
}

/// In C order, the per-tick scalars and loops first and the big blocks last (the sweep and
/// its result table at the end): with Rust's own order the every-feature tick took 2–3 more
/// instructions on the Cortex-M4 (`servo bench firmware`; probably address arithmetic for hot
/// fields placed beyond the immediate offsets of the FPU's loads, ±1020 bytes).
///
/// Not `Copy`: an axis is kilobytes (the acc/dec filter's and the sweep's tables); clone it
/// where a copy is meant.
#[derive(Clone, Debug)]
#[repr(C)]
pub struct Axis {
    /// Ticks since the last velocity, position, acquisition and PRBS-chip tick (`tick` modulo
    /// each divider, counted: a 64-bit modulo is software on a Cortex-M4), where a divider is
    /// not a power of two (see `TickSettings::due_masks`; unused otherwise).
    phases: [u32; 4],
    tick: u64,
    position_at_velocity_tick: i64,
    velocity_estimate: f32,
    velocity_reference: f32,
    torque_command: f32,
    /// The voltage circle limited the current loop's output on a tick since the last
    /// acquisition tick: the sweep's flag of a result not measured in the linear loop.
    output_limited: bool,
    /// Velocity-loop inputs of the last velocity tick: reference and feedback as used.
    velocity_loop_inputs: (f32, f32),
    /// The position-command injection of the last position tick (encoder counts, as added to
    /// the streamed position).
    position_injection: i32,
    /// The machine-end acceleration of the previous tick (rad/s²; see `inner_loop`).
    last_acceleration: f32,
    settings: TickSettings,
    mode: Option<Mode>,
    /// `commissioning` is here: the tick's one test (a flag beside the hot fields, not the
    /// option's tag at the struct's end).
    commissioning_started: bool,
    encoder: EncoderTracker,
    current_loop: CurrentLoop,
    velocity_loop: VelocityLoop,
    position_loop: PositionLoop,
    friction: FrictionCompensation,
    excitation: Option<(InjectionPoint, SineGenerator)>,
    /// The parameters as given (for [`Axis::params`]; the tick reads the loops' own settings).
    params: Params,
    command_path: CommandPath,
    sequence: StopSequence,
    /// The faults latched (the bridge is off while any is).
    faults: Faults,
    /// The position loop's following error on its last tick (counts; 0 outside position mode).
    following_error: f32,
    /// What the last tick's inner loop applied (the telemetry's per-tick part).
    applied: Applied,
    /// Every tick's torque command so far (a tick with a fault latched counts its command,
    /// the bridge off), summed ([`Telemetry::torque_command_sum`]).
    torque_command_sum: i64,
    sweep: PhaseShiftedSweep,
    /// [`Params::validate_sweep`] of `params`, computed when the axis is built: a drive starts
    /// a sweep with its interrupts off, and builds its axis outside that section.
    sweep_check: Result<(), SweepError>,
    /// The commissioning sequence, from [`Axis::start_commissioning`] until the axis is built
    /// again: while it is here, it drives the bridge instead of the loops.
    commissioning: Option<Commissioning>,
}

/// Why [`Axis::start_commissioning`] refused.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CommissioningRefusal {
    /// A setting out of range, or not this axis's (its encoder's counts, its tick): by name.
    Setting(&'static str),
    /// The axis is not at rest (a torque applied, a sweep running), or a sequence is running.
    Busy,
}

impl Axis {
    /// Build an axis in `slot`, where it will live: refuses parameters that do not validate,
    /// writing nothing. No axis value passes through any stack frame (an axis is 16 KiB, most
    /// of it the acc/dec filter's windows, zeroed in place). Each loop is built from its
    /// settings here, with what its tick derives from them (periods, scales, reciprocals,
    /// filter coefficients), so the tick reads them and computes none.
    #[allow(unsafe_code)]
    pub fn new_in<'a>(slot: &'a mut MaybeUninit<Self>, params: &Params) -> Result<&'a mut Self, ParamError> {
        params.validate()?;
        // SAFETY: `slot` is valid for writes and aligned; `init` writes every field.
        unsafe {
            Self::init(slot.as_mut_ptr(), params)?;
            Ok(slot.assume_init_mut())
        }
    }

    /// This axis built again from `params`, in place, as [`Self::new_in`] builds one (the loops
    /// from rest, no fault, no sweep result); refused, changing nothing, when they do not
    /// validate.
    #[allow(unsafe_code)]
    pub fn rebuild(&mut self, params: &Params) -> Result<(), ParamError> {
        params.validate()?;
        // SAFETY: `self` is valid for writes; an axis owns no resource (nothing to drop), and
        // `init` either refuses before its first write or writes every field.
        unsafe { Self::init(self, params) }
    }

    /// [`Self::new_in`] returning the axis by value: for a host, whose stack has room for one
    /// (a drive builds its axes in place).
    #[allow(unsafe_code)]
    pub fn new(params: Params) -> Result<Self, ParamError> {
        let mut slot = MaybeUninit::uninit();
        Self::new_in(&mut slot, &params)?;
        // SAFETY: built above.
        Ok(unsafe { slot.assume_init() })
    }

    /// Write every field of the axis of validated `params` at `axis`. What can refuse runs
    /// before the first write (so a refusal writes nothing): never once `params` validated.
    ///
    /// # Safety
    /// `axis` is valid for writes and aligned.
    #[inline(never)]
    #[allow(unsafe_code)]
    unsafe fn init(axis: *mut Self, params: &Params) -> Result<(), ParamError> {
        use core::ptr::addr_of_mut;
        let position_period = params.rates.position_period();
        let cpr = params.encoder_counts_per_rev;
        let counts_per_rev = NonZeroU32::new(cpr).ok_or(ParamError::Zero { field: "encoder_counts_per_rev" })?;
        let correction =
            ResponseCorrection::new(&params.correction, position_period).map_err(ParamError::Correction)?;
        // SAFETY: the caller's; every field below is written once, the big ones (the command
        // path's filter, the sweep's result table) where they are. The command path comes
        // first: its filter's checks run before anything is written.
        unsafe {
            CommandPath::init(addr_of_mut!((*axis).command_path), &params.acc_dec, position_period, &correction)
                .map_err(ParamError::AccDec)?;
            PhaseShiftedSweep::init(addr_of_mut!((*axis).sweep), params.sweep, params.rates.current_loop_hz);
            write_fields!(axis, Axis {
                params: *params,
                settings: TickSettings::new(params),
                current_loop: CurrentLoop::new(&params.current, &params.motor, params.rates.tick_period()),
                velocity_loop: VelocityLoop::new(&params.velocity, &params.filters, &params.rates),
                position_loop: PositionLoop::new(&params.position, cpr, position_period),
                sequence: StopSequence::new(&params.sequence, cpr, position_period),
                friction: FrictionCompensation::new(&params.friction, params.rates.velocity_period()),
                sweep_check: params.validate_sweep(),
                velocity_loop_inputs: (0.0, 0.0),
                position_injection: 0,
                last_acceleration: 0.0,
                phases: [0; 4],
                encoder: EncoderTracker::new(counts_per_rev, params.motor.pole_pairs, &params.encoder_mounting),
                excitation: None,
                tick: 0,
                mode: None,
                position_at_velocity_tick: 0,
                velocity_estimate: 0.0,
                velocity_reference: 0.0,
                torque_command: 0.0,
                output_limited: false,
                // Not commissioned: refused from the start (see `switch_mode`).
                faults: Faults(if params.commissioned { 0 } else { Faults::NOT_COMMISSIONED }),
                following_error: 0.0,
                applied: Applied::default(),
                torque_command_sum: 0,
                commissioning: None,
                commissioning_started: false,
                ; command_path, sweep
            });
        }
        Ok(())
    }

    pub fn params(&self) -> &Params {
        &self.params
    }

    /// The record of the last tick, built from the axis's state when asked (the tick keeps
    /// no copy of what the axis already holds: a record written on every tick cost the
    /// Cortex-M4 about 40 instructions of its budget).
    pub fn telemetry(&self) -> Telemetry {
        let a = &self.applied;
        Telemetry {
            tick: self.tick.saturating_sub(1),
            mode: self.mode.unwrap_or_default(),
            position: self.encoder.position(),
            position_command: self.command_path.position(),
            command_pulses: self.command_path.pulses(),
            velocity_estimate: self.velocity_estimate,
            velocity_reference: self.velocity_reference,
            following_error: self.following_error,
            torque_command: a.torque_command,
            torque_command_sum: self.torque_command_sum,
            current_reference: a.current_reference,
            current: a.current,
            voltage: a.voltage,
            voltage_saturated: a.voltage_saturated,
            faults: self.faults,
            sequence: *self.sequence.status(),
            sweep: *self.sweep.status(),
            commissioning: self.commissioning.as_ref().map(Commissioning::status),
        }
    }

    /// Start commissioning the motor (`crate::commissioning`): from the next tick the sequence
    /// drives the bridge, the loops rest, whatever the mode, until the axis is built again
    /// ([`Axis::rebuild`], with [`Params::with_commissioned`] once it is done). Only at rest:
    /// no torque applied (the bridge off counts as none), the rotor still, no sweep, no sequence running. A fault the axis latches meanwhile
    /// (bus limits, an outside fault) stops it with the bridge off.
    pub fn start_commissioning(&mut self, settings: &CommissioningSettings) -> Result<(), CommissioningRefusal> {
        settings.validate().map_err(CommissioningRefusal::Setting)?;
        if settings.counts_per_rev != self.params.encoder_counts_per_rev {
            return Err(CommissioningRefusal::Setting("counts_per_rev"));
        }
        if settings.tick_period != self.params.rates.tick_period() {
            return Err(CommissioningRefusal::Setting("tick_period"));
        }
        // The sequence's own trip level within the drive's (its only current trip meanwhile).
        if !(settings.overcurrent <= self.params.limits.overcurrent) {
            return Err(CommissioningRefusal::Setting("overcurrent"));
        }
        let running = matches!(self.commissioning(), Some(CommissioningStatus::Running(_)));
        // A torque the last tick applied with the bridge on (off, nothing was applied).
        let pushing = self.applied.torque_command != 0.0 && !self.faults.any();
        // A rotor still turning (coasting, or stopped by a fault while moving) is not at rest:
        // a tenth of a radian a second at most.
        let turning = !(self.velocity_estimate.abs() <= 0.1);
        if running || pushing || turning || self.sweep.running() {
            return Err(CommissioningRefusal::Busy);
        }
        self.commissioning = Some(Commissioning::new(*settings).map_err(CommissioningRefusal::Setting)?);
        self.commissioning_started = true;
        self.current_loop.reset();
        self.velocity_loop.reset();
        self.torque_command = 0.0;
        Ok(())
    }

    /// Stop a running commissioning sequence (the bridge off from the next tick).
    pub fn stop_commissioning(&mut self) {
        if let Some(c) = self.commissioning.as_mut() {
            c.stop(CommissioningFault::Stopped);
        }
    }

    /// The commissioning sequence's state since it started (None: never started since the
    /// axis was built).
    pub fn commissioning(&self) -> Option<CommissioningStatus> {
        self.commissioning.as_ref().map(Commissioning::status)
    }

    /// A tick of the commissioning sequence: the readings checked as on any tick (a fault
    /// the axis latches stops the sequence), its vector to the bridge. Out of line: the
    /// loops' tick keeps only the test that sends it here.
    #[inline(never)]
    fn commissioning_tick(&mut self, inputs: &AxisInputs) -> PwmOutput {
        let limits = &self.settings.limits;
        let bus = inputs.bus_voltage;
        if bus < limits.bus_undervoltage {
            self.faults.latch(Faults::BUS_UNDERVOLTAGE);
        }
        if bus > limits.bus_overvoltage {
            self.faults.latch(Faults::BUS_OVERVOLTAGE);
        }
        self.tick += 1;
        let Some(c) = self.commissioning.as_mut() else {
            return PwmOutput::default();
        };
        // Any fault but the one that says the motor is not commissioned yet.
        let faults = self.faults.0 & !Faults::NOT_COMMISSIONED;
        if faults != 0 {
            c.stop(CommissioningFault::DriveFault { faults });
        }
        let readings = CommissioningInputs {
            phase_currents: inputs.phase_currents,
            encoder_count: inputs.encoder_count,
            bus_voltage: bus,
        };
        match c.step(&readings) {
            Some(v) => PwmOutput { duties: crate::reference_frames::space_vector_duties(v, bus), enabled: true },
            None => PwmOutput::default(),
        }
    }

    /// The torque command the last tick applied, with its injections (N·m): the telemetry's
    /// `torque_command` without building the whole record.
    pub fn applied_torque(&self) -> f32 {
        self.applied.torque_command
    }

    pub fn faults(&self) -> Faults {
        self.faults
    }

    /// Latch a fault found outside the core (the power stage's break input, current sensing):
    /// the next [`Axis::step`] switches the PWM off, like any fault, until cleared.
    pub fn latch_fault(&mut self, bit: u32) {
        self.faults.latch(bit);
    }

    /// Clear latched faults; the loops restart from rest. An axis not commissioned keeps its
    /// `NOT_COMMISSIONED` fault (nothing clears it but commissioned parameters).
    pub fn clear_faults(&mut self) {
        self.faults = Faults::default();
        if !self.params.commissioned {
            self.faults.latch(Faults::NOT_COMMISSIONED);
        }
        self.friction.reset();
        self.current_loop.reset();
        self.velocity_loop.reset();
        self.position_loop.reset();
        self.torque_command = 0.0;
    }

    /// An event for the stop sequence (keys, network); refused with the reason, and counted,
    /// outside [`Mode::Sequence`] or when the sequence's state does not allow it.
    pub fn sequence_event(&mut self, e: SequenceEvent) -> Result<(), Refusal> {
        if self.mode != Some(Mode::Sequence) {
            return self.sequence.refuse(Refusal::NotInSequenceMode);
        }
        self.sequence.event(e)
    }

    /// Switch to `commands.mode` now if it differs (the next [`Axis::step`] would do it):
    /// lets events for the new mode be applied before that step.
    pub fn apply_mode(&mut self, commands: &Commands) {
        if self.mode != Some(commands.mode) {
            self.switch_mode(commands);
        }
    }

    /// The change of mode [`Axis::apply_mode`] makes (out of line: the tick's path, where the
    /// mode stays, keeps only the compare).
    #[inline(never)]
    fn switch_mode(&mut self, commands: &Commands) {
        // Every mode closes the current loop on the encoder's angle: refused (the bridge kept
        // off) until the motor is commissioned. Checked on a change of mode only (the first
        // tick's among them), not on every tick.
        if !self.params.commissioned {
            self.faults.latch(Faults::NOT_COMMISSIONED);
        }
        // Bumpless mode changes: the outer loops take over the torque now commanded.
        self.velocity_loop.preset(self.torque_command);
        self.position_loop.reset();
        // Streaming starts at the streamed position (a step, as a position command
        // always was); a move or a jog starts where the axis is.
        let start = if commands.move_speed == 0.0 && commands.jog_velocity == 0.0 {
            commands.position
        } else {
            self.encoder.position()
        };
        self.command_path.reset(start);
        if commands.mode == Mode::Sequence {
            // The sequence starts idle at the present speed, keeping the selected gain.
            let gain = self.sequence.status().gain_index;
            self.sequence.enter(self.encoder.position(), self.velocity_estimate, gain);
            self.velocity_reference = self.velocity_estimate;
        }
        if commands.mode != Mode::Position {
            self.following_error = 0.0;
        }
        self.mode = Some(commands.mode);
    }

    /// Start the frequency-response sweep of `Params::sweep` (seed 000). Velocity-command and
    /// feedback injection need the velocity loop running, position-command injection the
    /// position mode.
    ///
    /// The settings are held against the axis's rates and limits here
    /// ([`Params::validate_sweep`], evaluated when the axis was built): a sweep that would
    /// alias or be cut is refused with the reason and nothing changes, while an axis that never
    /// sweeps runs whatever its rate.
    pub fn start_sweep(&mut self) -> Result<(), SweepError> {
        self.sweep_check?;
        let point = self.params.sweep.point;
        if point == InjectionPoint::PositionCommand {
            if self.mode != Some(Mode::Position) {
                return Err(SweepError::NeedsPositionMode);
            }
            // The sine starts on the next position tick (the command path takes it there):
            // the same samples of the same sine wherever the request falls between two.
            let divider = self.settings.dividers[1];
            let phase = if self.settings.counted_phases {
                self.phases[1]
            } else {
                self.tick as u32 & self.settings.due_masks[1]
            };
            return self.sweep.start_after((divider - phase) % divider);
        }
        let velocity_loop = matches!(self.mode, Some(Mode::Velocity | Mode::Position | Mode::Sequence));
        if point == InjectionPoint::Off || (point != InjectionPoint::TorqueCommand && !velocity_loop) {
            return Err(SweepError::PointUnusable);
        }
        self.sweep.start()
    }

    /// Load response-correction coefficients (seed 001) while running; refused, with nothing
    /// changed, while a command is in motion through the filter or when they are invalid.
    pub fn load_correction(&mut self, p: &CorrectionParams) -> Result<(), CorrectionError> {
        self.command_path.load_correction(p, self.params.rates.position_period())?;
        self.params.correction = *p;
        Ok(())
    }

    /// Install a correction built ahead with `ResponseCorrection::new` from `p` at this axis's
    /// position period (the drive builds it outside the section it shares with the control
    /// interrupt; this only copies the sections in). Refused, changing nothing, while command
    /// pulses are in flight, as [`Axis::load_correction`]. [`Axis::params`] still shows the
    /// previous correction until [`Axis::record_correction`] (the drive does that in a second,
    /// short section: the tick never reads it).
    pub fn install_correction(&mut self, built: &ResponseCorrection) -> Result<(), CorrectionError> {
        self.command_path.install_correction(built)
    }

    /// Record the correction installed by [`Axis::install_correction`] in the parameters.
    pub fn record_correction(&mut self, p: &CorrectionParams) {
        // Section by section (a whole-struct copy is a slow `memcpy` on the Cortex-M4).
        for (d, s) in self.params.correction.sections.iter_mut().zip(&p.sections) {
            *d = *s;
        }
        self.params.correction.count = p.count;
    }

    pub fn sweep(&self) -> &PhaseShiftedSweep {
        &self.sweep
    }

    /// Add a sine (amplitude in Nm or rad/s depending on the point) from the next tick on.
    pub fn set_excitation(&mut self, point: InjectionPoint, sine: SineGenerator) {
        self.excitation = (point != InjectionPoint::Off).then_some((point, sine));
    }

    /// One base tick: sense, run the commanded mode's outer loops that are due, run the inner
    /// (current) loop, record; returns the PWM command.
    pub fn step(&mut self, inputs: &AxisInputs, commands: &Commands) -> PwmOutput {
        if self.commissioning_started {
            return self.commissioning_tick(inputs);
        }
        self.loops_tick(inputs, commands)
    }

    /// [`Axis::step`] of the loops (out of line: the commissioning's test in front of it
    /// left in the caller cost the Cortex-M4 about 20 instructions a tick of spilled registers).
    #[inline(never)]
    fn loops_tick(&mut self, inputs: &AxisInputs, commands: &Commands) -> PwmOutput {
        // Sense: inputs checked, encoder followed, the mode switched, the velocity estimated.
        let mut sensed = self.sense(inputs, commands);
        if self.mode != Some(commands.mode) {
            self.switch_mode(commands);
            // A refusal latched there is this tick's too.
            sensed.faults.latch(self.faults.0);
        }
        let due = self.due();
        self.estimate_velocity(due.velocity, sensed.position);
        let excitation = self.excitation(due.prbs_chip);

        // Mode: the commanded mode's outer loops on their ticks. On a velocity tick of a mode
        // with a velocity loop, the commanded velocity, which the friction compensation
        // follows (the commanded motion, not the feedback).
        let commanded_velocity = match commands.mode {
            Mode::Torque => {
                self.torque_command = self.velocity_loop.limit_torque(commands.torque);
                None
            }
            Mode::Velocity => due.velocity.then(|| {
                self.velocity_reference = commands.velocity;
                commands.velocity
            }),
            Mode::Position => {
                if due.position {
                    self.position_tick(commands, excitation, &mut sensed);
                }
                due.velocity.then(|| crate::counts_to_f32(self.command_path.pulses()))
            }
            Mode::Sequence => {
                if due.position {
                    self.sequence_tick(sensed.position);
                }
                due.velocity.then(|| self.sequence.status().speed_reference)
            }
        };
        if let Some(commanded) = commanded_velocity {
            self.velocity_tick(commanded, excitation);
        }

        // Inner loop: torque to current to PWM; then the record of the tick.
        let inner = self.inner_loop(inputs, commands, excitation, due, &mut sensed.faults);
        self.record(&sensed, &inner)
    }

    /// Sensing: the inputs and set-points checked (faults latched), the encoder followed.
    #[inline(always)]
    fn sense(&mut self, inputs: &AxisInputs, commands: &Commands) -> Sensed {
        let mut faults = self.faults;
        if !inputs.phase_currents.iter().all(|x| x.is_finite()) || !inputs.bus_voltage.is_finite() {
            faults.latch(Faults::NOT_FINITE);
        }
        // Set-points: a NaN or infinity is a non-finite fault; a finite value outside its
        // range (`crate::ranges`) a range fault. The detailed check only when the quick one
        // fails. `|x| ≤ limit` on the magnitudes' bit patterns, exactly: the limits are
        // positive and finite, non-negative floats order as their patterns do, and a NaN's or
        // an infinity's pattern lies above every finite one (integer compares cost the
        // Cortex-M4 fewer instructions than the FPU's compare, flag transfer and move).
        let magnitude = |x: f32| x.to_bits() & 0x7FFF_FFFF;
        let speed_bits = MAX_SPEED.to_bits();
        let speeds_in_range = magnitude(commands.move_speed).max(magnitude(commands.jog_velocity)) <= speed_bits;
        if !(speeds_in_range
            && magnitude(commands.velocity) <= speed_bits
            && magnitude(commands.torque) <= crate::ranges::MAX_TORQUE.to_bits()
            && position_in_range(commands))
        {
            let finite = [commands.move_speed, commands.jog_velocity, commands.velocity, commands.torque]
                .iter()
                .all(|x| x.is_finite());
            faults.latch(if finite { Faults::COMMAND_RANGE } else { Faults::NOT_FINITE });
        }
        if self.encoder.update(inputs.encoder_count) == EncoderUpdate::Jump {
            faults.latch(Faults::ENCODER);
        }
        let limits = &self.settings.limits;
        let [ia, ib] = inputs.phase_currents;
        let ic = -(ia + ib);
        // Each phase against the limit (`f32::max`'s NaN handling cost 13 instructions a tick
        // on the Cortex-M4; a NaN phase compares false either way).
        let overcurrent = limits.overcurrent;
        if ia.abs() > overcurrent || ib.abs() > overcurrent || ic.abs() > overcurrent {
            faults.latch(Faults::OVERCURRENT);
        }
        if inputs.bus_voltage < limits.bus_undervoltage {
            faults.latch(Faults::BUS_UNDERVOLTAGE);
        }
        if inputs.bus_voltage > limits.bus_overvoltage {
            faults.latch(Faults::BUS_OVERVOLTAGE);
        }
        Sensed { faults, speeds_in_range, position: self.encoder.position() }
    }

    #[inline(always)]
    fn due(&self) -> Due {
        // Four plain comparisons (an array `map` here cost several times as much).
        if self.settings.counted_phases {
            return Due {
                velocity: self.phases[0] == 0,
                position: self.phases[1] == 0,
                acquisition: self.phases[2] == 0,
                prbs_chip: self.phases[3] == 0,
            };
        }
        let (t, m) = (self.tick as u32, &self.settings.due_masks);
        Due { velocity: t & m[0] == 0, position: t & m[1] == 0, acquisition: t & m[2] == 0, prbs_chip: t & m[3] == 0 }
    }

    /// The velocity estimate from the encoder counts of the last velocity period.
    #[inline(always)]
    fn estimate_velocity(&mut self, velocity_due: bool, position: i64) {
        if velocity_due {
            let counts = position.saturating_sub(self.position_at_velocity_tick);
            self.position_at_velocity_tick = position;
            if self.tick > 0 {
                let s = &self.settings;
                self.velocity_estimate = crate::counts_to_f32(counts) * s.rad_per_count / s.velocity_period;
            }
        }
    }

    /// This tick's injection: the sweep's, else the test sine's, else none.
    #[inline(always)]
    fn excitation(&mut self, chip_due: bool) -> (InjectionPoint, f32) {
        match (self.sweep.excitation(chip_due), self.excitation.as_mut()) {
            (Some(e), _) => e,
            (None, Some((point, sine))) => (*point, sine.next_sample()),
            (None, None) => (InjectionPoint::Off, 0.0),
        }
    }

    /// Position mode's position tick: the command path, then the position loop. A
    /// position-command injection is added to the streamed position (in whole counts, through
    /// the command path as any streamed command); a move or a jog takes none.
    #[inline(always)]
    fn position_tick(&mut self, commands: &Commands, excitation: (InjectionPoint, f32), sensed: &mut Sensed) {
        let counts_per_tick = self.settings.counts_per_position_tick;
        let mut streamed = commands.position;
        let motion = if commands.jog_velocity != 0.0 {
            Move::Jog(commands.jog_velocity * counts_per_tick)
        } else if commands.move_speed != 0.0 {
            Move::Absolute { target: commands.position, speed: commands.move_speed.abs() * counts_per_tick }
        } else {
            if excitation.0 == InjectionPoint::PositionCommand {
                // `as` saturates (one conversion instruction on the Cortex-M4's FPU).
                self.position_injection = libm::roundf(excitation.1 / self.settings.rad_per_count) as i32;
                streamed = streamed.saturating_add(self.position_injection as i64);
            }
            Move::Stream
        };
        // A non-finite or out-of-range speed or position has latched a fault in sensing; it
        // must not reach the carry.
        let command = if sensed.speeds_in_range && position_in_range(commands) {
            self.command_path.step(motion, streamed)
        } else {
            self.command_path.position()
        };
        let out = self.position_loop.step(command, sensed.position);
        self.velocity_reference = out.velocity_reference;
        self.following_error = out.following_error;
        if out.following_error.abs() > self.settings.limits.following_error {
            sensed.faults.latch(Faults::FOLLOWING_ERROR);
        }
    }

    /// Sequence mode's position tick: the stop sequence's speed reference.
    #[inline(always)]
    fn sequence_tick(&mut self, position: i64) {
        self.velocity_reference = self.sequence.step(position, self.velocity_estimate);
        // The stop's hand-over: the deceleration torque lets go (see `stop_sequence`).
        if self.sequence.take_integrator_release() {
            self.velocity_loop.set_integral(0.0);
        }
    }

    /// A velocity tick: the velocity loop on the reference with the injection, plus friction
    /// compensation for the `commanded` velocity, within the torque limit.
    #[inline(always)]
    fn velocity_tick(&mut self, commanded: f32, excitation: (InjectionPoint, f32)) {
        let mut reference = self.velocity_reference;
        if excitation.0 == InjectionPoint::VelocityCommand {
            reference += excitation.1;
        }
        let compensation = self.friction.step(commanded);
        let mut feedback = self.velocity_estimate;
        if excitation.0 == InjectionPoint::VelocityFeedback {
            feedback += excitation.1;
        }
        self.velocity_loop_inputs = (reference, feedback);
        let torque = self.velocity_loop.step(reference, feedback) + compensation;
        self.torque_command = self.velocity_loop.limit_torque(torque);
    }

    /// The inner loop: the torque command with the injections, the sweep's acquisition, the
    /// current loop (off while a fault is latched).
    #[inline(always)]
    fn inner_loop(
        &mut self,
        inputs: &AxisInputs,
        commands: &Commands,
        excitation: (InjectionPoint, f32),
        due: Due,
        faults: &mut Faults,
    ) -> InnerLoop {
        let mut torque = self.torque_command;
        if excitation.0 == InjectionPoint::TorqueCommand {
            torque += excitation.1;
        }
        torque += self.sweep.torque_dither();
        // The sweep's U and Y (see `phase_shifted_sweep`): Y is the velocity estimate, but for
        // a position-command injection, where U is the injection and Y the position, both
        // counted from the streamed position (rad: full f32 resolution wherever the axis is).
        let (u, y) = match excitation.0 {
            InjectionPoint::VelocityCommand => (self.velocity_loop_inputs.0, self.velocity_estimate),
            InjectionPoint::VelocityFeedback => (self.velocity_loop_inputs.1, self.velocity_estimate),
            InjectionPoint::PositionCommand => {
                let rad_per_count = self.settings.rad_per_count;
                let injected = self.position_injection as f32 * rad_per_count;
                if self.settings.measured_torque_constant != 0.0 {
                    // The machine-end acceleration measure: Y the accelerometer sampled with
                    // this tick's encoder count, as the position Y below is (no delay between
                    // the command and the reading beyond the loops').
                    (injected, inputs.load_acceleration)
                } else {
                    let moved = self.encoder.position().saturating_sub(commands.position);
                    (injected, crate::counts_to_f32(moved) * rad_per_count)
                }
            }
            // The machine-end acceleration measure: the torque from the q current the current
            // loop measured on the previous tick (its telemetry) and the accelerometer sampled
            // with it (kept from that tick), summed on every base tick: both one tick late, so
            // from the same instant. (Taken after the current loop from this tick's current
            // instead, the every-feature tick was 2 instructions longer: `servo bench firmware`.)
            InjectionPoint::TorqueCommand if self.settings.measured_torque_constant != 0.0 => {
                let acceleration = self.last_acceleration;
                self.last_acceleration = inputs.load_acceleration;
                (self.settings.measured_torque_constant * self.applied.current.q, acceleration)
            }
            _ => (torque, self.velocity_estimate),
        };
        let summed = due.velocity || self.settings.measured_torque_constant != 0.0;
        // Whether the voltage circle limited the current loop's output on a tick of the
        // acquisition period that ends here (the ticks before this one; see
        // `PhaseShiftedSweep::end_tick`).
        let limited = self.output_limited && due.acquisition;
        if due.acquisition {
            self.output_limited = false;
        }
        self.sweep.end_tick(self.tick, summed, due.acquisition, u, y, limited);

        let current_reference = self.current_loop.reference(torque);
        let theta_e = self.encoder.electrical_angle();
        let out = if faults.any() {
            CurrentLoopOutput::default()
        } else {
            self.current_loop.step(
                inputs.phase_currents,
                theta_e,
                self.velocity_estimate,
                current_reference,
                inputs.bus_voltage,
            )
        };
        if !(out.voltage.d.is_finite() && out.voltage.q.is_finite() && torque.is_finite()) {
            faults.latch(Faults::NOT_FINITE);
        }
        // What the current loop asked for was cut by the voltage circle. (The current and
        // torque limits are not watched here: each cost the Cortex-M4 about 20 instructions
        // per tick, past the budget; a torque-command amplitude whose own peak reaches the
        // current limit's torque is refused instead, `Params::validate`.)
        self.output_limited |= out.saturated;
        InnerLoop { torque, current_reference, out }
    }

    /// Record the tick in the telemetry, move the slower ticks' phases on; the PWM command
    /// (off while a fault is latched, the loops reset).
    #[inline(always)]
    fn record(&mut self, sensed: &Sensed, inner: &InnerLoop) -> PwmOutput {
        let faults = sensed.faults;
        let enabled = !faults.any();
        if !enabled {
            self.current_loop.reset();
            self.velocity_loop.reset();
            self.torque_command = 0.0;
        }
        // The inner loop's part of the record (the rest the telemetry reads from the axis).
        self.applied = Applied {
            torque_command: inner.torque,
            current_reference: inner.current_reference,
            current: inner.out.current,
            voltage: inner.out.voltage,
            voltage_saturated: inner.out.saturated,
        };
        // Scaled by a power of two (exact), truncated toward zero (a bias under one unit).
        self.torque_command_sum =
            self.torque_command_sum.wrapping_add((inner.torque * (1.0 / TORQUE_SUM_UNIT)) as i32 as i64);
        self.faults = faults;
        self.tick += 1;
        if self.settings.counted_phases {
            for (phase, divider) in self.phases.iter_mut().zip(self.settings.dividers) {
                *phase = if *phase + 1 >= divider { 0 } else { *phase + 1 };
            }
        }
        PwmOutput { duties: if enabled { inner.out.duties } else { [0.0; 3] }, enabled }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::EncoderMounting;

    /// The default parameters, commissioned on a motor whose encoder starts at electrical zero.
    fn commissioned() -> Params {
        Params::default().commissioned_as(EncoderMounting::default())
    }

    /// Commissioning starts only with a trip level within the drive's own and a rotor at rest.
    #[test]
    fn commissioning_is_refused_above_the_drive_s_trip_level_and_on_a_turning_rotor() {
        let p = commissioned();
        let mut axis = Axis::new(p).unwrap();
        let mut settings = crate::commissioning::CommissioningSettings::for_params(&p);
        settings.overcurrent = 2.0 * p.limits.overcurrent;
        assert_eq!(axis.start_commissioning(&settings), Err(CommissioningRefusal::Setting("overcurrent")));
        settings.overcurrent = p.limits.overcurrent;
        // The encoder moving: the velocity estimate is not at rest.
        let rest = Commands { mode: Mode::Torque, ..Commands::default() };
        for k in 0..8 {
            axis.step(&AxisInputs { encoder_count: 50 * k, ..inputs() }, &rest);
        }
        assert_eq!(axis.start_commissioning(&settings), Err(CommissioningRefusal::Busy));
        for _ in 0..8 {
            axis.step(&AxisInputs { encoder_count: 400, ..inputs() }, &rest);
        }
        assert_eq!(axis.start_commissioning(&settings), Ok(()));
        assert!(matches!(axis.commissioning(), Some(crate::commissioning::CommissioningStatus::Running(_))));
    }

    /// An axis whose motor is not commissioned refuses every mode (each closes the current
    /// loop on the encoder's angle): the bridge stays off from the first tick, clearing the
    /// faults does not lift it, commissioned parameters do.
    #[test]
    fn an_axis_not_commissioned_refuses_every_mode_from_its_first_tick() {
        for mode in [Mode::Torque, Mode::Velocity, Mode::Position, Mode::Sequence] {
            let mut axis = Axis::new(Params::default()).unwrap();
            let commands = Commands { mode, torque: 0.5, velocity: 10.0, ..Commands::default() };
            for _ in 0..3 {
                let pwm = axis.step(&inputs(), &commands);
                assert!(!pwm.enabled && pwm.duties == [0.0; 3], "{mode:?}");
                assert!(axis.faults().contains(Faults::NOT_COMMISSIONED), "{mode:?}");
            }
            axis.clear_faults();
            assert!(!axis.step(&inputs(), &commands).enabled);
            let other = Commands { mode: Mode::Torque, ..commands };
            axis.step(&inputs(), &other);
            assert!(axis.faults().contains(Faults::NOT_COMMISSIONED));
            axis.rebuild(&commissioned()).unwrap();
            assert!(axis.step(&inputs(), &commands).enabled, "{mode:?}");
            assert_eq!(axis.faults(), Faults::default());
        }
    }

    fn inputs() -> AxisInputs {
        AxisInputs { phase_currents: [0.0, 0.0], encoder_count: 0, bus_voltage: 48.0, load_acceleration: 0.0 }
    }

    /// A position move of `ticks` base ticks on `axis` with a moving encoder and currents:
    /// every tick's telemetry and PWM.
    fn run(axis: &mut Axis, ticks: u32) -> ([f32; 3], Telemetry) {
        let commands = Commands { mode: Mode::Position, position: 40_000, move_speed: 30.0, ..Commands::default() };
        let mut last = ([0.0; 3], Telemetry::default());
        for k in 0..ticks {
            let i = AxisInputs {
                phase_currents: [0.3 * libm::sinf(k as f32 * 0.01), -0.1],
                encoder_count: (k / 3) as i32,
                bus_voltage: 48.0,
                load_acceleration: 0.0,
            };
            let pwm = axis.step(&i, &commands);
            last = (pwm.duties, axis.telemetry());
        }
        last
    }

    /// The telemetry's torque sum is the ticks' torque commands summed, each to within one
    /// unit (truncated toward zero): the mean between two records read far apart is the mean
    /// of every tick between them, which a reading of `torque_command` now and then is not.
    /// A rebuilt axis starts its sum again, as its tick.
    #[test]
    fn the_torque_sum_is_every_tick_s_torque_command_summed() {
        extern crate std;
        let mut axis = Axis::new(commissioned()).unwrap();
        let commands = Commands { mode: Mode::Velocity, velocity: 5.0, ..Commands::default() };
        let (mut exact, mut ticks) = (0.0f64, 0u32);
        let mut seen = std::vec::Vec::new();
        for k in 0..4000u32 {
            let i = AxisInputs {
                phase_currents: [0.2 * libm::sinf(k as f32 * 0.013), -0.05],
                encoder_count: (k * k / 97) as i32,
                ..inputs()
            };
            axis.step(&i, &commands);
            let t = axis.telemetry();
            exact += t.torque_command as f64;
            ticks += 1;
            seen.push(t.torque_command);
            let sum = t.torque_command_sum as f64 * TORQUE_SUM_UNIT as f64;
            assert!((sum - exact).abs() <= ticks as f64 * TORQUE_SUM_UNIT as f64, "tick {k}: {sum} against {exact}");
        }
        // The loops moved the torque (a sum of one constant would prove little).
        let (lo, hi) = seen.iter().fold((f32::MAX, f32::MIN), |(a, b), &x| (a.min(x), b.max(x)));
        assert!(hi - lo > 0.01 && exact.abs() > 1.0, "{lo} {hi} {exact}");
        axis.rebuild(&commissioned()).unwrap();
        assert_eq!(axis.telemetry().torque_command_sum, 0);
    }

    /// Every acc/dec kind, and every feature of the golden vectors at once.
    fn param_sets() -> [Params; 4] {
        use crate::acc_dec::AccDecKind;
        let with = |kind| {
            let mut p = commissioned();
            p.acc_dec.kind = kind;
            p.acc_dec.ma_stages = 2;
            p.acc_dec.ma_lengths = [7, 300, 16];
            p
        };
        [
            with(AccDecKind::None),
            with(AccDecKind::MovingAverage),
            with(AccDecKind::Butterworth),
            crate::golden_vectors::preset(crate::golden_vectors::ALL_FEATURES).unwrap(),
        ]
    }

    /// The set-points' range check on bit patterns says what `|x| ≤ limit` says for every
    /// kind of value: zeros of both signs, the limits and the floats just beyond them,
    /// subnormals, infinities and NaNs.
    #[test]
    fn a_set_point_is_in_range_exactly_when_its_magnitude_is_within_the_limit() {
        use crate::ranges::{MAX_SPEED, MAX_TORQUE};
        let beyond = |x: f32| f32::from_bits(x.to_bits() + 1);
        let values = |max: f32| {
            [
                0.0,
                -0.0,
                1e-45,
                -1e-45,
                1.0,
                max,
                -max,
                beyond(max),
                -beyond(max),
                f32::INFINITY,
                -f32::INFINITY,
                f32::NAN,
                -f32::NAN,
            ]
        };
        for field in 0..4 {
            let max = if field == 3 { MAX_TORQUE } else { MAX_SPEED };
            for x in values(max) {
                let mut c = Commands::default();
                match field {
                    0 => c.move_speed = x,
                    1 => c.jog_velocity = x,
                    2 => c.velocity = x,
                    _ => c.torque = x,
                }
                let mut axis = Axis::new(commissioned()).unwrap();
                axis.step(&inputs(), &c);
                let expected = if !x.is_finite() {
                    Faults::NOT_FINITE
                } else if x.abs() > max {
                    Faults::COMMAND_RANGE
                } else {
                    0
                };
                let got = axis.faults();
                assert_eq!(
                    (got.contains(Faults::NOT_FINITE), got.contains(Faults::COMMAND_RANGE)),
                    (expected == Faults::NOT_FINITE, expected == Faults::COMMAND_RANGE),
                    "field {field}, {x:e}: {got:?}"
                );
            }
        }
    }

    #[test]
    fn the_position_range_check_is_the_magnitudes() {
        let max = crate::ranges::MAX_POSITION_COUNTS;
        for x in [0, 1, -1, max, -max, max + 1, -max - 1, max - 1, -max + 1, i64::MAX, i64::MIN, i64::MIN + 1] {
            let c = Commands { position: x, ..Commands::default() };
            assert_eq!(position_in_range(&c), x.unsigned_abs() <= max as u64, "{x}");
        }
    }

    /// Power-of-two dividers (due from the tick count's low bits) and others (counted phases)
    /// put the slower ticks on the same base ticks: a velocity loop at 1/3 and a position loop
    /// at 1/6 of the rate against the same loops at 1/2 and 1/4, each tick's due flags against
    /// `tick mod divider`.
    #[test]
    fn slower_ticks_fall_on_the_tick_count_modulo_their_dividers_either_way() {
        for (v, p, a, c) in [(2u32, 4u32, 4u32, 1u32), (3, 6, 3, 5), (1, 8, 2, 16), (4, 4, 8, 3)] {
            let mut params = commissioned();
            params.rates.velocity_divider = v;
            params.rates.position_divider = p;
            params.sweep.acquisition_divider = a;
            params.sweep.prbs_divider = c;
            let mut axis = Axis::new(params).unwrap();
            for tick in 0..200u64 {
                let due = axis.due();
                let expect = |d: u32| tick % d as u64 == 0;
                assert_eq!(
                    (due.velocity, due.position, due.acquisition, due.prbs_chip),
                    (expect(v), expect(p), expect(a), expect(c)),
                    "dividers {v} {p} {a} {c}, tick {tick}"
                );
                axis.step(&inputs(), &Commands::default());
            }
        }
    }

    #[test]
    fn an_axis_built_in_a_slot_of_garbage_runs_as_one_built_by_value() {
        extern crate std;
        for p in param_sets() {
            let mut by_value = Axis::new(p).unwrap();
            let mut slot = std::boxed::Box::new(MaybeUninit::<Axis>::uninit());
            // Whatever the slot held before (here a byte pattern) must not show through.
            // SAFETY: a MaybeUninit may hold any bytes.
            #[allow(unsafe_code)]
            unsafe {
                slot.as_mut_ptr().write_bytes(0xA5, 1)
            };
            let in_place = Axis::new_in(&mut slot, &p).unwrap();
            assert_eq!(run(in_place, 3000), run(&mut by_value, 3000), "{:?}", p.acc_dec.kind);
        }
    }

    #[test]
    fn an_axis_rebuilt_in_place_runs_as_a_new_one_and_a_refusal_changes_nothing() {
        for p in param_sets() {
            let mut fresh = Axis::new(p).unwrap();
            let mut rebuilt = Axis::new(commissioned()).unwrap();
            run(&mut rebuilt, 1234);
            rebuilt.rebuild(&p).unwrap();
            assert_eq!(run(&mut rebuilt, 3000), run(&mut fresh, 3000), "{:?}", p.acc_dec.kind);
            // Refused: the axis runs on as if nothing had been asked.
            let mut bad = p;
            bad.acc_dec.ma_lengths[0] = 0;
            bad.acc_dec.ma_stages = 3;
            assert!(rebuilt.rebuild(&bad).is_err());
            let mut twin = fresh.clone();
            assert_eq!(run(&mut rebuilt, 500), run(&mut twin, 500));
        }
    }

    #[test]
    fn refuses_invalid_params() {
        let mut p = commissioned();
        p.motor.resistance = f32::NAN;
        assert!(Axis::new(p).is_err());
    }

    #[test]
    fn nan_input_latches_a_fault_and_switches_pwm_off() {
        let mut axis = Axis::new(commissioned()).unwrap();
        let mut i = inputs();
        i.phase_currents[0] = f32::NAN;
        let out = axis.step(&i, &Commands::default());
        assert!(!out.enabled);
        assert!(axis.faults().contains(Faults::NOT_FINITE));
        // Latched: clean inputs do not clear it.
        assert!(!axis.step(&inputs(), &Commands::default()).enabled);
        axis.clear_faults();
        assert!(axis.step(&inputs(), &Commands::default()).enabled);
    }

    #[test]
    fn an_outside_fault_switches_the_pwm_off_at_the_next_tick_until_cleared() {
        let mut axis = Axis::new(commissioned()).unwrap();
        assert!(axis.step(&inputs(), &Commands::default()).enabled);
        axis.latch_fault(Faults::HARDWARE_BREAK);
        let out = axis.step(&inputs(), &Commands::default());
        assert!(!out.enabled && out.duties == [0.0; 3]);
        assert!(axis.faults().contains(Faults::HARDWARE_BREAK));
        assert!(axis.faults().names().any(|n| n == "hardware break input"));
        axis.clear_faults();
        assert!(axis.step(&inputs(), &Commands::default()).enabled);
    }

    #[test]
    fn bus_limits_trip() {
        let mut axis = Axis::new(commissioned()).unwrap();
        let mut i = inputs();
        i.bus_voltage = 70.0;
        axis.step(&i, &Commands::default());
        assert!(axis.faults().contains(Faults::BUS_OVERVOLTAGE));
    }

    #[test]
    fn torque_command_becomes_q_current_reference() {
        let mut axis = Axis::new(commissioned()).unwrap();
        let c = Commands { mode: Mode::Torque, torque: 0.5, ..Default::default() };
        axis.step(&inputs(), &c);
        let kt = Params::default().motor.torque_constant();
        assert!((axis.telemetry().current_reference.q - 0.5 / kt).abs() < 1e-6);
    }

    #[test]
    fn mode_switch_from_torque_to_velocity_keeps_the_torque() {
        let mut axis = Axis::new(commissioned()).unwrap();
        let c = Commands { mode: Mode::Torque, torque: 0.3, ..Default::default() };
        axis.step(&inputs(), &c);
        axis.step(&inputs(), &c);
        let c = Commands { mode: Mode::Velocity, velocity: 0.0, ..Default::default() };
        axis.step(&inputs(), &c);
        assert!((axis.telemetry().torque_command - 0.3).abs() < 1e-6);
    }
}
