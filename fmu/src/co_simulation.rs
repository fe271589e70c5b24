//! The co-simulation of one axis as the FMI functions see it, without any C types: values
//! set and read by value reference, initialisation, communication steps, reset and the
//! state an importer can save and restore. The C API (`crate::fmi3`, `crate::fmi2`) adds the
//! state machine, the logger and the panic barrier around it.

use control_core::stop_sequence::SequenceEvent;
use control_core::{Commands, Mode};

use crate::parameters::simulation_config;
use crate::simulation::{AxisSimulation, UserInputs};
use crate::variables::{self, Causality, Kind, Value, Values};

/// The longest communication step accepted, in base ticks (1000 s at 16 kHz; about three
/// seconds of work here): a step of 1e300 s is refused instead of running for ever.
pub const MAX_STEP_TICKS: u64 = 16_000_000;

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

/// Everything that makes up the instance's state (`Copy`: no pointers, so a saved state is
/// a plain copy and its serialisation a plain byte image, see `crate::fmu_state`).
#[derive(Clone, Debug)]
pub struct ModelState {
    pub values: Values,
    pub(crate) sim: Option<AxisSimulation>,
    /// Model time of tick 0 (the importer's start time).
    start_time: f64,
    last_fault_reset: bool,
    seen: SequenceInputsSeen,
    seen_sweep_start: i32,
    /// The sweep result (bits of its re, im) that sweep_last_gain_db / _phase_deg show.
    reported_sweep_result: Option<(u32, u32)>,
    /// The last communication step size accepted (its bits) and its number of base ticks.
    accepted_step: Option<(u64, u64)>,
}

/// One servo axis: control core (current, velocity, position loops) driving a PMSM with a
/// two-inertia load.
#[derive(Clone, Debug)]
pub struct AxisModel {
    pub state: ModelState,
    /// Refused events of the last step (logged as warnings by the C API).
    pub refusals: Vec<String>,
}

impl Default for AxisModel {
    fn default() -> Self {
        Self::new()
    }
}

impl AxisModel {
    pub fn new() -> Self {
        Self {
            state: ModelState {
                values: Values::start(),
                sim: None,
                start_time: 0.0,
                last_fault_reset: false,
                seen: SequenceInputsSeen::default(),
                seen_sweep_start: 0,
                reported_sweep_result: None,
                accepted_step: None,
            },
            refusals: Vec::new(),
        }
    }

    pub fn values(&self) -> &Values {
        &self.state.values
    }

    /// Whether initialisation has ended (the axis is built).
    pub fn initialized(&self) -> bool {
        self.state.sim.is_some()
    }

    /// Whether `set` would take this value. Refused: an unknown value reference, an output
    /// or the time, a fixed parameter once initialised, a value of another type, NaN or a
    /// value outside its declared range.
    pub fn check_set(&self, vr: u32, value: Value) -> Result<(), String> {
        let d = variables::declaration(vr).ok_or_else(|| format!("no variable has value reference {vr}"))?;
        match d.causality {
            Causality::Output => return Err(format!("{} is an output: it cannot be set", d.name)),
            Causality::Independent => return Err(format!("{} is the independent variable: it cannot be set", d.name)),
            // Some masters send every parameter again after initialisation: the value it
            // already has is accepted, a change is refused.
            Causality::Parameter
                if self.initialized()
                    && self.state.values.get(vr).map(|v| v.as_f64().to_bits()) != Some(value.as_f64().to_bits()) =>
            {
                return Err(format!(
                    "{} is a fixed parameter: set it before ExitInitializationMode (or after Reset)",
                    d.name
                ));
            }
            _ => {}
        }
        if !matches!(
            (d.kind, value),
            (Kind::Float64, Value::Float64(_)) | (Kind::Int32, Value::Int32(_)) | (Kind::Boolean, Value::Boolean(_))
        ) {
            return Err(format!("{} is a {:?} variable, not {:?}", d.name, d.kind, value));
        }
        variables::check(d, value)
    }

    /// Set one variable (nothing changes when it is refused, see [`Self::check_set`]).
    pub fn set(&mut self, vr: u32, value: Value) -> Result<(), String> {
        self.check_set(vr, value)?;
        self.state.values.set(vr, value)
    }

    /// Set several variables: all of them, or none when one is refused.
    pub fn set_all(&mut self, items: impl Iterator<Item = (u32, Value)> + Clone) -> Result<(), String> {
        for (vr, v) in items.clone() {
            self.check_set(vr, v)?;
        }
        for (vr, v) in items {
            self.state.values.set(vr, v)?;
        }
        Ok(())
    }

