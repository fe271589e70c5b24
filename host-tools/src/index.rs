//! `servo index`: out/index.html, the report a user opens first, gathering every experiment
//! found in the out folder; each experiment's section comes from its own `index.rs`.

use std::path::PathBuf;

use anyhow::{bail, Result};

use crate::cli::Common;

/// Gather every experiment's results in the out folder into one page, out/index.html.
///
/// Reads what `servo run`, `servo sequence`, `servo sweep`, `servo accdec`, `servo ident`,
/// `servo tune` and `servo circle` wrote under --out (default out/): their checks with the
/// verdicts, the fmpy cross-checks, the plots and the files behind them.
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
        ]
        .into_iter()
        .flatten()
        .collect();
        if sections.is_empty() {
            bail!("no experiment results in {}: run the experiments first (scripts/demo)", root.display());
        }
        let path = crate::page::write_index(&root, &sections)?;
        let failed = sections.iter().flat_map(|s| &s.verdicts).filter(|v| !v.1).count();
        if !self.common.json {
            println!("{} experiments, {failed} failed checks → {}", sections.len(), path.display());
        }
        Ok(failed == 0)
    }
}
