//! The telemetry's unused stack (protocol version 9): `None` from a board that does not
//! measure its stack, the board's gauge read afresh on every `GetTelemetry` once it gives one,
//! and the figure crosses the link as the drive answered it.

mod common;

use std::sync::atomic::{AtomicU32, Ordering};

use common::{RamFlash, RestingStage};
use control_core::params::Params;
use control_core::protocol::{decode_response, Request, Response};
use drive_application::link::OUT_BYTES;
use drive_application::Drive;

/// A gauge whose reading the test sets.
static UNUSED: AtomicU32 = AtomicU32::new(0);

fn gauge() -> u32 {
    UNUSED.load(Ordering::Relaxed)
}

fn stack_free(host: &mut drive_application::Host<'_>, flash: &mut RamFlash) -> Option<u32> {
    match host.handle(Request::GetTelemetry, flash) {
        Response::Telemetry(t) => t.stack_free_bytes,
        other => panic!("{other:?}"),
    }
}

#[test]
fn the_telemetry_reports_the_boards_unused_stack_once_it_gives_a_gauge() {
    let mut flash = RamFlash::new();
    let drive = Box::leak(Box::new(Drive::new()));
    let mut host = drive.install::<RestingStage, _>(Params::default(), &mut flash).unwrap();
    assert_eq!(stack_free(&mut host, &mut flash), None, "no gauge: not measured");
    host.report_stack_with(gauge);
    for unused in [4_712, 0, 82_040, u32::MAX] {
        UNUSED.store(unused, Ordering::Relaxed);
        assert_eq!(stack_free(&mut host, &mut flash), Some(unused));
    }
    // Through the link: the request's frame in, the answer's frame out.
    UNUSED.store(1_234, Ordering::Relaxed);
    let mut request = [0u8; 16];
    let n = control_core::protocol::encode(&Request::GetTelemetry, &mut request).unwrap();
    let mut out = [0u8; OUT_BYTES];
    let answered = request[..n].iter().find_map(|&b| host.receive(b, &mut flash, &mut out)).expect("an answer");
    match decode_response(&mut out[..answered]) {
        Ok(Response::Telemetry(t)) => assert_eq!(t.stack_free_bytes, Some(1_234)),
        other => panic!("{other:?}"),
    }
}
