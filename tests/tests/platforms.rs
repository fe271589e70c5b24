//! Issue 17: the archives carry three binaries (x86_64 Linux for glibc 2.17, x86_64 Windows,
//! aarch64 Linux) and all three give the same bits. `scripts/platforms` builds them and
//! scripts/test runs it first. A C harness (`tests/platforms/harness.c`), compiled with gcc,
//! x86_64-w64-mingw32-gcc and aarch64-linux-gnu-gcc, drives each binary through the FMI 3.0
//! C API: natively, under Wine and under qemu-user. It runs every shipped scenario
//! (`scenarios/*.toml`, `scenarios/sequences/*.toml`) as a schedule of FMI calls made here
//! from the scenario (what `servo run` does, step for step) and prints every recorded output
//! at every step as the hex of its bits. The native run must equal the Rust host's run of the
//! same archive (the harness drives the FMU as the host does), and the three platforms must
//! print the same text.

use std::fmt::Write as _;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

use cross_checks::{fmu_path, load_fmu};
use fmi::schema::fmi3::Causality;
use host_tools::fmu::runner::{Fmu, Kind};
use host_tools::fmu::scenario::{Scenario, Value};
use host_tools::fmu::trace::Trace;
use host_tools::paths::workspace_root;
use host_tools::sequence::timeline::SequenceScenario;

/// `binaries/` folders: (FMI 3.0 name, FMI 2.0 name, file name).
const BINARIES: [(&str, &str, &str); 3] = [
    ("x86_64-linux", "linux64", "servo_axis.so"),
    ("x86_64-windows", "win64", "servo_axis.dll"),
    ("aarch64-linux", "aarch64-linux", "servo_axis.so"),
];

/// DLLs every 64-bit Windows (10 and later) has.
const WINDOWS_SYSTEM_DLLS: [&str; 9] = [
    "kernel32.dll",
    "ntdll.dll",
    "msvcrt.dll",
    "userenv.dll",
    "ws2_32.dll",
    "advapi32.dll",
    "bcrypt.dll",
    "bcryptprimitives.dll",
    "api-ms-win-core-synch-l1-2-0.dll",
];

