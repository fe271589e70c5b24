//! Issue 16 item 7: the virtual drive as a user (and CI) runs it — `servo virtual-drive
//! --speed max` behind its pseudo-terminal — and experiments over it with the same commands
//! as on a board: a sweep compared with its FMU twin, a parameter save, a restart that loads
//! it, a correction loaded; and what goes wrong (faults, no device, a drive that dies) ends
//! in a clear error and an exit status, never a hang.

use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

mod common;

use common::{servo, tmp, OnTheFmu};
use host_tools::paths::default_fmu as fmu_path;

/// One virtual drive at a time: the real-time ones keep their pace better on a loaded
/// two-core CI machine without a drive at `--speed max` beside them.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner())
}

/// A running virtual drive and its port; killed when dropped.
struct VirtualDrive {
    child: Child,
    port: String,
}

impl VirtualDrive {
    /// A drive whose motor is then commissioned (`servo commission`), as a user does once.
    fn start(dir: &Path, speed: &str, extra: &[&str]) -> Self {
        Self::start_with(dir, speed, extra, true)
    }

    /// A drive left as it boots: its motor not commissioned (what a save, a scheduled fault or
    /// a missing commissioning needs).
    fn start_uncommissioned(dir: &Path, speed: &str, extra: &[&str]) -> Self {
        Self::start_with(dir, speed, extra, false)
    }

    fn start_with(dir: &Path, speed: &str, extra: &[&str], commission: bool) -> Self {
        let port_file = dir.join("port");
        let _ = std::fs::remove_file(&port_file);
        let child = servo()
            .args(["virtual-drive", "--speed", speed, "--flash"])
            .arg(dir.join("flash.bin"))
            .arg("--port-file")
            .arg(&port_file)
            .args(extra)
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .unwrap();
        let until = Instant::now() + Duration::from_secs(20);
        while !port_file.exists() {
            assert!(Instant::now() < until, "the virtual drive did not open its port");
            std::thread::sleep(Duration::from_millis(20));
        }
        std::thread::sleep(Duration::from_millis(50));
        let port = std::fs::read_to_string(&port_file).unwrap();
        // A new machine: the drive measures its motor before anything runs (the plant hides
        // its encoder's mounting, as a real one does), kept in its RAM (not saved).
        if commission {
            let o =
                output_within(servo().args(["commission", "--device", &port, "--out"]).arg(dir.join("commission")), 60);
            assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        }
        Self { child, port }
    }

    /// The drive killed after `ms` (a drive that dies mid-experiment), from another thread;
    /// join it to get the drive back.
    fn killed_after(self, ms: u64) -> std::thread::JoinHandle<Self> {
        std::thread::spawn(move || {
            let mut vd = self;
            std::thread::sleep(Duration::from_millis(ms));
            vd.child.kill().unwrap();
            vd
        })
    }
}

