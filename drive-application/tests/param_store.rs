//! The parameter store (issue 16 item 3) on RAM flash: a power loss at every byte of a save
//! leaves a valid set (the previous one or the new one), and corrupt, foreign or refused
//! pages fall back to the defaults with the reason.

mod common;

use common::{RamFlash, RestingStage};
use control_core::params::Params;
use control_core::protocol::{DefaultsReason, FieldName, ParamsOrigin, Request, Response};
use drive_application::param_store::{self, encode_record, load, read_page, save, PageContent, StoreState};
use drive_application::{Drive, ParamFlash};

/// Two parameter sets that differ (a field that validates either way).
fn set(k: u32) -> Params {
    let mut p = Params::default();
    p.limits.following_error = 0.5 + k as f32 * 0.25;
    p
}

/// The set a fresh boot loads, as `(params, origin)`.
fn boot(flash: &mut RamFlash) -> (Params, ParamsOrigin) {
    let drive = Box::leak(Box::new(Drive::new()));
    let host = drive.install::<RestingStage, _>(Params::default(), flash).unwrap();
    (*host.params(), host.boot_params())
}

#[test]
fn a_power_loss_at_every_byte_of_a_save_keeps_the_previous_or_the_new_set() {
    for already in [1u32, 2] {
        // `already` saves before the interrupted one: the next goes to page 1, then page 0.
        let mut base = RamFlash::new();
        let mut state = StoreState::default();
        for k in 0..already {
            save(&mut base, &mut state, &set(k)).unwrap();
        }
        let previous = set(already - 1);
        let new = set(already);
        // Bytes a whole save spends: the erase of a page and the record.
        let mut counting = base.clone();
        counting.budget = Some(usize::MAX);
        save(&mut counting, &mut state.clone(), &new).unwrap();
        let spent = usize::MAX - counting.budget.unwrap();
        assert!(spent > common::PAGE, "a save erases a page and writes a record");
        let (mut kept_previous, mut kept_new) = (0, 0);
        for cut in 0..=spent {
            let mut flash = base.clone();
            flash.budget = Some(cut);
            let _ = save(&mut flash, &mut state.clone(), &new);
            flash.budget = None;
            let (params, origin) = boot(&mut flash);
            match origin {
                ParamsOrigin::Stored { sequence } if params == new => {
                    assert_eq!(sequence, already + 1);
                    kept_new += 1;
                }
                ParamsOrigin::Stored { sequence } if params == previous => {
                    assert_eq!(sequence, already);
                    kept_previous += 1;
                }
                other => panic!("cut after {cut} of {spent} bytes: {other:?}"),
            }
        }
        // The head is written last: only a complete save yields the new set.
        assert_eq!(kept_new, 1, "only the uninterrupted save gives the new set");
        assert_eq!(kept_previous, spent, "every cut keeps the previous set");
    }
}

#[test]
fn saves_alternate_pages_and_the_newest_wins_across_wrap_around() {
    let mut flash = RamFlash::new();
    let mut state = StoreState { newest: Some((1, u32::MAX - 1)) };
    for k in 0..4 {
        save(&mut flash, &mut state, &set(k)).unwrap();
        let (params, origin) = boot(&mut flash);
        assert_eq!(params, set(k));
        assert_eq!(origin, ParamsOrigin::Stored { sequence: (u32::MAX - 1).wrapping_add(k + 1) });
        assert_eq!(state.newest.unwrap().0, k as usize % 2, "pages used in turn");
    }
}

#[test]
fn nothing_stored_corrupt_foreign_and_refused_sets_fall_back_to_the_defaults_with_the_reason() {
    let mut flash = RamFlash::new();
    assert_eq!(boot(&mut flash), (Params::default(), ParamsOrigin::Defaults(DefaultsReason::NothingStored)));

    // One record, one byte of its payload changed: corrupt.
    let mut state = StoreState::default();
    save(&mut flash, &mut state, &set(3)).unwrap();
    let mut corrupt = flash.clone();
    corrupt.pages[0][param_store::HEAD_BYTES + 5] ^= 0x10;
    assert_eq!(read_page(&mut corrupt, 0, None), PageContent::Corrupt);
    assert_eq!(boot(&mut corrupt), (Params::default(), ParamsOrigin::Defaults(DefaultsReason::Corrupt)));

    // Garbage where the head should be: corrupt.
    let mut garbage = RamFlash::new();
    garbage.pages[1][..16].copy_from_slice(b"not a record....");
    assert_eq!(boot(&mut garbage).1, ParamsOrigin::Defaults(DefaultsReason::Corrupt));

    // Another format number (another firmware's layout), the check value right: foreign.
    let mut foreign = flash.clone();
    foreign.pages[0][4..6].copy_from_slice(&7u16.to_le_bytes());
    assert_eq!(boot(&mut foreign).1, ParamsOrigin::Defaults(DefaultsReason::Foreign { format: 7 }));

    // A whole record whose parameters this firmware refuses: the defaults, naming the field.
    let mut bad = Params::default();
    bad.rates.position_divider = 0;
    let field = Params::validate(&bad).unwrap_err().field();
    let mut refused = RamFlash::new();
    let mut record = [0xFFu8; 2048];
    let n = encode_record(&bad, 9, 8, &mut record).unwrap();
    refused.program(0, 0, &record[..n]).unwrap();
    assert_eq!(read_page(&mut refused, 0, None), PageContent::Record { sequence: 9 });
    assert_eq!(
        boot(&mut refused),
        (Params::default(), ParamsOrigin::Defaults(DefaultsReason::Invalid(FieldName::new(field))))
    );

    // A corrupt page beside a valid one: the valid one.
    let mut one_bad = flash.clone();
    save(&mut one_bad, &mut state, &set(4)).unwrap(); // page 1
    one_bad.pages[1][param_store::HEAD_BYTES + 1] ^= 1;
    assert_eq!(boot(&mut one_bad), (set(3), ParamsOrigin::Stored { sequence: 1 }));
    assert_eq!(
        load(&mut one_bad, &mut Params::default()).1.newest,
        Some((0, 1)),
        "the next save overwrites the corrupt page"
    );
}

