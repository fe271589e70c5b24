//! The virtual drive in this process, over the host's own link code: what a board does, done
//! by the firmware's application on the simulated board.

use std::time::Duration;

use control_core::faults::Faults;
use control_core::protocol::{DefaultsReason, ParamsOrigin, Request, Response};
use control_core::{Commands, Mode, Params};

use crate::device::link::DeviceLink;
use crate::device::session::DriveSession;
use crate::fmu::configuration::configuration;
use crate::virtual_drive::faults::{BoardFault, ScheduledFault};
use crate::virtual_drive::flash::FileFlash;
use crate::virtual_drive::in_process::InProcessDrive;
use crate::virtual_drive::simulator::{VirtualDrive, VirtualDriveSettings};
use crate::virtual_drive::uart::LineSettings;

fn settings() -> VirtualDriveSettings {
    let c = configuration(&Default::default()).unwrap();
    VirtualDriveSettings { defaults: c.control, plant: c.plant, line: LineSettings::default(), faults: vec![] }
}

fn session(drive: VirtualDrive<FileFlash>) -> DriveSession<InProcessDrive<FileFlash>> {
    let link = DeviceLink::new(InProcessDrive::new(drive), Duration::from_millis(300));
    DriveSession::open(link).unwrap()
}

#[test]
fn calibrates_then_follows_a_velocity_command_like_the_fmu() {
    let mut s = session(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
    assert_eq!(s.boot_params, ParamsOrigin::Defaults(DefaultsReason::NothingStored));
    s.rest().unwrap();
    let velocity = Commands { mode: Mode::Velocity, velocity: 20.0, ..Commands::default() };
    s.order(Request::SetCommands(velocity), "velocity").unwrap();
    let t = s.wait(0.5).unwrap();
    assert!(!t.faults.any(), "{:?}", t.faults);
    assert!((t.velocity_estimate - 20.0).abs() < 0.5, "velocity {} rad/s after 0.5 s", t.velocity_estimate);
}

#[test]
fn saved_parameters_survive_a_power_cycle_and_a_foreign_rate_is_refused() {
    let mut s = session(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
    let mut p = power_stage::ratings::with_board_limits(Params::default());
    p.velocity.kp *= 1.25;
    s.set_params(&p).unwrap();
    assert_eq!(s.save_params().unwrap(), 1);
    // Another current-loop rate than the board's PWM is refused, with the rate.
    let mut other = p;
    other.rates.current_loop_hz = 20_000.0;
    match s.link.request(&Request::SetParams(other)).unwrap() {
        Response::Refused(why) => assert!(why.to_string().contains("16000 Hz"), "{why}"),
        r => panic!("{r:?}"),
    }
    let off = VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap();
    let flash = std::mem::replace(&mut s.link.port_mut().drive, off).power_off();
    let again = VirtualDrive::power_on(&settings(), flash).unwrap();
    assert_eq!(again.boot_params(), ParamsOrigin::Stored { sequence: 1 });
    assert_eq!(again.params().velocity.kp, p.velocity.kp);
}

#[test]
fn an_injected_break_latches_its_fault_and_an_experiment_refuses_to_start() {
    let mut st = settings();
    st.faults = vec![ScheduledFault { fault: BoardFault::Break, at: 0.2 }];
    let mut s = session(VirtualDrive::power_on(&st, FileFlash::in_memory()).unwrap());
    let t = s.wait(0.3).unwrap();
    assert!(t.faults.contains(Faults::HARDWARE_BREAK), "{:?}", t.faults);
    let e = s.rest().unwrap_err().to_string();
    assert!(e.contains("hardware break input") && e.contains("clear-faults"), "{e}");
    s.order(Request::ClearFaults, "clear").unwrap();
    assert!(!s.rest().unwrap().faults.any());
}

#[test]
fn undervoltage_and_encoder_disconnect_are_seen_by_the_drive() {
    for (fault, bit) in
        [(BoardFault::Undervoltage, Faults::BUS_UNDERVOLTAGE), (BoardFault::EncoderDisconnect, Faults::ENCODER)]
    {
        let mut st = settings();
        st.faults = vec![ScheduledFault { fault, at: 0.2 }];
        let mut s = session(VirtualDrive::power_on(&st, FileFlash::in_memory()).unwrap());
        let t = s.wait(0.3).unwrap();
        assert!(t.faults.contains(bit), "{}: {:?}", fault.name(), t.faults);
    }
}

#[test]
fn a_corrupting_line_gives_a_clear_error_not_a_wrong_answer() {
    let mut st = settings();
    st.line.corrupt_rate = 0.05;
    let mut s = session(VirtualDrive::power_on(&st, FileFlash::in_memory()).unwrap());
    let mut errors = 0;
    for _ in 0..10 {
        match s.telemetry() {
            Ok(t) => assert!(t.velocity_estimate.is_finite()),
            Err(e) => {
                let e = e.to_string();
                // A corrupted answer fails its check; a corrupted terminator leaves the drive
                // waiting for the frame's end: the host's timeout says so.
                assert!(["corrupt", "could not read", "unexpected", "no answer"].iter().any(|w| e.contains(w)), "{e}");
                errors += 1;
            }
        }
    }
    assert!(errors > 0, "5 % of bytes corrupted and every answer got through?");
}

#[test]
fn a_fault_during_a_sweep_stops_it_with_the_fault_named_and_the_samples_kept() {
    let mut st = settings();
    // The sweep starts at START_AT (0.5 s): the break comes about 1.4 s into it.
    st.faults = vec![ScheduledFault { fault: BoardFault::Break, at: crate::fmu::sweep_run::START_AT + 1.4 }];
    let mut s = session(VirtualDrive::power_on(&st, FileFlash::in_memory()).unwrap());
    let run = crate::fmu::sweep_run::SweepRun {
        settings: control_core::phase_shifted_sweep::SweepParams::default(),
        parameters: Default::default(),
        velocity: 50.0,
    };
    let e = crate::sweep::device::sweep_on_drive(&mut s, &run, |_| {}).unwrap_err().to_string();
    assert!(e.contains("latched a fault during the sweep") && e.contains("hardware break input"), "{e}");
    let kept = crate::device::frame_stream::sample_rows(&s.take_samples()).unwrap();
    // About 1.4 s of a 4 kHz stream arrived before the fault.
    assert!(kept.len() > 4_000, "{} samples kept", kept.len());
}

#[test]
fn a_rarely_corrupted_line_loses_no_telemetry_poll() {
    let mut st = settings();
    st.line.corrupt_rate = 2e-4;
    let mut s = session(VirtualDrive::power_on(&st, FileFlash::in_memory()).unwrap());
    for _ in 0..300 {
        let t = s.telemetry().expect("asked again after a corrupt answer");
        assert!(t.velocity_estimate.is_finite());
    }
    let line = s.link.port().drive.line();
    assert!(line.corrupted > 0, "no byte was corrupted: the test proves nothing");
    // And the drive still answers its orders after resynchronising.
    s.order(Request::ClearFaults, "clear").unwrap();
}
