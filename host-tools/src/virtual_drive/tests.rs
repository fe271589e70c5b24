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

/// A session on a drive whose motor is commissioned (the plant hides its mounting: the drive
/// measures it over the link, as on a board).
fn commissioned(drive: VirtualDrive<FileFlash>) -> DriveSession<InProcessDrive<FileFlash>> {
    let mut s = session(drive);
    commission(&mut s);
    s
}

fn commission<T: crate::device::link::DrivePort>(s: &mut DriveSession<T>) {
    let p = s.params().unwrap();
    s.commission(&control_core::commissioning::CommissioningSettings::for_params(&p)).unwrap();
}

/// Schedule `fault` on the session's drive `after` seconds from now.
fn fault_after(s: &mut DriveSession<InProcessDrive<FileFlash>>, fault: BoardFault, after: f64) {
    let drive = &mut s.link.port_mut().drive;
    let at = drive.time() + after;
    drive.schedule_fault(ScheduledFault { fault, at });
}

/// A drive fresh from the factory refuses every mode until its motor is commissioned over the
/// link; the commissioning measures the plant's hidden mounting (direction, electrical offset)
/// and constants, and the drive then runs.
#[test]
fn a_drive_refuses_to_run_until_commissioned_over_the_link_and_then_runs() {
    let st = settings();
    let mut s = session(VirtualDrive::power_on(&st, FileFlash::in_memory()).unwrap());
    let e = s.rest().unwrap_err().to_string();
    assert!(e.contains("not commissioned") && e.contains("servo commission"), "{e}");
    let defaults = s.params().unwrap();
    let e = s.set_params(&defaults).unwrap_err().to_string();
    assert!(e.contains("servo commission"), "{e}");
    let p = s.params().unwrap();
    let c = s.commission(&control_core::commissioning::CommissioningSettings::for_params(&p)).unwrap();
    let truth = st.plant;
    let close = |got: f32, want: f64| (got as f64 / want - 1.0).abs() < 0.03;
    assert!(close(c.measured.resistance, truth.resistance), "{:?}", c.measured);
    assert!(close(c.measured.flux_linkage, truth.flux_linkage), "{:?}", c.measured);
    assert_eq!(c.measured.alignment.pole_pairs, truth.pole_pairs);
    assert!(c.seconds < 5.0, "{} s", c.seconds);
    assert!(s.params().unwrap().commissioned);
    s.rest().unwrap();
}

