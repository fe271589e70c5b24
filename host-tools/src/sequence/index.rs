//! `servo sequence`'s part of out/index.html: every timeline's expectations, fmpy verdict and plot.

use std::path::Path;

use crate::page::{add_scenario_files, files_with, Section};

pub fn section(root: &Path) -> Option<Section> {
    let dir = root.join("sequence");
    let jsons = files_with(&dir, "json");
    if jsons.is_empty() {
        return None;
    }
    let mut s = Section {
        title: "Stop, zero-servo and fine-adjust sequences (seed 004)".into(),
        command: "servo sequence --fmpy".into(),
        ..Default::default()
    };
    add_scenario_files(&mut s, root, &dir, &jsons);
    Some(s)
}
