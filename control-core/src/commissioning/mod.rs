//! Commissioning a motor and encoder the drive has never seen: the phase resistance, the
//! encoder's direction, the pole pairs and the electrical angle at count 0, and the d- and
//! q-axis inductances, measured by the drive itself, one tick at a time, the current kept
//! within the test current throughout (a tenth over it at most, in the current loop's
//! transients) and the voltage within the highest voltage and the bus's circle.
//!
//! The sequence, each stage on the previous one's result, after 16 ms at zero voltage that
//! read the current sensors' noise (`sensor_noise`: the q fit on a winding of more than four
//! ticks takes it out) and their offsets (taken off every reading after):
//! 1. **Probe.** Pseudo-random voltage chips of zero mean on a fixed angle (0), their size
//!    growing from a millivolt by a quarter a period (two such steps a period while their
//!    current would stay under a fiftieth of the test current) while the current stays under
//!    a third of the test current; a fit of the response gives a first resistance and
//!    inductance: enough to close a current loop. The fit with the rotor's back-EMF as a series capacitance
//!    (`free_rotor_fit`: the chips make torque on a rotor that is not on the fixed angle, and
//!    turn a light one) where it finds a winding, else the first-order one (`winding_fit`).
//!    On a winding that settles within the tick, whose pole no fit tells from the inverter's
//!    dead-time voltage under binary chips, the winding's gain and a third of a tick
//!    (`WindingFit::settled_within_tick`).
//!    Where none finds a winding (a light rotor a quarter turn or so from angle 0 turns with
//!    the chips, most torque there), once more on the axis a quarter turn on, its chips grown
//!    again from an eighth of their size.
//!    The resistance is rough: the loop's integral corner is kept to a third of its bandwidth.
//!    No current at the highest voltage: an open phase.
//! 2. **Resistance.** The current loop ramps the current to the test current while the vector
//!    turns half an electrical turn back to the fixed angle, fastest at the start and slowing
//!    to rest (the rotor, wherever it stands, is pulled in while the current is small: on a
//!    vector that stood still, a rotor at its unstable equilibrium would stay there, held by
//!    friction, and fall at the full current later). A light rotor, which the probe's chips
//!    turned (the probe ran again, or the rotor's mechanical time constant as they saw it is
//!    under half a millisecond), could still chase that vector on its unstable side and fall at
//!    half the test current: its vector sweeps one way from three quarters of a turn back to
//!    angle 0 at 0.22 of the test current, and the current then grows on the still vector. The
//!    loop holds the test current and then half of it, the rotor's swing on the vector damped
//!    until shortly before the first hold has settled, or until it is still where it swings back
//!    through the vector (`swing_damping`); a swing back is also damped by the held current,
//!    weakened to a quarter from each turning point the encoder sees to the swing's centre
//!    (`spring_weakening`: it needs no sign, no pole pairs and no back-EMF, where a weak magnet's
//!    winding barely damps the swing and its back-EMF is lost in the errors). `R = ΔV/ΔI`
//!    between the two holds (the sensors' offsets and the inverter's dead-time voltage, the same at
//!    both, drop out). The third phase's current not the other two's mean: a phase is missing.
//! 3. **Encoder.** The loop holds the test current on a vector that turns slowly forward by a
//!    few electrical turns and back; the rotor follows. Counts against the vector's angle give
//!    the direction, the pole pairs and the electrical angle at count 0 (`encoder_alignment`).
//!    The q voltage the loop needs at full speed, forward and back, is the back-EMF:
//!    `v_q = ω·(L_d·i·cos²δ + L_q·i·sin²δ + ψ·cos δ)` in the vector's frame, the rotor lagging
//!    by `δ` either way, so half their difference over `ω` gives the flux linkage `ψ` once the
//!    inductances are known (stages 4 and 5). The inverter's dead-time voltage (what the holds'
//!    voltage carries beyond `R·I`) is fed forward, so the loop has no steps of it to follow
//!    as the phase currents change sign (their lag, opposite on the two passes, would bias
//!    the difference). The inductive term `ω·L_d·I` stands beside the back-EMF: the flux
//!    linkage's error is the d-axis inductance's times `L_d·I/ψ`, small on servo motors
//!    (their armature's flux at the test current is a fraction of the magnet's) and large on
//!    a motor whose armature's flux at the test current exceeds its magnet's. The loop holds
//!    the current at the ticks' samples, so a winding that settles within about a tick adds
//!    `(y·coth y − 1)·L_q·i` to the armature's flux at a small lag (`y = R·T/(2·L_q)`: the d
//!    voltage, held in the stator over the tick, turns against the rotor, and the q winding
//!    follows it), taken out with the rest; on a weak magnet with a large resistance it is a
//!    few percent of `ψ`.
//!    The rotor swings on the vector (the magnet's torque a spring on its inertia); the lines'
//!    intercepts and the back-EMF's mean need a few of its periods in a pass (4 Hz or more at
//!    the test current: a heavy load on a weak magnet needs a higher test current). The
//!    swing's variance about the lag (the counts' scatter about the line of the exact counts
//!    per radian) takes the mean of `cos δ` below `cos` of the mean lag, which the flux
//!    linkage takes into account.
//! 4. **d-axis inductance.** Chips around the voltage of half the test current on the rotor's
//!    d axis (read from the encoder each tick; the d current keeps its sign) and the fit
//!    again, the q current held at zero by the loop meanwhile (a rotor still swinging from the
//!    passes would drive its back-EMF through the winding). On a winding that settles within
//!    the tick, the fit with the inverter's dead-time voltage beside it (`d_winding`).
//! 5. **q-axis inductance.** Chips on the rotor's q axis (now known from the encoder) beside
//!    the held d-axis voltage (shaped on a winding of more than 256 ticks: `q_shaping`), and
//!    the fit. The chips' q current turns the rotor, whose
//!    back-EMF the free rotor's fit takes (`free_rotor_fit`), on the samples' differences on a
//!    winding of a tick or more, where a rotor sticking and slipping on its friction acts least
//!    (on a winding of more than four ticks the sensors' noise taken out: `noise_matching`); on
//!    a faster winding where the rotor's motion shows, on their second differences
//!    (`q_winding`). Where no fit finds a winding, or the fit's resistance lies 3 % or more
//!    off the holds' (the rotor's motion shows), or the second differences' fit is taken and
//!    the free rotor's disagrees with it on the inductance by a tenth or more (the rotor
//!    sticks and slips: each fit bends differently, their resistances may still agree), on a
//!    winding of up to four ticks (a light rotor on a strong magnet reverses with each chip
//!    and sticks on its friction), the stage runs once more: a constant q voltage three times
//!    the chips', ramped in first, turns the rotor one way throughout (at most 1¼ electrical
//!    turns over the stage, by the flux linkage the passes give), the frame following the
//!    rotor, so that its friction is a constant torque, which no chip reverses
//!    (`turning_bias`); on it the free rotor's fit is taken where its resistance agrees within
//!    3 % and at most half as far off as the second differences'. Of the two runs, the one
//!    whose resistance agrees with the holds' is kept; where the first run's fits disagreed,
//!    the turned run's where its resistance agrees within 3 %.
//! 6. **Current loop.** The PI for the stated bandwidth from `R` and `L_q` (the torque's axis;
//!    `current_loop_design`), the drive's gains for both axes. The design is checked on the d
//!    axis, the rotor's own (where a current makes no torque and the rotor stays still), with
//!    the same design from `R` and `L_d`: steps of the d current around half the test
//!    current, their measured bandwidth and overshoot reported (the host holds them to the
//!    target); an overshoot over half the step fails the sequence. Then the winding, shorted,
//!    brakes the rotor to rest (what the q chips left of its motion; a machine without
//!    friction would drift on) before the sequence ends.
//!
//! Any fault (an overcurrent, a reading that is not finite, a failed stage) ends the sequence
//! with the bridge off and its reason; nothing is kept.

mod current_loop_design;
mod encoder_alignment;
mod free_rotor_fit;
mod noise_matching;
mod regression;
mod sensor_noise;
mod spring_weakening;
mod swing_damping;
mod winding_fit;

#[cfg(test)]
mod motor_model;
#[cfg(test)]
mod tests;

pub use current_loop_design::{design as design_current_loop, StepCheck};
pub use encoder_alignment::{Alignment, AlignmentError};
pub use winding_fit::Winding;

use core::f32::consts::TAU;

use crate::m_sequence::MSequence;
use crate::pi_controller::{PiController, PiGains};
use crate::reference_frames::{clarke, inverse_park, park, AlphaBeta, Dq};
use crate::trigonometry::sin_cos;
use current_loop_design::{BandwidthSearch, StepResponse, STEP_SAMPLES};
use encoder_alignment::{align, Pass};
use free_rotor_fit::FreeRotorFit;
use noise_matching::NoiseMatching;
use sensor_noise::SensorNoise;
use spring_weakening::SpringWeakening;
use swing_damping::SwingDamping;
use winding_fit::{inductance_in_range, resistance_in_range, WindingFit};

/// What the sequence needs to know before it starts: nothing of the motor.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// The current loop's closed-loop bandwidth the gains are designed for (Hz): from 0.02 to
    /// 0.1 of the tick rate (320 Hz to 1.6 kHz at 16 kHz).
    pub current_bandwidth_hz: f32,
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
        let share = self.current_bandwidth_hz * self.tick_period;
        if !(0.02..=0.1).contains(&share) {
            return Err("current_bandwidth_hz");
        }
        Ok(())
    }

    /// [`Self::for_encoder`] of an axis's parameters (its encoder, its tick).
    pub fn for_params(p: &crate::params::Params) -> Self {
        Self::for_encoder(p.encoder_counts_per_rev, p.rates.tick_period())
    }

    /// A test current of 2 A, at most 12 V, one and a half electrical turns each way at two
    /// turns a second, a current loop of 3/32 of the tick rate (1.5 kHz at 16 kHz, the
    /// bandwidth the default gains are tuned for).
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
            current_bandwidth_hz: 0.09375 / tick_period,
        }
    }
}

/// What commissioning found.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct MeasuredMotor {
    /// Phase resistance (Ω).
    pub resistance: f32,
    /// d- and q-axis inductances (H).
    pub ld: f32,
    pub lq: f32,
    /// Permanent-magnet flux linkage (Wb).
    pub flux_linkage: f32,
    pub alignment: Alignment,
    /// The current loop's gains (V/A, V/(A·s)), designed for the settings' bandwidth, and what
    /// their step measured.
    pub current_kp: f32,
    pub current_ki: f32,
    pub current_step: StepCheck,
    /// The current the measurements drove (A): the settings' test current, or less where the
    /// highest voltage allowed less on this winding. The scale of the currents the motor
    /// takes (`Params::with_commissioned` weighs the decoupling's steps against it).
    pub test_current: f32,
}

/// Why commissioning stopped; the bridge is off and nothing is kept.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
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
    /// The designed current loop's step: no bandwidth within a factor of 4 of the target, or
    /// an overshoot over half the step.
    CurrentLoop {
        bandwidth_hz: f32,
        overshoot: f32,
    },
    /// A value outside what the drive can run.
    OutOfRange {
        quantity: MeasuredQuantity,
        value: f32,
    },
    /// The drive latched a fault of its own (a bus voltage out of its limits, the power
    /// stage's break input) while the sequence ran.
    DriveFault {
        faults: u32,
    },
    /// Stopped from the outside (the host asked, or its link was lost).
    Stopped,
}

/// What a value out of range was.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum MeasuredQuantity {
    /// The probe's first-order fit (its resistance).
    Winding,
    Resistance,
    Inductance,
    FluxLinkage,
}