impl Drop for VirtualDrive {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Run `c` to its end, failing the test (and killing it) if it takes longer than `seconds`:
/// a hang is a failure, not a stuck CI job.
fn output_within(c: &mut Command, seconds: u64) -> std::process::Output {
    let mut child = c.stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let until = Instant::now() + Duration::from_secs(seconds);
    while child.try_wait().unwrap().is_none() {
        if Instant::now() > until {
            let _ = child.kill();
            panic!("{c:?} still running after {seconds} s");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    child.wait_with_output().unwrap()
}

fn device(port: &str, action: &[&str]) -> std::process::Output {
    output_within(servo().args(["device", "--port", port, "--json"]).args(action), 30)
}

fn json(o: &std::process::Output) -> serde_json::Value {
    // With --json a command's error can be on stdout: both are shown.
    assert!(
        o.status.success(),
        "{:?}\nstderr: {}\nstdout: {}",
        o.status,
        String::from_utf8_lossy(&o.stderr),
        String::from_utf8_lossy(&o.stdout)
    );
    serde_json::from_slice(&o.stdout).unwrap()
}

/// `servo sweep --device PORT --json` with its output in `dir/out` and the project's FMU as
/// the twin, bounded to two minutes.
fn sweep_over(port: &str, dir: &std::path::Path) -> std::process::Output {
    output_within(servo().args(["sweep", "--device", port, "--json"]).on_fmu(dir.join("out")), 120)
}

/// Every point of a device sweep's report within its bound (`device::bench::difference_bound`),
/// checked here from the points' differences and standard errors (not only from the report's
/// verdict): the current converter's systematic allowance plus the goal where the drive's
/// standard error is within the precision target, plus 5 standard errors (at most 5 times the
/// goal) where it is not; and at least `precise_share` of the points held to the goal itself.
fn assert_within_bounds(r: &serde_json::Value, context: &str, precise_share: f64) {
    use host_tools::device::bench::{difference_bound, measured_to_target};
    let points = r["points"].as_array().unwrap();
    let mut at_goal = 0;
    for p in points {
        let f = |v: &serde_json::Value| v.as_f64().unwrap_or(f64::INFINITY);
        // The report's standard errors (one it cannot tell is written as null: infinite).
        let se = host_tools::sweep::standard_error::ResponseStandardError {
            gain_db: f(&p["standard_error"]["gain_db"]),
            phase_deg: f(&p["standard_error"]["phase_deg"]),
            ..host_tools::sweep::standard_error::ResponseStandardError::unknown()
        };
        let (bound_db, bound_deg) = difference_bound(&se);
        let (db, deg) = (f(&p["difference_db"]).abs(), f(&p["difference_deg"]).abs());
        assert!(
            db <= bound_db && deg <= bound_deg,
            "drive vs twin at {} Hz: {db} dB, {deg} deg, bound {bound_db} dB, {bound_deg} deg (standard errors {} dB, {} deg){context}",
            p["frequency"],
            se.gain_db,
            se.phase_deg
        );
        at_goal += measured_to_target(&se) as usize;
    }
    assert!(
        at_goal as f64 >= precise_share * points.len() as f64,
        "{at_goal} of {} points measured to the precision target{context}",
        points.len()
    );
    assert_eq!(r["beyond_bound_hz"].as_array().unwrap().len(), 0, "{}", r["beyond_bound_hz"]);
}

#[test]
fn a_sweep_over_the_virtual_drive_matches_its_twin_and_parameters_survive_a_restart() {
    let _serial = one_at_a_time();
    let dir = tmp("sweep");
    let _ = std::fs::remove_file(dir.join("flash.bin"));
    let vd = VirtualDrive::start(&dir, "max", &[]);
    let hello = json(&device(&vd.port, &["hello"]));
    assert!(hello["boot_params"].as_str().unwrap().contains("nothing saved"), "{hello}");
    // What the drive's commissioning owns cannot be set for one experiment: refused by name
    // before the drive runs anything.
    for set in ["ctrl.current_kp=5", "ctrl.motor_flux_linkage=0.02"] {
        let o = output_within(servo().args(["sweep", "--device", &vd.port, "--set", set]).on_fmu(dir.join("out")), 60);
        let e = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{e}");
        assert!(e.contains("is the drive's") && e.contains(set.split('=').next().unwrap()), "{e}");
        assert!(!dir.join("out").join("device_stream.csv").exists(), "the drive ran: {e}");
    }
    let o = sweep_over(&vd.port, &dir);
    let r = json(&o);
    assert_eq!(r["drive"]["dropped"], 0, "samples dropped on the link");
    assert_eq!(r["points"].as_array().unwrap().len(), 41);
    // Every drive result has its standard error from the streamed samples, finite and positive.
    for p in r["points"].as_array().unwrap() {
        let e = &p["standard_error"];
        let (g, ph) = (e["gain_db"].as_f64().unwrap_or(f64::NAN), e["phase_deg"].as_f64().unwrap_or(f64::NAN));
        assert!(g.is_finite() && g > 0.0 && ph.is_finite() && ph > 0.0, "{p}");
    }
    let csv = std::fs::read_to_string(dir.join("out").join("sweep.csv")).unwrap();
    assert!(csv.lines().next().unwrap().contains(",quality,gain_se_db,phase_se_deg,"), "{csv}");
    // Two measurements of the same response through two current sensors (see
    // `device::bench::GOAL_DB`): each point within the converter's allowance plus the goal, or
    // plus 5 of its standard errors where the drive could not measure it to the precision
    // target (`device::bench::difference_bound`).
    assert_within_bounds(&r, "", 0.75);
    // The sweep gave the drive its parameters: save them, power-cycle, and they are loaded.
    assert_eq!(json(&device(&vd.port, &["save-params"]))["done"], true);
    drop(vd);
    let vd = VirtualDrive::start(&dir, "max", &[]);
    let hello = json(&device(&vd.port, &["hello"]));
    assert!(hello["boot_params"].as_str().unwrap().contains("loaded from flash (record 1)"), "{hello}");
    // A correction frame as `servo tune` writes it loads.
    let mut frame = vec![0u8; control_core::protocol::MAX_FRAME + 8];
    let n = control_core::protocol::encode(
        &control_core::protocol::Request::LoadCorrection(control_core::Params::default().correction),
        &mut frame,
    )
    .unwrap();
    let file = dir.join("x.corr.frame");
    std::fs::write(&file, &frame[..n]).unwrap();
    assert_eq!(json(&device(&vd.port, &["load-correction", file.to_str().unwrap()]))["done"], true);
}

/// `servo device telemetry` prints the drive's telemetry as JSON fields (not a debug string):
/// the tick advances between two polls, and the parameter record is the one a save wrote.
#[test]
fn telemetry_is_printed_as_json_fields() {
    let _serial = one_at_a_time();
    let dir = tmp("telemetry");
    let _ = std::fs::remove_file(dir.join("flash.bin"));
    let vd = VirtualDrive::start(&dir, "max", &[]);
    let first = json(&device(&vd.port, &["telemetry"]));
    let t = &first["telemetry"];
    assert_eq!(t["axis"]["faults"], 0, "a fresh drive has no faults: {first}");
    assert!(t["axis"]["current"]["q"].is_number() && t["axis"]["mode"].is_string(), "{first}");
    assert!(t["params_record"].is_null(), "nothing saved yet: {first}");
    // Protocol 9's unused stack: the field is there, and the simulated board measures none.
    assert!(t.get("stack_free_bytes").is_some_and(|v| v.is_null()), "not measured on the host: {first}");
    let tick =
        |v: &serde_json::Value| v["telemetry"]["axis"]["tick"].as_u64().unwrap_or_else(|| panic!("no tick: {v}"));
    for field in ["position", "velocity_estimate", "torque_command", "sequence", "sweep"] {
        assert!(!t["axis"][field].is_null(), "{field} missing: {first}");
    }
    let record = json(&device(&vd.port, &["save-params"]))["record"].as_u64().unwrap();
    let second = json(&device(&vd.port, &["telemetry"]));
    assert!(tick(&second) > tick(&first), "{first} then {second}");
    assert_eq!(second["telemetry"]["params_record"].as_u64(), Some(record), "{second}");
}

/// The link's summary on stderr: (corrupt frames, requests sent again).
fn line_costs(stderr: &str) -> (u64, u64) {
    let Some(line) = stderr.lines().find(|l| l.starts_with("link: ")) else { return (0, 0) };
    let n: Vec<u64> = line.split(|c: char| !c.is_ascii_digit()).filter_map(|w| w.parse().ok()).collect();
    (n[0], n[1])
}

/// Issue 16 item 8: a line that corrupts 2 bytes in 1 000 each way (`--corrupt-rate 2e-3`,
/// seed 3). Of a sweep's stream, about one sample batch (≈ 140 bytes) in five is lost; the
/// drive vs twin difference stays within its goal (the fit loses samples, not its phase
/// reference: worst 0.122 dB, 0.69° over seeds 1–6). The orders around it — the parameter
/// set, a few hundred bytes, is hit about half the time — and its telemetry polls get hit
/// (2–4 requests sent again a sweep over seeds 1–6, never none), and each is carried out once:
/// the sweep completes. A save over that line succeeds and writes one record (a lost answer is
/// told from the telemetry): after a restart the drive loads record 1.
#[test]
fn a_sweep_and_a_save_over_a_corrupting_line_complete_and_act_once() {
    let _serial = one_at_a_time();
    let dir = tmp("corrupt");
    let _ = std::fs::remove_file(dir.join("flash.bin"));
    let vd = VirtualDrive::start(&dir, "max", &["--corrupt-rate", "2e-3", "--seed", "3"]);
    let o = sweep_over(&vd.port, &dir);
    let e = String::from_utf8_lossy(&o.stderr);
    // Exit status 1: complete, but not every sample arrived (the report says how many frames
    // were lost).
    assert!(matches!(o.status.code(), Some(0 | 1)), "{e}");
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["points"].as_array().unwrap().len(), 41);
    // The line loses about a batch of samples in five: fewer points reach the precision target.
    assert_within_bounds(&r, " over the corrupting line", 0.5);
    let (corrupt, resent) = line_costs(&e);
    assert!(corrupt > 0 && resent > 0, "nothing on the line was hit: the test proves nothing ({e})");
    // A save: done, with the record it wrote (its answer lost or not), and only that record.
    assert_eq!(json(&device(&vd.port, &["save-params"]))["record"], 1);
    drop(vd);
    assert_eq!(records_in(&dir.join("flash.bin")), [Some(1), None]);
    let vd = VirtualDrive::start(&dir, "max", &[]);
    let hello = json(&device(&vd.port, &["hello"]));
    assert!(hello["boot_params"].as_str().unwrap().contains("loaded from flash (record 1)"), "{hello}");
}

/// The sequence numbers of the records in a virtual drive's flash file, page by page (`None`:
/// an erased page; anything else on a page fails the test).
fn records_in(flash: &Path) -> [Option<u32>; 2] {
    use drive_application::param_store::{read_page, PageContent};
    let mut f = host_tools::virtual_drive::flash::FileFlash::open(flash).unwrap();
    [0, 1].map(|page| match read_page(&mut f, page, None) {
        PageContent::Record { sequence } => Some(sequence),
        PageContent::Empty => None,
        other => panic!("page {page}: {other:?}"),
    })
}

/// Issue 16 item 8: a save whose answer the line loses. At `--corrupt-rate 5e-3` seed 1 (3
/// before protocol version 9's telemetry field moved the bytes, 34 before version 7's; 21
/// hits it too) the
/// one byte the line corrupts on the way to a `servo device save-params` is in the save's
/// answer (the summary on stderr says so, or the test proves nothing): the host reads the
/// drive's newest record in the telemetry after it, takes the save as done without sending it
/// again, and the flash holds exactly that one record. (The in-process tests hit the answer by
/// design: `virtual_drive::tests`.)
#[test]
fn a_save_whose_answer_the_line_loses_succeeds_and_writes_one_record() {
    let _serial = one_at_a_time();
    let dir = tmp("lost-save");
    let _ = std::fs::remove_file(dir.join("flash.bin"));
    let vd = VirtualDrive::start_uncommissioned(&dir, "max", &["--corrupt-rate", "5e-3", "--seed", "1"]);
    let o = device(&vd.port, &["save-params"]);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(json(&o)["record"], 1, "{e}");
    assert!(e.contains("judged from the drive's telemetry (SaveParams 1)"), "the save's answer was not lost: {e}");
    drop(vd);
    assert_eq!(records_in(&dir.join("flash.bin")), [Some(1), None]);
}

/// Riding at 250 rad/s the back-EMF leaves too little of the bus for 0.4 N·m from about 800 Hz
/// up (the current loop's commissioned gains ask the most voltage between 0.8 and 3 kHz), none
/// at the sweep's low frequencies: the stream's per-sample flags give every result its share of limited
/// samples, also those that finish between two telemetry polls (most do, the drive being
/// simulated faster than real time), and name each limited one.
#[test]
fn a_sweep_over_the_virtual_drive_names_every_result_measured_with_the_output_limited() {
    let _serial = one_at_a_time();
    let dir = tmp("sweep-limited");
    let vd = VirtualDrive::start(&dir, "max", &[]);
    let o = output_within(
        servo()
            .args(["sweep", "--device", &vd.port, "--json", "--point", "torque", "--amplitude", "0.4"])
            .args(["--velocity", "250", "--start", "100", "--stop", "3000", "--points", "6"])
            .on_fmu(dir.join("out")),
        120,
    );
    // Limited results differ from the twin's beyond the goal: exit 1, not an error (2).
    assert!(matches!(o.status.code(), Some(0 | 1)), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let d = &r["drive"];
    assert_eq!(d["dropped"], 0, "samples dropped on the link");
    // Paired by index with the stream's results.
    let shares: Vec<(f64, f64)> = d["stream"]
        .as_array()
        .unwrap()
        .iter()
        .zip(d["limited_share"].as_array().unwrap())
        .map(|(p, share)| (p["frequency"].as_f64().unwrap(), share.as_f64().unwrap()))
        .collect();
    assert_eq!(d["limited_share"].as_array().unwrap().len(), d["stream"].as_array().unwrap().len());
    assert_eq!(shares.len(), 7, "every result of 6 points and 2 kHz has its share: {shares:?}");
    let named: Vec<f64> = d["limited_hz"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    for &(f, share) in &shares {
        assert!((0.0..=1.0).contains(&share), "{f} Hz: {share}");
        assert_eq!(share > 0.0, named.contains(&f), "{f} Hz share {share}, named {named:?}");
    }
    assert!(named.contains(&3000.0) && !named.iter().any(|&f| f < 500.0), "{named:?}");
    // The table's rows carry the same shares.
    let csv = std::fs::read_to_string(dir.join("out").join("sweep.csv")).unwrap();
    assert!(csv.lines().next().unwrap().ends_with(",limited_share"), "{csv}");
}

#[test]
fn a_pseudo_circle_over_the_virtual_drive_matches_its_twin() {
    let _serial = one_at_a_time();
    let dir = tmp("circle");
    let vd = VirtualDrive::start(&dir, "max", &[]);
    let count = std::f64::consts::TAU / control_core::Params::default().encoder_counts_per_rev as f64;
    let o = output_within(
        servo().args(["circle", "--single", "x", "--device", &vd.port, "--json"]).on_fmu(dir.join("out")),
        120,
    );
    let r = &json(&o)["circle"];
    assert_eq!(r["dropped"], 0, "samples dropped on the link");
    assert_eq!(r["corrupt_frames"], 0);
    // The same core on the same plant: the feedback figures agree within the goal (3 encoder
    // counts: see `circle::device::GOAL_COUNTS`), and the friction's quadrant protrusions,
    // which the figure is there to show, stand far above that on both.
    let (largest, rms) = (r["difference"]["largest"].as_f64().unwrap(), r["difference"]["rms"].as_f64().unwrap());
    assert!(largest <= host_tools::circle::device::GOAL_COUNTS * count, "drive vs twin {largest:e} rad");
    assert!(rms <= count, "drive vs twin rms {rms:e} rad");
    assert_eq!(r["passed"], true, "{r}");
    // The sine starts on a position tick on both: the same command samples, the same figure.
    assert_eq!(r["command_difference"]["largest"].as_f64(), Some(0.0), "{r}");
    for run in r["runs"].as_array().unwrap() {
        let p = run["feedback"]["max_protrusion"].as_f64().unwrap();
        assert!(p > 50.0 * largest, "{}: protrusion {p:e} rad against a difference of {largest:e} rad", run["label"]);
    }
    for f in ["pseudo_circle.svg", "pseudo_circle.csv", "pseudo_circle_twin.csv", "pseudo_circle.json"] {
        assert!(dir.join("out").join(f).exists(), "{f} missing");
    }
    // A drive has no machine-end position sensor: asking for it is refused before the port is opened.
    let o = output_within(
        servo().args(["circle", "--single", "x", "--measure", "load", "--device", &vd.port, "--fmu"]).arg(fmu_path()),
        30,
    );
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no machine-end position sensor"));
}

/// `servo tune --device` over a virtual drive whose plant is axis y's of the 40/70 Hz pair
/// (`servo ident`'s, friction off as the tuning measures): the correction loads, both
/// pseudo-circles match their twins, and at the machine end (the drive's accelerometer) the
/// response matches its twin without and with the correction, agrees with the FMU check's own
/// multisine measurement of the axis, and comes to the other axis's with the correction.
#[test]
fn tune_over_the_virtual_drive_loads_the_correction_and_both_circles_match_their_twins() {
    let _serial = one_at_a_time();
    let dir = tmp("tune");
    let count = std::f64::consts::TAU / control_core::Params::default().encoder_counts_per_rev as f64;
    let goal = host_tools::circle::device::GOAL_COUNTS * count;
    let o = output_within(servo().args(["ident", "--anti-resonance", "x=40,y=70"]).on_fmu(dir.join("ident")), 120);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let models = [dir.join("ident/x.model.json"), dir.join("ident/y.model.json")];
    // The drive's machine is the tuned axis's (the twin's plant is the model's).
    let y: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&models[1]).unwrap()).unwrap();
    let mut plant: Vec<String> = y["fmu_parameters"]
        .as_object()
        .unwrap()
        .iter()
        .filter(|(k, _)| k.starts_with("plant."))
        .map(|(k, v)| format!("{k}={}", v.as_f64().unwrap()))
        .collect();
    assert!(plant.iter().any(|p| p.starts_with("plant.absorber_stiffness=")), "{plant:?}");
    plant.extend(["plant.motor_coulomb=0".into(), "plant.load_coulomb=0".into()]);
    let sets: Vec<&str> = plant.iter().flat_map(|p| ["--set", p.as_str()]).collect();
    let _ = std::fs::remove_file(dir.join("flash.bin"));
    let vd = VirtualDrive::start(&dir, "max", &sets);
    let tune = |extra: &[&str]| {
        output_within(
            servo()
                .args(["tune", "--device", &vd.port, "--json", "--model"])
                .args(&models)
                .args(extra)
                .on_fmu(dir.join("tune")),
            180,
        )
    };
    // An axis the models do not have is refused before the port is opened.
    let o = tune(&["--axis", "z"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--axis z"), "{}", String::from_utf8_lossy(&o.stderr));
    let r = json(&tune(&["--axis", "y"]));
    let d = &r["device"];
    assert_eq!(d["axis"], "y");
    assert_eq!(d["correction_loaded"], true, "{d}");
    for run in [&d["without"], &d["with"]] {
        assert_eq!(run["dropped"], 0, "samples dropped on the link");
        assert_eq!(run["corrupt_frames"], 0);
        let largest = run["difference"]["largest"].as_f64().unwrap();
        assert!(largest <= goal, "drive vs twin {largest:e} rad (goal {goal:e})");
    }
    assert_eq!(d["passed"], true, "{d}");
    // The drive's correction is only the one loaded over the link (its parameters carry none):
    // the correction moves both figures by far more than the goal, and the drive's as the
    // twin's.
    let (on_drive, on_twin) =
        (d["change_on_drive"]["rms"].as_f64().unwrap(), d["change_on_twin"]["rms"].as_f64().unwrap());
    assert!(on_twin > 20.0 * goal, "the correction moves the twin's figure by {on_twin:e} rad only");
    assert!(
        (on_drive - on_twin).abs() <= goal,
        "the correction moves the drive's figure by {on_drive:e} rad, the twin's by {on_twin:e} rad"
    );
    // The machine end, per run and frequency (5, 10, … 40 Hz).
    let m = &d["machine_end"];
    use host_tools::ident::device_machine_end::difference_bound;
    let bandwidth = r["tuning"]["position_bandwidth_hz"].as_f64().unwrap();
    let f = |p: &serde_json::Value, k: &str| p[k].as_f64().unwrap_or(f64::NAN);
    for run in [&m["without"], &m["with"]] {
        assert_eq!(run["dropped"], 0, "samples dropped on the link");
        let points = run["points"].as_array().unwrap();
        assert_eq!(points.len(), host_tools::ident::device_machine_end::POINTS as usize);
        // The delay, weighted by how well each point tells it (1/σ²).
        let mut weighted = (0.0, 0.0);
        for p in points {
            let hz = f(p, "frequency");
            // Drive and twin (the same parameters, the same correction) agree...
            let (rel, se) = (f(p, "relative_difference"), f(p, "standard_error"));
            assert!(rel <= difference_bound(se), "{hz} Hz: drive vs twin {p}");
            assert_eq!(p["within_goal"], true);
            // ...and the drive agrees with the independent measurement, the FMU check's
            // multisine on the FMU's load_position: the same gain, the phase a constant small
            // delay (the two take the command at different instants: 0.156 ms measured, half
            // the position period and half a tick; a wrong scale, sign or ω² would show in the
            // gain or by tens of degrees, a reading a tick late as 0.22 ms).
            let multisine = &p["multisine"];
            let (db, deg) =
                (f(p, "drive_db") - multisine[0].as_f64().unwrap(), f(p, "drive_deg") - multisine[1].as_f64().unwrap());
            let delay_ms = -deg / (360.0 * hz) * 1e3;
            assert!(db.abs() <= 0.02, "{hz} Hz: drive vs the multisine {db} dB ({p})");
            // The drive's own phase error (radians, relative): the difference's standard error
            // is the drive's and the twin's totals combined, each the sum of its real and
            // imaginary variances, so one component of one side is half of it. At 5 Hz the
            // accelerometer's quantisation leaves about 0.5° (0.3 ms); at 40 Hz 0.01 ms.
            let sigma_ms = (se / 2.0).to_degrees() / (360.0 * hz) * 1e3;
            assert!(
                (0.1 - 3.0 * sigma_ms..=0.2 + 3.0 * sigma_ms).contains(&delay_ms),
                "{hz} Hz: drive lags the multisine by {delay_ms} ms (± {sigma_ms}) ({p})"
            );
            weighted = (weighted.0 + delay_ms / sigma_ms.powi(2), weighted.1 + 1.0 / sigma_ms.powi(2));
        }
        let delay_ms = weighted.0 / weighted.1;
        assert!((0.1..=0.2).contains(&delay_ms), "the drive lags the multisine by {delay_ms} ms on average");
    }
    // Without the correction the drive's axis is 0.2 dB from axis x up to the bandwidth; with
    // it, as close as the FMU check brings the axes (0.003 dB, 0.01°) within what the drive
    // resolves (0.005 dB, 0.06°). Not loaded, the drive would stay 0.2 dB off its twin and x.
    let before = &m["without"]["largest_versus_other_axes"];
    let after = &m["with"]["largest_versus_other_axes"];
    assert!(before[0].as_f64().unwrap() > 0.1, "before: {before} (the check proves nothing)");
    assert!(
        after[0].as_f64().unwrap() <= 0.1 * before[0].as_f64().unwrap() && after[1].as_f64().unwrap() <= 0.2,
        "after {after} vs before {before} (up to {bandwidth} Hz)"
    );
    assert_eq!(m["equalised"], true);
    assert_eq!(m["matches_twin"], true);
    // tune.json has the check as its "device" section.
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("tune/tune.json")).unwrap()).unwrap();
    assert_eq!(saved["device"]["axis"], "y");
    assert_eq!(saved["device"]["machine_end"]["with"]["points"].as_array().unwrap().len(), 8);
    assert!(dir.join("tune/device/with/pseudo_circle.svg").exists());
}

#[test]
fn faults_a_missing_device_and_a_dying_drive_end_in_clear_errors() {
    let _serial = one_at_a_time();
    let dir = tmp("faults");
    // A break at 0.2 s: the sweep refuses to start and names the fault.
    let vd = VirtualDrive::start_uncommissioned(&dir, "max", &["--fault", "break@0.2"]);
    std::thread::sleep(Duration::from_millis(300));
    let o = output_within(servo().args(["sweep", "--device", &vd.port, "--fmu"]).arg(fmu_path()), 60);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("hardware break input"), "{e}");
    drop(vd);
    // No device at the path.
    let o = output_within(servo().args(["sweep", "--device", "/dev/no-such-port", "--fmu"]).arg(fmu_path()), 30);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("cannot open the serial port"), "{e}");
    // The drive dies mid-sweep (real-time pace: the sweep takes seconds): an error, no hang.
    let vd = VirtualDrive::start(&dir, "realtime", &[]);
    let port = vd.port.clone();
    let started = Instant::now();
    let killer = vd.killed_after(1500);
    let o = output_within(servo().args(["sweep", "--device", &port, "--fmu"]).arg(fmu_path()), 30);
    drop(killer.join().unwrap());
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(started.elapsed() < Duration::from_secs(15), "took {:?}", started.elapsed());
    assert!(e.contains("drive") && e.contains("sweep incomplete"), "{e}");
}

