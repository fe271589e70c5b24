//! The FMI 3.0 model: variables, parameter mapping and the co-simulation step.
//!
//! Parameters are grouped in three children (`ctrl.*`, `plant.*`, `excitation.*`); their
//! start values are the control core's and the plant's defaults (a unit test keeps them equal).
//! All parameters are `fixed`: changing one after initialisation is refused and undone.

use std::panic::{catch_unwind, AssertUnwindSafe};

use control_core::excitation::InjectionPoint;
use control_core::params::{
    CurrentLoopGains, Limits, MotorModel, PositionLoopGains, Rates, TorqueFilters, VelocityLoopGains,
};
use control_core::acc_dec::{AccDecKind, AccDecParams};
use control_core::friction_compensation::FrictionCompensationParams;
use control_core::phase_shifted_sweep::{SweepParams, SweepSignal};
use control_core::response_correction::{CorrectionParams, CorrectionSection, SecondOrder};
use control_core::stop_sequence::{SequenceEvent, SequenceParams};
use control_core::{Mode, Params};
use fmi::fmi3::{Fmi3Error, Fmi3Res, Fmi3Status};
use fmi_export::fmi3::{CSDoStepResult, Context, DefaultLoggingCategory, UserModel};
use fmi_export::FmuModel;

use crate::plant::PlantParams;
use crate::simulation::{AxisSimulation, ExcitationConfig, SimulationConfig, UserInputs};

