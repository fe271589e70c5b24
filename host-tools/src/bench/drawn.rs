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

/// `run` on each of `members` behind a progress bar labelled `label` (hidden with `quiet`),
/// on `jobs` threads, each with its own `state` (an FMU loaded once per thread, say): the
/// members are independent, so the rows are those a single thread gives, in the members'
/// order. An error making a thread's state stops the others after their member at hand, and
/// the run returns it.
pub fn run_each<T: Sync, S, R: Send>(
    label: &str,
    quiet: bool,
    members: &[T],
    jobs: usize,
    state: impl Fn() -> Result<S> + Sync,
    run: impl Fn(&mut S, &T) -> R + Sync,
) -> Result<Vec<R>> {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::sync::Mutex;
    let pb = crate::cli::progress_bar(label, quiet);
    pb.set_length(members.len() as u64);
    // Where the bar is not drawn (stderr not a terminal: a log file, CI), a line per member
    // ended, with the time so far and the time left at that pace.
    let log_lines = !quiet && !std::io::IsTerminal::is_terminal(&std::io::stderr());
    let (started, done) = (std::time::Instant::now(), AtomicUsize::new(0));
    let next = AtomicUsize::new(0);
    let rows: Mutex<Vec<Option<R>>> = Mutex::new(members.iter().map(|_| None).collect());
    let worker = || -> Result<()> {
        let mut s = state().inspect_err(|_| next.store(members.len(), Ordering::Relaxed))?;
        loop {
            let k = next.fetch_add(1, Ordering::Relaxed);
            let Some(m) = members.get(k) else { return Ok(()) };
            let row = run(&mut s, m);
            rows.lock().unwrap_or_else(|e| e.into_inner())[k] = Some(row);
            pb.inc(1);
            let n = done.fetch_add(1, Ordering::Relaxed) + 1;
            if log_lines {
                let elapsed = started.elapsed().as_secs_f64();
                let left = elapsed / n as f64 * (members.len() - n) as f64;
                eprintln!(
                    "{label}: {n} of {} done, {:.1} min so far, about {:.1} min left",
                    members.len(),
                    elapsed / 60.0,
                    left / 60.0
                );
            }
        }
    };
    let jobs = jobs.clamp(1, members.len().max(1));
    let ended = std::thread::scope(|scope| {
        let handles: Vec<_> = (0..jobs).map(|_| scope.spawn(worker)).collect();
        handles.into_iter().map(|h| h.join().unwrap_or_else(|p| std::panic::resume_unwind(p))).collect::<Vec<_>>()
    });
    pb.finish_and_clear();
    ended.into_iter().collect::<Result<()>>()?;
    let rows = rows.into_inner().unwrap_or_else(|e| e.into_inner());
    Ok(rows.into_iter().map(|r| r.expect("every member ran")).collect())
}

/// The threads a bench over a draw runs on by default: one per core, or one where each member
/// runs on a virtual drive (its link waits on wall-clock timeouts, which drives competing for
/// the cores can meet).
pub fn default_jobs(virtual_drive: bool) -> usize {
    if virtual_drive {
        1
    } else {
        std::thread::available_parallelism().map_or(1, |n| n.get())
    }
}

#[cfg(test)]
mod tests {
    use std::sync::atomic::{AtomicUsize, Ordering};
    use std::time::Duration;

    use super::*;

    /// On several threads, the members finishing out of order (the first ones take longest),
    /// each member's row lands in its place and each thread makes its state once; a state
    /// that one thread cannot make ends the run with its error.
    #[test]
    fn rows_keep_the_members_order_on_any_number_of_threads() {
        let members: Vec<u64> = (0..24).collect();
        let states = AtomicUsize::new(0);
        let slow_first = |_: &mut usize, m: &u64| {
            std::thread::sleep(Duration::from_millis(24 - m));
            m * m
        };
        for jobs in [1, 2, 5, 64] {
            states.store(0, Ordering::Relaxed);
            let rows =
                run_each("test", true, &members, jobs, || Ok(states.fetch_add(1, Ordering::Relaxed)), slow_first)
                    .unwrap();
            assert_eq!(rows, members.iter().map(|m| m * m).collect::<Vec<_>>());
            assert_eq!(states.load(Ordering::Relaxed), jobs.min(members.len()));
        }
        states.store(0, Ordering::Relaxed);
        let second_fails = || match states.fetch_add(1, Ordering::Relaxed) {
            1 => bail!("no FMU"),
            k => Ok(k),
        };
        let refused = run_each("test", true, &members, 3, second_fails, slow_first);
        assert_eq!(refused.unwrap_err().to_string(), "no FMU");
    }
}
