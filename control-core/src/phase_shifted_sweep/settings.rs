//! The sweep's settings ([`SweepParams`]), their checks and the errors that name a refused
//! value ([`SweepError`]).

use core::fmt;

use super::{SweepMeasure, SweepSignal, MAX_SWEEP_POINTS};
use crate::excitation::InjectionPoint;
use crate::m_sequence::MSequence;

const MAX_SHIFTS: u16 = 16;
/// Upper bound of `SweepParams::max_extensions`.
pub const MAX_EXTENSIONS: u32 = 64;
/// Fewest acquisition samples a stepped sine's record may hold: the three-parameter fit and
/// its noise estimate (`SineFitSums::response_error`) need eight; fewer, and precision control
/// cannot tell how far off the result is (with `min_measure_s` 0 a record at 3 kHz held three
/// samples and came out 3.8 dB off).
pub const MIN_RECORD_SAMPLES: u64 = 8;

/// Upper bound of `SweepParams::dither` (N·m).
pub const MAX_SWEEP_DITHER: f32 = 1000.0;

#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct SweepParams {
    pub point: InjectionPoint,
    pub signal: SweepSignal,
    /// Sine or PRBS amplitude (rad/s, Nm or rad, as the point).
    pub amplitude: f32,
    pub start_hz: f32,
    pub stop_hz: f32,
    /// Frequencies between start and stop, both included (1: start_hz alone).
    pub points: u32,
    pub logarithmic: bool,
    /// One more frequency inserted in order (0: none), for example the acquisition Nyquist.
    pub extra_hz: f32,
    /// Settling before each record: the longer of so many cycles and `min_settle_s`.
    pub settle_cycles: f32,
    pub min_settle_s: f32,
    /// Measurement of each record: the longer of so many cycles and `min_measure_s` (half of
    /// it below half the threshold while precision control runs: see
    /// [`SweepParams::record_length`]).
    pub measure_cycles: f32,
    pub min_measure_s: f32,
    /// Phase step 2π/shifts between repeats. 16-bit, as `repeats` (at most 16 each): the two
    /// leave room for `time_budget_s` without growing the settings, whose size moves the
    /// axis's fields (4 bytes more took the tick 34 instructions longer on the Cortex-M4,
    /// `servo bench firmware`); on the link postcard encodes both widths alike.
    pub shifts: u16,
    /// Records per frequency at and above the threshold.
    pub repeats: u16,
    /// Phase shifting from this frequency up (0: the acquisition Nyquist frequency).
    pub threshold_hz: f32,
    /// Base ticks per acquisition sample (a multiple of the velocity divider).
    pub acquisition_divider: u32,
    /// PRBS: M-sequence degree (period 2^n − 1 chips), base ticks per chip, and the measured
    /// duration after `min_settle_s`.
    pub prbs_degree: u32,
    pub prbs_divider: u32,
    pub prbs_seconds: f32,
    /// Stepped sine: lengthen a frequency's records by half blocks so that the standard
    /// errors of its gain and phase (predicted from the fits' residuals after the first block:
    /// mostly encoder quantisation; below the threshold checked against the half blocks' own
    /// spread, see `PhaseShiftedSweep::next_half_block`) are at most this (dB; 0: fixed
    /// records, no settling check). At low-gain points (a
    /// deep anti-resonance, the top of the sweep) the response is a few encoder counts and
    /// the base record leaves about 0.1 dB of error whose size depends on the fine detail of
    /// the motion; the well-measured points are not lengthened.
    pub precision_db: f32,
    /// At most so many extra blocks (each as long as one record's base measurement with the
    /// full `min_measure_s`) per record of a frequency, and at most twice as many half blocks
    /// discarded while its first record settles; where the base block is halved the cap stays
    /// the same in time (twice as many half blocks: see [`SweepParams::half_block_cap`]). The
    /// records go past it only with the time budget's room (`time_budget_s`).
    pub max_extensions: u32,
    /// Stepped sine with precision control: a record may take more half blocks than its cap
    /// ([`SweepParams::half_block_cap`]: `max_extensions`), up to the cap of
    /// [`MAX_EXTENSIONS`], when the sweep still ends within this time (s, from its start)
    /// with every later frequency at its own longest (0: never). The frequencies that finish
    /// early leave their time to the later ones that need more (the first to ask): in
    /// practice the top of the sweep, where the response is a few encoder counts and the cap
    /// left about 0.04 dB of spread, is measured longer when the lower frequencies were quick.
    /// The budget also bounds the sweep: where the frequencies before took long, a frequency
    /// adds or discards only the half blocks that still end the sweep within it with every
    /// later frequency at its shortest (`PhaseShiftedSweep::budget_bound`), so a sweep whose
    /// shortest schedule fits the budget ends within it. A short one (a few points) has room
    /// to run its noisy points to the precision (see `PhaseShiftedSweep::extension_cap`).
    /// Where there is room, an extended frequency also measures to 1/1.25 of the precision
    /// (`BUDGET_MARGIN` in `precision_control`). At most 2³⁰ base ticks (18.6 h at 16 kHz:
    /// refused above, when the sweep starts).
    pub time_budget_s: f32,
    /// Stepped sine: a pseudo-random ±dither (N·m) added to the torque command on every base
    /// tick of the frequencies at and above the threshold, or 2 kHz where the threshold is
    /// higher (a faster loop; see `DITHER_FROM_HZ`), (0: none). At constant speed and
    /// without sensor noise the encoder's count pattern is periodic and can lock to the
    /// excitation: at the top of the sweep, where the response is a few counts, a
    /// quantisation error that longer records do not remove (0.24 dB at 3 kHz on the default
    /// axis). A dither of a few milli-newton-metres moves the axis by enough counts to break
    /// the lock; the fit sees it as noise. Lower down the responses are large and the
    /// dither's own noise would cost more than it breaks.
    pub dither: f32,
    /// What U and Y are: the loop's signals, or the machine-end acceleration against the
    /// motor's torque from the measured q current (torque-command injection) or against the
    /// injected position (position-command injection; see [`SweepMeasure`]).
    pub measure: SweepMeasure,
}

