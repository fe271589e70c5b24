//! Commissioning a motor and encoder the drive has never seen: the phase resistance, the
//! encoder's direction, the pole pairs and the electrical angle at count 0, and the d- and
//! q-axis inductances, measured by the drive itself, one tick at a time, the current kept
//! within the test current throughout (a tenth over it at most, in the current loop's
//! transients) and the voltage within the highest voltage and the bus's circle.
//!
//! The sequence, each stage on the previous one's result:
//! 1. **Probe.** Pseudo-random voltage chips of zero mean on a fixed angle (0), their size
//!    growing from a millivolt by a quarter a period while the current stays under a third of
//!    the test current; a first-order fit of the response (`winding_fit`) gives a first
//!    resistance and inductance: enough to close a current loop. No current at the highest
//!    voltage: an open phase.
//! 2. **Resistance.** The current loop, on the same fixed angle, ramps the current to the test
//!    current (the rotor, wherever it stands, is pulled to the vector gradually), holds it and
//!    then half of it; `R = ΔV/ΔI` between the two holds (the sensors' offsets and the
//!    inverter's dead-time voltage, the same at both, drop out). The third phase's current not
//!    the other two's mean: a phase is missing.
//! 3. **d-axis inductance.** Chips around the voltage of half the test current (the current
//!    keeps its sign, so the inverter's error stays constant) and the fit again, on the
//!    rotor's d axis.
//! 4. **Encoder.** The loop holds the test current on a vector that turns slowly forward by a
//!    few electrical turns and back; the rotor follows. Counts against the vector's angle give
//!    the direction, the pole pairs and the electrical angle at count 0 (`encoder_alignment`).
//! 5. **q-axis inductance.** Chips on the rotor's q axis (now known from the encoder) beside
//!    the held d-axis voltage, and the fit.
//!
//! Any fault (an overcurrent, a reading that is not finite, a failed stage) ends the sequence
//! with the bridge off and its reason; nothing is kept. The flux linkage and the current
//! loop's gains and step check follow in later stages.

mod encoder_alignment;
mod winding_fit;

#[cfg(test)]
mod motor_model;
#[cfg(test)]
mod tests;

pub use encoder_alignment::{Alignment, AlignmentError};
pub use winding_fit::Winding;

use core::f32::consts::TAU;

use crate::m_sequence::MSequence;
use crate::pi_controller::{PiController, PiGains};
use crate::reference_frames::{clarke, inverse_park, park, AlphaBeta, Dq};
use crate::trigonometry::sin_cos;
use encoder_alignment::{align, Pass};
use winding_fit::WindingFit;

/// What the sequence needs to know before it starts: nothing of the motor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommissioningSettings {
    /// The current the measurements drive (A): within the drive's and the motor's ratings.
    pub test_current: f32,
    /// The highest voltage the sequence applies (V); a current short of the test current at
    /// this voltage is an open phase.
    pub max_voltage: f32,
    /// The trip level (A): above it the sequence stops with the bridge off.
    pub overcurrent: f32,
    /// Encoder counts per mechanical revolution (the setting the encoder check holds).
    pub counts_per_rev: u32,
    /// The most pole pairs a motor may have.
    pub max_pole_pairs: u32,
    /// Electrical turns the vector makes each way, and its speed (turns per second).
    pub alignment_turns: f32,
    pub alignment_speed: f32,
    /// The base tick (s).
    pub tick_period: f32,
}

impl CommissioningSettings {
    /// Every setting finite and in range: the first that is not, by name.
    pub fn validate(&self) -> Result<(), &'static str> {
        let positive = |x: f32| x.is_finite() && x > 0.0;
        if !positive(self.test_current) {
            return Err("test_current");
        }
        if !positive(self.max_voltage) {
            return Err("max_voltage");
        }
        // The chips swing the current by up to the test current around half of it.
        if !(positive(self.overcurrent) && self.overcurrent >= 2.0 * self.test_current) {
            return Err("overcurrent");
        }
        if self.counts_per_rev < 4 || self.counts_per_rev > 1 << 24 {
            return Err("counts_per_rev");
        }
        if self.max_pole_pairs == 0 || self.max_pole_pairs > 64 {
            return Err("max_pole_pairs");
        }
        if !(positive(self.alignment_turns) && self.alignment_turns <= 16.0) {
            return Err("alignment_turns");
        }
        if !(positive(self.alignment_speed) && self.alignment_speed <= 50.0) {
            return Err("alignment_speed");
        }
        if !(positive(self.tick_period) && self.tick_period <= 1e-2) {
            return Err("tick_period");
        }
        Ok(())
    }

    /// A test current of 2 A, at most 12 V, one and a half electrical turns each way at two
    /// turns a second.
    pub fn for_encoder(counts_per_rev: u32, tick_period: f32) -> Self {
        Self {
            test_current: 2.0,
            max_voltage: 12.0,
            overcurrent: 6.0,
            counts_per_rev,
            max_pole_pairs: 64,
            alignment_turns: 1.5,
            alignment_speed: 2.0,
            tick_period,
        }
    }
}

