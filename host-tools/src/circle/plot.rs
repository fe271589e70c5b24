//! The circle-test plot: figures about their centre with the radial error magnified, over
//! the nominal circle, as circle-test instruments draw it (scale, radius, feed, roundness).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use crate::fmu::circle::Figure;
use crate::plot::signals::{escape, fitted_text, nice_step, svg_opening};

const SIZE: f64 = 640.0;
const COLOURS: [&str; 4] = ["#888888", "#d62728", "#1f77b4", "#2ca02c"];

/// A "nice" radial-error scale: rad per ring such that `max_error` spans about two rings.
pub fn ring_step(max_error: f64) -> f64 {
    nice_step((max_error / 2.0).max(1e-12))
}

/// Plot `figures` (label, figure; the first is drawn grey as the reference) about the nominal
/// radius; radial errors are drawn `rings × ring` wide in a band of 30 % of the radius.
/// `about_own_mean`: each figure's radial error is drawn about its own mean radius (its shape,
/// for comparing roundness when the runs' radii differ), not about the nominal radius.
pub fn plot_circle(
    path: &Path,
    title: &str,
    notes: &[String],
    radius: f64,
    figures: &[(&str, &Figure)],
    about_own_mean: bool,
) -> Result<()> {
    // Each figure in polar form, once, with the radius its error is measured from.
    let polars: Vec<(Vec<(f64, f64)>, f64)> = figures
        .iter()
        .map(|(_, f)| {
            let p = f.polar();
            let r0 =
                if about_own_mean { p.iter().map(|(_, r)| r).sum::<f64>() / p.len().max(1) as f64 } else { radius };
            (p, r0)
        })
        .collect();
    let max_error = polars.iter().flat_map(|(p, r0)| p.iter().map(move |(_, r)| (r - r0).abs())).fold(0.0, f64::max);
    let ring = ring_step(max_error);
    let rings = 3.0;
    // Plot radius of the nominal circle, and pixels per rad of radial error.
    let nominal = SIZE * 0.28;
    let per_error = nominal * 0.3 / (rings * ring);
    let (cx, cy) = (SIZE / 2.0, SIZE / 2.0 + 20.0);
    let mut svg = String::new();
    let height = SIZE + 40.0 + 16.0 * notes.len() as f64;
    svg.push_str(&svg_opening(SIZE, height, title, 18.0, 14.0));
    for i in -3..=3 {
        let r = nominal + i as f64 * ring * per_error;
        let stroke = if i == 0 { "#444" } else { "#ddd" };
        writeln!(svg, r#"<circle cx="{cx}" cy="{cy}" r="{r:.2}" fill="none" stroke="{stroke}"/>"#)?;
    }
    for a in [0.0f64, 90.0, 180.0, 270.0] {
        let (s, c) = a.to_radians().sin_cos();
        let (r0, r1) = (nominal - 3.5 * ring * per_error, nominal + 3.5 * ring * per_error);
        writeln!(
            svg,
            r##"<line x1="{:.1}" y1="{:.1}" x2="{:.1}" y2="{:.1}" stroke="#bbb" stroke-dasharray="3,3"/>"##,
            cx + r0 * c,
            cy - r0 * s,
            cx + r1 * c,
            cy - r1 * s
        )?;
        writeln!(
            svg,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">{a}°</text>"#,
            cx + (r1 + 14.0) * c,
            cy - (r1 + 14.0) * s + 4.0
        )?;
    }
    for (i, ((label, _), (polar, r0))) in figures.iter().zip(&polars).enumerate() {
        let mut pts = String::new();
        let stride = (polar.len() / 2000).max(1);
        for (angle, r) in polar.iter().step_by(stride).chain(polar.first()) {
            let rp = nominal + (r - r0) * per_error;
            let (s, c) = angle.to_radians().sin_cos();
            write!(pts, "{:.2},{:.2} ", cx + rp * c, cy - rp * s)?;
        }
        let colour = COLOURS[i % COLOURS.len()];
        let width = if i == 0 { 1.0 } else { 1.4 };
        writeln!(svg, r#"<polyline fill="none" stroke="{colour}" stroke-width="{width}" points="{pts}"/>"#)?;
        let y = 40.0 + 14.0 * i as f64;
        writeln!(
            svg,
            r#"<line x1="12" y1="{y}" x2="32" y2="{y}" stroke="{colour}" stroke-width="2"/><text x="36" y="{}">{}</text>"#,
            y + 4.0,
            escape(label)
        )?;
    }
    let mut y = SIZE + 20.0;
    let about = if about_own_mean { "about each figure's own mean radius" } else { "about the nominal radius" };
    for n in [format!(
        "rings every {} rad of radial error {about} (magnified {:.3e}×); nominal radius {radius} rad",
        fmt(ring),
        per_error * radius / nominal
    )]
    .iter()
    .chain(notes)
    {
        writeln!(svg, "{}", fitted_text(12.0, y, 11.0, "start", SIZE - 24.0, n))?;
        y += 16.0;
    }
    svg.push_str("</svg>\n");
    std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))
}

fn fmt(x: f64) -> String {
    format!("{x:.0e}")
}