impl Default for SweepParams {
    /// Velocity-command injection, 10 Hz to 3 kHz in 40 log steps plus 2 kHz, 1 settle and
    /// 2 measure cycles (at least 10 ms of settling, and 40 ms of measurement from half the
    /// threshold up, 1 kHz at 16 kHz, 20 ms below: see [`SweepParams::record_length`]), 3 records
    /// shifted by 2π/3 from the acquisition Nyquist frequency up, acquisition every 4 ticks
    /// (4 kHz at 16 kHz). The base records are short: the settling check lengthens the wait
    /// where the loop rings (see `PhaseShiftedSweep::settled`), the precision control the
    /// records where the response is noisy (near 3 kHz it is a few encoder counts per
    /// velocity period), past their cap while the sweep still ends within 9.9 s (10 Hz–3 kHz
    /// within 10 s, with a tenth to spare: a trace sees the end up to a communication step
    /// late).
    fn default() -> Self {
        Self {
            point: InjectionPoint::VelocityCommand,
            signal: SweepSignal::SteppedSine,
            amplitude: 2.0,
            start_hz: 10.0,
            stop_hz: 3000.0,
            points: 40,
            logarithmic: true,
            extra_hz: 2000.0,
            settle_cycles: 1.0,
            min_settle_s: 0.01,
            measure_cycles: 2.0,
            min_measure_s: 0.04,
            shifts: 3,
            repeats: 3,
            threshold_hz: 0.0,
            acquisition_divider: 4,
            prbs_degree: 15,
            prbs_divider: 1,
            prbs_seconds: 5.0,
            precision_db: 0.03,
            max_extensions: 8,
            time_budget_s: 9.9,
            dither: 0.003,
            measure: SweepMeasure::Loop,
        }
    }
}

