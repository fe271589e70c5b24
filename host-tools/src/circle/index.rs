//! `servo circle`'s part of out/index.html: every circle run under out/circle/ (the XY circle,
//! the pseudo-circle with its fmpy verdict, the tuned axes), plots and figures.

use std::path::Path;

use crate::page::{files_with, relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let dir = root.join("circle");
    let mut dirs = vec![dir.clone()];
    let mut subdirs: Vec<_> =
        std::fs::read_dir(&dir).ok()?.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_dir()).collect();
    subdirs.sort();
    dirs.extend(subdirs);
    let mut s =
        Section { title: "Circle tests (seed 002)".into(), command: "servo circle …".into(), ..Default::default() };
    for d in &dirs {
        for name in ["circle.json", "pseudo_circle.json"] {
            let path = d.join(name);
            let Some(json) = s.read_result(root, &path) else { continue };
            let run = relative(root, d).display().to_string();
            for (key, what) in [("roundness_ratio", "roundness"), ("protrusion_ratio", "quadrant protrusion")] {
                if let Some(r) = json[key].as_f64() {
                    s.numbers.push((
                        format!("{run}: {what}, second run against the first"),
                        crate::circle::report::ratio_words(r),
                    ));
                }
            }
            if let Some(i) = json["fmpy"]["identical"].as_bool() {
                s.verdicts
                    .push((format!("{}: fmpy gives the same feedback bit for bit", relative(root, d).display()), i));
            }
            s.files.push(relative(root, &path));
        }
        s.plots.extend(files_with(d, "svg").iter().map(|p| relative(root, p)));
    }
    if s.files.is_empty() && s.unreadable.is_empty() {
        return None;
    }
    Some(s)
}