    /// (`time`, value reference 0, is kept equal to [`Self::time`] by every step.)
    pub fn get(&self, vr: u32) -> Result<Value, String> {
        self.state.values.get(vr).ok_or_else(|| format!("no variable has value reference {vr}"))
    }

    /// Model time: the start time plus the ticks run.
    pub fn time(&self) -> f64 {
        match &self.state.sim {
            Some(sim) => self.state.start_time + sim.ticks() as f64 * sim.tick_period(),
            None => self.state.start_time,
        }
    }

    pub fn set_start_time(&mut self, t: f64) -> Result<(), String> {
        if !t.is_finite() {
            return Err(format!("start time {t} is not a finite number"));
        }
        self.state.start_time = t;
        self.state.values.time = t;
        Ok(())
    }

    /// Build the axis from the parameters (end of initialisation). Nothing changes when the
    /// parameters are refused.
    pub fn initialize(&mut self) -> Result<(), String> {
        let config = simulation_config(&self.state.values).map_err(|e| format!("invalid parameters: {e}"))?;
        let sim = AxisSimulation::new(&config).map_err(|e| format!("invalid parameters: {e}"))?;
        let s = &mut self.state;
        // What commissioning at power-up found: outputs fixed from here on (0 without it).
        if let Some(c) = sim.commissioned {
            let (m, seconds) = (c.measured, c.seconds);
            let o = &mut s.values;
            o.commissioned_resistance = m.resistance as f64;
            o.commissioned_ld = m.ld as f64;
            o.commissioned_lq = m.lq as f64;
            o.commissioned_flux_linkage = m.flux_linkage as f64;
            o.commissioned_pole_pairs = m.alignment.pole_pairs as i32;
            o.commissioned_encoder_offset = m.alignment.offset as f64;
            o.commissioned_encoder_reversed = m.alignment.reversed as i32;
            o.commissioned_current_bandwidth = m.current_step.bandwidth_hz as f64;
            o.commissioning_time = seconds;
        }
        s.sim = Some(sim);
        s.last_fault_reset = s.values.fault_reset;
        // Every sequence input acts from its declared start value (0): a key counter set to
        // 1 before the first step is one press at the first step, a run switch set to 1
        // starts a run, a gain index selects its entry.
        s.seen = SequenceInputsSeen::default();
        s.seen_sweep_start = 0;
        s.reported_sweep_result = None;
        s.accepted_step = None;
        self.update_outputs();
        Ok(())
    }

    /// Back to the state right after instantiation: every variable at its start value.
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    fn user_inputs(&self) -> Result<UserInputs, String> {
        let v = &self.state.values;
        let mode = Mode::from_code(v.mode).ok_or_else(|| {
            format!("mode must be 0 (torque), 1 (velocity), 2 (position) or 3 (stop sequence), got {}", v.mode)
        })?;
        // Every input was range-checked when it was set; a NaN cannot be stored.
        Ok(UserInputs {
            mode,
            position_command: v.position_command,
            move_speed: v.move_speed,
            jog_velocity: v.jog_velocity,
            velocity_command: v.velocity_command,
            torque_command: v.torque_command,
            disturbance_torque: v.disturbance_torque,
        })
    }

    /// The number of base ticks of a communication step (checked once per new size).
    fn step_ticks(&mut self, h: f64) -> Result<u64, String> {
        let s = &mut self.state;
        let sim = s.sim.as_ref().ok_or("do_step before a successful exit from initialization mode")?;
        if let Some((bits, ticks)) = s.accepted_step {
            if bits == h.to_bits() {
                return Ok(ticks);
            }
        }
        let period = sim.tick_period() * s.values.ctrl_position_divider as f64;
        if !(h.is_finite() && h > 0.0) {
            return Err(format!("communication step {h} s must be a positive number"));
        }
        let max = MAX_STEP_TICKS as f64 * sim.tick_period();
        if h > max {
            return Err(format!(
                "communication step {h} s is longer than the longest step accepted ({max} s): split it"
            ));
        }
        let whole_periods = (h / period).round();
        if whole_periods < 1.0 || (h - whole_periods * period).abs() > 1e-9 * period.max(h) {
            return Err(format!(
                "communication step {h} s is not a whole multiple of the position-loop period {period} s \
                 (ctrl.position_divider / ctrl.current_loop_hz)"
            ));
        }
        let ticks = (h / sim.tick_period()).round() as u64;
        s.accepted_step = Some((h.to_bits(), ticks));
        Ok(ticks)
    }