/// Where the sequence is.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum CommissioningStatus {
    Running(Stage),
    Done(MeasuredMotor),
    Failed(CommissioningFault),
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
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
    CurrentStep,
    StepAnalysis,
    /// The first stage: the current sensors read at zero voltage (`sensor_noise`).
    SensorNoise,
}

/// The current sensors' reading at zero voltage before the probe (s).
const SENSOR_NOISE_S: f32 = 0.016;
/// The vector's acceleration to the alignment speed and its braking (s).
const ALIGNMENT_ACCELERATION_S: f32 = 0.25;
/// Ticks of each hold: the first part settles, the last part is averaged.
const HOLD_S: f32 = 0.15;
const AVERAGED_S: f32 = 0.05;
/// The current's ramp to the test current (s): slow beside the rotor's swing on the vector,
/// which it then follows nearly at rest.
const RAMP_S: f32 = 0.3;
/// The vector's turn over the ramp of a rotor that is not light (rad, electrical).
const RAMP_TURN: f32 = core::f32::consts::PI;
/// A rotor whose mechanical time constant the probe's chips saw ([`FreeRotorFit::branch`]) is
/// under this (s), or that made the probe run again, is light: its ramp sweeps the
/// vector at a low current first ([`LIGHT_SWEEP_CURRENT`], a share of the test current) three
/// quarters of an electrical turn back to a quarter turn short of angle 0 over the first
/// [`LIGHT_SWEEP_SHARE`] of the ramp, then the last quarter turn over the next
/// [`LIGHT_FINISH_SHARE`], and ramps the current on the still vector over the rest.
const LIGHT_ROTOR_S: f32 = 5e-4;
const LIGHT_SWEEP_CURRENT: f32 = 0.22;
const LIGHT_SWEEP_SHARE: f32 = 0.4;
const LIGHT_FINISH_SHARE: f32 = 0.2;
/// The share of the light rotor's sweep over which its current grows to
/// [`LIGHT_SWEEP_CURRENT`]: a rotor standing just ahead of the sweep's start is pulled along
/// before the vector has run half a turn from it.
const LIGHT_CURRENT_RISE: f32 = 0.25;

/// The ramp's vector angle (rad, electrical) and current (a share of the test current) at
/// `x` of its time. The vector turns back half an electrical turn as the current grows, to
/// rest at angle 0: a rotor that stood near the vector's unstable equilibrium would sit there
/// while friction holds it and fall later at the full current; the turning vector pulls every
/// rotor in while the current is still small. It turns fastest at the start, where the current
/// is least (`(1 − x)²`): a rotor ahead of it by more than a quarter turn, which chases it on
/// the unstable side, is passed while the current is small and falls back to it then, instead
/// of chasing it until it stops near the antipode and falls at half the test current or more
/// (over 3 000 drawn motors, a vector that starts from rest left 7 at 1.12–1.54 times the test
/// current). A light rotor can still chase it that far: [`light_ramp`].
fn ramp(x: f32) -> (f32, f32) {
    (RAMP_TURN * (1.0 - x) * (1.0 - x), x)
}

/// The light rotor's ramp (`LIGHT_ROTOR_S`): the vector sweeps back from three quarters of an
/// electrical turn to a quarter (`(1 − y)²`, fastest at the start), its current growing to a
/// low share of the test current over the sweep's first quarter and held there, then turns the
/// last quarter turn to angle 0 at that current, and the current then grows on the still
/// vector. A light rotor follows a vector that turns one way only: wherever it stood, it is
/// caught and drawn to angle 0 at the low current, and no rotor stands near the antipode when
/// the current grows. A heavy rotor on a weak magnet swings too slowly at the low current to
/// follow the sweep in its time: it takes [`ramp`].
fn light_ramp(x: f32) -> (f32, f32) {
    use core::f32::consts::FRAC_PI_2;
    let finished = LIGHT_SWEEP_SHARE + LIGHT_FINISH_SHARE;
    if x < LIGHT_SWEEP_SHARE {
        let y = x / LIGHT_SWEEP_SHARE;
        (FRAC_PI_2 + 2.0 * FRAC_PI_2 * (1.0 - y) * (1.0 - y), LIGHT_SWEEP_CURRENT * (y / LIGHT_CURRENT_RISE).min(1.0))
    } else if x < finished {
        let z = (x - LIGHT_SWEEP_SHARE) / LIGHT_FINISH_SHARE;
        (FRAC_PI_2 * (1.0 - z) * (1.0 - z), LIGHT_SWEEP_CURRENT)
    } else {
        let w = (x - finished) / (1.0 - finished);
        (0.0, LIGHT_SWEEP_CURRENT + (1.0 - LIGHT_SWEEP_CURRENT) * w)
    }
}
/// The rotor counts as still when its count has not changed for this long (s); the first
/// hold waits for it at most `STILL_WAIT_S`.
const STILL_S: f32 = 0.03;
const STILL_WAIT_S: f32 = 1.0;
/// The held current is weakened on a swinging rotor (`spring_weakening`) only until this long
/// before the wait's longest end; the wait sees the rotor still at the full current (for
/// `STILL_S` after its ramp back) before the holds average: a winding's transient as its
/// current comes back (`L·di/dt` on a slow winding) would bias the hold's voltage.
const STRONG_END_S: f32 = 0.25;
/// The held current's share moves by at most 1 in this long (s).
const SHARE_RAMP_S: f32 = 2e-3;
/// The swing's damping ends this long before the first hold's wait for a still rotor: a rotor
/// the damping held creeping takes the rest of its way then, and the wait sees it move.
const RELEASE_S: f32 = 0.04;
/// The probe's first chip size (V), its growth per period, the share of the test current it
/// grows to, and its chips' M-sequence degree (255 chips a period: the growth is checked over
/// whole periods, whose excursions the fit's periods repeat) and the periods it fits over.
const PROBE_START_V: f32 = 1e-3;
/// The probe's chips grow by this step from one period to the next, by two steps at once
/// ([`PROBE_MAX_STEPS`]) while their current's peak, grown in proportion, would stay under
/// [`PROBE_FLOOR`] of the test current. Not more: chips the inverter's dead-time voltage
/// swallows show no current either, and a jump past that voltage drives a current of up to
/// `(1.25^steps − 1)·V_dead/R` at once (0.56 of `V_dead/R` with two steps, 0.25 with one).
const PROBE_GROWTH: f32 = 1.25;
const PROBE_MAX_STEPS: u32 = 2;
const PROBE_SHARE: f32 = 0.3;
/// At the highest voltage, the least current (a share of the test current) the probe fits.
const PROBE_FLOOR: f32 = 0.02;
const PROBE_DEGREE: u32 = 8;
const PROBE_FIT_PERIODS: u32 = 8;
/// The probe's axis (rad, electrical) when its first run, on angle 0, found no winding: a
/// light rotor on a strong magnet that stands a quarter turn or so from angle 0 takes the most
/// torque from the chips and turns with them, and its back-EMF, beside a winding that settles
/// within the tick, leaves no fit a winding; a quarter turn on, the chips barely turn it.
const PROBE_RETRY_AXIS: f32 = 0.5 * core::f32::consts::PI;
/// The retry's chips start at this share of the first run's last ones.
const PROBE_RETRY_SHRINK: f32 = 0.125;
/// Chips of each inductance stage (an M-sequence of degree 12), after a few ticks' start.
const CHIP_DEGREE: u32 = 12;
const CHIP_SETTLING_TICKS: u32 = 64;
/// The q stage's constant voltage under its chips, their voltage's multiple (`turning_bias`).
const Q_BIAS_OVER_CHIP: f32 = 3.0;
/// The chips' share of their size on a stage that turns the rotor: at most the first, down to
/// the second where the turns or the voltage allow no more.
const Q_TURNING_CHIP_SHARE: f32 = 0.5;
const Q_LEAST_CHIP_SHARE: f32 = 0.15;
/// The q stage runs once more turning the rotor where its fit's resistance lies this far (a
/// share) or more off the holds' (the rotor's motion shows), or no fit finds a winding.
const Q_RETRY_AGREEMENT: f32 = 0.03;
/// The q stage runs once more turning the rotor too where its free-rotor fit and its second
/// differences' disagree on the inductance by this share or more (the rotor sticks and slips).
const Q_FITS_AGREEMENT: f32 = 0.1;
/// The slowest winding (its time constant in ticks) whose q stage turns the rotor.
const Q_TURNING_TICKS: f32 = 4.0;
/// The electrical turns the constant voltage may turn the rotor over the stage.
const Q_TURNS: f32 = 1.25;
/// The constant voltage's ramp from 0 (s), before the fit starts: the rotor's acceleration
/// current is the voltage's over `R` times its mechanical time constant over the ramp (the
/// ramp waits while it exceeds [`Q_BIAS_CURRENT`]; a rotor that slow then turns under a
/// voltage still rising, which the fit takes as applied).
const Q_BIAS_RAMP_S: f32 = 0.02;
/// The q current (a share of the test current, low-passed over `Q_BIAS_SMOOTHING_S`) under
/// which the constant voltage ramps on.
const Q_BIAS_CURRENT: f32 = 0.2;
const Q_BIAS_SMOOTHING_S: f32 = 0.002;
/// The q chips' current peak on a winding slower than a tick, a share of the test current
/// (`q_chip_volts`).
const Q_CHIP_PEAK: f32 = 0.65;
/// A q winding slower than this (ticks: the d axis's time constant, measured) has its chips
/// shaped (`q_shaping`), over this many shapings tried.
const Q_SHAPED_TICKS: f32 = 256.0;
const Q_SHAPINGS: u32 = 16;
// The turned q run's chips are sized unshaped (`turning_bias`): no winding it runs on is
// shaped.
const _: () = assert!(Q_TURNING_TICKS < Q_SHAPED_TICKS);
/// On a winding faster than a tick, the first-order fit's resistance this far off the holds'
/// (a share) says the rotor's motion shows in the q stage, and the second differences' fit is
/// taken if its own resistance lies within [`DIFFERENCES_AGREEMENT`] of the holds' (`q_winding`).
const RESISTANCE_AGREEMENT: f32 = 0.03;
/// On the turned q run, the free rotor's fit is taken over the second differences' where its
/// resistance lies at most this share as far off the holds' (`q_winding`).
const TURNED_FREE_ROTOR_SHARE: f32 = 0.5;
/// How far (a share) the second differences' fit's own resistance may lie off the holds' for
/// its inductance to be taken (`q_winding`): a check that the fit found a winding, not of its
/// resistance, which the second differences leave poorly determined (the resistance shows at
/// the low frequencies they weigh least): on a rotor of 15 µs sticking on a winding of a
/// tick, their resistance reads 30 % high while their inductance is within 1.1 %.
const DIFFERENCES_AGREEMENT: f32 = 0.5;

/// The current step's overshoot beyond which the sequence fails (the design is kept, and its
/// measured bandwidth and overshoot reported, below it).
const STEP_OVERSHOOT_LIMIT: f32 = 0.5;

/// Each level of the current step (ticks): the step's samples; levels 0, +1, 0, −1 in turn,
/// `STEP_CYCLES` times.
const STEP_CYCLES: u32 = 8;

/// How far behind the rotor the current step's frame follows it (s): each tick it moves
/// `T/STEP_FRAME_LAG_S` of the way to the rotor's angle. The d current pulls the rotor toward
/// the frame, a spring of stiffness `k`; an anchor that follows the rotor at a speed
/// proportional to the spring's stretch is a dashpot in series with it, which takes the
/// swing's energy: a rotor of inertia `J` swings on `s² + s/τ + k/J` (damped critically where
/// `√(k/J) = 1/(2τ)`, 17 rad/s, the slow swing of a heavy rotor on a weak magnet; a faster
/// one decays at `1/(2τ)`, a slower one at `τ·k/J`). A still rotor takes no torque
/// (the frame reaches it), and a rotor the q stage left standing off its frame on friction
/// finds the frame on it from the step's first tick, so the step sees the d axis alone.
const STEP_FRAME_LAG_S: f32 = 0.03;

