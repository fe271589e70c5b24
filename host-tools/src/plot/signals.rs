//! Time-series plots as standalone SVG: one panel per signal on a shared time axis, several
//! traces overlaid (for example the Rust host and fmpy, or before and after a change).

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context, Result};

use crate::fmu::trace::Trace;

const WIDTH: f64 = 900.0;
const PANEL_H: f64 = 150.0;
const LEFT: f64 = 80.0;
const RIGHT: f64 = 20.0;
const TOP: f64 = 40.0;
const GAP: f64 = 30.0;
const COLOURS: [&str; 4] = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd"];

/// A raw step rounded to 1, 2, 5 or 10 times a power of ten.
pub(crate) fn nice_step(raw: f64) -> f64 {
    let mag = 10f64.powf(raw.log10().floor());
    let norm = raw / mag;
    let nice = if norm < 1.5 {
        1.0
    } else if norm < 3.5 {
        2.0
    } else if norm < 7.5 {
        5.0
    } else {
        10.0
    };
    nice * mag
}

/// "Nice" tick spacing for a span: about five ticks.
pub(crate) fn tick_step(span: f64) -> f64 {
    nice_step(span / 5.0)
}

fn label(x: f64) -> String {
    if x == 0.0 {
        "0".into()
    } else if x.abs() >= 1e4 || x.abs() < 1e-3 {
        format!("{x:.1e}")
    } else {
        let s = format!("{x:.4}");
        s.trim_end_matches('0').trim_end_matches('.').to_string()
    }
}

/// The opening of a plot: the `<svg>` element of `width` × `height`, a white background and
/// the title centred at `title_y` in `title_size`, shrunk to fit the width.
pub(crate) fn svg_opening(width: f64, height: f64, title: &str, title_y: f64, title_size: f64) -> String {
    format!(
        "<svg xmlns=\"http://www.w3.org/2000/svg\" width=\"{width}\" height=\"{height}\" viewBox=\"0 0 {width} {height}\" font-family=\"sans-serif\" font-size=\"11\">\n<rect width=\"100%\" height=\"100%\" fill=\"white\"/>\n{}\n",
        fitted_text(width / 2.0, title_y, title_size, "middle", width - 20.0, title)
    )
}

