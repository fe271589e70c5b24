//! Response-correction filters (seed 001) and what they do on the FMU.
//!
//! Two ways to choose them ([`Method`]):
//! - `response` (default): every axis's command → machine-end response is measured and fitted
//!   ([`crate::ident::response_model`]); every axis gets the OTHER axes' models, so all answer their
//!   product.
//! - `zeros`, the seed as written: every axis gets `F·Π_{j≠i} N_j`, one section per OTHER
//!   axis's anti-resonance numerator over a pole pair of F and, for an axis with its own
//!   anti-resonance, one section of F alone, so that every axis carries the same F. F is a
//!   critically damped low-pass whose pole pairs sit at the higher of twice the position-loop
//!   bandwidth (`kp/2π`) and the highest anti-resonance.
//!
//! The measurement is a periodic multisine on the streamed position command (one second
//! period, 1 Hz to twice the position-loop bandwidth, one period for the transients and four
//! averaged), friction off; the check repeats it with the filters and reports the largest
//! difference between axes up to the position loop's bandwidth.

use servo_axis::variables::name;
use std::collections::BTreeMap;

use anyhow::{bail, Result};
use num_complex::Complex64;
use serde::Serialize;

use crate::analysis::response_point::ResponsePoint;
use crate::analysis::spectral::dft_bin;
use crate::correction::{drive_frame, validate, AxisCorrection, Section};
use crate::fmu::axis_health::{current_near_ceiling, torque_ceiling};
use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::{Scenario, Value, DEFAULT_STEP};
use crate::ident::identification::{AxisModel, Factor};
use crate::ident::response_model::{self, ResponseModel};