/// One hold's averaging window: the mean voltage asked for (V) and current (A) on the vector's
/// d axis, its length (s), and the encoder's count at its first and last tick.
#[derive(Clone, Copy, Debug, Default)]
struct HoldWindow {
    voltage: f32,
    current: f32,
    seconds: f32,
    first: Option<i32>,
    last: i32,
    /// Sums of the phase a and b currents over the window (A).
    phases: [f32; 2],
}

/// The q voltage asked for and the d current (vector's frame) over one pass's full-speed
/// ticks, and the vector's angle and the encoder's count on the first and the last of them.
#[derive(Clone, Copy, Debug, Default)]
struct BackEmf {
    voltage: f32,
    current: f32,
    q_current: f32,
    ticks: u32,
    first: Option<(f32, i32)>,
    last: (f32, i32),
}

impl BackEmf {
    fn add(&mut self, q_voltage: f32, current: Dq, angle: f32, count: i32) {
        self.voltage += q_voltage;
        self.current += current.d;
        self.q_current += current.q;
        self.ticks += 1;
        self.first.get_or_insert((angle, count));
        self.last = (angle, count);
    }

    /// The mean q voltage (V), d and q currents (A), and the window's length (s).
    fn means(&self, tick: f32) -> (f32, f32, f32, f32) {
        let n = self.ticks.max(2) as f32;
        (self.voltage / n, self.current / n, self.q_current / n, (n - 1.0) * tick)
    }
}

