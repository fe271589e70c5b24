//! Stop, zero-servo and fine-adjust sequence (seed 004) on top of the velocity loop.
//!
//! - **Running**: speed control; the speed reference ramps to the target speed with the
//!   acceleration gradient.
//! - **Decelerating** (run switched off): the reference ramps to zero.
//! - **Stop**: accepted only when |actual speed| ≤ the zero-speed level. Pressed while
//!   decelerating (or idle) above that level it is *held pending* and accepted by itself the
//!   first tick the speed is low enough; pressed while running it is *refused* (the run
//!   switch is on: the motor would never slow down).
//! - **Servo lock** (zero servo): position control holds the position at acceptance — the
//!   deviation counter starts at zero there, no position command needed; speed reference =
//!   deviation × position gain × the selected gain-table multiplier, limited to the target
//!   speed and to the speed from which the acceleration gradient stops on the target, and
//!   slewed with that gradient (so neither the hand-over nor a gain change can step the speed
//!   reference, hence the torque). Completion is signalled while
//!   |deviation| ≤ the completion width. New targets are refused (blocked).
//! - **Fine adjust** (after a blocking release, allowed only from servo lock): a new target
//!   within the soft limits moves the axis there with the same law; completion again.
//! - **Return to start** (from servo lock or fine adjust): the target becomes the position
//!   where the last run began.
//! - **Run on** again leaves stop mode for speed control from the present speed.
//!
//! Every event either applies completely or is refused with a [`Refusal`] (counted); a
//! refused event changes nothing else.

use core::fmt;

use crate::TAU;

/// Largest gain table.
pub const MAX_GAINS: usize = 8;
/// Longest completion hold time (s).
pub const MAX_COMPLETION_HOLD: f32 = 10.0;
/// An axis at rest may still move this many counts over a completion hold (the encoder's
/// count flickering at an edge, a count of noise): completion's rest condition allows at
/// least this drift whatever the hysteresis.
pub const REST_DITHER_COUNTS: u64 = 2;

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SequenceParams {
    /// Speed of a run and limit of every positioning move (rad/s, > 0).
    pub target_speed: f32,
    /// Acceleration/deceleration gradient of the speed reference (rad/s², > 0).
    pub acceleration: f32,
    /// A stop is accepted at or below this speed (rad/s, ≥ 0).
    pub zero_speed: f32,
    /// Base position gain (1/s, > 0): speed reference per radian of deviation.
    pub position_gain: f32,
    /// In position: |deviation| ≤ this many counts (and |speed| ≤ the zero-speed level).
    pub completion_counts: u32,
    /// Completion is raised once the axis has stayed in position this long (s, ≥ 0).
    pub completion_hold: f32,
    /// Once raised, completion drops only when |deviation| exceeds the width by more than
    /// this many counts (or on a new target).
    pub completion_hysteresis: u32,
    /// Gain-table multipliers (the first `gain_count` are used; each > 0).
    pub gains: [f32; MAX_GAINS],
    pub gain_count: usize,
    /// Targets must lie within [min, max] (counts).
    pub soft_limit_min: i64,
    pub soft_limit_max: i64,
}

impl Default for SequenceParams {
    /// 100 rad/s runs at 2000 rad/s², stop below 2 rad/s, base gain 20/s with the table
    /// 1×, 2×, 4×, 8× in use, completion within 8 counts (48 µrad at 2^20 counts per revolution),
    /// soft limits ±1000 revolutions at 2^20.
    fn default() -> Self {
        Self {
            target_speed: 100.0,
            acceleration: 2000.0,
            zero_speed: 2.0,
            position_gain: 20.0,
            completion_counts: 8,
            completion_hold: 0.02,
            completion_hysteresis: 24,
            // Entries 5–8 (½, ¼, 16, 32) are there to be switched on with `gain_count`.
            gains: [1.0, 2.0, 4.0, 8.0, 0.5, 0.25, 16.0, 32.0],
            gain_count: 4,
            soft_limit_min: -1000 << 20,
            soft_limit_max: 1000 << 20,
        }
    }
}

