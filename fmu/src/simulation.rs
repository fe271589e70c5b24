//! The closed loop of one axis: control core and plant, tick by tick.
//!
//! Order within a base tick (as on the drive): sample the sensors, run `Axis::step`, then
//! let the plant evolve over the tick with the PWM computed in the previous tick (the duty
//! registers are reloaded at the next PWM period: one tick of computation delay).

use control_core::commissioning::{CommissioningFault, CommissioningSettings, CommissioningStatus, MeasuredMotor};
use control_core::excitation::{InjectionPoint, SineGenerator};
use control_core::{Axis, AxisInputs, Commands, Mode, ParamError, Params, PwmOutput, Telemetry};

use crate::plant::{Plant, PlantError, PlantInputs, PlantParams};

/// Sine excitation settings (see `control_core::excitation`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ExcitationConfig {
    pub point: InjectionPoint,
    pub amplitude: f32,
    pub frequency_hz: f32,
}

#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SimulationConfig {
    pub control: Params,
    pub plant: PlantParams,
    pub excitation: ExcitationConfig,
    /// Commission the motor when the axis is built (the drive's power-up), or not: `control`
    /// is then a commissioned set.
    pub commissioning: Option<CommissioningConfig>,
}

/// The commissioning at power-up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommissioningConfig {
    pub settings: CommissioningSettings,
    /// Run with everything measured (the motor's constants and the current loop's gains
    /// designed from them); otherwise with the encoder's mounting measured and the constants
    /// and gains of `control`.
    pub apply_motor: bool,
}

/// What commissioning at power-up found, and how the machine fared meanwhile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommissioningOutcome {
    pub measured: MeasuredMotor,
    /// The drive's time it took (s).
    pub seconds: f64,
    /// The largest mechanical angle the motor turned from where it stood (rad) and the largest
    /// phase current the plant carried (A, true, not as sensed).
    pub excursion: f64,
    pub peak_current: f64,
    /// The sequence's stage when the phase current peaked.
    pub peak_stage: Option<control_core::commissioning::Stage>,
}

/// The longest a commissioning may take (s of the drive's time).
const COMMISSIONING_LIMIT_S: f64 = 20.0;

#[derive(Debug)]
pub enum ConfigError {
    Control(ParamError),
    Plant(PlantError),
    /// Controller and plant disagree on something both must share.
    Mismatch(String),
    /// Commissioning at power-up failed (the bridge is off; nothing was kept).
    Commissioning(CommissioningFault),
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Control(e) => write!(f, "controller parameter: {e}"),
            Self::Plant(e) => write!(f, "{e}"),
            Self::Mismatch(s) => f.write_str(s),
            Self::Commissioning(fault) => write!(f, "commissioning the motor failed: {fault:?}"),
        }
    }
}

impl std::error::Error for ConfigError {}

/// Inputs that the user (or the importer) sets between communication points.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct UserInputs {
    pub mode: Mode,
    /// Motor-side position command (rad): streamed, or the target of a move.
    pub position_command: f64,
    /// Positioning speed (rad/s); 0 streams `position_command` through the acc/dec filter.
    pub move_speed: f64,
    /// Jog speed (rad/s); non-zero overrides `position_command`.
    pub jog_velocity: f64,
    pub velocity_command: f64,
    pub torque_command: f64,
    pub disturbance_torque: f64,
}

/// Sums of two plant signals over the ticks of the last [`AxisSimulation::run_ticks`] (a
/// communication step), for their means: what an integrating acquisition records. A value
/// sampled once per step aliases whatever the loops put near the step's rate onto low
/// frequencies (the velocity loop's encoder-quantisation torque near 4 kHz lands on a few
/// hertz of a 4 kHz record); the mean over the step's ticks has nulls at the step's rate and
/// its multiples.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StepMeans {
    torque: f64,
    accelerometer: f64,
    ticks: u64,
}

impl StepMeans {
    fn add(&mut self, plant: &Plant) {
        self.torque += plant.electromagnetic_torque;
        self.accelerometer += plant.accelerometer;
        self.ticks += 1;
    }

