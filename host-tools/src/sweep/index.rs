//! `servo sweep`'s part of out/index.html: the drive's correlator against the host's
//! equivalent-time estimate (the command's own check), the Bode plot and the data.

use std::path::Path;

use crate::page::{read_result, relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let dir = root.join("sweep");
    let path = dir.join("sweep.json");
    let (json, unreadable) = match read_result(&path) {
        Ok(json) => (json?, vec![]),
        Err(why) => (serde_json::Value::Null, vec![(relative(root, &path), why)]),
    };
    let mut s = Section {
        unreadable,
        title: "Frequency response, phase-shifted stepped sine (seed 000)".into(),
        command: "servo sweep --oracle".into(),
        plots: vec![relative(root, &dir.join("bode.svg"))],
        files: ["sweep.csv", "sweep.json"].iter().map(|f| relative(root, &dir.join(f))).collect(),
        ..Default::default()
    };
    if let Some(t) = json["measurement_time_s"].as_f64() {
        s.numbers.push(("measurement time".into(), format!("{t:.2} s")));
    }
    if let Some(points) = json["stream"].as_array() {
        s.numbers.push(("points measured".into(), points.len().to_string()));
    }
    if let Some(hz) = json["acquisition_hz"].as_f64() {
        s.numbers.push(("acquisition rate".into(), format!("{hz} Hz")));
    }
    for (key, what) in [
        ("imprecise_hz", "points above the precision target"),
        ("limited_hz", "points measured with the output limited"),
        ("unmeasured_hz", "points not measured"),
    ] {
        if let Some(v) = json[key].as_array() {
            s.numbers.push((what.into(), v.len().to_string()));
        }
    }
    if let (Some(db), Some(deg)) = (json["stream_vs_online"][0].as_f64(), json["stream_vs_online"][1].as_f64()) {
        s.verdicts.push((
            format!(
                "equivalent-time stream vs the drive's correlator: {db:.1e} dB, {deg:.1e} deg (≤ 0.01 dB, 0.1 deg)"
            ),
            db <= 0.01 && deg <= 0.1,
        ));
    }
    Some(s)
}
