//! The report a user opens first (`out/index.html`): what failed or missed its goal first, then
//! the benches' figures against their goals (out/bench/*.json), then one section per
//! experiment, each built by the experiment's own `index.rs` from the files it wrote — its key
//! numbers, its checks and their verdicts, the fmpy cross-check, its plots and the files behind
//! them.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use anyhow::Result;

use crate::bench::figures::BenchFigures;

/// One experiment's part of the page.
#[derive(Default)]
pub struct Section {
    pub title: String,
    /// The command that wrote it.
    pub command: String,
    /// The experiment's key numbers (what, value with its unit), where its files hold them.
    pub numbers: Vec<(String, String)>,
    /// Check or cross-check → passed.
    pub verdicts: Vec<(String, bool)>,
    /// Plots (paths relative to the out folder).
    pub plots: Vec<PathBuf>,
    /// Other files worth opening (relative to the out folder).
    pub files: Vec<PathBuf>,
    /// Result files that are there but cannot be read (path relative to the out folder, why):
    /// named on the page and in a warning, and they make the exit status 1.
    pub unreadable: Vec<(PathBuf, String)>,
}

impl Section {
    /// The result file at `path`: None when it is absent; when it is there but is not JSON
    /// (corrupt, truncated), None and the file recorded as unreadable.
    pub fn read_result(&mut self, root: &Path, path: &Path) -> Option<serde_json::Value> {
        match read_result(path) {
            Ok(json) => json,
            Err(why) => {
                self.unreadable.push((relative(root, path), why));
                None
            }
        }
    }
}

/// The files of `dir` with extension `ext`, sorted (none when the folder is missing).
pub fn files_with(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .map(|d| {
            d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.extension().is_some_and(|x| x == ext)).collect()
        })
        .unwrap_or_default();
    v.sort();
    v
}

/// The files under `dir` (its subfolders too) with extension `ext`, sorted (none when the
/// folder is missing).
pub fn files_under(dir: &Path, ext: &str) -> Vec<PathBuf> {
    let mut v = files_with(dir, ext);
    if let Ok(entries) = std::fs::read_dir(dir) {
        for sub in entries.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_dir()) {
            v.extend(files_under(&sub, ext));
        }
    }
    v.sort();
    v
}

/// A JSON file, if it is there and readable.
pub fn read_json(path: &Path) -> Option<serde_json::Value> {
    read_result(path).ok().flatten()
}

/// A result file: Ok(None) when it is absent, Err(why) when it is there but cannot be read as
/// JSON.
pub fn read_result(path: &Path) -> std::result::Result<Option<serde_json::Value>, String> {
    let text = match std::fs::read_to_string(path) {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(format!("cannot be read: {e}")),
    };
    serde_json::from_str(&text).map(Some).map_err(|e| format!("not a JSON result file: {e}"))
}

/// The verdicts of a file a scenario-like command writes: `passed` and the fmpy cross-check.
pub fn scenario_verdicts(name: &str, json: &serde_json::Value) -> Vec<(String, bool)> {
    let mut v = Vec::new();
    if let Some(p) = json["passed"].as_bool() {
        v.push((format!("{name}: checks"), p));
    }
    if let Some(i) = json["fmpy"]["identical"].as_bool() {
        v.push((format!("{name}: fmpy gives the same outputs bit for bit"), i));
    }
    v
}

/// Each scenario-like file's verdicts and plot (`<name>.svg` beside it) added to `section`:
/// the part `servo run` and `servo sequence` share (fmpy's timing files name no scenario and
/// are skipped).
pub fn add_scenario_files(section: &mut Section, root: &Path, dir: &Path, jsons: &[PathBuf]) {
    for j in jsons {
        let Some(json) = section.read_result(root, j) else { continue };
        let Some(name) = json["scenario"].as_str().map(str::to_string) else { continue };
        section.verdicts.extend(scenario_verdicts(&name, &json));
        section.plots.push(relative(root, &dir.join(format!("{name}.svg"))));
    }
}

fn esc(s: &str) -> String {
    s.replace('&', "&amp;").replace('<', "&lt;").replace('>', "&gt;").replace('"', "&quot;")
}

/// `path` relative to `root`, with forward slashes (for a link in `root/index.html`).
pub fn relative(root: &Path, path: &Path) -> PathBuf {
    path.strip_prefix(root).map(Path::to_path_buf).unwrap_or_else(|_| path.to_path_buf())
}

