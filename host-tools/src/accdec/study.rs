//! Acc/dec filter study (seed 003): velocity, acceleration and jerk of a move through the
//! Butterworth and the moving-average filters, their delays, and the residual vibration they
//! leave on the FMU's two-inertia load.
//!
//! The filters are the control core's own ([`control_core::acc_dec`]); the shapes come from
//! two runs of each: the drive's whole-pulse output (what the position loop follows) and the
//! same transfer function in f64 without rounding (the ideal shape, free of the ±1-pulse
//! quantisation that dominates a numerically differentiated jerk).

use anyhow::{anyhow, bail, Result};
use control_core::acc_dec::reference::ReferenceFilter;
use control_core::acc_dec::{
    AccDecFilter, AccDecKind, ButterworthDesign, ButterworthPulseFilter, MovingAverageCascade, ZeroPlacement,
    MAX_MOVING_AVERAGE_LENGTH,
};
use control_core::axis::Mode;
use control_core::command_path::{CommandPath, Move};
use serde::Serialize;
use servo_axis::variables::name;

use crate::fmu::runner::Fmu;
use crate::fmu::scenario::{Event, Scenario, Value};
use crate::fmu::trace::Trace;

/// Which filter, with its settings.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum FilterSpec {
    Butterworth { order: u32, cutoff_hz: f32, all_delays: bool },
    MovingAverage { lengths: Vec<u32> },
}

impl FilterSpec {
    pub fn butterworth(order: u32, cutoff_hz: f32) -> Self {
        Self::Butterworth { order, cutoff_hz, all_delays: false }
    }

    pub fn label(&self) -> String {
        match self {
            Self::Butterworth { order, cutoff_hz, all_delays } => format!(
                "Butterworth order {order}, {cutoff_hz} Hz{}",
                if *all_delays { " (zeros as delays)" } else { "" }
            ),
            Self::MovingAverage { lengths } => format!(
                "{} x moving average {}",
                lengths.len(),
                lengths.iter().map(u32::to_string).collect::<Vec<_>>().join("/")
            ),
        }
    }

    pub fn design(&self, period: f32) -> Result<Option<ButterworthDesign>> {
        match self {
            Self::Butterworth { order, cutoff_hz, all_delays } => {
                let zeros = if *all_delays { ZeroPlacement::AllDelays } else { ZeroPlacement::Seed };
                ButterworthDesign::with_zeros(*order, *cutoff_hz, period, zeros).map(Some).map_err(|e| anyhow!("{e}"))
            }
            Self::MovingAverage { .. } => Ok(None),
        }
    }

    /// The drive's filter, as the command path runs it.
    pub fn build(&self, period: f32) -> Result<AccDecFilter> {
        Ok(match self {
            Self::Butterworth { .. } => {
                AccDecFilter::Butterworth(ButterworthPulseFilter::new(self.design(period)?.expect("a design")))
            }
            Self::MovingAverage { lengths } => {
                AccDecFilter::MovingAverage(MovingAverageCascade::new(lengths).map_err(|e| anyhow!("{e}"))?)
            }
        })
    }

    /// FMU parameters selecting this filter.
    pub fn fmu_parameters(&self) -> Result<Vec<(String, Value)>> {
        Ok(match self {
            Self::Butterworth { all_delays: true, .. } => {
                bail!("the FMU's Butterworth keeps the seed's zeros (N-1 at z = -1); zeros-as-delays runs on the host only")
            }
            Self::Butterworth { order, cutoff_hz, .. } => vec![
                (name::accdec_filter.into(), Value::code(AccDecKind::Butterworth.code())),
                (name::accdec_order.into(), Value::Int(*order as i64)),
                (name::accdec_cutoff_hz.into(), Value::Float(*cutoff_hz as f64)),
            ],
            Self::MovingAverage { lengths } => {
                let mut v = vec![
                    (name::accdec_filter.into(), Value::code(AccDecKind::MovingAverage.code())),
                    (name::accdec_ma_stages.into(), Value::Int(lengths.len() as i64)),
                ];
                // More than three stages: accdec.ma_stages says so and the FMU refuses it.
                for (l, n) in lengths.iter().zip(servo_axis::parameters::MOVING_AVERAGE_LENGTHS) {
                    v.push((n.to_string(), Value::Int(*l as i64)));
                }
                v
            }
        })
    }

