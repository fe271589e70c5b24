//! `servo ident` and `servo tune`'s part of out/index.html: measured responses and models, the
//! axes before and after the correction, the files a user edits or loads.

use std::path::Path;

use crate::page::{files_with, relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let (ident, tune) = (root.join("ident"), root.join("tune"));
    let models = files_with(&ident, "json");
    if models.is_empty() && !tune.join("tune.json").is_file() {
        return None;
    }
    let mut files: Vec<_> = models.iter().map(|p| relative(root, p)).collect();
    files.extend(files_with(&tune, "toml").iter().map(|p| relative(root, p)));
    let tune_json = files_with(&tune, "json");
    files.extend(tune_json.iter().map(|p| relative(root, p)));
    let mut s = Section::default();
    for path in models.iter().chain(&tune_json) {
        let Some(json) = s.read_result(root, path) else { continue };
        if let Some(axis) = json["axis"].as_str() {
            let zero = &json["anti_resonance"];
            let value = match (zero["hz"].as_f64(), zero["damping"].as_f64()) {
                (Some(hz), Some(d)) => format!("{hz:.2} Hz, damping {d:.3}"),
                _ => "none (a rigid axis)".into(),
            };
            s.numbers.push((format!("axis {axis}: anti-resonance"), value));
            if let Some(e) = json["fit_error"].as_f64() {
                s.numbers.push((format!("axis {axis}: fit error"), format!("{e:.3}")));
            }
        }
        let pair = |v: &serde_json::Value| match (v[0].as_f64(), v[1].as_f64()) {
            (Some(db), Some(deg)) => Some(format!("{db:.4} dB, {deg:.3}°")),
            _ => None,
        };
        if let (Some(before), Some(after)) = (pair(&json["spread_before"]), pair(&json["spread_after"])) {
            s.numbers.push(("the axes' responses apart up to the position-loop bandwidth, before".into(), before));
            s.numbers.push(("after the correction".into(), after));
        }
    }
    Some(Section {
        title: "Identification and response correction (seed 001)".into(),
        command: "servo ident …; servo tune --model out/ident/*.model.json".into(),
        plots: [files_with(&ident, "svg"), files_with(&tune, "svg")]
            .concat()
            .iter()
            .map(|p| relative(root, p))
            .collect(),
        files,
        ..s
    })
}
