//! Drive parameters and their validation.
//!
//! Every number the control core uses comes from [`Params`]; [`Params::validate`] checks them
//! all before an [`crate::Axis`] is built, and reports the first offending field by name.

use core::fmt;

use crate::acc_dec::{AccDecError, AccDecFilter, AccDecParams};
use crate::accelerometer::{AccelerometerParams, MAX_SENSITIVITY, MIN_SENSITIVITY};
use crate::friction_compensation::{FrictionCompensationError, FrictionCompensationParams};
use crate::phase_shifted_sweep::{SweepError, SweepParams};
use crate::response_correction::{CorrectionError, CorrectionParams};
use crate::stop_sequence::{SequenceParamError, SequenceParams};
use crate::torque_ceiling::{ExcitationEntry, TorqueCeiling};

/// Motor data the controller needs (decoupling, torque constant, electrical angle).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MotorModel {
    pub pole_pairs: u32,
    /// Stator resistance (Ω).
    pub resistance: f32,
    /// d-axis inductance (H).
    pub ld: f32,
    /// q-axis inductance (H).
    pub lq: f32,
    /// Permanent-magnet flux linkage (Wb).
    pub flux_linkage: f32,
}

impl MotorModel {
    /// Torque per q-axis ampere for id = 0: `1.5 · p · ψ` (Nm/A).
    pub fn torque_constant(&self) -> f32 {
        1.5 * self.pole_pairs as f32 * self.flux_linkage
    }
}

/// Where the encoder sits on the motor: what commissioning measures (a drive cannot know it
/// beforehand: the counter starts at 0 wherever the rotor stands).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct EncoderMounting {
    /// The counter counts down when the rotor turns the way the electrical angle increases.
    pub reversed: bool,
    /// The electrical angle (rad, in `[0, 2π)`) at count 0 of the direction-corrected counter.
    pub electrical_offset: f32,
}

/// Loop rates: the base tick and the dividers of the outer loops.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Rates {
    /// Current-loop (base tick) frequency in Hz.
    pub current_loop_hz: f32,
    /// Velocity loop every this many base ticks.
    pub velocity_divider: u32,
    /// Position loop every this many base ticks (a whole multiple of `velocity_divider`).
    pub position_divider: u32,
}

