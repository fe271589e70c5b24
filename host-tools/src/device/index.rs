//! The drive's part of out/index.html (`scripts/demo` runs the virtual drive): the sweep over
//! the link against its FMU twin, and the scenarios run on the drive, each with its verdicts.

use std::path::Path;

use crate::page::{files_with, read_result, relative, Section};

pub fn section(root: &Path) -> Option<Section> {
    let (sweep_dir, run_dir) = (root.join("device/sweep"), root.join("device/run"));
    let sweep_path = sweep_dir.join("sweep.json");
    let (sweep, unreadable) = match read_result(&sweep_path) {
        Ok(json) => (json, vec![]),
        Err(why) => (None, vec![(relative(root, &sweep_path), why)]),
    };
    let runs = files_with(&run_dir, "json");
    if sweep.is_none() && runs.is_empty() && unreadable.is_empty() {
        return None;
    }
    let mut s = Section {
        unreadable,
        title: "On a drive: the virtual drive over its serial link, against the FMU twin".into(),
        command: "servo virtual-drive & servo sweep --device PORT; servo run --device PORT".into(),
        ..Default::default()
    };
    if let Some(j) = sweep {
        let (db, deg) = (j["largest_difference"][0].as_f64(), j["largest_difference"][1].as_f64());
        let (dropped, lost) = (j["drive"]["dropped"].as_u64(), j["drive"]["corrupt_frames"].as_u64());
        s.verdicts.push((
            format!(
                "sweep over the link: drive vs twin {:.3} dB, {:.2} deg (each point within the converter's {} dB, {} deg plus {} dB, {} deg, or plus 5 of its standard errors); samples dropped {}, frames lost {}; line use {:.0} %",
                db.unwrap_or(f64::NAN),
                deg.unwrap_or(f64::NAN),
                crate::device::bench::QUANTISATION.0,
                crate::device::bench::QUANTISATION.1,
                crate::device::bench::GOAL_DB,
                crate::device::bench::GOAL_DEG,
                dropped.unwrap_or(0),
                lost.unwrap_or(0),
                100.0 * j["line_use"].as_f64().unwrap_or(f64::NAN)
            ),
            j["passed"].as_bool().unwrap_or(false),
        ));
        s.plots.push(relative(root, &sweep_dir.join("bode.svg")));
        s.files.extend(["sweep.csv", "sweep.json"].iter().map(|f| relative(root, &sweep_dir.join(f))));
    }
    for path in &runs {
        let Some(j) = s.read_result(root, path) else { continue };
        let name = j["scenario"].as_str().unwrap_or("?").to_string();
        for c in j["checks"].as_array().into_iter().flatten() {
            let what = c["description"].as_str().unwrap_or("check");
            s.verdicts.push((format!("{name} on the drive: {what}"), c["passed"].as_bool().unwrap_or(false)));
        }
        s.verdicts.push((format!("{name}: the FMU twin's checks"), j["twin_passed"].as_bool().unwrap_or(false)));
        s.plots.push(relative(root, &run_dir.join(format!("{name}.svg"))));
        s.files.push(relative(root, path));
    }
    Some(s)
}