    /// The same transfer function in f64 without rounding: the ideal output for `input`.
    pub fn ideal_response(&self, period: f32, input: &[f64]) -> Result<Vec<f64>> {
        // Refuse what the drive would refuse (length 0, order 7, …) with its reason.
        self.build(period)?;
        match self {
            Self::Butterworth { order, cutoff_hz, all_delays } => {
                // The designed filter in f64 (the reference the drive's integer filter is
                // checked against), without the drive's rounding to whole pulses.
                let zeros = if *all_delays { ZeroPlacement::AllDelays } else { ZeroPlacement::Seed };
                let mut f = ReferenceFilter::new(*order, *cutoff_hz as f64, period as f64, zeros);
                Ok(input.iter().map(|&x| f.step(x).0).collect())
            }
            Self::MovingAverage { lengths } => {
                let mut v = input.to_vec();
                for &l in lengths {
                    let l = l as usize;
                    let mut sum = 0.0;
                    let mut out = Vec::with_capacity(v.len());
                    for k in 0..v.len() {
                        sum += v[k];
                        if k >= l {
                            sum -= v[k - l];
                        }
                        out.push(sum / l as f64);
                    }
                    v = out;
                }
                Ok(v)
            }
        }
    }
}

/// Delay of a filter: its response to a velocity step (a jog starting at tick 0).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Delay {
    /// First time the output velocity reaches half the commanded one (s).
    pub t50: f64,
    /// Time after which the output velocity stays within 1 % of the commanded one (s).
    pub t99: f64,
    /// Largest velocity overshoot (fraction of the commanded velocity).
    pub overshoot: f64,
}

pub fn delay(spec: &FilterSpec, period: f32) -> Result<Delay> {
    // Long enough for the slowest allowed filter: 3 × 512 ticks, or a Butterworth at a low
    // cut-off (extended until the tail is inside 1 %).
    let mut n = 4096;
    loop {
        let y = spec.ideal_response(period, &vec![1.0; n])?;
        let t50 = y.iter().position(|&v| v >= 0.5);
        let last_out = y.iter().rposition(|&v| (v - 1.0).abs() > 0.01);
        let settled_for = n - last_out.map_or(0, |k| k + 1);
        if let (Some(k50), true) = (t50, settled_for > n / 4) {
            let overshoot = y.iter().fold(0.0f64, |m, &v| m.max(v - 1.0));
            let t = period as f64;
            return Ok(Delay { t50: k50 as f64 * t, t99: last_out.map_or(0, |k| k + 1) as f64 * t, overshoot });
        }
        if n > 1 << 22 {
            bail!("{}: the velocity-step response does not settle within {n} ticks", spec.label());
        }
        n *= 4;
    }
}

/// Which delay two filters are matched on.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum DelayMatch {
    /// Equal time to 50 % of the commanded velocity (s).
    T50(f64),
    /// Equal time until within 1 % for good (s).
    T99(f64),
}

impl DelayMatch {
    fn seconds(self) -> f64 {
        let (Self::T50(t) | Self::T99(t)) = self;
        t
    }

    fn name(self) -> &'static str {
        match self {
            Self::T50(_) => "50 %",
            Self::T99(_) => "99 %",
        }
    }
}

/// No cascade of moving averages within the drive's limit ([`MAX_MOVING_AVERAGE_LENGTH`] ticks
/// a stage) has the delay asked for to one tick: a comparison with the closest would not be at
/// equal delay.
#[derive(Clone, Debug, PartialEq)]
pub struct NoEqualDelay {
    pub target: DelayMatch,
    pub period: f32,
    /// The cascade whose delay comes closest, and that delay (s).
    pub closest: FilterSpec,
    pub closest_delay: f64,
}