    /// Mean electromagnetic torque (N·m) and accelerometer reading (rad/s²) over the step's
    /// tick ends; None before the first step.
    pub fn means(&self) -> Option<(f64, f64)> {
        (self.ticks > 0).then(|| {
            if self.ticks.is_power_of_two() {
                // 2^-k exactly (k ≤ 63): `x·2^-k` is `x / 2^k` bit for bit (both round the
                // same exact value once), without the two divisions per step.
                let inverse = f64::from_bits((1023 - self.ticks.trailing_zeros() as u64) << 52);
                (self.torque * inverse, self.accelerometer * inverse)
            } else {
                let n = self.ticks as f64;
                (self.torque / n, self.accelerometer / n)
            }
        })
    }
}

/// `x.round() as i64` (half away from zero, saturating, NaN to 0) without the library call
/// `f64::round` is on x86-64 without SSE4.1 (twice per communication step): truncate, then
/// step away from zero when the exact remainder is at least one half. (The remainder
/// `x − trunc(x)` is exact: below 2⁵² it keeps only bits of `x`, above it is 0.)
#[inline]
fn round_to_i64(x: f64) -> i64 {
    let t = x as i64;
    let remainder = x - t as f64;
    if remainder >= 0.5 {
        t.saturating_add(1)
    } else if remainder <= -0.5 {
        t.saturating_sub(1)
    } else {
        t
    }
}

#[derive(Clone, Debug)]
pub struct AxisSimulation {
    pub axis: Axis,
    pub plant: Plant,
    pending: PwmOutput,
    tick_period: f64,
    ticks: u64,
    step_means: StepMeans,
    /// Motor radians per encoder count and the position-loop period (s), from the axis's
    /// parameters (fixed once built): the outputs' conversions, computed once.
    radians_per_count: f64,
    position_period: f64,
    /// What commissioning at power-up measured, and how it went.
    pub commissioned: Option<CommissioningOutcome>,
    /// The motor's angle where time 0 starts (rad): where commissioning left the rotor, 0
    /// without it; and the encoder's count there, the drive's counter zeroed at it (a drive
    /// homes its counter where the axis stands once commissioned: position commands count
    /// from where the axis stands at time 0).
    position_origin: f64,
    count_origin: i32,
}

impl AxisSimulation {
    pub fn new(config: &SimulationConfig) -> Result<Self, ConfigError> {
        let mut plant_params = config.plant;
        plant_params.tick = 1.0 / config.control.rates.current_loop_hz as f64;
        if config.control.encoder_counts_per_rev != plant_params.encoder_counts_per_rev {
            return Err(ConfigError::Mismatch(format!(
                "controller encoder resolution {} differs from the plant's {}",
                config.control.encoder_counts_per_rev, plant_params.encoder_counts_per_rev
            )));
        }
        let mut axis = Axis::new(config.control).map_err(ConfigError::Control)?;
        let e = config.excitation;
        if !(e.amplitude.is_finite() && e.frequency_hz.is_finite() && e.frequency_hz >= 0.0) {
            return Err(ConfigError::Mismatch(format!(
                "excitation amplitude {} / frequency {} Hz must be finite, frequency >= 0",
                e.amplitude, e.frequency_hz
            )));
        }
        if e.frequency_hz >= 0.5 * config.control.rates.current_loop_hz {
            return Err(ConfigError::Mismatch(format!(
                "excitation frequency {} Hz must be below half the loop rate ({} Hz)",
                e.frequency_hz,
                0.5 * config.control.rates.current_loop_hz
            )));
        }
        axis.set_excitation(
            e.point,
            SineGenerator::new(e.amplitude, e.frequency_hz, config.control.rates.current_loop_hz, 0.0),
        );
        let plant = Plant::new(plant_params).map_err(ConfigError::Plant)?;
        let params = axis.params();
        let radians_per_count = std::f64::consts::TAU / params.encoder_counts_per_rev as f64;
        let position_period = params.rates.position_period() as f64;
        Ok(Self {
            axis,
            plant,
            pending: PwmOutput::default(),
            tick_period: plant_params.tick,
            ticks: 0,
            step_means: StepMeans::default(),
            radians_per_count,
            position_period,
            commissioned: None,
            position_origin: 0.0,
            count_origin: 0,
        })
        .and_then(|mut sim: Self| {
            if let Some(c) = config.commissioning {
                sim.commission(&c, config)?;
            }
            Ok(sim)
        })
    }

