//! The FMU in other importers: ecos (ecospy) on the FMI 3.0 archive; fmu-manipulation-toolbox's
//! `fmutool -check` on both archives and its FMU container (debug logging on) around each; fmpy
//! and libcosim (the Open Simulation Platform's, through libcosimpy) on the FMI 2.0 archive. Each
//! runs scenarios/position_step.toml its own way (tests/python/importers.py,
//! tests/python/fmpy_run.py) and every recorded value must have the bits of the Rust host's run
//! of the FMI 3.0 archive: one binary, one model, whichever importer and FMI version drive it.

use std::ffi::OsStr;
use std::os::unix::process::ExitStatusExt;
use std::path::{Path, PathBuf};
use std::process::{Command, ExitStatus};
use std::sync::OnceLock;
use std::time::Instant;

use cross_checks::{fmu_path, load_fmu};
use host_tools::fmu::fmpy::{python, run_fmpy};
use host_tools::fmu::scenario::Scenario;
use host_tools::fmu::trace::{compare_exact, Trace};
use host_tools::paths::{default_fmu, workspace_root};

/// The FMI 2.0 Co-Simulation archive the bundle writes beside the FMI 3.0 one.
fn fmi2_path() -> PathBuf {
    let p = default_fmu().with_file_name("servo_axis_fmi2.fmu");
    assert!(
        p.exists(),
        "{} is missing: `cargo run --release -p xtask -- bundle` must write the FMI 2.0 archive beside {}",
        p.display(),
        default_fmu().display()
    );
    p
}

fn scenario_file() -> PathBuf {
    workspace_root().join("scenarios/position_step.toml")
}

/// position_step with a sequence stop key pressed at 0.2 s in position mode: the axis refuses
/// it and the FMU logs the refusal as a Warning, through the importer's logger (its
/// instanceEnvironment), whether logging is on or not.
const REFUSED_KEY: &str = "name = \"position_step_refused_key\"
stop_time = 0.3

[[events]]
time = 0.0
mode = 2
position_command = 0.0

[[events]]
time = 0.01
position_command = 1.0

[[events]]
time = 0.2
seq_stop = 1
";
const REFUSAL_LOGGED: &str =
    "sequence event Stop at t = 0.2 s: sequence event refused: the axis is not in sequence mode";

fn refused_key_file() -> PathBuf {
    static FILE: OnceLock<PathBuf> = OnceLock::new();
    FILE.get_or_init(|| {
        let p = tmp("position_step_refused_key.toml");
        std::fs::write(&p, REFUSED_KEY).unwrap();
        p
    })
    .clone()
}

fn tmp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("servo-importers-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

fn rust_run(file: &Path) -> Trace {
    let trace = load_fmu().run(&Scenario::load(file).unwrap(), |_| {}).unwrap();
    // Not vacuous: the axis makes the 1 rad step.
    let p = trace.column("motor_position").unwrap();
    assert!((p.last().unwrap() - 1.0).abs() < 0.01, "the Rust host's axis did not settle at 1 rad");
    trace
}

/// The references: the Rust host's traces on the FMI 3.0 archive (each run once).
fn reference(refused_key: bool) -> &'static Trace {
    static STEP: OnceLock<Trace> = OnceLock::new();
    static REFUSED: OnceLock<Trace> = OnceLock::new();
    if !refused_key {
        return STEP.get_or_init(|| rust_run(&scenario_file()));
    }
    REFUSED.get_or_init(|| {
        let trace = rust_run(&refused_key_file());
        // The key was refused (reason 9: not in sequence mode), once.
        assert_eq!(trace.column("seq_refused").unwrap().last(), Some(&1.0));
        assert_eq!(trace.column("seq_last_refusal").unwrap().last(), Some(&9.0));
        trace
    })
}

fn describe(status: ExitStatus) -> String {
    match (status.code(), status.signal()) {
        (Some(c), _) => format!("exit status {c}"),
        (None, Some(11)) => "killed by SIGSEGV (signal 11)".into(),
        (None, Some(6)) => "killed by SIGABRT (signal 6)".into(),
        (None, Some(s)) => format!("killed by signal {s}"),
        _ => format!("{status}"),
    }
}