/// Why sequence parameters were refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SequenceParamError {
    /// Must be a finite number > 0 (or ≥ 0 for the zero-speed level).
    NotPositive { field: &'static str, value: f32 },
    /// Gain table of 0 or more than [`MAX_GAINS`] entries.
    GainCount(usize),
    /// A multiplier that is not a finite number > 0.
    Gain { index: usize, value: f32 },
    /// Soft limits not in order.
    SoftLimits { min: i64, max: i64 },
    /// A soft limit beyond ±2⁵³ counts (`crate::ranges::MAX_POSITION_COUNTS`).
    SoftLimitRange { value: i64 },
    /// Completion hold time outside 0 … [`MAX_COMPLETION_HOLD`] s.
    CompletionHold(f32),
}

impl fmt::Display for SequenceParamError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::NotPositive { field, value } => write!(f, "sequence {field} must be a positive number (got {value})"),
            Self::GainCount(n) => write!(f, "gain table of {n} entries: use 1..={MAX_GAINS}"),
            Self::Gain { index, value } => write!(f, "gain-table entry {index} must be > 0 (got {value})"),
            Self::SoftLimits { min, max } => write!(f, "soft limits {min}..{max} counts: min must be below max"),
            Self::SoftLimitRange { value } => write!(
                f,
                "soft limit {value} counts is outside [-{m}, {m}] counts",
                m = crate::ranges::MAX_POSITION_COUNTS
            ),
            Self::CompletionHold(t) => write!(f, "completion hold {t} s: use 0 to {MAX_COMPLETION_HOLD} s"),
        }
    }
}

impl SequenceParams {
    pub fn validate(&self) -> Result<(), SequenceParamError> {
        let positive = |field, value: f32, allow_zero: bool| {
            let ok = value.is_finite() && (value > 0.0 || (allow_zero && value == 0.0));
            if ok {
                Ok(())
            } else {
                Err(SequenceParamError::NotPositive { field, value })
            }
        };
        positive("target_speed", self.target_speed, false)?;
        positive("acceleration", self.acceleration, false)?;
        positive("zero_speed", self.zero_speed, true)?;
        positive("position_gain", self.position_gain, false)?;
        if !(0.0..=MAX_COMPLETION_HOLD).contains(&self.completion_hold) {
            return Err(SequenceParamError::CompletionHold(self.completion_hold));
        }
        if !(1..=MAX_GAINS).contains(&self.gain_count) {
            return Err(SequenceParamError::GainCount(self.gain_count));
        }
        for (index, &value) in self.gains[..self.gain_count].iter().enumerate() {
            if !(value.is_finite() && value > 0.0) {
                return Err(SequenceParamError::Gain { index, value });
            }
        }
        for value in [self.soft_limit_min, self.soft_limit_max] {
            if value.unsigned_abs() > crate::ranges::MAX_POSITION_COUNTS as u64 {
                return Err(SequenceParamError::SoftLimitRange { value });
            }
        }
        if self.soft_limit_min >= self.soft_limit_max {
            return Err(SequenceParamError::SoftLimits { min: self.soft_limit_min, max: self.soft_limit_max });
        }
        Ok(())
    }
}

/// Where the sequence is.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SequenceState {
    /// Speed control at zero speed (after entering the mode).
    #[default]
    Idle,
    Running,
    Decelerating,
    /// Stopped under position control; position commands blocked.
    ServoLock,
    /// Stopped under position control; position commands accepted.
    FineAdjust,
}