/// Why sweep settings or a start were refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SweepError {
    /// A value outside its range: the field and the value.
    Setting { field: &'static str, value: f32 },
    /// A value outside `[min, max]`.
    Range { field: &'static str, value: f32, min: f32, max: f32 },
    /// A frequency at or above the Nyquist frequency of the loop the sine is injected into,
    /// where it aliases: the field that sets it (`stop_hz`, `start_hz` or `extra_hz`), and
    /// the loop's rate as parameters (`rate`).
    AboveLoopNyquist { field: &'static str, frequency: f32, nyquist: f32, rate: &'static str },
    /// More frequencies than the result table holds.
    TooManyPoints(u32),
    /// The acquisition divider is not a multiple of the velocity divider.
    AcquisitionDivider { acquisition: u32, velocity: u32 },
    /// Injection point off, or a velocity-loop point while the velocity loop does not run.
    PointUnusable,
    /// Position-command injection outside position mode.
    NeedsPositionMode,
    /// A sweep is already running.
    Busy,
    /// A stepped sine's record at `frequency` would hold fewer than [`MIN_RECORD_SAMPLES`]
    /// acquisition samples.
    RecordTooShort { frequency: f32, samples: u32 },
    /// The machine-end acceleration measure with an injection point other than the torque or
    /// the position command: the velocity loop's injections would relate the acceleration to a
    /// velocity inside the loop, which no seed-001 figure is (and Off injects nothing).
    MeasureNeedsTorqueOrPositionInjection,
}

impl fmt::Display for SweepError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Setting { field, value } => write!(f, "sweep {field} = {value} is out of range"),
            Self::Range { field, value, min, max } => write!(f, "sweep {field} = {value} is outside [{min}, {max}]"),
            Self::AboveLoopNyquist { field, frequency, nyquist, rate } => write!(
                f,
                "sweep {field} = {frequency} Hz is at or above the Nyquist frequency {nyquist} Hz of the loop it is injected into (half of {rate})"
            ),
            Self::TooManyPoints(n) => write!(
                f,
                "sweep points = {n}: at most {} (the result table holds {MAX_SWEEP_POINTS}, one of them for the extra frequency)",
                MAX_SWEEP_POINTS - 1
            ),
            Self::AcquisitionDivider { acquisition, velocity } => write!(
                f,
                "acquisition every {acquisition} ticks is not a multiple of the velocity loop's {velocity} ticks"
            ),
            Self::PointUnusable => write!(
                f,
                "the sweep needs an injection point, and velocity-command or feedback injection needs the velocity loop (velocity, position or sequence mode)"
            ),
            Self::NeedsPositionMode => {
                write!(f, "position-command injection needs position mode (the drive holding or streaming a position)")
            }
            Self::Busy => write!(f, "a sweep is already running"),
            Self::RecordTooShort { frequency, samples } => write!(
                f,
                "a record at {frequency} Hz would hold {samples} acquisition samples; a sine fit and its noise estimate need at least {MIN_RECORD_SAMPLES}: lengthen min_measure_s (--min-measure) or measure_cycles (--measure-cycles)"
            ),
            Self::MeasureNeedsTorqueOrPositionInjection => write!(
                f,
                "the machine-end acceleration measure (sweep.measure 1) needs torque-command (sweep.point 1) or position-command (sweep.point 4) injection"
            ),
        }
    }
}

impl SweepParams {
    /// The dither the sweep adds (N·m peak): `dither` for the stepped sine, 0 for the PRBS
    /// mode, which adds none.
    pub fn dither_in_use(&self) -> f32 {
        match self.signal {
            super::SweepSignal::SteppedSine => self.dither,
            super::SweepSignal::Prbs => 0.0,
        }
    }

    /// The highest frequency swept (stop_hz, or start_hz alone with one point, or extra_hz).
    pub fn top_hz(&self) -> f32 {
        self.top().1
    }