/// A timeline on the virtual drive in real time (a drive keeps its own time): every
/// expectation holds on the drive's telemetry and on the FMU twin replaying the keys.
#[test]
fn a_sequence_timeline_over_the_virtual_drive_meets_its_expectations_and_the_twin_too() {
    let _serial = one_at_a_time();
    let dir = tmp("sequence");
    let vd = VirtualDrive::start(&dir, "realtime", &[]);
    let timeline = host_tools::paths::workspace_root().join("scenarios/sequences/stop_at_speed.toml");
    let o = output_within(
        servo().args(["sequence", "--device", &vd.port, "--json"]).on_fmu(dir.join("out")).arg(&timeline),
        60,
    );
    let r = json(&o);
    let r = &r[0];
    assert_eq!(r["passed"], true, "{r:#}");
    assert_eq!(r["twin_passed"], true, "{r:#}");
    // Keys reach the drive within a few milliseconds of their time (50 ms: a loaded CI
    // machine), and after the telemetry sample they were sent on.
    for k in r["keys"].as_array().unwrap() {
        let (planned, before, after) =
            (k["planned"].as_f64().unwrap(), k["before"].as_f64().unwrap(), k["after"].as_f64().unwrap());
        assert!(before - planned < 0.05 && after > before, "{k}");
    }
}

