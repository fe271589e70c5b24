//! Bode plot (gain and phase against a logarithmic frequency axis) as standalone SVG, several
//! curves overlaid, with an optional vertical marker (for example the acquisition Nyquist
//! frequency).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use crate::analysis::response_point::ResponsePoint;
use crate::plot::signals::{escape, svg_opening, tick_step};

const WIDTH: f64 = 900.0;
const PANEL_H: f64 = 220.0;
const LEFT: f64 = 70.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 60.0;
const GAP: f64 = 40.0;
const COLOURS: [&str; 6] = ["#444444", "#d62728", "#1f77b4", "#2ca02c", "#9467bd", "#ff7f0e"];

/// `curves`: (label, points); non-finite values are skipped.
pub fn plot_bode(
    path: &Path,
    title: &str,
    curves: &[(&str, &[ResponsePoint])],
    marker: Option<(f64, &str)>,
) -> Result<()> {
    // Room for the legend's rows above the panels.
    let top = TOP.max(30.0 + curves.len().div_ceil(3) as f64 * 14.0 + 16.0);
    let all = || curves.iter().flat_map(|(_, c)| c.iter()).filter(|p| p.gain_db.is_finite() && p.phase_deg.is_finite());
    let fmin = all().map(|p| p.frequency).fold(f64::INFINITY, f64::min);
    let fmax = all().map(|p| p.frequency).fold(f64::NEG_INFINITY, f64::max);
    let (l0, l1) = (fmin.max(1e-6).log10().floor(), fmax.max(1e-6).log10().ceil().max(fmin.log10().floor() + 1.0));
    let plot_w = WIDTH - LEFT - RIGHT;
    let x = |f: f64| LEFT + (f.log10() - l0) / (l1 - l0) * plot_w;
    let height = top + 2.0 * (PANEL_H + GAP) + 10.0;
    let mut svg = String::new();
    svg.push_str(&svg_opening(WIDTH, height, title, 18.0, 14.0));
    for (i, (label, _)) in curves.iter().enumerate() {
        let lx = LEFT + (i % 3) as f64 * 270.0;
        let ly = 34.0 + (i / 3) as f64 * 14.0;
        writeln!(
            svg,
            r#"<line x1="{lx}" y1="{ly}" x2="{}" y2="{ly}" stroke="{}" stroke-width="2"/><text x="{}" y="{}">{}</text>"#,
            lx + 20.0,
            COLOURS[i % 6],
            lx + 24.0,
            ly + 4.0,
            escape(label)
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
