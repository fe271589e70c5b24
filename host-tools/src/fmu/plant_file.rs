//! A plant file: the twin's machine as `servo calibrate` writes it and every command that
//! runs a twin takes with `--plant FILE` — a TOML file with one `[parameters]` table of the
//! FMU's `plant.*` parameters. A command's `--set` assignments apply on top of it.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::Path;

use anyhow::{bail, Context, Result};
use serde::Deserialize;

use crate::fmu::assignment::parse_assignment;
use crate::fmu::scenario::Value;

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct PlantFile {
    parameters: BTreeMap<String, Value>,
}

/// The `plant.*` parameters of the plant file at `path`. Refused with the reason: a name that
/// is not a plant parameter of the FMU (a drive's `ctrl.*` belongs to the drive, not to the
/// machine), a value that is not finite, a file that is not such TOML.
pub fn read_plant_file(path: &Path) -> Result<BTreeMap<String, Value>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("reading the plant file {}", path.display()))?;
    let file: PlantFile = toml::from_str(&text)
        .with_context(|| format!("{}: a plant file is a [parameters] table of plant.* values", path.display()))?;
    use servo_axis::variables::Kind;
    for (name, value) in &file.parameters {
        let Some(d) = servo_axis::variables::by_name(name).filter(|_| name.starts_with("plant.")) else {
            bail!("{}: `{name}` is not a plant parameter of the FMU (a plant file holds plant.* only)", path.display());
        };
        let fits = match (d.kind, value) {
            (_, Value::Float(x)) if !x.is_finite() => false,
            (Kind::Float64, Value::Float(_) | Value::Int(_)) => true,
            (Kind::Int32, Value::Int(_)) => true,
            (Kind::Int32, Value::Float(x)) => x.fract() == 0.0,
            (Kind::Boolean, Value::Bool(_)) => true,
            _ => false,
        };
        if !fits {
            let wants = match d.kind {
                Kind::Float64 => "a finite number",
                Kind::Int32 => "a whole number",
                Kind::Boolean => "true or false",
            };
            bail!("{}: `{name}` = {value} is not {wants}", path.display());
        }
    }
    Ok(file.parameters)
}

/// Write a plant file of `values` with a `#` comment `header` (one line or more).
pub fn write_plant_file(path: &Path, header: &str, values: &[(&str, Value)]) -> Result<()> {
    let mut text = String::new();
    for line in header.lines() {
        writeln!(text, "# {line}")?;
    }
    text.push_str("[parameters]\n");
    for (name, value) in values {
        match value {
            Value::Float(x) => writeln!(text, "\"{name}\" = {x:e}")?,
            other => writeln!(text, "\"{name}\" = {other}")?,
        }
    }
    std::fs::write(path, text).with_context(|| format!("writing {}", path.display()))
}

/// A run's FMU parameters: the plant file's (if any), then each `--set` NAME=VALUE over them.
pub fn machine_parameters(plant: Option<&Path>, set: &[String]) -> Result<BTreeMap<String, Value>> {
    let mut parameters = match plant {
        Some(path) => read_plant_file(path)?,
        None => BTreeMap::new(),
    };
    for s in set {
        let (k, v) = parse_assignment(s)?;
        parameters.insert(k, v);
    }
    Ok(parameters)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A written file reads back as its values; --set overrides it; a drive parameter, an
    /// unknown name or another table is refused with the reason.
    #[test]
    fn a_plant_file_round_trips_and_refuses_what_is_not_the_machine() {
        let dir = std::env::temp_dir().join(format!("plant-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("plant.toml");
        write_plant_file(
            &path,
            "calibrated\nfrom a sweep",
            &[
                ("plant.load_inertia", Value::Float(3.25e-4)),
                ("plant.motor_coulomb", Value::Float(0.03)),
                ("plant.substeps", Value::Int(4)),
            ],
        )
        .unwrap();
        let p = machine_parameters(Some(&path), &["plant.motor_coulomb=0.05".into()]).unwrap();
        assert_eq!(p["plant.load_inertia"], Value::Float(3.25e-4));
        assert_eq!(p["plant.motor_coulomb"], Value::Float(0.05));
        assert_eq!(p["plant.substeps"], Value::Int(4));
        for (text, says) in [
            ("[parameters]\n\"ctrl.velocity_kp\" = 0.1\n", "not a plant parameter"),
            ("[parameters]\n\"plant.no_such_thing\" = 1.0\n", "not a plant parameter"),
            ("[other]\nx = 1\n", "a plant file is a [parameters] table"),
            ("[parameters]\n\"plant.load_inertia\" = nan\n", "not a finite number"),
            ("[parameters]\n\"plant.load_inertia\" = true\n", "not a finite number"),
            ("[parameters]\n\"plant.substeps\" = 2.5\n", "not a whole number"),
        ] {
            std::fs::write(&path, text).unwrap();
            let e = format!("{:#}", read_plant_file(&path).unwrap_err());
            assert!(e.contains(says), "{text}: {e}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