/// A scenario on the virtual drive in real time: its set-points at their times, its checks on
/// the drive's telemetry; a scenario with an input a drive lacks is skipped with the reason.
#[test]
fn a_scenario_over_the_virtual_drive_passes_its_checks_and_the_twin_too() {
    let _serial = one_at_a_time();
    let dir = tmp("run");
    let vd = VirtualDrive::start(&dir, "realtime", &[]);
    let root = host_tools::paths::workspace_root();
    let o = output_within(
        servo()
            .args(["run", "--device", &vd.port, "--json"])
            .on_fmu(dir.join("out"))
            .arg(root.join("scenarios/position_step.toml")),
        60,
    );
    let r = json(&o);
    let r = &r[0];
    assert_eq!(r["passed"], true, "{r:#}");
    assert_eq!(r["twin_passed"], true, "{r:#}");
    assert_eq!(r["checks"].as_array().unwrap().len(), 3, "{r:#}");
    let o = output_within(
        servo()
            .args(["run", "--device", &vd.port, "--fmu"])
            .arg(fmu_path())
            .arg(root.join("scenarios/velocity_ramp.toml")),
        60,
    );
    assert!(o.status.success());
    assert!(String::from_utf8_lossy(&o.stdout).contains("skipped on the drive: it sets `disturbance_torque`"));
}

