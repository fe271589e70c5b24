//! The control core on a Cortex-M4F: replays recorded input vectors through `Axis::step` and
//! prints, over semihosting, the number of ticks and a digest (FNV-1a 64) of every output;
//! `tests/tests/core_on_cortex_m4.rs` computes the same digest on the host. The runtime (reset,
//! vector table, semihosting, the clock) is this package's library.

#![no_std]
#![no_main]

use core_vectors as _;

mod replay;

#[no_mangle]
fn program() -> bool {
    replay::run()
}
