//! Replay the vector file given at build time (`CORE_VECTORS_FILE`) and print the digest.

use core::fmt::Write as _;

use control_core::golden_vectors::{decode_only, replay, replay_only};

use core_vectors::semihosting::{write, Line};

static VECTORS: &[u8] = include_bytes!(env!("CORE_VECTORS_FILE"));

/// A vector file streamed from the host as it is replayed (`CORE_VECTORS_STREAM`, its path):
/// for files larger than the flash (a whole commissioning), the digest and the longest ticks.
struct Streamed(core_vectors::semihosting::HostFile);

impl control_core::golden_vectors::VectorSource for Streamed {
    fn fill(&mut self, buf: &mut [u8]) -> bool {
        self.0.fill(buf)
    }
}

pub fn run() -> bool {
    if let Some(path) = option_env!("CORE_VECTORS_STREAM") {
        return run_streamed(path);
    }
    let mut line = Line::new();
    core_vectors::clock::start();
    // Calibration: a loop of known length (2 instructions per pass).
    let passes: u32 = 100_000;
    let calibration = core_vectors::clock::calibrate(passes);
    let before = core_vectors::clock::ticks();
    let result = replay(VECTORS);
    let clocks = core_vectors::clock::ticks() - before;
    // The same replay without the output digest: what the core itself (and the decoding of
    // its inputs) costs.
    let before = core_vectors::clock::ticks();
    let _ = replay_only(VECTORS);
    let step_clocks = core_vectors::clock::ticks() - before;
    let before = core_vectors::clock::ticks();
    let _ = decode_only(VECTORS);
    let decode_clocks = core_vectors::clock::ticks() - before;
    let core_clocks = step_clocks.saturating_sub(decode_clocks);
    let ok = match result {
        Ok((ticks, digest)) => {
            let _ = writeln!(line, "core-vectors ticks {ticks} digest {digest:016x}");
            let mut cost = Line::new();
            let _ = writeln!(
                cost,
                "core-vectors clock {clocks} core {core_clocks} calibration {calibration} for {} instructions",
                2 * passes
            );
            write(cost.as_str(""));
            true
        }
        Err(e) => {
            let _ = writeln!(line, "core-vectors error {e}");
            false
        }
    };
    write(line.as_str("core-vectors: bad line\n"));
    ok
}

/// The streamed replay, each tick's step timed: its digest, and the longest ticks with the
/// calibration that turns their clocks into instructions.
fn run_streamed(path: &str) -> bool {
    let mut line = Line::new();
    core_vectors::clock::start();
    let passes: u32 = 100_000;
    let calibration = core_vectors::clock::calibrate(passes);
    let ok = match core_vectors::semihosting::HostFile::open(path) {
        None => {
            let _ = writeln!(line, "core-vectors error cannot open {path}");
            false
        }
        Some(file) => match control_core::golden_vectors::replay_timed(Streamed(file), &mut core_vectors::clock::ticks)
        {
            Ok((ticks, digest, longest)) => {
                let _ = writeln!(line, "core-vectors ticks {ticks} digest {digest:016x}");
                for t in longest {
                    let mut cost = Line::new();
                    let _ = writeln!(
                        cost,
                        "core-vectors longest tick {} clock {} calibration {calibration} for {} instructions",
                        t.tick,
                        t.clocks,
                        2 * passes
                    );
                    write(cost.as_str(""));
                }
                true
            }
            Err(e) => {
                let _ = writeln!(line, "core-vectors error {e}");
                false
            }
        },
    };
    write(line.as_str("core-vectors: bad line\n"));
    ok
}