fn work_dir(name: &str) -> PathBuf {
    let target = fmu_path().parent().unwrap().parent().unwrap().to_path_buf();
    let dir = target.join("platforms").join(name);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn entry(archive: &Path, name: &str) -> Vec<u8> {
    let mut zip = zip::ZipArchive::new(std::fs::File::open(archive).unwrap()).unwrap();
    let mut file = zip
        .by_name(name)
        .unwrap_or_else(|_| panic!("{} has no {name}: build it with scripts/platforms", archive.display()));
    let mut bytes = Vec::new();
    file.read_to_end(&mut bytes).unwrap();
    bytes
}

/// The three binaries of the FMI 3.0 archive, written to `dir`; checks the FMI 2.0 archive
/// carries the same bytes under its folder names.
fn extract_binaries(dir: &Path) -> Vec<PathBuf> {
    let fmi3 = fmu_path();
    let fmi2 = fmi3.with_file_name("servo_axis_fmi2.fmu");
    BINARIES
        .iter()
        .map(|(folder3, folder2, file)| {
            let bytes = entry(&fmi3, &format!("binaries/{folder3}/{file}"));
            assert!(
                bytes == entry(&fmi2, &format!("binaries/{folder2}/{file}")),
                "the FMI 2.0 archive's {folder2} binary differs from the FMI 3.0 archive's {folder3}"
            );
            let path = dir.join(folder3).join(file);
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            std::fs::write(&path, bytes).unwrap();
            path
        })
        .collect()
}

fn run(cmd: &mut Command) -> String {
    let out = cmd.output().unwrap_or_else(|e| panic!("{cmd:?}: {e} (scripts/platforms installs the tools)"));
    assert!(out.status.success(), "{cmd:?} failed:\n{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8(out.stdout).unwrap()
}

/// The newest `GLIBC_x.y[.z]` symbol version an ELF file needs.
fn newest_glibc(objdump: &str, library: &Path) -> (Vec<u32>, String) {
    let text = run(Command::new(objdump).arg("-T").arg(library));
    let newest = text
        .split(|c: char| c.is_whitespace() || c == '(' || c == ')')
        .filter_map(|w| w.strip_prefix("GLIBC_"))
        .filter_map(|v| v.split('.').map(|n| n.parse::<u32>().ok()).collect::<Option<Vec<u32>>>())
        .max()
        .expect("the library links glibc");
    let name = format!("GLIBC_{}", newest.iter().map(u32::to_string).collect::<Vec<_>>().join("."));
    (newest, name)
}

#[test]
fn linux_binaries_need_glibc_2_17_at_most_and_the_windows_one_only_system_dlls() {
    let dir = work_dir("imports");
    let libs = extract_binaries(&dir);
    for (lib, objdump) in [(&libs[0], "objdump"), (&libs[2], "aarch64-linux-gnu-objdump")] {
        let (version, name) = newest_glibc(objdump, lib);
        eprintln!("{}: newest glibc symbol {name}", lib.strip_prefix(&dir).unwrap().display());
        assert!(version <= vec![2, 17], "{} needs {name}, newer than glibc 2.17", lib.display());
    }
    let text = run(Command::new("x86_64-w64-mingw32-objdump").arg("-p").arg(&libs[1]));
    let dlls: Vec<String> =
        text.lines().filter_map(|l| l.trim().strip_prefix("DLL Name: ")).map(str::to_lowercase).collect();
    eprintln!("x86_64-windows/servo_axis.dll imports {}", dlls.join(", "));
    assert!(dlls.iter().any(|d| d == "kernel32.dll"), "no import table read: {text}");
    for d in &dlls {
        assert!(WINDOWS_SYSTEM_DLLS.contains(&d.as_str()), "the DLL imports {d}, not a Windows system DLL");
    }
}

/// Every shipped scenario, by file name.
fn shipped_scenarios() -> Vec<(String, Scenario)> {
    let root = workspace_root().join("scenarios");
    let mut out = Vec::new();
    for (dir, sequence) in [(root.clone(), false), (root.join("sequences"), true)] {
        let mut paths: Vec<PathBuf> = std::fs::read_dir(&dir)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "toml"))
            .collect();
        paths.sort();
        for p in paths {
            let s =
                if sequence { SequenceScenario::load(&p).unwrap().to_scenario() } else { Scenario::load(&p).unwrap() };
            out.push((p.strip_prefix(&root).unwrap().display().to_string(), s));
        }
    }
    out
}

fn bits(x: f64) -> String {
    format!("{:016x}", x.to_bits())
}

/// The scenario as the harness's schedule: the calls `Fmu::run` makes, in its order.
fn schedule(fmu: &Fmu, s: &Scenario, out: &mut String) {
    let set = |out: &mut String, name: &str, v: Value| {
        let var = fmu.variable(name).unwrap();
        match (var.kind, v) {
            (Kind::Float64, v) => writeln!(out, "F {} {}", var.vr, bits(v.as_f64())),
            (Kind::Int32, Value::Int(i)) => writeln!(out, "I {} {i}", var.vr),
            (Kind::Int32, Value::Float(f)) if f.fract() == 0.0 => writeln!(out, "I {} {}", var.vr, f as i32),
            (Kind::Boolean, Value::Bool(b)) => writeln!(out, "B {} {}", var.vr, b as u8),
            (kind, v) => panic!("{name} is {kind:?}, {v:?} is not of that type"),
        }
        .unwrap();
    };
    writeln!(out, "T {}", servo_axis::model_description::instantiation_token()).unwrap();
    for (name, v) in &s.parameters {
        assert_eq!(fmu.variable(name).unwrap().causality, Causality::Parameter, "{name}");
        set(out, name, *v);
    }
    writeln!(out, "E {} {}", bits(0.0), bits(s.stop_time)).unwrap();
    let changes = s.changes();
    let mut pending = changes.iter().peekable();
    let mut apply = |out: &mut String, k: usize| {
        while let Some((_, group)) = pending.next_if(|(j, _)| *j <= k) {
            for (name, v) in group {
                set(out, name, *v);
            }
        }
    };
    apply(out, 0);
    writeln!(out, "X").unwrap();
    for (kind, letter) in [(Kind::Float64, 'f'), (Kind::Int32, 'i'), (Kind::Boolean, 'b')] {
        let vrs: Vec<String> =
            fmu.recorded(&s.record).unwrap().iter().filter(|v| v.kind == kind).map(|v| v.vr.to_string()).collect();
        if !vrs.is_empty() {
            writeln!(out, "O {letter} {} {}", vrs.len(), vrs.join(" ")).unwrap();
        }
    }
    writeln!(out, "R").unwrap();
    let h = s.step();
    for k in 0..s.steps() {
        apply(out, k);
        writeln!(out, "S {} {}\nR", bits(k as f64 * h), bits(h)).unwrap();
    }
    writeln!(out, "Q").unwrap();
}