/// What commissioning found.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredMotor {
    /// Phase resistance (Ω).
    pub resistance: f32,
    /// d- and q-axis inductances (H).
    pub ld: f32,
    pub lq: f32,
    pub alignment: Alignment,
}

/// Why commissioning stopped; the bridge is off and nothing is kept.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CommissioningFault {
    /// A phase current above the trip level (A).
    Overcurrent {
        amps: f32,
    },
    /// The bus voltage is not a positive finite value, or a reading is not finite.
    Reading,
    /// The current did not reach the test current at the highest voltage: a phase is open.
    OpenPhase {
        amps: f32,
    },
    /// One phase's current is not what the other two imply: a phase is missing.
    PhaseImbalance,
    Alignment(AlignmentError),
    /// A winding's response that no resistance and inductance give (axis 'd' or 'q').
    Inductance {
        axis: char,
    },
    /// A value outside what the drive can run.
    OutOfRange {
        quantity: &'static str,
        value: f32,
    },
}

/// Where the sequence is.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CommissioningStatus {
    Running(Stage),
    Done(MeasuredMotor),
    Failed(CommissioningFault),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stage {
    Probe,
    ProbeFit,
    Ramp,
    HoldHigh,
    HoldLow,
    Forward,
    Backward,
    InductanceD,
    InductanceQ,
}

/// The vector's acceleration to the alignment speed and its braking (s).
const ALIGNMENT_ACCELERATION_S: f32 = 0.25;
/// Ticks of each hold: the first part settles, the last part is averaged.
const HOLD_S: f32 = 0.15;
const AVERAGED_S: f32 = 0.05;
/// The current's ramp to the test current (s): slow beside the rotor's swing on the vector,
/// which it then follows nearly at rest.
const RAMP_S: f32 = 0.3;
/// The rotor counts as still when its count has not changed for this long (s); the first
/// hold waits for it at most `STILL_WAIT_S`.
const STILL_S: f32 = 0.03;
const STILL_WAIT_S: f32 = 1.0;
/// The probe's first chip size (V), its growth per period, the share of the test current it
/// grows to, and its chips' M-sequence degree (255 chips a period: the growth is checked over
/// whole periods, whose excursions the fit's periods repeat) and the periods it fits over.
const PROBE_START_V: f32 = 1e-3;
const PROBE_GROWTH: f32 = 1.25;
const PROBE_SHARE: f32 = 0.3;
/// At the highest voltage, the least current (a share of the test current) the probe fits.
const PROBE_FLOOR: f32 = 0.02;
const PROBE_DEGREE: u32 = 8;
const PROBE_FIT_PERIODS: u32 = 8;
/// Chips of each inductance stage (an M-sequence of degree 12), after a few ticks' start.
const CHIP_DEGREE: u32 = 12;
const CHIP_SETTLING_TICKS: u32 = 64;

/// The sequence's current-loop bandwidth (Hz): well inside a 16 kHz tick's reach (one tick of
/// delay), far above the vector's turn.
const ALIGNMENT_BANDWIDTH_HZ: f32 = 300.0;

/// The sequence's d and q current loops (the drive's PI, its output within the highest
/// voltage).
#[derive(Clone, Copy, Debug, Default)]
struct DqPi {
    d: PiController,
    q: PiController,
    limit: f32,
}

impl DqPi {
    fn d(&mut self, error: f32) -> f32 {
        self.d.update(error, self.limit).value
    }

    fn q(&mut self, error: f32) -> f32 {
        self.q.update(error, self.limit).value
    }
}