/// The filters of every axis.
pub fn corrections(models: &[AxisModel], position_bandwidth_hz: f64) -> Result<(f64, Vec<AxisCorrection>)> {
    let resonant: Vec<&AxisModel> = models.iter().filter(|m| m.anti_resonance.is_some()).collect();
    if resonant.len() > control_core::response_correction::MAX_SECTIONS {
        bail!(
            "{} axes with an anti-resonance: the filter holds {} sections",
            resonant.len(),
            control_core::response_correction::MAX_SECTIONS
        );
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
                    Section { zeros: Some((z.hz, z.damping)), pole_hz, pole_damping: 1.0 }
                })
                .collect();
            // As many F sections as every other axis: its own slot carries F alone.
            while sections.len() < resonant.len() {
                sections.push(Section { zeros: None, pole_hz, pole_damping: 1.0 });
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

/// Amplitude of each multisine tone (rad): small enough that the corrected command stays far
/// from the current limit, large enough (170 encoder counts) that quantisation does not matter.
pub const MULTISINE_AMPLITUDE: f64 = 1.0e-3;
/// Periods measured after the first (transient) one; the DFT over all of them averages the
/// encoder-quantisation noise.
pub const MEASURED_PERIODS: usize = 4;

/// Command → machine-end response of one axis at `frequencies` (Hz, whole numbers), complex.
pub fn command_to_load(
    fmu: &Fmu,
    parameters: &BTreeMap<String, Value>,
    frequencies: &[u32],
) -> Result<Vec<(f64, Complex64)>> {
    let period = (1.0 / DEFAULT_STEP).round() as usize; // one second
    let command = multisine(frequencies, MULTISINE_AMPLITUDE, (1 + MEASURED_PERIODS) * period);
    // The model's own response to the correction, with its encoder's mounting given: what the
    // check judges is the correction's design on the identified model, not a commissioning.
    let mut parameters = parameters.clone();
    parameters.insert("commissioning.at_start".to_string(), Value::Bool(false));
    let scenario = Scenario::streamed_position("command_to_load", &parameters, &command);
    let trace = fmu.run(&scenario, |_| {})?;
    // A response measured through a current or torque clamp or a trip is not the axis's
    // response. The multisine is streamed in front of the loop, without a dither: the lower of
    // the two clamps binds.
    if let Some(trip) = crate::fmu::axis_health::first_trip(&trace)? {
        bail!("the axis tripped during the multisine: {}; its response cannot be measured this way", trip.sentence());
    }
    // The ceiling of the drive the run had: on a drive's twin, that drive's motor and
    // current loop (`Fmu::twin_parameters_for`), the scenario's own otherwise.
    let mut run_parameters = parameters.clone();
    for (name, value) in fmu.twin_parameters_for(&parameters) {
        run_parameters.entry(name).or_insert(value);
    }
    let ceiling = torque_ceiling(&run_parameters)?;
    if let Some(largest) = current_near_ceiling(&trace, &ceiling)? {
        bail!(
            "the multisine drove the current to {largest:.2} A, near the {} A limit ({ceiling}): the measured response would not be linear (the correction filter lifts the command too much near a lightly damped mode?)",
            ceiling.rounded_current()
        );
    }
    let load = trace.column("load_position").unwrap_or_default();
    // Row k+1 follows command k: all periods after the first.
    let (u, y): (Vec<f64>, Vec<f64>) =
        (period..(1 + MEASURED_PERIODS) * period).map(|k| (command[k], load[k + 1])).unzip();
    // The record is whole seconds: frequency f Hz is bin f·seconds.
    let seconds = MEASURED_PERIODS as f64;
    Ok(frequencies
        .iter()
        .map(|&f| (f as f64, dft_bin(&y, f as f64 * seconds) / dft_bin(&u, f as f64 * seconds)))
        .collect())
}

/// Largest gain (dB) and phase (deg) difference between any two axes' responses.
pub fn spread(responses: &[Vec<ResponsePoint>]) -> (f64, f64) {
    let mut worst = (0.0f64, 0.0f64);
    for a in responses {
        for b in responses {
            for (p, q) in a.iter().zip(b) {
                let (dg, dp) = crate::analysis::response_point::difference(p, q);
                worst = (worst.0.max(dg.abs()), worst.1.max(dp.abs()));
            }
        }
    }
    worst
}

/// How the correction filters are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Method {
    /// Every axis gets the other axes' measured command → machine-end models (the seed's
    /// structure with F chosen per axis; see `response_model`).
    Response,
    /// The seed as written: `F·Π N_other` from the identified anti-resonances.
    Zeros,
}

impl std::str::FromStr for Method {
    type Err = anyhow::Error;
    fn from_str(s: &str) -> Result<Self> {
        match s {
            "response" => Ok(Self::Response),
            "zeros" => Ok(Self::Zeros),
            other => bail!("--method must be response or zeros (got `{other}`)"),
        }
    }
}

/// One axis as tuned: the FMU parameters its measurements ran with, its filter and model.
#[derive(Clone, Debug, Serialize)]
pub struct TunedAxis {
    pub axis: String,
    pub fmu_parameters: BTreeMap<String, f64>,
    pub correction: AxisCorrection,
    pub response_model: Option<ResponseModel>,
}

#[derive(Clone, Debug, Serialize)]
pub struct Tuning {
    pub method: Method,
    pub position_bandwidth_hz: f64,
    /// The seed's F (zeros method): critically damped pole pairs at this frequency.
    pub f_pole_hz: Option<f64>,
    pub axes: Vec<TunedAxis>,
    /// Measured command → machine-end responses before and after (per axis), if measured.
    #[serde(skip)]
    pub before: Vec<Vec<(f64, Complex64)>>,
    #[serde(skip)]
    pub after: Vec<Vec<(f64, Complex64)>>,
    /// Largest difference between axes up to the position-loop bandwidth (dB, degrees).
    pub spread_before: Option<(f64, f64)>,
    pub spread_after: Option<(f64, f64)>,
}

