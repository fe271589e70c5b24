//! On-target tests of the drive's board code live in `on_target.rs` (defmt-test). This
//! library is empty: cargo wants one target besides the tests.
#![no_std]
