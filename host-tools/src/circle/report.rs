//! `servo circle`: run the two-axis circle or the single-axis pseudo-circle (optionally twice,
//! with and without some parameter overrides), write the plot, points and figures.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::Serialize;

use crate::circle::plot::plot_circle;
use crate::fmu::circle::{single_axis, two_axis, CircleRequest, Figure, Roundness};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::trace::Trace;

#[derive(Clone, Debug, Serialize)]
pub struct CircleFigures {
    pub label: String,
    pub feedback: Roundness,
    /// Single axis only: the feedback against the quarter-period-shifted command.
    pub against_command: Option<Roundness>,
}

#[derive(Clone, Debug, Serialize)]
pub struct CircleReport {
    pub mode: &'static str,
    pub radius: f64,
    pub feed: f64,
    pub samples_per_revolution: usize,
    pub runs: Vec<CircleFigures>,
    /// With a comparison: largest protrusion of the second run over the first's.
    pub protrusion_ratio: Option<f64>,
    /// With a comparison: roundness of the second run over the first's.
    pub roundness_ratio: Option<f64>,
    pub files: Vec<PathBuf>,
}

/// The points of a figure and its reference as CSV (index, both figures, polar form).
pub fn write_points(path: &Path, command: &Figure, feedback: &Figure) -> Result<()> {
    let mut t = Trace::new(
        ["index", "command_x", "command_y", "feedback_x", "feedback_y", "angle_deg", "radius"]
            .map(String::from)
            .to_vec(),
    );
    let polar = feedback.polar();
    for i in 0..feedback.x.len() {
        t.rows.push(vec![i as f64, command.x[i], command.y[i], feedback.x[i], feedback.y[i], polar[i].0, polar[i].1]);
    }
    t.write_csv(path)
}

/// Overrides of the second run: for both axes, and for each axis alone.
#[derive(Clone, Debug, Default)]
pub struct Comparison {
    pub both: Vec<(String, Value)>,
    pub x: BTreeMap<String, Value>,
    pub y: BTreeMap<String, Value>,
    /// Plot each run's shape about its own mean radius (the runs' radii differ by more
    /// than their roundness, as with and without a response correction).
    pub shape_only: bool,
}

impl Comparison {
    pub fn is_empty(&self) -> bool {
        self.both.is_empty() && self.x.is_empty() && self.y.is_empty()
    }
}

