//! The model file of an axis (`<axis>.model.json`): written by `servo ident`, edited by the
//! user, read by `servo ident --model` and `servo tune`. Both read it through [`AxisModel::load`],
//! which refuses a file whose values no axis can have, naming the field and its value.

use anyhow::{bail, Context, Result};

use crate::ident::axis_name::{is_axis_name, ALLOWED};
use crate::ident::identification::{AxisModel, Factor};

impl AxisModel {
    /// Read and check a model file (`servo ident` writes them; the user may edit them).
    pub fn load(path: &std::path::Path) -> Result<Self> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let model: AxisModel =
            serde_json::from_str(&text).with_context(|| format!("{} is not a model file", path.display()))?;
        if let Err(why) = model.check() {
            bail!("{}: {why}", path.display());
        }
        Ok(model)
    }

    /// Why this model cannot be an axis's (the field, its value and the rule), if it cannot.
    pub fn check(&self) -> std::result::Result<(), String> {
        if !is_axis_name(&self.axis) {
            return Err(format!(
                "`axis` = {:?}: not an axis name (axis names name the output files: {ALLOWED})",
                self.axis
            ));
        }
        if let Some(z) = self.anti_resonance {
            check_factor(z, "anti_resonance", "the anti-resonance", true)?;
        }
        if let Some(p) = self.resonance {
            check_factor(p, "resonance", "the resonance", false)?;
        }
        if !(self.gain.is_finite() && self.gain > 0.0) {
            return Err(format!(
                "`gain` = {}: the torque → acceleration gain 1/J must be positive and finite (1/(kg·m²))",
                self.gain
            ));
        }
        let (lo, hi) = self.band;
        if !(lo.is_finite() && hi.is_finite() && lo > 0.0 && lo < hi) {
            return Err(format!(
                "`band` = [{lo}, {hi}]: the fit band must be two finite frequencies 0 < low < high (Hz)"
            ));
        }
        if !(self.fit_error.is_finite() && self.fit_error >= 0.0) {
            return Err(format!("`fit_error` = {}: a relative error is finite and >= 0", self.fit_error));
        }
        if let Some(e) = self.anti_resonance_error {
            for (field, v) in [("frequency", e.frequency), ("damping", e.damping)] {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(format!("`anti_resonance_error.{field}` = {v}: a relative error is finite and >= 0"));
                }
            }
        }
        if let Some((k, v)) = self.fmu_parameters.iter().find(|(_, v)| !v.is_finite()) {
            return Err(format!("`fmu_parameters.{k}` = {v}: FMU parameters are finite numbers"));
        }
        Ok(())
    }
}

/// A zero pair may have no damping (an undamped anti-resonance); a pole pair may not.
fn check_factor(f: Factor, field: &str, what: &str, zero_damping_allowed: bool) -> std::result::Result<(), String> {
    if !(f.hz.is_finite() && f.hz > 0.0) {
        return Err(format!("`{field}.hz` = {}: {what}'s frequency must be positive and finite (Hz)", f.hz));
    }
    let damped = if zero_damping_allowed { f.damping >= 0.0 } else { f.damping > 0.0 };
    if !(f.damping.is_finite() && damped) {
        let rule = if zero_damping_allowed { ">= 0" } else { "> 0" };
        return Err(format!(
            "`{field}.damping` = {}: {what}'s damping must be finite and {rule} (a negative damping puts its roots in the right half plane)",
            f.damping
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn good() -> AxisModel {
        AxisModel {
            axis: "x".into(),
            anti_resonance: Some(Factor { hz: 40.0, damping: 0.05 }),
            resonance: Some(Factor { hz: 51.0, damping: 0.06 }),
            gain: 4000.0,
            band: (12.0, 240.0),
            fit_error: 0.001,
            anti_resonance_error: None,
            fmu_parameters: [("plant.absorber_inertia".to_string(), 1e-4)].into(),
        }
    }

    /// Each edit a user could make that no axis has is refused with its field and value; the
    /// unedited model and an undamped anti-resonance pass.
    #[test]
    fn a_model_no_axis_can_have_is_refused_naming_the_field() {
        assert_eq!(good().check(), Ok(()));
        let mut undamped = good();
        undamped.anti_resonance = Some(Factor { hz: 40.0, damping: 0.0 });
        assert_eq!(undamped.check(), Ok(()));
        type Edit = fn(&mut AxisModel);
        let cases: Vec<(Edit, &str)> = vec![
            (|m| m.anti_resonance = Some(Factor { hz: -5.0, damping: 0.05 }), "`anti_resonance.hz` = -5"),
            (|m| m.anti_resonance = Some(Factor { hz: 40.0, damping: -1.0 }), "`anti_resonance.damping` = -1"),
            (|m| m.resonance = Some(Factor { hz: 51.0, damping: 0.0 }), "`resonance.damping` = 0"),
            (|m| m.resonance = Some(Factor { hz: f64::NAN, damping: 0.1 }), "`resonance.hz` = NaN"),
            (|m| m.gain = 0.0, "`gain` = 0"),
            (|m| m.gain = -3.0, "`gain` = -3"),
            (|m| m.band = (240.0, 12.0), "`band` = [240, 12]"),
            (|m| m.fit_error = -0.1, "`fit_error` = -0.1"),
            (|m| m.axis = "../evil".into(), "`axis` = \"../evil\""),
            (|m| m.axis = String::new(), "`axis` = \"\""),
            (
                |m| _ = m.fmu_parameters.insert("plant.load_inertia".into(), f64::INFINITY),
                "`fmu_parameters.plant.load_inertia` = inf",
            ),
        ];
        for (edit, named) in cases {
            let mut m = good();
            edit(&mut m);
            let e = m.check().unwrap_err();
            assert!(e.contains(named), "{named}: {e}");
        }
    }
}
