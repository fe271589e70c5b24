//! Bode plot (gain and phase against a logarithmic frequency axis) as standalone SVG, several
//! curves overlaid, with an optional vertical marker (for example the acquisition Nyquist
//! frequency).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use crate::analysis::response_point::ResponsePoint;
use crate::plot::signals::{escape, fitted_text, svg_opening, tick_step};

const WIDTH: f64 = 900.0;
const PANEL_H: f64 = 220.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 60.0;
const GAP: f64 = 40.0;
const LEGEND_ROW: f64 = 15.0;
/// A legend entry: its line sample and the gap before its label, the gap after the label, and a
/// character's width at the plot's 11 px font (estimated at 0.6 em, a little wide for safety).
const LEGEND_SAMPLE: f64 = 24.0;
const LEGEND_GAP: f64 = 22.0;
const LEGEND_CHAR: f64 = 7.0;
const COLOURS: [&str; 6] = ["#444444", "#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e"];

/// `curves`: (label, points); non-finite values are skipped.
pub fn plot_bode(
    path: &Path,
    title: &str,
    curves: &[(&str, &[ResponsePoint])],
    marker: Option<(f64, &str)>,
) -> Result<()> {
    // The legend above the panels, its entries flowed into rows by their labels' widths.
    let legend = legend_positions(curves.iter().map(|(label, _)| *label));
    let rows = legend.iter().map(|&(_, row)| row + 1).max().unwrap_or(0);
    let top = TOP.max(30.0 + rows as f64 * LEGEND_ROW + 16.0);
    let all = || curves.iter().flat_map(|(_, c)| c.iter()).filter(|p| p.gain_db.is_finite() && p.phase_deg.is_finite());
    let fmin = all().map(|p| p.frequency).fold(f64::INFINITY, f64::min);
    let fmax = all().map(|p| p.frequency).fold(f64::NEG_INFINITY, f64::max);
    let (l0, l1) = (fmin.max(1e-6).log10().floor(), fmax.max(1e-6).log10().ceil().max(fmin.log10().floor() + 1.0));
    let plot_w = WIDTH - LEFT - RIGHT;
    let x = |f: f64| LEFT + (f.log10() - l0) / (l1 - l0) * plot_w;
    let height = top + 2.0 * (PANEL_H + GAP) + 10.0;
    let mut svg = String::new();
    svg.push_str(&svg_opening(WIDTH, height, title, 18.0, 14.0));
    for (i, ((label, _), &(lx, row))) in curves.iter().zip(&legend).enumerate() {
        let ly = 34.0 + row as f64 * LEGEND_ROW;
        // A label wider than the plot (on a row of its own) is squeezed to fit.
        writeln!(
            svg,
            r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{}" stroke-width="2"/>{}"#,
            lx + 20.0,
            COLOURS[i % 6],
            fitted_text(lx + LEGEND_SAMPLE, ly + 4.0, 11.0, "start", WIDTH - RIGHT - lx - LEGEND_SAMPLE, label)
        )?;
    }
    for (panel, name) in [(0, "gain (dB)"), (1, "phase (deg)")] {
        let y0 = top + panel as f64 * (PANEL_H + GAP);
        let values: Vec<f64> = all().map(|p| if panel == 0 { p.gain_db } else { p.phase_deg }).collect();
        let (mut vmin, mut vmax) =
            values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| (a.min(*v), b.max(*v)));
        if !(vmin.is_finite() && vmax.is_finite()) {
            continue;
        }
        if vmax - vmin < 1e-9 {
            vmin -= 1.0;
            vmax += 1.0;
        }
        let step = tick_step(vmax - vmin);
        let (vmin, vmax) = ((vmin / step).floor() * step, (vmax / step).ceil() * step);
        let y = |v: f64| y0 + PANEL_H - (v - vmin) / (vmax - vmin) * PANEL_H;
        writeln!(
            svg,
            r##"<rect x="{LEFT}" y="{y0}" width="{plot_w}" height="{PANEL_H}" fill="none" stroke="#888"/>"##
        )?;
        let mut v = vmin;
        while v <= vmax + 1e-9 {
            writeln!(
                svg,
                r##"<line x1="{LEFT}" y1="{:.1}" x2="{}" y2="{:.1}" stroke="#eee"/><text x="{}" y="{:.1}" text-anchor="end">{}</text>"##,
                y(v),
                LEFT + plot_w,
                y(v),
                LEFT - 4.0,
                y(v) + 4.0,
                v
            )?;
            v += step;
        }
        let mut decade = l0;
        while decade <= l1 {
            for m in 1..10 {
                let f = 10f64.powf(decade) * m as f64;
                if f.log10() > l1 + 1e-9 {
                    break;
                }
                let stroke = if m == 1 { "#ccc" } else { "#f2f2f2" };
                writeln!(
                    svg,
                    r#"<line x1="{:.1}" y1="{y0}" x2="{:.1}" y2="{}" stroke="{stroke}"/>"#,
                    x(f),
                    x(f),
                    y0 + PANEL_H
                )?;
                if m == 1 {
                    writeln!(
                        svg,
                        r#"<text x="{:.1}" y="{}" text-anchor="middle">{}</text>"#,
                        x(f),
                        y0 + PANEL_H + 13.0,
                        f
                    )?;
                }
            }
            decade += 1.0;
        }
        if let Some((m, label)) = marker {
            writeln!(
                svg,
                r##"<line x1="{:.1}" y1="{y0}" x2="{:.1}" y2="{}" stroke="#999" stroke-dasharray="4,3"/><text x="{:.1}" y="{}" fill="#666">{}</text>"##,
                x(m),
                x(m),
                y0 + PANEL_H,
                x(m) + 3.0,
                y0 + 12.0,
                escape(label)
            )?;
        }
        writeln!(svg, r#"<text x="{}" y="{}" font-weight="bold">{name}</text>"#, LEFT + 5.0, y0 - 4.0)?;
        for (i, (_, c)) in curves.iter().enumerate() {
            let pts: Vec<String> = c
                .iter()
                .filter(|p| p.gain_db.is_finite() && p.phase_deg.is_finite())
                .map(|p| {
                    format!(
                        "{:.1},{:.1}",
                        x(p.frequency),
                        y(if panel == 0 { p.gain_db } else { p.phase_deg }).clamp(y0 - 5.0, y0 + PANEL_H + 5.0)
                    )
                })
                .collect();
            let colour = COLOURS[i % 6];
            writeln!(
                svg,
                r#"<polyline fill="none" stroke="{colour}" stroke-width="1.3" points="{}"/>"#,
                pts.join(" ")
            )?;
            for p in &pts {
                let (px, py) = p.split_once(',').unwrap_or(("0", "0"));
                writeln!(svg, r#"<circle cx="{px}" cy="{py}" r="1.8" fill="{colour}"/>"#)?;
            }
        }
    }
    writeln!(
        svg,
        r#"<text x="{}" y="{}" text-anchor="middle">frequency (Hz)</text>"#,
        LEFT + plot_w / 2.0,
        height - 4.0
    )?;
    svg.push_str("</svg>\n");
    std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))
}