    /// Commission the motor as a drive does at power-up: the sequence runs on the plant, then
    /// the axis is built again with what it measured (`c.apply_motor`) or with the encoder's
    /// mounting only; the excitation is set again, the tick count starts from 0.
    fn commission(&mut self, c: &CommissioningConfig, config: &SimulationConfig) -> Result<(), ConfigError> {
        let mut settings = c.settings;
        settings.counts_per_rev = config.control.encoder_counts_per_rev;
        settings.tick_period = config.control.rates.tick_period();
        let fault = |e: &'static str| ConfigError::Mismatch(format!("commissioning setting {e} is out of range"));
        self.axis.start_commissioning(&settings).map_err(|e| match e {
            control_core::axis::CommissioningRefusal::Setting(name) => fault(name),
            control_core::axis::CommissioningRefusal::Busy => fault("(the axis is busy)"),
        })?;
        let rest = Commands { mode: Mode::Torque, ..Commands::default() };
        let limit = (COMMISSIONING_LIMIT_S / self.tick_period) as u64;
        let mut ticks = 0u64;
        let (start, mut excursion, mut peak_current) = (self.plant.state.motor_angle, 0.0f64, 0.0f64);
        let mut peak_stage = None;
        let measured = loop {
            self.tick_inner(&rest, 0.0, |_| {});
            ticks += 1;
            excursion = excursion.max((self.plant.state.motor_angle - start).abs());
            let current = self.plant.phase_current_peak();
            if current > peak_current {
                peak_current = current;
                if let Some(CommissioningStatus::Running(stage)) = self.axis.commissioning() {
                    peak_stage = Some(stage);
                }
            }
            match self.axis.commissioning() {
                Some(CommissioningStatus::Running(_)) if ticks < limit => {}
                Some(CommissioningStatus::Running(_)) => {
                    return Err(ConfigError::Commissioning(CommissioningFault::Stopped));
                }
                Some(CommissioningStatus::Done(m)) => break m,
                Some(CommissioningStatus::Failed(f)) => return Err(ConfigError::Commissioning(f)),
                None => return Err(ConfigError::Commissioning(CommissioningFault::Stopped)),
            }
        };
        // The counter zeroed where the rotor stands: the electrical angle at the new count 0
        // is the one at the old count `origin` (in the direction-corrected counter).
        let origin = self.plant.encoder_count();
        let mut zeroed = measured;
        let a = &mut zeroed.alignment;
        let corrected = if a.reversed { -(origin as f64) } else { origin as f64 };
        let counts_per_rev = config.control.encoder_counts_per_rev as f64;
        let turn = (corrected * a.pole_pairs as f64).rem_euclid(counts_per_rev) / counts_per_rev;
        a.offset = (a.offset as f64 + std::f64::consts::TAU * turn).rem_euclid(std::f64::consts::TAU) as f32;
        if a.offset >= std::f32::consts::TAU {
            a.offset = 0.0;
        }
        let params = if c.apply_motor {
            config.control.with_commissioned(&zeroed)
        } else {
            let mounting = control_core::params::EncoderMounting {
                reversed: zeroed.alignment.reversed,
                electrical_offset: zeroed.alignment.offset,
            };
            config.control.commissioned_as(mounting)
        };
        self.axis.rebuild(&params).map_err(ConfigError::Control)?;
        let e = config.excitation;
        let rate = config.control.rates.current_loop_hz;
        self.axis.set_excitation(e.point, SineGenerator::new(e.amplitude, e.frequency_hz, rate, 0.0));
        self.pending = PwmOutput::default();
        self.ticks = 0;
        self.step_means = StepMeans::default();
        let seconds = ticks as f64 * self.tick_period;
        self.commissioned = Some(CommissioningOutcome { measured, seconds, excursion, peak_current, peak_stage });
        self.position_origin = self.plant.state.motor_angle;
        self.count_origin = origin;
        Ok(())
    }