#[test]
fn save_params_over_the_link_is_loaded_at_the_next_boot_and_refused_in_motion() {
    let mut flash = RamFlash::new();
    let drive = Box::leak(Box::new(Drive::new()));
    let mut host = drive.install::<RestingStage, _>(Params::default(), &mut flash).unwrap();
    assert_eq!(
        host.handle(Request::Hello { version: control_core::protocol::VERSION }, &mut flash),
        Response::Hello {
            version: control_core::protocol::VERSION,
            boot_params: ParamsOrigin::Defaults(DefaultsReason::NothingStored)
        }
    );
    assert_eq!(host.handle(Request::SetParams(set(6)), &mut flash), Response::Done);
    let loaded = host.handle(Request::LoadCorrection(Params::default().correction), &mut flash);
    assert_eq!(loaded, Response::Done);
    // Moving (velocity mode): refused, nothing written.
    let moving = control_core::Commands { mode: control_core::Mode::Velocity, velocity: 10.0, ..Default::default() };
    assert_eq!(host.handle(Request::SetCommands(moving), &mut flash), Response::Done);
    let before = flash.pages.clone();
    assert_eq!(
        host.handle(Request::SaveParams, &mut flash),
        Response::Refused(control_core::protocol::RefusalReason::Busy)
    );
    assert_eq!(flash.pages, before);
    let record = |host: &mut drive_application::Host<'_>, flash: &mut RamFlash| match host
        .handle(Request::GetTelemetry, flash)
    {
        Response::Telemetry(t) => t.params_record,
        other => panic!("{other:?}"),
    };
    assert_eq!(record(&mut host, &mut flash), None, "nothing saved yet, nor by the refused save");
    assert_eq!(host.handle(Request::SetCommands(Default::default()), &mut flash), Response::Done);
    // Each save answers the record it wrote, and the telemetry reports it from then on.
    assert_eq!(host.handle(Request::SaveParams, &mut flash), Response::Saved { sequence: 1 });
    assert_eq!(record(&mut host, &mut flash), Some(1));
    assert_eq!(boot(&mut flash), (set(6), ParamsOrigin::Stored { sequence: 1 }));
    assert_eq!(host.handle(Request::SaveParams, &mut flash), Response::Saved { sequence: 2 });
    assert_eq!(record(&mut host, &mut flash), Some(2));
    // After a restart, the record loaded.
    let again = Box::leak(Box::new(Drive::new()));
    let mut host = again.install::<RestingStage, _>(Params::default(), &mut flash).unwrap();
    assert_eq!(host.boot_params(), ParamsOrigin::Stored { sequence: 2 });
    assert_eq!(record(&mut host, &mut flash), Some(2));
}

#[test]
fn refused_parameter_changes_leave_the_axis_in_force() {
    let mut flash = RamFlash::new();
    let drive = Box::leak(Box::new(Drive::new()));
    let mut host = drive.install::<RestingStage, _>(Params::default(), &mut flash).unwrap();
    assert_eq!(host.handle(Request::SetParams(set(2)), &mut flash), Response::Done);
    let mut bad = set(5);
    bad.rates.position_divider = 0;
    let field = Params::validate(&bad).unwrap_err().field();
    assert_eq!(
        host.handle(Request::SetParams(bad), &mut flash),
        Response::Refused(control_core::protocol::RefusalReason::InvalidParams(FieldName::new(field)))
    );
    assert_eq!(drive.with(|_, axis| *axis.params()).unwrap(), set(2), "the axis in force is unchanged");
    assert_eq!(*host.params(), set(2));
    // A sweep the board's rate cannot run (5 kHz above the velocity loop's 4 kHz Nyquist
    // frequency at 16 kHz): the axis would build, the drive refuses the set by the field now.
    let mut aliasing = set(5);
    aliasing.sweep.stop_hz = 5000.0;
    assert_eq!(Params::validate(&aliasing), Ok(()));
    assert_eq!(
        host.handle(Request::SetParams(aliasing), &mut flash),
        Response::Refused(control_core::protocol::RefusalReason::InvalidParams(FieldName::new("stop_hz")))
    );
    assert_eq!(drive.with(|_, axis| *axis.params()).unwrap(), set(2), "the axis in force is unchanged");
    // Moving: refused as busy, nothing swapped.
    let moving = control_core::Commands { mode: control_core::Mode::Velocity, velocity: 10.0, ..Default::default() };
    assert_eq!(host.handle(Request::SetCommands(moving), &mut flash), Response::Done);
    assert_eq!(
        host.handle(Request::SetParams(set(7)), &mut flash),
        Response::Refused(control_core::protocol::RefusalReason::Busy)
    );
    assert_eq!(drive.with(|_, axis| *axis.params()).unwrap(), set(2));
    // A correction that does not design (a pole above the Nyquist frequency): refused, unchanged.
    let mut c = Params::default().correction;
    c.count = 1;
    c.sections[0].poles.hz = 1.0e6;
    assert_eq!(host.handle(Request::SetCommands(Default::default()), &mut flash), Response::Done);
    assert_eq!(
        host.handle(Request::LoadCorrection(c), &mut flash),
        Response::Refused(control_core::protocol::RefusalReason::Correction)
    );
    assert_eq!(drive.with(|_, axis| *axis.params()).unwrap(), set(2));
}
