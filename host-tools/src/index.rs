//! `servo index`: out/index.html, the report a user opens first, gathering every experiment
//! found in the out folder; each experiment's section comes from its own `index.rs`.

use std::path::PathBuf;

use anyhow::{bail, Result};

use crate::cli::Common;

/// Gather every experiment's results in the out folder into one page, out/index.html.
///
/// Reads what `servo run`, `servo sequence`, `servo sweep`, `servo accdec`, `servo ident`,
/// `servo tune`, `servo circle`, `servo calibrate` and `servo autotune` wrote under --out (default out/): their key numbers, their
/// checks with the verdicts, the fmpy cross-checks, the plots and the files behind them; and
/// the benches' figures against their goals (bench/*.json). Anything failed or not met is
/// listed at the top of the page (a bench goal not met on this machine does not change the
/// exit status). A result file that is
/// there but cannot be read is named in a warning and on the page, and the exit status is 1
/// (as for a failed check). --json prints the summary as JSON.
#[derive(clap::Args)]
pub struct IndexArgs {
    #[command(flatten)]
    common: Common,
}

impl IndexArgs {
    pub fn run(&self) -> Result<bool> {
        let root: PathBuf = self.common.out.clone().unwrap_or_else(|| PathBuf::from("out"));
        let sections: Vec<_> = [
            crate::run::index::section(&root),
            crate::sequence::index::section(&root),
            crate::sweep::index::section(&root),
            crate::ident::index::section(&root),
            crate::circle::index::section(&root),
            crate::accdec::index::section(&root),
            crate::device::index::section(&root),
            crate::calibrate::index::section(&root),
            crate::autotune::index::section(&root),
        ]
        .into_iter()
        .flatten()
        .collect();
        // The benches' figures (out/bench/*.json); a figure file that cannot be read is named
        // like an unreadable result file.
        let (benches, bench_error) = match crate::bench::figures::read_dir(&root.join("bench")) {
            Ok(b) => (b, None),
            Err(e) => (Vec::new(), Some(format!("{e:#}"))),
        };
        if sections.is_empty() && benches.is_empty() {
            bail!("no experiment results in {}: run the experiments first (scripts/demo)", root.display());
        }
        let experiments = sections.len();
        let mut sections = sections;
        if let Some(why) = &bench_error {
            sections.push(crate::page::Section {
                title: "Benches".into(),
                command: "servo bench …".into(),
                unreadable: vec![(PathBuf::from("bench"), why.clone())],
                ..Default::default()
            });
        }
        let path = crate::page::write_index(&root, &sections, &benches)?;
        let not_met: Vec<String> = benches
            .iter()
            .flat_map(|b| b.figures.iter().filter(|f| f.not_met()).map(move |f| format!("{}: {}", b.bench, f.name)))
            .collect();
        let failed = sections.iter().flat_map(|s| &s.verdicts).filter(|v| !v.1).count();
        let unreadable: Vec<&(PathBuf, String)> = sections.iter().flat_map(|s| &s.unreadable).collect();
        for (file, why) in &unreadable {
            eprintln!("warning: {}: {why}", root.join(file).display());
        }
        if self.common.json {
            let summary = serde_json::json!({
                "experiments": experiments,
                "checks": sections.iter().map(|s| s.verdicts.len()).sum::<usize>(),
                "failed_checks": failed,
                "unreadable": unreadable.iter().map(|(f, why)| serde_json::json!({"file": root.join(f), "reason": why})).collect::<Vec<_>>(),
                "index": path,
                "benches": benches.iter().map(|b| serde_json::json!({"bench": b.bench, "passed": b.passed, "figures": b.figures})).collect::<Vec<_>>(),
                "bench_goals_not_met": not_met,
                "sections": sections.iter().map(|s| serde_json::json!({
                    "title": s.title,
                    "verdicts": s.verdicts.iter().map(|(check, passed)| serde_json::json!({"check": check, "passed": passed})).collect::<Vec<_>>(),
                })).collect::<Vec<_>>(),
            });
            println!("{}", serde_json::to_string_pretty(&summary)?);
        } else {
            let unread = if unreadable.is_empty() {
                String::new()
            } else {
                format!(", {} result file(s) that cannot be read", unreadable.len())
            };
            let goals = if benches.is_empty() {
                String::new()
            } else {
                format!(", {} bench(es) with {} goal(s) not met on this machine", benches.len(), not_met.len())
            };
            println!("{} experiments, {failed} failed checks{unread}{goals} → {}", experiments, path.display());
        }
        // Exit status 1: a check failed, or something in the folder could not be read.
        Ok(failed == 0 && unreadable.is_empty())
    }
}