impl std::fmt::Display for NoEqualDelay {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let stages = match &self.closest {
            FilterSpec::MovingAverage { lengths } => lengths.len(),
            FilterSpec::Butterworth { .. } => 0,
        };
        write!(
            f,
            "no cascade of {stages} moving averages within the drive's limit of {MAX_MOVING_AVERAGE_LENGTH} ticks a stage ({:.1} ms at T = {} ms) has the Butterworth's {} delay of {:.1} ms (to one tick): the closest, {}, has {:.1} ms, so a comparison would not be at equal delay",
            MAX_MOVING_AVERAGE_LENGTH as f64 * self.period as f64 * 1e3,
            self.period * 1e3,
            self.target.name(),
            self.target.seconds() * 1e3,
            self.closest.label(),
            self.closest_delay * 1e3
        )
    }
}

impl std::error::Error for NoEqualDelay {}

/// Three equal (or nearly equal: lengths differ by at most one) moving averages with the 99 %
/// delay `t99` (to one tick); an error holding a [`NoEqualDelay`] when there are none.
pub fn matching_moving_average(t99: f64, period: f32, stages: usize) -> Result<FilterSpec> {
    moving_average_matched_on(DelayMatch::T99(t99), period, stages)
}

/// `stages` equal (or nearly equal) moving averages whose delay is `target` to one tick (the
/// closest); an error holding a [`NoEqualDelay`] when none within the drive's limit is.
pub fn moving_average_matched_on(target: DelayMatch, period: f32, stages: usize) -> Result<FilterSpec> {
    let t = target.seconds();
    let mut best: Option<(f64, f64, FilterSpec)> = None;
    for base in 1..=MAX_MOVING_AVERAGE_LENGTH {
        for extra in 0..stages {
            let lengths: Vec<u32> = (0..stages).map(|i| base + u32::from(i >= stages - extra)).collect();
            if lengths.iter().any(|&l| l > MAX_MOVING_AVERAGE_LENGTH) {
                continue;
            }
            let spec = FilterSpec::MovingAverage { lengths };
            let d = delay(&spec, period)?;
            let reached = match target {
                DelayMatch::T50(_) => d.t50,
                DelayMatch::T99(_) => d.t99,
            };
            let err = (reached - t).abs();
            if best.as_ref().is_none_or(|(e, ..)| err < *e) {
                best = Some((err, reached, spec));
            }
        }
        // Both delays grow with the length and exceed one window: stop once past the target.
        if base as f64 * period as f64 > t + 1e-12 {
            break;
        }
    }
    let (err, reached, spec) = best.ok_or_else(|| anyhow!("no moving average matches a delay of {target:?} s"))?;
    // The cascades' delays are whole ticks: within one tick is equal.
    if err > period as f64 * (1.0 + 1e-6) {
        return Err(NoEqualDelay { target, period, closest: spec, closest_delay: reached }.into());
    }
    Ok(spec)
}

/// A positioning move in encoder counts, as the drive's interpolator gets it.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct PulseMove {
    pub distance: i64,
    /// Counts per position tick.
    pub speed: f32,
}

/// One filter's response to a move, tick by tick.
#[derive(Clone, Debug)]
pub struct Profile {
    pub period: f64,
    /// Interpolator pulses per tick (before the filter).
    pub input: Vec<i64>,
    /// The drive's whole-pulse output.
    pub output: Vec<i64>,
    /// The unrounded output of the same transfer function.
    pub ideal: Vec<f64>,
}

/// Shape figures of one profile (counts, seconds).
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ShapeFigures {
    pub peak_velocity: f64,
    pub peak_acceleration: f64,
    pub peak_jerk: f64,
    /// Same, from the whole-pulse output (quantisation included).
    pub peak_jerk_pulses: f64,
    /// Time from the start of the move until the interpolator has sent its last pulse.
    pub interpolation_end: f64,
    /// Time from the start of the move until the filtered position is on target for good
    /// (the whole-pulse tail of a Butterworth can trickle well past its 99 % delay).
    pub arrival: f64,
    /// Sum of the output pulses minus the sum of the input pulses (must be 0).
    pub pulse_balance: i64,
}

