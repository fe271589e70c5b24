//! Axis names: they name the files `servo ident` and `servo tune` write (`<axis>.model.json`,
//! `<axis>.corr.toml`, ...), so they are restricted to what cannot leave the output folder or
//! hide a file: letters, digits, `_` and `-`, not empty.

use anyhow::{bail, Result};

/// What an axis name may hold, for error messages.
pub const ALLOWED: &str = "letters, digits, _ and -, not empty";

/// Whether `name` is an axis name (see [`ALLOWED`]).
pub fn is_axis_name(name: &str) -> bool {
    !name.is_empty() && name.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

/// Refuse `name` unless it is an axis name; `what` says where it came from (`--axes`, a file).
pub fn check_axis_name(name: &str, what: &str) -> Result<()> {
    if !is_axis_name(name) {
        bail!("{what}: axis name `{name}` is not allowed (axis names name the output files: {ALLOWED})");
    }
    Ok(())
}

/// Refuse any name that is not an axis name, and any name given twice.
pub fn check_axis_names<'a>(names: impl IntoIterator<Item = &'a str>, what: &str) -> Result<()> {
    let mut seen: Vec<&str> = Vec::new();
    for name in names {
        check_axis_name(name, what)?;
        if seen.contains(&name) {
            bail!("{what}: axis `{name}` is given twice (each axis is identified once, into its own files)");
        }
        seen.push(name);
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_that_could_leave_the_folder_or_hide_a_file_are_refused() {
        for good in ["x", "Y2", "axis_1", "z-left"] {
            assert!(is_axis_name(good), "{good}");
        }
        for bad in ["", "../evil", "a/b", ".", "..", ".hidden", "x y", "x\\y", "é", "x:1"] {
            let e = check_axis_name(bad, "--axes").unwrap_err().to_string();
            assert!(e.contains(ALLOWED) && e.contains("--axes"), "{bad}: {e}");
        }
    }

    #[test]
    fn a_name_given_twice_is_refused() {
        assert!(check_axis_names(["x", "y"], "--axes").is_ok());
        let e = check_axis_names(["x", "y", "x"], "--axes").unwrap_err().to_string();
        assert!(e.contains("`x` is given twice"), "{e}");
    }
}
