//! `servo run`'s part of out/index.html: every scenario's checks, fmpy verdict and plot.

use std::path::Path;

use crate::page::{files_with, read_json, relative, scenario_verdicts, Section};

pub fn section(root: &Path) -> Option<Section> {
    let dir = root.join("run");
    let jsons = files_with(&dir, "json");
    if jsons.is_empty() {
        return None;
    }
    let mut s = Section {
        title: "Scenarios".into(),
        command: "servo run --fmpy".into(),
        files: vec![relative(root, &dir.join("index.html"))],
        ..Default::default()
    };
    for j in &jsons {
        // A scenario's file names it (fmpy's timing files do not).
        let Some(json) = read_json(j) else { continue };
        let Some(name) = json["scenario"].as_str().map(str::to_string) else { continue };
        s.verdicts.extend(scenario_verdicts(&name, &json));
        s.plots.push(relative(root, &dir.join(format!("{name}.svg"))));
    }
    Some(s)
}
