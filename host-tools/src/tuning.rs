//! Response-correction filters from identified axis models (seed 001), and a check of what
//! they do on the FMU.
//!
//! Every axis gets `F·Π_{j≠i} N_j`: one section per OTHER axis's anti-resonance numerator over
//! a pole pair of F, and, for an axis with its own anti-resonance, one section of F alone, so
//! that every axis carries the same F. F is a critically damped low-pass whose pole pairs sit
//! at the higher of twice the position-loop bandwidth (`kp/2π`) and the highest
//! anti-resonance (so `N/F` never lifts the command's high frequencies by more than the
//! anti-resonances' own ratio).
//!
//! The check measures each axis's command → machine-end response on the FMU before and after,
//! with a periodic multisine on the streamed position command (one second period, one period
//! for the transients), and reports the largest difference between axes up to the position
//! loop's bandwidth.

use std::collections::BTreeMap;

use anyhow::{bail, Result};
use serde::Serialize;

use crate::fmu_runner::Fmu;
use crate::frequency_response::ResponsePoint;
use crate::identification::AxisModel;
use crate::scenario::{Scenario, Value, DEFAULT_STEP};
use crate::spectral::dft_bin;

/// One correction section as the FMU takes it.
#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct Section {
    /// Anti-resonance numerator (Hz, damping); None: F alone.
    pub zeros: Option<(f64, f64)>,
    pub pole_hz: f64,
}

#[derive(Clone, Debug, Serialize)]
pub struct AxisCorrection {
    pub axis: String,
    pub sections: Vec<Section>,
}

impl AxisCorrection {
    /// `corr.*` FMU parameters.
    pub fn parameters(&self) -> BTreeMap<String, Value> {
        let mut p = BTreeMap::new();
        p.insert("corr.count".into(), Value::Int(self.sections.len() as i64));
        for (i, s) in self.sections.iter().enumerate() {
            let n = i + 1;
            let (zh, zd) = s.zeros.unwrap_or((0.0, 0.0));
            p.insert(format!("corr.zero_hz_{n}"), Value::Float(zh));
            p.insert(format!("corr.zero_damping_{n}"), Value::Float(zd));
            p.insert(format!("corr.pole_hz_{n}"), Value::Float(s.pole_hz));
            p.insert(format!("corr.pole_damping_{n}"), Value::Float(1.0));
        }
        p
    }
}

/// The filters of every axis.
pub fn corrections(models: &[AxisModel], position_bandwidth_hz: f64) -> Result<(f64, Vec<AxisCorrection>)> {
    let resonant: Vec<&AxisModel> = models.iter().filter(|m| m.anti_resonance.is_some()).collect();
    if resonant.len() > control_core::response_correction::MAX_SECTIONS {
        bail!("{} axes with an anti-resonance: the filter holds {} sections", resonant.len(), control_core::response_correction::MAX_SECTIONS);
    }
    for m in &resonant {
        let z = m.anti_resonance.expect("filtered");
        if !(z.hz.is_finite() && z.hz > 0.0 && z.damping.is_finite() && z.damping >= 0.0) {
            bail!("axis {}: anti-resonance {} Hz, damping {} cannot be used (zeros in the right half plane or not finite)", m.axis, z.hz, z.damping);
        }
    }
    let highest = resonant.iter().map(|m| m.anti_resonance.expect("filtered").hz).fold(0.0, f64::max);
    let pole_hz = (2.0 * position_bandwidth_hz).max(highest);
    let out = models
        .iter()
        .map(|m| {
            let mut sections: Vec<Section> = resonant
                .iter()
                .filter(|o| o.axis != m.axis)
                .map(|o| {
                    let z = o.anti_resonance.expect("filtered");
                    Section { zeros: Some((z.hz, z.damping)), pole_hz }
                })
                .collect();
            // As many F sections as every other axis: its own slot carries F alone.
            while sections.len() < resonant.len() {
                sections.push(Section { zeros: None, pole_hz });
            }
            AxisCorrection { axis: m.axis.clone(), sections }
        })
        .collect();
    Ok((pole_hz, out))
}

/// Periodic multisine position command: frequencies k Hz (1 s period), Schroeder phases.
pub fn multisine(frequencies: &[u32], amplitude: f64, steps: usize) -> Vec<f64> {
    let n = frequencies.len() as f64;
    (0..steps)
        .map(|k| {
            let t = k as f64 * DEFAULT_STEP;
            frequencies
                .iter()
                .enumerate()
                .map(|(i, &f)| {
                    let phase = -std::f64::consts::PI * (i as f64) * (i as f64 + 1.0) / n;
                    amplitude * (std::f64::consts::TAU * f as f64 * t + phase).sin()
                })
                .sum()
        })
        .collect()
}

/// Command → machine-end response of one axis at `frequencies` (Hz, whole numbers).
pub fn command_to_load(fmu: &Fmu, parameters: &BTreeMap<String, Value>, frequencies: &[u32]) -> Result<Vec<ResponsePoint>> {
    let period = (1.0 / DEFAULT_STEP).round() as usize; // one second
    let command = multisine(frequencies, 2.0e-3, 2 * period);
    let scenario = Scenario::streamed_position("command_to_load", parameters, &command);
    let trace = fmu.run(&scenario, |_| {})?;
    let load = trace.column("load_position").unwrap_or_default();
    // Row k+1 follows command k: the last period of both.
    let (u, y): (Vec<f64>, Vec<f64>) = (period..2 * period).map(|k| (command[k], load[k + 1])).unzip();
    // The record is one second: frequency f Hz is bin f.
    Ok(frequencies.iter().map(|&f| ResponsePoint::from_complex(f as f64, dft_bin(&y, f as f64).div(dft_bin(&u, f as f64)), 1.0)).collect())
}

/// Largest gain (dB) and phase (deg) difference between any two axes' responses.
pub fn spread(responses: &[Vec<ResponsePoint>]) -> (f64, f64) {
    let mut worst = (0.0f64, 0.0f64);
    for a in responses {
        for b in responses {
            for (p, q) in a.iter().zip(b) {
                let (dg, dp) = crate::frequency_response::difference(p, q);
                worst = (worst.0.max(dg.abs()), worst.1.max(dp.abs()));
            }
        }
    }
    worst
}