/// A line of text that fits `max_width` pixels: wider text (estimated at 0.6 em a character)
/// is squeezed to that width (SVG `textLength`) instead of running off the canvas.
pub(crate) fn fitted_text(x: f64, y: f64, font_size: f64, anchor: &str, max_width: f64, text: &str) -> String {
    let estimated = 0.6 * font_size * text.chars().count() as f64;
    let fit = if estimated > max_width {
        format!(r#" textLength="{max_width:.0}" lengthAdjust="spacingAndGlyphs""#)
    } else {
        String::new()
    };
    format!(r#"<text x="{x}" y="{y}" font-size="{font_size}" text-anchor="{anchor}"{fit}>{}</text>"#, escape(text))
}

/// Text made safe for SVG.
pub(crate) fn escape(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

/// Plot `signals` of every `(label, trace)` into `path`, against time.
pub fn plot_signals(path: &Path, title: &str, traces: &[(&str, &Trace)], signals: &[String]) -> Result<()> {
    plot_against(path, title, traces, "time", "time (s)", signals)
}

/// Plot `signals` of every `(label, trace)` into `path`, against the column `x` (for
/// example a swept parameter). A trace without a signal's column is left out of its panel.
pub fn plot_against(
    path: &Path,
    title: &str,
    traces: &[(&str, &Trace)],
    x: &str,
    x_label: &str,
    signals: &[String],
) -> Result<()> {
    let height = TOP + signals.len() as f64 * (PANEL_H + GAP) + 30.0;
    let mut svg = String::new();
    svg.push_str(&svg_opening(WIDTH, height, title, 20.0, 15.0));
    for (li, (name, _)) in traces.iter().enumerate().filter(|_| traces.len() > 1) {
        let x = LEFT + 10.0 + li as f64 * 160.0;
        writeln!(
            svg,
            r#"<line x1="{x}" y1="30" x2="{}" y2="30" stroke="{}" stroke-width="2"/>"#,
            x + 20.0,
            COLOURS[li % 4]
        )?;
        writeln!(svg, r#"<text x="{}" y="34">{}</text>"#, x + 25.0, escape(name))?;
    }
    let plot_w = WIDTH - LEFT - RIGHT;
    for (si, signal) in signals.iter().enumerate() {
        let y0 = TOP + si as f64 * (PANEL_H + GAP);
        let series: Vec<(Vec<f64>, Vec<f64>)> =
            traces.iter().filter_map(|(_, t)| Some((t.column(x)?, t.column(signal)?))).collect();
        let (mut tmin, mut tmax, mut vmin, mut vmax) =
            (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY, f64::NEG_INFINITY);
        for (t, v) in &series {
            for (&a, &b) in t.iter().zip(v) {
                if a.is_finite() && b.is_finite() {
                    tmin = tmin.min(a);
                    tmax = tmax.max(a);
                    vmin = vmin.min(b);
                    vmax = vmax.max(b);
                }
            }
        }
        if !tmin.is_finite() {
            continue;
        }
        if vmax - vmin < 1e-12 * vmax.abs().max(1.0) {
            vmin -= 0.5 * vmin.abs().max(1e-9);
            vmax += 0.5 * vmax.abs().max(1e-9);
        }
        let pad = 0.05 * (vmax - vmin);
        let (vmin, vmax) = (vmin - pad, vmax + pad);
        let tx = |t: f64| LEFT + (t - tmin) / (tmax - tmin).max(1e-300) * plot_w;
        let vy = |v: f64| y0 + PANEL_H - (v - vmin) / (vmax - vmin) * PANEL_H;
        writeln!(
            svg,
            r##"<rect x="{LEFT}" y="{y0}" width="{plot_w}" height="{PANEL_H}" fill="none" stroke="#888"/>"##
        )?;
        let ts = tick_step(tmax - tmin);
        let mut t = (tmin / ts).ceil() * ts;
        while t <= tmax + 1e-12 {
            let x = tx(t);
            writeln!(svg, r##"<line x1="{x:.1}" y1="{y0}" x2="{x:.1}" y2="{}" stroke="#eee"/>"##, y0 + PANEL_H)?;
            writeln!(svg, r#"<text x="{x:.1}" y="{}" text-anchor="middle">{}</text>"#, y0 + PANEL_H + 13.0, label(t))?;
            t += ts;
        }
        let vs = tick_step(vmax - vmin);
        let mut v = (vmin / vs).ceil() * vs;
        while v <= vmax {
            let y = vy(v);
            writeln!(svg, r##"<line x1="{LEFT}" y1="{y:.1}" x2="{}" y2="{y:.1}" stroke="#eee"/>"##, LEFT + plot_w)?;
            writeln!(svg, r#"<text x="{}" y="{:.1}" text-anchor="end">{}</text>"#, LEFT - 5.0, y + 4.0, label(v))?;
            v += vs;
        }
        writeln!(svg, r#"<text x="{}" y="{}" font-weight="bold">{}</text>"#, LEFT + 5.0, y0 + 13.0, escape(signal))?;
        for (ci, (t, v)) in series.iter().enumerate() {
            let mut pts = String::new();
            // Decimate to about two points per pixel column (min/max kept).
            let stride = (t.len() as f64 / (2.0 * plot_w)).ceil().max(1.0) as usize;
            for chunk in t.chunks(stride).zip(v.chunks(stride)) {
                let (ct, cv) = chunk;
                let (imin, imax) = cv
                    .iter()
                    .enumerate()
                    .fold((0, 0), |(a, b), (i, x)| (if *x < cv[a] { i } else { a }, if *x > cv[b] { i } else { b }));
                for i in if imin <= imax { [imin, imax] } else { [imax, imin] } {
                    if cv[i].is_finite() {
                        write!(pts, "{:.1},{:.1} ", tx(ct[i]), vy(cv[i]))?;
                    }
                }
            }
            let dash = if ci > 0 { r#" stroke-dasharray="6,4""# } else { "" };
            writeln!(
                svg,
                r#"<polyline fill="none" stroke="{}" stroke-width="1.3"{dash} points="{pts}"/>"#,
                COLOURS[ci % 4]
            )?;
        }
    }
    writeln!(
        svg,
        r#"<text x="{}" y="{}" text-anchor="middle">{}</text>"#,
        LEFT + plot_w / 2.0,
        height - 8.0,
        escape(x_label)
    )?;
    svg.push_str("</svg>\n");
    std::fs::write(path, svg).with_context(|| format!("cannot write {}", path.display()))
}

#[cfg(test)]
mod fitted_text_tests {
    use super::fitted_text;

    #[test]
    fn long_text_is_squeezed_to_the_canvas_and_short_text_is_left_alone() {
        let short = fitted_text(450.0, 20.0, 15.0, "middle", 880.0, "position_step");
        assert!(!short.contains("textLength"), "{short}");
        let long = fitted_text(450.0, 20.0, 15.0, "middle", 880.0, &"a very long title ".repeat(10));
        assert!(long.contains(r#"textLength="880""#), "{long}");
        assert!(fitted_text(0.0, 0.0, 11.0, "start", 100.0, "a < b").contains("a &lt; b"));
    }
}
