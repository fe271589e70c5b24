//! FMU parameters from the command line: `NAME=VALUE`.

use std::collections::BTreeMap;

use anyhow::{bail, Result};

use crate::fmu::scenario::Value;

/// Parse `NAME=VALUE` (an integer stays an integer, `true`/`false` a boolean).
pub fn parse_assignment(s: &str) -> Result<(String, Value)> {
    let Some((name, value)) = s.split_once('=') else {
        bail!("`{s}` is not NAME=VALUE");
    };
    let value = value.trim();
    let v = if let Ok(i) = value.parse::<i64>() {
        Value::Int(i)
    } else if let Ok(x) = value.parse::<f64>() {
        if !x.is_finite() {
            bail!("`{s}`: the value must be a finite number");
        }
        Value::Float(x)
    } else if let Ok(b) = value.parse::<bool>() {
        Value::Bool(b)
    } else {
        bail!("`{s}`: `{value}` is not a number or a boolean");
    };
    Ok((name.trim().to_string(), v))
}

/// Parameters per axis from `--set` (both), `--x-set`, `--y-set`.
pub fn axis_parameters(both: &[String], own: &[String]) -> Result<BTreeMap<String, Value>> {
    let mut m = BTreeMap::new();
    for s in both.iter().chain(own) {
        let (k, v) = parse_assignment(s)?;
        m.insert(k, v);
    }
    Ok(m)
}