pub fn profile(spec: &FilterSpec, period: f32, m: PulseMove, settle_ticks: usize) -> Result<Profile> {
    let mut path = CommandPath::new(spec.build(period)?);
    path.reset(0);
    let motion = Move::Absolute { target: m.distance, speed: m.speed };
    let (mut input, mut output) = (Vec::new(), Vec::new());
    let mut quiet = 0;
    while quiet < settle_ticks {
        let before = path.interpolated();
        path.step(motion, 0);
        input.push(path.interpolated() - before);
        output.push(path.pulses());
        quiet = if path.position() == m.distance && path.pulses() == 0 && path.interpolated() == m.distance {
            quiet + 1
        } else {
            0
        };
        if input.len() > 50_000_000 {
            bail!("the move does not end: distance {} counts at {} counts per tick", m.distance, m.speed);
        }
    }
    let ideal = spec.ideal_response(period, &input.iter().map(|&x| x as f64).collect::<Vec<_>>())?;
    Ok(Profile { period: period as f64, input, output, ideal })
}

fn derivative(v: &[f64], period: f64) -> Vec<f64> {
    let mut prev = 0.0;
    v.iter()
        .map(|&x| {
            let d = (x - prev) / period;
            prev = x;
            d
        })
        .collect()
}

impl Profile {
    /// Velocity, acceleration, jerk (counts/s, /s², /s³) of the ideal output.
    pub fn ideal_kinematics(&self) -> [Vec<f64>; 3] {
        let v: Vec<f64> = self.ideal.iter().map(|p| p / self.period).collect();
        let a = derivative(&v, self.period);
        let j = derivative(&a, self.period);
        [v, a, j]
    }

    pub fn figures(&self) -> ShapeFigures {
        let peak = |x: &[f64]| x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let [v, a, j] = self.ideal_kinematics();
        let vp: Vec<f64> = self.output.iter().map(|&p| p as f64 / self.period).collect();
        let jp = derivative(&derivative(&vp, self.period), self.period);
        let mut position = 0i64;
        let target: i64 = self.input.iter().sum();
        let mut arrival = 0;
        for (k, p) in self.output.iter().enumerate() {
            position += p;
            if position != target || *p != 0 {
                arrival = k + 1;
            }
        }
        ShapeFigures {
            peak_velocity: peak(&v),
            peak_acceleration: peak(&a),
            peak_jerk: peak(&j),
            peak_jerk_pulses: peak(&jp),
            interpolation_end: self.input.iter().rposition(|&p| p != 0).map_or(0, |k| k + 1) as f64 * self.period,
            arrival: arrival as f64 * self.period,
            pulse_balance: self.output.iter().sum::<i64>() - target,
        }
    }

    /// Columns time, input and output pulses, ideal velocity, acceleration, jerk.
    pub fn trace(&self, scale_to_rad: f64) -> Trace {
        let [v, a, j] = self.ideal_kinematics();
        let mut t = Trace::new(
            ["time", "input_pulses", "output_pulses", "velocity", "acceleration", "jerk", "command_velocity"]
                .map(String::from)
                .to_vec(),
        );
        for k in 0..self.input.len() {
            t.rows.push(vec![
                (k + 1) as f64 * self.period,
                self.input[k] as f64,
                self.output[k] as f64,
                v[k] * scale_to_rad,
                a[k] * scale_to_rad,
                j[k] * scale_to_rad,
                self.input[k] as f64 / self.period * scale_to_rad,
            ]);
        }
        t
    }
}

/// A load resonance of the FMU plant: the load's natural frequency against a locked motor,
/// `f = √(k/J_L)/2π`, with a damping ratio; friction is switched off so that what remains
/// after a move is the filter's doing.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct Resonance {
    pub hz: f64,
    pub damping_ratio: f64,
}