/// The host's trace in the harness's format (outputs grouped by type as the schedule's O lines).
fn trace_as_text(fmu: &Fmu, s: &Scenario, trace: &Trace, out: &mut String) {
    let recorded = fmu.recorded(&s.record).unwrap();
    let mut order: Vec<(usize, Kind)> = Vec::new();
    for kind in [Kind::Float64, Kind::Int32, Kind::Boolean] {
        order.extend(recorded.iter().enumerate().filter(|(_, v)| v.kind == kind).map(|(i, v)| (i, v.kind)));
    }
    for row in &trace.rows {
        let cells: Vec<String> = order
            .iter()
            .map(|&(i, kind)| match kind {
                Kind::Float64 => bits(row[i + 1]),
                _ => format!("{}", row[i + 1] as i64),
            })
            .collect();
        writeln!(out, "{}", cells.join(" ")).unwrap();
    }
}

fn compile(compiler: &str, args: &[&str], output: &Path, extra: &[&str]) {
    let src = workspace_root().join("tests/platforms");
    let mut cmd = Command::new(compiler);
    cmd.args(["-O2", "-std=c11", "-D_POSIX_C_SOURCE=200809L", "-Wall", "-Wextra", "-Werror", "-o"]).arg(output);
    for a in args {
        cmd.arg(src.join(a));
    }
    cmd.args(extra);
    run(&mut cmd);
}

/// Largest |a − b| over the f64 cells of two traces in the harness's format, and the number of
/// cells that differ at all (integers compared as numbers).
fn difference(a: &str, b: &str) -> (f64, usize, usize) {
    let (mut worst, mut differ, mut cells) = (0.0f64, 0, 0);
    assert_eq!(a.lines().count(), b.lines().count(), "the runs have different lengths");
    for (la, lb) in a.lines().zip(b.lines()) {
        for (x, y) in la.split(' ').zip(lb.split(' ')) {
            cells += 1;
            if x == y {
                continue;
            }
            differ += 1;
            let v = |t: &str| {
                if t.len() == 16 {
                    f64::from_bits(u64::from_str_radix(t, 16).unwrap())
                } else {
                    t.parse::<f64>().unwrap()
                }
            };
            worst = worst.max((v(x) - v(y)).abs());
        }
    }
    (worst, differ, cells)
}

