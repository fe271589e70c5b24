//! `servo ident`: identify every axis's anti-resonance on the FMU, write the editable model
//! files, the measured responses and a Bode plot of measurement and model (embodiment 5).

use servo_axis::variables::name;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{anyhow, bail, Context, Result};
use serde::Serialize;

use crate::analysis::response_point::ResponsePoint;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::trace::Trace;
use crate::ident::identification::{acceleration_rms, identify, measure, AxisModel, FitRefused, Measured, Notch};
use crate::plot::bode::plot_bode;

/// Band the response is measured over (Hz).
pub const BAND: (f64, f64) = (5.0, 500.0);

#[derive(Clone, Debug, Serialize)]
pub struct IdentifiedAxis {
    pub axis: String,
    /// None when the fit was refused (see `refusal`): no model file is written.
    pub model: Option<AxisModel>,
    /// The notch search (embodiment 4): frequency, depth and confidence of the deepest dip.
    pub notch: Option<Notch>,
    /// Why the fitted model was refused.
    pub refusal: Option<String>,
    /// Why a clear notch gave no anti-resonance: the measurement does not determine its zero
    /// pair (see `Identified::undetermined`).
    pub undetermined: Option<String>,
    /// Accelerometer noise used (rad/s², standard deviation) and the resulting SNR.
    pub noise_std: f64,
    pub snr_db: Option<f64>,
    pub files: Vec<PathBuf>,
}

/// The measured response as CSV: frequency, gain (dB), phase (deg), real and imaginary parts.
pub fn write_measured(path: &Path, m: &Measured) -> Result<()> {
    let mut t = Trace::new(["frequency", "gain_db", "phase_deg", "re", "im"].map(String::from).to_vec());
    for (f, h) in m.frequencies.iter().zip(&m.response) {
        t.rows.push(vec![*f, 20.0 * h.norm().log10(), h.arg().to_degrees(), h.re, h.im]);
    }
    t.write_csv(path)
}

pub fn model_points(model: &AxisModel, frequencies: &[f64]) -> Vec<ResponsePoint> {
    frequencies.iter().map(|&f| ResponsePoint::from_complex(f, model.response(f), 1.0)).collect()
}

/// Identify one axis with `parameters`; with `snr_db`, accelerometer noise is set from a
/// noise-free pilot run to that signal-to-noise ratio.
pub fn identify_axis(
    fmu: &Fmu,
    axis: &str,
    parameters: &BTreeMap<String, Value>,
    amplitude: f64,
    snr_db: Option<f64>,
    out: &Path,
) -> Result<IdentifiedAxis> {
    if !(amplitude.is_finite() && amplitude > 0.0) {
        bail!("--amplitude must be a positive torque (N·m)");
    }
    let mut p = parameters.clone();
    let mut noise_std = 0.0;
    if let Some(snr) = snr_db {
        if !snr.is_finite() {
            bail!("--snr-db must be a finite number of dB");
        }
        let rms = acceleration_rms(fmu, parameters, amplitude)?;
        // The accelerometer's noise is white per base tick; the record holds means over a
        // communication step, which divide its deviation by √(ticks per step). The SNR is that
        // of the record the identification uses.
        let ticks_per_sample =
            (crate::fmu::scenario::DEFAULT_STEP * control_core::Params::default().rates.current_loop_hz as f64).round();
        noise_std = rms / 10f64.powf(snr / 20.0) * ticks_per_sample.sqrt();
        p.insert(name::plant_acceleration_noise_std.into(), Value::Float(noise_std));
    }
    let m = measure(fmu, &p, amplitude, BAND.0, BAND.1).with_context(|| format!("axis {axis}"))?;
    // The measurement first: it is there to look at when the fit is refused.
    crate::paths::create_out_dir(out)?;
    let measured_path = out.join(format!("{axis}.measured.csv"));
    write_measured(&measured_path, &m)?;
    let model_path = out.join(format!("{axis}.model.json"));
    let identified = match identify(axis, &m) {
        Ok(i) => i,
        Err(e) => {
            let refused = e.downcast_ref::<FitRefused>().cloned().ok_or(e).with_context(|| format!("axis {axis}"))?;
            // A stale model of an earlier run must not be taken for this one's.
            let _ = std::fs::remove_file(&model_path);
            return Ok(IdentifiedAxis {
                axis: axis.into(),
                model: None,
                notch: Some(refused.notch),
                refusal: Some(refused.reason),
                undetermined: None,
                noise_std,
                snr_db,
                files: vec![measured_path],
            });
        }
    };
    let mut model = identified.model;
    // The plant as given (without the measurement noise), for `servo tune`'s check runs.
    model.fmu_parameters = parameters.iter().map(|(k, v)| (k.clone(), v.as_f64())).collect();
    std::fs::write(&model_path, serde_json::to_string_pretty(&model)?)?;
    Ok(IdentifiedAxis {
        axis: axis.into(),
        model: Some(model),
        notch: identified.notch,
        refusal: None,
        undetermined: identified.undetermined,
        noise_std,
        snr_db,
        files: vec![model_path, measured_path],
    })
}

/// Bode plot of every axis's measured response and its model.
pub fn plot(path: &Path, axes: &[(AxisModel, Vec<ResponsePoint>)]) -> Result<()> {
    let mut curves: Vec<(String, Vec<ResponsePoint>)> = Vec::new();
    for (model, measured) in axes {
        let freqs: Vec<f64> = measured.iter().map(|p| p.frequency).collect();
        curves.push((format!("{}: measured", model.axis), measured.clone()));
        let label = match model.anti_resonance {
            Some(z) => format!("{}: model, anti-resonance {:.2} Hz, ζ {:.3}", model.axis, z.hz, z.damping),
            None => format!("{}: model, rigid (N = 1)", model.axis),
        };
        curves.push((label, model_points(model, &freqs)));
    }
    let refs: Vec<(&str, &[ResponsePoint])> = curves.iter().map(|(l, c)| (l.as_str(), c.as_slice())).collect();
    plot_bode(path, "Torque → machine-end acceleration: measured and fitted model", &refs, None)
}

/// Re-plot edited model files against the measurements saved next to them.
pub fn replot(models: &[PathBuf], out: &Path) -> Result<PathBuf> {
    let mut axes = Vec::new();
    for path in models {
        let model = AxisModel::load(path)?;
        let measured_path = path.with_file_name(format!("{}.measured.csv", model.axis));
        let t = Trace::read_csv(&measured_path)
            .with_context(|| format!("the measurement of axis {} ({})", model.axis, measured_path.display()))?;
        let (f, g, ph) = (
            t.column("frequency").ok_or_else(|| anyhow!("no frequency column"))?,
            t.column("gain_db").ok_or_else(|| anyhow!("no gain_db column"))?,
            t.column("phase_deg").ok_or_else(|| anyhow!("no phase_deg column"))?,
        );
        let measured = (0..f.len())
            .map(|i| ResponsePoint { frequency: f[i], gain_db: g[i], phase_deg: ph[i], quality: 1.0 })
            .collect();
        axes.push((model, measured));
    }
    crate::paths::create_out_dir(out)?;
    let svg = out.join("ident.svg");
    plot(&svg, &axes)?;
    Ok(svg)
}
