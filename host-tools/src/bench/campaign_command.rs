//! `servo bench fmi-campaign`, `servo bench fault-campaign` and `servo bench robustness`: the
//! FMU under random call sequences, the axis under injected faults, the drive link's campaigns.

use anyhow::{bail, Context, Result};

use crate::bench::args::{FaultCampaignArgs, FmiCampaignArgs, RobustnessBenchArgs};
use crate::bench::figures::Recorder;
use crate::bench::{fault_campaign, fmi_campaign};
use crate::cli::{progress_bar, Common};
use crate::paths::{default_fmu, workspace_root};

impl FmiCampaignArgs {
    pub fn run(&self) -> Result<bool> {
        bench_fmi_campaign(self)
    }
}

fn bench_fmi_campaign(args: &FmiCampaignArgs) -> Result<bool> {
    let (seconds, seed, common) = (args.seconds, args.seed, &args.common);
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
    let sum = |f: fn(&fmi_campaign::ArchiveResult) -> u64| results.iter().map(f).sum::<u64>() as f64;
    Recorder::new("fmi-campaign")
        .equal("random FMI call sequences through fmpy (FMI 3.0 and 2.0): crashes", sum(|r| r.crashes), 0.0, "")
        .equal("hangs", sum(|r| r.hangs), 0.0, "")
        .equal("OK steps with a non-finite output", sum(|r| r.ok_with_non_finite_output), 0.0, "")
        .info("calls made", sum(|r| r.calls), "")
        .write(common.out.as_deref(), passed)?;
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

impl FaultCampaignArgs {
    pub fn run(&self) -> Result<bool> {
        bench_fault_campaign(self)
    }
}

fn bench_fault_campaign(args: &FaultCampaignArgs) -> Result<bool> {
    let (runs, seed, common) = (args.runs, args.seed, &args.common);
    anyhow::ensure!(runs > 0, "--runs must be at least 1");
    let pb = progress_bar("fault campaign", common.json);
    let r = fault_campaign::run(runs, seed, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let undetected: usize = r.kinds.iter().map(|k| k.runs - k.detected).sum();
    Recorder::new("fault-campaign")
        .equal(
            &format!("injected faults ({} kinds × {} runs): faults not detected", r.kinds.len(), r.runs_per_kind),
            undetected as f64,
            0.0,
            "",
        )
        .at_most(
            "worst reaction, from the fault to the bridge off",
            r.worst_reaction_ticks as f64,
            fault_campaign::REACTION_GOAL_TICKS as f64,
            "ticks",
        )
        .equal("ticks with the bridge on again before ClearFaults", r.restarts_without_clear as f64, 0.0, "")
        .write(common.out.as_deref(), r.passed)?;
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

impl RobustnessBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_robustness(&self.campaign, self.seconds, self.seed, &self.common)
    }
}

/// `servo bench robustness`: the campaigns live in `robustness/` and run from a build with
/// overflow checks (`cargo run --profile robustness -p robustness`), which this release
/// binary is not; their figures are printed as they come.
fn bench_robustness(campaign: &str, seconds: f64, seed: u64, common: &Common) -> Result<bool> {
    if !["frames", "requests", "stream", "all"].contains(&campaign) {
        bail!("unknown campaign `{campaign}`: frames, requests, stream or all");
    }
    if !(seconds.is_finite() && seconds > 0.0 && seconds <= 86_400.0) {
        bail!("--seconds must be in (0, 86400] (got {seconds})");
    }
    let mut cmd = std::process::Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    cmd.current_dir(workspace_root()).args(["run", "--profile", "robustness", "-q", "-p", "robustness", "--"]).args([
        "--campaign",
        campaign,
        "--seconds",
        &seconds.to_string(),
        "--seed",
        &seed.to_string(),
    ]);
    if common.json {
        cmd.arg("--json");
    }
    let figures_file = std::env::temp_dir().join(format!("servo-robustness-{}.json", std::process::id()));
    cmd.arg("--figures").arg(&figures_file);
    let status = cmd.status().context("cannot run cargo for the robustness campaigns")?;
    let passed = match status.code() {
        Some(0) => true,
        Some(1) => false,
        _ => bail!("the robustness campaigns did not run to the end ({status})"),
    };
    let text = std::fs::read_to_string(&figures_file).context("the robustness campaigns wrote no figures")?;
    let _ = std::fs::remove_file(&figures_file);
    let campaigns: Vec<serde_json::Value> =
        serde_json::from_str(&text).context("the robustness campaigns' figures are not JSON")?;
    let sum = |key: &str| campaigns.iter().map(|c| c[key].as_u64().unwrap_or(0)).sum::<u64>() as f64;
    let names: Vec<&str> = campaigns.iter().filter_map(|c| c["campaign"].as_str()).collect();
    let overflow_checks = campaigns.iter().all(|c| c["overflow_checks"].as_bool() == Some(true));
    Recorder::new("robustness")
        .equal(
            &format!("link robustness campaigns ({}, {seconds} s each, overflow checks on): crashes", names.join(", ")),
            sum("crashes"),
            0.0,
            "",
        )
        .equal("corrupt frames accepted", sum("accepted_corrupt"), 0.0, "")
        .equal("overflow panics", sum("overflow_panics"), 0.0, "")
        .equal("refusals that changed the drive's state", sum("refusals_that_changed_state"), 0.0, "")
        .equal("stream batches whose bad count reached the rows", sum("bad_counts_used"), 0.0, "")
        .equal("campaigns run without overflow checks", if overflow_checks { 0.0 } else { 1.0 }, 0.0, "")
        .info("inputs tried", sum("inputs"), "")
        .write(common.out.as_deref(), passed)?;
    Ok(passed)
}
