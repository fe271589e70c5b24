//! Circle tests (seed 002) on the FMU: the classic two-axis XY circle, and the single-axis
//! pseudo-circle — one axis driven with a sine, its feedback plotted against its own copy a
//! quarter period later, `(x(t), x(t − T/4))`, which for a linear axis is exactly the circle
//! two identical axes would draw.
//!
//! Geometry (angles in radians of the motor or the load, as an axis of the machine):
//! - two axes, counter-clockwise: `X = R·sin ωt`, `Y = R − R·cos ωt` (centre (0, R); both
//!   axes start at rest at 0, X with the full feed); clockwise mirrors Y;
//! - one axis: `x = R·sin ωt`, figure `(x(t), x(t − T/4))` about (0, 0); the same
//!   construction on the command is the reference, and the feedback against the shifted
//!   command, `(x(t), c(t − T/4))`, is the variant.
//!
//! Axis reversals (where friction leaves its protrusions) sit at 0°, 90°, 180° and 270°
//! about the centre. The first `lead_in` revolutions settle the start transient; the last
//! revolution is measured.

use std::collections::BTreeMap;
use std::f64::consts::TAU;

use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;

use crate::fmu::axis_health::{first_trip, torque_ceiling, torque_limited, LimitedSteps, Trip};
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::{Scenario, Value, DEFAULT_STEP};
use crate::fmu::trace::Trace;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Direction {
    CounterClockwise,
    Clockwise,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
pub enum Measure {
    /// Machine-end (load) position.
    Load,
    Motor,
}

impl Measure {
    fn column(self) -> &'static str {
        match self {
            Self::Load => "load_position",
            Self::Motor => "motor_position",
        }
    }
}

#[derive(Clone, Debug)]
pub struct CircleRequest {
    /// Radius (rad of axis travel).
    pub radius: f64,
    /// Tangential speed (rad/s).
    pub feed: f64,
    pub direction: Direction,
    /// Revolutions before the measured one.
    pub lead_in: u32,
    pub measure: Measure,
    /// FMU parameters per axis (X, Y); the single-axis test uses X's.
    pub x_parameters: BTreeMap<String, Value>,
    pub y_parameters: BTreeMap<String, Value>,
}

/// The most steps one axis's run may take (its lead-in and measured revolutions). While a run
/// lasts, each step keeps about 0.7 kB per axis in memory (a trace row of the FMU's outputs,
/// the streamed command's event) and the run writes about 0.4 kB of trace CSV per step and
/// axis (measured: a two-axis run of 404 000 steps per axis peaked at 580 MB and wrote
/// 320 MB). 500 000 steps, 125 s of simulated time at 250 µs, keep a two-axis run under about
/// 0.7 GB of memory and 0.4 GB of files (a few seconds), and still take a slow circle of a
/// minute per revolution with a lead-in revolution.
pub const MAX_RUN_STEPS: usize = 500_000;

/// What one step of one axis costs, as [`MAX_RUN_STEPS`] says, for the messages.
const STEP_COST: &str = "each step keeps about 0.7 kB per axis in memory and writes 0.4 kB of trace";

impl CircleRequest {
    /// ω, period and samples per revolution; refuses what cannot make a circle test, or would
    /// take more than [`MAX_RUN_STEPS`] steps per axis.
    pub fn timing(&self) -> Result<(f64, f64, usize)> {
        if !(self.radius.is_finite() && self.radius > 0.0) {
            bail!("radius must be a positive number of radians (got {})", self.radius);
        }
        if !(self.feed.is_finite() && self.feed > 0.0) {
            bail!("feed must be a positive speed in rad/s (got {})", self.feed);
        }
        let omega = self.feed / self.radius;
        let period = TAU / omega;
        let samples = period / DEFAULT_STEP;
        if samples < 8.0 {
            bail!(
                "feed {} rad/s on radius {} rad gives {samples:.2} samples per revolution at {} s: at least 8 are needed (lower the feed or raise the radius)",
                self.feed,
                self.radius,
                DEFAULT_STEP
            );
        }
        if samples > MAX_RUN_STEPS as f64 {
            bail!(
                "--radius {} rad at --feed {} rad/s makes a revolution of {period:.4e} s, {samples:.4e} samples of {DEFAULT_STEP} s: a run takes at most {MAX_RUN_STEPS} samples per axis ({} s; {STEP_COST}): lower the radius or raise the feed",
                self.radius,
                self.feed,
                MAX_RUN_STEPS as f64 * DEFAULT_STEP
            );
        }
        let n = samples.round();
        if (samples - n).abs() > 1e-6 * samples {
            bail!(
                "the revolution ({period} s) is not a whole number of {DEFAULT_STEP} s samples ({samples:.4}): choose feed = radius·2π / (k·{DEFAULT_STEP} s)"
            );
        }
        let n = n as usize;
        self.run_steps(n, self.lead_in)?;
        Ok((omega, period, n))
    }