/// `y·coth(y) − 1` for `y = R·T/(2·L)` of a rotor axis's winding of inductance `L`: on a
/// vector turning at `ω` with the current `I` held at the ticks (sampled at each tick's start,
/// the voltage held over the tick and placed at its middle), on a rotor on the vector's axis
/// the q voltage the loop needs is `ω·(ψ + L_d·I + (y·coth(y) − 1)·L_q·I)` with `L = L_q` (the
/// q current starting and ending each tick at 0 under the d voltage's turn within it). A
/// winding much slower than the tick gives `y²/3`, nothing; one that settles within the tick,
/// `y − 1`: its current follows the held voltage's turn, not the vector's.
fn sampled_winding_excess(y: f32) -> f32 {
    if y.abs() < 0.1 {
        // The series `y²/3 − y⁴/45 + …`, where the closed form loses digits.
        let y2 = y * y;
        y2 * (1.0 / 3.0 - y2 / 45.0)
    } else {
        y / libm::tanhf(y) - 1.0
    }
}

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
    /// Full-speed ticks of each pass (forward, backward).
    back_emf: [BackEmf; 2],
    /// The holds' averaging windows (high, low).
    hold_windows: [HoldWindow; 2],
    flux_linkage: f32,
    /// The current step: its response, the q-current step's size (A), the gains designed and
    /// the bandwidth's search.
    step: StepResponse,
    step_size: f32,
    designed: (f32, f32),
    search: Option<BandwidthSearch>,
    /// The present pass's angle turned and its speed (rad, rad per tick); the output's angle
    /// ahead of the vector's (rad).
    advance: f32,
    travelled: f32,
    speed: f32,
    alignment: Option<Alignment>,
    ld: f32,
    lq: f32,
    /// The inverter's dead-time voltage per phase (V), from the holds.
    dead_time: f32,
    /// The probe's inductance (H): the alignment's current loop is designed with it.
    probe_inductance: f32,
    /// The probe's resistance (Ω), as its fit gave it (the loop's design may take less).
    probe_resistance: f32,
    /// The first hold's d voltage and current summed while its damping runs.
    swing_hold: (f32, f32),
    /// The current loop of the alignment (in the vector's frame) and the damping of the
    /// rotor's swing on its vector (the q current it asks for).
    current_pi: DqPi,
    swing: SwingDamping,
    /// The held current's weakening on a swinging rotor's way back to the vector.
    weakening: SpringWeakening,
    /// The share of the test current the first hold asks for (1 but where weakened).
    held_share: f32,
    chips: MSequence,
    fit: WindingFit,
    q_fit: FreeRotorFit,
    /// The free rotor's fit of the q stage's samples' second differences (`free_rotor_fit`),
    /// fed and taken on a winding faster than a tick only (`q_winding`): what a rotor that sticks and slips
    /// on its friction adds at low and middle frequencies weighs least there.
    q_fit_twice: FreeRotorFit,
    /// The probe's free-rotor fit of the samples' differences: its last resort.
    probe_high_passed: FreeRotorFit,
    /// The dead-time voltage along the measured axis for the phase currents' signs at the
    /// last reading (V).
    dead_time_along_axis: f32,
    /// The probe's dead-time regressor at the last reading: the voltage along its axis per
    /// volt of dead time, for the phase currents' signs then.
    dead_time_shape: f32,
    /// The chip voltage asked for on the last tick (applied over this one) and the one
    /// before, and the last tick's current on the injected axis.
    last_chip: f32,
    applied_chip: f32,
    last_current: Option<f32>,
    /// The q stage's constant voltage once ramped (V; 0: none): the rotor turns on it
    /// (`turning_bias`).
    q_bias: f32,
    /// The constant voltage applied now (V), on its ramp to `q_bias`, and the q current
    /// low-passed (A): the ramp waits while the rotor's acceleration draws more than
    /// [`Q_BIAS_CURRENT`] of the test current.
    bias_now: f32,
    q_lowpass: f32,
    /// The q stage's first run's winding, while a second turns the rotor (`Q_RETRY_AGREEMENT`).
    first_q: Option<Winding>,
    /// The second run turned the rotor because the first run's fits disagreed.
    q_fits_disagreed: bool,
    /// The probe runs again on the axis a quarter of an electrical turn on
    /// ([`PROBE_RETRY_AXIS`]): its first run found no winding.
    probe_retried: bool,
    /// The probe's chips turned the rotor as a light one ([`LIGHT_ROTOR_S`]).
    light_rotor: bool,
    /// The current sensors' noise, read before the probe.
    sensor_noise: SensorNoise,
    /// The current sensors' offsets (A, phases a and b), read with their noise and taken off
    /// every reading after it.
    sensor_offsets: [f32; 2],
    /// A slow q winding's search for the noise variance its fit takes out (`noise_matching`),
    /// once its chips have ended.
    noise_matching: Option<NoiseMatching>,
    /// Ticks an inductance stage has spent on its end's work (`choose_winding` and after).
    finishing: u32,
    /// The q chips' shaping once chosen (`q_shaping`), and the last chip's sign.
    q_shaping: Option<f32>,
    last_sign: f32,
    /// What was measured, kept while the rotor is braked to rest.
    result: Option<MeasuredMotor>,
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
            status: CommissioningStatus::Running(Stage::SensorNoise),
            ticks: 0,
            voltage: 0.0,
            angle: 0.0,
            chip_size: PROBE_START_V,
            peak: 0.0,
            held: 0.0,
            held_low: 0.0,
            q_bias: 0.0,
            bias_now: 0.0,
            q_lowpass: 0.0,
            first_q: None,
            q_fits_disagreed: false,
            probe_retried: false,
            light_rotor: false,
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
            back_emf: [BackEmf::default(); 2],
            hold_windows: [HoldWindow::default(); 2],
            flux_linkage: 0.0,
            step: StepResponse::default(),
            step_size: 0.0,
            designed: (0.0, 0.0),
            search: None,
            advance: 0.0,
            travelled: 0.0,
            speed: 0.0,
            alignment: None,
            ld: 0.0,
            lq: 0.0,
            dead_time: 0.0,
            probe_inductance: 0.0,
            probe_resistance: 0.0,
            swing_hold: (0.0, 0.0),
            current_pi: DqPi::default(),
            swing: SwingDamping::default(),
            weakening: SpringWeakening::default(),
            held_share: 1.0,
            chips: match MSequence::new(PROBE_DEGREE) {
                Ok(m) => m,
                Err(_) => MSequence::DEGREE_15,
            },
            fit: WindingFit::default(),
            q_fit: FreeRotorFit::default(),
            q_fit_twice: FreeRotorFit::high_passed_twice(),
            probe_high_passed: FreeRotorFit::high_passed(),
            dead_time_along_axis: 0.0,
            dead_time_shape: 0.0,
            last_chip: 0.0,
            applied_chip: 0.0,
            last_current: None,
            sensor_noise: SensorNoise::default(),
            sensor_offsets: [0.0; 2],
            noise_matching: None,
            finishing: 0,
            q_shaping: None,
            last_sign: 0.0,
            result: None,
        })
    }

    pub fn status(&self) -> CommissioningStatus {
        self.status
    }

    /// End a running sequence from the outside (the bridge goes off at once: the next step
    /// returns `None`); a finished one keeps its result.
    pub fn stop(&mut self, fault: CommissioningFault) {
        if matches!(self.status, CommissioningStatus::Running(_)) {
            self.status = CommissioningStatus::Failed(fault);
        }
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

    /// The ticks the encoder has kept its count, with this tick's `count`.
    fn count_still(&mut self, count: i32) {
        if count != self.last_count {
            self.last_count = count;
            self.still_ticks = 0;
        } else {
            self.still_ticks += 1;
        }
    }

    /// The rotor's electrical angle from the encoder, once aligned.
    fn rotor_angle(&self, a: &Alignment, count: i32) -> f32 {
        // In 32 bits, whose division the Cortex-M4 has in hardware (64-bit remainders are a
        // library call of a few hundred instructions each): the counts per revolution (at
        // most 2²⁴) times the pole pairs (at most 64) stay under 2³⁰.
        let cpr = self.settings.counts_per_rev;
        let raw = count.rem_euclid(cpr as i32) as u32;
        let corrected = if a.reversed { (cpr - raw) % cpr } else { raw };
        let turns = ((corrected * a.pole_pairs) % cpr) as f32 / cpr as f32;
        // The middle of the count (`encoder_alignment`: a count n stands for [n, n + 1) in the
        // counter's own direction, and the reversed counter's corrected count is its interval's
        // upper end): the rotor lies within half a count of it. A frame that follows the rotor
        // on a count's end sits up to a count behind or ahead of it, always the same way: its
        // d current pulls the rotor over that end, where the frame steps a count on, and on
        // little friction the rotor runs as a stepper motor does (30 electrical turns for a
        // 12-pole-pair rotor on 1 024 counts, 0.65 % friction, over the d chips and the step).
        // Every frame the sequence reads from the encoder takes it (the d chips, the current
        // step, the q stage's held and turned frames, the holds read again, the passes' lag).
        let half = if a.reversed { -0.5 } else { 0.5 };
        TAU * (turns + half * a.pole_pairs as f32 / cpr as f32) + a.offset
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
        // The currents less the sensors' offsets (`sensor_noise`; none while they are read). The
        // trip above takes the readings as they are: a few milliamps of offset beside its level.
        let [offset_a, offset_b] = self.sensor_offsets;
        let (ia, ib) = (ia - offset_a, ib - offset_b);
        let ic = -(ia + ib);
        let start = *self.start_count.get_or_insert(i.encoder_count);
        let relative = i.encoder_count.wrapping_sub(start);
        self.ticks += 1;
        let s = self.settings;
        // The current in the frame of the vector's angle: on the q-axis stage, the rotor's
        // angle where the stage began (held there: a frame that followed the rotor's small
        // swings would turn the held d current into the measured q current), unless the stage
        // turns the rotor (`turning_bias`): then the rotor's, read each tick.
        // The d-axis chips run on the rotor's own frame, read from the encoder each tick at the
        // middle of its count (`rotor_angle`): a rotor that drifts or swings (a load on a soft
        // shaft, no friction) then takes no torque from the d current. The current step's
        // frame starts on the rotor and follows it [`STEP_FRAME_LAG_S`] behind: the swing the
        // q stage's held frame leaves (the chips push the rotor off it, and at the stage's end
        // it runs back through it) is braked rather than let run on.
        let lags = stage == Stage::CurrentStep;
        if lags || stage == Stage::InductanceD || (stage == Stage::InductanceQ && self.q_bias > 0.0) {
            if let Some(a) = self.alignment {
                let rotor = self.rotor_angle(&a, i.encoder_count);
                self.angle = if lags && self.ticks > 1 {
                    let lag = rotor - self.angle;
                    let lag = lag - TAU * libm::floorf(lag / TAU + 0.5);
                    let angle = self.angle + (s.tick_period / STEP_FRAME_LAG_S).min(1.0) * lag;
                    angle - TAU * libm::floorf(angle / TAU)
                } else {
                    rotor
                };
            }
        }
        let frame = self.angle;
        let (sin, cos) = sin_cos(frame);
        let current = park(clarke(ia, ib), sin, cos);
        let mut q_voltage = 0.0;
        match stage {
            Stage::SensorNoise => {
                self.sensor_noise.add(ia, ib);
                self.voltage = 0.0;
                if self.ticks >= self.ticks_of(SENSOR_NOISE_S) {
                    self.sensor_offsets = self.sensor_noise.offsets();
                    self.next_stage(Stage::Probe);
                }
            }
            Stage::Probe | Stage::ProbeFit => {
                let period = self.chips.period();
                self.peak = self.peak.max(current.d.abs());
                if stage == Stage::ProbeFit {
                    if let Some(previous) = self.last_current {
                        self.fit.add_with_dead_time(previous, current.d, self.applied_chip, self.dead_time_shape);
                    }
                    self.q_fit.add(current.d, self.applied_chip);
                    self.probe_high_passed.add(current.d, self.applied_chip);
                    self.last_current = Some(current.d);
                    // Per volt of dead time (its size is not known yet: the fit finds it), for
                    // the phase currents' signs at the next tick's start.
                    self.dead_time_shape = dead_time_per_volt([ia, ib, ic], frame).d;
                    if self.ticks >= PROBE_FIT_PERIODS * period {
                        // A free rotor's fit gives the rotor's mechanical time constant as the
                        // chips saw it beside the winding.
                        let free_rotor = |fit: &FreeRotorFit| {
                            let branch = fit.branch(s.tick_period)?;
                            branch.winding.in_range().then_some((branch.winding, Some(branch.time_constant)))
                        };
                        let without_rotor = |w: Winding| (w, None);
                        // The fits in turn: the free rotor's, the first-order one, and where a
                        // light rotor on a strong magnet sticks and slips under the chips so
                        // that neither finds a winding, the free rotor's high-passed; last, on
                        // a winding settling within the tick whose pole none tells from the
                        // dead time's flips, its gain and a third of a tick. The loop closed on
                        // it needs the inductance roughly; the stages after it measure the
                        // winding.
                        let found = free_rotor(&self.q_fit)
                            .or_else(|| self.fit.winding(s.tick_period).map(without_rotor))
                            .or_else(|| free_rotor(&self.probe_high_passed))
                            .or_else(|| {
                                self.fit.settled_within_tick(s.tick_period).filter(Winding::in_range).map(without_rotor)
                            });
                        let Some((w, time_constant)) = found else {
                            if self.probe_retried {
                                return self.fail(CommissioningFault::Inductance { axis: 'd' });
                            }
                            // Once more on the axis a quarter turn on (the probe's stage again),
                            // the chips an eighth of their size to grow from: the rotor's motion
                            // held their current down on the first axis, by up to eight times
                            // on the drawn motors. No voltage this tick: the last chip, at its
                            // full size, would meet the winding alone on the new axis.
                            self.probe_retried = true;
                            self.angle = PROBE_RETRY_AXIS;
                            self.chip_size *= PROBE_RETRY_SHRINK;
                            (self.voltage, self.last_chip) = (0.0, 0.0);
                            self.peak = 0.0;
                            self.next_stage(Stage::Probe);
                            return self.output(i.bus_voltage, 0.0);
                        };
                        if !w.in_range() {
                            return self.fail(CommissioningFault::OutOfRange {
                                quantity: MeasuredQuantity::Winding,
                                value: w.resistance,
                            });
                        }
                        (self.probe_inductance, self.probe_resistance) = (w.inductance, w.resistance);
                        // A light rotor: the chips turned it, as far as a retry (on the first
                        // axis) or a short time constant (`sin²` of its angle from this one
                        // lengthens it) shows.
                        self.light_rotor =
                            self.probe_retried || time_constant.is_some_and(|seconds| seconds < LIGHT_ROTOR_S);
                        // Within what the voltage allows on this winding, with room for the
                        // loop to act.
                        self.test_current = s.test_current.min(0.7 * s.max_voltage / w.resistance);
                        // The probe's resistance is rough (a rotor that jitters on the chips,
                        // sticking on its friction at each reversal, reads as several times
                        // the winding's): the loop's integral corner, `R/L` in its design, is
                        // kept to a third of its bandwidth, where an overestimate cannot make
                        // it unstable. The holds measure the resistance the passes use.
                        let corner = TAU * s.current_bandwidth_hz / 3.0;
                        self.start_current_loop(w.resistance.min(corner * w.inductance), w.inductance, 0.0);
                        self.next_stage(Stage::Ramp);
                    }
                } else if self.ticks.is_multiple_of(period) {
                    // A whole period under the share: larger chips, up to the highest voltage;
                    // there, the fit's periods. At the highest voltage a current the sensors
                    // can read (a high resistance, a long time constant) is fitted as it is;
                    // none at all is an open phase.
                    let at_most = self.chip_size >= s.max_voltage;
                    if self.peak < PROBE_SHARE * s.test_current && !at_most {
                        // The winding answers in proportion (the chips repeat every period):
                        // while its current would stay under the floor an open phase is told by
                        // (lost in the sensors' offset and noise), the chips take two of the
                        // ladder's steps at once; from there one step a period, the sizes on
                        // the ladder, so the probe ends on the chips it would have ended on.
                        let aim = PROBE_FLOOR * s.test_current;
                        let mut peak = self.peak * PROBE_GROWTH;
                        self.chip_size = (self.chip_size * PROBE_GROWTH).min(s.max_voltage);
                        for _ in 1..PROBE_MAX_STEPS {
                            peak *= PROBE_GROWTH;
                            if !(peak < aim) {
                                break;
                            }
                            self.chip_size = (self.chip_size * PROBE_GROWTH).min(s.max_voltage);
                        }
                    } else if self.peak < PROBE_FLOOR * s.test_current {
                        return self.fail(CommissioningFault::OpenPhase { amps: self.peak });
                    } else {
                        self.fit = WindingFit::default();
                        self.q_fit = FreeRotorFit::default();
                        self.probe_high_passed = FreeRotorFit::high_passed();
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
                let x = share.min(1.0);
                let (angle, current_share) = if self.light_rotor { light_ramp(x) } else { ramp(x) };
                self.voltage = self.current_pi.d(self.test_current * current_share - current.d);
                // The frame's turn (rad per tick, the last tick's) puts `ω·L·i_d` on the q
                // voltage beside the rotor's back-EMF.
                let turning = self.speed / s.tick_period * self.probe_inductance * current.d;
                let damping = self.swing.reference(current.q, turning, s.tick_period);
                // The damping grows with the current's square (the spring's energy): at a
                // small current its full share would hold a rotor on a strong magnet creeping
                // far behind the turning vector, to break free later at a larger current.
                q_voltage = self.current_pi.q(damping * current_share * current_share - current.q);
                self.speed = angle - self.angle;
                self.angle = angle;
                if share >= 1.0 {
                    (self.angle, self.speed) = (0.0, 0.0);
                    self.next_stage(Stage::HoldHigh);
                }
            }
            Stage::HoldHigh | Stage::HoldLow => {
                let (hold, averaged) = (self.ticks_of(HOLD_S), self.ticks_of(AVERAGED_S));
                // The swing damped until shortly before the first hold's settling ends
                // (`swing_damping`): a rotor creeping under a damping far beyond critical takes
                // the rest of its way at once, before the wait for a still rotor; the wait and
                // the averaging run undamped.
                let damping = self.swing.reference(current.q, 0.0, s.tick_period);
                let damped = stage == Stage::HoldHigh && self.ticks + self.ticks_of(RELEASE_S) < hold - averaged;
                // A rotor that swings back through the vector (a heavy rotor on a weak magnet
                // with little friction, whose winding damps it far under critical) is damped
                // until the wait sees it still, and more strongly where it swings back under
                // the damping (`SwingDamping::raise`); one that creeps to the vector is
                // released as above, and damped again as the winding damps it where it then
                // swings back.
                let waiting = stage == Stage::HoldHigh && self.ticks <= hold - averaged;
                if waiting {
                    self.swing.observe(i.encoder_count, damped || self.swing.reversed());
                }
                if damped {
                    // At the full current only (a weakened hold's is not the holds').
                    if self.held_share == 1.0 {
                        self.swing_hold.0 += self.voltage;
                        self.swing_hold.1 += current.d;
                    }
                } else if waiting {
                    // The swing reversed under the winding's damping: raised from here on.
                    let hold_resistance = self.swing_hold.0 / self.swing_hold.1;
                    self.swing.raise(self.probe_resistance, hold_resistance);
                }
                let swinging = waiting && self.swing.reversed();
                q_voltage = self.current_pi.q(if damped || swinging { damping } else { 0.0 } - current.q);
                // A swing that reversed is also damped by the held current's strength: weakened
                // from each turning point to the swing's centre (`spring_weakening`).
                if waiting {
                    self.weakening.observe(i.encoder_count);
                }
                let late = self.waited + self.ticks_of(STRONG_END_S) >= self.ticks_of(STILL_WAIT_S);
                let weakened = swinging && !late && self.weakening.weakened();
                // The share ramped: a step, beside the q damping's current, would take the
                // current loop's overshoot over the test current.
                let aim = if weakened { self.weakening.share() } else { 1.0 };
                let most_step = s.tick_period / SHARE_RAMP_S;
                self.held_share += crate::limit(aim - self.held_share, -most_step, most_step);
                let share = self.held_share;
                let target = if stage == Stage::HoldHigh { share * self.test_current } else { 0.5 * self.test_current };
                let voltage = self.current_pi.d(target - current.d);
                // The back-EMF of a rotor still swinging on the vector would bias the voltage:
                // the first hold waits for it to stop before it averages (a rotor that stands
                // on a weakened hold is not yet at rest).
                self.count_still(i.encoder_count);
                if self.held_share < 1.0 {
                    self.still_ticks = 0;
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
                    let window = &mut self.hold_windows[(stage == Stage::HoldLow) as usize];
                    window.first.get_or_insert(i.encoder_count);
                    window.last = i.encoder_count;
                    window.phases[0] += ia;
                    window.phases[1] += ib;
                }
                self.voltage = voltage;
                if self.ticks >= hold {
                    let (mean_i, mean_v) = (self.sum / averaged as f32, self.voltage_sum / averaged as f32);
                    let window = &mut self.hold_windows[(stage == Stage::HoldLow) as usize];
                    (window.voltage, window.current, window.seconds) =
                        (mean_v, mean_i, averaged as f32 * s.tick_period);
                    // The vector lies on phase a: b and c carry half of a's current each (on
                    // the window's means: the sensors' noise of single samples is not a phase).
                    let (ma, mb) = (window.phases[0] / averaged as f32, window.phases[1] / averaged as f32);
                    let mc = -(ma + mb);
                    if (mb - mc).abs() > 0.25 * ma.abs() + 0.05 * self.test_current {
                        return self.fail(CommissioningFault::PhaseImbalance);
                    }
                    if stage == Stage::HoldHigh {
                        self.high = (mean_v, mean_i);
                        self.held = mean_v;
                        self.next_stage(Stage::HoldLow);
                    } else {
                        self.held_low = mean_v;
                        let (dv, di) = (self.high.0 - mean_v, self.high.1 - mean_i);
                        let r = dv / di;
                        if !resistance_in_range(r) {
                            return self.fail(CommissioningFault::OutOfRange {
                                quantity: MeasuredQuantity::Resistance,
                                value: r,
                            });
                        }
                        self.resistance = r;
                        self.dead_time = dead_time_of_hold(self.high.0 - r * self.high.1, s.max_voltage);
                        self.start_alignment();
                    }
                }
            }
            Stage::Forward | Stage::Backward => {
                // The test current on the vector's d axis, none on its q axis: the turning
                // rotor's back-EMF is the loop's to reject, not the current's to follow.
                // The inverter's dead-time voltage fed forward: the loop then has no steps of it
                // to follow as the phase currents change sign, whose lag, opposite on the two
                // passes, would bias the back-EMF.
                let compensation = self.dead_time_compensation(self.angle);
                let vd = self.current_pi.d(self.test_current - current.d);
                q_voltage = self.current_pi.q(-current.q) + compensation.q;
                self.voltage = vd + compensation.d;
                // A trapezoid of speed: the rotor's lag is the same on both passes only at the
                // full speed, so only those ticks are fitted (the swing that starting and
                // stopping excite would bias the intercepts).
                let full = TAU * s.alignment_speed * s.tick_period;
                let accel = full / self.ticks_of(ALIGNMENT_ACCELERATION_S) as f32;
                let end = TAU * s.alignment_turns;
                let remaining = end - self.travelled;
                let braking = libm::sqrtf(2.0 * accel * remaining.max(0.0));
                // The last ticks' crawl at least a few of the turn's f32 steps (a fast tick's
                // acceleration per tick, 1e-8 rad at 64 kHz, would add nothing to the angle
                // turned and the pass would never end).
                let crawl = accel.max(4.0 * f32::EPSILON * end);
                self.speed = (self.speed + accel).min(full).min(braking).max(crawl.min(remaining));
                let at_full_speed = self.speed == full;
                self.travelled += self.speed;
                let done = self.travelled >= end;
                // The voltage asked for now is applied over the next tick but one's reading:
                // placed half a tick's turn ahead of the vector's next angle, it sits where the
                // vector is in the middle of that tick (else it lags it by `ω·T/2`, which the
                // loop makes up with a q voltage of `v_d·ω·T/2` of the pass's sign).
                self.advance = if done {
                    0.0
                } else if stage == Stage::Forward {
                    0.5 * self.speed
                } else {
                    -0.5 * self.speed
                };
                if at_full_speed {
                    self.back_emf[(stage == Stage::Backward) as usize].add(
                        q_voltage,
                        current,
                        self.angle,
                        i.encoder_count,
                    );
                }
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
                        self.start_chips(Stage::InductanceD, 0.0);
                    }
                }
            }
            Stage::InductanceD | Stage::InductanceQ => {
                let axis_current = if stage == Stage::InductanceD { current.d } else { current.q };
                // The fit's model holds through the transient of the chips' start: a few ticks
                // only, for the delayed voltage's bookkeeping.
                let turning = stage == Stage::InductanceQ && self.q_bias > 0.0;
                let settling = self.chip_settling_ticks(turning);
                // The q current turns the rotor: its fit takes the rotor's back-EMF
                // (`free_rotor_fit`); the d current makes no torque on the rotor it is
                // aligned with.
                // The voltage the winding had over the tick just read: the chip asked for, short
                // of the inverter's dead-time voltage for the phase currents' signs at that
                // tick's start (the chips swing some phase currents through zero, where it
                // flips; its constant part goes to the fits' intercepts).
                let applied = self.applied_chip - self.dead_time_along_axis;
                let chips_end = settling + self.chips.period();
                if self.ticks > settling && self.ticks <= chips_end {
                    if stage == Stage::InductanceQ {
                        self.q_fit.add(axis_current, applied);
                        if !self.slow_q_winding() {
                            self.q_fit_twice.add(axis_current, applied);
                        }
                    }
                    if let Some(previous) = self.last_current {
                        // What the holds' dead time leaves (a winding faster than a tick flips
                        // it within the tick), fitted beside the winding: first on the d axis
                        // (`d_winding`), where the first-order fit alone fails on the q axis.
                        self.fit.add_with_dead_time(previous, axis_current, applied, self.dead_time_shape);
                    }
                }
                let unit = dead_time_per_volt([ia, ib, ic], frame);
                self.dead_time_shape = if stage == Stage::InductanceD { unit.d } else { unit.q };
                self.dead_time_along_axis = self.dead_time * self.dead_time_shape;
                self.last_current = Some(axis_current);
                if self.ticks >= chips_end
                    && stage == Stage::InductanceQ
                    && self.finishing == 0
                    && !self.q_may_turn()
                    && self.noise_matching.is_none_or(|m| m.result().is_none())
                {
                    // A slow q winding's noise matching, one fit's solve a tick (the winding's
                    // choice on the tick after the last): the d current held, no q voltage.
                    let tick = s.tick_period;
                    let (sensor_noise, angle) = (&self.sensor_noise, self.angle);
                    let matching =
                        self.noise_matching.get_or_insert_with(|| NoiseMatching::new(sensor_noise.q_variance(angle)));
                    let fit = &self.q_fit;
                    matching.advance(|v| fit.branch_less_noise(tick, v).map(|b| b.winding), self.resistance);
                    return self.hold_between(stage, current.q, i.bus_voltage);
                }
                if self.ticks >= chips_end {
                    // The stage's end, its work spread over ticks (a few fits' solves a tick at
                    // most, on the Cortex-M4F a few thousand instructions): the winding's
                    // choice; then on the d axis the holds read again, on the q axis the flux
                    // linkage, the resistance and the current loop's design, one a tick, the d
                    // current held meanwhile.
                    let finishing = self.finishing;
                    self.finishing += 1;
                    match (stage, finishing) {
                        (_, 0) => {
                            if let Err(fault) = self.choose_winding(stage, i.bus_voltage) {
                                return self.fail(fault);
                            }
                            return self.hold_between(stage, current.q, i.bus_voltage);
                        }
                        (Stage::InductanceD, _) => {
                            // (The q stage starts here, and this tick's output is still the d
                            // stage's: a d chip, the first of the q stage's sequence, whose
                            // sign the q stage's first chip is shaped against; within the room
                            // and the settling ticks.)
                            // The holds read again without the swing's back-EMF, for the q
                            // stage's dead time and resistance (the flux linkage the passes
                            // give with `L_q = L_d`; where that or the resistance is not found,
                            // the holds' stand, and the q stage's end reports it).
                            if let Ok((r, dead_time)) =
                                self.flux_with(self.ld).and_then(|psi| self.holds_without_swing(psi))
                            {
                                (self.resistance, self.dead_time) = (r, dead_time);
                            }
                            self.start_chips(Stage::InductanceQ, 0.0);
                        }
                        (_, 1) => {
                            match self.flux_from_back_emf() {
                                Ok(psi) => self.flux_linkage = psi,
                                Err(fault) => return self.fail(fault),
                            }
                            return self.hold_between(stage, current.q, i.bus_voltage);
                        }
                        (_, 2) => {
                            match self.resistance_without_swing() {
                                Ok(r) => self.resistance = r,
                                Err(fault) => return self.fail(fault),
                            }
                            return self.hold_between(stage, current.q, i.bus_voltage);
                        }
                        _ => {
                            self.start_current_step();
                            return self.output(i.bus_voltage, 0.0);
                        }
                    }
                }
                // A slow winding's q chips shaped (`q_shaping`), chosen on the stage's first
                // chip.
                let shaped = stage == Stage::InductanceQ && self.q_bias == 0.0 && self.slow_q_winding();
                if shaped && self.q_shaping.is_none() {
                    self.q_shaping = Some(self.q_shaping(i.bus_voltage));
                }
                let volts = self.chip_volts(stage, i.bus_voltage);
                let sign = self.chips.next_chip() as f32;
                let shaping = if shaped { self.q_shaping.unwrap_or(0.0) } else { 0.0 };
                let chip = volts * (sign - shaping * self.last_sign);
                self.last_sign = sign;
                // The q stage's constant voltage, ramped from 0 over its settling while the
                // rotor's acceleration (its current: the voltage's over `R` times the rotor's
                // mechanical time constant over the ramp) stays within its share; a heavy rotor
                // takes longer, whose speed swings little under the chips.
                let bias = if turning {
                    let smoothing = s.tick_period / Q_BIAS_SMOOTHING_S;
                    self.q_lowpass += smoothing.min(1.0) * (current.q - self.q_lowpass);
                    if libm::fabsf(self.q_lowpass) < Q_BIAS_CURRENT * self.test_current {
                        self.bias_now = (self.bias_now + self.q_bias / settling as f32).min(self.q_bias);
                    }
                    self.bias_now
                } else {
                    0.0
                };
                self.applied_chip = self.last_chip;
                self.last_chip = bias + chip;
                if stage == Stage::InductanceD {
                    self.voltage = self.held_low + chip;
                    // The q current held at zero: the rotor, still swinging on the vector
                    // where the passes left it, would otherwise drive its back-EMF through the
                    // winding's resistance alone (on a strong magnet and a small resistance,
                    // more than the test current). Within nine tenths of the room the d
                    // voltage leaves, so that the vector is never scaled down under the fit.
                    let room = 0.9 * self.room_beside(i.bus_voltage, self.voltage);
                    q_voltage = self.current_pi.q.update(-current.q, room.min(self.current_pi.limit)).value;
                } else {
                    self.voltage = self.held_low;
                    q_voltage = bias + chip;
                }
            }
            Stage::CurrentStep => {
                let (hold, cycle) = (STEP_SAMPLES as u32, 4 * STEP_SAMPLES as u32);
                // The level this tick's reading answers: the ticks before the first step
                // settle the held d current.
                let t = self.ticks - 1;
                let held = 0.5 * self.test_current;
                let level = |t: u32| [0.0f32, 1.0, 0.0, -1.0][((t / hold) % 4) as usize];
                let (k, edge) = ((t % hold) as usize, t >= hold);
                if edge {
                    let (before, after) = (level(t - hold), level(t));
                    let size = (after - before) * self.step_size;
                    if size != 0.0 {
                        self.step.add(k, (current.d - (held + before * self.step_size)) / size);
                    }
                    if k == STEP_SAMPLES - 1 {
                        self.step.end_step();
                    }
                }
                if t + 1 >= hold + STEP_CYCLES * cycle {
                    self.search = Some(BandwidthSearch::new(s.current_bandwidth_hz, s.tick_period));
                    self.next_stage(Stage::StepAnalysis);
                    self.voltage = 0.0;
                    return self.output(i.bus_voltage, 0.0);
                }
                // The level's reference from its first tick on (its sample 0: the reading the
                // new reference first meets).
                let reference = level(t) * self.step_size;
                self.voltage = self.current_pi.d(held + reference - current.d);
                q_voltage = self.current_pi.q(-current.q);
            }
            Stage::StepAnalysis => {
                // No voltage while the search runs, one evaluation a tick.
                self.voltage = 0.0;
                let searching = self.result.is_none();
                let found = self
                    .search
                    .as_mut()
                    .filter(|_| searching)
                    .and_then(|search| search.step(&self.step, s.tick_period));
                match found {
                    None => {}
                    Some(Err(())) => {
                        let overshoot = self.step.overshoot();
                        return self.fail(CommissioningFault::CurrentLoop { bandwidth_hz: f32::NAN, overshoot });
                    }
                    Some(Ok(bandwidth_hz)) => {
                        let overshoot = self.step.overshoot();
                        // A loop far from its design (an overshoot of half the step: the
                        // winding is not what was measured) fails; one within reach of it is
                        // kept and reported (`StepCheck`: the host holds it to the target).
                        if !(overshoot <= STEP_OVERSHOOT_LIMIT) {
                            return self.fail(CommissioningFault::CurrentLoop { bandwidth_hz, overshoot });
                        }
                        let alignment = self.alignment.unwrap_or(Alignment {
                            pole_pairs: 1,
                            reversed: false,
                            offset: 0.0,
                            lag: 0.0,
                        });
                        self.still_ticks = 0;
                        self.last_count = i.encoder_count;
                        self.waited = 0;
                        self.result = Some(MeasuredMotor {
                            resistance: self.resistance,
                            ld: self.ld,
                            lq: self.lq,
                            flux_linkage: self.flux_linkage,
                            alignment,
                            current_kp: self.designed.0,
                            current_ki: self.designed.1,
                            current_step: StepCheck { bandwidth_hz, overshoot },
                            test_current: self.test_current,
                        });
                    }
                }
                // Found: the winding shorted (no voltage) brakes what the chips left of the
                // rotor's motion (a machine without friction would drift on), until the
                // encoder is still or for at most a second.
                if let Some(measured) = self.result {
                    self.count_still(i.encoder_count);
                    self.waited += 1;
                    if self.still_ticks >= self.ticks_of(STILL_S) || self.waited >= self.ticks_of(STILL_WAIT_S) {
                        self.status = CommissioningStatus::Done(measured);
                        return None;
                    }
                }
            }
        }
        // The q voltage the bridge will apply (scaled as `output` scales it).
        self.swing.asked(q_voltage * self.output_scale(i.bus_voltage, q_voltage));
        self.output(i.bus_voltage, q_voltage)
    }

    /// The vector for the next tick, `self.voltage` on its d axis and `q_voltage` on its q
    /// axis: on the fixed angle until aligned, then the rotor's. Within the highest voltage
    /// and the bus's circle, the direction kept.
    fn output(&self, bus_voltage: f32, q_voltage: f32) -> Option<AlphaBeta> {
        let scale = self.output_scale(bus_voltage, q_voltage);
        let (sin, cos) = sin_cos(self.angle + self.advance);
        Some(inverse_park(Dq { d: self.voltage * scale, q: q_voltage * scale }, sin, cos))
    }

    /// What `output` scales the vector by to keep it within the highest voltage and the bus's
    /// circle.
    fn output_scale(&self, bus_voltage: f32, q_voltage: f32) -> f32 {
        let limit = self.voltage_limit(bus_voltage);
        let magnitude = libm::sqrtf(self.voltage * self.voltage + q_voltage * q_voltage);
        if magnitude > limit {
            limit / magnitude
        } else {
            1.0
        }
    }

    /// The largest vector `output` applies unscaled (V): the highest voltage, within the bus's
    /// circle.
    fn voltage_limit(&self, bus_voltage: f32) -> f32 {
        self.settings.max_voltage.min(crate::reference_frames::voltage_circle_radius(bus_voltage))
    }

    /// The q voltage the limit leaves beside a d voltage of `d` (V).
    fn room_beside(&self, bus_voltage: f32, d: f32) -> f32 {
        let limit = self.voltage_limit(bus_voltage);
        libm::sqrtf((limit * limit - d * d).max(0.0))
    }

    /// Nine tenths of the room beside the held d voltage (V): what the q stage's chips and
    /// the ticks between the inductance stages take on the q axis, the vector never scaled
    /// down.
    fn room_beside_held(&self, bus_voltage: f32) -> f32 {
        0.9 * self.room_beside(bus_voltage, self.held_low)
    }

    /// The vector's turn under a current loop designed from the resistance and the probe's
    /// inductance (`start_current_loop`), its integrators starting from the held voltage.
    fn start_alignment(&mut self) {
        let compensation = self.dead_time_compensation(0.0);
        // From the low hold's voltage (the one applied now): the loop's own step to the test
        // current, without the kick a preset for the test current would add to it.
        self.start_current_loop(self.resistance, self.probe_inductance, self.held_low - compensation.d);
        self.voltage = self.held_low;
        self.travelled = 0.0;
        self.speed = 0.0;
        self.forward = Pass::new(0.0);
        self.next_stage(Stage::Forward);
    }

    /// A current loop for a winding of `resistance` and `inductance` at the stated bandwidth
    /// (`current_loop_design`); its d integrator from `held` (V).
    fn start_current_loop(&mut self, resistance: f32, inductance: f32, held: f32) {
        let s = &self.settings;
        let (kp, ki) = current_loop_design::design(resistance, inductance, s.tick_period, s.current_bandwidth_hz);
        let gains = PiGains { kp, ki, period: s.tick_period };
        let (mut d, q) = (PiController::new(gains), PiController::new(gains));
        d.preset(held);
        self.current_pi = DqPi { d, q, limit: s.max_voltage };
        self.swing =
            SwingDamping::new(resistance, inductance, self.test_current, s.current_bandwidth_hz, s.tick_period);
    }

    /// The resistance again from the holds, without the back-EMF of a rotor that still swung
    /// on the vector while they were averaged (`holds_without_swing`, the flux linkage
    /// measured).
    fn resistance_without_swing(&self) -> Result<f32, CommissioningFault> {
        self.holds_without_swing(self.flux_linkage).map(|(r, _)| r)
    }

    /// The resistance (Ω) and the inverter's dead-time voltage (V) from the holds, without the
    /// back-EMF of a rotor that still swung on the vector while they were averaged, for a flux
    /// linkage `psi`: on the vector's d axis (angle 0) that back-EMF's mean over a window is
    /// `ψ·(cos θ_end − cos θ_start)/T`, the rotor's electrical angle `θ` at the window's ends
    /// now known from the encoder (a rotor at rest leaves the holds' values). A heavy rotor on
    /// a weak magnet swings for seconds on its vector at a few hertz; its back-EMF, a few
    /// percent of a small resistance's voltage, reads in the high hold's voltage beyond
    /// `R·I` as dead time (half as much again on a bench motor: the q fits of a winding
    /// faster than a tick then take a dead time the inverter does not have).
    fn holds_without_swing(&self, psi: f32) -> Result<(f32, f32), CommissioningFault> {
        let Some(a) = self.alignment else { return Ok((self.resistance, self.dead_time)) };
        let voltage = |w: &HoldWindow| {
            let first = w.first.unwrap_or(w.last);
            let change = sin_cos(self.rotor_angle(&a, w.last)).1 - sin_cos(self.rotor_angle(&a, first)).1;
            w.voltage - psi * change / w.seconds
        };
        let [high, low] = &self.hold_windows;
        let high_voltage = voltage(high);
        let r = (high_voltage - voltage(low)) / (high.current - low.current);
        if !resistance_in_range(r) {
            return Err(CommissioningFault::OutOfRange { quantity: MeasuredQuantity::Resistance, value: r });
        }
        Ok((r, dead_time_of_hold(high_voltage - r * high.current, self.settings.max_voltage)))
    }

    /// The voltage (vector's frame, V) that makes up the inverter's dead-time error for a
    /// current on the vector at `angle` (each phase short by `dead_time` against its current's
    /// sign; the common mode drops out).
    fn dead_time_compensation(&self, angle: f32) -> Dq {
        // cos(angle ∓ 2π/3) from one sine and cosine (f32 only: it runs every tick).
        let (sin, cos) = sin_cos(angle);
        let (half, root) = (0.5 * cos, 0.866_025_4 * sin);
        self.phase_dead_time([cos, root - half, -root - half], angle)
    }

    /// The inverter's dead-time voltage (what each phase falls short by against its current)
    /// for phase currents of the signs of `phases` (A), in the frame at `angle`.
    fn phase_dead_time(&self, phases: [f32; 3], angle: f32) -> Dq {
        let unit = dead_time_per_volt(phases, angle);
        Dq { d: self.dead_time * unit.d, q: self.dead_time * unit.q }
    }

    /// The flux linkage from the passes' q voltages (stage 4) and the inductances.
    fn flux_from_back_emf(&self) -> Result<f32, CommissioningFault> {
        self.flux_with(self.lq)
    }

    /// The flux linkage from the passes' q voltages with a q-axis inductance of `lq`.
    fn flux_with(&self, lq: f32) -> Result<f32, CommissioningFault> {
        let Some(a) = self.alignment else {
            return Err(CommissioningFault::OutOfRange { quantity: MeasuredQuantity::FluxLinkage, value: f32::NAN });
        };
        let s = &self.settings;
        let omega = TAU * s.alignment_speed;
        let [f, b] = self.back_emf.map(|p| p.means(s.tick_period));
        let current = 0.5 * (f.1 + b.1);
        // The q current the loop leaves (its mean over a window, about 0) takes its resistive
        // voltage from the q voltage.
        let r = self.resistance;
        let (f_voltage, b_voltage) = (f.0 - r * f.2, b.0 - r * b.2);
        let (sin, cos) = sin_cos(a.lag);
        // In the vector's frame the magnet's flux is `ψ·e^{−jδ}`, the rotor lagging by `δ`:
        // its q voltage is `ψ·(ω − dδ/dt)·cos δ`, whose mean over a window is `ψ·(ω·cos δ −
        // Δsin δ/T)`. The rotor swings on the vector (a spring of the magnet's torque), so the
        // lag's change over each window counts, and so does the swing's own share of cos δ
        // (of second order: below).
        let swing = |p: &BackEmf, window: f32| {
            let lag_at = |(angle, count): (f32, i32)| angle - self.rotor_angle(&a, count);
            let first = p.first.unwrap_or(p.last);
            (crate::trigonometry::sin(lag_at(p.last)) - crate::trigonometry::sin(lag_at(first))) / window
        };
        let (swing_f, swing_b) = (swing(&self.back_emf[0], f.3), swing(&self.back_emf[1], b.3));
        // The armature's flux along the current, and what the tick's sampling adds: the loop
        // holds the current at the ticks, and within a tick the voltage, held in the stator,
        // turns against the rotor, which the windings follow (`sampled_winding_excess`). On a
        // rotor lagging by `δ` that share splits on the rotor's own axes, each winding with
        // its own time constant: `sin²δ` of it on d, `cos²δ` on q.
        let along = self.ld * cos * cos + lq * sin * sin;
        let excess = |l: f32| l * sampled_winding_excess(r * s.tick_period / (2.0 * l));
        let sampled = sin * sin * excess(self.ld) + cos * cos * excess(lq);
        let inductive = 2.0 * omega * current * (along + sampled);
        // The swing about the lag (its variance `v` from the counts' scatter about each pass's
        // line of the exact counts per radian) takes the mean of `cos δ` under `cos` of the
        // mean lag: `cos δ·(1 − v/2 + v²/16)` (the last term a sine's). A heavy rotor on a
        // weak magnet, whose swing at the test current is slow (4 Hz), keeps much of what the
        // pass's start excites: ±0.46 rad over a forward pass gives a flux linkage 3.7 % low
        // without this.
        let counts_per_radian = a.counts_per_radian(s.counts_per_rev);
        let radians_per_count = 1.0 / counts_per_radian;
        let mean_cos = |p: &Pass| {
            let v = (p.scatter_about(counts_per_radian) * radians_per_count * radians_per_count).min(0.5);
            1.0 - 0.5 * v + v * v / 16.0
        };
        let swept = mean_cos(&self.forward) + mean_cos(&self.backward);
        let psi = (f_voltage - b_voltage - inductive) / (omega * cos * swept - swing_f + swing_b);
        if !(psi > 1e-4 && psi < 10.0) {
            return Err(CommissioningFault::OutOfRange { quantity: MeasuredQuantity::FluxLinkage, value: psi });
        }
        Ok(psi)
    }

    /// The drive's current loop designed from the resistance and the q-axis inductance; its
    /// check's, from the d-axis inductance, on the rotor's d axis (the q-axis stage's frame),
    /// its d integrator from the held voltage; the d step's size within what the voltage
    /// leaves beside the held d voltage.
    fn start_current_step(&mut self) {
        let s = self.settings;
        let bandwidth = s.current_bandwidth_hz;
        self.designed = current_loop_design::design(self.resistance, self.lq, s.tick_period, bandwidth);
        let (kp, ki) = current_loop_design::design(self.resistance, self.ld, s.tick_period, bandwidth);
        let gains = PiGains { kp, ki, period: s.tick_period };
        let (mut d, q) = (PiController::new(gains), PiController::new(gains));
        d.preset(self.held_low);
        self.current_pi = DqPi { d, q, limit: s.max_voltage };
        // The first tick's voltage of a step is `(kp + ki·T)·size`: within half what the held
        // voltage leaves.
        let room = s.max_voltage - self.held_low.abs();
        self.step_size = (0.25 * self.test_current).min(0.5 * room.max(0.0) / (kp + ki * s.tick_period));
        // No room beside the held voltage (or gains that are not numbers): a step of 0 would
        // measure nothing; the analysis then finds no bandwidth and the sequence fails.
        if !(self.step_size > 0.0) {
            self.step_size = 0.0;
        }
        self.step = StepResponse::default();
        self.voltage = self.held_low;
        self.next_stage(Stage::CurrentStep);
    }

    /// The winding an inductance stage's fits give once its chips have ended: on the d axis
    /// `d_winding`, on the q axis `q_winding`, where a first run that found none (or one whose
    /// resistance the rotor's motion bends) starts the stage again with the rotor turned
    /// through the chips (`turning_bias`), and a second keeps the run whose resistance agrees
    /// with the holds'. Kept as `ld` or `lq`; refused by name where there is none or it lies
    /// outside the part's range.
    fn choose_winding(&mut self, stage: Stage, bus_voltage: f32) -> Result<(), CommissioningFault> {
        let tick = self.settings.tick_period;
        let axis = if stage == Stage::InductanceD { 'd' } else { 'q' };
        let first_order = if stage == Stage::InductanceD { self.d_winding() } else { self.fit.winding(tick) };
        let (mut fitted, disagree) =
            if stage == Stage::InductanceQ { self.q_winding(first_order) } else { (first_order, false) };
        if stage == Stage::InductanceQ {
            let off = self.resistance_off(&fitted);
            if self.q_bias == 0.0 {
                // No winding, or one whose resistance the rotor's motion bends, or fits its
                // motion bends apart, under chips that the rotor may reverse with: once more
                // with the rotor turned through them, where it can be (`turning_bias`).
                let bias = if off >= Q_RETRY_AGREEMENT || disagree { self.turning_bias(bus_voltage) } else { 0.0 };
                if bias > 0.0 {
                    self.first_q = fitted;
                    self.q_fits_disagreed = disagree && off < Q_RETRY_AGREEMENT;
                    self.start_chips(Stage::InductanceQ, bias);
                    return Ok(());
                }
            } else if (!self.q_fits_disagreed || off >= Q_RETRY_AGREEMENT) && self.resistance_off(&self.first_q) < off {
                // Of the two runs, the one whose resistance agrees with the holds'; where the
                // first run's fits disagreed, the turned run's where its resistance agrees
                // within `Q_RETRY_AGREEMENT`.
                fitted = self.first_q;
            }
        }
        let Some(w) = fitted else {
            return Err(CommissioningFault::Inductance { axis });
        };
        if !inductance_in_range(w.inductance) {
            return Err(CommissioningFault::OutOfRange { quantity: MeasuredQuantity::Inductance, value: w.inductance });
        }
        if stage == Stage::InductanceD {
            self.ld = w.inductance;
        } else {
            self.lq = w.inductance;
        }
        Ok(())
    }

    /// A tick between an inductance stage's chips and what follows them: the held d voltage,
    /// and on the d stage its q loop holding the q current at zero (the rotor may still swing
    /// on the vector), on the q stage no q voltage.
    fn hold_between(&mut self, stage: Stage, q_current: f32, bus_voltage: f32) -> Option<AlphaBeta> {
        self.voltage = self.held_low;
        let q_voltage = if stage == Stage::InductanceD {
            let room = self.room_beside_held(bus_voltage);
            self.current_pi.q.update(-q_current, room.min(self.current_pi.limit)).value
        } else {
            0.0
        };
        self.output(bus_voltage, q_voltage)
    }

    /// The d winding from its stage's fit: the one with the inverter's dead-time voltage
    /// fitted beside it (`WindingFit::winding_with_dead_time`) where that finds a winding
    /// within the part's range settling within a tick (its pole under `1/e`), else the
    /// first-order one. The chips take the d current from about the test current to about
    /// none, and on a winding that settles within the tick it gets there: the sensors' noise
    /// then moves the phase currents across zero and the dead-time voltage flips with them,
    /// which the first-order fit reads as a pole a little too slow (its inductance a few
    /// percent high at a third of a tick). On a slower winding the d current keeps its sign,
    /// the dead-time regressor hardly varies, and the first-order fit is kept
    /// (`WindingFit::winding`).
    fn d_winding(&self) -> Option<Winding> {
        let tick = self.settings.tick_period;
        let settles_within_tick = |w: &Winding| w.in_range() && w.inductance < w.resistance * tick;
        self.fit.winding_with_dead_time(tick).filter(settles_within_tick).or_else(|| self.fit.winding(tick))
    }

    /// The chips' size on the measured axis of `stage` (V): around the voltage that holds half
    /// the test current. The resistive voltage of half the test current where the winding
    /// follows a chip within a few ticks (the current then swings between none and the test
    /// current and keeps its sign, so the inverter's error stays constant); up to sixteen
    /// times it on a slow winding, whose current moves by a small share of a chip (its random
    /// walk over the record, about `sqrt(T/2τ)` of the chip's current), so that the ripple
    /// stands above the sensors' noise: a swing of about a tenth of the test current either
    /// way. The resistive part of half the test current only (the held voltage also carries
    /// the inverter's dead-time voltage, which a chip's swing must not scale). The q chips of
    /// a slow winding: `q_chip_volts`; on a stage that turns the rotor, a third of its constant
    /// voltage (`turning_bias`).
    fn chip_volts(&self, stage: Stage, bus_voltage: f32) -> f32 {
        if stage == Stage::InductanceQ && self.q_bias > 0.0 {
            return self.q_bias / Q_BIAS_OVER_CHIP;
        }
        if stage == Stage::InductanceQ && self.slow_q_winding() {
            return self.q_chip_volts(bus_voltage);
        }
        let ticks_per_tau = self.probe_inductance / (self.resistance * self.settings.tick_period);
        let size = crate::limit(0.25 * libm::sqrtf(ticks_per_tau), 1.0, 16.0);
        size * 0.5 * self.resistance * self.test_current
    }

    /// A winding whose time constant (the d axis's, measured) is longer than a tick: the q
    /// chips are sized for the current's peak and fitted high-passed (`q_chip_volts`,
    /// `FreeRotorFit::high_passed`). A faster one keeps the chips and the fit the d axis has.
    fn slow_q_winding(&self) -> bool {
        self.ld > self.resistance * self.settings.tick_period
    }

    /// A winding of up to [`Q_TURNING_TICKS`] (the d axis's time constant, measured): its q
    /// stage may run once more turning the rotor (`turning_bias`).
    fn q_may_turn(&self) -> bool {
        !(self.ld > Q_TURNING_TICKS * self.resistance * self.settings.tick_period)
    }

    /// The q chips' size (V). Their current is zero-mean and makes torque, which a rotor's
    /// friction resists: the rotor then sticks and slips, which no linear fit follows, unless
    /// the chips' torque stands well above the friction's. So the chips are as large as the
    /// current allows, their peak [`Q_CHIP_PEAK`] of the test current beside the held d
    /// current (half of it): the current's random walk under ±V chips has a standard
    /// deviation of `V·(1 − a)/(R·√(1 − a²))` = `V·√tanh(RT/2L)/R` (`a = e^{−RT/L}`), and
    /// stays within 3.5 of them over a record, and within `V/R` whatever the record. Within
    /// nine tenths of the voltage the held d voltage leaves (the vector is never scaled down,
    /// which would scale the fitted chips with it).
    ///
    /// Shaped chips (`q_shaping`: each less `β` times the one before) swing the voltage by up
    /// to `(1 + β)·V`, which stays within that room.
    fn q_chip_volts(&self, bus_voltage: f32) -> f32 {
        let room = self.room_beside_held(bus_voltage);
        let shaping = self.q_shaping.unwrap_or(0.0);
        if shaping > 0.0 {
            return self.shaped_chip_volts(self.sampled_winding(), shaping, room);
        }
        let x = self.resistance * self.settings.tick_period / self.ld;
        let peak_per_volt = crate::limit(3.5 * libm::sqrtf(libm::tanhf(0.5 * x)), 0.0, 1.0) / self.resistance;
        (Q_CHIP_PEAK * self.test_current / peak_per_volt).min(room)
    }

    /// The chips' size (V) shaped by `shaping` (`β`) within `room` (V): the q current's peak
    /// [`Q_CHIP_PEAK`] of the test current. Under chips `V·(c[k] − β·c[k−1])` the sampled
    /// winding's current has the impulse response `b·(1, (a − β), (a − β)·a, …)` per volt
    /// (`a = e^{−RT/L}`, `b = (1 − a)/R`): a standard deviation of
    /// `b·√(1 + (a − β)²/(1 − a²))` per volt, within 3.5 of them over a record, and within
    /// `b·(1 + |a − β|/(1 − a))` whatever the record (`V/R` unshaped, `b·V` at `β = a`, where
    /// the current follows the chips themselves).
    fn shaped_chip_volts(&self, w: SampledWinding, shaping: f32, room: f32) -> f32 {
        let d = w.pole - shaping;
        let spread = crate::square_root::sqrt(1.0 + d * d / (w.decay * (1.0 + w.pole)));
        let peak_per_volt = (3.5 * w.gain * spread).min(w.gain * (1.0 + libm::fabsf(d) / w.decay));
        (Q_CHIP_PEAK * self.test_current / peak_per_volt).min(room / (1.0 + shaping))
    }

    /// The d winding sampled every tick: its pole `a = e^{−RT/L}`, `1 − a` (to f32's precision
    /// on a winding of millions of ticks) and its gain `b = (1 − a)/R`.
    fn sampled_winding(&self) -> SampledWinding {
        let decay = -libm::expm1f(-self.resistance * self.settings.tick_period / self.ld);
        SampledWinding { pole: 1.0 - decay, decay, gain: decay / self.resistance }
    }

    /// The q chips' shaping `β` on a winding slower than [`Q_SHAPED_TICKS`] (0 elsewhere):
    /// each chip less `β` times the one before. Unshaped ±V chips drive a slow winding's current
    /// on a random walk that the current's peak bounds: their voltage, and with it the current's
    /// change from tick to tick that the fit reads beside the sensors' noise, is a few times
    /// the winding's resistive voltage at the peak current. Shaping takes the chips' low
    /// frequencies down and leaves their high ones (at `β` = `a`, the winding's pole, the
    /// current follows the chips themselves, its random walk gone): for the same peak the
    /// chips may be many times larger, up to the room the held d voltage leaves. Of
    /// [`Q_SHAPINGS`] shapings from none to `a`, the chips' largest swing from tick to tick
    /// (`(1 + β)·V`) is found, and the least shaping whose swing lies within a ten-thousandth
    /// of it is taken: where the room limits the chips many reach it, and the least keeps the
    /// most of the chips' low frequencies, where the winding's resistance and the rotor's
    /// motion show.
    fn q_shaping(&self, bus_voltage: f32) -> f32 {
        let tick = self.settings.tick_period;
        if !(self.ld > Q_SHAPED_TICKS * self.resistance * tick) {
            return 0.0;
        }
        let room = self.room_beside_held(bus_voltage);
        let w = self.sampled_winding();
        // Once, on the stage's first chip: thirty-two sizes of a few tens of instructions each
        // on the Cortex-M4F (the square root its instruction).
        let shapings = (1..=Q_SHAPINGS).map(|k| w.pole * k as f32 / Q_SHAPINGS as f32);
        let swing = |shaping: f32| (1.0 + shaping) * self.shaped_chip_volts(w, shaping, room);
        let largest = shapings.clone().map(swing).fold(0.0f32, f32::max);
        shapings.clone().find(|&shaping| swing(shaping) >= (1.0 - 1e-4) * largest).unwrap_or(0.0)
    }

    /// The q winding from the fits of its stage (`first_order` the first-order fit's). The
    /// chips' torque turns the rotor, which may stick and slip on its friction at each
    /// reversal: no linear model follows that, and it acts at the low and middle frequencies
    /// of the chips' band. On a winding faster than a tick, whose current follows each chip
    /// within the tick, the free rotor's fit of the samples' second differences (each
    /// frequency weighed by `4·sin²(πfT)`, those bands least) is taken where the first-order
    /// fit's resistance is [`RESISTANCE_AGREEMENT`] or more off the holds' (the rotor's motion
    /// shows in the winding's response), the plain free-rotor fit finds a winding (where it
    /// finds none, no linear model follows this motor: the differences are not taken either)
    /// and the second differences' own resistance lies within [`DIFFERENCES_AGREEMENT`] of
    /// the holds'. Otherwise, and on slower windings (where the second differences would weigh
    /// the sensors' noise up beside the current's small changes from tick to tick), of the
    /// first-order fit and the free rotor's (`q_fit`: of the samples' differences on a slow
    /// winding), the one whose resistance agrees better with the holds' (the rotor's swing the
    /// first-order fit cannot take reads as extra resistance; on a slow winding that a few
    /// hertz of pull and friction hold, the free rotor's model is the one that errs); where
    /// neither resistance is plausible, the first-order fit's (`None`, or a winding the caller
    /// refuses as out of range). On a winding of more than [`Q_TURNING_TICKS`] the free
    /// rotor's fit has the sensors' noise taken out (`noise_matching`, one solve a tick once
    /// the chips have ended): where a variance in its range gives the holds' resistance, that
    /// fit agrees with the holds' by construction and is kept. On the run that turns the
    /// rotor through the chips (its friction a constant torque, which the free rotor's model
    /// holds), the free rotor's fit where its resistance lies within [`RESISTANCE_AGREEMENT`]
    /// of the holds' and at most [`TURNED_FREE_ROTOR_SHARE`] as far off as the second
    /// differences'; otherwise as above. Beside it, where the second differences' fit is
    /// taken on a winding whose q stage may turn the rotor, whether the free rotor's fit
    /// disagrees with it on the inductance by [`Q_FITS_AGREEMENT`] or more, both plausible (a
    /// rotor that sticks and slips on its friction bends each differently, where their
    /// resistances may still agree with the holds': Lq 6.6–8 % low on the bench's 15–36 µs
    /// rotors on 0.4–0.7-tick windings).
    fn q_winding(&self, first_order: Option<Winding>) -> (Option<Winding>, bool) {
        let tick = self.settings.tick_period;
        let off = |w: &Option<Winding>| self.resistance_off(w);
        // On a winding slower than the stage turns the rotor on (`Q_TURNING_TICKS`) the
        // high-passed fit's current changes are small beside the sensors' noise: its bias is
        // taken out (`sensor_noise`). That fit's resistance then agrees with the holds' by
        // construction, so the windings whose q stage may run once more, on the resistances'
        // agreement, keep the fit as it is.
        let free_rotor = if !self.q_may_turn() {
            self.noise_matching.and_then(|m| m.result()).flatten()
        } else {
            self.q_fit.winding(tick)
        };
        // Each fit solved once: three solves in the stage's last tick at most.
        let twice = if self.slow_q_winding() { None } else { self.q_fit_twice.winding(tick) };
        // Where the second differences' fit is the one taken (below), both it and the free
        // rotor's plausible windings.
        let disagree = self.q_may_turn()
            && match (free_rotor, twice) {
                (Some(a), Some(b)) if inductance_in_range(a.inductance) && inductance_in_range(b.inductance) => {
                    !(libm::fabsf(a.inductance / b.inductance - 1.0) < Q_FITS_AGREEMENT)
                }
                _ => false,
            };
        // On the run that turns the rotor, its friction a constant torque: the free rotor's
        // model holds, and its fit is taken where its resistance agrees with the holds' within
        // `RESISTANCE_AGREEMENT` and at most half as far off as the second differences'.
        if self.q_bias > 0.0 {
            let free = off(&free_rotor);
            if free < RESISTANCE_AGREEMENT && free < TURNED_FREE_ROTOR_SHARE * off(&twice) {
                return (free_rotor, false);
            }
        }
        if !self.slow_q_winding()
            && off(&first_order) >= RESISTANCE_AGREEMENT
            && off(&free_rotor).is_finite()
            && off(&twice) < DIFFERENCES_AGREEMENT
        {
            return (twice, disagree);
        }
        (if off(&free_rotor) < off(&first_order) { free_rotor } else { first_order }, false)
    }

    /// How far a fit's resistance lies off the holds' (a share; infinite for no winding or
    /// an implausible inductance).
    fn resistance_off(&self, w: &Option<Winding>) -> f32 {
        match w {
            Some(w) if inductance_in_range(w.inductance) => libm::fabsf(w.resistance / self.resistance - 1.0),
            _ => f32::INFINITY,
        }
    }

    /// An inductance stage from its start; a q stage with a constant voltage `q_bias` under
    /// its chips (V; 0: none) turns the rotor (`turning_bias`).
    fn start_chips(&mut self, stage: Stage, q_bias: f32) {
        self.chips = MSequence::new(CHIP_DEGREE).unwrap_or(MSequence::DEGREE_15);
        self.fit = WindingFit::default();
        self.q_fit = if stage == Stage::InductanceQ && self.slow_q_winding() {
            FreeRotorFit::high_passed()
        } else {
            FreeRotorFit::default()
        };
        self.q_fit_twice = FreeRotorFit::high_passed_twice();
        self.noise_matching = None;
        self.finishing = 0;
        self.q_shaping = None;
        self.last_sign = 0.0;
        if stage == Stage::InductanceD {
            // The d stage's q loop starts from nothing (its integrator held the passes'
            // back-EMF, in the vector's frame).
            self.current_pi.q.reset();
        }
        self.dead_time_along_axis = 0.0;
        self.dead_time_shape = 0.0;
        self.last_chip = 0.0;
        self.applied_chip = 0.0;
        self.last_current = None;
        self.voltage = self.held_low;
        self.q_bias = q_bias;
        self.bias_now = 0.0;
        self.q_lowpass = 0.0;
        self.next_stage(stage);
    }

    /// The constant q voltage under the q chips that keeps the rotor turning one way (V; 0:
    /// none). The chips' torque turns a light rotor on a strong magnet back and forth, and at
    /// each reversal its friction holds it, then lets it slip: no linear model follows that.
    /// Under a constant voltage [`Q_BIAS_OVER_CHIP`] times the chips' the rotor turns one way
    /// throughout (a rotor whose speed follows its voltage within a tick swings by at most
    /// the chips' voltage over the flux linkage), its friction a constant torque, and the
    /// chips see the winding and the free rotor's back-EMF alone; the frame follows the
    /// rotor (read from the encoder each tick). Only where the rotor then turns at most
    /// [`Q_TURNS`] electrical turns over the stage (the flux linkage the passes give with
    /// `L_q = L_d`, with the armature's `L_d·I/2` beside it) and the voltage leaves room for
    /// it beside the held d voltage and the chips; elsewhere the stage holds its frame and
    /// adds nothing (a weak magnet's rotor hardly moves under the chips).
    fn turning_bias(&self, bus_voltage: f32) -> f32 {
        if !self.q_may_turn() {
            return 0.0;
        }
        let Ok(psi) = self.flux_with(self.ld) else { return 0.0 };
        let s = &self.settings;
        let volts = self.chip_volts(Stage::InductanceQ, bus_voltage);
        let seconds = (self.chip_settling_ticks(true) + self.chips.period()) as f32 * s.tick_period;
        let flux = psi + 0.5 * self.ld * self.test_current;
        let turning = Q_TURNS * TAU * flux / seconds;
        // The voltage beside the held d voltage takes the constant and the chips.
        let room = self.room_beside_held(bus_voltage) / (1.0 + 1.0 / Q_BIAS_OVER_CHIP);
        let bias = (Q_BIAS_OVER_CHIP * Q_TURNING_CHIP_SHARE * volts).min(turning).min(room);
        if bias >= Q_BIAS_OVER_CHIP * Q_LEAST_CHIP_SHARE * volts && bias.is_finite() {
            bias
        } else {
            0.0
        }
    }

    /// Ticks of an inductance stage before its fit starts: the chips' start, and on a q stage
    /// that turns the rotor its constant voltage's ramp ([`Q_BIAS_RAMP_S`]).
    fn chip_settling_ticks(&self, turning: bool) -> u32 {
        if turning {
            CHIP_SETTLING_TICKS.max(self.ticks_of(Q_BIAS_RAMP_S))
        } else {
            CHIP_SETTLING_TICKS
        }
    }
}