/// Run `tests/python/importers.py ARGS`; panics with everything it printed when it fails.
/// Returns (stdout, stderr) and prints the process's wall time.
fn importer<S: AsRef<OsStr>>(label: &str, args: &[S]) -> (String, String) {
    let script = workspace_root().join("tests/python/importers.py");
    let t0 = Instant::now();
    let out = Command::new(python().unwrap()).arg(&script).args(args).output().unwrap();
    let secs = t0.elapsed().as_secs_f64();
    let (so, se) =
        (String::from_utf8_lossy(&out.stdout).into_owned(), String::from_utf8_lossy(&out.stderr).into_owned());
    eprintln!("{label}: {secs:.2} s (process)\n{se}");
    assert!(out.status.success(), "{label} failed ({}):\n--- stdout\n{so}\n--- stderr\n{se}", describe(out.status));
    (so, se)
}

fn assert_bit_identical(label: &str, csv: &Path, refused_key: bool) {
    let rust = reference(refused_key);
    let other = Trace::read_csv(csv).unwrap();
    assert_eq!(other.columns, rust.columns, "{label}: not the Rust host's columns");
    match compare_exact(rust, &other).unwrap() {
        Ok(n) => assert_eq!(n, rust.columns.len()),
        Err(m) => panic!("{label} differs from the Rust host: {m:?}"),
    }
}

#[test]
fn ecospy_runs_the_fmi3_archive_with_the_rust_hosts_bits() {
    let csv = tmp("position_step.ecospy.csv");
    let label = "ecospy (FMI 3.0)";
    importer(label, &[OsStr::new("ecospy"), fmu_path().as_os_str(), scenario_file().as_os_str(), csv.as_os_str()]);
    assert_bit_identical(label, &csv, false);
    // The FMU's warning reaches ecos's logger (which finds its instance through instanceEnvironment).
    let csv = tmp("position_step_refused_key.ecospy.csv");
    let (_, se) = importer(
        label,
        &[OsStr::new("ecospy"), fmu_path().as_os_str(), refused_key_file().as_os_str(), csv.as_os_str()],
    );
    assert!(se.contains(&format!("[servo] Warning {REFUSAL_LOGGED}")), "{label}: the refusal was not logged:\n{se}");
    assert_bit_identical(label, &csv, true);
}

fn fmutool_check(fmu: &Path, version: &str) {
    let label = format!("fmutool -check (FMI {version})");
    let (so, _) = importer(&label, &[OsStr::new("fmutool-check"), fmu.as_os_str()]);
    // The report says which FMI version it checked against: the archive must be the one named.
    assert!(so.contains(&format!("fmutool-check: FMI {version}, exit 0, 0 error(s)")), "{label}:\n{so}");
}

#[test]
fn fmutool_check_finds_no_error_in_the_fmi3_archive() {
    fmutool_check(&fmu_path(), "3.0");
}

#[test]
fn fmutool_check_finds_no_error_in_the_fmi2_archive() {
    fmutool_check(&fmi2_path(), "2.0");
}

fn container(fmu: &Path, version: &str) {
    let label = format!("fmutool container (FMI {version}, logging on)");
    let v = &version[..1];
    let csv = tmp(&format!("position_step.container{v}.csv"));
    let (_, se) = importer(
        &label,
        &[OsStr::new("fmutool-container"), fmu.as_os_str(), csv.as_os_str(), scenario_file().as_os_str()],
    );
    assert!(se.contains(&format!("FMI {version} container built")), "{label}:\n{se}");
    assert_bit_identical(&label, &csv, false);
    // The FMU's warning comes back through the container's logger, which finds the embedded
    // FMU through instanceEnvironment and prefixes its messages with the FMU's file name.
    let csv = tmp(&format!("position_step_refused_key.container{v}.csv"));
    let (_, se) = importer(
        &label,
        &[OsStr::new("fmutool-container"), fmu.as_os_str(), csv.as_os_str(), refused_key_file().as_os_str()],
    );
    let name = fmu.file_name().unwrap().to_string_lossy();
    assert!(
        se.contains(&format!("container log (FMU): [Warning] {name}: {REFUSAL_LOGGED}")),
        "{label}: the refusal was not logged:\n{se}"
    );
    assert_bit_identical(&label, &csv, true);
}

#[test]
fn an_fmu_container_around_the_fmi3_archive_with_logging_on_has_the_rust_hosts_bits() {
    container(&fmu_path(), "3.0");
}

#[test]
fn an_fmu_container_around_the_fmi2_archive_with_logging_on_has_the_rust_hosts_bits() {
    container(&fmi2_path(), "2.0");
}