/// The commissioning sequence.
#[derive(Clone, Copy, Debug)]
pub struct Commissioning {
    settings: CommissioningSettings,
    status: CommissioningStatus,
    /// Ticks into the present stage.
    ticks: u32,
    /// The vector's voltage on its d axis (V) and its angle (rad, electrical) now.
    voltage: f32,
    angle: f32,
    /// The probe's chip size (V) and the largest current of its present period (A).
    chip_size: f32,
    peak: f32,
    /// The held voltage that drives the test current (V) and the averages of the two holds.
    held: f32,
    /// The voltage that drives half the test current (V): the chips' centre.
    held_low: f32,
    /// The test current this winding allows (A; the settings' unless the voltage limits it).
    test_current: f32,
    /// The encoder's last count and the ticks it has kept it; the ticks waited for it.
    last_count: i32,
    still_ticks: u32,
    waited: u32,
    sum: f32,
    voltage_sum: f32,
    high: (f32, f32),
    resistance: f32,
    start_count: Option<i32>,
    forward: Pass,
    backward: Pass,
    /// The present pass's angle turned and its speed (rad, rad per tick).
    travelled: f32,
    speed: f32,
    alignment: Option<Alignment>,
    ld: f32,
    /// The probe's inductance (H): the alignment's current loop is designed with it.
    probe_inductance: f32,
    /// The current loop of the alignment (in the vector's frame).
    current_pi: DqPi,
    chips: MSequence,
    fit: WindingFit,
    /// The chip voltage asked for on the last tick (applied over this one) and the one
    /// before, and the last tick's current on the injected axis.
    last_chip: f32,
    applied_chip: f32,
    last_current: Option<f32>,
}

/// One tick's readings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CommissioningInputs {
    pub phase_currents: [f32; 2],
    pub encoder_count: i32,
    pub bus_voltage: f32,
}

