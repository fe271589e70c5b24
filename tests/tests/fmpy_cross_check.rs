//! The same scenarios through the Rust host (fmi crate) and through fmpy.simulate_fmu: both
//! run the same binary, so every output must have the same bits. Also `fmpy validate`.

use std::process::Command;

use cross_checks::{fmu_path, load_fmu, scenario_from_text};
use host_tools::fmu::fmpy::{python, run_fmpy};
use host_tools::fmu::scenario::Scenario;
use host_tools::fmu::trace::{compare_exact, Trace};
use host_tools::paths::workspace_root;

#[test]
fn fmpy_validate_finds_no_problem_in_either_archive() {
    let fmi2 = fmu_path().with_file_name("servo_axis_fmi2.fmu");
    for archive in [fmu_path(), fmi2] {
        let out = Command::new(python().unwrap()).args(["-m", "fmpy", "validate"]).arg(&archive).output().unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success() && text.contains("No problems found"),
            "fmpy validate {}:\n{text}",
            archive.display()
        );
    }
}

#[test]
fn every_shipped_scenario_is_bit_identical_in_fmpy() {
    let fmu = load_fmu();
    let dir = workspace_root().join("scenarios");
    let tmp = std::env::temp_dir().join(format!("servo-fmpy-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_none_or(|e| e != "toml") {
            continue;
        }
        let scenario = Scenario::load(&path).unwrap();
        let rust = fmu.run(&scenario, |_| {}).unwrap();
        let csv = tmp.join(format!("{}.fmpy.csv", scenario.name));
        run_fmpy(&fmu_path(), &path, &csv).unwrap();
        let py = Trace::read_csv(&csv).unwrap();
        assert_eq!(py.columns, rust.columns, "{}: same columns", scenario.name);
        match compare_exact(&rust, &py).unwrap() {
            Ok(cols) => assert_eq!(cols, rust.columns.len()),
            Err(m) => panic!("{}: {m:?}", scenario.name),
        }
        // The comparison is not vacuous: the motion is real.
        let v = rust.column("motor_velocity").unwrap();
        assert!(v.iter().any(|x| x.abs() > 1.0), "{}: the axis never moved", scenario.name);
        n += 1;
    }
    assert!(n >= 2, "expected the shipped scenarios, found {n}");
}

#[test]
fn every_parameter_and_input_reads_back_its_start_value_in_fmpy() {
    // Each value reference must reach its own variable (the FMU routes them through its fields).
    let script = workspace_root().join("tests/python/fmpy_start_values.py");
    let out = Command::new(python().unwrap()).arg(&script).arg(fmu_path()).output().unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{text}{}", String::from_utf8_lossy(&out.stderr));
    assert!(text.contains(", 0 mismatches"), "{text}");
}

#[test]
fn a_record_list_gives_those_columns_in_its_order_with_the_full_runs_bits_in_both_hosts() {
    let fmu = load_fmu();
    let body = "stop_time = 0.05\n\n[[events]]\ntime = 0.0\nmode = 1\nvelocity_command = 20.0\n";
    let full = fmu.run(&scenario_from_text("record_full", &format!("name = \"record_full\"\n{body}")), |_| {}).unwrap();
    let text = format!("name = \"record_some\"\nrecord = [\"iq\", \"faults\", \"motor_velocity\"]\n{body}");
    let some = scenario_from_text("record_some", &text);
    let rust = fmu.run(&some, |_| {}).unwrap();
    assert_eq!(rust.columns, ["time", "iq", "faults", "motor_velocity"]);
    assert_eq!(rust.rows.len(), full.rows.len());
    for name in &rust.columns {
        let (a, b) = (rust.column(name).unwrap(), full.column(name).unwrap());
        assert!(a.iter().zip(&b).all(|(x, y)| x.to_bits() == y.to_bits()), "{name} differs from the full run");
    }
    assert!(rust.column("motor_velocity").unwrap().iter().any(|v| *v > 10.0), "the axis never moved");
    // fmpy reads the same list from the file.
    let tmp = std::env::temp_dir().join(format!("servo-record-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    let (toml, csv) = (tmp.join("record_some.toml"), tmp.join("record_some.fmpy.csv"));
    std::fs::write(&toml, &text).unwrap();
    run_fmpy(&fmu_path(), &toml, &csv).unwrap();
    let py = Trace::read_csv(&csv).unwrap();
    assert_eq!(py.columns, rust.columns);
    assert_eq!(compare_exact(&rust, &py).unwrap().map_err(|m| format!("{m:?}")), Ok(4));
    // Names that are not outputs are refused with the reason, by both hosts.
    for (bad, why) in [("nonsense", "no variable `nonsense`"), ("mode", "not an output")] {
        let s = scenario_from_text("record_bad", &format!("name = \"record_bad\"\nrecord = [\"{bad}\"]\n{body}"));
        let e = fmu.run(&s, |_| {}).unwrap_err().to_string();
        assert!(e.contains(why), "{bad}: {e}");
    }
    let bad = tmp.join("record_bad.toml");
    std::fs::write(&bad, format!("name = \"record_bad\"\nrecord = [\"mode\"]\n{body}")).unwrap();
    assert!(run_fmpy(&fmu_path(), &bad, &tmp.join("bad.csv")).is_err(), "fmpy runner accepted a non-output");
}
