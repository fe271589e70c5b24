//! Nyquist diagram of an open loop as standalone SVG: `L` in the complex plane near the
//! critical point −1, with the unit circle, the circle of a sensitivity peak `Ms` (centre
//! −1, radius 1/Ms: a loop that stays outside it has `|1/(1 + L)| ≤ Ms`) and a marked point
//! (for example the gain crossover with its phase margin). The view is the square around −1
//! where the margins are read; the curve leaves it at low frequency (where `|L|` is large)
//! and is cut there.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};
use num_complex::Complex64;

use crate::plot::signals::{escape, svg_opening};

const SIZE: f64 = 560.0;
const MARGIN: f64 = 50.0;
/// The view: real and imaginary parts from −VIEW − 1 … VIEW − 1 (centred on −1).
const VIEW: f64 = 2.0;
const COLOURS: [&str; 3] = ["#d62728", "#1f77b4", "#2ca02c"];

/// `curves`: (label, L at increasing frequencies); `ms`: the circle to draw; `mark`: a point
/// and its label.
pub fn plot_nyquist(
    path: &Path,
    title: &str,
    curves: &[(&str, &[Complex64])],
    ms: Option<f64>,
    mark: Option<(Complex64, &str)>,
) -> Result<()> {
    let plot = SIZE - 2.0 * MARGIN;
    let x = |re: f64| MARGIN + (re + 1.0 + VIEW) / (2.0 * VIEW) * plot;
    let y = |im: f64| MARGIN + (VIEW - im) / (2.0 * VIEW) * plot;
    let scale = plot / (2.0 * VIEW);
    let inside =
        |l: &Complex64| (l.re + 1.0).abs() <= VIEW && l.im.abs() <= VIEW && l.re.is_finite() && l.im.is_finite();
    let mut svg = svg_opening(SIZE, SIZE + 20.0 * curves.len() as f64, title, 22.0, 14.0);
    writeln!(svg, r##"<rect x="{MARGIN}" y="{MARGIN}" width="{plot}" height="{plot}" fill="none" stroke="#888"/>"##)?;
    // Axes through 0, a grid every 0.5.
    let mut v = -1.0 - VIEW;
    while v <= VIEW - 1.0 + 1e-9 {
        let colour = if v.abs() < 1e-9 { "#888" } else { "#eee" };
        writeln!(svg, r#"<line x1="{0}" y1="{MARGIN}" x2="{0}" y2="{1}" stroke="{colour}"/>"#, x(v), MARGIN + plot)?;
        writeln!(svg, r#"<text x="{}" y="{}" text-anchor="middle">{v:.1}</text>"#, x(v), MARGIN + plot + 14.0)?;
        v += 0.5;
    }
    let mut v = -VIEW;
    while v <= VIEW + 1e-9 {
        let colour = if v.abs() < 1e-9 { "#888" } else { "#eee" };
        writeln!(svg, r#"<line x1="{MARGIN}" y1="{0}" x2="{1}" y2="{0}" stroke="{colour}"/>"#, y(v), MARGIN + plot)?;
        writeln!(svg, r#"<text x="{}" y="{}" text-anchor="end">{v:.1}</text>"#, MARGIN - 4.0, y(v) + 4.0)?;
        v += 0.5;
    }
    writeln!(
        svg,
        r##"<circle cx="{}" cy="{}" r="{scale}" fill="none" stroke="#999" stroke-dasharray="4 3"/>"##,
        x(0.0),
        y(0.0)
    )?;
    if let Some(ms) = ms.filter(|m| m.is_finite() && *m > 0.0) {
        writeln!(
            svg,
            r##"<circle cx="{}" cy="{}" r="{}" fill="#fbe3e3" stroke="#d62728" stroke-dasharray="2 2"/>"##,
            x(-1.0),
            y(0.0),
            scale / ms
        )?;
        writeln!(
            svg,
            r##"<text x="{}" y="{}" fill="#d62728">Ms {ms:.2}</text>"##,
            x(-1.0) + scale / ms * 0.75,
            y(0.0) - scale / ms * 0.75
        )?;
    }
    writeln!(svg, r#"<circle cx="{}" cy="{}" r="3" fill="black"/>"#, x(-1.0), y(0.0))?;
    writeln!(svg, r#"<text x="{}" y="{}">−1</text>"#, x(-1.0) + 5.0, y(0.0) + 14.0)?;
    for (i, (label, points)) in curves.iter().enumerate() {
        let colour = COLOURS[i % COLOURS.len()];
        // The curve in pieces: a point outside the view ends a piece.
        let mut piece = String::new();
        let flush = |piece: &mut String, svg: &mut String| -> std::fmt::Result {
            if piece.split(' ').filter(|s| !s.is_empty()).count() > 1 {
                writeln!(svg, r#"<polyline points="{piece}" fill="none" stroke="{colour}" stroke-width="1.5"/>"#)?;
            }
            piece.clear();
            Ok(())
        };
        for l in points.iter() {
            if inside(l) {
                write!(piece, "{:.1},{:.1} ", x(l.re), y(l.im))?;
            } else {
                flush(&mut piece, &mut svg)?;
            }
        }
        flush(&mut piece, &mut svg)?;
        let ly = SIZE + 4.0 + 20.0 * i as f64;
        writeln!(
            svg,
            r#"<line x1="{MARGIN}" y1="{ly}" x2="{}" y2="{ly}" stroke="{colour}" stroke-width="2"/><text x="{}" y="{}">{}</text>"#,
            MARGIN + 20.0,
            MARGIN + 26.0,
            ly + 4.0,
            escape(label)
        )?;
    }
    if let Some((p, label)) = mark.filter(|(p, _)| inside(p)) {
        writeln!(svg, r#"<circle cx="{}" cy="{}" r="4" fill="none" stroke="black"/>"#, x(p.re), y(p.im))?;
        writeln!(
            svg,
            r#"<line x1="{}" y1="{}" x2="{}" y2="{}" stroke="black" stroke-dasharray="3 2"/>"#,
            x(0.0),
            y(0.0),
            x(p.re),
            y(p.im)
        )?;
        writeln!(svg, r#"<text x="{}" y="{}">{}</text>"#, x(p.re) + 6.0, y(p.im) - 6.0, escape(label))?;
    }
    svg.push_str("</svg>\n");
    std::fs::write(path, svg).with_context(|| format!("writing {}", path.display()))
}