    /// The motor's angle where time 0 starts (rad): the origin of the position outputs.
    pub fn position_origin(&self) -> f64 {
        self.position_origin
    }

    /// Motor radians per encoder count: `2π / encoder_counts_per_rev`.
    pub fn radians_per_count(&self) -> f64 {
        self.radians_per_count
    }

    /// The position-loop period (s): `position_divider / current_loop_hz` (in f32, as the
    /// core computes it).
    pub fn position_period(&self) -> f64 {
        self.position_period
    }

    pub fn tick_period(&self) -> f64 {
        self.tick_period
    }

    pub fn ticks(&self) -> u64 {
        self.ticks
    }

    /// The PWM command the plant will apply during the next tick.
    pub fn pending_pwm(&self) -> PwmOutput {
        self.pending
    }

    pub fn telemetry(&self) -> Telemetry {
        self.axis.telemetry()
    }

    /// Encoder counts for a motor-side angle in rad.
    pub fn counts_for(&self, angle: f64) -> i64 {
        round_to_i64(angle / std::f64::consts::TAU * self.axis.params().encoder_counts_per_rev as f64)
    }

    /// The core's commands for the inputs (a communication step converts them once, for
    /// [`Self::apply_mode_of`] and [`Self::run_ticks_with`]).
    pub fn commands(&self, u: &UserInputs) -> Commands {
        Commands {
            mode: u.mode,
            position: self.counts_for(u.position_command),
            move_speed: u.move_speed as f32,
            jog_velocity: u.jog_velocity as f32,
            velocity: u.velocity_command as f32,
            torque: u.torque_command as f32,
        }
    }

    /// Enter the inputs' mode now (before events meant for it); see `Axis::apply_mode`.
    pub fn apply_mode(&mut self, u: &UserInputs) {
        let commands = self.commands(u);
        self.apply_mode_of(&commands);
    }

    /// [`Self::apply_mode`] with the commands already converted.
    pub fn apply_mode_of(&mut self, commands: &Commands) {
        self.axis.apply_mode(commands);
    }

    /// One base tick.
    pub fn tick(&mut self, u: &UserInputs) {
        self.tick_traced(u);
    }

    /// `n` base ticks with the inputs held: the commands are converted once, not per tick.
    /// [`Self::step_means`] then holds the means over these ticks.
    pub fn run_ticks(&mut self, n: u64, u: &UserInputs) {
        let commands = self.commands(u);
        self.run_ticks_with(n, &commands, u.disturbance_torque);
    }

    /// [`Self::run_ticks`] with the commands already converted.
    pub fn run_ticks_with(&mut self, n: u64, commands: &Commands, disturbance_torque: f64) {
        self.step_means = StepMeans::default();
        for _ in 0..n {
            self.tick_adding_means(commands, disturbance_torque);
        }
    }

    /// One base tick of [`Self::run_ticks`], its plant signals added to the step's sums here,
    /// where the tick has just computed them (read back from memory after the call, they
    /// stalled the load: two 8-byte stores do not forward to one 16-byte load). Kept out of
    /// line, like [`Self::tick_with`], so that the plant's step is inlined into it.
    #[inline(never)]
    fn tick_adding_means(&mut self, commands: &Commands, disturbance_torque: f64) {
        self.tick_inner(commands, disturbance_torque, |_| {});
        self.step_means.add(&self.plant);
    }

    /// Means of the electromagnetic torque and the accelerometer over the last `run_ticks`.
    pub fn step_means(&self) -> &StepMeans {
        &self.step_means
    }

    /// One base tick; returns what the control core was given (for golden vectors).
    pub fn tick_traced(&mut self, u: &UserInputs) -> (AxisInputs, Commands) {
        let commands = self.commands(u);
        (self.tick_with(&commands, u.disturbance_torque), commands)
    }

