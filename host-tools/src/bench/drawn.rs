//! What the benches over a random draw share: running one member of the draw alone
//! (`--plant N`, `--motor N`) and running each member with a progress bar.

use anyhow::{bail, Result};

/// `draw`, or only its member `pick` (named by `option`, e.g. `--plant`, its members `what`,
/// e.g. "machines"), refused with the draw's range when there is no such member.
pub fn one_or_all<T: Copy>(draw: Vec<T>, pick: Option<u32>, option: &str, what: &str) -> Result<Vec<T>> {
    let Some(k) = pick else { return Ok(draw) };
    match draw.get(k as usize) {
        Some(m) => Ok(vec![*m]),
        None => bail!("{option} {k}: the draw has {what} 0 to {}", draw.len().saturating_sub(1)),
    }
}

/// `run` on each of `members`, in order, behind a progress bar labelled `label` (hidden
/// with `quiet`).
pub fn run_each<T, R>(label: &str, quiet: bool, members: &[T], mut run: impl FnMut(&T) -> R) -> Vec<R> {
    let pb = crate::cli::progress_bar(label, quiet);
    let rows = members
        .iter()
        .enumerate()
        .map(|(k, m)| {
            pb.set_position((1000 * k as u64) / members.len() as u64);
            run(m)
        })
        .collect();
    pb.finish_and_clear();
    rows
}
