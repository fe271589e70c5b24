//! `servo accdec`'s part of out/index.html: the profiles, vibration and cut-off plots.

use std::path::Path;

use crate::page::{files_with, relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let dir = root.join("accdec");
    if !dir.join("accdec.json").is_file() {
        return None;
    }
    let mut s = Section::default();
    s.read_result(root, &dir.join("accdec.json"));
    Some(Section {
        title: "Acc/dec after interpolation: Butterworth against moving averages (seed 003)".into(),
        command: "servo accdec".into(),
        plots: files_with(&dir, "svg").iter().map(|p| relative(root, p)).collect(),
        files: vec![relative(root, &dir.join("accdec.json"))],
        ..s
    })
}