/// The plant parameters of an absorber at `hz` with 5 % damping on the default load (its
/// inertia the load's), as `--set` arguments for the virtual drive.
fn absorber_settings(hz: f64) -> Vec<String> {
    let load = servo_axis::plant::PlantParams::default().load_inertia;
    let w = std::f64::consts::TAU * hz;
    vec![
        "--set".into(),
        format!("plant.absorber_inertia={load}"),
        "--set".into(),
        format!("plant.absorber_stiffness={}", load * w * w),
        "--set".into(),
        format!("plant.absorber_damping={}", 2.0 * 0.05 * load * w),
    ]
}

/// Seed 001 over the drive: the anti-resonance identified from the drive's measured torque
/// and its accelerometer is the plant's (40 Hz, 5 % damping: √(k/J)/2π and c/(2√(kJ)) of the
/// absorber the virtual drive simulates), and the FMU twin's.
#[test]
fn ident_over_the_virtual_drive_finds_the_plants_anti_resonance_and_matches_its_twin() {
    use host_tools::ident::device::{GOAL_DAMPING, GOAL_HZ, GOAL_STANDARD_ERRORS};
    let _serial = one_at_a_time();
    let dir = tmp("ident");
    let settings = absorber_settings(40.0);
    let extra: Vec<&str> = settings.iter().map(String::as_str).collect();
    let vd = VirtualDrive::start(&dir, "max", &extra);
    let ident = |extra: &[&str]| {
        output_within(
            servo()
                .args(["ident", "--device", &vd.port, "--axes", "x", "--anti-resonance", "x=40"])
                .on_fmu(dir.join("out"))
                .args(extra),
            120,
        )
    };
    // An axis that is not among --axes is refused before the port is opened.
    let o = ident(&["--axis", "z"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("--axis z"), "{}", String::from_utf8_lossy(&o.stderr));
    // The report as ident.json has it (its --json output, a thousand points, is more than a
    // pipe holds while `output_within` waits).
    let o = ident(&[]);
    assert!(o.status.success(), "{}{}", String::from_utf8_lossy(&o.stdout), String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/ident.json")).unwrap()).unwrap();
    let found = &r["drive"]["model"]["anti_resonance"];
    let (hz, damping) = (found["hz"].as_f64().unwrap(), found["damping"].as_f64().unwrap());
    assert!((hz - 40.0).abs() <= 0.005 * 40.0, "drive's anti-resonance {hz} Hz, the plant's 40 Hz");
    assert!((damping - 0.05).abs() <= 0.05 * 0.05, "drive's damping {damping}, the plant's 0.05");
    let twin = &r["twin"]["model"]["anti_resonance"];
    let (twin_hz, twin_damping) = (twin["hz"].as_f64().unwrap(), twin["damping"].as_f64().unwrap());
    assert!((hz - twin_hz).abs() <= GOAL_HZ * twin_hz, "drive {hz} Hz, twin {twin_hz} Hz");
    assert!((damping - twin_damping).abs() <= GOAL_DAMPING * twin_damping, "drive {damping}, twin {twin_damping}");
    let z = r["largest_standard_errors"].as_f64().unwrap();
    assert!(z <= GOAL_STANDARD_ERRORS, "drive vs twin: {z} standard errors");
    assert_eq!(r["link"]["dropped"], 0, "samples dropped on the link");
    assert_eq!(r["link"]["corrupt_frames"], 0);
    assert_eq!(r["passed"], true);
    // The same files as the identification on the FMU, and the comparison.
    for f in ["x.model.json", "x.measured.csv", "ident.svg", "ident.json", "x.twin.csv"] {
        assert!(dir.join("out").join(f).exists(), "{f} missing");
    }
    let model = host_tools::ident::identification::AxisModel::load(&dir.join("out/x.model.json")).unwrap();
    assert_eq!(model.anti_resonance.map(|z| z.hz), Some(hz));
}

/// A drive fault before the identification and a drive that dies during it: a clear error,
/// exit status 2, the partial samples saved and marked incomplete, no hang.
#[test]
fn ident_over_a_faulted_or_dying_drive_ends_in_a_clear_error() {
    let _serial = one_at_a_time();
    let dir = tmp("ident-faults");
    let vd = VirtualDrive::start_uncommissioned(&dir, "max", &["--fault", "break@0.2"]);
    std::thread::sleep(Duration::from_millis(300));
    let ident = |port: &str| output_within(servo().args(["ident", "--device", port]).on_fmu(dir.join("out")), 60);
    let o = ident(&vd.port);
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("hardware break input"), "{e}");
    drop(vd);
    // Real-time pace: the record takes 18 s of the drive's time; the drive dies after 1.5 s.
    let vd = VirtualDrive::start(&dir, "realtime", &[]);
    let port = vd.port.clone();
    let started = Instant::now();
    let killer = vd.killed_after(1500);
    let o = ident(&port);
    drop(killer.join().unwrap());
    let e = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(started.elapsed() < Duration::from_secs(15), "took {:?}", started.elapsed());
    assert!(e.contains("ident incomplete"), "{e}");
    let saved: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(dir.join("out/ident.json")).unwrap()).unwrap();
    assert_eq!(saved["complete"], false, "{saved}");
}