impl Resonance {
    pub fn plant_parameters(&self) -> Result<Vec<(String, Value)>> {
        if !(self.hz.is_finite() && self.hz > 0.0 && self.damping_ratio.is_finite() && self.damping_ratio >= 0.0) {
            bail!(
                "a load resonance needs a positive frequency and a damping ratio >= 0 (got {} Hz, {})",
                self.hz,
                self.damping_ratio
            );
        }
        let load_inertia = servo_axis::plant::PlantParams::default().load_inertia;
        let w = std::f64::consts::TAU * self.hz;
        Ok(vec![
            (name::plant_shaft_stiffness.into(), Value::Float(load_inertia * w * w)),
            (name::plant_shaft_damping.into(), Value::Float(2.0 * self.damping_ratio * load_inertia * w)),
            (name::plant_motor_coulomb.into(), Value::Float(0.0)),
            (name::plant_load_coulomb.into(), Value::Float(0.0)),
        ])
    }
}

/// What a move leaves behind on the load.
#[derive(Clone, Debug, Serialize)]
pub struct Vibration {
    pub filter: String,
    pub resonance_hz: f64,
    /// When the filtered command is on target for good (s after the move starts).
    pub arrival: f64,
    /// Start of the residual window: end of interpolation + the filter's 99 % delay (s).
    pub window_start: f64,
    /// Residual vibration: largest shaft twist |θ_load − θ_motor| from the window start to
    /// the end of the run (rad). Without friction the twist at rest is zero, so this is the
    /// amplitude of the load's oscillation against the motor that the move left behind.
    pub residual: f64,
    /// Largest |θ_load − target| during the whole run (rad), for scale.
    pub peak_error: f64,
}

/// FMU parameters that put its position loop at `period` (a whole number of 62.5 µs ticks).
pub fn position_period_parameters(period: f64) -> Result<Vec<(String, Value)>> {
    let defaults = control_core::Params::default();
    let tick = 1.0 / defaults.rates.current_loop_hz as f64;
    let divider = (period / tick).round();
    if !((1.0..=1000.0).contains(&divider) && (divider * tick - period).abs() <= 1e-6 * period) {
        bail!("the FMU's position loop runs at whole multiples of its {} µs tick; {period} s is not one", tick * 1e6);
    }
    Ok(vec![(name::ctrl_position_divider.into(), Value::Int(divider as i64))])
}

/// `period` snapped to the FMU's tick grid (an f32 period converted to f64 is off by ~1e-8).
fn divider_step(period: f64) -> f64 {
    let tick = 1.0 / control_core::Params::default().rates.current_loop_hz as f64;
    (period / tick).round() * tick
}