#[test]
fn shipped_scenarios_give_the_same_bits_natively_under_wine_and_under_qemu() {
    let dir = work_dir("scenarios");
    let libs = extract_binaries(&dir);
    let fmu = load_fmu();

    // Schedules and the Rust host's traces of the same archive.
    let (mut sched, mut host) = (String::new(), String::new());
    let scenarios = shipped_scenarios();
    assert!(scenarios.len() >= 7, "scenarios found: {}", scenarios.len());
    for (_, s) in &scenarios {
        schedule(&fmu, s, &mut sched);
        trace_as_text(&fmu, s, &fmu.run(s, |_| {}).unwrap(), &mut host);
    }
    let sched_path = dir.join("schedule.txt");
    std::fs::write(&sched_path, &sched).unwrap();

    // The harness for each platform; the Windows one next to its DLL and the Wine-only shim.
    let windows = libs[1].parent().unwrap();
    compile("gcc", &["harness.c"], &dir.join("harness"), &["-ldl"]);
    compile("aarch64-linux-gnu-gcc", &["harness.c"], &dir.join("harness-aarch64"), &["-ldl"]);
    compile("x86_64-w64-mingw32-gcc", &["harness.c"], &windows.join("harness.exe"), &["-static"]);
    compile(
        "x86_64-w64-mingw32-gcc",
        &["bcryptprimitives_shim.c"],
        &windows.join("bcryptprimitives.dll"),
        &["-shared", "-ladvapi32"],
    );

    let wine =
        ["/usr/lib/wine/wine64", "/usr/bin/wine64"].into_iter().find(|p| Path::new(p).exists()).unwrap_or("wine64");
    let prefix = work_dir("wine-prefix");
    let mut runs: Vec<(&str, Command)> = Vec::new();
    let mut native = Command::new(dir.join("harness"));
    native.arg(&libs[0]);
    runs.push(("x86_64-linux (native)", native));
    let mut under_wine = Command::new(wine);
    under_wine
        .current_dir(windows)
        .args(["harness.exe", "servo_axis.dll"])
        .env("WINEPREFIX", &prefix)
        .env("WINEDEBUG", "-all")
        .env("WINEDLLOVERRIDES", "bcryptprimitives=n,b");
    runs.push(("x86_64-windows (Wine)", under_wine));
    let mut under_qemu = Command::new("qemu-aarch64-static");
    under_qemu.args(["-L", "/usr/aarch64-linux-gnu"]).arg(dir.join("harness-aarch64")).arg(&libs[2]);
    runs.push(("aarch64-linux (qemu-user)", under_qemu));

    let steps: usize = scenarios.iter().map(|(_, s)| s.steps() + 1).sum();
    eprintln!("{} scenarios, {steps} recorded steps per platform", scenarios.len());
    let mut outputs = Vec::new();
    for (name, mut cmd) in runs {
        // Wine's first start in a new prefix sets the prefix up: not part of the run's time.
        if name.contains("Wine") && !prefix.join("system.reg").exists() {
            let mut boot = Command::new(wine);
            boot.arg("wineboot").env("WINEPREFIX", &prefix).env("WINEDEBUG", "-all");
            run(&mut boot);
        }
        cmd.stdin(Stdio::from(std::fs::File::open(&sched_path).unwrap()));
        let start = Instant::now();
        let text = run(&mut cmd);
        eprintln!("harness run time {name}: {:.2} s", start.elapsed().as_secs_f64());
        std::fs::write(dir.join(format!("{}.txt", name.split(' ').next().unwrap())), &text).unwrap();
        outputs.push((name, text));
    }

    let (worst, differ, cells) = difference(&host, &outputs[0].1);
    assert!(
        differ == 0,
        "the native harness differs from the Rust host in {differ} of {cells} values (largest {worst:e})"
    );
    let mut failures = Vec::new();
    let (mut differing, mut compared) = (0, 0);
    for (name, text) in &outputs[1..] {
        let (worst, differ, cells) = difference(&outputs[0].1, text);
        eprintln!("{name} against x86_64-linux: max difference {worst:e}, {differ} of {cells} values differ");
        (differing, compared) = (differing + differ, compared + cells);
        if differ != 0 {
            failures
                .push(format!("{name} differs from x86_64-linux in {differ} of {cells} values (largest {worst:e})"));
        }
    }
    // The figure for the book's figures page (`servo figures` renders out/bench/platforms.json,
    // at the workspace's root: a test runs in its package's folder).
    host_tools::bench::figures::Recorder::new("platforms")
        .command("cargo test --release -p cross-checks --test platforms -- --nocapture")
        .equal(
            "output differences between x86_64 Linux, Windows (Wine) and aarch64 (qemu), shipped scenarios",
            differing as f64,
            0.0,
            "",
        )
        .info("values compared", compared as f64, "")
        .write(Some(&host_tools::paths::workspace_root().join("out/bench")), failures.is_empty())
        .unwrap();
    assert!(failures.is_empty(), "{}", failures.join("; "));
}

/// Both archives carry the licence texts where FMI 3.0 puts them (`documentation/licenses/`),
/// byte for byte the repository's.
#[test]
fn both_archives_carry_the_licence_texts() {
    let fmi3 = fmu_path();
    let fmi2 = fmi3.with_file_name("servo_axis_fmi2.fmu");
    for licence in ["LICENSE-MIT", "LICENSE-APACHE"] {
        let text = std::fs::read(host_tools::paths::workspace_root().join(licence)).unwrap();
        for archive in [&fmi3, &fmi2] {
            assert!(
                entry(archive, &format!("documentation/licenses/{licence}.txt")) == text,
                "{licence} in {}",
                archive.display()
            );
        }
    }
}
