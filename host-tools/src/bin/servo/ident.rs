//! `servo ident` and `servo bench ident` (seed 001).

use super::*;

#[allow(clippy::too_many_arguments)]
pub fn ident(
    axes: &[String],
    set: &[String],
    anti_resonance: &[String],
    amplitude: f64,
    snr_db: Option<f64>,
    model: &[PathBuf],
    common: &Common,
) -> Result<bool> {
    use host_tools::ident_report::{identify_axis, plot, replot};
    let out = common.out.clone().unwrap_or_else(|| default_out("ident"));
    if !model.is_empty() {
        let svg = replot(model, &out)?;
        println!("re-plotted {} model(s) → {}", model.len(), svg.display());
        return Ok(true);
    }
    let mut parameters: std::collections::BTreeMap<String, std::collections::BTreeMap<String, host_tools::scenario::Value>> =
        axes.iter().map(|a| (a.clone(), Default::default())).collect();
    for s in set {
        let (axis, rest) = s.split_once(':').ok_or_else(|| anyhow::anyhow!("--set `{s}`: use AXIS:NAME=VALUE"))?;
        let (k, v) = host_tools::circle_report::parse_assignment(rest)?;
        parameters.get_mut(axis).ok_or_else(|| anyhow::anyhow!("--set `{s}`: no axis `{axis}` in --axes"))?.insert(k, v);
    }
    for s in anti_resonance {
        let (axis, hz) = s.split_once('=').ok_or_else(|| anyhow::anyhow!("--anti-resonance `{s}`: use AXIS=HZ"))?;
        let hz: f64 = hz.parse().map_err(|_| anyhow::anyhow!("--anti-resonance `{s}`: `{hz}` is not a frequency"))?;
        if !(hz.is_finite() && hz > 0.0) {
            bail!("--anti-resonance `{s}`: the frequency must be positive");
        }
        let load = servo_axis::plant::PlantParams::default().load_inertia;
        parameters
            .get_mut(axis)
            .ok_or_else(|| anyhow::anyhow!("--anti-resonance `{s}`: no axis `{axis}` in --axes"))?
            .extend(host_tools::identification::absorber_parameters(hz, 0.05, load));
    }
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("identification", common.json);
    let mut results = Vec::new();
    for (i, axis) in axes.iter().enumerate() {
        pb.set_prefix(format!("axis {axis}"));
        pb.set_position((i * 1000 / axes.len()) as u64);
        results.push(identify_axis(&fmu, axis, &parameters[axis], amplitude, snr_db, &out)?);
    }
    pb.finish_and_clear();
    let plotted: Vec<_> = results
        .iter()
        .map(|r| {
            let t = Trace::read_csv(&r.files[1])?;
            let (f, g, p) = (t.column("frequency").unwrap_or_default(), t.column("gain_db").unwrap_or_default(), t.column("phase_deg").unwrap_or_default());
            let pts = (0..f.len()).map(|i| host_tools::frequency_response::ResponsePoint { frequency: f[i], gain_db: g[i], phase_deg: p[i], quality: 1.0 }).collect();
            Ok((r.model.clone(), pts))
        })
        .collect::<Result<_>>()?;
    let svg = out.join("ident.svg");
    plot(&svg, &plotted)?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"axes": results, "plot": svg}))?);
        return Ok(true);
    }
    println!("servo ident — M-sequence degree {} at 1 kHz on the torque, one 2.05 s period measured after 0.5 s of transients", host_tools::identification::DEGREE);
    for r in &results {
        let m = &r.model;
        match (m.anti_resonance, m.resonance) {
            (Some(z), p) => println!(
                "  {}: anti-resonance {:.3} Hz, damping {:.4}; resonance {}; gain {:.4e}; fit band {:.1}–{:.1} Hz, rms fit error {:.1} %{}",
                m.axis,
                z.hz,
                z.damping,
                p.map_or("-".into(), |p| format!("{:.2} Hz, damping {:.4}", p.hz, p.damping)),
                m.gain,
                m.band.0,
                m.band.1,
                m.fit_error * 100.0,
                r.snr_db.map_or(String::new(), |s| format!(" (accelerometer noise {:.3e} rad/s² for {s} dB SNR)", r.noise_std))
            ),
            (None, _) => println!("  {}: no anti-resonance found (rigid axis, N = 1); gain {:.4e}", m.axis, m.gain),
        }
        for f in &r.files {
            println!("    → {}", f.display());
        }
    }
    println!("  → {}", svg.display());
    Ok(true)
}