    /// The field that sets the highest frequency swept, and that frequency.
    fn top(&self) -> (&'static str, f32) {
        let (field, hz) = if self.points > 1 { ("stop_hz", self.stop_hz) } else { ("start_hz", self.start_hz) };
        if self.extra_hz > hz {
            ("extra_hz", self.extra_hz)
        } else {
            (field, hz)
        }
    }

    /// Refuse a highest frequency at or above `nyquist`, the Nyquist frequency of the loop
    /// whose rate `rate` names.
    pub(crate) fn below_nyquist(&self, nyquist: f32, rate: &'static str) -> Result<(), SweepError> {
        let (field, frequency) = self.top();
        if frequency >= nyquist {
            return Err(SweepError::AboveLoopNyquist { field, frequency, nyquist, rate });
        }
        Ok(())
    }

    /// The settings and the loop rates they are injected at: [`SweepParams::validate_settings`]
    /// and every frequency below the Nyquist frequency of its loop (the velocity loop's, the
    /// base rate's for torque-command injection). What a sweep start needs (with the checks
    /// against the axis's other parameters in [`crate::Params::validate_sweep`]).
    pub fn validate(&self, base_rate_hz: f32, velocity_divider: u32) -> Result<(), SweepError> {
        self.validate_settings(velocity_divider)?;
        // The budget's ticks are counted in 32 bits (see `PhaseShiftedSweep::budget_left`).
        if self.budget_ticks(base_rate_hz) >= super::MAX_BUDGET_TICKS {
            let max = (super::MAX_BUDGET_TICKS - 1) as f32 / base_rate_hz;
            return Err(SweepError::Range { field: "time_budget_s", value: self.time_budget_s, min: 0.0, max });
        }
        // The sine is updated at the velocity-loop rate for velocity-loop points.
        if self.point == InjectionPoint::TorqueCommand {
            self.below_nyquist(0.5 * base_rate_hz, "current_loop_hz")?;
        } else {
            self.below_nyquist(0.5 * base_rate_hz / velocity_divider as f32, "current_loop_hz / velocity_divider")?;
        }
        self.records_long_enough(base_rate_hz)
    }

    /// Every record of a stepped sine holds at least [`MIN_RECORD_SAMPLES`] acquisition samples
    /// at this base rate. A record's samples fall with its frequency within each stretch of
    /// one shortest measurement (halved below half the threshold: see `min_measure_at`), so
    /// the shortest records are at the top of each stretch: the highest frequency, and just
    /// below half the threshold where the sweep reaches that low. Two evaluations, not one per
    /// frequency: on the drive each planned frequency is a `powf` in soft f64 (about 30 000
    /// Cortex-M4 instructions for the 41 default ones, a `SetParams` 10 times longer).
    fn records_long_enough(&self, base_rate_hz: f32) -> Result<(), SweepError> {
        if self.signal != SweepSignal::SteppedSine {
            return Ok(());
        }
        let top = self.top_hz();
        let half_threshold = 0.5 * self.threshold(base_rate_hz);
        let lowest = if self.points > 1 { self.start_hz.min(top) } else { self.start_hz };
        let mut tops = [Some(top), None];
        if lowest < half_threshold && half_threshold < top {
            // The halved stretch ends just below half the threshold.
            tops[1] = Some(half_threshold * (1.0 - f32::EPSILON));
        }
        for frequency in tops.into_iter().flatten() {
            let samples = self.record_length(frequency, base_rate_hz).1;
            if samples < MIN_RECORD_SAMPLES {
                return Err(SweepError::RecordTooShort { frequency, samples: samples as u32 });
            }
        }
        Ok(())
    }