    /// Steps of a run of `lead_in` revolutions and the measured one, `n` samples each; refused
    /// over [`MAX_RUN_STEPS`], naming the largest lead-in that fits.
    fn run_steps(&self, n: usize, lead_in: u32) -> Result<usize> {
        let revolutions = lead_in as usize + 1;
        let steps = n.saturating_mul(revolutions);
        if steps > MAX_RUN_STEPS {
            bail!(
                "--lead-in {lead_in}: {revolutions} revolutions of {n} samples are {steps} samples per axis, over the limit of {MAX_RUN_STEPS} ({} s of simulated time; {STEP_COST}): at most --lead-in {} at this radius and feed",
                MAX_RUN_STEPS as f64 * DEFAULT_STEP,
                (MAX_RUN_STEPS / n).saturating_sub(1)
            );
        }
        Ok(steps)
    }

    /// The single-axis test also needs T/4 to be whole samples.
    pub fn quarter(&self) -> Result<usize> {
        let (_, period, n) = self.timing()?;
        if n % 4 != 0 {
            bail!("a quarter period ({} s) is not a whole number of samples: {n} samples per revolution is not a multiple of 4", period / 4.0);
        }
        Ok(n / 4)
    }

    /// Each axis's parameters as the FMU takes them (known names, parameters only, types,
    /// ranges, the core's own rules), checked before anything runs.
    pub fn check_parameters(&self) -> Result<()> {
        for (axis, p) in [("x", &self.x_parameters), ("y", &self.y_parameters)] {
            configuration(p).with_context(|| format!("axis {axis}"))?;
        }
        Ok(())
    }
}

/// Figures of one closed figure about its centre.
#[derive(Clone, Debug, Serialize)]
pub struct Roundness {
    /// max − min radius (rad).
    pub roundness: f64,
    /// Mean radius − nominal radius (rad).
    pub mean_radius_error: f64,
    /// Per quadrant point (0°, 90°, 180°, 270°): (angle of the peak in degrees, height above
    /// the median radial error in rad) within ±`QUADRANT_WINDOW` degrees; None where no point
    /// of the figure lies within that window (the figure does not go round there).
    pub protrusions: Vec<Option<(f64, f64)>>,
    /// Largest protrusion height (rad); None unless all four quadrants were measured.
    pub max_protrusion: Option<f64>,
    /// Why some protrusions could not be measured (None when all were).
    pub not_measurable: Option<String>,
}

pub const QUADRANT_WINDOW: f64 = 20.0;

/// A figure: points and its centre.
#[derive(Clone, Debug, Default)]
pub struct Figure {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub centre: (f64, f64),
}

impl Figure {
    /// Angle about the centre (degrees, 0..360) and radius of each point.
    pub fn polar(&self) -> Vec<(f64, f64)> {
        self.x
            .iter()
            .zip(&self.y)
            .map(|(x, y)| {
                let (dx, dy) = (x - self.centre.0, y - self.centre.1);
                (dy.atan2(dx).to_degrees().rem_euclid(360.0), dx.hypot(dy))
            })
            .collect()
    }

