//! `servo circle`: run the two-axis circle or the single-axis pseudo-circle (optionally twice,
//! with and without some parameter overrides), write the plot, points and figures.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, Result};
use serde::Serialize;

use crate::circle::plot::plot_circle;
use crate::fmu::axis_health::Trip;
use crate::fmu::circle::{single_axis, two_axis, AxisHealth, CircleRequest, Figure, Roundness};
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::trace::Trace;

#[derive(Clone, Debug, Serialize)]
pub struct CircleFigures {
    pub label: String,
    /// None when a drive tripped during the run (see `axes`): a tripped axis stops following
    /// its command, and what it drew is not a measurement of the loop.
    pub feedback: Option<Roundness>,
    /// Single axis only: the feedback against the quarter-period-shifted command.
    pub against_command: Option<Roundness>,
    /// Each axis's drive during the run: a trip, the steps at the torque limit (empty where
    /// the run does not tell: a drive's figures).
    pub axes: Vec<AxisHealth>,
}

#[derive(Clone, Debug, Serialize)]
pub struct CircleReport {
    pub mode: &'static str,
    pub radius: f64,
    pub feed: f64,
    pub samples_per_revolution: usize,
    pub runs: Vec<CircleFigures>,
    /// With a comparison: largest protrusion of the second run over the first's (None where
    /// either is not measurable).
    pub protrusion_ratio: Option<f64>,
    /// With a comparison: roundness of the second run over the first's.
    pub roundness_ratio: Option<f64>,
    /// With --tuned: whether the correction made the circle rounder (the roundness ratio
    /// below 1), as `servo tune` says whether it brought the axes' responses closer.
    pub improved: Option<bool>,
    /// Runs measured with a torque command at its limit (also printed as WARNINGs): their
    /// figures are not the linear loop's where that happened in the measured revolution.
    pub warnings: Vec<String>,
    /// Why the command failed (a drive tripped during a run; with --tuned, the correction
    /// did not make the circle rounder); empty when it passed.
    pub failures: Vec<String>,
    pub passed: bool,
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
    /// The second run must be rounder than the first (a response correction's purpose, with
    /// --tuned): the command fails when it is not.
    pub must_be_rounder: bool,
}

impl Comparison {
    pub fn is_empty(&self) -> bool {
        self.both.is_empty() && self.x.is_empty() && self.y.is_empty()
    }

    /// `request` with the overrides.
    pub fn applied_to(&self, request: &CircleRequest) -> CircleRequest {
        let mut second = request.clone();
        for (k, v) in &self.both {
            second.x_parameters.insert(k.clone(), *v);
            second.y_parameters.insert(k.clone(), *v);
        }
        second.x_parameters.extend(self.x.clone());
        second.y_parameters.extend(self.y.clone());
        second
    }
}