impl SequenceState {
    /// The state of a `seq_state` output code: 0 idle, 1 running, 2 decelerating, 3 servo
    /// lock, 4 fine adjust.
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(Self::Idle),
            1 => Some(Self::Running),
            2 => Some(Self::Decelerating),
            3 => Some(Self::ServoLock),
            4 => Some(Self::FineAdjust),
            _ => None,
        }
    }

    /// The inverse of [`Self::from_code`].
    pub fn code(self) -> i32 {
        match self {
            Self::Idle => 0,
            Self::Running => 1,
            Self::Decelerating => 2,
            Self::ServoLock => 3,
            Self::FineAdjust => 4,
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Self::Idle => "idle",
            Self::Running => "running",
            Self::Decelerating => "decelerating",
            Self::ServoLock => "servo_lock",
            Self::FineAdjust => "fine_adjust",
        }
    }

    fn position_control(self) -> bool {
        matches!(self, Self::ServoLock | Self::FineAdjust)
    }
}

/// What the user (keys, network) asks.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum SequenceEvent {
    RunOn,
    RunOff,
    Stop,
    ReleaseBlocking,
    /// Go to this position (counts); only in fine adjust.
    MoveTo(i64),
    ReturnToStart,
    /// Select a gain-table entry.
    SelectGain(usize),
}

/// Why an event was refused; the state is unchanged.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Refusal {
    /// Run on while already running.
    AlreadyRunning,
    /// Run off while not running.
    NotRunning,
    /// Stop while the run switch is on.
    StopWhileRunning,
    /// Stop while already stopped.
    AlreadyStopped,
    /// Blocking release or return to start without an accepted stop.
    NoAcceptedStop,
    /// A target while position commands are blocked (servo lock).
    TargetBlocked,
    /// A target outside the soft limits.
    BeyondSoftLimits,
    /// A gain index outside the table.
    GainIndex,
    /// The axis is not in sequence mode.
    NotInSequenceMode,
}

impl Refusal {
    pub fn code(self) -> i32 {
        self as i32 + 1
    }
}

impl fmt::Display for Refusal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::AlreadyRunning => "run on refused: already running",
            Self::NotRunning => "run off refused: the run switch is not on",
            Self::StopWhileRunning => "stop refused: the run switch is on (switch it off first)",
            Self::AlreadyStopped => "stop refused: already stopped under position control",
            Self::NoAcceptedStop => "refused: only after an accepted stop (servo lock or fine adjust)",
            Self::TargetBlocked => "target refused: position commands are blocked (release the blocking first)",
            Self::BeyondSoftLimits => "target refused: beyond the soft limits",
            Self::GainIndex => "gain selection refused: index outside the gain table",
            Self::NotInSequenceMode => "sequence event refused: the axis is not in sequence mode (mode 3)",
        })
    }
}

/// The sequence's outputs for telemetry.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SequenceStatus {
    pub state: SequenceState,
    /// Completion (zero servo or fine adjust inside the completion width).
    pub complete: bool,
    /// Target − position (counts); 0 outside position control.
    pub deviation: i64,
    /// Position control target (counts).
    pub target: i64,
    /// A stop is waiting for the speed to fall to the zero-speed level.
    pub stop_pending: bool,
    pub gain_index: usize,
    pub refused: u32,
    pub last_refusal: Option<Refusal>,
    /// Speed reference handed to the velocity loop (rad/s).
    pub speed_reference: f32,
}

/// The sequence's settings, with what its tick derives from them computed once by
/// [`StopSequence::new`], and its state.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StopSequence {
    settings: SequenceParams,
    /// Encoder count to rad.
    rad_per_count: f32,
    /// Position-loop period (s).
    period: f32,
    /// Largest change of the speed reference in one tick: acceleration × period (rad/s).
    max_change: f32,
    /// The completion hold less a relative 10⁻⁶, so that a hold of whole ticks is reached on
    /// its last tick despite rounding (s).
    hold: f32,
    status: SequenceStatus,
    /// Where the last run began (counts).
    start: i64,
    /// Position and speed at the last step (for events between steps).
    position: i64,
    /// Position ticks the axis has been in position without completion raised, and its
    /// deviation on the first of them (counts).
    in_position_ticks: u32,
    hold_start_deviation: i64,
    /// From acceptance until the speed reference stops ramping: the integrator's
    /// deceleration torque is still to be released.
    releasing: bool,
    /// For the axis: clear the velocity loop's integrator now (once).
    release: bool,
}