    pub fn roundness(&self, radius: f64) -> Roundness {
        let polar = self.polar();
        let errors: Vec<f64> = polar.iter().map(|(_, r)| r - radius).collect();
        let max = errors.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
        let min = errors.iter().cloned().fold(f64::INFINITY, f64::min);
        let mean = errors.iter().sum::<f64>() / errors.len().max(1) as f64;
        let mut sorted = errors.clone();
        sorted.sort_by(f64::total_cmp);
        let median = sorted.get(sorted.len() / 2).copied().unwrap_or(0.0);
        const QUADRANTS: [f64; 4] = [0.0, 90.0, 180.0, 270.0];
        let protrusions: Vec<Option<(f64, f64)>> = QUADRANTS
            .iter()
            .map(|&q: &f64| {
                polar
                    .iter()
                    .zip(&errors)
                    .filter(|((a, _), _)| {
                        let d = (a - q + 540.0).rem_euclid(360.0) - 180.0;
                        d.abs() <= QUADRANT_WINDOW
                    })
                    .map(|((a, _), e)| (*a, e - median))
                    .fold(
                        None,
                        |best: Option<(f64, f64)>, p| if best.is_some_and(|b| b.1 >= p.1) { best } else { Some(p) },
                    )
            })
            .collect();
        let missing: Vec<String> =
            QUADRANTS.iter().zip(&protrusions).filter(|(_, p)| p.is_none()).map(|(q, _)| format!("{q}°")).collect();
        let max_protrusion =
            (missing.is_empty()).then(|| protrusions.iter().flatten().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max));
        let not_measurable = (!missing.is_empty()).then(|| {
            format!(
                "no point of the figure lies within ±{QUADRANT_WINDOW}° of {} (it does not go round the centre there)",
                missing.join(", ")
            )
        });
        Roundness { roundness: max - min, mean_radius_error: mean, protrusions, max_protrusion, not_measurable }
    }
}