impl Rates {
    pub fn tick_period(&self) -> f32 {
        1.0 / self.current_loop_hz
    }
    pub fn velocity_period(&self) -> f32 {
        self.velocity_divider as f32 / self.current_loop_hz
    }
    pub fn position_period(&self) -> f32 {
        self.position_divider as f32 / self.current_loop_hz
    }
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CurrentLoopGains {
    /// Proportional gain (V/A), both axes.
    pub kp: f32,
    /// Integral gain (V/(A·s)), both axes.
    pub ki: f32,
    /// Feed-forward of the cross-coupling and back-EMF terms.
    pub decoupling: bool,
    /// Electrical-angle advance for the voltage output, in base ticks (compensates the one-tick
    /// computation delay plus half a tick of PWM averaging: 1.5 is the usual value).
    pub angle_advance_ticks: f32,
    /// Largest current the loop may command (A, magnitude of the dq vector).
    pub max_current: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct VelocityLoopGains {
    /// Proportional gain (Nm per rad/s).
    pub kp: f32,
    /// Integral gain (Nm per rad).
    pub ki: f32,
    /// Torque limit (Nm).
    pub torque_limit: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PositionLoopGains {
    /// Proportional gain (1/s: rad/s of velocity command per rad of error).
    pub kp: f32,
    /// Velocity feed-forward fraction, 0 to 1.
    pub velocity_feedforward: f32,
    /// Velocity command limit (rad/s).
    pub velocity_limit: f32,
}

/// Optional torque-command filters; a frequency of 0 switches a filter off.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct TorqueFilters {
    pub low_pass_hz: f32,
    pub notch_hz: f32,
    pub notch_q: f32,
    /// Gain at the notch centre, 0 (full) to 1 (none).
    pub notch_depth: f32,
    /// A second notch after the first, for a machine with two resonances above the
    /// crossover (0 Hz: off).
    pub notch2_hz: f32,
    pub notch2_q: f32,
    pub notch2_depth: f32,
}

/// Protective limits; crossing one latches a fault and switches the PWM off.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Limits {
    /// Phase-current magnitude that trips (A).
    pub overcurrent: f32,
    pub bus_undervoltage: f32,
    pub bus_overvoltage: f32,
    /// Position following error that trips in position mode (rad). The default, 2 rad, leaves
    /// room above the shipped position step of 1 rad: a step as large as the limit trips on
    /// the first backward micro-radian of a rotor not perfectly at rest.
    pub following_error: f32,
}

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Params {
    pub motor: MotorModel,
    /// Encoder counts per mechanical revolution.
    pub encoder_counts_per_rev: u32,
    /// The encoder's direction and electrical offset.
    #[serde(default)]
    pub encoder_mounting: EncoderMounting,
    /// `motor` and `encoder_mounting` were measured by commissioning (or come from a set it
    /// saved). Until they are, the axis refuses every mode (each closes the current loop on
    /// the encoder's angle): [`crate::faults::Faults::NOT_COMMISSIONED`].
    #[serde(default)]
    pub commissioned: bool,
    pub rates: Rates,
    pub current: CurrentLoopGains,
    pub velocity: VelocityLoopGains,
    pub position: PositionLoopGains,
    pub filters: TorqueFilters,
    pub limits: Limits,
    /// Acceleration/deceleration filter of the position command path.
    pub acc_dec: AccDecParams,
    /// Stop / zero-servo / fine-adjust sequence (seed 004).
    pub sequence: SequenceParams,
    /// Torque pulse at each reversal of the commanded velocity.
    pub friction: FrictionCompensationParams,
    /// Frequency-response measurement (seed 000).
    pub sweep: SweepParams,
    /// Response-correction filter in front of the position loop (seed 001).
    pub correction: CorrectionParams,
    /// The removable machine-end accelerometer (seed 001's identification over a drive).
    pub accelerometer: AccelerometerParams,
}

/// Why a parameter set was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ParamError {
    /// NaN or infinite.
    NotFinite { field: &'static str },
    /// Must be strictly positive.
    NotPositive { field: &'static str, value: f32 },
    /// Must lie in `[min, max]`.
    OutOfRange { field: &'static str, value: f32, min: f32, max: f32 },
    /// The position divider must be a whole multiple of the velocity divider.
    RatesNotDivisible { velocity_divider: u32, position_divider: u32 },
    /// A divider or count of zero.
    Zero { field: &'static str },
    /// A filter frequency at or above the Nyquist frequency of the rate it runs at.
    AboveNyquist { field: &'static str, value: f32, nyquist: f32 },
    /// Undervoltage limit not below overvoltage limit.
    BusLimitsInverted { under: f32, over: f32 },
    /// The acc/dec filter cannot be built.
    AccDec(AccDecError),
    /// The stop sequence's settings are invalid.
    Sequence(SequenceParamError),
    /// The friction compensation's settings are invalid.
    Friction(FrictionCompensationError),
    /// The sweep's settings are invalid.
    Sweep(SweepError),
    /// The response-correction sections are invalid.
    Correction(CorrectionError),
}

impl fmt::Display for ParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::NotFinite { field } => write!(f, "{field} is not a finite number"),
            Self::NotPositive { field, value } => write!(f, "{field} must be > 0 (got {value})"),
            Self::OutOfRange { field, value, min, max } => {
                write!(f, "{field} = {value} is outside [{min}, {max}]")
            }
            Self::RatesNotDivisible { velocity_divider, position_divider } => write!(
                f,
                "position_divider ({position_divider}) must be a whole multiple of velocity_divider ({velocity_divider})"
            ),
            Self::Zero { field } => write!(f, "{field} must be at least 1"),
            Self::AboveNyquist { field, value, nyquist } => {
                write!(f, "{field} = {value} Hz is at or above the Nyquist frequency {nyquist} Hz")
            }
            Self::BusLimitsInverted { under, over } => write!(
                f,
                "bus_undervoltage ({under} V) must be below bus_overvoltage ({over} V)"
            ),
            Self::AccDec(e) => write!(f, "acc/dec filter: {e}"),
            Self::Sequence(e) => write!(f, "stop sequence: {e}"),
            Self::Friction(e) => write!(f, "{e}"),
            Self::Sweep(e) => write!(f, "{e}"),
            Self::Correction(e) => write!(f, "{e}"),
        }
    }
}

impl ParamError {
    /// The offending parameter's name (the group for the filters' and sequences' own checks).
    pub fn field(&self) -> &'static str {
        use crate::acc_dec::AccDecError as A;
        use crate::friction_compensation::FrictionCompensationError as F;
        use crate::response_correction::CorrectionError as C;
        use crate::stop_sequence::SequenceParamError as S;
        match *self {
            Self::NotFinite { field }
            | Self::NotPositive { field, .. }
            | Self::OutOfRange { field, .. }
            | Self::Zero { field } => field,
            Self::AboveNyquist { field, .. } => field,
            Self::RatesNotDivisible { .. } => "rates.position_divider",
            Self::BusLimitsInverted { .. } => "limits.bus_undervoltage",
            Self::AccDec(A::Order(_)) => "acc_dec.order",
            Self::AccDec(A::Cutoff(_) | A::CutoffAboveNyquist { .. } | A::CutoffBelowMinimum { .. }) => {
                "acc_dec.cutoff_hz"
            }
            Self::AccDec(A::Stages(_)) => "acc_dec.stages",
            Self::AccDec(A::Length { .. }) => "acc_dec.lengths",
            Self::AccDec(_) => "acc_dec",
            Self::Sequence(S::NotPositive { field, .. }) => field,
            Self::Sequence(S::GainCount(_)) => "sequence.gain_count",
            Self::Sequence(S::Gain { .. }) => "sequence.gains",
            Self::Sequence(S::SoftLimits { .. } | S::SoftLimitRange { .. }) => "sequence.soft_limit",
            Self::Sequence(S::CompletionHold(_)) => "sequence.completion_hold",
            Self::Friction(F::Amplitude(_)) => "friction.amplitude",
            Self::Friction(F::Decay(_)) => "friction.decay",
            Self::Sweep(crate::phase_shifted_sweep::SweepError::Setting { field, .. }) => field,
            Self::Sweep(crate::phase_shifted_sweep::SweepError::Range { field, .. }) => field,
            Self::Sweep(crate::phase_shifted_sweep::SweepError::AboveLoopNyquist { field, .. }) => field,
            Self::Sweep(_) => "sweep",
            Self::Correction(C::Count(_)) => "correction.count",
            Self::Correction(C::Frequency { .. }) => "correction frequency",
            Self::Correction(C::Damping { .. }) => "correction damping",
            Self::Correction(_) => "correction",
        }
    }
}

fn finite(field: &'static str, v: f32) -> Result<f32, ParamError> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(ParamError::NotFinite { field })
    }
}