/// An experiment's parameters never move the drive's commissioned set: a plan made on a twin
/// carries the twin's plant's mounting and motor (on a real machine a mounting the twin cannot
/// know, which would reverse the torque) and the FMU's current-loop gains; the drive keeps its
/// own and takes the rest.
#[test]
fn an_experiments_parameters_keep_the_drives_commissioned_motor_mounting_and_current_gains() {
    let mut s = commissioned(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
    let own = s.params().unwrap();
    let mut plan = own;
    plan.encoder_mounting.reversed = !own.encoder_mounting.reversed;
    plan.encoder_mounting.electrical_offset = (own.encoder_mounting.electrical_offset + 3.0) % control_core::TAU;
    plan.motor.flux_linkage *= 1.5;
    plan.motor.pole_pairs += 1;
    plan.current.kp *= 2.0;
    plan.current.ki *= 0.5;
    plan.velocity.kp *= 1.25;
    s.set_params(&plan).unwrap();
    let now = s.params().unwrap();
    assert_eq!(now.encoder_mounting, own.encoder_mounting);
    assert_eq!(now.motor, own.motor);
    assert_eq!((now.current.kp, now.current.ki), (own.current.kp, own.current.ki));
    assert_eq!(now.velocity.kp, plan.velocity.kp);
    assert!(now.commissioned);
    // It then runs: a velocity command followed, not a reversed torque's run-away.
    let velocity = Commands { mode: Mode::Velocity, velocity: 20.0, ..Commands::default() };
    s.order(Request::SetCommands(velocity), "velocity").unwrap();
    let t = s.wait(0.5).unwrap();
    assert!(!t.faults.any() && (t.velocity_estimate - 20.0).abs() < 0.5, "{:?} {}", t.faults, t.velocity_estimate);
}

#[test]
fn calibrates_then_follows_a_velocity_command_like_the_fmu() {
    let mut s = commissioned(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
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
    let mut s = commissioned(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
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
    let mut s = commissioned(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
    fault_after(&mut s, BoardFault::Break, 0.2);
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
    let mut s = commissioned(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
    // The sweep starts at START_AT (0.5 s) from now: the break comes about 1.4 s into it.
    fault_after(&mut s, BoardFault::Break, crate::fmu::sweep_run::START_AT + 1.4);
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

/// The line between the host and an in-process drive, losing the answer to the first
/// `SaveParams` the host sends: one bit flipped in its first byte, or its delimiter corrupted
/// (the answer then runs into whatever comes next), as a corrupting line does.
struct LosesSaveAnswer {
    drive: InProcessDrive<FileFlash>,
    /// Corrupt the answer's delimiter rather than its first byte.
    at_the_end: bool,
    /// Bytes of the frame the host is writing.
    frame: Vec<u8>,
    /// A save was sent and its answer is still to be hit.
    armed: bool,
    /// Answers hit.
    lost: u32,
}

impl LosesSaveAnswer {
    fn new(drive: VirtualDrive<FileFlash>, at_the_end: bool) -> Self {
        Self { drive: InProcessDrive::new(drive), at_the_end, frame: Vec::new(), armed: false, lost: 0 }
    }
}

impl std::io::Write for LosesSaveAnswer {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        for &b in buf {
            if b != 0 {
                self.frame.push(b);
                continue;
            }
            let mut frame = std::mem::take(&mut self.frame);
            if self.lost == 0 && control_core::protocol::decode::<Request>(&mut frame) == Ok(Request::SaveParams) {
                self.armed = true;
            }
        }
        self.drive.write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.drive.flush()
    }
}

impl std::io::Read for LosesSaveAnswer {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let n = self.drive.read(buf)?;
        if self.armed && n > 0 {
            let k = if self.at_the_end { buf[..n].iter().position(|&b| b == 0) } else { Some(0) };
            if let Some(k) = k {
                buf[k] = match buf[k] {
                    0 => 0x55,
                    0x01 => 0x03,
                    b => b ^ 0x01,
                };
                (self.armed, self.lost) = (false, self.lost + 1);
            }
        }
        Ok(n)
    }
}

impl crate::device::link::DrivePort for LosesSaveAnswer {
    fn pause(&mut self, d: Duration) {
        self.drive.pause(d);
    }
}

/// Issue 16 item 8: a save whose answer the line loses, on the firmware's application and its
/// flash. Written: the host reads the new record's number in the telemetry, takes that as the
/// answer and does not send the save again — the flash holds exactly one record. Not written
/// (refused: the axis moves), its refusal lost: the telemetry shows no new record, the save is
/// sent again and refused again, with the drive's reason.
#[test]
fn a_save_whose_answer_is_lost_is_told_from_the_telemetry_and_writes_one_record() {
    use drive_application::param_store::{read_page, PageContent};
    for at_the_end in [false, true] {
        let drive = VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap();
        let link = DeviceLink::new(LosesSaveAnswer::new(drive, at_the_end), Duration::from_millis(300));
        let mut s = DriveSession::open(link).unwrap();
        commission(&mut s);
        s.rest().unwrap();
        assert_eq!(s.save_params().unwrap(), 1);
        assert_eq!(s.link.port().lost, 1, "the save's answer was not hit: the test proves nothing");
        assert_eq!((s.link.verified, s.link.resent), (1, 0), "judged from the telemetry, not sent again");
        assert_eq!(s.link.by_request.get("SaveParams"), Some(&(0, 1)));
        let flash = s.link.port_mut().drive.drive.flash_mut();
        assert_eq!(read_page(flash, 0, None), PageContent::Record { sequence: 1 });
        assert_eq!(read_page(flash, 1, None), PageContent::Empty, "a second record was written");
        // The next save, answered, writes the next record (the store was left in step).
        assert_eq!(s.save_params().unwrap(), 2);

        // Not written: moving, the refusal lost, the save sent again and refused again.
        let drive = VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap();
        let link = DeviceLink::new(LosesSaveAnswer::new(drive, at_the_end), Duration::from_millis(300));
        let mut s = DriveSession::open(link).unwrap();
        commission(&mut s);
        s.rest().unwrap();
        s.order(Request::SetCommands(Commands { mode: Mode::Velocity, velocity: 20.0, ..Commands::default() }), "v")
            .unwrap();
        let e = s.save_params().unwrap_err().to_string();
        assert!(e.contains("refused the parameter save") && e.contains("stands still"), "{e}");
        assert_eq!(s.link.port().lost, 1);
        assert_eq!((s.link.verified, s.link.resent), (0, 1));
        let flash = s.link.port_mut().drive.drive.flash_mut();
        for page in 0..2 {
            assert_eq!(read_page(flash, page, None), PageContent::Empty);
        }
    }
}

/// A run over the link starts from rest, as its twin does: on a rotor left coasting at speed
/// (torque mode at zero torque after 30 rad/s) `servo run --device`'s position step stops it
/// first and then runs without a fault; the stop at the end of a velocity experiment
/// (`stop_and_rest`) leaves the rotor stopped.
#[test]
fn a_run_on_a_coasting_rotor_stops_it_first_and_a_velocity_experiment_ends_stopped() {
    use crate::device::velocity_ramp::REST_SPEED;
    let mut s = commissioned(VirtualDrive::power_on(&settings(), FileFlash::in_memory()).unwrap());
    let defaults = s.params().unwrap();
    s.set_params(&defaults).unwrap();
    let spin = |s: &mut DriveSession<InProcessDrive<FileFlash>>| {
        s.ramp_velocity(0.0, 30.0, 2000.0).unwrap();
        s.link.pause(Duration::from_millis(200));
    };
    spin(&mut s);
    s.order(Request::SetCommands(Commands { mode: Mode::Torque, ..Commands::default() }), "coast").unwrap();
    assert!(s.telemetry().unwrap().velocity_estimate.abs() > 10.0, "not coasting: no test");
    let scenario =
        crate::fmu::scenario::Scenario::load(&crate::paths::workspace_root().join("scenarios/position_step.toml"))
            .unwrap();
    let run = crate::run::device::scenario_on_drive(&mut s, &scenario, |_| {}).unwrap();
    let faults = run.trace.column("faults").unwrap();
    assert!(faults.iter().all(|&f| f == 0.0), "a fault latched during the run");
    // It started from rest, as its twin does.
    let v0 = run.trace.column("velocity_estimate").unwrap()[0];
    assert!(v0.abs() < REST_SPEED as f64, "the run started at {v0} rad/s");
    // A velocity experiment's end: ramped down, held until stopped, at rest.
    spin(&mut s);
    let t = s.stop_and_rest().unwrap();
    assert!(t.velocity_estimate.abs() < REST_SPEED, "still turning at {} rad/s", t.velocity_estimate);
}