pub fn bench_ident(common: &Common) -> Result<bool> {
    use host_tools::identification::{absorber_parameters, true_anti_resonance};
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let out = common.out.clone().unwrap_or_else(|| default_out("bench/ident"));
    let load = servo_axis::plant::PlantParams::default().load_inertia;
    let cases: Vec<(&str, Vec<(&str, Option<f64>)>)> = vec![
        ("two axes", vec![("x", Some(40.0)), ("y", Some(70.0))]),
        ("three axes", vec![("x", Some(40.0)), ("y", Some(70.0)), ("z", Some(55.0))]),
        ("rigid axis", vec![("w", None)]),
    ];
    let mut rows = Vec::new();
    let mut ok = true;
    let pb = progress_bar("ident bench", common.json);
    let total: usize = cases.iter().map(|c| c.1.len()).sum();
    let mut done = 0;
    for (case, axes) in &cases {
        for (axis, hz) in axes {
            pb.set_position((done * 1000 / total) as u64);
            done += 1;
            let params = hz.map(|h| absorber_parameters(h, 0.05, load)).unwrap_or_default();
            let r = host_tools::ident_report::identify_axis(&fmu, axis, &params, 0.05, Some(20.0), &out.join(case.replace(' ', "_")))?;
            let truth = hz.map(|h| {
                let w = std::f64::consts::TAU * h;
                true_anti_resonance(load, load * w * w, 2.0 * 0.05 * load * w)
            });
            let (f_err, d_err) = match (truth, r.model.anti_resonance) {
                (Some(t), Some(z)) => ((z.hz - t.hz) / t.hz, (z.damping - t.damping) / t.damping),
                (None, None) => (0.0, 0.0),
                _ => (f64::INFINITY, f64::INFINITY),
            };
            ok &= f_err.abs() <= 0.01 && d_err.abs() <= 0.2;
            rows.push(serde_json::json!({"case": case, "axis": axis, "truth": truth, "model": r.model, "frequency_error": f_err, "damping_error": d_err}));
        }
    }
    pb.finish_and_clear();
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "ident", "rows": rows, "passed": ok}))?);
        return Ok(ok);
    }
    println!("servo bench ident — seed 001: accelerometer noise at 20 dB SNR, 2.05 s of M-sequence measured after 0.5 s of transients");
    println!("  {:<11} {:<5} {:>12} {:>12} {:>12} {:>12} {:>10} {:>10}", "case", "axis", "true Hz", "found Hz", "true ζ", "found ζ", "Hz err %", "ζ err %");
    for r in &rows {
        let t = &r["truth"];
        let m = &r["model"]["anti_resonance"];
        let num = |v: &serde_json::Value, k: &str| v.get(k).and_then(|x| x.as_f64()).map_or("-".to_string(), |x| format!("{x:.4}"));
        println!(
            "  {:<11} {:<5} {:>12} {:>12} {:>12} {:>12} {:>10.3} {:>10.2}",
            r["case"].as_str().unwrap_or(""),
            r["axis"].as_str().unwrap_or(""),
            num(t, "hz"),
            num(m, "hz"),
            num(t, "damping"),
            num(m, "damping"),
            r["frequency_error"].as_f64().unwrap_or(f64::NAN) * 100.0,
            r["damping_error"].as_f64().unwrap_or(f64::NAN) * 100.0
        );
    }
    println!("  goal: at most 1 % in frequency and 20 % in damping: {}", if ok { "met" } else { "NOT met" });
    Ok(ok)
}