/// Where each legend entry goes: (left edge, row). Entries are laid left to right and wrap to
/// a new row when the next one would run past the right edge, so no label overlaps the next
/// (a label wider than the plot gets a row of its own).
fn legend_positions<'a>(labels: impl Iterator<Item = &'a str>) -> Vec<(f64, usize)> {
    let (mut x, mut row) = (LEFT, 0);
    let mut out = Vec::new();
    for label in labels {
        let width = LEGEND_SAMPLE + label.chars().count() as f64 * LEGEND_CHAR;
        if x > LEFT && x + width > WIDTH - RIGHT {
            x = LEFT;
            row += 1;
        }
        out.push((x, row));
        x += width + LEGEND_GAP;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sweep's legend (long labels) wraps instead of overlapping: every entry ends before
    /// the next one on its row starts.
    #[test]
    fn legend_labels_do_not_overlap() {
        let labels = [
            "oracle (8 kHz acquisition, 10x longer, 2^24-count encoder, no noise)",
            "analytic linear model",
            "equivalent time (acquisition stream)",
            "on-line correlator (drive)",
            "x before",
            "x after",
        ];
        let at = legend_positions(labels.iter().copied());
        for (i, (&(x, row), label)) in at.iter().zip(labels).enumerate() {
            let end = x + LEGEND_SAMPLE + label.chars().count() as f64 * LEGEND_CHAR;
            assert!(end <= WIDTH - RIGHT || x == LEFT, "{label} runs past the edge");
            if let Some(&(next, next_row)) = at.get(i + 1) {
                assert!(next_row > row || next >= end + LEGEND_GAP, "{label} overlaps the next entry");
            }
        }
        assert!(at.iter().any(|&(_, row)| row > 0), "long labels wrap");
    }
}