/// Run one or two configurations (`compare` = overrides of the second run). Every request is
/// checked (timing, length, each run's parameters) before anything runs or is written.
pub fn run(
    fmu: &Fmu,
    request: &CircleRequest,
    single: bool,
    compare: &Comparison,
    labels: (&str, &str),
    out: &Path,
) -> Result<(CircleReport, Vec<(String, crate::fmu::circle::PseudoCircleRun)>)> {
    let (_, period, n) = request.timing()?;
    if single {
        request.quarter()?;
    }
    let mut requests = vec![(labels.0.to_string(), request.clone())];
    if !compare.is_empty() {
        requests.push((labels.1.to_string(), compare.applied_to(request)));
    }
    for (i, (label, r)) in requests.iter().enumerate() {
        let given = if i == 0 { "--set / --x-set / --y-set" } else { "the second run's --compare / --tuned" };
        r.check_parameters().with_context(|| format!("parameters of the run `{label}` ({given})"))?;
    }
    crate::paths::create_out_dir(out)?;
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
            let tripped = p.health.trip.is_some();
            runs.push(CircleFigures {
                label: label.clone(),
                feedback: (!tripped).then(|| p.feedback.roundness(r.radius)),
                against_command: (!tripped).then(|| p.against_command.roundness(r.radius)),
                axes: vec![p.health.clone()],
            });
            reference.get_or_insert(p.command.clone());
            figures.push((format!("{}: (x(t), x(t − T/4))", plot_label(label, tripped)), p.feedback.clone()));
            figures
                .push((format!("{}: (x(t), command(t − T/4))", plot_label(label, tripped)), p.against_command.clone()));
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
            let tripped = c.health.iter().any(|h| h.trip.is_some());
            runs.push(CircleFigures {
                label: label.clone(),
                feedback: (!tripped).then(|| c.feedback.roundness(r.radius)),
                against_command: None,
                axes: c.health.clone(),
            });
            reference.get_or_insert(c.command.clone());
            figures.push((plot_label(label, tripped), c.feedback));
        }
    }
    let several = runs.len() > 1;
    let revolutions = if single { request.lead_in.max(1) } else { request.lead_in } + 1;
    let mut warnings = Vec::new();
    let mut failures = Vec::new();
    for run in &runs {
        let prefix = if several { format!("{}: ", run.label) } else { String::new() };
        for h in &run.axes {
            if let Some(trip) = &h.trip {
                failures.push(format!("{prefix}{}", trip_words(h, trip, (period, n, revolutions))));
            }
        }
        // A run without figures (a trip) has none to warn about: the trip says it all.
        for w in run.axes.iter().filter_map(|h| torque_limited_words(h, request)).filter(|_| run.feedback.is_some()) {
            warnings.push(format!("{prefix}{w}"));
        }
    }
    let reference = reference.expect("one run at least");
    let mut plotted: Vec<(&str, &Figure)> = vec![("command (reference)", &reference)];
    plotted.extend(figures.iter().map(|(l, f)| (l.as_str(), f)));
    let mut notes: Vec<String> = runs
        .iter()
        .map(|r| match &r.feedback {
            Some(f) => f.summary(&r.label),
            None => format!("{}: a drive tripped, no figures (see the report)", r.label),
        })
        .collect();
    notes.extend(warnings.iter().map(|w| format!("WARNING: {w}")));
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
    let measured: Vec<&Roundness> = runs.iter().filter_map(|r| r.feedback.as_ref()).collect();
    let (protrusion_ratio, roundness_ratio) = match measured[..] {
        [first, second] if runs.len() == 2 => (
            first.max_protrusion.zip(second.max_protrusion).filter(|(a, _)| *a > 0.0).map(|(a, b)| b / a),
            (first.roundness > 0.0).then(|| second.roundness / first.roundness),
        ),
        _ => (None, None),
    };
    let improved = (compare.must_be_rounder && runs.len() == 2).then(|| roundness_ratio.is_some_and(|r| r < 1.0));
    if let (Some(false), [first, second]) = (improved, &measured[..]) {
        failures.push(format!(
            "the correction does NOT make the circle rounder: roundness {:.3e} rad with it against {:.3e} rad without ({})",
            second.roundness,
            first.roundness,
            roundness_ratio.map_or("not comparable".into(), ratio_words)
        ));
    }
    let report = CircleReport {
        mode: if single { "single" } else { "two-axis" },
        radius: request.radius,
        feed: request.feed,
        samples_per_revolution: n,
        runs,
        protrusion_ratio,
        roundness_ratio,
        improved,
        warnings,
        passed: failures.is_empty(),
        failures,
        files: files.clone(),
    };
    let json = out.join(if single { "pseudo_circle.json" } else { "circle.json" });
    std::fs::write(&json, serde_json::to_string_pretty(&report)?)?;
    Ok((CircleReport { files: [files, vec![json]].concat(), ..report }, pseudo_runs))
}

/// A run's label in the plot's legend: marked when a drive tripped in it.
fn plot_label(label: &str, tripped: bool) -> String {
    if tripped {
        format!("{label} (TRIPPED: not a measurement)")
    } else {
        label.to_string()
    }
}

/// A ratio of two figures in words: "3.42× smaller", "3.42× larger", "the same".
pub fn ratio_words(ratio: f64) -> String {
    if ratio < 1.0 {
        format!("{:.2}× smaller", 1.0 / ratio)
    } else if ratio > 1.0 {
        format!("{ratio:.2}× larger")
    } else {
        "the same".into()
    }
}