/// Run the move on the FMU (position mode, the filter between command and position loop,
/// position loop at `period`) and measure the load's residual vibration from `window_start`
/// (s after the move starts; at equal delay, the same for both filters) until `duration`.
pub fn residual_vibration(
    fmu: &Fmu,
    spec: &FilterSpec,
    resonance: Resonance,
    period: f64,
    distance_rad: f64,
    speed_rad_s: f64,
    (window_start, duration): (f64, f64),
) -> Result<(Vibration, Trace)> {
    let mut parameters: std::collections::BTreeMap<String, Value> = spec.fmu_parameters()?.into_iter().collect();
    parameters.extend(resonance.plant_parameters()?);
    parameters.extend(position_period_parameters(period)?);
    let step = divider_step(period);
    let steps = (duration / step).ceil();
    let scenario = Scenario {
        name: "accdec_move".into(),
        description: format!("{} on a {} Hz load resonance", spec.label(), resonance.hz),
        stop_time: steps * step,
        step: Some(step),
        parameters,
        events: vec![Event {
            time: 0.0,
            inputs: [
                ("mode".to_string(), Value::code(Mode::Position.code())),
                ("move_speed".to_string(), Value::Float(speed_rad_s)),
                ("position_command".to_string(), Value::Float(distance_rad)),
            ]
            .into_iter()
            .collect(),
        }],
        checks: vec![],
        plot: vec![],
        record: vec![],
    };
    let mut trace = fmu.run(&scenario, |_| {})?;
    let col = |n: &str| trace.column(n).ok_or_else(|| anyhow!("the FMU has no output {n}"));
    let (time, command) = (col("time")?, col("position_command_out")?);
    let (load, motor) = (col("load_position")?, col("motor_position")?);
    let target = *command.last().unwrap_or(&0.0);
    let on_target_from = command.iter().rposition(|&c| c != target).map_or(0, |k| k + 1);
    if on_target_from + 1 >= command.len() {
        bail!("{}: the command does not reach its target within {duration} s; simulate longer", spec.label());
    }
    let err = |k: usize| (load[k] - target).abs();
    let from = time.iter().position(|&t| t >= window_start - 0.5 * step).unwrap_or(time.len());
    if from + 1 >= time.len() {
        bail!("the residual window starts at {window_start} s, after the end of the run ({duration} s)");
    }
    let residual = (from..load.len()).map(|k| (load[k] - motor[k]).abs()).fold(0.0, f64::max);
    let peak_error = (0..load.len()).map(err).fold(0.0, f64::max);
    trace.columns.extend(["load_error".into(), "shaft_twist".into()]);
    let narrow = std::mem::take(&mut trace.rows);
    trace.rows = crate::fmu::trace::Rows::new(trace.columns.len());
    for ((row, l), m) in narrow.iter().zip(&load).zip(&motor) {
        trace.rows.push_from(row.iter().copied().chain([l - target, l - m]));
    }
    Ok((
        Vibration {
            filter: spec.label(),
            resonance_hz: resonance.hz,
            arrival: time[on_target_from],
            window_start: time[from],
            residual,
            peak_error,
        },
        trace,
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A delay the drive's moving averages reach is matched to one tick (checked on the
    /// cascade's own step response); one beyond three stages of 512 ticks is refused with the
    /// closest cascade, never returned as a match.
    #[test]
    fn a_delay_beyond_the_longest_cascade_is_no_match() {
        let period = 0.00025f32;
        let t99 = 0.1;
        let ma = matching_moving_average(t99, period, 3).expect("reachable");
        assert!((delay(&ma, period).unwrap().t99 - t99).abs() <= period as f64 * 1.000001, "{ma:?}");
        let longest = FilterSpec::MovingAverage { lengths: vec![MAX_MOVING_AVERAGE_LENGTH; 3] };
        let reach = delay(&longest, period).unwrap().t99;
        let e = matching_moving_average(reach + 3.0 * period as f64, period, 3).unwrap_err();
        let no = e.downcast_ref::<NoEqualDelay>().expect("a NoEqualDelay");
        assert_eq!(no.closest, longest);
        assert!(e.to_string().contains("512 ticks") && e.to_string().contains("not be at equal delay"), "{e}");
        assert!(matching_moving_average(reach, period, 3).is_ok());
    }

    /// `servo bench accdec`'s comparisons (the default Butterworth, matched on its 99 % and on
    /// its 50 % delay) are at equal delay to one tick.
    #[test]
    fn the_benchs_matches_are_at_equal_delay() {
        let period = 0.00025f32;
        let bw = FilterSpec::butterworth(3, crate::accdec::report::default_cutoff_hz());
        let bd = delay(&bw, period).unwrap();
        for target in [DelayMatch::T99(bd.t99), DelayMatch::T50(bd.t50)] {
            let ma = moving_average_matched_on(target, period, 3).expect("matched");
            let md = delay(&ma, period).unwrap();
            let reached = if matches!(target, DelayMatch::T99(_)) { md.t99 } else { md.t50 };
            assert!((reached - target.seconds()).abs() <= period as f64 * 1.000001, "{target:?}: {ma:?}");
        }
    }
}