pub fn tune(models: &[PathBuf], no_check: bool, common: &Common) -> Result<bool> {
    use host_tools::frequency_response::ResponsePoint;
    use host_tools::identification::AxisModel;
    use host_tools::tuning::{command_to_load, corrections, spread};
    let out = common.out.clone().unwrap_or_else(|| default_out("tune"));
    std::fs::create_dir_all(&out)?;
    let models: Vec<AxisModel> = models
        .iter()
        .map(|p| -> Result<AxisModel> {
            let text = std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?;
            serde_json::from_str(&text).with_context(|| format!("{} is not a model file", p.display()))
        })
        .collect::<Result<_>>()?;
    if models.len() < 2 {
        bail!("tuning makes axes alike: give at least two model files");
    }
    let defaults = control_core::Params::default();
    let bandwidth = defaults.position.kp as f64 / std::f64::consts::TAU;
    let (pole_hz, filters) = corrections(&models, bandwidth)?;
    for f in &filters {
        let text: String = f.parameters().iter().map(|(k, v)| format!("{k:?} = {}\n", match v {
            host_tools::scenario::Value::Int(i) => i.to_string(),
            other => format!("{:?}", other.as_f64()),
        })).collect();
        std::fs::write(out.join(format!("{}.corr.toml", f.axis)), format!("# servo tune: response correction of axis {}\n{text}", f.axis))?;
    }
    let mut report = serde_json::json!({"f_pole_hz": pole_hz, "position_bandwidth_hz": bandwidth, "filters": filters});
    if !no_check {
        let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
        let frequencies: Vec<u32> = (1..=(2.0 * bandwidth).round() as u32).collect();
        let pb = progress_bar("tune check", common.json);
        let mut before = Vec::new();
        let mut after = Vec::new();
        for (i, (m, f)) in models.iter().zip(&filters).enumerate() {
            pb.set_position((i * 1000 / models.len()) as u64);
            let mut p: std::collections::BTreeMap<String, host_tools::scenario::Value> =
                m.fmu_parameters.iter().map(|(k, v)| (k.clone(), host_tools::scenario::Value::Float(*v))).collect();
            p.insert("plant.motor_coulomb".into(), host_tools::scenario::Value::Float(0.0));
            p.insert("plant.load_coulomb".into(), host_tools::scenario::Value::Float(0.0));
            before.push(command_to_load(&fmu, &p, &frequencies)?);
            p.extend(f.parameters());
            after.push(command_to_load(&fmu, &p, &frequencies)?);
        }
        pb.finish_and_clear();
        let upto = |r: &[Vec<ResponsePoint>]| -> Vec<Vec<ResponsePoint>> {
            r.iter().map(|v| v.iter().copied().filter(|p| p.frequency <= bandwidth + 1e-9).collect()).collect()
        };
        let (b, a) = (spread(&upto(&before)), spread(&upto(&after)));
        let mut curves: Vec<(String, Vec<ResponsePoint>)> = Vec::new();
        for (m, (bv, av)) in models.iter().zip(before.iter().zip(&after)) {
            curves.push((format!("{} before", m.axis), bv.clone()));
            curves.push((format!("{} after", m.axis), av.clone()));
        }
        let refs: Vec<(&str, &[ResponsePoint])> = curves.iter().map(|(l, c)| (l.as_str(), c.as_slice())).collect();
        let svg = out.join("tune.svg");
        host_tools::bode_plot::plot_bode(&svg, "Command → machine-end position, before and after the correction", &refs, Some(bandwidth))?;
        report["check"] = serde_json::json!({"spread_before": b, "spread_after": a, "up_to_hz": bandwidth, "plot": svg});
    }
    std::fs::write(out.join("tune.json"), serde_json::to_string_pretty(&report)?)?;
    if common.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
        return Ok(true);
    }
    println!("servo tune — F: critically damped pole pairs at {pole_hz:.1} Hz (position bandwidth {bandwidth:.1} Hz)");
    for f in &filters {
        let secs: Vec<String> = f
            .sections
            .iter()
            .map(|s| match s.zeros {
                Some((hz, d)) => format!("N({hz:.2} Hz, ζ {d:.3})/F"),
                None => "1/F".into(),
            })
            .collect();
        println!("  {}: {}  → {}", f.axis, secs.join(" · "), out.join(format!("{}.corr.toml", f.axis)).display());
    }
    if let Some(c) = report.get("check") {
        println!(
            "  largest difference between axes' command → machine-end responses up to {:.1} Hz: before {:.3} dB / {:.2}°, after {:.3} dB / {:.2}°",
            bandwidth, c["spread_before"][0].as_f64().unwrap_or(f64::NAN), c["spread_before"][1].as_f64().unwrap_or(f64::NAN),
            c["spread_after"][0].as_f64().unwrap_or(f64::NAN), c["spread_after"][1].as_f64().unwrap_or(f64::NAN)
        );
    }
    Ok(true)
}
