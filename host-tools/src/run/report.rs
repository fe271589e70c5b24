//! A small HTML report of a demo run: every scenario with its description, checks, the
//! fmpy cross-check verdict and its plot.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;

use crate::fmu::runner::CheckResult;

pub struct ScenarioReport {
    pub name: String,
    pub description: String,
    pub checks: Vec<CheckResult>,
    /// `Ok(columns compared)` or the first difference.
    pub fmpy: Option<std::result::Result<String, String>>,
    pub plot_file: String,
    pub csv_file: String,
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;")
}

pub fn write_html(path: &Path, title: &str, preamble: &str, scenarios: &[ScenarioReport]) -> Result<()> {
    let mut h = String::new();
    writeln!(h, "<!doctype html><html><head><meta charset=\"utf-8\"><title>{}</title>", esc(title))?;
    h.push_str(
        "<style>body{font-family:sans-serif;max-width:960px;margin:2em auto}table{border-collapse:collapse}\
         td,th{border:1px solid #ccc;padding:3px 8px}.pass{color:#080}.fail{color:#c00;font-weight:bold}</style></head><body>",
    );
    writeln!(h, "<h1>{}</h1>{preamble}", esc(title))?;
    for s in scenarios {
        writeln!(h, "<h2>{}</h2><p>{}</p>", esc(&s.name), esc(&s.description))?;
        if !s.checks.is_empty() {
            h.push_str("<table><tr><th>check</th><th>signal</th><th>window (s)</th><th>bounds</th><th>observed</th><th>result</th></tr>");
            for c in &s.checks {
                let observed = match &c.not_evaluated {
                    Some(why) => format!("not evaluated: {}", esc(why)),
                    None => format!("{:.6} … {:.6}", c.observed.0, c.observed.1),
                };
                let bounds = format!(
                    "{} … {}",
                    c.min.map(|x| x.to_string()).unwrap_or("-∞".into()),
                    c.max.map(|x| x.to_string()).unwrap_or("+∞".into())
                );
                writeln!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{} – {}</td><td>{}</td><td>{}</td><td class=\"{}\">{}</td></tr>",
                    esc(&c.description),
                    esc(&c.signal),
                    c.window.0,
                    c.window.1,
                    bounds,
                    observed,
                    if c.passed { "pass" } else { "fail" },
                    if c.passed { "pass" } else { "FAIL" }
                )?;
            }
            h.push_str("</table>");
        }
        match &s.fmpy {
            Some(Ok(msg)) => writeln!(h, "<p class=\"pass\">fmpy cross-check: {}</p>", esc(msg))?,
            Some(Err(msg)) => writeln!(h, "<p class=\"fail\">fmpy cross-check: {}</p>", esc(msg))?,
            None => {}
        }
        writeln!(h, "<p><img src=\"{}\" width=\"900\"></p><p><a href=\"{}\">CSV</a></p>", s.plot_file, s.csv_file)?;
    }
    h.push_str("</body></html>\n");
    std::fs::write(path, h)?;
    Ok(())
}

/// A check's line in a report.
pub fn print_check(c: &crate::fmu::runner::CheckResult) {
    if let Some(why) = &c.not_evaluated {
        println!("  [FAIL] {:<45} {:<18} not evaluated: {why}", c.description, c.signal);
        return;
    }
    println!(
        "  [{}] {:<45} {:<18} observed {:>11.6} … {:<11.6} bounds {} … {}",
        if c.passed { "pass" } else { "FAIL" },
        c.description,
        c.signal,
        c.observed.0,
        c.observed.1,
        c.min.map_or("-inf".into(), |x| x.to_string()),
        c.max.map_or("+inf".into(), |x| x.to_string()),
    );
}