    /// The settings on their own (each value in its range, the acquisition on velocity-loop
    /// ticks), whatever the loop rates: what an axis needs to be built, sweep or not. The
    /// frequencies are held against the rates when a sweep starts ([`SweepParams::validate`]):
    /// an axis whose rate was lowered runs with the default sweep settings as long as it does
    /// not sweep.
    pub fn validate_settings(&self, velocity_divider: u32) -> Result<(), SweepError> {
        let finite_positive = |field, value: f32| {
            if value.is_finite() && value > 0.0 {
                Ok(())
            } else {
                Err(SweepError::Setting { field, value })
            }
        };
        let finite_non_negative = |field, value: f32| {
            if value.is_finite() && value >= 0.0 {
                Ok(())
            } else {
                Err(SweepError::Setting { field, value })
            }
        };
        finite_positive("amplitude", self.amplitude)?;
        // A velocity sine beyond the largest speed set-point, or a torque sine beyond the
        // largest torque set-point, is not a command the loop takes (`crate::ranges`).
        let max_amplitude = match self.point {
            InjectionPoint::VelocityCommand | InjectionPoint::VelocityFeedback => crate::ranges::MAX_SPEED,
            InjectionPoint::TorqueCommand => crate::ranges::MAX_TORQUE,
            _ => f32::INFINITY,
        };
        if self.amplitude > max_amplitude {
            return Err(SweepError::Range { field: "amplitude", value: self.amplitude, min: 0.0, max: max_amplitude });
        }
        if self.measure == SweepMeasure::MachineAcceleration
            && !matches!(self.point, InjectionPoint::TorqueCommand | InjectionPoint::PositionCommand)
        {
            return Err(SweepError::MeasureNeedsTorqueOrPositionInjection);
        }
        finite_positive("start_hz", self.start_hz)?;
        finite_positive("stop_hz", self.stop_hz)?;
        // One point measures start_hz alone (stop_hz unused).
        if self.points > 1 && self.stop_hz <= self.start_hz {
            return Err(SweepError::Setting { field: "stop_hz (must exceed start_hz)", value: self.stop_hz });
        }
        finite_non_negative("extra_hz", self.extra_hz)?;
        if self.points < 1 {
            return Err(SweepError::Setting { field: "points", value: self.points as f32 });
        }
        if self.points as usize + 1 > MAX_SWEEP_POINTS {
            return Err(SweepError::TooManyPoints(self.points));
        }
        finite_non_negative("settle_cycles", self.settle_cycles)?;
        finite_non_negative("min_settle_s", self.min_settle_s)?;
        finite_positive("measure_cycles", self.measure_cycles)?;
        finite_non_negative("min_measure_s", self.min_measure_s)?;
        if !(1..=MAX_SHIFTS).contains(&self.shifts) {
            return Err(SweepError::Setting { field: "shifts", value: self.shifts as f32 });
        }
        if !(1..=MAX_SHIFTS).contains(&self.repeats) {
            return Err(SweepError::Setting { field: "repeats", value: self.repeats as f32 });
        }
        finite_non_negative("threshold_hz", self.threshold_hz)?;
        if self.acquisition_divider == 0 || !self.acquisition_divider.is_multiple_of(velocity_divider) {
            return Err(SweepError::AcquisitionDivider {
                acquisition: self.acquisition_divider,
                velocity: velocity_divider,
            });
        }
        if MSequence::new(self.prbs_degree).is_err() {
            return Err(SweepError::Setting { field: "prbs_degree (2 to 20)", value: self.prbs_degree as f32 });
        }
        if self.prbs_divider == 0 {
            return Err(SweepError::Setting { field: "prbs_divider", value: 0.0 });
        }
        finite_positive("prbs_seconds", self.prbs_seconds)?;
        finite_non_negative("precision_db", self.precision_db)?;
        finite_non_negative("dither", self.dither)?;
        finite_non_negative("time_budget_s", self.time_budget_s)?;
        if self.max_extensions > MAX_EXTENSIONS {
            return Err(SweepError::Setting {
                field: "max_extensions (at most 64)",
                value: self.max_extensions as f32,
            });
        }
        // Bounds that keep every tick count far from overflow (`crate::ranges`): at most
        // 10⁴ s or 10⁴ cycles from 1 mHz per record, 2·10¹² ticks at 200 kHz.
        let range = |field, value: f32, min: f32, max: f32| {
            if value >= min && value <= max {
                Ok(())
            } else {
                Err(SweepError::Range { field, value, min, max })
            }
        };
        use crate::ranges::{MAX_SWEEP_CYCLES, MAX_SWEEP_DIVIDER, MAX_SWEEP_SECONDS, MIN_SWEEP_HZ};
        range("start_hz", self.start_hz, MIN_SWEEP_HZ, f32::MAX)?;
        if self.extra_hz != 0.0 {
            range("extra_hz (0 or above)", self.extra_hz, MIN_SWEEP_HZ, f32::MAX)?;
        }
        range("settle_cycles", self.settle_cycles, 0.0, MAX_SWEEP_CYCLES)?;
        range("measure_cycles", self.measure_cycles, 0.0, MAX_SWEEP_CYCLES)?;
        range("min_settle_s", self.min_settle_s, 0.0, MAX_SWEEP_SECONDS)?;
        range("min_measure_s", self.min_measure_s, 0.0, MAX_SWEEP_SECONDS)?;
        range("prbs_seconds", self.prbs_seconds, 0.0, MAX_SWEEP_SECONDS)?;
        range("time_budget_s", self.time_budget_s, 0.0, MAX_SWEEP_SECONDS)?;
        range("dither", self.dither, 0.0, MAX_SWEEP_DITHER)?;
        range("acquisition_divider", self.acquisition_divider as f32, 1.0, MAX_SWEEP_DIVIDER as f32)?;
        range("prbs_divider", self.prbs_divider as f32, 1.0, MAX_SWEEP_DIVIDER as f32)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FS: f32 = 16_000.0;

    /// The record-length check evaluates two frequencies, not every one: it refuses every
    /// setting where some planned frequency's record is too short (checked one by one here),
    /// and accepts those where none is, up to the frequencies it takes as the stretches' tops.
    #[test]
    fn the_record_length_check_finds_every_too_short_record() {
        let mut refused_right = 0;
        for min_measure_s in [0.0, 0.001, 0.002, 0.004, 0.04] {
            for measure_cycles in [0.5, 1.0, 2.0, 8.0] {
                for (start_hz, stop_hz, points, extra_hz) in [
                    (10.0, 3000.0, 40, 2000.0),
                    (100.0, 900.0, 7, 0.0),
                    (1500.0, 3000.0, 3, 0.0),
                    (300.0, 300.0, 1, 0.0),
                ] {
                    for acquisition_divider in [2, 4, 8] {
                        let p = SweepParams {
                            min_measure_s,
                            measure_cycles,
                            start_hz,
                            stop_hz,
                            points,
                            extra_hz,
                            acquisition_divider,
                            ..Default::default()
                        };
                        let plan = p.plan();
                        let short = (0..plan.count as usize)
                            .any(|i| p.record_length(p.frequency_in(&plan, i), FS).1 < MIN_RECORD_SAMPLES);
                        let refused = matches!(p.records_long_enough(FS), Err(SweepError::RecordTooShort { .. }));
                        assert!(!short || refused, "{p:?}: a planned record is too short and the check passed it");
                        // Where every planned frequency is fine, it refuses only if a stretch's
                        // top (not a planned frequency) would be short.
                        if refused && !short {
                            let Err(SweepError::RecordTooShort { frequency, .. }) = p.records_long_enough(FS) else {
                                unreachable!()
                            };
                            assert!(frequency < 0.5 * p.threshold(FS), "{p:?}");
                        }
                        refused_right += (short && refused) as u32;
                    }
                }
            }
        }
        assert!(refused_right > 20, "{refused_right} too-short settings refused: the grid must exercise them");
    }

    #[test]
    fn bad_settings_are_named() {
        let v = |p: SweepParams| p.validate(FS, 2);
        assert_eq!(
            v(SweepParams { stop_hz: 4000.0, ..Default::default() }),
            Err(SweepError::AboveLoopNyquist {
                field: "stop_hz",
                frequency: 4000.0,
                nyquist: 4000.0,
                rate: "current_loop_hz / velocity_divider"
            })
        );
        assert!(matches!(
            v(SweepParams { amplitude: f32::NAN, ..Default::default() }),
            Err(SweepError::Setting { field: "amplitude", .. })
        ));
        assert_eq!(
            v(SweepParams { amplitude: 1e6, ..Default::default() }),
            Err(SweepError::Range { field: "amplitude", value: 1e6, min: 0.0, max: crate::ranges::MAX_SPEED })
        );
        // Two cycles without a shortest measurement: three samples at 3 kHz (4 kHz acquisition).
        assert_eq!(
            v(SweepParams { min_measure_s: 0.0, ..Default::default() }),
            Err(SweepError::RecordTooShort { frequency: 3000.0, samples: 3 })
        );

        assert_eq!(v(SweepParams { min_measure_s: 0.0, measure_cycles: 8.0, ..Default::default() }), Ok(()));
        assert_eq!(
            v(SweepParams { acquisition_divider: 3, ..Default::default() }),
            Err(SweepError::AcquisitionDivider { acquisition: 3, velocity: 2 })
        );
        assert_eq!(v(SweepParams { points: 200, ..Default::default() }), Err(SweepError::TooManyPoints(200)));
        // One point: start_hz alone (stop_hz unused), the only frequency of the plan.
        let one = SweepParams { points: 1, start_hz: 20.0, stop_hz: 20.0, extra_hz: 0.0, ..Default::default() };
        assert_eq!(v(one), Ok(()));
        assert_eq!((one.count(), one.frequency(0)), (1, 20.0));
        assert!(matches!(v(SweepParams { points: 0, ..one }), Err(SweepError::Setting { field: "points", .. })));
        assert_eq!(
            v(SweepParams { start_hz: 5000.0, ..one }),
            Err(SweepError::AboveLoopNyquist {
                field: "start_hz",
                frequency: 5000.0,
                nyquist: 4000.0,
                rate: "current_loop_hz / velocity_divider"
            })
        );
        assert!(matches!(
            v(SweepParams { dither: f32::NAN, ..Default::default() }),
            Err(SweepError::Setting { field: "dither", .. })
        ));
        assert!(matches!(
            v(SweepParams { dither: 2000.0, ..Default::default() }),
            Err(SweepError::Range { field: "dither", .. })
        ));
        assert_eq!(v(SweepParams::default()), Ok(()));
        // A budget past 2³⁰ ticks is refused at the rate that makes it so, not ignored.
        let long = SweepParams { time_budget_s: 9000.0, ..Default::default() };
        assert_eq!(v(long), Ok(()));
        assert!(matches!(
            long.validate(200_000.0, 2),
            Err(SweepError::Range { field: "time_budget_s", value: 9000.0, .. })
        ));
        assert_eq!(SweepParams { time_budget_s: 0.0, ..long }.validate(200_000.0, 2), Ok(()));
    }

    #[test]
    fn the_acceleration_measure_is_refused_without_torque_or_position_injection() {
        let v = |p: SweepParams| p.validate(FS, 2);
        let acceleration = SweepParams { measure: SweepMeasure::MachineAcceleration, ..Default::default() };
        for point in [InjectionPoint::Off, InjectionPoint::VelocityCommand, InjectionPoint::VelocityFeedback] {
            assert_eq!(
                v(SweepParams { point, ..acceleration }),
                Err(SweepError::MeasureNeedsTorqueOrPositionInjection)
            );
        }
        assert_eq!(v(SweepParams { point: InjectionPoint::TorqueCommand, ..acceleration }), Ok(()));
        assert_eq!(v(SweepParams { point: InjectionPoint::PositionCommand, ..acceleration }), Ok(()));
    }
}