    /// One communication step from `current` over `h`. Refused (nothing advances): a step
    /// before initialisation, a step size that is not a whole number of position-loop
    /// periods, a current time that is not the model's.
    pub fn do_step(&mut self, current: f64, h: f64) -> Result<(), String> {
        let inputs = self.user_inputs()?;
        let n = self.step_ticks(h)?;
        let expected = self.time();
        let sim = self.state.sim.as_ref().ok_or("model not initialized")?;
        if (current - expected).abs() > 0.5 * sim.tick_period() {
            return Err(format!("current communication point {current} s does not match the model time {expected} s"));
        }
        let s = &mut self.state;
        let sim = s.sim.as_mut().ok_or("model not initialized")?;
        if s.values.fault_reset && !s.last_fault_reset {
            sim.axis.clear_faults();
        }
        s.last_fault_reset = s.values.fault_reset;
        // The commands are converted once for the mode and the ticks (the events in between
        // change neither the inputs nor the encoder resolution they are converted with).
        let commands = sim.commands(&inputs);
        self.sequence_events(&commands);
        let s = &mut self.state;
        let sim = s.sim.as_mut().ok_or("model not initialized")?;
        if s.values.sweep_start > s.seen_sweep_start {
            // Like a refused sequence key: logged as a warning, nothing else changes (the
            // sweep stays idle, sweep_state says so); not an FMI error, which would leave the
            // sequence events of this step half applied.
            if let Err(e) = sim.axis.start_sweep() {
                let t = s.start_time + sim.ticks() as f64 * sim.tick_period();
                self.refusals.push(format!("sweep_start refused at t = {t} s: {e}"));
            }
            s.seen_sweep_start = s.values.sweep_start;
        }
        sim.run_ticks_with(n, &commands, inputs.disturbance_torque);
        if self.update_outputs() {
            Ok(())
        } else {
            self.refuse_non_finite_output()
        }
    }

    /// No step ends with an OK status and a non-finite output: if the plant or the core
    /// produced one ([`Self::update_outputs`] says so), the axis latches its non-finite fault
    /// (the bridge goes off) and the step is an error naming the output.
    #[cold]
    #[inline(never)]
    fn refuse_non_finite_output(&mut self) -> Result<(), String> {
        let values = &self.state.values;
        let finite = |vr: u32| values.float64(vr).is_some_and(f64::is_finite);
        let Some(d) = crate::variables::DECLARATIONS
            .iter()
            .find(|d| d.causality == Causality::Output && d.kind == Kind::Float64 && !finite(d.vr))
        else {
            return Ok(());
        };
        let t = self.time();
        if let Some(sim) = self.state.sim.as_mut() {
            sim.axis.latch_fault(control_core::faults::Faults::NOT_FINITE);
            self.state.values.faults = sim.axis.faults().0 as i32;
        }
        Err(format!(
            "output {} is {} at t = {t} s: the non-finite fault is latched (bridge off); clear it with fault_reset",
            d.name,
            self.state.values.float64(d.vr).unwrap_or(f64::NAN)
        ))
    }

    /// Turn changes of the sequence inputs into events, in a fixed order: gain, run, stop,
    /// release, move, return. A refused event is reported (logged), not an FMI error.
    fn sequence_events(&mut self, commands: &Commands) {
        let s = &mut self.state;
        let Some(sim) = s.sim.as_mut() else { return };
        sim.apply_mode_of(commands);
        let v = &s.values;
        let seen = s.seen;
        let pressed = |now: i32, before: i32| now > before;
        let mut events = Vec::new();
        if v.seq_gain_index != seen.gain_index {
            // A negative index is as far outside the table as a large one.
            events.push(SequenceEvent::SelectGain(usize::try_from(v.seq_gain_index).unwrap_or(usize::MAX)));
        }
        let run = v.seq_run != 0;
        if run != seen.run {
            events.push(if run { SequenceEvent::RunOn } else { SequenceEvent::RunOff });
        }
        if pressed(v.seq_stop, seen.stop) {
            events.push(SequenceEvent::Stop);
        }
        if pressed(v.seq_release, seen.release) {
            events.push(SequenceEvent::ReleaseBlocking);
        }
        if pressed(v.seq_move, seen.moves) {
            events.push(SequenceEvent::MoveTo(sim.counts_for(v.seq_target)));
        }
        if pressed(v.seq_return, seen.returns) {
            events.push(SequenceEvent::ReturnToStart);
        }
        for e in events {
            if let Err(reason) = sim.axis.sequence_event(e) {
                let t = s.start_time + sim.ticks() as f64 * sim.tick_period();
                self.refusals.push(format!("sequence event {e:?} at t = {t} s: {reason}"));
            }
        }
        s.seen = SequenceInputsSeen {
            run,
            gain_index: v.seq_gain_index,
            stop: v.seq_stop,
            release: v.seq_release,
            moves: v.seq_move,
            returns: v.seq_return,
        };
    }