fn positive(field: &'static str, v: f32) -> Result<(), ParamError> {
    if finite(field, v)? > 0.0 {
        Ok(())
    } else {
        Err(ParamError::NotPositive { field, value: v })
    }
}

fn in_range(field: &'static str, v: f32, min: f32, max: f32) -> Result<(), ParamError> {
    let v = finite(field, v)?;
    if v >= min && v <= max {
        Ok(())
    } else {
        Err(ParamError::OutOfRange { field, value: v, min, max })
    }
}

fn nonzero(field: &'static str, v: u32) -> Result<(), ParamError> {
    if v == 0 {
        Err(ParamError::Zero { field })
    } else {
        Ok(())
    }
}

fn filter_frequency(field: &'static str, v: f32, rate: f32) -> Result<(), ParamError> {
    in_range(field, v, 0.0, f32::MAX)?;
    let nyquist = 0.5 * rate;
    if v >= nyquist {
        Err(ParamError::AboveNyquist { field, value: v, nyquist })
    } else {
        Ok(())
    }
}

impl Default for Params {
    /// A 48 V, 4-pole-pair servo motor of 0.1 Nm/A with a 20-bit encoder, tuned for about
    /// 1.5 kHz current, 100 Hz velocity and 20 Hz position bandwidth on the default plant;
    /// not commissioned (the encoder's mounting unknown): an axis of these parameters refuses
    /// every mode until commissioning measures the motor, or [`Params::commissioned_as`] says
    /// where the encoder sits.
    fn default() -> Self {
        let motor = MotorModel { pole_pairs: 4, resistance: 0.3, ld: 0.5e-3, lq: 0.5e-3, flux_linkage: 0.1 / 6.0 };
        // Gains (rounded): current kp = Lq·ωc, ki = R·ωc with ωc = 2π·1500 rad/s; velocity
        // kp = J·ωv, ki = J·ωv²/5 with J = 1.5e-4 kg·m², ωv = 2π·100 rad/s; position 2π·20 1/s.
        Params {
            motor,
            encoder_counts_per_rev: 1 << 20,
            encoder_mounting: EncoderMounting::default(),
            commissioned: false,
            rates: Rates { current_loop_hz: 16_000.0, velocity_divider: 2, position_divider: 4 },
            current: CurrentLoopGains {
                kp: 4.7124,
                ki: 2827.4,
                decoupling: true,
                angle_advance_ticks: 1.5,
                max_current: 20.0,
            },
            velocity: VelocityLoopGains { kp: 0.0942, ki: 11.84, torque_limit: 2.0 },
            position: PositionLoopGains { kp: 125.7, velocity_feedforward: 1.0, velocity_limit: 300.0 },
            filters: TorqueFilters {
                low_pass_hz: 0.0,
                notch_hz: 0.0,
                notch_q: 1.0,
                notch_depth: 0.0,
                notch2_hz: 0.0,
                notch2_q: 1.0,
                notch2_depth: 0.0,
            },
            limits: Limits { overcurrent: 30.0, bus_undervoltage: 20.0, bus_overvoltage: 60.0, following_error: 2.0 },
            acc_dec: AccDecParams::default(),
            sequence: SequenceParams::default(),
            friction: FrictionCompensationParams::default(),
            sweep: SweepParams::default(),
            correction: CorrectionParams::default(),
            accelerometer: AccelerometerParams::default(),
        }
    }
}