/// The FMU parameters a tuning measurement runs an axis with: the identified ones, friction
/// off (the correction is linear; friction's quadrant effects are seed 002's business).
pub fn measurement_parameters(model: &AxisModel) -> BTreeMap<String, Value> {
    let mut p: BTreeMap<String, Value> =
        model.fmu_parameters.iter().map(|(k, v)| (k.clone(), Value::Float(*v))).collect();
    p.insert(name::plant_motor_coulomb.into(), Value::Float(0.0));
    p.insert(name::plant_load_coulomb.into(), Value::Float(0.0));
    p
}

/// Every axis gets every other axis's sections.
pub fn response_corrections(models: &[ResponseModel]) -> Result<Vec<AxisCorrection>> {
    let max = control_core::response_correction::MAX_SECTIONS;
    models
        .iter()
        .map(|m| {
            let sections: Vec<Section> =
                models.iter().filter(|o| o.axis != m.axis).flat_map(|o| o.sections()).collect();
            if sections.len() > max {
                bail!(
                    "axis {}: the other axes' models need {} sections; the filter holds {max}",
                    m.axis,
                    sections.len()
                );
            }
            Ok(AxisCorrection { axis: m.axis.clone(), sections })
        })
        .collect()
}

/// Measure, fit, correct and (with `check`) measure again. `progress` gets 0..1.
pub fn tune(
    fmu: &Fmu,
    models: &[AxisModel],
    method: Method,
    check: bool,
    mut progress: impl FnMut(f64),
) -> Result<Tuning> {
    if models.len() < 2 {
        bail!("tuning makes axes alike: give at least two axes");
    }
    for (i, m) in models.iter().enumerate() {
        if models[..i].iter().any(|o| o.axis == m.axis) {
            bail!("axis `{}` is given twice", m.axis);
        }
    }
    let parameters: Vec<BTreeMap<String, Value>> = models.iter().map(measurement_parameters).collect();
    // The position loop the axes run (the same on every axis: one bandwidth to make them alike at).
    let mut position_loops = Vec::new();
    for (m, p) in models.iter().zip(&parameters) {
        let control = configuration(p)?.control;
        position_loops.push((m.axis.as_str(), control.position.kp, control.rates.position_period()));
    }
    let (_, kp, position_period) = position_loops[0];
    if let Some((axis, ..)) = position_loops.iter().find(|&&(_, k, t)| (k, t) != (kp, position_period)) {
        bail!("axis `{axis}` runs another position loop (gain or period) than axis `{}`: tuning makes axes alike at one position-loop bandwidth", models[0].axis);
    }
    let bandwidth = kp as f64 / std::f64::consts::TAU;
    let nyquist = 0.5 / position_period as f64;
    let frequencies: Vec<u32> = (1..=(2.0 * bandwidth).round() as u32).collect();
    let runs = models.len() as f64 * if check { 2.0 } else { 1.0 };
    let mut done = 0.0;
    let measure_before = check || method == Method::Response;
    let mut before = Vec::new();
    if measure_before {
        for p in &parameters {
            before.push(command_to_load(fmu, p, &frequencies)?);
            done += 1.0;
            progress(done / runs);
        }
    }
    let (f_pole_hz, filters, response_models) = match method {
        Method::Zeros => {
            let (pole, f) = corrections(models, bandwidth)?;
            (Some(pole), f, vec![None; models.len()])
        }
        Method::Response => {
            let per_model = control_core::response_correction::MAX_SECTIONS / (models.len() - 1);
            let fitted: Vec<ResponseModel> = models
                .iter()
                .zip(&before)
                .map(|(m, b)| response_model::fit(&m.axis, b, (1.0, 1.5 * bandwidth), per_model, nyquist))
                .collect::<Result<_>>()?;
            let f = response_corrections(&fitted)?;
            (None, f, fitted.into_iter().map(Some).collect())
        }
    };
    for f in &filters {
        validate(f)?;
    }
    let mut after = Vec::new();
    if check {
        for (p, f) in parameters.iter().zip(&filters) {
            let mut p = p.clone();
            p.extend(f.parameters());
            after.push(command_to_load(fmu, &p, &frequencies)?);
            done += 1.0;
            progress(done / runs);
        }
    }
    let upto = |r: &[Vec<(f64, Complex64)>]| -> Vec<Vec<ResponsePoint>> {
        r.iter()
            .map(|v| {
                v.iter()
                    .filter(|p| p.0 <= bandwidth + 1e-9)
                    .map(|&(f, h)| ResponsePoint::from_complex(f, h, 1.0))
                    .collect()
            })
            .collect()
    };
    let axes = models
        .iter()
        .zip(parameters)
        .zip(filters)
        .zip(response_models)
        .map(|(((m, p), correction), response_model)| TunedAxis {
            axis: m.axis.clone(),
            fmu_parameters: p.into_iter().map(|(k, v)| (k, v.as_f64())).collect(),
            correction,
            response_model,
        })
        .collect();
    Ok(Tuning {
        method,
        position_bandwidth_hz: bandwidth,
        f_pole_hz,
        axes,
        spread_before: check.then(|| spread(&upto(&before))),
        spread_after: check.then(|| spread(&upto(&after))),
        before,
        after,
    })
}