/// Run one or two configurations (`compare` = overrides of the second run).
pub fn run(
    fmu: &Fmu,
    request: &CircleRequest,
    single: bool,
    compare: &Comparison,
    labels: (&str, &str),
    out: &Path,
) -> Result<(CircleReport, Vec<(String, crate::fmu::circle::PseudoCircleRun)>)> {
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let (_, _, n) = request.timing()?;
    if single {
        request.quarter()?;
    }
    let mut requests = vec![(labels.0.to_string(), request.clone())];
    if !compare.is_empty() {
        let mut second = request.clone();
        for (k, v) in &compare.both {
            second.x_parameters.insert(k.clone(), *v);
            second.y_parameters.insert(k.clone(), *v);
        }
        second.x_parameters.extend(compare.x.clone());
        second.y_parameters.extend(compare.y.clone());
        requests.push((labels.1.to_string(), second));
    }
    let mut runs = Vec::new();
    let mut figures: Vec<(String, Figure)> = Vec::new();
    let mut files = Vec::new();
    let mut reference = None;
    let mut pseudo_runs = Vec::new();
    for (i, (label, r)) in requests.iter().enumerate() {
        let suffix = if i == 0 { String::new() } else { "_compare".into() };
        if single {
            let p = single_axis(fmu, r)?;
            let csv = out.join(format!("pseudo_circle{suffix}.csv"));
            write_points(&csv, &p.command, &p.feedback)?;
            let trace_csv = out.join(format!("pseudo_circle{suffix}_trace.csv"));
            p.trace.write_csv(&trace_csv)?;
            files.extend([csv, trace_csv]);
            runs.push(CircleFigures {
                label: label.clone(),
                feedback: p.feedback.roundness(r.radius),
                against_command: Some(p.against_command.roundness(r.radius)),
            });
            reference.get_or_insert(p.command.clone());
            figures.push((format!("{label}: (x(t), x(t − T/4))"), p.feedback.clone()));
            figures.push((format!("{label}: (x(t), command(t − T/4))"), p.against_command.clone()));
            pseudo_runs.push((label.clone(), p));
        } else {
            let c = two_axis(fmu, r)?;
            let csv = out.join(format!("circle{suffix}.csv"));
            write_points(&csv, &c.command, &c.feedback)?;
            files.push(csv);
            for (axis, t) in ["x", "y"].iter().zip(&c.traces) {
                let p = out.join(format!("circle{suffix}_{axis}_trace.csv"));
                t.write_csv(&p)?;
                files.push(p);
            }
            runs.push(CircleFigures {
                label: label.clone(),
                feedback: c.feedback.roundness(r.radius),
                against_command: None,
            });
            reference.get_or_insert(c.command.clone());
            figures.push((label.clone(), c.feedback));
        }
    }
    let reference = reference.expect("one run at least");
    let mut plotted: Vec<(&str, &Figure)> = vec![("command (reference)", &reference)];
    plotted.extend(figures.iter().map(|(l, f)| (l.as_str(), f)));
    let notes: Vec<String> = runs
        .iter()
        .map(|r| {
            format!(
                "{}: roundness {:.3e} rad, mean radius error {:+.3e} rad, largest quadrant protrusion {:.3e} rad",
                r.label, r.feedback.roundness, r.feedback.mean_radius_error, r.feedback.max_protrusion
            )
        })
        .collect();
    let svg = out.join(if single { "pseudo_circle.svg" } else { "circle.svg" });
    let title = format!(
        "{} — radius {} rad, feed {} rad/s, {} samples/rev",
        if single { "single-axis pseudo-circle" } else { "two-axis circle" },
        request.radius,
        request.feed,
        n
    );
    plot_circle(&svg, &title, &notes, request.radius, &plotted, compare.shape_only)?;
    files.push(svg);
    let protrusion_ratio = (runs.len() == 2).then(|| runs[1].feedback.max_protrusion / runs[0].feedback.max_protrusion);
    let roundness_ratio = (runs.len() == 2).then(|| runs[1].feedback.roundness / runs[0].feedback.roundness);
    let report = CircleReport {
        mode: if single { "single" } else { "two-axis" },
        radius: request.radius,
        feed: request.feed,
        samples_per_revolution: n,
        runs,
        protrusion_ratio,
        roundness_ratio,
        files: files.clone(),
    };
    let json = out.join(if single { "pseudo_circle.json" } else { "circle.json" });
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    Ok((CircleReport { files: [files, vec![json]].concat(), ..report }, pseudo_runs))
}

impl CircleReport {
    pub fn print(&self) {
        println!(
            "servo circle — {}: radius {} rad, feed {} rad/s, {} samples per revolution",
            self.mode, self.radius, self.feed, self.samples_per_revolution
        );
        for r in &self.runs {
            println!("  {}:", r.label);
            print_roundness("feedback", &r.feedback);
            if let Some(a) = &r.against_command {
                print_roundness("feedback vs shifted command", a);
            }
        }
        if let Some(ratio) = self.protrusion_ratio {
            println!("  largest quadrant protrusion, second run / first: {ratio:.3}");
        }
        if let Some(ratio) = self.roundness_ratio {
            println!(
                "  roundness, second run / first: {ratio:.4} ({:.1}× {})",
                1.0 / ratio,
                if ratio < 1.0 { "smaller" } else { "LARGER" }
            );
        }
        for f in &self.files {
            println!("  → {}", f.display());
        }
    }
}

/// One line of a report: a figure's roundness, mean radius error and protrusions.
pub fn print_roundness(name: &str, f: &Roundness) {
    println!(
        "    {name:<34} roundness {:>10.3e} rad  mean radius error {:>+10.3e} rad  protrusions (deg: height) {}",
        f.roundness,
        f.mean_radius_error,
        f.protrusions.iter().map(|(a, h)| format!("{a:.1}°: {h:.2e}")).collect::<Vec<_>>().join(", ")
    );
}
