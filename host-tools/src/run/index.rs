//! `servo run`'s part of out/index.html: every scenario's checks, fmpy verdict and plot.

use std::path::Path;

use crate::page::{add_scenario_files, files_with, relative, Section};

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
    add_scenario_files(&mut s, root, &dir, &jsons);
    Some(s)
}
