//! Helpers shared by the cross-package tests in `tests/tests/`.

use std::path::PathBuf;

use host_tools::fmu::runner::Fmu;
use host_tools::fmu::scenario::Scenario;
use host_tools::paths::default_fmu;

/// The FMU built by `cargo run -p xtask -- bundle` (scripts/test builds it first).
pub fn fmu_path() -> PathBuf {
    let p = default_fmu();
    assert!(p.exists(), "{} is missing: run scripts/test (it bundles the FMU first)", p.display());
    p
}

pub fn load_fmu() -> Fmu {
    Fmu::load(&fmu_path()).expect("FMU loads")
}

/// A scenario from TOML text, written to a file and loaded through the same path as `servo run`.
pub fn scenario_from_text(name: &str, text: &str) -> Scenario {
    let dir = std::env::temp_dir().join(format!("servo-tests-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join(format!("{name}.toml"));
    std::fs::write(&p, text).unwrap();
    Scenario::load(&p).unwrap()
}

/// Correlate `u` and `y` at frequency `f` (Hz) over samples taken every `h` seconds:
/// returns the complex ratio Y/U as (gain, phase in degrees).
pub fn frequency_response(u: &[f64], y: &[f64], f: f64, h: f64) -> (f64, f64) {
    let w = std::f64::consts::TAU * f;
    let (mut ur, mut ui, mut yr, mut yi) = (0.0, 0.0, 0.0, 0.0);
    for k in 0..u.len() {
        let (s, c) = (w * k as f64 * h).sin_cos();
        ur += u[k] * c;
        ui -= u[k] * s;
        yr += y[k] * c;
        yi -= y[k] * s;
    }
    let den = ur * ur + ui * ui;
    let gr = (yr * ur + yi * ui) / den;
    let gi = (yi * ur - yr * ui) / den;
    ((gr * gr + gi * gi).sqrt(), gi.atan2(gr).to_degrees())
}

/// Wrap a phase difference into (-180, 180].
pub fn wrap_deg(x: f64) -> f64 {
    let mut y = x % 360.0;
    if y > 180.0 {
        y -= 360.0;
    }
    if y <= -180.0 {
        y += 360.0;
    }
    y
}
