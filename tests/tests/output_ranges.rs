//! The FMU's outputs stay within the ranges their declarations give (`fmu/src/variables/table.rs`,
//! written to the model descriptions as `min`/`max` and to the book's FMU variables page): every
//! shipped scenario and a sweep, run through the Rust host with every output recorded, and every
//! value of every output checked (finite where no range is declared).

use std::collections::{BTreeMap, BTreeSet};
use std::path::PathBuf;

use control_core::faults::Faults;
use control_core::phase_shifted_sweep::SweepParams;
use cross_checks::load_fmu;
use host_tools::fmu::scenario::Scenario;
use host_tools::fmu::sweep_run::SweepRun;
use host_tools::fmu::trace::Trace;
use host_tools::paths::workspace_root;
use host_tools::sequence::timeline::SequenceScenario;
use servo_axis::variables::{Causality, Declaration, DECLARATIONS};

/// The `.toml` files of `scenarios/<sub>`, sorted.
fn files_in(sub: &str) -> Vec<PathBuf> {
    host_tools::page::files_with(&workspace_root().join("scenarios").join(sub), "toml")
}

/// Every value of every output column of `trace` against its declaration; the outputs seen are
/// added to `seen`, the ones whose value moved to `moved`.
fn check(run: &str, trace: &Trace, seen: &mut BTreeSet<&'static str>, moved: &mut BTreeSet<&'static str>) {
    let outputs: BTreeMap<&str, &Declaration> =
        DECLARATIONS.iter().filter(|d| d.causality == Causality::Output).map(|d| (d.name, d)).collect();
    for (i, name) in trace.columns.iter().enumerate() {
        let Some(d) = outputs.get(name.as_str()) else { continue };
        seen.insert(d.name);
        let (min, max) = (d.range.min.unwrap_or(f64::NEG_INFINITY), d.range.max.unwrap_or(f64::INFINITY));
        let first = trace.rows.iter().next().map(|r| r[i]);
        for row in trace.rows.iter() {
            let v = row[i];
            assert!(
                v.is_finite() && v >= min && v <= max,
                "{run}: {} = {v} at t = {} s, outside {min} … {max}",
                d.name,
                row[0]
            );
            if Some(v) != first {
                moved.insert(d.name);
            }
        }
    }
}

#[test]
fn every_output_stays_within_its_declared_range() {
    let fmu = load_fmu();
    let (mut seen, mut moved) = (BTreeSet::new(), BTreeSet::new());
    // The scenarios (position and velocity modes, an acc/dec move) and the stop sequences'
    // timelines (the sequence's states, refusals and gains).
    let scenarios = files_in("");
    let sequences = files_in("sequences");
    assert!(scenarios.len() >= 3 && sequences.len() >= 4, "{scenarios:?} {sequences:?}");
    for file in &scenarios {
        let trace = fmu.run(&Scenario::load(file).unwrap(), |_| {}).unwrap();
        check(&file.display().to_string(), &trace, &mut seen, &mut moved);
    }
    for file in &sequences {
        let scenario = SequenceScenario::load(file).unwrap().to_scenario();
        let trace = fmu.run(&scenario, |_| {}).unwrap();
        check(&file.display().to_string(), &trace, &mut seen, &mut moved);
    }
    // A sweep through the acquisition Nyquist frequency: the sweep's and acquisition's outputs.
    let settings = SweepParams { start_hz: 500.0, stop_hz: 3000.0, points: 4, ..Default::default() };
    let run = SweepRun { settings, parameters: BTreeMap::new(), velocity: 50.0 };
    check("sweep", &run.run(&fmu, |_| {}).unwrap(), &mut seen, &mut moved);

    // Every output was recorded by some run, and most of them moved (a range test over values
    // that never change would tell little).
    let outputs: BTreeSet<&str> =
        DECLARATIONS.iter().filter(|d| d.causality == Causality::Output).map(|d| d.name).collect();
    let unseen: Vec<_> = outputs.difference(&seen).collect();
    assert!(unseen.is_empty(), "outputs no run recorded: {unseen:?}");
    assert!(
        moved.len() * 10 >= outputs.len() * 7,
        "only {} of {} outputs moved: {moved:?}",
        moved.len(),
        outputs.len()
    );
}

/// The `faults` output's range is every latched bit the core has, and no more: a new fault bit
/// must widen it (and name itself in the variable's description).
#[test]
fn the_faults_range_covers_every_fault_bit() {
    let faults = DECLARATIONS.iter().find(|d| d.name == "faults").unwrap();
    let max = faults.range.max.unwrap() as u32;
    assert_eq!(Faults(max).names().count(), (max + 1).trailing_zeros() as usize, "every bit up to {max} is a fault");
    assert!((max + 1).is_power_of_two());
    assert_eq!(Faults(!max).names().count(), 0, "a fault bit above {max}");
    for bit in 0..(max + 1).trailing_zeros() {
        assert!(faults.description.contains(&format!("{} ", 1u32 << bit)), "the description names bit {}", 1u32 << bit);
    }
}