    /// Write every output from the axis; returns whether every Float64 output is finite (the
    /// check of every step, [`Values::float64_outputs_finite`]; the output it names, and the
    /// fault, are [`Self::refuse_non_finite_output`]'s, off the step's path).
    fn update_outputs(&mut self) -> bool {
        let s = &mut self.state;
        let Some(sim) = s.sim.as_ref() else { return s.values.float64_outputs_finite() };
        let o = &mut s.values;
        let x = sim.plant.state;
        let t = sim.telemetry();
        o.time = s.start_time + sim.ticks() as f64 * sim.tick_period();
        // From where the rotor stood at time 0 (after commissioning), as the drive counts.
        let origin = sim.position_origin();
        o.motor_position = x.motor_angle - origin;
        o.motor_velocity = x.motor_velocity;
        o.load_position = x.load_angle - origin;
        o.load_velocity = x.load_velocity;
        o.load_acceleration = sim.plant.accelerometer;
        o.iq = t.current.q as f64;
        o.id = t.current.d as f64;
        o.torque_command_out = t.torque_command as f64;
        o.electromagnetic_torque = sim.plant.electromagnetic_torque;
        (o.electromagnetic_torque_mean, o.load_acceleration_mean) =
            sim.step_means().means().unwrap_or((o.electromagnetic_torque, o.load_acceleration));
        o.velocity_estimate = t.velocity_estimate as f64;
        o.following_error = t.following_error as f64;
        let params = sim.axis.params();
        let rad_per_count = sim.radians_per_count();
        o.position_command_out = t.position_command as f64 * rad_per_count;
        o.command_velocity = t.command_pulses as f64 * rad_per_count / sim.position_period();
        let q = &t.sequence;
        o.seq_state = q.state.code();
        o.seq_complete = q.complete as i32;
        o.seq_deviation = q.deviation.clamp(i32::MIN as i64, i32::MAX as i64) as i32;
        o.seq_hold_position = q.target as f64 * rad_per_count;
        o.seq_speed_reference = q.speed_reference as f64;
        o.seq_gain = params.sequence.gains[q.gain_index] as f64;
        o.seq_refused = q.refused.min(i32::MAX as u32) as i32;
        o.seq_last_refusal = q.last_refusal.map_or(0, |r| r.code());
        let w = &t.sweep;
        o.sweep_state = w.state.code();
        o.sweep_point_index = w.point as i32;
        o.sweep_record = w.record as i32;
        o.sweep_frequency = w.frequency as f64;
        o.sweep_done_points = w.done_points as i32;
        o.sweep_last_frequency = w.last.frequency as f64;
        o.sweep_last_limited = w.last_limited as f64;
        // A logarithm and an arctangent: only when the result they come from changes.
        let key = (w.last.re.to_bits(), w.last.im.to_bits());
        if s.reported_sweep_result != Some(key) {
            // No result yet (0 + 0j), or none the excitation defines (U without power at the
            // frequency: a ratio that is not finite): 0 dB, 0 deg and quality 0, rather than
            // -inf or NaN. Quality 0 says the gain and phase mean nothing.
            // (A copy of the result is what the two calls take: were they given the telemetry's,
            // all of it would be kept in memory, copied there at every step.)
            let last = w.last;
            let measured = last.re.is_finite() && last.im.is_finite() && (last.re != 0.0 || last.im != 0.0);
            let gain = last.gain_db() as f64;
            let phase = last.phase_deg() as f64;
            let defined = measured && gain.is_finite() && phase.is_finite();
            o.sweep_last_gain_db = if defined { gain } else { 0.0 };
            o.sweep_last_phase_deg = if defined { phase } else { 0.0 };
            o.sweep_last_quality = if defined && last.quality.is_finite() { last.quality as f64 } else { 0.0 };
            s.reported_sweep_result = Some(key);
        }
        o.acq_time = s.start_time + w.sample.tick as f64 * sim.tick_period();
        o.acq_u = w.sample.u as f64;
        o.acq_y = w.sample.y as f64;
        o.acq_phase = w.sample.phase as f64;
        o.acq_measuring = w.sample.measuring as i32;
        o.acq_point = w.sample.point as i32;
        o.acq_record = w.sample.record() as i32;
        o.acq_half_block = w.sample.half_block() as i32;
        o.acq_limited = w.sample.limited as i32;
        o.faults = t.faults.0 as i32;
        o.float64_outputs_finite()
    }
}

#[cfg(test)]
mod tests;