impl StopSequence {
    /// The sequence of `settings` on an encoder of `counts_per_rev`, stepped every `period`
    /// seconds (the position loop's), idle.
    pub fn new(settings: &SequenceParams, counts_per_rev: u32, period: f32) -> Self {
        Self {
            settings: *settings,
            rad_per_count: TAU / counts_per_rev as f32,
            period,
            max_change: settings.acceleration * period,
            hold: settings.completion_hold * (1.0 - 1e-6),
            status: SequenceStatus::default(),
            start: 0,
            position: 0,
            in_position_ticks: 0,
            hold_start_deviation: 0,
            releasing: false,
            release: false,
        }
    }

    /// Enter the sequence at `position` moving at `speed` (rad/s): idle, speed reference
    /// = the present speed (it then ramps to zero), nothing pending.
    pub fn enter(&mut self, position: i64, speed: f32, gain_index: usize) {
        let refused = self.status.refused;
        self.status =
            SequenceStatus { speed_reference: speed, gain_index, refused, target: position, ..Default::default() };
        self.start = position;
        self.position = position;
        self.in_position_ticks = 0;
        self.releasing = false;
        self.release = false;
    }

    /// Whether the hand-over asks the axis to clear the velocity loop's integrator now
    /// (true once per stop).
    pub fn take_integrator_release(&mut self) -> bool {
        core::mem::take(&mut self.release)
    }

    pub fn status(&self) -> &SequenceStatus {
        &self.status
    }

    /// Apply an event, or refuse it with the reason (counted) and change nothing else.
    pub fn event(&mut self, e: SequenceEvent) -> Result<(), Refusal> {
        match self.try_event(e) {
            Ok(()) => Ok(()),
            Err(reason) => self.refuse(reason),
        }
    }

    /// Count a refusal decided elsewhere (for example by the axis).
    pub fn refuse(&mut self, reason: Refusal) -> Result<(), Refusal> {
        self.status.refused = self.status.refused.saturating_add(1);
        self.status.last_refusal = Some(reason);
        Err(reason)
    }

    fn try_event(&mut self, e: SequenceEvent) -> Result<(), Refusal> {
        use SequenceState::*;
        let p = &self.settings;
        let s = &mut self.status;
        match e {
            SequenceEvent::RunOn => {
                if s.state == Running {
                    return Err(Refusal::AlreadyRunning);
                }
                if s.state != Decelerating {
                    self.start = self.position;
                }
                s.state = Running;
                s.stop_pending = false;
            }
            SequenceEvent::RunOff => {
                if s.state != Running {
                    return Err(Refusal::NotRunning);
                }
                s.state = Decelerating;
            }
            SequenceEvent::Stop => match s.state {
                Running => return Err(Refusal::StopWhileRunning),
                ServoLock | FineAdjust => return Err(Refusal::AlreadyStopped),
                Idle | Decelerating => s.stop_pending = true,
            },
            SequenceEvent::ReleaseBlocking => match s.state {
                ServoLock => s.state = FineAdjust,
                _ => return Err(Refusal::NoAcceptedStop),
            },
            SequenceEvent::MoveTo(target) => match s.state {
                FineAdjust if (p.soft_limit_min..=p.soft_limit_max).contains(&target) => s.target = target,
                FineAdjust => return Err(Refusal::BeyondSoftLimits),
                ServoLock => return Err(Refusal::TargetBlocked),
                _ => return Err(Refusal::NoAcceptedStop),
            },
            SequenceEvent::ReturnToStart => {
                if !s.state.position_control() {
                    return Err(Refusal::NoAcceptedStop);
                }
                if !(p.soft_limit_min..=p.soft_limit_max).contains(&self.start) {
                    return Err(Refusal::BeyondSoftLimits);
                }
                s.target = self.start;
            }
            SequenceEvent::SelectGain(i) => {
                if i >= p.gain_count {
                    return Err(Refusal::GainIndex);
                }
                s.gain_index = i;
            }
        }
        if matches!(e, SequenceEvent::MoveTo(_) | SequenceEvent::ReturnToStart) {
            // A new positioning: completion drops and must be earned again.
            s.complete = false;
            self.in_position_ticks = 0;
        }
        Ok(())
    }

