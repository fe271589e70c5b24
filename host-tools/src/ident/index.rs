//! `servo ident` and `servo tune`'s part of out/index.html: measured responses and models, the
//! axes before and after the correction, the files a user edits or loads.

use std::path::Path;

use crate::page::{files_with, relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let (ident, tune) = (root.join("ident"), root.join("tune"));
    let models = files_with(&ident, "json");
    if models.is_empty() && !tune.join("tune.json").is_file() {
        return None;
    }
    let mut files: Vec<_> = models.iter().map(|p| relative(root, p)).collect();
    files.extend(files_with(&tune, "toml").iter().map(|p| relative(root, p)));
    let tune_json = files_with(&tune, "json");
    files.extend(tune_json.iter().map(|p| relative(root, p)));
    let mut s = Section::default();
    for path in models.iter().chain(&tune_json) {
        s.read_result(root, path);
    }
    Some(Section {
        title: "Identification and response correction (seed 001)".into(),
        command: "servo ident …; servo tune --model out/ident/*.model.json".into(),
        plots: [files_with(&ident, "svg"), files_with(&tune, "svg")]
            .concat()
            .iter()
            .map(|p| relative(root, p))
            .collect(),
        files,
        ..s
    })
}
