//! `servo bench fmi-campaign` and `servo bench fault-campaign`: the FMU under random call
//! sequences, and the axis under injected faults.

use crate::bench::{fault_campaign, fmi_campaign};
use crate::paths::default_fmu;
use anyhow::Result;

use crate::cli::{progress_bar, Common};

pub fn bench_fmi_campaign(seconds: f64, seed: u64, common: &Common) -> Result<bool> {
    anyhow::ensure!(seconds.is_finite() && seconds > 0.0, "--seconds must be a positive number");
    let fmi3 = common.fmu.clone().unwrap_or_else(default_fmu);
    let fmi2 = fmi3.with_file_name(format!(
        "{}_fmi2.fmu",
        fmi3.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
    ));
    let mut results = Vec::new();
    for archive in [fmi3, fmi2] {
        anyhow::ensure!(
            archive.exists(),
            "{} not found: build it with `cargo run -p xtask -- bundle`",
            archive.display()
        );
        if !common.json {
            eprintln!("random FMI call sequences on {} for {seconds} s …", archive.display());
        }
        results.push(fmi_campaign::run_archive(&archive, seconds, seed)?);
    }
    let passed = results.iter().all(|r| r.passed());
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"bench": "fmi-campaign", "results": results, "passed": passed})
            )?
        );
    } else {
        println!("servo bench fmi-campaign — random FMI call sequences through fmpy (seed {seed}), every call in any state, hostile arguments");
        println!(
            "  {:<8} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8} {:>7} {:>6} {:>14} {:>7}",
            "FMI",
            "sequences",
            "calls",
            "OK",
            "Error",
            "refused",
            "steps",
            "crashes",
            "hangs",
            "OK+non-finite",
            "wall s"
        );
        for r in &results {
            println!(
                "  {:<8} {:>9} {:>9} {:>8} {:>8} {:>8} {:>8} {:>7} {:>6} {:>14} {:>7.1}",
                r.fmi_version,
                r.sequences,
                r.calls,
                r.statuses.ok + r.statuses.warning,
                r.statuses.error,
                r.statuses.exception,
                r.steps_ok,
                r.crashes,
                r.hangs,
                r.ok_with_non_finite_output,
                r.wall_seconds
            );
            for f in &r.findings {
                println!("    finding: {f}");
            }
        }
        println!(
            "  goals: 0 crashes, 0 hangs, 0 OK steps with a non-finite output: {}",
            if passed { "met" } else { "NOT met" }
        );
    }
    Ok(passed)
}

pub fn bench_fault_campaign(runs: usize, seed: u64, common: &Common) -> Result<bool> {
    anyhow::ensure!(runs > 0, "--runs must be at least 1");
    let pb = progress_bar("fault campaign", common.json);
    let r = fault_campaign::run(runs, seed, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    if common.json {
        println!("{}", serde_json::to_string_pretty(&serde_json::json!({"bench": "fault-campaign", "result": r}))?);
    } else {
        println!(
            "servo bench fault-campaign — {} runs per fault, injected at random times in position mode with a jog (seed {seed}), {:.1} s",
            r.runs_per_kind, r.wall_seconds
        );
        println!(
            "  {:<40} {:>9} {:>22} {:>24} {:>22}",
            "fault", "detected", "worst reaction (ticks)", "restarts before clear", "runs again after clear"
        );
        for k in &r.kinds {
            println!(
                "  {:<40} {:>5}/{:<3} {:>22} {:>24} {:>22}",
                k.label, k.detected, k.runs, k.worst_reaction_ticks, k.restarts_without_clear, k.recovered_after_clear
            );
        }
        println!(
            "  reaction: from the tick the fault is in what the core reads (runaway: its following error over the limit) to the first PWM command with the bridge off"
        );
        println!(
            "  goals: every fault detected, worst reaction ≤ {} tick(s) (got {}), no restart without ClearFaults (got {}): {}",
            fault_campaign::REACTION_GOAL_TICKS,
            r.worst_reaction_ticks,
            r.restarts_without_clear,
            if r.passed { "met" } else { "NOT met" }
        );
    }
    Ok(r.passed)
}
