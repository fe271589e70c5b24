//! `servo autotune`'s part of out/index.html: the gains and filters it chose, their designed
//! margins, each verification's measured margins with its verdict (the twin's, and the
//! drive's with --device), the predicted responses, and the plots.

use std::path::Path;

use crate::page::{relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let dir = root.join("autotune");
    let path = dir.join("autotune.json");
    if !path.exists() {
        return None;
    }
    let mut s = Section {
        title: "Velocity and position loops tuned from the measured response".into(),
        command: "servo autotune".into(),
        plots: ["plant.svg", "open-loop.svg", "nyquist.svg", "closed-loop.svg", "step.svg", "disturbance.svg"]
            .iter()
            .map(|f| relative(root, &dir.join(f)))
            .collect(),
        files: ["autotune.toml", "calibrated-plant.toml", "autotune.json"]
            .iter()
            .map(|f| relative(root, &dir.join(f)))
            .collect(),
        ..Default::default()
    };
    let json = s.read_result(root, &path)?;
    let t = &json["design"]["tuning"];
    if let (Some(kp), Some(ki)) = (t["kp"].as_f64(), t["ki"].as_f64()) {
        s.numbers.push(("velocity loop".into(), format!("kp {kp:.4} N·m·s/rad, ki {ki:.2} N·m/rad")));
    }
    let notch_text = |n: &serde_json::Value, name: &str| match (n["hz"].as_f64(), n["q"].as_f64(), n["depth"].as_f64())
    {
        (Some(hz), Some(q), Some(depth)) => Some(format!("{name} {hz:.1} Hz, Q {q:.2}, depth {depth:.2}")),
        _ => None,
    };
    let mut notch = notch_text(&t["notch"], "notch").unwrap_or_else(|| "no notch".into());
    if let Some(second) = notch_text(&t["notch2"], "second notch") {
        notch = format!("{notch}; {second}");
    }
    let low_pass = match t["low_pass_hz"].as_f64().filter(|&hz| hz > 0.0) {
        Some(hz) => format!("low-pass {hz:.0} Hz"),
        None => "no low-pass".into(),
    };
    s.numbers.push(("torque filters".into(), format!("{notch}; {low_pass}")));
    let m = &json["design"]["margins"];
    if let (Some(bw), Some(pm), Some(gm), Some(ms)) = (
        m["bandwidth_hz"].as_f64(),
        m["phase_margin_deg"].as_f64(),
        m["gain_margin_db"].as_f64(),
        m["sensitivity_peak"].as_f64(),
    ) {
        let reserve = json["reserve"].as_str().unwrap_or("-");
        s.numbers.push((
            "designed".into(),
            format!(
                "bandwidth {bw:.0} Hz, phase margin {pm:.1}°, gain margin {gm:.1} dB, Ms {ms:.2} ({reserve} reserve)"
            ),
        ));
    }
    let p = &json["position"];
    if let (Some(kp), Some(ff)) = (p["kp"].as_f64(), p["velocity_feedforward"].as_f64()) {
        s.numbers.push(("position loop".into(), format!("kp {kp:.1} 1/s, velocity feed-forward {ff:.2}")));
    }
    for (key, on) in [("verification", "the twin"), ("drive_verification", "the drive")] {
        let v = &json[key];
        let Some(passed) = v["passed"].as_bool() else { continue };
        let pm = v["phase_margin_deg"].as_f64().map_or("no crossover measured".into(), |x| format!("{x:.1}°"));
        let ms = v["sensitivity_peak"].as_f64().map_or("-".into(), |x| format!("{x:.2}"));
        s.verdicts.push((
            format!("open loop measured on {on} with the new gains: phase margin {pm}, Ms {ms} (goal of the chosen margins)"),
            passed,
        ));
    }
    if let Some(seq) = json["saved_sequence"].as_u64() {
        s.numbers.push(("saved on the drive".into(), format!("record {seq}")));
    }
    let r = &json["responses"];
    if let (Some(o), Some(t)) = (r["tuned"]["overshoot_percent"].as_f64(), r["tuned"]["settling_time_s"].as_f64()) {
        s.numbers
            .push(("velocity step, predicted".into(), format!("overshoot {o:.1} %, settles in {:.1} ms", 1e3 * t)));
    }
    if let Some(t) = json["drive_time_s"].as_f64() {
        s.numbers.push(("drive time".into(), format!("{t:.1} s")));
    }
    Some(s)
}
