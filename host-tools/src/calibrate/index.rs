//! `servo calibrate`'s part of out/index.html: each calibrated value with its standard error
//! (and the twin's truth where there is one), the model's fit, the plots and the plant file.

use std::path::Path;

use crate::page::{relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let dir = root.join("calibrate");
    let path = dir.join("calibration.json");
    if !path.exists() {
        return None;
    }
    let mut s = Section {
        title: "The twin calibrated to the machine".into(),
        command: "servo calibrate".into(),
        plots: ["plant.svg", "friction.svg"].iter().map(|f| relative(root, &dir.join(f))).collect(),
        files: ["calibrated-plant.toml", "calibration.json"].iter().map(|f| relative(root, &dir.join(f))).collect(),
        ..Default::default()
    };
    let json = s.read_result(root, &path)?;
    for v in json["values"].as_array().into_iter().flatten() {
        let (Some(name), Some(value)) = (v["name"].as_str(), v["value"].as_f64()) else { continue };
        let unit = v["unit"].as_str().unwrap_or("");
        let mut text = format!("{value:.4e} {unit}");
        if let Some(se) = v["standard_error"].as_f64().filter(|x| x.is_finite()) {
            text += &format!(" ± {se:.2e}");
        }
        if let Some(e) = v["error_percent"].as_f64() {
            text += &format!(" ({e:+.2} % from the twin's truth)");
        }
        s.numbers.push((name.into(), text));
    }
    if let (Some(db), Some(deg)) = (json["fit"]["worst_gain_db"].as_f64(), json["fit"]["worst_phase_deg"].as_f64()) {
        s.numbers.push(("model vs measurement".into(), format!("within {db:.2} dB, {deg:.1}°")));
    }
    if let Some(t) = json["calibration"]["drive_time_s"].as_f64() {
        s.numbers.push(("drive time".into(), format!("{t:.1} s")));
    }
    Some(s)
}