impl Roundness {
    /// The protrusions in words: "4.9°: 2.29e-3, …", "not measurable" where they are not.
    pub fn protrusions_text(&self) -> String {
        self.protrusions
            .iter()
            .map(|p| match p {
                Some((a, h)) => format!("{a:.1}°: {h:.2e}"),
                None => "not measurable".into(),
            })
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// The largest protrusion in words: its height in rad, or "not measurable" and why.
    pub fn max_protrusion_text(&self) -> String {
        match (self.max_protrusion, &self.not_measurable) {
            (Some(h), _) => format!("{h:.3e} rad"),
            (None, Some(why)) => format!("not measurable: {why}"),
            (None, None) => "not measurable".into(),
        }
    }

    /// One line for a plot's notes: roundness, mean radius error, largest protrusion.
    pub fn summary(&self, label: &str) -> String {
        format!(
            "{label}: roundness {:.3e} rad, mean radius error {:+.3e} rad, largest quadrant protrusion {}",
            self.roundness,
            self.mean_radius_error,
            self.max_protrusion_text()
        )
    }
}

/// One axis's drive during a circle run: whether it tripped, and on how many steps its torque
/// command sat at its limit, over the run and over the measured revolution.
#[derive(Clone, Debug, Serialize)]
pub struct AxisHealth {
    /// "x" or "y" in the two-axis test; None for the single axis of the pseudo-circle.
    pub axis: Option<&'static str>,
    pub trip: Option<Trip>,
    /// The torque the drive cannot exceed (N·m): see [`torque_ceiling`].
    pub torque_limit_nm: f64,
    /// That limit by its parameter and value ("velocity.torque_limit = 0.05 N·m").
    pub torque_limit_by: String,
    pub torque_limited_run: LimitedSteps,
    pub torque_limited_measured: LimitedSteps,
}

impl AxisHealth {
    /// "axis x", or "the axis" of the pseudo-circle.
    pub fn name(&self) -> String {
        self.axis.map_or("the axis".into(), |a| format!("axis {a}"))
    }
}

/// The health of the axis run with `parameters` over `steps` steps, `measured` the command
/// indices of the measured revolution (trace row k+1 follows command k).
fn axis_health(
    axis: Option<&'static str>,
    trace: &Trace,
    parameters: &BTreeMap<String, Value>,
    steps: usize,
    measured: &std::ops::Range<usize>,
) -> Result<AxisHealth> {
    let ceiling = torque_ceiling(parameters)?;
    let limit = ceiling.torque as f64;
    Ok(AxisHealth {
        axis,
        trip: first_trip(trace)?,
        // As set: 0.05, not the f32's 0.05000000074505806.
        torque_limit_nm: servo_axis::variables::from_f32(ceiling.torque),
        torque_limit_by: ceiling.to_string(),
        torque_limited_run: torque_limited(trace, 1..steps + 1, limit)?,
        torque_limited_measured: torque_limited(trace, measured.start + 1..measured.end + 1, limit)?,
    })
}

/// A two-axis circle: commands and feedback over the measured revolution.
#[derive(Clone, Debug)]
pub struct CircleRun {
    pub command: Figure,
    pub feedback: Figure,
    pub traces: Vec<Trace>,
    /// X's and Y's drives during the run.
    pub health: Vec<AxisHealth>,
}

fn measured_window(total: usize, n: usize) -> std::ops::Range<usize> {
    // Trace rows: 0 is the initial state, row k+1 follows step k (command index k).
    total - n..total
}

pub fn two_axis(fmu: &Fmu, r: &CircleRequest) -> Result<CircleRun> {
    let (omega, _, n) = r.timing()?;
    let steps = r.run_steps(n, r.lead_in)?;
    let sign = if r.direction == Direction::CounterClockwise { 1.0 } else { -1.0 };
    let xc: Vec<f64> = (0..steps).map(|k| r.radius * (omega * k as f64 * DEFAULT_STEP).sin()).collect();
    let yc: Vec<f64> =
        (0..steps).map(|k| sign * (r.radius - r.radius * (omega * k as f64 * DEFAULT_STEP).cos())).collect();
    let tx = fmu.run(&Scenario::streamed_position("circle_x", &r.x_parameters, &xc), |_| {})?;
    let ty = fmu.run(&Scenario::streamed_position("circle_y", &r.y_parameters, &yc), |_| {})?;
    let fx = tx.column(r.measure.column()).ok_or_else(|| anyhow!("no {}", r.measure.column()))?;
    let fy = ty.column(r.measure.column()).ok_or_else(|| anyhow!("no {}", r.measure.column()))?;
    // Feedback row k+1 answers command k: compare each command with the position one step on.
    let w = measured_window(steps, n);
    let centre = (0.0, sign * r.radius);
    let health = vec![
        axis_health(Some("x"), &tx, &r.x_parameters, steps, &w)?,
        axis_health(Some("y"), &ty, &r.y_parameters, steps, &w)?,
    ];
    Ok(CircleRun {
        command: Figure { x: xc[w.clone()].to_vec(), y: yc[w.clone()].to_vec(), centre },
        feedback: Figure { x: w.clone().map(|k| fx[k + 1]).collect(), y: w.map(|k| fy[k + 1]).collect(), centre },
        traces: vec![tx, ty],
        health,
    })
}

/// A single-axis pseudo-circle.
#[derive(Clone, Debug)]
pub struct PseudoCircleRun {
    /// (c(t), c(t − T/4)): the reference.
    pub command: Figure,
    /// (x(t), x(t − T/4)).
    pub feedback: Figure,
    /// (x(t), c(t − T/4)).
    pub against_command: Figure,
    pub trace: Trace,
    pub scenario: Scenario,
    /// The axis's drive during the run.
    pub health: AxisHealth,
}

pub fn single_axis(fmu: &Fmu, r: &CircleRequest) -> Result<PseudoCircleRun> {
    let q = r.quarter()?;
    let (omega, _, n) = r.timing()?;
    let steps = r.run_steps(n, r.lead_in.max(1))?;
    let c: Vec<f64> = (0..steps).map(|k| r.radius * (omega * k as f64 * DEFAULT_STEP).sin()).collect();
    let scenario = Scenario::streamed_position("pseudo_circle", &r.x_parameters, &c);
    let trace = fmu.run(&scenario, |_| {})?;
    let x = trace.column(r.measure.column()).ok_or_else(|| anyhow!("no {}", r.measure.column()))?;
    let w = measured_window(steps, n);
    let health = axis_health(None, &trace, &r.x_parameters, steps, &w)?;
    let fb = |k: usize| x[k + 1];
    Ok(PseudoCircleRun {
        command: Figure {
            x: w.clone().map(|k| c[k]).collect(),
            y: w.clone().map(|k| c[k - q]).collect(),
            centre: (0.0, 0.0),
        },
        feedback: Figure {
            x: w.clone().map(fb).collect(),
            y: w.clone().map(|k| fb(k - q)).collect(),
            centre: (0.0, 0.0),
        },
        against_command: Figure {
            x: w.clone().map(fb).collect(),
            y: w.map(|k| c[k - q]).collect(),
            centre: (0.0, 0.0),
        },
        trace,
        scenario,
        health,
    })
}

/// Largest difference of two figures' radial errors at matching angles (rad): how far one
/// figure departs from the other, point for point around the circle.
pub fn radial_difference(a: &Figure, b: &Figure) -> f64 {
    radial_differences(a, b).0
}

/// The largest and the rms difference of two figures' radii at matching angles (rad), over
/// the points of `a` (the radius of `b` interpolated at each one's angle).
pub fn radial_differences(a: &Figure, b: &Figure) -> (f64, f64) {
    let (pa, pb) = (a.polar(), b.polar());
    let mut sorted_b = pb.clone();
    sorted_b.sort_by(|x, y| x.0.total_cmp(&y.0));
    let at = |angle: f64| -> f64 {
        // Linear interpolation of b's radius at `angle` (periodic).
        let i = sorted_b.partition_point(|p| p.0 < angle);
        let (p0, p1) = if i == 0 || i == sorted_b.len() {
            let last = sorted_b[sorted_b.len() - 1];
            let first = sorted_b[0];
            ((last.0 - 360.0, last.1), first)
        } else {
            (sorted_b[i - 1], sorted_b[i])
        };
        let (a0, a1) = if i == sorted_b.len() { (p0.0 + 360.0, p1.0 + 360.0) } else { (p0.0, p1.0) };
        let f = if a1 > a0 { (angle - a0) / (a1 - a0) } else { 0.0 };
        p0.1 + f * (p1.1 - p0.1)
    };
    let d: Vec<f64> = pa.iter().map(|(angle, r)| (r - at(*angle)).abs()).collect();
    let rms = (d.iter().map(|x| x * x).sum::<f64>() / d.len().max(1) as f64).sqrt();
    (d.iter().cloned().fold(0.0, f64::max), rms)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn figure(r: impl Fn(f64) -> f64) -> Figure {
        let n = 3600;
        let (mut x, mut y) = (Vec::new(), Vec::new());
        for i in 0..n {
            let a = TAU * i as f64 / n as f64;
            x.push(2.0 + r(a) * a.cos());
            y.push(-1.0 + r(a) * a.sin());
        }
        Figure { x, y, centre: (2.0, -1.0) }
    }

    #[test]
    fn roundness_of_analytic_figures() {
        let f = figure(|_| 1.001).roundness(1.0);
        assert!(f.roundness < 1e-12 && (f.mean_radius_error - 0.001).abs() < 1e-12);
        // A bump of 1e-3 peaking 5° after each quadrant point, 2° wide.
        let bump = |a: f64| {
            let d = a.to_degrees().rem_euclid(90.0) - 5.0;
            1.0 + 1e-3 * (-(d / 2.0).powi(2)).exp()
        };
        let f = figure(bump).roundness(1.0);
        for (p, q) in f.protrusions.iter().zip([0.0, 90.0, 180.0, 270.0]) {
            let (angle, height) = p.expect("every quadrant measured");
            assert!((angle - (q + 5.0)).abs() < 0.2, "{angle} vs {q}");
            assert!((height - 1e-3).abs() < 1e-5, "{height}");
        }
        assert!((f.roundness - 1e-3).abs() < 1e-5);
    }

    #[test]
    fn quadrants_the_figure_does_not_reach_are_not_measurable_not_minus_infinity() {
        // Half a figure, from 45° to 200°: nothing within ±20° of 0° and 270°.
        let n = 1000;
        let angles = (0..n).map(|i| (45.0 + 155.0 * i as f64 / n as f64).to_radians());
        let (x, y) = angles.map(|a| (a.cos(), a.sin())).unzip();
        let f = Figure { x, y, centre: (0.0, 0.0) }.roundness(1.0);
        assert!(f.protrusions[0].is_none() && f.protrusions[3].is_none(), "{:?}", f.protrusions);
        assert!(f.protrusions[1].is_some() && f.protrusions[2].is_some(), "{:?}", f.protrusions);
        assert_eq!(f.max_protrusion, None);
        let why = f.not_measurable.clone().unwrap();
        assert!(why.contains("0°, 270°"), "{why}");
        let text = format!("{} | {}", f.protrusions_text(), f.max_protrusion_text());
        assert!(text.contains("not measurable") && !text.contains("inf") && !text.contains("NaN"), "{text}");
        assert!(serde_json::to_string(&f).unwrap().contains("\"max_protrusion\":null"));
    }

    fn request(radius: f64, feed: f64, lead_in: u32) -> CircleRequest {
        CircleRequest {
            radius,
            feed,
            direction: Direction::CounterClockwise,
            lead_in,
            measure: Measure::Load,
            x_parameters: BTreeMap::new(),
            y_parameters: BTreeMap::new(),
        }
    }

    #[test]
    fn a_run_longer_than_the_limit_is_refused_naming_the_option_before_any_allocation() {
        // 1 revolution per second: 4000 samples; lead-in 124 makes 125 revolutions, the limit.
        let steps = |lead_in| request(1.0, TAU, lead_in).timing().map(|(_, _, n)| n * (lead_in as usize + 1));
        assert_eq!(steps(124).unwrap(), MAX_RUN_STEPS);
        for (lead_in, value) in
            [(125, "--lead-in 125"), (100_000, "--lead-in 100000"), (u32::MAX, "--lead-in 4294967295")]
        {
            let e = steps(lead_in).unwrap_err().to_string();
            assert!(e.contains(value) && e.contains("500000") && e.contains("at most --lead-in 124"), "{e}");
        }
        // One revolution of exactly the limit (125 s) with no lead-in fits; one more sample
        // of revolution does not, and neither does a radius of 10⁶ or 10¹² rad.
        assert_eq!(request(125.0, TAU, 0).timing().unwrap().2, MAX_RUN_STEPS);
        assert!(request(125.0, TAU, 1).timing().unwrap_err().to_string().contains("at most --lead-in 0"));
        for radius in [125.001, 1e6, 1e12] {
            let e = request(radius, TAU, 0).timing().unwrap_err().to_string();
            assert!(e.contains(&format!("--radius {radius} rad")) && e.contains("500000"), "{e}");
        }
        // The single-axis test runs at least one lead-in revolution: counted.
        let single = request(125.0, TAU, 0);
        assert!(single.run_steps(single.timing().unwrap().2, 1).is_err());
    }

    #[test]
    fn parameters_out_of_range_or_not_parameters_are_refused_naming_the_axis() {
        let mut r = request(1.0, TAU, 1);
        r.check_parameters().unwrap();
        r.y_parameters.insert("ctrl.friction_comp_amplitude".into(), Value::Int(-1));
        let e = format!("{:#}", r.check_parameters().unwrap_err());
        assert!(e.contains("axis y") && e.contains("outside its range"), "{e}");
        r.y_parameters.clear();
        r.x_parameters.insert("position_command".into(), Value::Float(1.0));
        let e = format!("{:#}", r.check_parameters().unwrap_err());
        assert!(e.contains("axis x") && e.contains("not a parameter"), "{e}");
    }

    #[test]
    fn radial_difference_of_a_figure_and_its_offset_copy() {
        let a = figure(|_| 1.0);
        let b = figure(|a| 1.0 + 2e-4 * a.cos());
        assert!((radial_difference(&a, &b) - 2e-4).abs() < 1e-9);
        // rms of 2e-4·cos over a whole turn: 2e-4/√2.
        assert!((radial_differences(&a, &b).1 - 2e-4 / 2f64.sqrt()).abs() < 1e-8);
        assert!(radial_difference(&a, &a) < 1e-12);
    }
}