/// A winding sampled every tick (`Commissioning::sampled_winding`).
#[derive(Clone, Copy, Debug)]
struct SampledWinding {
    pole: f32,
    decay: f32,
    gain: f32,
}

/// The inverter's dead-time voltage per phase (V) from what a hold's voltage on the vector at
/// phase a carries beyond `R·I` (`error`): `4/3` of each phase's there. Within a quarter of the
/// highest voltage (`max_voltage`), and not below none.
fn dead_time_of_hold(error: f32, max_voltage: f32) -> f32 {
    crate::limit(0.75 * error, 0.0, 0.25 * max_voltage)
}

/// The inverter's dead-time voltage per volt of dead time (each phase short by it against its
/// current's sign; the common mode drops out) for phase currents of the signs of `phases`,
/// in the frame at `angle`.
fn dead_time_per_volt(phases: [f32; 3], angle: f32) -> Dq {
    let sign = |x: f32| if x >= 0.0 { 1.0 } else { -1.0 };
    let (sa, sb, sc) = (sign(phases[0]), sign(phases[1]), sign(phases[2]));
    let alpha = (2.0 * sa - sb - sc) / 3.0;
    let beta = (sb - sc) * 0.577_350_26;
    let (sin, cos) = sin_cos(angle);
    park(AlphaBeta { alpha, beta }, sin, cos)
}
