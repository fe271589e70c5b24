//! `servo bench circle`: the figures of the circle-test issue (seed 002).
//!
//! 1. On the shipped demo axis (the FMU's defaults: Coulomb friction on motor and load), the
//!    largest quadrant protrusion of the two-axis circle with friction compensation off and
//!    on, and their ratio.
//! 2. With friction off, the single-axis pseudo-circle against the two-axis circle of two
//!    identical axes: they coincide by construction (a linear, time-invariant axis answers
//!    R·sin(ω(t − T/4)) with its answer to R·sin ωt shifted by T/4); the largest radial
//!    difference, relative to the radius.

use servo_axis::variables::name;
use std::collections::BTreeMap;

use anyhow::{anyhow, Result};
use serde::Serialize;

use crate::fmu::circle::{radial_difference, single_axis, two_axis, CircleRequest, Direction, Measure};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;

/// The compensation the demo uses: twice the axis' total Coulomb friction (the swing from
/// holding it one way to the other), decaying over 0.2 s.
pub const COMPENSATION: [(&str, f64); 2] =
    [(name::ctrl_friction_comp_amplitude, 0.06), (name::ctrl_friction_comp_decay, 0.2)];

#[derive(Clone, Debug, Serialize)]
pub struct CircleBench {
    pub radius: f64,
    pub feed: f64,
    pub protrusion_off: f64,
    pub protrusion_on: f64,
    pub protrusion_ratio: f64,
    pub roundness_off: f64,
    pub roundness_on: f64,
    /// Largest radial difference pseudo-circle vs two-axis circle (rad) and relative to R.
    pub pseudo_vs_two_axis: f64,
    pub pseudo_vs_two_axis_relative: f64,
}

pub fn demo_request(parameters: BTreeMap<String, Value>) -> CircleRequest {
    CircleRequest {
        radius: 1.0,
        feed: std::f64::consts::TAU,
        direction: Direction::CounterClockwise,
        lead_in: 1,
        measure: Measure::Load,
        x_parameters: parameters.clone(),
        y_parameters: parameters,
    }
}

pub fn bench(fmu: &Fmu) -> Result<CircleBench> {
    let off = two_axis(fmu, &demo_request(BTreeMap::new()))?.feedback.roundness(1.0);
    let on_params: BTreeMap<String, Value> =
        COMPENSATION.iter().map(|(k, v)| (k.to_string(), Value::Float(*v))).collect();
    let on = two_axis(fmu, &demo_request(on_params))?.feedback.roundness(1.0);
    let frictionless: BTreeMap<String, Value> = [name::plant_motor_coulomb, name::plant_load_coulomb]
        .iter()
        .map(|k| (k.to_string(), Value::Float(0.0)))
        .collect();
    let r = demo_request(frictionless);
    let pseudo = single_axis(fmu, &r)?;
    let circle = two_axis(fmu, &r)?;
    let d = radial_difference(&pseudo.feedback, &circle.feedback)
        .max(radial_difference(&circle.feedback, &pseudo.feedback));
    let largest = |f: &crate::fmu::circle::Roundness, what: &str| {
        f.max_protrusion.ok_or_else(|| anyhow!("the protrusions with compensation {what}: {}", f.max_protrusion_text()))
    };
    let (protrusion_off, protrusion_on) = (largest(&off, "off")?, largest(&on, "on")?);
    Ok(CircleBench {
        radius: r.radius,
        feed: r.feed,
        protrusion_off,
        protrusion_on,
        protrusion_ratio: protrusion_on / protrusion_off,
        roundness_off: off.roundness,
        roundness_on: on.roundness,
        pseudo_vs_two_axis: d,
        pseudo_vs_two_axis_relative: d / r.radius,
    })
}