#[test]
fn libcosim_runs_the_fmi2_archive_with_the_rust_hosts_bits() {
    let label = "libcosim (FMI 2.0)";
    for (file, refused_key) in [(scenario_file(), false), (refused_key_file(), true)] {
        let csv = tmp(&format!("{}.libcosim.csv", file.file_stem().unwrap().to_string_lossy()));
        let (so, _) =
            importer(label, &[OsStr::new("libcosim"), fmi2_path().as_os_str(), file.as_os_str(), csv.as_os_str()]);
        assert_bit_identical(label, &csv, refused_key);
        if refused_key {
            // The FMU's warning reaches libcosim's log (on stdout; its level: warning and up).
            let logged = format!("[FMI status=warning, category=logStatusWarning] {REFUSAL_LOGGED}");
            assert!(so.contains(&logged), "{label}: the refusal was not logged:\n{so}");
        }
    }
    // libcosim reads FMI 1.0 and 2.0 only: it refuses the FMI 3.0 archive with its reason (the
    // script checks its null slave: libcosimpy would crash on it).
    let script = workspace_root().join("tests/python/importers.py");
    let out = Command::new(python().unwrap())
        .arg(&script)
        .args([OsStr::new("libcosim"), fmu_path().as_os_str(), scenario_file().as_os_str(), tmp("no.csv").as_os_str()])
        .output()
        .unwrap();
    let se = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.code() == Some(1) && se.contains("Unsupported FMI version"), "{}: {se}", describe(out.status));
}

#[test]
fn fmpy_runs_the_fmi2_archive_with_the_rust_hosts_bits() {
    for (file, refused_key) in [(scenario_file(), false), (refused_key_file(), true)] {
        let csv = tmp(&format!("{}.fmpy-fmi2.csv", file.file_stem().unwrap().to_string_lossy()));
        let t0 = Instant::now();
        let wall = run_fmpy(&fmi2_path(), &file, &csv).unwrap();
        eprintln!("fmpy (FMI 2.0): {:.2} s (process), {wall:.2} s simulating", t0.elapsed().as_secs_f64());
        assert_bit_identical("fmpy (FMI 2.0)", &csv, refused_key);
    }
}

/// The import tutorial's Python recipes, as the book prints them (every ```python block of
/// docs/src/tutorials/import-the-fmu.md), run in a folder where `target/fmu/` holds the archives
/// and a copy of the FMI 3.0 one sits beside (the container's recipe takes it from there): each
/// exits 0, and each that prints a number prints the load's position 0.3 s after a 1 rad
/// position command, about 1 rad.
#[test]
fn the_import_tutorials_python_recipes_run_as_printed() {
    let page = std::fs::read_to_string(workspace_root().join("docs/src/tutorials/import-the-fmu.md")).unwrap();
    let recipes: Vec<&str> = page.split("```python\n").skip(1).map(|rest| rest.split("```").next().unwrap()).collect();
    assert!(recipes.len() >= 4, "{} recipes", recipes.len());
    let dir = tmp("recipes");
    std::fs::create_dir_all(dir.join("target")).unwrap();
    let fmu_dir = dir.join("target/fmu");
    if !fmu_dir.exists() {
        std::os::unix::fs::symlink(fmu_path().parent().unwrap(), &fmu_dir).unwrap();
    }
    std::fs::copy(fmu_path(), dir.join("servo_axis.fmu")).unwrap();
    let mut printed = 0;
    for (i, recipe) in recipes.iter().enumerate() {
        let out = Command::new(python().unwrap()).arg("-c").arg(recipe).current_dir(&dir).output().unwrap();
        let (so, se) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(
            out.status.success(),
            "recipe {i} failed ({}):\n{recipe}\n--- stdout\n{so}\n--- stderr\n{se}",
            describe(out.status)
        );
        // The number is the last line (libcosim's log lines come before it).
        if let Some(x) = so.lines().last().and_then(|l| l.trim().parse::<f64>().ok()) {
            assert!((x - 1.0).abs() < 0.02, "recipe {i} printed {x}:\n{recipe}");
            printed += 1;
        }
    }
    assert!(printed >= 3, "only {printed} recipes printed the load's position");
    assert!(dir.join("servo_container.fmu").is_file(), "the container recipe wrote no servo_container.fmu");
}