/// The largest current one step of the decoupling's back-EMF term may drive in a tick, a
/// share of the currents the motor takes ([`Params::decoupling_steps_small`]).
pub const DECOUPLING_STEP_SHARE: f32 = 0.1;

impl Params {
    /// These parameters with the encoder's mounting given and marked commissioned: for a
    /// motor whose constants and mounting are known (a set commissioning saved, a test's
    /// synthetic motor).
    pub fn commissioned_as(mut self, mounting: EncoderMounting) -> Self {
        self.encoder_mounting = mounting;
        self.commissioned = true;
        self
    }

    /// These parameters with what commissioning measured: the motor's constants, the encoder's
    /// mounting and the current loop's gains, marked commissioned (every other setting kept;
    /// the decoupling, where it was on, only where its steps are small:
    /// [`Params::decoupling_steps_small`]).
    pub fn with_commissioned(mut self, m: &crate::commissioning::MeasuredMotor) -> Self {
        self.motor = MotorModel {
            pole_pairs: m.alignment.pole_pairs,
            resistance: m.resistance,
            ld: m.ld,
            lq: m.lq,
            flux_linkage: m.flux_linkage,
        };
        self.current.kp = m.current_kp;
        self.current.ki = m.current_ki;
        self.current.decoupling &= self.decoupling_steps_small(m.test_current);
        self.commissioned_as(EncoderMounting { reversed: m.alignment.reversed, electrical_offset: m.alignment.offset })
    }

    /// Whether the current loop's back-EMF feed-forward moves in small steps on this motor and
    /// encoder. The feed-forward `p·ω·ψ` takes the velocity estimate, which moves in steps of
    /// one count per velocity period; one such step held over a tick drives
    /// `p·ψ·(2π/counts)/T_v · T/L_q` amperes into the q winding before the loop answers. On a
    /// coarse encoder under a strong magnet with many pole pairs that is amperes a count, and
    /// the steps, fed back through the rotor's motion, make the loop trip (a light rotor's back
    /// EMF follows the current within a few ticks). Small means at most
    /// [`DECOUPLING_STEP_SHARE`] of `current` (A, the currents the motor takes) a tick; the
    /// loop's integrator then takes the back-EMF instead.
    pub fn decoupling_steps_small(&self, current: f32) -> bool {
        let m = &self.motor;
        let count_speed = crate::TAU / self.encoder_counts_per_rev as f32 / self.rates.velocity_period();
        let step = m.pole_pairs as f32 * count_speed * m.flux_linkage * self.rates.tick_period() / m.lq;
        step <= DECOUPLING_STEP_SHARE * current
    }

    /// Encoder counts per position tick at 1 rad/s: the scale from a speed to the
    /// interpolator's pulses per tick.
    pub fn counts_per_position_tick(&self) -> f32 {
        self.encoder_counts_per_rev as f32 / crate::TAU * self.rates.position_period()
    }