impl Commissioning {
    /// The sequence for `settings`; refused, by the setting's name, when they do not validate.
    pub fn new(settings: CommissioningSettings) -> Result<Self, &'static str> {
        settings.validate()?;
        Ok(Self {
            settings,
            status: CommissioningStatus::Running(Stage::Probe),
            ticks: 0,
            voltage: 0.0,
            angle: 0.0,
            chip_size: PROBE_START_V,
            peak: 0.0,
            held: 0.0,
            held_low: 0.0,
            test_current: settings.test_current,
            last_count: 0,
            still_ticks: 0,
            waited: 0,
            sum: 0.0,
            voltage_sum: 0.0,
            high: (0.0, 0.0),
            resistance: 0.0,
            start_count: None,
            forward: Pass::new(0.0),
            backward: Pass::new(0.0),
            travelled: 0.0,
            speed: 0.0,
            alignment: None,
            ld: 0.0,
            probe_inductance: 0.0,
            current_pi: DqPi::default(),
            chips: match MSequence::new(PROBE_DEGREE) {
                Ok(m) => m,
                Err(_) => MSequence::DEGREE_15,
            },
            fit: WindingFit::default(),
            last_chip: 0.0,
            applied_chip: 0.0,
            last_current: None,
        })
    }

    pub fn status(&self) -> CommissioningStatus {
        self.status
    }

    fn ticks_of(&self, seconds: f32) -> u32 {
        libm::ceilf(seconds / self.settings.tick_period) as u32
    }

    fn fail(&mut self, fault: CommissioningFault) -> Option<AlphaBeta> {
        self.status = CommissioningStatus::Failed(fault);
        None
    }

    fn next_stage(&mut self, stage: Stage) {
        self.status = CommissioningStatus::Running(stage);
        self.ticks = 0;
        self.sum = 0.0;
        self.voltage_sum = 0.0;
    }

    /// The rotor's electrical angle from the encoder, once aligned.
    fn rotor_angle(&self, a: &Alignment, count: i32) -> f32 {
        let cpr = self.settings.counts_per_rev as i64;
        let raw = (count as i64).rem_euclid(cpr);
        let corrected = if a.reversed { (cpr - raw) % cpr } else { raw };
        let turns = ((corrected * a.pole_pairs as i64) % cpr) as f32 / cpr as f32;
        TAU * turns + a.offset
    }

    /// One tick: the readings in, the stator-frame voltage for the next tick out (`None`: the
    /// bridge off — the sequence has ended, done or failed).
    pub fn step(&mut self, i: &CommissioningInputs) -> Option<AlphaBeta> {
        let CommissioningStatus::Running(stage) = self.status else {
            return None;
        };
        let [ia, ib] = i.phase_currents;
        if !(ia.is_finite() && ib.is_finite() && i.bus_voltage.is_finite() && i.bus_voltage > 0.0) {
            return self.fail(CommissioningFault::Reading);
        }
        let ic = -(ia + ib);
        let peak = ia.abs().max(ib.abs()).max(ic.abs());
        if peak > self.settings.overcurrent {
            return self.fail(CommissioningFault::Overcurrent { amps: peak });
        }
        let start = *self.start_count.get_or_insert(i.encoder_count);
        let relative = i.encoder_count.wrapping_sub(start);
        self.ticks += 1;
        let s = self.settings;
        // The current in the frame of the vector's angle: on the q-axis stage, the rotor's
        // angle where the stage began (held there: a frame that followed the rotor's small
        // swings would turn the held d current into the measured q current).
        let frame = self.angle;
        let (sin, cos) = sin_cos(frame);
        let current = park(clarke(ia, ib), sin, cos);
        let mut q_voltage = 0.0;
        match stage {
            Stage::Probe | Stage::ProbeFit => {
                let period = self.chips.period();
                self.peak = self.peak.max(current.d.abs());
                if stage == Stage::ProbeFit {
                    if let Some(previous) = self.last_current {
                        self.fit.add(previous, current.d, self.applied_chip);
                    }
                    self.last_current = Some(current.d);
                    if self.ticks >= PROBE_FIT_PERIODS * period {
                        let Some(w) = self.fit.winding(s.tick_period) else {
                            return self.fail(CommissioningFault::Inductance { axis: 'd' });
                        };
                        if !(w.resistance > 1e-3 && w.resistance < 100.0 && w.inductance > 1e-6 && w.inductance < 1.0) {
                            return self
                                .fail(CommissioningFault::OutOfRange { quantity: "winding", value: w.resistance });
                        }
                        self.probe_inductance = w.inductance;
                        self.start_current_loop(w.resistance, w.inductance, 0.0);
                        // Within what the voltage allows on this winding, with room for the
                        // loop to act.
                        self.test_current = s.test_current.min(0.7 * s.max_voltage / w.resistance);
                        self.next_stage(Stage::Ramp);
                    }
                } else if self.ticks.is_multiple_of(period) {
                    // A whole period under the share: larger chips, up to the highest voltage;
                    // there, the fit's periods. At the highest voltage a current the sensors
                    // can read (a high resistance, a long time constant) is fitted as it is;
                    // none at all is an open phase.
                    let at_most = self.chip_size >= s.max_voltage;
                    if self.peak < PROBE_SHARE * s.test_current && !at_most {
                        self.chip_size = (self.chip_size * PROBE_GROWTH).min(s.max_voltage);
                    } else if self.peak < PROBE_FLOOR * s.test_current {
                        return self.fail(CommissioningFault::OpenPhase { amps: self.peak });
                    } else {
                        self.fit = WindingFit::default();
                        self.last_current = None;
                        self.next_stage(Stage::ProbeFit);
                    }
                    self.peak = 0.0;
                }
                let chip = self.chip_size * self.chips.next_chip() as f32;
                self.applied_chip = self.last_chip;
                self.last_chip = chip;
                self.voltage = chip;
            }
            Stage::Ramp => {
                let share = self.ticks as f32 / self.ticks_of(RAMP_S) as f32;
                self.voltage = self.current_pi.d(self.test_current * share.min(1.0) - current.d);
                q_voltage = self.current_pi.q(-current.q);
                if share >= 1.0 {
                    self.next_stage(Stage::HoldHigh);
                }
            }
            Stage::HoldHigh | Stage::HoldLow => {
                let target = if stage == Stage::HoldHigh { self.test_current } else { 0.5 * self.test_current };
                let voltage = self.current_pi.d(target - current.d);
                q_voltage = self.current_pi.q(-current.q);
                let (hold, averaged) = (self.ticks_of(HOLD_S), self.ticks_of(AVERAGED_S));
                // The back-EMF of a rotor still swinging on the vector would bias the voltage:
                // the first hold waits for it to stop before it averages.
                if i.encoder_count != self.last_count {
                    self.last_count = i.encoder_count;
                    self.still_ticks = 0;
                } else {
                    self.still_ticks += 1;
                }
                if stage == Stage::HoldHigh
                    && self.ticks == hold - averaged
                    && self.still_ticks < self.ticks_of(STILL_S)
                    && self.waited < self.ticks_of(STILL_WAIT_S)
                {
                    self.waited += 1;
                    self.ticks -= 1;
                }
                if self.ticks > hold - averaged {
                    // The voltage applied over the tick just measured (asked for a tick
                    // before) against the current: both averaged over the same ticks.
                    self.sum += current.d;
                    self.voltage_sum += self.voltage;
                    // The vector lies on phase a: b and c carry half of a's current each.
                    if (ib - ic).abs() > 0.25 * ia.abs() + 0.05 * self.test_current {
                        return self.fail(CommissioningFault::PhaseImbalance);
                    }
                }
                self.voltage = voltage;
                if self.ticks >= hold {
                    let (mean_i, mean_v) = (self.sum / averaged as f32, self.voltage_sum / averaged as f32);
                    if stage == Stage::HoldHigh {
                        self.high = (mean_v, mean_i);
                        self.held = mean_v;
                        self.next_stage(Stage::HoldLow);
                    } else {
                        self.held_low = mean_v;
                        let (dv, di) = (self.high.0 - mean_v, self.high.1 - mean_i);
                        let r = dv / di;
                        if !(r > 1e-3 && r < 100.0) {
                            return self.fail(CommissioningFault::OutOfRange { quantity: "resistance", value: r });
                        }
                        self.resistance = r;
                        self.start_alignment();
                    }
                }
            }
            Stage::Forward | Stage::Backward => {
                // The test current on the vector's d axis, none on its q axis: the turning
                // rotor's back-EMF is the loop's to reject, not the current's to follow.
                let vd = self.current_pi.d(self.test_current - current.d);
                q_voltage = self.current_pi.q(-current.q);
                self.voltage = vd;
                // A trapezoid of speed: the rotor's lag is the same on both passes only at the
                // full speed, so only those ticks are fitted (the swing that starting and
                // stopping excite would bias the intercepts).
                let full = TAU * s.alignment_speed * s.tick_period;
                let accel = full / self.ticks_of(ALIGNMENT_ACCELERATION_S) as f32;
                let end = TAU * s.alignment_turns;
                let remaining = end - self.travelled;
                let braking = libm::sqrtf(2.0 * accel * remaining.max(0.0));
                self.speed = (self.speed + accel).min(full).min(braking).max(accel.min(remaining));
                let at_full_speed = self.speed == full;
                self.travelled += self.speed;
                let done = self.travelled >= end;
                if stage == Stage::Forward {
                    if at_full_speed {
                        self.forward.add(self.angle, relative);
                    }
                    self.angle = self.travelled.min(end);
                    if done {
                        self.angle = end;
                        self.backward = Pass::new(end);
                        self.travelled = 0.0;
                        self.speed = 0.0;
                        self.next_stage(Stage::Backward);
                    }
                } else {
                    if at_full_speed {
                        self.backward.add(self.angle, relative);
                    }
                    self.angle = (end - self.travelled).max(0.0);
                    if done {
                        self.angle = 0.0;
                        let a = match align(&self.forward, &self.backward, s.counts_per_rev, s.max_pole_pairs, start) {
                            Ok(a) => a,
                            Err(e) => return self.fail(CommissioningFault::Alignment(e)),
                        };
                        self.alignment = Some(a);
                        self.angle = self.rotor_angle(&a, i.encoder_count);
                        self.start_chips(Stage::InductanceD);
                    }
                }
            }
            Stage::InductanceD | Stage::InductanceQ => {
                let axis_current = if stage == Stage::InductanceD { current.d } else { current.q };
                // The fit's model holds through the transient of the chips' start: a few ticks
                // only, for the delayed voltage's bookkeeping.
                let settling = CHIP_SETTLING_TICKS;
                if self.ticks > settling {
                    if let Some(previous) = self.last_current {
                        self.fit.add(previous, axis_current, self.applied_chip);
                    }
                }
                self.last_current = Some(axis_current);
                if self.ticks >= settling + self.chips.period() {
                    let axis = if stage == Stage::InductanceD { 'd' } else { 'q' };
                    let Some(w) = self.fit.winding(s.tick_period) else {
                        return self.fail(CommissioningFault::Inductance { axis });
                    };
                    if !(w.inductance > 1e-6 && w.inductance < 1.0) {
                        return self
                            .fail(CommissioningFault::OutOfRange { quantity: "inductance", value: w.inductance });
                    }
                    if stage == Stage::InductanceD {
                        self.ld = w.inductance;
                        self.start_chips(Stage::InductanceQ);
                    } else {
                        let alignment =
                            self.alignment.unwrap_or(Alignment { pole_pairs: 1, reversed: false, offset: 0.0 });
                        self.status = CommissioningStatus::Done(MeasuredMotor {
                            resistance: self.resistance,
                            ld: self.ld,
                            lq: w.inductance,
                            alignment,
                        });
                        return None;
                    }
                }
                // A chip around the voltage that holds half the test current, on the measured
                // axis. Its size: the resistive voltage of half the test current where the
                // winding follows a chip within a few ticks (the current then swings between
                // none and the test current and keeps its sign, so the inverter's error stays
                // constant); up to four times it on a slow winding, whose current moves by a
                // small share of a chip (its random walk over the record, about `sqrt(T/2τ)` of
                // the chip's current), so that the ripple stands above the sensors' noise.
                let ticks_per_tau = self.probe_inductance / (self.resistance * s.tick_period);
                let size = crate::limit(0.25 * libm::sqrtf(ticks_per_tau), 1.0, 4.0);
                // The resistive part of half the test current (the held voltage also carries
                // the inverter's dead-time voltage, which a chip's swing must not scale).
                let chip = size * 0.5 * self.resistance * self.test_current * self.chips.next_chip() as f32;
                self.applied_chip = self.last_chip;
                self.last_chip = chip;
                if stage == Stage::InductanceD {
                    self.voltage = self.held_low + chip;
                } else {
                    self.voltage = self.held_low;
                    q_voltage = chip;
                }
            }
        }
        // The vector for the next tick: on the fixed angle until aligned, then the rotor's.
        // Within the highest voltage and the bus's circle, the direction kept.
        let limit = s.max_voltage.min(crate::reference_frames::voltage_circle_radius(i.bus_voltage));
        let magnitude = libm::sqrtf(self.voltage * self.voltage + q_voltage * q_voltage);
        let scale = if magnitude > limit { limit / magnitude } else { 1.0 };
        let (sin, cos) = sin_cos(self.angle);
        Some(inverse_park(Dq { d: self.voltage * scale, q: q_voltage * scale }, sin, cos))
    }

    /// The vector's turn under a current loop designed from the resistance and the d-axis
    /// inductance just measured (its zero on the winding's pole, `ALIGNMENT_BANDWIDTH_HZ`),
    /// its integrators starting from the held voltage.
    fn start_alignment(&mut self) {
        self.start_current_loop(self.resistance, self.probe_inductance, self.held);
        self.voltage = self.held;
        self.travelled = 0.0;
        self.speed = 0.0;
        self.forward = Pass::new(0.0);
        self.next_stage(Stage::Forward);
    }

    /// A current loop for a winding of `resistance` and `inductance`: its zero on the winding's
    /// pole, `ALIGNMENT_BANDWIDTH_HZ`; its d integrator starting from `held` (V).
    fn start_current_loop(&mut self, resistance: f32, inductance: f32, held: f32) {
        let w = TAU * ALIGNMENT_BANDWIDTH_HZ;
        let (kp, ki) = (inductance * w, resistance * w);
        let limit = self.settings.max_voltage;
        let period = self.settings.tick_period;
        let gains = PiGains { kp, ki, period };
        let (mut d, q) = (PiController::new(gains), PiController::new(gains));
        d.preset(held);
        self.current_pi = DqPi { d, q, limit };
    }

    fn start_chips(&mut self, stage: Stage) {
        self.chips = MSequence::new(CHIP_DEGREE).unwrap_or(MSequence::DEGREE_15);
        self.fit = WindingFit::default();
        self.last_chip = 0.0;
        self.applied_chip = 0.0;
        self.last_current = None;
        self.voltage = self.held_low;
        self.next_stage(stage);
    }
}