    /// One position-loop tick: `position` (counts), measured `speed` (rad/s). Returns the
    /// speed reference for the velocity loop (rad/s).
    ///
    /// **Hand-over.** At the end of a deceleration the velocity loop's integrator holds
    /// the deceleration torque (≈ J·a). Discharging it takes ∫(reference − speed) dt =
    /// J·a/kᵢ; with the reference already at zero that area can only come from the axis
    /// running *backwards* (≈ 15 mrad, 2 500 counts, at the defaults). So once the stop is
    /// accepted and the speed reference has caught up with the position law (the
    /// deceleration is over), the sequence asks the axis to clear the integrator
    /// ([`Self::take_integrator_release`]): the deceleration torque lets go at once. Clearing
    /// it to what it held in the steady run (load and friction) was tried and left the
    /// friction torque pushing the stopped axis on (282 counts against 198 at the defaults),
    /// so it is cleared to zero; on an axis with a standing load (gravity) the integrator
    /// then builds that torque up again, which costs about load / kᵢ of motion.
    ///
    /// **Completion.** In position = |deviation| ≤ `completion_counts` and |speed| ≤
    /// `zero_speed`. Completion is raised after the axis has been in position for
    /// `completion_hold` without a break *and at rest over it*: its deviation changed by at
    /// most `completion_hysteresis` (at least [`REST_DITHER_COUNTS`]) from the hold's first
    /// tick to its last (the motion completion tolerates once raised). An axis still creeping through a wide window
    /// (friction after the release: 3 000 counts/s crossed a 60-count window in exactly the
    /// 20 ms hold, was raised and then left by 86 counts) starts a new hold instead. Once
    /// raised it drops only when |deviation| > `completion_counts + completion_hysteresis`,
    /// on a new target, or on leaving position control.
    pub fn step(&mut self, position: i64, speed: f32) -> f32 {
        use SequenceState::*;
        self.position = position;
        let p = &self.settings;
        let s = &mut self.status;
        if s.stop_pending && speed.abs() <= p.zero_speed {
            // Servo lock at the position of acceptance: the deviation counter starts at 0.
            s.stop_pending = false;
            s.state = ServoLock;
            s.target = position;
            s.complete = false;
            self.in_position_ticks = 0;
            self.releasing = true;
        }
        let wanted = match s.state {
            Running => p.target_speed,
            Idle | Decelerating => 0.0,
            ServoLock | FineAdjust => {
                // Position → speed conversion: deviation × gain near the target; farther
                // out, the speed from which the gradient stops the axis on the target
                // (√(a·|e|), decelerating at a/2) and the target speed, whichever is lower.
                // The P branch decelerates at gain²·|e| ≤ a, so no gain in the table can
                // make the slewed reference lag behind and overshoot.
                let gain = p.position_gain * p.gains[s.gain_index];
                let deviation = crate::counts_to_f32(s.target.saturating_sub(position)) * self.rad_per_count;
                let magnitude = deviation.abs();
                let speed =
                    (gain * magnitude).min(crate::square_root::sqrt(p.acceleration * magnitude)).min(p.target_speed);
                libm::copysignf(speed, deviation)
            }
        };
        let max_change = self.max_change;
        let before = s.speed_reference;
        s.speed_reference += crate::limit(wanted - s.speed_reference, -max_change, max_change);
        if self.releasing && (wanted - before).abs() <= max_change {
            // The reference has caught up with the position law: the deceleration is over,
            // so is the torque the integrator holds for it.
            self.release = true;
            self.releasing = false;
        }
        if s.state.position_control() {
            s.deviation = s.target.saturating_sub(position);
            let magnitude = s.deviation.unsigned_abs();
            if s.complete {
                if magnitude > p.completion_counts as u64 + p.completion_hysteresis as u64 {
                    s.complete = false;
                    self.in_position_ticks = 0;
                }
            } else if magnitude <= p.completion_counts as u64 && speed.abs() <= p.zero_speed {
                if self.in_position_ticks == 0 {
                    self.hold_start_deviation = s.deviation;
                }
                self.in_position_ticks = self.in_position_ticks.saturating_add(1);
                if self.in_position_ticks as f32 * self.period >= self.hold {
                    // At least the count an axis at rest dithers by, with any hysteresis (0
                    // included, where a one-count dither would otherwise restart every hold).
                    let rest = (p.completion_hysteresis as u64).max(REST_DITHER_COUNTS);
                    if s.deviation.abs_diff(self.hold_start_deviation) <= rest {
                        s.complete = true;
                    } else {
                        // Still moving through the window: a new hold starts on this tick.
                        self.in_position_ticks = 1;
                        self.hold_start_deviation = s.deviation;
                    }
                }
            } else {
                self.in_position_ticks = 0;
            }
        } else {
            s.deviation = 0;
            s.complete = false;
            self.in_position_ticks = 0;
            self.releasing = false;
        }
        s.speed_reference
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn state_codes_round_trip() {
        use super::SequenceState::*;
        for s in [Idle, Running, Decelerating, ServoLock, FineAdjust] {
            assert_eq!(super::SequenceState::from_code(s.code()), Some(s));
        }
        assert_eq!(super::SequenceState::from_code(5), None);
    }

    use super::*;

    const CPR: u32 = 1 << 20;
    const DT: f32 = 0.00025;

    /// A perfect velocity loop: the speed equals the reference; position integrates it.
    fn run(seq: &mut StopSequence, position: &mut f64, ticks: usize) -> f32 {
        let mut speed = 0.0;
        for _ in 0..ticks {
            speed = seq.step(position.round() as i64, speed);
            *position += speed as f64 * DT as f64 * CPR as f64 / core::f64::consts::TAU;
        }
        speed
    }

    #[test]
    fn run_stop_lock_fine_adjust_and_return() {
        let p = SequenceParams::default();
        let mut seq = StopSequence::new(&p, CPR, DT);
        let mut x = 0.0;
        seq.enter(0, 0.0, 0);
        seq.event(SequenceEvent::RunOn).unwrap();
        let v = run(&mut seq, &mut x, 1000);
        assert!((v - p.target_speed).abs() < 1e-3, "reached the target speed: {v}");
        assert_eq!(seq.event(SequenceEvent::Stop), Err(Refusal::StopWhileRunning));
        seq.event(SequenceEvent::RunOff).unwrap();
        seq.event(SequenceEvent::Stop).unwrap();
        assert!(seq.status().stop_pending);
        run(&mut seq, &mut x, 400);
        assert_eq!(seq.status().state, SequenceState::ServoLock);
        let lock = seq.status().target;
        run(&mut seq, &mut x, 4000);
        assert!(seq.status().complete && (x.round() as i64 - lock).abs() <= 2);
        assert_eq!(seq.event(SequenceEvent::MoveTo(lock + 1000)), Err(Refusal::TargetBlocked));
        seq.event(SequenceEvent::ReleaseBlocking).unwrap();
        seq.event(SequenceEvent::MoveTo(lock + 100_000)).unwrap();
        assert!(!{
            run(&mut seq, &mut x, 1);
            seq.status().complete
        });
        run(&mut seq, &mut x, 8000);
        assert!(seq.status().complete, "{:?}", seq.status());
        seq.event(SequenceEvent::ReturnToStart).unwrap();
        run(&mut seq, &mut x, 20000);
        assert!(seq.status().complete && x.round().abs() <= 2.0, "back at the start: {x}");
        assert_eq!(seq.status().refused, 2);
    }

    #[test]
    fn refused_events_change_nothing_but_the_counter() {
        let p = SequenceParams::default();
        let mut seq = StopSequence::new(&p, CPR, DT);
        seq.enter(0, 0.0, 0);
        let before = seq;
        for (e, why) in [
            (SequenceEvent::RunOff, Refusal::NotRunning),
            (SequenceEvent::ReleaseBlocking, Refusal::NoAcceptedStop),
            (SequenceEvent::MoveTo(5), Refusal::NoAcceptedStop),
            (SequenceEvent::ReturnToStart, Refusal::NoAcceptedStop),
            (SequenceEvent::SelectGain(4), Refusal::GainIndex),
        ] {
            assert_eq!(seq.event(e), Err(why));
        }
        assert_eq!(seq.status().refused, 5);
        assert_eq!(seq.status().last_refusal, Some(Refusal::GainIndex));
        let mut after = seq;
        after.status.refused = 0;
        after.status.last_refusal = None;
        assert_eq!(after, before);
    }

    #[test]
    fn soft_limits_refuse_far_targets() {
        let p = SequenceParams { soft_limit_min: -1000, soft_limit_max: 1000, ..Default::default() };
        let mut seq = StopSequence::new(&p, CPR, DT);
        seq.enter(0, 0.0, 0);
        seq.event(SequenceEvent::Stop).unwrap();
        seq.step(0, 0.0);
        seq.event(SequenceEvent::ReleaseBlocking).unwrap();
        assert_eq!(seq.event(SequenceEvent::MoveTo(1001)), Err(Refusal::BeyondSoftLimits));
        assert_eq!(seq.status().target, 0);
        seq.event(SequenceEvent::MoveTo(1000)).unwrap();
    }

    #[test]
    fn gain_change_never_steps_the_speed_reference() {
        let p = SequenceParams::default();
        let mut seq = StopSequence::new(&p, CPR, DT);
        let mut x = 0.0;
        seq.enter(0, 0.0, 0);
        seq.event(SequenceEvent::Stop).unwrap();
        run(&mut seq, &mut x, 1);
        seq.event(SequenceEvent::ReleaseBlocking).unwrap();
        seq.event(SequenceEvent::MoveTo(200_000)).unwrap();
        let mut previous = run(&mut seq, &mut x, 40);
        seq.event(SequenceEvent::SelectGain(3)).unwrap();
        for _ in 0..200 {
            let v = run(&mut seq, &mut x, 1);
            assert!((v - previous).abs() <= p.acceleration * DT * 1.0001, "{previous} -> {v}");
            previous = v;
        }
    }

    #[test]
    fn completion_waits_for_the_hold_and_drops_only_beyond_the_hysteresis() {
        let p = SequenceParams { completion_hold: 0.01, completion_hysteresis: 5, ..Default::default() };
        let hold_ticks = (p.completion_hold / DT).round() as usize;
        let mut seq = StopSequence::new(&p, CPR, DT);
        seq.enter(0, 0.0, 0);
        seq.event(SequenceEvent::Stop).unwrap();
        seq.step(0, 0.0);
        assert_eq!((seq.status().state, seq.status().target), (SequenceState::ServoLock, 0));
        // In position but moving faster than the zero-speed level: never complete.
        for _ in 0..2 * hold_ticks {
            seq.step(0, p.zero_speed * 1.5);
            assert!(!seq.status().complete);
        }
        // Still: raised on exactly the hold's last tick, not before.
        for k in 1..=hold_ticks {
            seq.step(3, 0.0);
            assert_eq!(seq.status().complete, k == hold_ticks, "tick {k}");
        }
        // Beyond the width but inside the hysteresis: stays; beyond it: drops.
        seq.step(p.completion_counts as i64 + 5, 0.0);
        assert!(seq.status().complete);
        seq.step(p.completion_counts as i64 + 6, 0.0);
        assert!(!seq.status().complete);
        // Back in position: the hold starts again.
        seq.step(0, 0.0);
        assert!(!seq.status().complete);
    }

    /// An axis creeping through a wide window (width 30 counts, hysteresis 24) at a speed
    /// that crosses it in exactly the hold is not complete: the hold's drift (60 counts) is
    /// more than completion tolerates once raised. It is raised once, after the axis has come
    /// to rest inside, and the creep that carried it 56 counts beyond the width no longer
    /// toggles it (the case `servo bench sequence` found at 10 rad/s, level 5, width 30).
    #[test]
    fn completion_is_not_raised_while_the_axis_creeps_through_the_window() {
        let p = SequenceParams { completion_counts: 30, ..Default::default() };
        let hold_ticks = (p.completion_hold / DT).round() as i64;
        let mut seq = StopSequence::new(&p, CPR, DT);
        seq.enter(0, 0.0, 0);
        seq.event(SequenceEvent::Stop).unwrap();
        seq.step(-200, 0.0);
        let target = seq.status().target;
        // From +30 through the window to −30 and on to −86: one window (60 counts) per hold.
        let counts_per_tick = 60.0 / hold_ticks as f64;
        let deviation_at = |k: i64| 30 - (k as f64 * counts_per_tick).round() as i64;
        let (mut k, mut raised, mut was) = (0i64, 0u32, false);
        while deviation_at(k) >= -86 {
            seq.step(target - deviation_at(k), 0.01);
            let c = seq.status().complete;
            raised += (c && !was) as u32;
            was = c;
            k += 1;
        }
        assert_eq!(raised, 0, "raised while creeping");
        // At rest inside the window: raised once, at the end of a hold.
        for _ in 0..2 * hold_ticks {
            seq.step(target - 20, 0.0);
            let c = seq.status().complete;
            raised += (c && !was) as u32;
            was = c;
        }
        assert_eq!((raised, was), (1, true));
    }

    /// With no hysteresis an axis at rest that flickers by a count every tick is still
    /// complete after one hold (the rest condition allows the dither).
    #[test]
    fn a_dithering_axis_completes_without_hysteresis() {
        let p = SequenceParams { completion_hysteresis: 0, ..Default::default() };
        let hold_ticks = (p.completion_hold / DT).round() as usize;
        // Both phases of the flicker against the hold's ends.
        for phase in 0..2 {
            let mut seq = StopSequence::new(&p, CPR, DT);
            seq.enter(0, 0.0, 0);
            seq.event(SequenceEvent::Stop).unwrap();
            seq.step(0, 0.0);
            let target = seq.status().target;
            let mut first = None;
            for k in 0..4 * hold_ticks {
                seq.step(target - ((k + phase) % 2) as i64, 0.0);
                if seq.status().complete && first.is_none() {
                    first = Some(k);
                }
            }
            assert!(
                first.is_some_and(|k| k < hold_ticks + 2),
                "phase {phase}: raised at {first:?} (hold {hold_ticks})"
            );
        }
    }

    #[test]
    fn bad_parameters_are_named() {
        let mut p = SequenceParams { zero_speed: -1.0, ..Default::default() };
        assert!(matches!(p.validate(), Err(SequenceParamError::NotPositive { field: "zero_speed", .. })));
        p = SequenceParams { gain_count: 0, ..Default::default() };
        assert_eq!(p.validate(), Err(SequenceParamError::GainCount(0)));
        p = SequenceParams::default();
        p.gains[1] = f32::NAN;
        assert!(matches!(p.validate(), Err(SequenceParamError::Gain { index: 1, .. })));
        p = SequenceParams { completion_hold: 10.5, ..Default::default() };
        assert_eq!(p.validate(), Err(SequenceParamError::CompletionHold(10.5)));
        p = SequenceParams { soft_limit_min: 5, soft_limit_max: 5, ..Default::default() };
        assert!(matches!(p.validate(), Err(SequenceParamError::SoftLimits { .. })));
        assert_eq!(SequenceParams::default().validate(), Ok(()));
    }
}