    /// Check every field; the first problem found is returned.
    pub fn validate(&self) -> Result<(), ParamError> {
        let m = &self.motor;
        nonzero("motor.pole_pairs", m.pole_pairs)?;
        in_range("motor.pole_pairs", m.pole_pairs as f32, 1.0, 64.0)?;
        positive("motor.resistance", m.resistance)?;
        positive("motor.ld", m.ld)?;
        positive("motor.lq", m.lq)?;
        positive("motor.flux_linkage", m.flux_linkage)?;
        nonzero("encoder_counts_per_rev", self.encoder_counts_per_rev)?;
        in_range("encoder_counts_per_rev", self.encoder_counts_per_rev as f32, 4.0, (1u32 << 24) as f32)?;
        let offset = self.encoder_mounting.electrical_offset;
        if !(finite("encoder_mounting.electrical_offset", offset)? >= 0.0 && offset < crate::TAU) {
            return Err(ParamError::OutOfRange {
                field: "encoder_mounting.electrical_offset",
                value: offset,
                min: 0.0,
                max: crate::TAU,
            });
        }

        let r = &self.rates;
        positive("rates.current_loop_hz", r.current_loop_hz)?;
        in_range("rates.current_loop_hz", r.current_loop_hz, 1000.0, 200_000.0)?;
        nonzero("rates.velocity_divider", r.velocity_divider)?;
        nonzero("rates.position_divider", r.position_divider)?;
        let max_divider = crate::ranges::MAX_LOOP_DIVIDER as f32;
        in_range("rates.velocity_divider", r.velocity_divider as f32, 1.0, max_divider)?;
        in_range("rates.position_divider", r.position_divider as f32, 1.0, max_divider)?;
        if !r.position_divider.is_multiple_of(r.velocity_divider) {
            return Err(ParamError::RatesNotDivisible {
                velocity_divider: r.velocity_divider,
                position_divider: r.position_divider,
            });
        }

        let c = &self.current;
        positive("current.kp", c.kp)?;
        in_range("current.ki", c.ki, 0.0, f32::MAX)?;
        in_range("current.angle_advance_ticks", c.angle_advance_ticks, 0.0, 4.0)?;
        positive("current.max_current", c.max_current)?;

        let v = &self.velocity;
        positive("velocity.kp", v.kp)?;
        in_range("velocity.ki", v.ki, 0.0, f32::MAX)?;
        positive("velocity.torque_limit", v.torque_limit)?;

        let p = &self.position;
        positive("position.kp", p.kp)?;
        in_range("position.velocity_feedforward", p.velocity_feedforward, 0.0, 1.0)?;
        positive("position.velocity_limit", p.velocity_limit)?;

        let f = &self.filters;
        let velocity_rate = r.current_loop_hz / r.velocity_divider as f32;
        filter_frequency("filters.low_pass_hz", f.low_pass_hz, velocity_rate)?;
        filter_frequency("filters.notch_hz", f.notch_hz, velocity_rate)?;
        positive("filters.notch_q", f.notch_q)?;
        in_range("filters.notch_depth", f.notch_depth, 0.0, 1.0)?;
        filter_frequency("filters.notch2_hz", f.notch2_hz, velocity_rate)?;
        positive("filters.notch2_q", f.notch2_q)?;
        in_range("filters.notch2_depth", f.notch2_depth, 0.0, 1.0)?;

        let l = &self.limits;
        positive("limits.overcurrent", l.overcurrent)?;
        positive("limits.bus_undervoltage", l.bus_undervoltage)?;
        positive("limits.bus_overvoltage", l.bus_overvoltage)?;
        if l.bus_undervoltage >= l.bus_overvoltage {
            return Err(ParamError::BusLimitsInverted { under: l.bus_undervoltage, over: l.bus_overvoltage });
        }
        positive("limits.following_error", l.following_error)?;
        AccDecFilter::check(&self.acc_dec, r.position_period()).map_err(ParamError::AccDec)?;
        self.sequence.validate().map_err(ParamError::Sequence)?;
        self.friction.validate().map_err(ParamError::Friction)?;
        // The sweep's settings on their own; held against the rates and the limits when a
        // sweep starts (`validate_sweep`): an axis that never sweeps runs at a lowered rate
        // with the default sweep settings.
        self.sweep.validate_settings(r.velocity_divider).map_err(ParamError::Sweep)?;
        self.correction.validate(r.position_period()).map_err(ParamError::Correction)?;
        in_range("accelerometer.sensitivity", self.accelerometer.sensitivity, MIN_SENSITIVITY, MAX_SENSITIVITY)?;
        Ok(())
    }

