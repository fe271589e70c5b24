//! The response correction (seed 001) as the FMU and the drive take it: its sections, their
//! `corr.*` FMU parameters, the core's `CorrectionParams` and the drive's `LoadCorrection`
//! frame; and the axes of a `servo tune` output directory.

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::{Deserialize, Serialize};
use servo_axis::variables::name;

use crate::fmu::scenario::Value;

/// One correction section as the FMU takes it.
#[derive(Clone, Copy, Debug, Serialize, Deserialize, PartialEq)]
pub struct Section {
    /// Anti-resonance numerator (Hz, damping); None: F alone.
    pub zeros: Option<(f64, f64)>,
    pub pole_hz: f64,
    pub pole_damping: f64,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct AxisCorrection {
    pub axis: String,
    pub sections: Vec<Section>,
}

impl AxisCorrection {
    /// `corr.*` FMU parameters.
    pub fn parameters(&self) -> BTreeMap<String, Value> {
        let mut p = BTreeMap::new();
        p.insert(name::corr_count.into(), Value::Int(self.sections.len() as i64));
        for (s, names) in self.sections.iter().zip(servo_axis::parameters::CORRECTION_SECTIONS) {
            let (zh, zd) = s.zeros.unwrap_or((0.0, 0.0));
            for (n, x) in names.into_iter().zip([zh, zd, s.pole_hz, s.pole_damping]) {
                p.insert(n.into(), Value::Float(x));
            }
        }
        p
    }
}

/// The core's filter parameters of a correction (what the FMU builds from the `corr.*`
/// parameters and the drive receives in a `LoadCorrection` frame), checked against the core's
/// own rules before any FMU or drive sees them.
pub fn core_parameters(c: &AxisCorrection) -> Result<control_core::response_correction::CorrectionParams> {
    use control_core::response_correction::{CorrectionParams, CorrectionSection, SecondOrder};
    let mut p = CorrectionParams { count: c.sections.len(), ..Default::default() };
    if c.sections.len() > p.sections.len() {
        bail!("axis {}: {} sections; the filter holds {}", c.axis, c.sections.len(), p.sections.len());
    }
    for (o, s) in p.sections.iter_mut().zip(&c.sections) {
        *o = CorrectionSection {
            zeros: s.zeros.map(|(hz, damping)| SecondOrder { hz: hz as f32, damping: damping as f32 }),
            poles: SecondOrder { hz: s.pole_hz as f32, damping: s.pole_damping as f32 },
        };
    }
    let period = control_core::Params::default().rates.position_period();
    p.validate(period).map_err(|e| anyhow::anyhow!("axis {}: {e}", c.axis))?;
    Ok(p)
}

/// Check a correction against the core's rules.
pub fn validate(c: &AxisCorrection) -> Result<()> {
    core_parameters(c).map(|_| ())
}

/// The drive's `LoadCorrection` request for a correction, as one framed message (postcard,
/// CRC-16, COBS, zero delimiter) ready for the link.
pub fn drive_frame(c: &AxisCorrection) -> Result<Vec<u8>> {
    use control_core::protocol::{encode, Request, MAX_FRAME};
    let mut buf = vec![0u8; MAX_FRAME + 8];
    let n = encode(&Request::LoadCorrection(core_parameters(c)?), &mut buf)
        .map_err(|e| anyhow::anyhow!("axis {}: {e}", c.axis))?;
    buf.truncate(n);
    Ok(buf)
}

/// One tuned axis: the FMU parameters the tuning measured it with, its correction parameters.
pub type TunedAxisParameters = (BTreeMap<String, Value>, BTreeMap<String, Value>);

/// The x and y axes of a `servo tune` output directory.
pub fn tuned_axes(dir: &Path) -> Result<[TunedAxisParameters; 2]> {
    let path = dir.join("tune.json");
    let text = std::fs::read_to_string(&path)
        .with_context(|| format!("cannot read {} (run `servo tune --out {}` first)", path.display(), dir.display()))?;
    let json: serde_json::Value =
        serde_json::from_str(&text).with_context(|| format!("{} is not a tuning file", path.display()))?;
    let axes = json["axes"].as_array().ok_or_else(|| anyhow::anyhow!("{}: no axes", path.display()))?;
    let axis = |name: &str| -> Result<TunedAxisParameters> {
        let a = axes.iter().find(|a| a["axis"] == name).ok_or_else(|| {
            anyhow::anyhow!("{}: no axis `{name}` (the XY circle needs axes x and y)", path.display())
        })?;
        let floats = |v: &serde_json::Value| -> BTreeMap<String, Value> {
            v.as_object()
                .map(|o| o.iter().filter_map(|(k, v)| v.as_f64().map(|x| (k.clone(), Value::Float(x)))).collect())
                .unwrap_or_default()
        };
        let base = floats(&a["fmu_parameters"]);
        let correction: crate::correction::AxisCorrection = serde_json::from_value(a["correction"].clone())
            .with_context(|| format!("{}: axis {name}: the correction is not readable", path.display()))?;
        crate::correction::validate(&correction)?;
        let corr = correction.parameters();
        Ok((base, corr))
    };
    Ok([axis("x")?, axis("y")?])
}