    /// One base tick with the sensor readings altered by `fault` before the core sees them
    /// (fault campaigns: a NaN or saturated current sample, an encoder jump, a bus fault);
    /// returns the PWM the core commanded for the next tick.
    pub fn tick_with_sensor_fault(&mut self, u: &UserInputs, fault: impl FnOnce(&mut AxisInputs)) -> PwmOutput {
        let commands = self.commands(u);
        self.tick_inner(&commands, u.disturbance_torque, fault);
        self.pending
    }

    fn tick_with(&mut self, commands: &Commands, disturbance_torque: f64) -> AxisInputs {
        self.tick_inner(commands, disturbance_torque, |_| {})
    }

    #[inline(always)]
    fn tick_inner(
        &mut self,
        commands: &Commands,
        disturbance_torque: f64,
        fault: impl FnOnce(&mut AxisInputs),
    ) -> AxisInputs {
        let m = self.plant.measure();
        let mut inputs = AxisInputs {
            phase_currents: [m.phase_currents[0] as f32, m.phase_currents[1] as f32],
            encoder_count: m.encoder_count.wrapping_sub(self.count_origin),
            bus_voltage: m.bus_voltage as f32,
            // The plant's accelerometer (with its noise), read at the sampling instant as the
            // currents: what a drive's accelerometer input gives the core.
            load_acceleration: self.plant.accelerometer as f32,
        };
        fault(&mut inputs);
        let pwm = self.axis.step(&inputs, commands);
        let applied = PlantInputs {
            duties: self.pending.duties.map(|d| d as f64),
            // A fault switches the bridge off at once, not one tick later.
            bridge_enabled: self.pending.enabled && pwm.enabled,
            disturbance_torque,
        };
        self.plant.advance(&applied);
        self.pending = pwm;
        self.ticks += 1;
        inputs
    }
}

#[cfg(test)]
mod tests {
    use super::{round_to_i64, StepMeans};

    #[test]
    fn the_means_over_a_power_of_two_of_ticks_are_the_quotients_bit_for_bit() {
        let mut state = 0x2545_F491_4F6C_DD1Du64;
        let mut values =
            vec![0.0, -0.0, 1.0, -3.5, f64::MIN_POSITIVE, 5e-324, -5e-324, 1e-310, f64::MAX, f64::INFINITY];
        for _ in 0..100_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            values.push(f64::from_bits(state));
        }
        for ticks in [1u64, 2, 3, 4, 5, 8, 12, 16, 1 << 20, 1 << 40, 1 << 63, 16_000_000] {
            for &x in &values {
                let means = StepMeans { torque: x, accelerometer: -x, ticks }.means().unwrap();
                let n = ticks as f64;
                let (a, b) = (x / n, -x / n);
                assert!(means.0.to_bits() == a.to_bits() || (a.is_nan() && means.0.is_nan()), "{x:e} / {ticks}");
                assert!(means.1.to_bits() == b.to_bits() || (b.is_nan() && means.1.is_nan()), "{x:e} / {ticks}");
            }
        }
    }

    #[test]
    fn rounding_to_an_integer_matches_the_standard_library() {
        let mut cases = vec![
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.5,
            -1.5,
            2.5,
            -2.5,
            0.499_999_999_999_999_94,
            -0.499_999_999_999_999_94,
            4_503_599_627_370_495.5,
            -4_503_599_627_370_495.5,
            4_503_599_627_370_497.0,
            9_007_199_254_740_993.0,
            9.223_372_036_854_775e18,
            -9.223_372_036_854_775e18,
            1e19,
            -1e19,
            1e300,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            f64::MIN_POSITIVE,
            -f64::MIN_POSITIVE,
        ];
        // And a sweep of fractions around the half-way points.
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        for _ in 0..200_000 {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            let x = f64::from_bits(state);
            cases.push(x);
            cases.push((state % 2_000_001) as f64 * 0.25 - 250_000.0);
            cases.push((state >> 11) as f64 / (1u64 << 30) as f64 - 4096.0);
        }
        for x in cases {
            assert_eq!(round_to_i64(x), x.round() as i64, "{x:e} ({:#x})", x.to_bits());
        }
    }
}