    /// The sweep's settings against the rates and limits of these (validated) parameters: what
    /// [`crate::axis::Axis::start_sweep`] checks before a sweep starts (and a drive when it is
    /// given parameters: its rate is its board's, so a sweep that cannot run there is refused
    /// by name at once). Every frequency below the Nyquist frequency of the loop it is
    /// injected into, a position-command amplitude within an i32 of counts, and no injection
    /// the torque or current limit would cut.
    pub fn validate_sweep(&self) -> Result<(), SweepError> {
        let r = &self.rates;
        self.sweep.validate(r.current_loop_hz, r.velocity_divider)?;
        if self.sweep.point == crate::excitation::InjectionPoint::PositionCommand {
            // Taken on position ticks, in whole counts of an i32 (`Axis::position_tick`).
            let nyquist = 0.5 * r.current_loop_hz / r.position_divider as f32;
            self.sweep.below_nyquist(nyquist, "current_loop_hz / position_divider")?;
            let (value, max) =
                (self.sweep.amplitude, i32::MAX as f32 * crate::TAU / self.encoder_counts_per_rev as f32);
            if value > max {
                return Err(SweepError::Range { field: "amplitude", value, min: 0.0, max });
            }
        }
        // The dither runs with the stepped sine only (the PRBS mode adds none): a PRBS sweep is
        // held against its own injection.
        let dither = self.sweep.dither_in_use();
        // The dither is added after the loop's torque clamp, so the current clamp cuts it: one
        // beyond the lower of the torque limit and the current limit's torque (kt·max_current)
        // is refused rather than cut (`crate::torque_ceiling`; at the clamp, on its own, it is
        // not cut).
        let dither_ceiling = TorqueCeiling::of(self, ExcitationEntry::BeforeTheLoopClamp, 0.0);
        if dither > dither_ceiling.torque {
            let (value, max) = (dither, dither_ceiling.torque);
            return Err(SweepError::Range { field: "dither", value, min: 0.0, max });
        }
        // Likewise a torque-command excitation whose own peak with the dither reaches the
        // current limit's torque (the injection is added after the loop's clamp, the current
        // reference's clamp cuts it): the measured response would not be the loop's. The
        // torque the loop commands beside it (a riding speed's friction, a torque set-point)
        // is not known here; the voltage circle is watched while it runs
        // (`SweepStatus::last_limited`), the torque command on the FMU's trace by the host.
        if self.sweep.point == crate::excitation::InjectionPoint::TorqueCommand {
            let ceiling = TorqueCeiling::of(self, ExcitationEntry::AfterTheLoopClamp, dither);
            if self.sweep.amplitude + dither >= ceiling.torque {
                let (value, max) = (self.sweep.amplitude, ceiling.room_beside(dither));
                return Err(SweepError::Range { field: "amplitude", value, min: 0.0, max });
            }
        }
        Ok(())
    }