/// Declares a group of fixed parameters whose `Default` is the start values written into the
/// model description, so an instance (and `fmi3Reset`) starts from exactly those values.
macro_rules! parameter_group {
    ($name:ident { $( $(#[doc = $doc:literal])* $field:ident : $ty:ty = $start:literal, )* }) => {
        #[derive(FmuModel, Debug, Clone, PartialEq)]
        #[model()]
        pub struct $name {
            $(
                $(#[doc = $doc])*
                #[variable(causality = Parameter, variability = Fixed, start = $start)]
                pub $field: $ty,
            )*
        }

        impl Default for $name {
            fn default() -> Self {
                Self { $( $field: $start, )* }
            }
        }

        impl $name {
            /// `self == other` without stopping at the first difference: every field is
            /// compared, branch-free, which the compiler vectorises (this runs every step).
            fn same_as(&self, other: &Self) -> bool {
                true $( & (self.$field == other.$field) )*
            }
        }
    };
}

// Controller parameters (the drive's own settings).
parameter_group! {
    ControllerParameters {
        /// Current-loop (base tick) rate
        current_loop_hz: f64 = 16000.0,
        /// Velocity loop every this many base ticks
        velocity_divider: i32 = 2,
        /// Position loop every this many base ticks (multiple of velocity_divider)
        position_divider: i32 = 4,
        /// Current-loop proportional gain
        current_kp: f64 = 4.7124,
        /// Current-loop integral gain
        current_ki: f64 = 2827.4,
        /// Cross-coupling and back-EMF feed-forward on
        decoupling: bool = true,
        /// Electrical-angle advance of the voltage output, in base ticks
        angle_advance_ticks: f64 = 1.5,
        /// Largest commanded current magnitude
        max_current: f64 = 20.0,
        /// Velocity-loop proportional gain
        velocity_kp: f64 = 0.0942,
        /// Velocity-loop integral gain
        velocity_ki: f64 = 11.84,
        /// Torque limit
        torque_limit: f64 = 2.0,
        /// Position-loop gain
        position_kp: f64 = 125.7,
        /// Velocity feed-forward fraction
        velocity_feedforward: f64 = 1.0,
        /// Velocity command limit
        velocity_limit: f64 = 300.0,
        /// Torque-command low-pass cut-off (0 = off)
        low_pass_hz: f64 = 0.0,
        /// Torque-command notch centre (0 = off)
        notch_hz: f64 = 0.0,
        /// Notch quality factor
        notch_q: f64 = 1.0,
        /// Notch gain at the centre (0 = full notch)
        notch_depth: f64 = 0.0,
        /// Phase current that trips the overcurrent fault
        overcurrent: f64 = 30.0,
        /// Bus voltage below which the drive trips
        bus_undervoltage: f64 = 20.0,
        /// Bus voltage above which the drive trips
        bus_overvoltage: f64 = 60.0,
        /// Following error that trips in position mode
        following_error_limit: f64 = 1.0,
        /// Friction-compensation torque pulse at each reversal of the commanded velocity (0 = off)
        friction_comp_amplitude: f64 = 0.0,
        /// Decay time constant of that pulse
        friction_comp_decay: f64 = 0.01,
    }
}

// Motor, mechanics, encoder and sensor parameters of the simulated machine.
parameter_group! {
    PlantParameters {
        /// Motor pole pairs
        pole_pairs: i32 = 4,
        /// Stator resistance
        resistance: f64 = 0.3,
        /// d-axis inductance
        ld: f64 = 0.0005,
        /// q-axis inductance
        lq: f64 = 0.0005,
        /// Permanent-magnet flux linkage
        flux_linkage: f64 = 0.016666666666666666,
        /// DC-bus voltage
        bus_voltage: f64 = 48.0,
        /// Motor (rotor) inertia
        motor_inertia: f64 = 5.0e-5,
        /// Load inertia
        load_inertia: f64 = 1.0e-4,
        /// Shaft stiffness
        shaft_stiffness: f64 = 88.83,
        /// Shaft damping
        shaft_damping: f64 = 0.009425,
        /// Motor-side Coulomb friction
        motor_coulomb: f64 = 0.01,
        /// Motor-side viscous friction
        motor_viscous: f64 = 1.0e-5,
        /// Load-side Coulomb friction
        load_coulomb: f64 = 0.02,
        /// Load-side viscous friction
        load_viscous: f64 = 2.0e-5,
        /// Second mode on the load: absorber inertia (0 = none); anti-resonance sqrt(k/J)
        absorber_inertia: f64 = 0.0,
        /// Absorber spring to the load
        absorber_stiffness: f64 = 0.0,
        /// Absorber damping to the load
        absorber_damping: f64 = 0.0,
        /// Velocity scale of the smoothed Coulomb friction
        coulomb_velocity: f64 = 0.05,
        /// Encoder counts per motor revolution
        encoder_counts_per_rev: i32 = 1048576,
        /// Phase-current sensor noise (standard deviation; 0 = off)
        current_noise_std: f64 = 0.0,
        /// Machine-end accelerometer noise (standard deviation; 0 = off)
        acceleration_noise_std: f64 = 0.0,
        /// Seed of the sensor noise
        noise_seed: i32 = 1,
        /// Integration sub-steps per base tick (linear parts exact, couplings held)
        substeps: i32 = 1,
    }
}

// A sine added inside the drive at the loop rate.
parameter_group! {
    ExcitationParameters {
        /// 0 off, 1 torque command (Nm), 2 velocity command (rad/s)
        point: i32 = 0,
        /// Amplitude (Nm or rad/s)
        amplitude: f64 = 0.0,
        /// Frequency
        frequency: f64 = 0.0,
    }
}

// Acceleration/deceleration filter between the position command and the position loop.
parameter_group! {
    AccDecParameters {
        /// 0 none, 1 cascaded moving averages, 2 Butterworth (pole-zero matched)
        filter: i32 = 0,
        /// Butterworth order (1 to 6)
        order: i32 = 3,
        /// Butterworth cut-off (at most the position loop's Nyquist frequency)
        cutoff_hz: f64 = 40.0,
        /// Moving-average stages in use (1 to 3)
        ma_stages: i32 = 3,
        /// Length of moving-average stage 1 (position ticks)
        ma_length_1: i32 = 16,
        /// Length of moving-average stage 2 (position ticks)
        ma_length_2: i32 = 16,
        /// Length of moving-average stage 3 (position ticks)
        ma_length_3: i32 = 16,
    }
}

impl AccDecParameters {
    fn to_params(&self) -> Result<AccDecParams, String> {
        let kind = AccDecKind::from_code(self.filter).ok_or_else(|| {
            format!("accdec.filter must be 0 (none), 1 (moving averages) or 2 (Butterworth), got {}", self.filter)
        })?;
        Ok(AccDecParams {
            kind,
            order: count("accdec.order", self.order)?,
            cutoff_hz: self.cutoff_hz as f32,
            ma_stages: count("accdec.ma_stages", self.ma_stages)?,
            ma_lengths: [
                count("accdec.ma_length_1", self.ma_length_1)?,
                count("accdec.ma_length_2", self.ma_length_2)?,
                count("accdec.ma_length_3", self.ma_length_3)?,
            ],
        })
    }
}

// Stop / zero-servo / fine-adjust sequence (seed 004), used in mode 3.
parameter_group! {
    SequenceParameters {
        /// Speed of a run, and the speed limit of every positioning move
        target_speed: f64 = 100.0,
        /// Acceleration/deceleration gradient of the speed reference
        acceleration: f64 = 2000.0,
        /// A stop is accepted at or below this speed
        zero_speed: f64 = 2.0,
        /// Base position gain (speed reference per radian of deviation)
        position_gain: f64 = 20.0,
        /// Completion while |deviation| <= this many encoder counts
        completion_counts: i32 = 8,
        /// Entries of the gain table in use (1 to 8)
        gain_count: i32 = 4,
        /// Gain-table multiplier 1
        gain_1: f64 = 1.0,
        /// Gain-table multiplier 2
        gain_2: f64 = 2.0,
        /// Gain-table multiplier 3
        gain_3: f64 = 4.0,
        /// Gain-table multiplier 4
        gain_4: f64 = 8.0,
        /// Gain-table multiplier 5
        gain_5: f64 = 0.5,
        /// Gain-table multiplier 6
        gain_6: f64 = 0.25,
        /// Gain-table multiplier 7
        gain_7: f64 = 16.0,
        /// Gain-table multiplier 8
        gain_8: f64 = 32.0,
        /// Lowest allowed target
        soft_limit_min: f64 = -6283.185307179586,
        /// Highest allowed target
        soft_limit_max: f64 = 6283.185307179586,
    }
}

impl SequenceParameters {
    fn to_params(&self, counts_per_rev: u32) -> Result<SequenceParams, String> {
        let gains = [
            self.gain_1, self.gain_2, self.gain_3, self.gain_4, self.gain_5, self.gain_6, self.gain_7, self.gain_8,
        ]
        .map(|g| g as f32);
        let counts = |name: &str, rad: f64| -> Result<i64, String> {
            if !(rad.is_finite() && rad.abs() <= 1.0e9) {
                return Err(format!("{name} {rad} rad must be a finite angle within ±1e9 rad"));
            }
            Ok((rad / std::f64::consts::TAU * counts_per_rev as f64).round() as i64)
        };
        Ok(SequenceParams {
            target_speed: self.target_speed as f32,
            acceleration: self.acceleration as f32,
            zero_speed: self.zero_speed as f32,
            position_gain: self.position_gain as f32,
            completion_counts: count("seq.completion_counts", self.completion_counts)?,
            gains,
            gain_count: count("seq.gain_count", self.gain_count)? as usize,
            soft_limit_min: counts("seq.soft_limit_min", self.soft_limit_min)?,
            soft_limit_max: counts("seq.soft_limit_max", self.soft_limit_max)?,
        })
    }
}

// Frequency-response sweep (seed 000), started by `sweep_start`.
parameter_group! {
    SweepParameters {
        /// Injection point: 1 torque command, 2 velocity command, 3 velocity feedback (open loop)
        point: i32 = 2,
        /// 0 stepped sine (phase shifted above the threshold), 1 PRBS (broadband baseline)
        signal: i32 = 0,
        /// Sine or PRBS amplitude (rad/s or N.m, as the point)
        amplitude: f64 = 2.0,
        /// First frequency
        start_hz: f64 = 10.0,
        /// Last frequency
        stop_hz: f64 = 3000.0,
        /// Frequencies from start to stop, both included
        points: i32 = 40,
        /// 1 logarithmic, 0 linear spacing
        logarithmic: i32 = 1,
        /// One more frequency inserted in order (0 = none)
        extra_hz: f64 = 2000.0,
        /// Settling before each record, in cycles (at least min_settle_s)
        settle_cycles: f64 = 2.0,
        /// Shortest settling
        min_settle_s: f64 = 0.02,
        /// Measurement of each record, in cycles (at least min_measure_s)
        measure_cycles: f64 = 4.0,
        /// Shortest measurement
        min_measure_s: f64 = 0.08,
        /// Phase step 2*pi/shifts between the repeats of one frequency
        shifts: i32 = 3,
        /// Records per frequency at and above the threshold
        repeats: i32 = 3,
        /// Phase shifting from this frequency up (0 = the acquisition Nyquist frequency)
        threshold_hz: f64 = 0.0,
        /// Base ticks per acquisition sample (4 = 4 kHz at 16 kHz)
        acquisition_divider: i32 = 4,
        /// PRBS: M-sequence degree (2 to 20; period 2^n - 1 chips)
        prbs_degree: i32 = 15,
        /// PRBS: base ticks per chip
        prbs_divider: i32 = 1,
        /// PRBS: measured duration
        prbs_seconds: f64 = 5.0,
        /// Stepped sine: lengthen a frequency's records by whole blocks so that the standard error of its gain, predicted after the first block, is at most this (dB; 0 = fixed records)
        precision_db: f64 = 0.03,
        /// At most so many extra measurement blocks per record (0 to 64)
        max_extensions: i32 = 8,
    }
}

impl SweepParameters {
    fn to_params(&self) -> Result<SweepParams, String> {
        let point = InjectionPoint::from_code(self.point)
            .filter(|p| *p != InjectionPoint::Off)
            .ok_or_else(|| format!("sweep.point must be 1 (torque), 2 (velocity command) or 3 (velocity feedback), got {}", self.point))?;
        let signal = match self.signal {
            0 => SweepSignal::SteppedSine,
            1 => SweepSignal::Prbs,
            other => return Err(format!("sweep.signal must be 0 (stepped sine) or 1 (PRBS), got {other}")),
        };
        Ok(SweepParams {
            point,
            signal,
            amplitude: self.amplitude as f32,
            start_hz: self.start_hz as f32,
            stop_hz: self.stop_hz as f32,
            points: count("sweep.points", self.points)?,
            logarithmic: self.logarithmic != 0,
            extra_hz: self.extra_hz as f32,
            settle_cycles: self.settle_cycles as f32,
            min_settle_s: self.min_settle_s as f32,
            measure_cycles: self.measure_cycles as f32,
            min_measure_s: self.min_measure_s as f32,
            shifts: count("sweep.shifts", self.shifts)?,
            repeats: count("sweep.repeats", self.repeats)?,
            threshold_hz: self.threshold_hz as f32,
            acquisition_divider: count("sweep.acquisition_divider", self.acquisition_divider)?,
            prbs_degree: count("sweep.prbs_degree", self.prbs_degree)?,
            prbs_divider: count("sweep.prbs_divider", self.prbs_divider)?,
            prbs_seconds: self.prbs_seconds as f32,
            precision_db: self.precision_db as f32,
            max_extensions: count("sweep.max_extensions", self.max_extensions)?,
        })
    }
}

// Response-correction filter in front of the position loop (seed 001): `servo tune` writes it.
parameter_group! {
    CorrectionParameters {
        /// Sections in use (0 = no correction, up to 8)
        count: i32 = 0,
        /// Section 1: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_1: f64 = 0.0,
        /// Section 1: anti-resonance numerator damping
        zero_damping_1: f64 = 0.0,
        /// Section 1: low-pass pole-pair frequency
        pole_hz_1: f64 = 100.0,
        /// Section 1: low-pass pole-pair damping
        pole_damping_1: f64 = 1.0,
        /// Section 2: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_2: f64 = 0.0,
        /// Section 2: anti-resonance numerator damping
        zero_damping_2: f64 = 0.0,
        /// Section 2: low-pass pole-pair frequency
        pole_hz_2: f64 = 100.0,
        /// Section 2: low-pass pole-pair damping
        pole_damping_2: f64 = 1.0,
        /// Section 3: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_3: f64 = 0.0,
        /// Section 3: anti-resonance numerator damping
        zero_damping_3: f64 = 0.0,
        /// Section 3: low-pass pole-pair frequency
        pole_hz_3: f64 = 100.0,
        /// Section 3: low-pass pole-pair damping
        pole_damping_3: f64 = 1.0,
        /// Section 4: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_4: f64 = 0.0,
        /// Section 4: anti-resonance numerator damping
        zero_damping_4: f64 = 0.0,
        /// Section 4: low-pass pole-pair frequency
        pole_hz_4: f64 = 100.0,
        /// Section 4: low-pass pole-pair damping
        pole_damping_4: f64 = 1.0,
        /// Section 5: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_5: f64 = 0.0,
        /// Section 5: anti-resonance numerator damping
        zero_damping_5: f64 = 0.0,
        /// Section 5: low-pass pole-pair frequency
        pole_hz_5: f64 = 100.0,
        /// Section 5: low-pass pole-pair damping
        pole_damping_5: f64 = 1.0,
        /// Section 6: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_6: f64 = 0.0,
        /// Section 6: anti-resonance numerator damping
        zero_damping_6: f64 = 0.0,
        /// Section 6: low-pass pole-pair frequency
        pole_hz_6: f64 = 100.0,
        /// Section 6: low-pass pole-pair damping
        pole_damping_6: f64 = 1.0,
        /// Section 7: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_7: f64 = 0.0,
        /// Section 7: anti-resonance numerator damping
        zero_damping_7: f64 = 0.0,
        /// Section 7: low-pass pole-pair frequency
        pole_hz_7: f64 = 100.0,
        /// Section 7: low-pass pole-pair damping
        pole_damping_7: f64 = 1.0,
        /// Section 8: anti-resonance numerator frequency (0 = no zeros in this section)
        zero_hz_8: f64 = 0.0,
        /// Section 8: anti-resonance numerator damping
        zero_damping_8: f64 = 0.0,
        /// Section 8: low-pass pole-pair frequency
        pole_hz_8: f64 = 100.0,
        /// Section 8: low-pass pole-pair damping
        pole_damping_8: f64 = 1.0,
    }
}

impl CorrectionParameters {
    fn to_params(&self) -> Result<CorrectionParams, String> {
        let raw = [
            (self.zero_hz_1, self.zero_damping_1, self.pole_hz_1, self.pole_damping_1),
            (self.zero_hz_2, self.zero_damping_2, self.pole_hz_2, self.pole_damping_2),
            (self.zero_hz_3, self.zero_damping_3, self.pole_hz_3, self.pole_damping_3),
            (self.zero_hz_4, self.zero_damping_4, self.pole_hz_4, self.pole_damping_4),
            (self.zero_hz_5, self.zero_damping_5, self.pole_hz_5, self.pole_damping_5),
            (self.zero_hz_6, self.zero_damping_6, self.pole_hz_6, self.pole_damping_6),
            (self.zero_hz_7, self.zero_damping_7, self.pole_hz_7, self.pole_damping_7),
            (self.zero_hz_8, self.zero_damping_8, self.pole_hz_8, self.pole_damping_8),
        ];
        let mut p = CorrectionParams { count: count("corr.count", self.count)? as usize, ..Default::default() };
        for (s, (zh, zd, ph, pd)) in p.sections.iter_mut().zip(raw) {
            *s = CorrectionSection {
                zeros: (zh != 0.0).then_some(SecondOrder { hz: zh as f32, damping: zd as f32 }),
                poles: SecondOrder { hz: ph as f32, damping: pd as f32 },
            };
        }
        Ok(p)
    }
}

/// Sequence inputs as last seen: presses are increases of a counter input.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
struct SequenceInputsSeen {
    run: bool,
    gain_index: i32,
    stop: i32,
    release: i32,
    moves: i32,
    returns: i32,
}

#[derive(Clone, Debug, PartialEq)]
struct AppliedParameters {
    ctrl: ControllerParameters,
    plant: PlantParameters,
    excitation: ExcitationParameters,
    accdec: AccDecParameters,
    seq: SequenceParameters,
    sweep: SweepParameters,
    corr: CorrectionParameters,
}

/// One servo axis: control core (current, velocity, position loops) driving a PMSM with a
/// two-inertia load.
#[derive(FmuModel, Default)]
#[model(model_exchange = false, co_simulation = true, user_model = false)]
pub struct ServoAxis {
    #[child(prefix = "ctrl")]
    pub ctrl: ControllerParameters,
    #[child(prefix = "plant")]
    pub plant: PlantParameters,
    #[child(prefix = "excitation")]
    pub excitation: ExcitationParameters,
    #[child(prefix = "accdec")]
    pub accdec: AccDecParameters,
    #[child(prefix = "seq")]
    pub seq: SequenceParameters,
    #[child(prefix = "sweep")]
    pub sweep: SweepParameters,
    #[child(prefix = "corr")]
    pub corr: CorrectionParameters,

    /// Control mode: 0 torque, 1 velocity, 2 position, 3 stop sequence (seq_* inputs)
    #[variable(causality = Input, variability = Discrete, start = 2)]
    pub mode: i32,
    /// Motor-side position command: streamed through the acc/dec filter, or the target of a move when move_speed > 0
    #[variable(causality = Input, variability = Continuous, start = 0.0)]
    pub position_command: f64,
    /// Positioning speed towards position_command (0: stream position_command)
    #[variable(causality = Input, variability = Continuous, start = 0.0)]
    pub move_speed: f64,
    /// Jog speed in position mode (non-zero overrides position_command)
    #[variable(causality = Input, variability = Continuous, start = 0.0)]
    pub jog_velocity: f64,
    /// Motor velocity command
    #[variable(causality = Input, variability = Continuous, start = 0.0)]
    pub velocity_command: f64,
    /// Torque command (torque mode)
    #[variable(causality = Input, variability = Continuous, start = 0.0)]
    pub torque_command: f64,
    /// External torque on the load
    #[variable(causality = Input, variability = Continuous, start = 0.0)]
    pub disturbance_torque: f64,
    /// A change from false to true clears latched faults
    #[variable(causality = Input, variability = Discrete, start = false)]
    pub fault_reset: bool,
    /// Sequence run switch (mode 3): non-zero = run at seq.target_speed, 0 = decelerate
    #[variable(causality = Input, variability = Discrete, start = 0)]
    pub seq_run: i32,
    /// Sequence stop key: each increase is one press (accepted at or below seq.zero_speed, held pending while decelerating)
    #[variable(causality = Input, variability = Discrete, start = 0)]
    pub seq_stop: i32,
    /// Sequence position-command blocking release key: each increase is one press
    #[variable(causality = Input, variability = Discrete, start = 0)]
    pub seq_release: i32,
    /// Sequence move key: each increase moves to seq_target (fine adjust only)
    #[variable(causality = Input, variability = Discrete, start = 0)]
    pub seq_move: i32,
    /// Sequence return-to-start key: each increase is one press
    #[variable(causality = Input, variability = Discrete, start = 0)]
    pub seq_return: i32,
    /// Target of the sequence move key (motor side)
    #[variable(causality = Input, variability = Discrete, start = 0.0)]
    pub seq_target: f64,
    /// Frequency-response sweep start key: each increase starts the sweep of the sweep.* parameters (refused with a logged warning in torque mode for a velocity-loop injection point)
    #[variable(causality = Input, variability = Discrete, start = 0)]
    pub sweep_start: i32,
    /// Selected gain-table entry (0-based); a change selects it
    #[variable(causality = Input, variability = Discrete, start = 0)]
    pub seq_gain_index: i32,

    /// Motor angle (true, not quantised)
    #[variable(causality = Output, variability = Continuous)]
    pub motor_position: f64,
    /// Motor velocity (true)
    #[variable(causality = Output, variability = Continuous)]
    pub motor_velocity: f64,
    /// Load (machine-end) angle
    #[variable(causality = Output, variability = Continuous)]
    pub load_position: f64,
    /// Load (machine-end) velocity
    #[variable(causality = Output, variability = Continuous)]
    pub load_velocity: f64,
    /// Load (machine-end) acceleration, as the accelerometer reads it (with its noise)
    #[variable(causality = Output, variability = Continuous)]
    pub load_acceleration: f64,
    /// Measured q-axis current
    #[variable(causality = Output, variability = Continuous)]
    pub iq: f64,
    /// Measured d-axis current
    #[variable(causality = Output, variability = Continuous)]
    pub id: f64,
    /// Torque command into the current loop (after limits, filters and excitation)
    #[variable(causality = Output, variability = Continuous)]
    pub torque_command_out: f64,
    /// Electromagnetic torque of the motor (true)
    #[variable(causality = Output, variability = Continuous)]
    pub electromagnetic_torque: f64,
    /// Velocity estimated by the drive from the encoder
    #[variable(causality = Output, variability = Continuous)]
    pub velocity_estimate: f64,
    /// Position command minus encoder position (position mode)
    #[variable(causality = Output, variability = Continuous)]
    pub following_error: f64,
    /// Position command after interpolation and acc/dec filter (position mode)
    #[variable(causality = Output, variability = Continuous)]
    pub position_command_out: f64,
    /// Speed of that command (its pulses per position tick)
    #[variable(causality = Output, variability = Continuous)]
    pub command_velocity: f64,
    /// Sequence state: 0 idle, 1 running, 2 decelerating, 3 servo lock, 4 fine adjust
    #[variable(causality = Output, variability = Discrete)]
    pub seq_state: i32,
    /// Zero-servo / fine-adjust completion (|deviation| <= seq.completion_counts)
    #[variable(causality = Output, variability = Discrete)]
    pub seq_complete: i32,
    /// Deviation counter: target minus position, in encoder counts (saturates at the Int32 range)
    #[variable(causality = Output, variability = Discrete)]
    pub seq_deviation: i32,
    /// Position the sequence holds or moves to (the accepted stop position in servo lock)
    #[variable(causality = Output, variability = Discrete)]
    pub seq_hold_position: f64,
    /// Speed reference the sequence hands to the velocity loop
    #[variable(causality = Output, variability = Continuous)]
    pub seq_speed_reference: f64,
    /// Gain multiplier in use
    #[variable(causality = Output, variability = Discrete)]
    pub seq_gain: f64,
    /// Sequence events refused so far
    #[variable(causality = Output, variability = Discrete)]
    pub seq_refused: i32,
    /// Reason of the last refusal: 0 none, 1 already running, 2 not running, 3 stop while running, 4 already stopped, 5 no accepted stop, 6 target blocked, 7 beyond soft limits, 8 gain index, 9 not in sequence mode
    #[variable(causality = Output, variability = Discrete)]
    pub seq_last_refusal: i32,
    /// Sweep state: 0 idle, 1 settling, 2 measuring, 3 done
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_state: i32,
    /// Index of the frequency being measured
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_point: i32,
    /// Record (phase-shifted repeat) of that frequency
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_record: i32,
    /// Frequency being measured
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_frequency: f64,
    /// Frequencies measured so far (the on-line correlator's results)
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_done_points: i32,
    /// Last measured frequency
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_last_frequency: f64,
    /// Its gain (on-line correlator, on the drive)
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_last_gain_db: f64,
    /// Its phase
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_last_phase_deg: f64,
    /// Its quality: fraction of U's AC power at the excitation frequency
    #[variable(causality = Output, variability = Discrete)]
    pub sweep_last_quality: f64,
    /// Time of the last acquisition sample (the base tick it was taken at)
    #[variable(causality = Output, variability = Discrete)]
    pub acq_time: f64,
    /// Acquired U (see the README for what it is per injection point)
    #[variable(causality = Output, variability = Discrete)]
    pub acq_u: f64,
    /// Acquired Y (the velocity estimate)
    #[variable(causality = Output, variability = Discrete)]
    pub acq_y: f64,
    /// Excitation phase at that sample
    #[variable(causality = Output, variability = Discrete)]
    pub acq_phase: f64,
    /// 1 if the sample belongs to a measured record
    #[variable(causality = Output, variability = Discrete)]
    pub acq_measuring: i32,
    /// Frequency index the sample belongs to
    #[variable(causality = Output, variability = Discrete)]
    pub acq_point: i32,
    /// Record (phase-shifted repeat) the sample belongs to
    #[variable(causality = Output, variability = Discrete)]
    pub acq_record: i32,
    /// Latched fault bits: 1 overcurrent, 2 undervoltage, 4 overvoltage, 8 following error, 16 non-finite, 32 encoder
    #[variable(causality = Output, variability = Discrete)]
    pub faults: i32,

    sim: Option<AxisSimulation>,
    applied: Option<AppliedParameters>,
    last_fault_reset: bool,
    seen: SequenceInputsSeen,
    seen_sweep_start: i32,
    /// Refused sequence events of the last step, for the log.
    refusals: Vec<String>,
    /// The sweep result (bits of its re, im) that sweep_last_gain_db / _phase_deg show.
    reported_sweep_result: Option<(u32, u32)>,
    /// The last communication step size accepted (its bits) and its number of base ticks.
    accepted_step: Option<(u64, u64)>,
}

impl ControllerParameters {
    fn to_params(&self, motor: MotorModel, counts: u32) -> Params {
        Params {
            motor,
            encoder_counts_per_rev: counts,
            rates: Rates {
                current_loop_hz: self.current_loop_hz as f32,
                velocity_divider: self.velocity_divider.max(0) as u32,
                position_divider: self.position_divider.max(0) as u32,
            },
            current: CurrentLoopGains {
                kp: self.current_kp as f32,
                ki: self.current_ki as f32,
                decoupling: self.decoupling,
                angle_advance_ticks: self.angle_advance_ticks as f32,
                max_current: self.max_current as f32,
            },
            velocity: VelocityLoopGains {
                kp: self.velocity_kp as f32,
                ki: self.velocity_ki as f32,
                torque_limit: self.torque_limit as f32,
            },
            position: PositionLoopGains {
                kp: self.position_kp as f32,
                velocity_feedforward: self.velocity_feedforward as f32,
                velocity_limit: self.velocity_limit as f32,
            },
            filters: TorqueFilters {
                low_pass_hz: self.low_pass_hz as f32,
                notch_hz: self.notch_hz as f32,
                notch_q: self.notch_q as f32,
                notch_depth: self.notch_depth as f32,
            },
            limits: Limits {
                overcurrent: self.overcurrent as f32,
                bus_undervoltage: self.bus_undervoltage as f32,
                bus_overvoltage: self.bus_overvoltage as f32,
                following_error: self.following_error_limit as f32,
            },
            friction: FrictionCompensationParams {
                amplitude: self.friction_comp_amplitude as f32,
                decay: self.friction_comp_decay as f32,
            },
            // Set from the `accdec`, `seq` and `sweep` groups by `ServoAxis::config`.
            acc_dec: AccDecParams::default(),
            sequence: SequenceParams::default(),
            sweep: SweepParams::default(),
            correction: CorrectionParams::default(),
        }
    }
}

/// A negative value given for a count parameter.
fn count(name: &str, v: i32) -> Result<u32, String> {
    u32::try_from(v).map_err(|_| format!("{name} must not be negative (got {v})"))
}

impl ServoAxis {
    fn config(&self) -> Result<SimulationConfig, String> {
        let pp = &self.plant;
        let pole_pairs = count("plant.pole_pairs", pp.pole_pairs)?;
        let counts = count("plant.encoder_counts_per_rev", pp.encoder_counts_per_rev)?;
        count("ctrl.velocity_divider", self.ctrl.velocity_divider)?;
        count("ctrl.position_divider", self.ctrl.position_divider)?;
        let motor = MotorModel {
            pole_pairs,
            resistance: pp.resistance as f32,
            ld: pp.ld as f32,
            lq: pp.lq as f32,
            flux_linkage: pp.flux_linkage as f32,
        };
        let plant = PlantParams {
            pole_pairs,
            resistance: pp.resistance,
            ld: pp.ld,
            lq: pp.lq,
            flux_linkage: pp.flux_linkage,
            bus_voltage: pp.bus_voltage,
            motor_inertia: pp.motor_inertia,
            load_inertia: pp.load_inertia,
            shaft_stiffness: pp.shaft_stiffness,
            shaft_damping: pp.shaft_damping,
            motor_coulomb: pp.motor_coulomb,
            motor_viscous: pp.motor_viscous,
            load_coulomb: pp.load_coulomb,
            load_viscous: pp.load_viscous,
            absorber_inertia: pp.absorber_inertia,
            absorber_stiffness: pp.absorber_stiffness,
            absorber_damping: pp.absorber_damping,
            coulomb_velocity: pp.coulomb_velocity,
            encoder_counts_per_rev: counts,
            current_noise_std: pp.current_noise_std,
            acceleration_noise_std: pp.acceleration_noise_std,
            noise_seed: pp.noise_seed as u32 as u64,
            tick: 1.0 / self.ctrl.current_loop_hz,
            substeps: count("plant.substeps", pp.substeps)?,
        };
        let point = InjectionPoint::from_code(self.excitation.point).ok_or_else(|| {
            format!("excitation.point must be 0, 1 or 2 (got {})", self.excitation.point)
        })?;
        let mut control = self.ctrl.to_params(motor, counts);
        control.acc_dec = self.accdec.to_params()?;
        control.sequence = self.seq.to_params(counts)?;
        control.sweep = self.sweep.to_params()?;
        control.correction = self.corr.to_params()?;
        Ok(SimulationConfig {
            control,
            plant,
            excitation: ExcitationConfig {
                point,
                amplitude: self.excitation.amplitude as f32,
                frequency_hz: self.excitation.frequency as f32,
            },
        })
    }

    fn applied_now(&self) -> AppliedParameters {
        AppliedParameters {
            ctrl: self.ctrl.clone(),
            plant: self.plant.clone(),
            excitation: self.excitation.clone(),
            accdec: self.accdec.clone(),
            seq: self.seq.clone(),
            sweep: self.sweep.clone(),
            corr: self.corr.clone(),
        }
    }

    fn user_inputs(&self) -> Result<UserInputs, String> {
        let mode = Mode::from_code(self.mode)
            .ok_or_else(|| format!("mode must be 0 (torque), 1 (velocity), 2 (position) or 3 (stop sequence), got {}", self.mode))?;
        for (name, v) in [
            ("position_command", self.position_command),
            ("move_speed", self.move_speed),
            ("jog_velocity", self.jog_velocity),
            ("velocity_command", self.velocity_command),
            ("torque_command", self.torque_command),
            ("disturbance_torque", self.disturbance_torque),
            ("seq_target", self.seq_target),
        ] {
            if !v.is_finite() {
                return Err(format!("input {name} is not a finite number ({v})"));
            }
        }
        // Encoder counts are i64 in the core; keep far from overflow.
        if self.position_command.abs() > 1.0e9 {
            return Err(format!("position_command {} rad is out of range (|x| <= 1e9)", self.position_command));
        }
        if self.move_speed < 0.0 {
            return Err(format!("move_speed {} rad/s must be >= 0 (the direction comes from the target)", self.move_speed));
        }
        Ok(UserInputs {
            mode,
            position_command: self.position_command,
            move_speed: self.move_speed,
            jog_velocity: self.jog_velocity,
            velocity_command: self.velocity_command,
            torque_command: self.torque_command,
            disturbance_torque: self.disturbance_torque,
        })
    }

    fn update_outputs(&mut self) {
        let Some(sim) = self.sim.as_ref() else { return };
        let x = sim.plant.state;
        let t = sim.telemetry();
        self.motor_position = x.motor_angle;
        self.motor_velocity = x.motor_velocity;
        self.load_position = x.load_angle;
        self.load_velocity = x.load_velocity;
        self.load_acceleration = sim.plant.accelerometer;
        self.iq = t.current.q as f64;
        self.id = t.current.d as f64;
        self.torque_command_out = t.torque_command as f64;
        self.electromagnetic_torque = sim.plant.electromagnetic_torque;
        self.velocity_estimate = t.velocity_estimate as f64;
        self.following_error = t.following_error as f64;
        let rad_per_count = std::f64::consts::TAU / sim.axis.params().encoder_counts_per_rev as f64;
        self.position_command_out = t.position_command as f64 * rad_per_count;
        self.command_velocity =
            t.command_pulses as f64 * rad_per_count / sim.axis.params().rates.position_period() as f64;
        let q = &t.sequence;
        self.seq_state = q.state.code();
        self.seq_complete = q.complete as i32;
        self.seq_deviation = q.deviation.clamp(i32::MIN as i64, i32::MAX as i64) as i32;
        self.seq_hold_position = q.target as f64 * rad_per_count;
        self.seq_speed_reference = q.speed_reference as f64;
        self.seq_gain = sim.axis.params().sequence.gains[q.gain_index] as f64;
        self.seq_refused = q.refused.min(i32::MAX as u32) as i32;
        self.seq_last_refusal = q.last_refusal.map_or(0, |r| r.code());
        let w = &t.sweep;
        self.sweep_state = w.state.code();
        self.sweep_point = w.point as i32;
        self.sweep_record = w.record as i32;
        self.sweep_frequency = w.frequency as f64;
        self.sweep_done_points = w.done_points as i32;
        self.sweep_last_frequency = w.last.frequency as f64;
        // A logarithm and an arctangent: only when the result they come from changes.
        let key = (w.last.re.to_bits(), w.last.im.to_bits());
        if self.reported_sweep_result != Some(key) {
            self.sweep_last_gain_db = w.last.gain_db() as f64;
            self.sweep_last_phase_deg = w.last.phase_deg() as f64;
            self.reported_sweep_result = Some(key);
        }
        self.sweep_last_quality = w.last.quality as f64;
        self.acq_time = w.sample.tick as f64 * sim.tick_period();
        self.acq_u = w.sample.u as f64;
        self.acq_y = w.sample.y as f64;
        self.acq_phase = w.sample.phase as f64;
        self.acq_measuring = w.sample.measuring as i32;
        self.acq_point = w.sample.point as i32;
        self.acq_record = w.sample.record as i32;
        self.faults = t.faults.0 as i32;
    }

    /// Turn changes of the sequence inputs into events, in a fixed order: gain, run, stop,
    /// release, move, return. A refused event is reported (logged), not an FMI error.
    fn sequence_events(&mut self, inputs: &UserInputs) {
        let Some(sim) = self.sim.as_mut() else { return };
        sim.apply_mode(inputs);
        let seen = self.seen;
        let pressed = |now: i32, before: i32| now > before;
        let mut events = Vec::new();
        if self.seq_gain_index != seen.gain_index {
            // A negative index is as far outside the table as a large one.
            events.push(SequenceEvent::SelectGain(usize::try_from(self.seq_gain_index).unwrap_or(usize::MAX)));
        }
        let run = self.seq_run != 0;
        if run != seen.run {
            events.push(if run { SequenceEvent::RunOn } else { SequenceEvent::RunOff });
        }
        if pressed(self.seq_stop, seen.stop) {
            events.push(SequenceEvent::Stop);
        }
        if pressed(self.seq_release, seen.release) {
            events.push(SequenceEvent::ReleaseBlocking);
        }
        if pressed(self.seq_move, seen.moves) {
            events.push(SequenceEvent::MoveTo(sim.counts_for(self.seq_target)));
        }
        if pressed(self.seq_return, seen.returns) {
            events.push(SequenceEvent::ReturnToStart);
        }
        for e in events {
            if let Err(reason) = sim.axis.sequence_event(e) {
                self.refusals.push(format!("sequence event {e:?} at t = {} s: {reason}", sim.ticks() as f64 * sim.tick_period()));
            }
        }
        self.seen = SequenceInputsSeen {
            run,
            gain_index: self.seq_gain_index,
            stop: self.seq_stop,
            release: self.seq_release,
            moves: self.seq_move,
            returns: self.seq_return,
        };
    }

    fn step(&mut self, current: f64, h: f64) -> Result<(), String> {
        let Some(applied) = self.applied.as_ref() else {
            return Err("do_step before a successful exit from initialization mode".into());
        };
        let unchanged = applied.ctrl.same_as(&self.ctrl)
            & applied.plant.same_as(&self.plant)
            & applied.excitation.same_as(&self.excitation)
            & applied.accdec.same_as(&self.accdec)
            & applied.seq.same_as(&self.seq)
            & applied.sweep.same_as(&self.sweep)
            & applied.corr.same_as(&self.corr);
        if !unchanged {
            let applied = applied.clone();
            let changed = describe_changes(&applied, &self.applied_now());
            self.ctrl = applied.ctrl;
            self.plant = applied.plant;
            self.excitation = applied.excitation;
            self.accdec = applied.accdec;
            self.seq = applied.seq;
            self.sweep = applied.sweep;
            self.corr = applied.corr;
            return Err(format!(
                "fixed parameter(s) {changed} changed after initialization; the change was undone \
                 (set parameters before fmi3ExitInitializationMode)"
            ));
        }
        let inputs = self.user_inputs()?;
        let sim = self.sim.as_mut().ok_or("model not initialized")?;
        // The step size is checked once per new size; most importers keep it.
        let n = match self.accepted_step {
            Some((bits, ticks)) if bits == h.to_bits() => ticks,
            _ => {
                let period = sim.tick_period() * self.ctrl.position_divider as f64;
                if !(h.is_finite() && h > 0.0) {
                    return Err(format!("communication step {h} s must be a positive number"));
                }
                let whole_periods = (h / period).round();
                if whole_periods < 1.0 || (h - whole_periods * period).abs() > 1e-9 * period.max(h) {
                    return Err(format!(
                        "communication step {h} s is not a whole multiple of the position-loop period {period} s \
                         (ctrl.position_divider / ctrl.current_loop_hz)"
                    ));
                }
                let ticks = (h / sim.tick_period()).round() as u64;
                self.accepted_step = Some((h.to_bits(), ticks));
                ticks
            }
        };
        let expected_time = sim.ticks() as f64 * sim.tick_period();
        if (current - expected_time).abs() > 0.5 * sim.tick_period() {
            return Err(format!(
                "current communication point {current} s does not match the model time {expected_time} s"
            ));
        }
        if self.fault_reset && !self.last_fault_reset {
            sim.axis.clear_faults();
        }
        self.last_fault_reset = self.fault_reset;
        self.sequence_events(&inputs);
        let sim = self.sim.as_mut().ok_or("model not initialized")?;
        if self.sweep_start > self.seen_sweep_start {
            // Like a refused sequence key: logged as a warning, nothing else changes (the
            // sweep stays idle, sweep_state says so); not an FMI error, which would leave the
            // sequence events of this step half applied.
            if let Err(e) = sim.axis.start_sweep() {
                self.refusals.push(format!("sweep_start refused at t = {} s: {e}", sim.ticks() as f64 * sim.tick_period()));
            }
            self.seen_sweep_start = self.sweep_start;
        }
        sim.run_ticks(n, &inputs);
        self.update_outputs();
        Ok(())
    }

    /// Log an error through the importer's logger and on stderr (many importers hide the
    /// FMI log unless debug logging is on; a refused parameter must never go unexplained).
    fn report(&self, context: &dyn Context<Self>, message: &str) {
        context.log(Fmi3Status::from(Fmi3Error::Error), DefaultLoggingCategory::LogAll, format_args!("{message}"));
        eprintln!("servo_axis: {message}");
    }
}

fn describe_changes(before: &AppliedParameters, after: &AppliedParameters) -> String {
    let a = format!("{before:?}");
    let b = format!("{after:?}");
    // Field-level diff of the Debug renderings: "name: value" pairs.
    let fields = |s: &str| -> Vec<String> {
        s.split([',', '{', '}']).map(|x| x.trim().to_string()).filter(|x| x.contains(':')).collect()
    };
    let (fa, fb) = (fields(&a), fields(&b));
    let changed: Vec<String> = fb
        .iter()
        .zip(fa.iter())
        .filter(|(x, y)| x != y)
        .map(|(x, _)| x.split(':').next().unwrap_or("?").trim().to_string())
        .collect();
    changed.join(", ")
}

fn panic_message(p: Box<dyn std::any::Any + Send>) -> String {
    p.downcast_ref::<&str>()
        .map(|s| s.to_string())
        .or_else(|| p.downcast_ref::<String>().cloned())
        .unwrap_or_else(|| "unknown panic".into())
}

impl UserModel for ServoAxis {
    type LoggingCategory = DefaultLoggingCategory;

    fn configurate(&mut self, context: &dyn Context<Self>) -> Result<(), Fmi3Error> {
        let result = catch_unwind(AssertUnwindSafe(|| -> Result<(), String> {
            let config = self.config()?;
            let sim = AxisSimulation::new(&config).map_err(|e| e.to_string())?;
            self.sim = Some(sim);
            self.applied = Some(self.applied_now());
            self.last_fault_reset = self.fault_reset;
            // Every sequence input acts from its declared start value (0): a key counter set
            // to 1 before the first step is one press at the first step, a run switch set to
            // 1 starts a run, a gain index selects its entry.
            self.seen = SequenceInputsSeen::default();
            self.seen_sweep_start = 0;
            self.reported_sweep_result = None;
            self.accepted_step = None;
            self.update_outputs();
            Ok(())
        }));
        match result {
            Ok(Ok(())) => Ok(()),
            Ok(Err(msg)) => {
                self.report(context, &format!("invalid parameters: {msg}"));
                Err(Fmi3Error::Error)
            }
            Err(p) => {
                self.report(context, &format!("internal error during initialization: {}", panic_message(p)));
                Err(Fmi3Error::Error)
            }
        }
    }

    fn calculate_values(&mut self, _context: &dyn Context<Self>) -> Result<Fmi3Res, Fmi3Error> {
        Ok(Fmi3Res::OK)
    }

    fn do_step(
        &mut self,
        context: &mut dyn Context<Self>,
        current_communication_point: f64,
        communication_step_size: f64,
        _no_set_fmu_state_prior_to_current_point: bool,
    ) -> Result<CSDoStepResult, Fmi3Error> {
        let result = catch_unwind(AssertUnwindSafe(|| self.step(current_communication_point, communication_step_size)));
        for note in std::mem::take(&mut self.refusals) {
            context.log(Fmi3Status::from(Fmi3Res::Warning), DefaultLoggingCategory::LogAll, format_args!("{note}"));
        }
        match result {
            Ok(Ok(())) => {
                let t = self.sim.as_ref().map(|s| s.ticks() as f64 * s.tick_period()).unwrap_or(0.0);
                context.set_time(t);
                Ok(CSDoStepResult::completed(t))
            }
            Ok(Err(msg)) => {
                self.report(&*context, &msg);
                Err(Fmi3Error::Error)
            }
            Err(p) => {
                // The instance may be half-updated: drop it so no further step runs on it.
                self.sim = None;
                self.applied = None;
                self.report(&*context, &format!("internal error in do_step, instance disabled: {}", panic_message(p)));
                Err(Fmi3Error::Error)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use fmi_export::fmi3::Model;

    fn started() -> ServoAxis {
        let mut m = ServoAxis::default();
        m.set_start_values();
        m
    }

    #[test]
    fn start_values_are_the_core_and_plant_defaults() {
        let m = started();
        let config = m.config().unwrap();
        let defaults = Params::default();
        // f64 start values rounded to f32 must equal the core defaults exactly.
        assert_eq!(config.control, defaults);
        let mut plant = PlantParams::default();
        plant.tick = config.plant.tick;
        assert_eq!(config.plant, plant);
    }

    #[test]
    fn step_size_must_be_a_whole_number_of_position_periods() {
        let mut m = started();
        m.sim = Some(AxisSimulation::new(&m.config().unwrap()).unwrap());
        m.applied = Some(m.applied_now());
        assert!(m.step(0.0, 0.0003).unwrap_err().contains("whole multiple"));
        assert!(m.step(0.0, 0.00025).is_ok());
        assert!(m.step(0.00025, 0.0005).is_ok());
    }

    #[test]
    fn fixed_parameter_change_is_refused_and_undone() {
        let mut m = started();
        m.sim = Some(AxisSimulation::new(&m.config().unwrap()).unwrap());
        m.applied = Some(m.applied_now());
        m.ctrl.velocity_kp = 5.0;
        let err = m.step(0.0, 0.00025).unwrap_err();
        assert!(err.contains("velocity_kp"), "{err}");
        assert_eq!(m.ctrl.velocity_kp, ControllerParameters { ..started().ctrl }.velocity_kp);
    }

    #[test]
    fn bad_mode_and_nan_inputs_are_refused_without_advancing() {
        let mut m = started();
        m.sim = Some(AxisSimulation::new(&m.config().unwrap()).unwrap());
        m.applied = Some(m.applied_now());
        m.mode = 7;
        assert!(m.step(0.0, 0.00025).unwrap_err().contains("mode"));
        m.mode = 1;
        m.velocity_command = f64::NAN;
        assert!(m.step(0.0, 0.00025).unwrap_err().contains("velocity_command"));
        assert_eq!(m.sim.as_ref().unwrap().ticks(), 0);
    }

    #[test]
    fn bad_acc_dec_settings_are_refused_with_the_reason() {
        let mut m = started();
        let build = |m: &ServoAxis| -> Result<(), String> {
            AxisSimulation::new(&m.config()?).map(|_| ()).map_err(|e| e.to_string())
        };
        m.accdec.filter = 2;
        m.accdec.cutoff_hz = 5000.0; // position loop 4 kHz: Nyquist 2 kHz
        assert!(build(&m).unwrap_err().contains("Nyquist"), "{:?}", build(&m));
        m.accdec.cutoff_hz = 40.0;
        m.accdec.order = 7;
        assert!(build(&m).unwrap_err().contains("order"), "{:?}", build(&m));
        m.accdec.order = 3;
        m.accdec.filter = 1;
        m.accdec.ma_length_2 = 0;
        assert!(build(&m).unwrap_err().contains("length"), "{:?}", build(&m));
        m.accdec.ma_length_2 = 16;
        m.accdec.filter = 3;
        assert!(build(&m).unwrap_err().contains("accdec.filter"));
        m.accdec.filter = 2;
        assert!(build(&m).is_ok());
    }

    #[test]
    fn bad_sequence_settings_are_refused_with_the_reason() {
        let build = |m: &ServoAxis| -> Result<(), String> {
            AxisSimulation::new(&m.config()?).map(|_| ()).map_err(|e| e.to_string())
        };
        let mut m = started();
        m.seq.completion_counts = -1;
        assert!(build(&m).unwrap_err().contains("seq.completion_counts"));
        m = started();
        m.seq.gain_count = 9;
        assert!(build(&m).unwrap_err().contains("gain table of 9"));
        m = started();
        m.seq.gain_2 = -1.0;
        assert!(build(&m).unwrap_err().contains("gain-table entry 1"));
        m = started();
        m.seq.soft_limit_min = 10.0;
        m.seq.soft_limit_max = -10.0;
        assert!(build(&m).unwrap_err().contains("soft limits"));
        m = started();
        m.seq.zero_speed = f64::NAN;
        assert!(build(&m).unwrap_err().contains("zero_speed"));
        assert!(build(&started()).is_ok());
    }

    #[test]
    fn sequence_keys_are_presses_and_refusals_are_counted_not_errors() {
        let mut m = started();
        m.sim = Some(AxisSimulation::new(&m.config().unwrap()).unwrap());
        m.applied = Some(m.applied_now());
        m.mode = 3;
        m.seq_release = 1; // no accepted stop yet: refused, counted
        m.step(0.0, 0.00025).unwrap();
        assert_eq!((m.seq_refused, m.seq_last_refusal, m.seq_state), (1, 5, 0));
        m.step(0.00025, 0.00025).unwrap(); // unchanged counter: no second press
        assert_eq!(m.seq_refused, 1);
        m.seq_stop = 1; // at rest: accepted at the next position tick
        m.step(0.0005, 0.00025).unwrap();
        assert_eq!(m.seq_state, 3);
        m.seq_gain_index = -1;
        m.step(0.00075, 0.00025).unwrap();
        assert_eq!((m.seq_refused, m.seq_last_refusal, m.seq_gain), (2, 8, 1.0));
        assert_eq!(m.refusals.len(), 2, "both refusals wait for do_step to log them");
    }

    #[test]
    fn a_sweep_start_the_mode_cannot_take_is_a_logged_refusal() {
        let mut m = started();
        m.sim = Some(AxisSimulation::new(&m.config().unwrap()).unwrap());
        m.applied = Some(m.applied_now());
        m.mode = 0; // torque mode: no velocity loop for the default velocity-command injection
        m.sweep_start = 1;
        m.step(0.0, 0.00025).unwrap();
        assert_eq!(m.sweep_state, 0);
        assert!(m.refusals.iter().any(|r| r.contains("sweep_start refused")), "{:?}", m.refusals);
        m.mode = 1;
        m.sweep_start = 2;
        m.step(0.00025, 0.00025).unwrap();
        assert_eq!(m.sweep_state, 1, "settling after a start in velocity mode");
    }

    #[test]
    fn negative_move_speed_is_refused_without_advancing() {
        let mut m = started();
        m.sim = Some(AxisSimulation::new(&m.config().unwrap()).unwrap());
        m.applied = Some(m.applied_now());
        m.move_speed = -1.0;
        assert!(m.step(0.0, 0.00025).unwrap_err().contains("move_speed"));
        assert_eq!(m.sim.as_ref().unwrap().ticks(), 0);
    }
}