/// `<axis>.corr.toml` (FMU parameters) and `<axis>.corr.frame` (the drive's framed
/// `LoadCorrection` request) per axis, tune.json and (when measured) tune.svg; returns the
/// files.
pub fn write(t: &Tuning, out: &std::path::Path) -> Result<Vec<std::path::PathBuf>> {
    crate::paths::create_out_dir(out)?;
    let mut files = Vec::new();
    for a in &t.axes {
        let text: String = a
            .correction
            .parameters()
            .iter()
            .map(|(k, v)| match v {
                Value::Int(i) => format!("{k:?} = {i}\n"),
                other => format!("{k:?} = {:?}\n", other.as_f64()),
            })
            .collect();
        let path = out.join(format!("{}.corr.toml", a.axis));
        std::fs::write(
            &path,
            format!("# servo tune ({:?} method): response correction of axis {}\n{text}", t.method, a.axis),
        )?;
        files.push(path);
        let frame = out.join(format!("{}.corr.frame", a.axis));
        std::fs::write(&frame, drive_frame(&a.correction)?)?;
        files.push(frame);
    }
    let json = out.join("tune.json");
    std::fs::write(&json, serde_json::to_string_pretty(t)?)?;
    files.push(json);
    if !t.after.is_empty() {
        let mut curves: Vec<(String, Vec<ResponsePoint>)> = Vec::new();
        let points =
            |v: &[(f64, Complex64)]| v.iter().map(|&(f, h)| ResponsePoint::from_complex(f, h, 1.0)).collect::<Vec<_>>();
        for (a, (b, c)) in t.axes.iter().zip(t.before.iter().zip(&t.after)) {
            curves.push((format!("{} before", a.axis), points(b)));
            curves.push((format!("{} after", a.axis), points(c)));
        }
        let refs: Vec<(&str, &[ResponsePoint])> = curves.iter().map(|(l, c)| (l.as_str(), c.as_slice())).collect();
        let svg = out.join("tune.svg");
        crate::plot::bode::plot_bode(
            &svg,
            "Command → machine-end position, before and after the correction",
            &refs,
            Some((t.position_bandwidth_hz, "position-loop bandwidth")),
        )?;
        files.push(svg);
    }
    Ok(files)
}