    /// [`Params::validate`] and [`Params::validate_sweep`]: what a drive accepts (its loop
    /// rate is fixed by its board, so a sweep its parameters cannot run is refused when they
    /// are given, by name, rather than at the start).
    pub fn validate_for_drive(&self) -> Result<(), ParamError> {
        self.validate()?;
        self.validate_sweep().map_err(ParamError::Sweep)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// One count per velocity period of the back-EMF feed-forward, held a tick over the q
    /// inductance, computed here in f64 from the formula's parts.
    fn feed_forward_step(p: &Params) -> f64 {
        let m = &p.motor;
        let period = p.rates.velocity_divider as f64 / p.rates.current_loop_hz as f64;
        let speed = 2.0 * core::f64::consts::PI / p.encoder_counts_per_rev as f64 / period;
        m.pole_pairs as f64 * speed * m.flux_linkage as f64 / p.rates.current_loop_hz as f64 / m.lq as f64
    }

    #[test]
    fn the_decoupling_stays_on_where_a_count_of_its_back_emf_drives_a_tenth_of_the_current_at_most() {
        // The default motor on its 20-bit encoder: 0.4 mA a count.
        let default = Params::default();
        let step = feed_forward_step(&default);
        assert!((step - 4.0e-4).abs() < 1e-5, "{step}");
        assert!(default.decoupling_steps_small(0.01) && default.decoupling_steps_small(2.0));
        // 11 pole pairs, 54 mWb, 170 µH on a 1024-count encoder: 10.7 A a count.
        let mut coarse = Params {
            motor: MotorModel { pole_pairs: 11, resistance: 0.16, ld: 1.7e-4, lq: 1.7e-4, flux_linkage: 0.054 },
            encoder_counts_per_rev: 1024,
            ..Params::default()
        };
        let step = feed_forward_step(&coarse);
        assert!((step - 10.7).abs() < 0.05, "{step}");
        assert!(!coarse.decoupling_steps_small(2.0) && !coarse.decoupling_steps_small(100.0));
        // The boundary: a tenth of the current, either side by a hundredth.
        let at = (step / DECOUPLING_STEP_SHARE as f64) as f32;
        assert!(coarse.decoupling_steps_small(1.01 * at) && !coarse.decoupling_steps_small(0.99 * at));
        // A longer velocity period or a finer encoder makes the steps smaller in proportion.
        coarse.rates.velocity_divider = 4;
        assert!((feed_forward_step(&coarse) - step / 2.0).abs() < 1e-9);
        coarse.rates.velocity_divider = 2;
        coarse.encoder_counts_per_rev = 1024 * 64;
        assert!((feed_forward_step(&coarse) - step / 64.0).abs() < 1e-9);
        assert!(coarse.decoupling_steps_small(2.0));
    }

    #[test]
    fn a_sweep_dither_beyond_the_torque_limit_is_refused_not_cut() {
        let mut p = Params::default();
        p.sweep.dither = p.velocity.torque_limit;
        assert_eq!(p.validate_for_drive(), Ok(()));
        p.sweep.dither = p.velocity.torque_limit * 1.5;
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::Range { field: "dither", .. })), "{e:?}");
        assert_eq!(e.field(), "dither");
        // The axis itself runs (held against the limit when a sweep starts).
        assert_eq!(p.validate(), Ok(()));
    }

    /// The dither is added after the loop's torque clamp: where the current limit's torque
    /// (kt·max_current) is the lower, it is what cuts the dither, and what bounds it. (The
    /// torque limit alone accepted a 1.5 N·m dither on a 1 N·m current clamp.)
    #[test]
    fn a_sweep_dither_beyond_the_current_limit_torque_is_refused_where_the_current_binds() {
        let mut p = Params::default();
        p.current.max_current = 10.0;
        let current_torque = p.motor.torque_constant() * p.current.max_current;
        assert!(current_torque < p.velocity.torque_limit);
        p.sweep.dither = current_torque;
        assert_eq!(p.validate_for_drive(), Ok(()));
        p.sweep.dither = 1.5 * current_torque;
        assert_eq!(
            p.validate_sweep(),
            Err(SweepError::Range { field: "dither", value: 1.5 * current_torque, min: 0.0, max: current_torque })
        );
        // Where the torque limit is the lower, it bounds the dither as before.
        p.current.max_current = 40.0;
        assert_eq!(p.validate_for_drive(), Ok(()));
        p.sweep.dither = 1.01 * p.velocity.torque_limit;
        assert!(matches!(p.validate_sweep(), Err(SweepError::Range { field: "dither", .. })));
    }

    /// A lowered loop rate with the default sweep settings (3 kHz, above the velocity loop's
    /// Nyquist frequency of 2 kHz at 8 kHz): the axis builds and runs; the sweep is refused
    /// when it starts, naming the field, the frequency and the loop.
    #[test]
    fn a_lowered_rate_builds_the_axis_and_refuses_only_the_sweep_it_cannot_run() {
        extern crate std;
        let mut p = Params::default();
        p.rates.current_loop_hz = 8000.0;
        assert_eq!(p.validate(), Ok(()));
        let e = p.validate_sweep().unwrap_err();
        assert_eq!(
            e,
            SweepError::AboveLoopNyquist {
                field: "stop_hz",
                frequency: 3000.0,
                nyquist: 2000.0,
                rate: "current_loop_hz / velocity_divider"
            }
        );
        assert_eq!(
            std::format!("{e}"),
            "sweep stop_hz = 3000 Hz is at or above the Nyquist frequency 2000 Hz of the loop it is injected into (half of current_loop_hz / velocity_divider)"
        );
        assert_eq!(ParamError::Sweep(e).field(), "stop_hz");
        // A drive, whose rate is its board's, refuses such parameters at once, by name.
        assert_eq!(p.validate_for_drive().map_err(|e| e.field()), Err("stop_hz"));
        // Below the lowered Nyquist frequency, extra_hz is the highest and named.
        p.sweep.stop_hz = 1500.0;
        assert!(matches!(p.validate_sweep(), Err(SweepError::AboveLoopNyquist { field: "extra_hz", .. })));
        p.sweep.extra_hz = 0.0;
        assert_eq!(p.validate_for_drive(), Ok(()));
    }

    #[test]
    fn a_torque_command_sweep_whose_peak_reaches_the_current_limit_is_refused_not_cut() {
        let mut p = Params::default();
        p.sweep.point = crate::excitation::InjectionPoint::TorqueCommand;
        let peak = p.motor.torque_constant() * p.current.max_current;
        p.sweep.amplitude = 0.99 * (peak - p.sweep.dither);
        assert_eq!(p.validate_for_drive(), Ok(()));
        // The default amplitude (2, for the velocity points' rad/s) is the default axis's
        // current-limit torque (0.1 N·m/A × 20 A).
        p.sweep.amplitude = peak - p.sweep.dither;
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::Range { field: "amplitude", .. })), "{e:?}");
        // The current limit is what cuts the injection, not the velocity loop's torque limit
        // (the injection is added after it): a lower torque limit refuses nothing more, a
        // lower current limit does.
        p.sweep.amplitude = 1.5;
        p.velocity.torque_limit = 1.0;
        assert_eq!(p.validate_for_drive(), Ok(()));
        p.velocity.torque_limit = 2.0;
        p.current.max_current = 10.0;
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::Range { field: "amplitude", .. })), "{e:?}");
        // The velocity points' amplitude is a speed: not held against the torque limit.
        p.sweep.point = crate::excitation::InjectionPoint::VelocityCommand;
        p.sweep.amplitude = 2.0 * p.velocity.torque_limit;
        assert_eq!(p.validate_for_drive(), Ok(()));
    }

    #[test]
    fn a_prbs_sweep_is_held_against_its_own_injection_without_the_sine_s_dither() {
        // The PRBS mode adds no dither: an amplitude that leaves no room for the stepped
        // sine's dither below the current limit's torque is the PRBS's to use, and a dither
        // it does not run is not refused.
        let mut p = Params::default();
        p.sweep.point = crate::excitation::InjectionPoint::TorqueCommand;
        let peak = p.motor.torque_constant() * p.current.max_current;
        p.sweep.amplitude = peak - 0.5 * p.sweep.dither;
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::Range { field: "amplitude", .. })), "{e:?}");
        p.sweep.signal = crate::phase_shifted_sweep::SweepSignal::Prbs;
        assert_eq!(p.validate_for_drive(), Ok(()));
        // Its own peak at the ceiling is refused all the same.
        p.sweep.amplitude = peak;
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::Range { field: "amplitude", .. })), "{e:?}");
        p.sweep.amplitude = 0.5 * peak;
        p.sweep.dither = 1.5 * p.velocity.torque_limit;
        assert_eq!(p.validate_for_drive(), Ok(()));
        p.sweep.signal = crate::phase_shifted_sweep::SweepSignal::SteppedSine;
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::Range { field: "dither", .. })), "{e:?}");
    }

    #[test]
    fn a_position_command_sweep_stays_below_the_position_loop_nyquist_and_within_an_i32_of_counts() {
        let mut p = Params::default();
        p.sweep.point = crate::excitation::InjectionPoint::PositionCommand;
        let nyquist = 0.5 * p.rates.current_loop_hz / p.rates.position_divider as f32;
        // Below the velocity loop's Nyquist frequency (what the other points need), above the
        // position loop's: refused, not aliased.
        (p.sweep.stop_hz, p.sweep.extra_hz) = (1.5 * nyquist, 0.0);
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::AboveLoopNyquist { .. })), "{e:?}");
        p.sweep.stop_hz = 0.9 * nyquist;
        assert_eq!(p.validate_for_drive(), Ok(()));
        // An amplitude beyond 2³¹ counts would saturate: refused, not cut.
        p.sweep.amplitude = 1.01 * i32::MAX as f32 * crate::TAU / p.encoder_counts_per_rev as f32;
        let e = p.validate_for_drive().unwrap_err();
        assert!(matches!(e, ParamError::Sweep(SweepError::Range { field: "amplitude", .. })), "{e:?}");
    }

    #[test]
    fn defaults_are_valid() {
        assert_eq!(Params::default().validate_for_drive(), Ok(()));
    }

    #[test]
    fn each_kind_of_bad_value_is_named() {
        let mut p = Params::default();
        p.velocity.kp = f32::NAN;
        assert_eq!(p.validate(), Err(ParamError::NotFinite { field: "velocity.kp" }));

        let mut p = Params::default();
        p.motor.ld = -1e-3;
        assert!(matches!(p.validate(), Err(ParamError::NotPositive { field: "motor.ld", .. })));

        let mut p = Params::default();
        p.rates.position_divider = 5;
        assert!(matches!(p.validate(), Err(ParamError::RatesNotDivisible { .. })));

        let mut p = Params::default();
        p.rates.velocity_divider = 0;
        assert_eq!(p.validate(), Err(ParamError::Zero { field: "rates.velocity_divider" }));

        let mut p = Params::default();
        p.filters.notch_hz = 4000.0;
        assert!(matches!(p.validate(), Err(ParamError::AboveNyquist { .. })));

        let mut p = Params::default();
        p.filters.notch2_hz = 4000.0;
        assert!(matches!(p.validate(), Err(ParamError::AboveNyquist { field: "filters.notch2_hz", .. })));

        let mut p = Params::default();
        p.filters.notch2_q = f32::NAN;
        assert_eq!(p.validate().map_err(|e| e.field()), Err("filters.notch2_q"));

        let mut p = Params::default();
        p.limits.bus_undervoltage = 70.0;
        assert!(matches!(p.validate(), Err(ParamError::BusLimitsInverted { .. })));

        let mut p = Params::default();
        p.position.velocity_feedforward = 1.5;
        assert!(matches!(p.validate(), Err(ParamError::OutOfRange { .. })));
    }
}