/// Write `root/index.html`: what failed or missed a goal, the benches' figures, then the
/// sections (in order); returns its path.
pub fn write_index(root: &Path, sections: &[Section], benches: &[BenchFigures]) -> Result<PathBuf> {
    let mut h = String::new();
    h.push_str("<!doctype html><html><head><meta charset=\"utf-8\"><title>servo: experiments</title>");
    h.push_str(
        "<style>body{font-family:sans-serif;max-width:980px;margin:2em auto}table{border-collapse:collapse}\
         td,th{border:1px solid #ccc;padding:3px 8px}.pass{color:#080}.fail{color:#c00;font-weight:bold}\
         .attention{border:2px solid #c00;padding:0.5em 1em;margin:1em 0}\
         img{max-width:100%;border:1px solid #eee}code{background:#f4f4f4}small{color:#666}</style></head><body>",
    );
    let failed: usize = sections.iter().map(|s| s.verdicts.iter().filter(|v| !v.1).count()).sum();
    let total: usize = sections.iter().map(|s| s.verdicts.len()).sum();
    let unreadable: usize = sections.iter().map(|s| s.unreadable.len()).sum();
    let figures: usize = benches.iter().map(|b| b.figures.iter().filter(|f| f.goal.is_some()).count()).sum();
    let not_met: Vec<(&BenchFigures, &crate::bench::figures::Figure)> =
        benches.iter().flat_map(|b| b.figures.iter().filter(|f| f.not_met()).map(move |f| (b, f))).collect();
    writeln!(h, "<h1>servo: experiments on the servo-axis FMU</h1>")?;
    writeln!(
        h,
        "<p class=\"{}\">{} of {total} checks and cross-checks pass.</p>",
        if failed == 0 { "pass" } else { "fail" },
        total - failed
    )?;
    if !benches.is_empty() {
        writeln!(
            h,
            "<p class=\"{}\">{} of {figures} bench goals met on this machine ({} benches).</p>",
            if not_met.is_empty() { "pass" } else { "fail" },
            figures - not_met.len(),
            benches.len()
        )?;
    }
    // Everything that failed or missed a goal, first.
    if failed + unreadable + not_met.len() > 0 {
        h.push_str("<div class=\"attention\"><h2>Failed or not met</h2><ul>");
        for (i, s) in sections.iter().enumerate() {
            for (label, _) in s.verdicts.iter().filter(|v| !v.1) {
                writeln!(
                    h,
                    "<li class=\"fail\">FAILED: {} (<a href=\"#s{i}\">{}</a>)</li>",
                    esc(label),
                    esc(&s.title)
                )?;
            }
            for (path, why) in &s.unreadable {
                writeln!(h, "<li class=\"fail\">UNREADABLE {}: {}</li>", esc(&path.display().to_string()), esc(why))?;
            }
        }
        for (b, f) in &not_met {
            writeln!(
                h,
                "<li class=\"fail\">NOT MET on this machine: {}: {} against {} (<a href=\"#bench-{}\"><code>{}</code></a>)</li>",
                esc(&f.name),
                esc(&f.measured_text()),
                esc(&f.goal_text()),
                esc(&b.bench),
                esc(&f.command)
            )?;
        }
        h.push_str("</ul></div>");
    }
    h.push_str("<ul>");
    if !benches.is_empty() {
        h.push_str("<li><a href=\"#benches\">Benches: figures against their goals</a></li>");
    }
    for (i, s) in sections.iter().enumerate() {
        writeln!(h, "<li><a href=\"#s{i}\">{}</a></li>", esc(&s.title))?;
    }
    h.push_str("</ul>");
    if !benches.is_empty() {
        h.push_str("<h2 id=\"benches\">Benches: figures against their goals</h2>");
        h.push_str(
            "<p>The worst case each bench measured over its range. Times depend on the machine and its load.</p>",
        );
        for b in benches {
            writeln!(
                h,
                "<h3 id=\"bench-{0}\">{0}</h3><p><code>{1}</code> <span class=\"{2}\">{3}</span><br><small>{4}</small></p>",
                esc(&b.bench),
                esc(&b.command),
                if b.passed { "pass" } else { "fail" },
                if b.passed { "passed" } else { "goal not met or check failed" },
                esc(&b.stamp.text().replace('`', ""))
            )?;
            h.push_str("<table><tr><th>figure</th><th>goal</th><th>measured (worst case)</th><th>result</th></tr>");
            for f in &b.figures {
                let (class, word) = match f.met {
                    Some(true) => ("pass", "met"),
                    Some(false) => ("fail", "NOT met"),
                    None => ("", ""),
                };
                writeln!(
                    h,
                    "<tr><td>{}</td><td>{}</td><td>{}</td><td class=\"{class}\">{word}</td></tr>",
                    esc(&f.name),
                    esc(&f.goal_text()),
                    esc(&f.measured_text())
                )?;
            }
            h.push_str("</table>");
        }
    }
    for (i, s) in sections.iter().enumerate() {
        writeln!(h, "<h2 id=\"s{i}\">{}</h2><p><code>{}</code></p>", esc(&s.title), esc(&s.command))?;
        for (path, why) in &s.unreadable {
            writeln!(h, "<p class=\"fail\">UNREADABLE {}: {}</p>", esc(&path.display().to_string()), esc(why))?;
        }
        if !s.numbers.is_empty() {
            h.push_str("<table><tr><th>key number</th><th>value</th></tr>");
            for (what, value) in &s.numbers {
                writeln!(h, "<tr><td>{}</td><td>{}</td></tr>", esc(what), esc(value))?;
            }
            h.push_str("</table><p></p>");
        }
        if !s.verdicts.is_empty() {
            h.push_str("<table><tr><th>check</th><th>result</th></tr>");
            for (label, ok) in &s.verdicts {
                let class = if *ok { "pass" } else { "fail" };
                writeln!(
                    h,
                    "<tr><td>{}</td><td class=\"{class}\">{}</td></tr>",
                    esc(label),
                    if *ok { "pass" } else { "FAIL" }
                )?;
            }
            h.push_str("</table>");
        }
        for p in &s.plots {
            writeln!(h, "<p><img src=\"{0}\" alt=\"{0}\"></p>", esc(&p.display().to_string()))?;
        }
        if !s.files.is_empty() {
            h.push_str("<p>");
            for f in &s.files {
                writeln!(h, "<a href=\"{0}\">{0}</a> ", esc(&f.display().to_string()))?;
            }
            h.push_str("</p>");
        }
    }
    h.push_str("</body></html>\n");
    let path = root.join("index.html");
    std::fs::write(&path, h)?;
    Ok(path)
}
