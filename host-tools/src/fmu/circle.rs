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

use anyhow::{anyhow, bail, Result};
use serde::Serialize;

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

impl CircleRequest {
    /// ω, period and samples per revolution; refuses what cannot make a circle test.
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
        let n = samples.round();
        if (samples - n).abs() > 1e-6 * samples {
            bail!(
                "the revolution ({period} s) is not a whole number of {DEFAULT_STEP} s samples ({samples:.4}): choose feed = radius·2π / (k·{DEFAULT_STEP} s)"
            );
        }
        Ok((omega, period, n as usize))
    }

    /// The single-axis test also needs T/4 to be whole samples.
    pub fn quarter(&self) -> Result<usize> {
        let (_, period, n) = self.timing()?;
        if n % 4 != 0 {
            bail!("a quarter period ({} s) is not a whole number of samples: {n} samples per revolution is not a multiple of 4", period / 4.0);
        }
        Ok(n / 4)
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
    /// the median radial error in rad) within ±`QUADRANT_WINDOW` degrees.
    pub protrusions: Vec<(f64, f64)>,
    /// Largest protrusion height (rad).
    pub max_protrusion: f64,
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
        let protrusions: Vec<(f64, f64)> = [0.0, 90.0, 180.0, 270.0]
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
                    .fold((q, f64::NEG_INFINITY), |best, p| if p.1 > best.1 { p } else { best })
            })
            .collect();
        let max_protrusion = protrusions.iter().map(|p| p.1).fold(f64::NEG_INFINITY, f64::max);
        Roundness { roundness: max - min, mean_radius_error: mean, protrusions, max_protrusion }
    }
}

/// A two-axis circle: commands and feedback over the measured revolution.
#[derive(Clone, Debug)]
pub struct CircleRun {
    pub command: Figure,
    pub feedback: Figure,
    pub traces: Vec<Trace>,
}

fn measured_window(total: usize, n: usize) -> std::ops::Range<usize> {
    // Trace rows: 0 is the initial state, row k+1 follows step k (command index k).
    total - n..total
}

pub fn two_axis(fmu: &Fmu, r: &CircleRequest) -> Result<CircleRun> {
    let (omega, _, n) = r.timing()?;
    let steps = n * (r.lead_in as usize + 1);
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
    Ok(CircleRun {
        command: Figure { x: xc[w.clone()].to_vec(), y: yc[w.clone()].to_vec(), centre },
        feedback: Figure { x: w.clone().map(|k| fx[k + 1]).collect(), y: w.map(|k| fy[k + 1]).collect(), centre },
        traces: vec![tx, ty],
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
}

pub fn single_axis(fmu: &Fmu, r: &CircleRequest) -> Result<PseudoCircleRun> {
    let q = r.quarter()?;
    let (omega, _, n) = r.timing()?;
    let steps = n * (r.lead_in.max(1) as usize + 1);
    let c: Vec<f64> = (0..steps).map(|k| r.radius * (omega * k as f64 * DEFAULT_STEP).sin()).collect();
    let scenario = Scenario::streamed_position("pseudo_circle", &r.x_parameters, &c);
    let trace = fmu.run(&scenario, |_| {})?;
    let x = trace.column(r.measure.column()).ok_or_else(|| anyhow!("no {}", r.measure.column()))?;
    let w = measured_window(steps, n);
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
        for ((angle, height), q) in f.protrusions.iter().zip([0.0, 90.0, 180.0, 270.0]) {
            assert!((angle - (q + 5.0)).abs() < 0.2, "{angle} vs {q}");
            assert!((height - 1e-3).abs() < 1e-5, "{height}");
        }
        assert!((f.roundness - 1e-3).abs() < 1e-5);
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