/// Issue 38's workflow over a virtual drive whose machine is not the FMU's default (load
/// inertia 2e-4 kg·m², shaft 120 N·m/rad, load friction 0.02 N·m and 1e-4 N·m·s/rad):
/// commission → `servo calibrate --device` (the mechanics and friction from the drive's own
/// sweep and constant-speed runs, within the bounds of the plant the drive simulates)
/// → `servo autotune --device --plant` (the tuning verified on the twin of the calibrated
/// machine and then on the drive itself, margins held there, kept and saved; the drive's
/// parameters read back are the tuning's), autotune's sweeps within 30 s of drive time. A
/// drive whose motor is not commissioned is refused before anything moves.
#[test]
fn calibrate_and_autotune_over_the_virtual_drive_tune_its_machine_verify_it_there_and_save_it() {
    let _serial = one_at_a_time();
    let dir = tmp("autotune-device");
    let machine = [
        "--set",
        "plant.load_inertia=2e-4",
        "--set",
        "plant.shaft_stiffness=120",
        "--set",
        "plant.load_coulomb=0.02",
        "--set",
        "plant.load_viscous=1e-4",
    ];
    let vd = VirtualDrive::start(&dir, "max", &machine);
    let truth = host_tools::fmu::configuration::configuration(&Default::default()).unwrap().plant;
    let (coulomb, viscous) = (truth.motor_coulomb + 0.02, truth.motor_viscous + 1e-4);
    let near = |v: &serde_json::Value, truth: f64| (v.as_f64().unwrap() / truth - 1.0).abs();
    // Calibrate on the drive.
    let o = output_within(servo().args(["calibrate", "--device", &vd.port, "--json"]).on_fmu(dir.join("cal")), 120);
    let cal = json(&o);
    let m = &cal["calibration"]["mechanics"]["mechanics"];
    let f = &cal["calibration"]["friction"];
    for (value, truth, bound) in [
        (&m["motor_inertia"], truth.motor_inertia, 0.03),
        (&m["load_inertia"], 2e-4, 0.03),
        (&m["shaft_stiffness"], 120.0, 0.03),
        // The bounds are 10 % and 20 %; the drive's torque sums make its means every
        // tick's, so this machine's friction comes out within a fraction of a percent.
        (&f["coulomb"], coulomb, 0.02),
        (&f["viscous"], viscous, 0.03),
    ] {
        assert!(near(value, truth) <= bound, "{value} against {truth}: {cal}");
    }
    assert!(cal["values"][0]["truth"].is_null(), "a drive's calibration has no truth: {}", cal["values"][0]);
    // Autotune on the drive, its twin the calibrated machine.
    let o = output_within(
        servo()
            .args(["autotune", "--device", &vd.port, "--json", "--plant"])
            .arg(dir.join("cal/calibrated-plant.toml"))
            .on_fmu(dir.join("out")),
        180,
    );
    let r = json(&o);
    let m = &r["calibration"]["mechanics"];
    assert!(near(&m["load_inertia"], 2e-4) <= 0.03, "{m}");
    assert!(near(&m["shaft_stiffness"], 120.0) <= 0.03, "{m}");
    for v in [&r["verification"], &r["drive_verification"]] {
        assert_eq!(v["passed"], true, "{v}");
        assert!(v["phase_margin_deg"].as_f64().unwrap() >= 45.0, "{v}");
        assert!(v["sensitivity_peak"].as_f64().unwrap() <= 1.6, "{v}");
    }
    assert!(r["drive_verification"]["on"].as_str().unwrap().contains(&vd.port), "{}", r["drive_verification"]);
    assert!(r["saved_sequence"].as_u64().is_some(), "{}", r["saved_sequence"]);
    // The drive time of autotune's two sweeps (the drive ends each itself). A drive at
    // `--speed max` behind a pseudo-terminal runs on while the host waits on the line, so its
    // sweeps' measurement time counts the host's latency in reading the stream (33–36 s here
    // on a 2-core VM, the same design each time), and the constant-speed runs, paced by the
    // host, count it many times over: held to the workflow's goal (60 s), whose figure is the
    // in-process bench's (`servo bench autotune --virtual-drive`, `servo bench calibrate
    // --virtual-drive`).
    let drive_time = r["drive_time_s"].as_f64().unwrap();
    assert!(
        drive_time > 0.0 && drive_time <= 60.0,
        "autotune: {drive_time} s of drive time (reserve {}, close design {}, verification {} s)",
        r["reserve"],
        r["close_design"],
        r["drive_verification"]["drive_time_s"]
    );
    assert!(cal["calibration"]["drive_time_s"].as_f64().unwrap() > 0.0, "{cal}");
    // The drive runs the tuning (f32 on the drive).
    let p = json(&device(&vd.port, &["params"]));
    let tuning = &r["design"]["tuning"];
    for gain in ["kp", "ki"] {
        let (a, b) = (p["params"]["velocity"][gain].as_f64().unwrap(), tuning[gain].as_f64().unwrap());
        assert!((a / b - 1.0).abs() < 1e-6, "drive {gain} {a}, designed {b}");
    }
    let kp = (p["params"]["position"]["kp"].as_f64().unwrap(), r["position"]["kp"].as_f64().unwrap());
    assert!((kp.0 / kp.1 - 1.0).abs() < 1e-6, "drive position kp {}, designed {}", kp.0, kp.1);
    assert!(dir.join("out/open-loop.svg").exists() && dir.join("out/autotune.toml").exists());
    drop(vd);
    // Not commissioned: refused, naming what to do.
    let vd = VirtualDrive::start_uncommissioned(&tmp("autotune-device-new"), "max", &machine);
    let o = output_within(servo().args(["autotune", "--device", &vd.port]).on_fmu(dir.join("refused")), 60);
    assert!(!o.status.success());
    let e = String::from_utf8_lossy(&o.stderr);
    assert!(e.contains("not commissioned") && e.contains("servo commission"), "{e}");
}