/// What a user reads when an axis tripped: which fault, when (the time and the revolution of
/// `revolutions`, `n` samples of `period` each), and that the run has no figures.
fn trip_words(h: &AxisHealth, trip: &Trip, (period, n, revolutions): (f64, usize, u32)) -> String {
    // Row k of a trace (time k·step) follows command k − 1.
    let row = (trip.time_s / period * n as f64).round() as usize;
    let revolution = (row.saturating_sub(1) / n + 1).min(revolutions as usize);
    let part = if revolution == revolutions as usize { "the measured one" } else { "the lead-in" };
    // The torque is 0 once tripped: every step at the limit came before.
    let limited = &h.torque_limited_run;
    let torque = if limited.limited > 0 {
        format!(
            ", after its torque command had sat at its {} N·m limit ({}) on {} samples",
            h.torque_limit_nm, h.torque_limit_by, limited.limited
        )
    } else {
        String::new()
    };
    format!(
        "{} tripped at t = {:.4} s (revolution {revolution} of {revolutions}, {part}): {}{torque} — its drive switched the output off, so the run has no figures (lower the feed, or see the trace's following_error and torque_command_out)",
        h.name(),
        trip.time_s,
        trip.faults
    )
}

/// What a user reads when an axis's torque command sat at its limit during the run: how much
/// of the measured revolution and of the run, and what it means for the figures.
fn torque_limited_words(h: &AxisHealth, request: &CircleRequest) -> Option<String> {
    let (run, measured) = (&h.torque_limited_run, &h.torque_limited_measured);
    if run.limited == 0 {
        return None;
    }
    let percent = |s: f64| format!("{:.2} %", s * 100.0);
    Some(if measured.limited > 0 {
        format!(
            "{}'s torque command sat at its {} N·m limit ({}) on {} of the measured revolution's {} samples ({}; {} of the run's {}, {}): the drive ran out of torque there, so the figures are not the linear loop's (the circle asks each axis for up to feed²/radius = {:.1} rad/s²: lower the feed or raise the radius, or give the axis more torque)",
            h.name(),
            h.torque_limit_nm,
            h.torque_limit_by,
            measured.limited,
            measured.steps,
            percent(measured.share),
            run.limited,
            run.steps,
            percent(run.share),
            request.feed * request.feed / request.radius
        )
    } else {
        format!(
            "{}'s torque command sat at its {} N·m limit ({}) on {} of the run's {} samples ({}), all before the measured revolution (the start from rest at full feed) and none in it: its figures are the linear loop's once that start has settled (a longer --lead-in shows whether they change)",
            h.name(),
            h.torque_limit_nm,
            h.torque_limit_by,
            run.limited,
            run.steps,
            percent(run.share)
        )
    })
}

impl CircleReport {
    pub fn print(&self) {
        println!(
            "servo circle — {}: radius {} rad, feed {} rad/s, {} samples per revolution",
            self.mode, self.radius, self.feed, self.samples_per_revolution
        );
        for r in &self.runs {
            println!("  {}:", r.label);
            match &r.feedback {
                Some(f) => print_roundness("feedback", f),
                None => println!("    no figures: a drive tripped during the run (below)"),
            }
            if let Some(a) = &r.against_command {
                print_roundness("feedback vs shifted command", a);
            }
        }
        if let Some(ratio) = self.protrusion_ratio {
            println!("  largest quadrant protrusion, second run / first: {ratio:.3} ({})", ratio_words(ratio));
        }
        if let Some(ratio) = self.roundness_ratio {
            println!("  roundness, second run / first: {ratio:.4} ({})", ratio_words(ratio));
        }
        for w in &self.warnings {
            println!("  WARNING: {w}");
        }
        for f in &self.failures {
            println!("  FAILED: {f}");
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
        f.protrusions_text()
    );
    if let Some(why) = &f.not_measurable {
        println!("    {:<34} protrusions not measurable: {why}", "");
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ratio_reads_as_how_many_times_smaller_or_larger() {
        assert_eq!(ratio_words(1.0 / 3.4186), "3.42× smaller");
        assert_eq!(ratio_words(3.4186), "3.42× larger");
        assert_eq!(ratio_words(1.0), "the same");
    }
}