impl Tuning {
    pub fn print(&self) {
        match self.method {
            Method::Zeros => println!(
                "servo tune (zeros method: the seed's F·Π N_other) — F: critically damped pole pairs at {:.1} Hz (position bandwidth {:.1} Hz)",
                self.f_pole_hz.unwrap_or(f64::NAN),
                self.position_bandwidth_hz
            ),
            Method::Response => println!(
                "servo tune (response method: every axis gets the other axes' measured command → machine-end models) — position bandwidth {:.1} Hz",
                self.position_bandwidth_hz
            ),
        }
        for a in &self.axes {
            if let Some(m) = &a.response_model {
                let f = |v: &[Factor]| {
                    v.iter().map(|x| format!("({:.2} Hz, ζ {:.3})", x.hz, x.damping)).collect::<Vec<_>>().join("·")
                };
                println!(
                    "  model of {}: zeros {} / poles {}, fitted {:.0}–{:.0} Hz, worst error {:.3} %",
                    a.axis,
                    if m.zeros.is_empty() { "-".into() } else { f(&m.zeros) },
                    f(&m.poles),
                    m.band.0,
                    m.band.1,
                    m.worst_error * 100.0
                );
            }
        }
        for a in &self.axes {
            let secs: Vec<String> = a
                .correction
                .sections
                .iter()
                .map(|s| match s.zeros {
                    Some((hz, d)) => format!("({hz:.2} Hz, ζ {d:.3})/({:.2} Hz, ζ {:.3})", s.pole_hz, s.pole_damping),
                    None => format!("1/({:.2} Hz, ζ {:.3})", s.pole_hz, s.pole_damping),
                })
                .collect();
            println!("  filter of {}: {}", a.axis, secs.join(" · "));
        }
        if let (Some(b), Some(a)) = (self.spread_before, self.spread_after) {
            println!(
                "  largest difference between axes' command → machine-end responses up to {:.1} Hz: before {:.4} dB / {:.3}°, after {:.4} dB / {:.3}°",
                self.position_bandwidth_hz, b.0, b.1, a.0, a.1
            );
        }
    }
}

/// Circle (seed 002's XY test) of the tuned x and y axes without and with their corrections.
#[derive(Clone, Debug, Serialize)]
pub struct CircleCheck {
    pub radius: f64,
    pub frequency_hz: f64,
    pub lead_in: u32,
    /// Roundness (max − min machine-end radius, rad) without and with the correction.
    pub roundness_without: f64,
    pub roundness_with: f64,
}

/// Run the XY circle at `frequency_hz` on the tuning's axes `x` and `y`.
pub fn circle_check(fmu: &Fmu, t: &Tuning, radius: f64, frequency_hz: f64, lead_in: u32) -> Result<CircleCheck> {
    use crate::fmu::circle::{two_axis, CircleRequest, Direction, Measure};
    let axis = |name: &str| {
        t.axes
            .iter()
            .find(|a| a.axis == name)
            .ok_or_else(|| anyhow::anyhow!("the circle check needs axes x and y; the tuning has no `{name}`"))
    };
    let (x, y) = (axis("x")?, axis("y")?);
    let base = |a: &TunedAxis| -> BTreeMap<String, Value> {
        a.fmu_parameters.iter().map(|(k, v)| (k.clone(), Value::Float(*v))).collect()
    };
    let mut request = CircleRequest {
        radius,
        feed: radius * std::f64::consts::TAU * frequency_hz,
        direction: Direction::CounterClockwise,
        lead_in,
        measure: Measure::Load,
        x_parameters: base(x),
        y_parameters: base(y),
    };
    // A roundness is only the loops' where neither drive tripped.
    let roundness = |request: &CircleRequest, label: &str| -> Result<f64> {
        let run = two_axis(fmu, request)?;
        if let Some((h, trip)) = run.health.iter().find_map(|h| h.trip.as_ref().map(|t| (h, t))) {
            anyhow::bail!("the circle check {label} the correction: {} tripped: {}", h.name(), trip.sentence());
        }
        Ok(run.feedback.roundness(radius).roundness)
    };
    let without = roundness(&request, "without")?;
    request.x_parameters.extend(x.correction.parameters());
    request.y_parameters.extend(y.correction.parameters());
    let with = roundness(&request, "with")?;
    Ok(CircleCheck { radius, frequency_hz, lead_in, roundness_without: without, roundness_with: with })
}
