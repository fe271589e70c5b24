//! Replay the vector file given at build time (`CORE_VECTORS_FILE`) and print the digest.

use core::fmt::Write as _;

use control_core::golden_vectors::{decode_only, replay, replay_only};

use core_vectors::semihosting::write;

static VECTORS: &[u8] = include_bytes!(env!("CORE_VECTORS_FILE"));

/// A line buffer for `write!`.
struct Line {
    buf: [u8; 128],
    len: usize,
}

impl core::fmt::Write for Line {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let b = s.as_bytes();
        let n = b.len().min(self.buf.len() - self.len);
        self.buf[self.len..self.len + n].copy_from_slice(&b[..n]);
        self.len += n;
        Ok(())
    }
}

pub fn run() -> bool {
    let mut line = Line { buf: [0; 128], len: 0 };
    core_vectors::clock::start();
    // Calibration: a loop of known length (2 instructions per pass).
    let passes: u32 = 100_000;
    let c0 = core_vectors::clock::ticks();
    // SAFETY: a register-only countdown loop.
    unsafe { core::arch::asm!("1:", "subs {0}, {0}, #1", "bne 1b", inout(reg) passes => _, options(nostack)) };
    let calibration = core_vectors::clock::ticks() - c0;
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
            let mut cost = Line { buf: [0; 128], len: 0 };
            let _ = writeln!(
                cost,
                "core-vectors clock {clocks} core {core_clocks} calibration {calibration} for {} instructions",
                2 * passes
            );
            write(core::str::from_utf8(&cost.buf[..cost.len]).unwrap_or(""));
            true
        }
        Err(e) => {
            let _ = writeln!(line, "core-vectors error {e}");
            false
        }
    };
    write(core::str::from_utf8(&line.buf[..line.len]).unwrap_or("core-vectors: bad line\n"));
    ok
}
