//! The `servo` binary as a user runs it: exit codes, outputs, error messages.

mod common;

use common::{servo, tmp, OnTheFmu};
use host_tools::paths::{default_fmu as fmu_path, workspace_root};

#[test]
fn run_writes_csv_plot_json_and_report() {
    let out = tmp("run");
    let scenario = workspace_root().join("scenarios/position_step.toml");
    let o = servo().arg("run").arg(&scenario).on_fmu(&out).arg("--json").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary[0]["passed"], true);
    for f in ["position_step.csv", "position_step.svg", "position_step.json", "index.html"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

#[test]
fn a_failing_check_gives_exit_status_1() {
    let out = tmp("fail");
    let s = out.join("strict.toml");
    std::fs::write(
        &s,
        "name='strict'\nstop_time=0.01\n[[events]]\ntime=0.0\nmode=1\nvelocity_command=10.0\n[[checks]]\nsignal='motor_velocity'\nat=0.01\nmin=1000.0\n",
    )
    .unwrap();
    let o = servo().arg("run").arg(&s).on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stdout));
}

#[test]
fn bad_input_gets_a_clear_error() {
    let out = tmp("bad");
    let s = out.join("bad.toml");
    std::fs::write(&s, "name='bad'\nstop_time=0.01\n[parameters]\n\"ctrl.velocity_kp\" = -1.0\n").unwrap();
    let o = servo().arg("run").arg(&s).on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(err.contains("ctrl.velocity_kp") && err.contains("outside its range"), "stderr: {err}");

    std::fs::write(&s, "name='bad'\nstop_time=0.01\n[[events]]\ntime=0.0\nnot_an_input=1.0\n").unwrap();
    let o = servo().arg("run").arg(&s).on_fmu(&out).output().unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("not_an_input"));

    let o = servo().arg("run").arg(&s).arg("--fmu").arg("/nonexistent.fmu").output().unwrap();
    assert!(String::from_utf8_lossy(&o.stderr).contains("xtask -- bundle"));

    // The FMI 2.0 archive of the same model: named as such, not a schema error.
    let fmi2 = fmu_path().with_file_name("servo_axis_fmi2.fmu");
    let o = servo().arg("run").arg(&s).arg("--fmu").arg(&fmi2).arg("--out").arg(&out).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("it is an FMI 2.0 FMU") && err.contains("run FMI 3.0 FMUs"), "{err}");
}

#[test]
fn accdec_prints_the_seed_design_and_writes_its_files() {
    let out = tmp("accdec");
    let o = servo()
        .args(["accdec", "--cutoff", "1000", "--order", "3", "--sample-period", "0.0005", "--no-sweep", "--json"])
        .on_fmu(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let den = r["design"]["denominator"].as_array().unwrap();
    assert!((den[1].as_f64().unwrap() - 0.33626).abs() < 5e-6, "{den:?}");
    assert_eq!(r["butterworth"]["shape"]["pulse_balance"], 0);
    assert_eq!(r["moving_average"]["shape"]["pulse_balance"], 0);
    assert_eq!(r["vibration"].as_array().unwrap().len(), 4, "two filters on two resonances");
    for f in
        ["profiles.svg", "profile_butterworth.csv", "profile_moving_average.csv", "vibration_20hz.svg", "accdec.json"]
    {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

/// The cut-off sweep, as the demo runs it (the test above skips it): its table carries each
/// resonance's residual vibration for both filters, every row as wide as the header.
#[test]
fn accdec_sweeps_the_cut_off_and_writes_the_residuals_of_each_resonance() {
    let out = tmp("accdec_sweep");
    let o = servo().args(["accdec", "--json"]).on_fmu(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    let mut lines = csv.lines();
    let header: Vec<&str> = lines.next().unwrap().split(',').collect();
    for name in ["butterworth_residual_20hz", "moving_average_residual_20hz", "butterworth_residual_60hz"] {
        assert!(header.contains(&name), "{name} missing from {header:?}");
    }
    let rows: Vec<&str> = lines.collect();
    assert!(rows.len() >= 5, "{} cut-offs swept", rows.len());
    for row in rows {
        assert_eq!(row.split(',').count(), header.len(), "{row}");
    }
    assert!(out.join("sweep.svg").exists());
}

#[test]
fn accdec_refuses_bad_designs_with_the_reason() {
    for (args, reason) in [
        (vec!["--order", "7"], "order 7"),
        (vec!["--order", "0"], "order 0"),
        (vec!["--cutoff", "2500"], "Nyquist"),
        (vec!["--cutoff", "NaN"], "cut-off"),
        (vec!["--ma-lengths", "16,0,16"], "length 0"),
        (vec!["--speed=-1"], "--speed"),
    ] {
        let o = servo()
            .arg("accdec")
            .args(&args)
            .args(["--no-fmu", "--no-sweep"])
            .arg("--out")
            .arg(tmp("accdec-bad"))
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(reason), "{args:?}: {err}");
    }
}

/// A Butterworth slower than any cascade of moving averages the drive holds is not compared
/// "at equal delay": the closest cascade is, reported as not at equal delay with the limit;
/// so are --ma-lengths of another delay.
#[test]
fn accdec_never_calls_a_comparison_equal_delay_that_is_not() {
    let out = tmp("accdec-delay");
    let run = |extra: &[&str]| {
        servo()
            .args(["accdec", "--order", "2", "--cutoff", "1", "--no-sweep", "--no-fmu"])
            .args(extra)
            .on_fmu(&out)
            .output()
            .unwrap()
    };
    for extra in [&[][..], &["--ma-lengths", "100,100,100"][..]] {
        let o = run(extra);
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(o.status.success(), "{extra:?}: {}", String::from_utf8_lossy(&o.stderr));
        assert!(text.contains("comparison NOT at equal delay") && !text.contains("at equal 99 %"), "{extra:?}: {text}");
        let o = run(&[extra, &["--json"]].concat());
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!(r["equal_delay"], false, "{extra:?}: {r}");
    }
    let text = String::from_utf8_lossy(&run(&[]).stdout).into_owned();
    assert!(text.contains("512 ticks") && text.contains("512/512/512"), "{text}");
    // The automatic sweep leaves such cut-offs out, naming them.
    let o = servo().args(["accdec", "--order", "2", "--cutoff", "4", "--no-fmu"]).on_fmu(&out).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success() && text.contains("left out 1 Hz") && text.contains("comparison at equal 99 % delay"),
        "{text}"
    );
}

/// The documented corners: the lowest cut-off runs with its automatic sweep (kept inside the
/// design's range), and a sample period the FMU's position loop cannot run at is refused
/// naming --sample-period and its range.
#[test]
fn accdec_runs_its_documented_range_and_names_a_bad_sample_period() {
    let out = tmp("accdec-range");
    let o = servo()
        .args(["accdec", "--order", "6", "--cutoff", "0.5", "--no-fmu", "--json"])
        .on_fmu(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let swept: Vec<f64> = r["sweep"].as_array().unwrap().iter().map(|p| p["cutoff_hz"].as_f64().unwrap()).collect();
    let left_out = r["sweep_left_out"].as_array().unwrap();
    assert!(swept.iter().all(|&c| c >= 0.5), "{swept:?}");
    assert_eq!(swept.len() + left_out.len(), 3, "0.5, 1 and 2 Hz: {r}");
    for (t, named) in
        [("0", "positive"), ("0.0000625", "125.0 µs"), ("0.0001875", "whole multiple"), ("0.07", "62.5 ms")]
    {
        let o = servo().args(["accdec", "--no-sweep", "--sample-period", t]).on_fmu(&out).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{t}: {err}");
        assert!(err.contains("--sample-period") && err.contains(named), "{t}: {err}");
    }
}

#[test]
fn sequence_reports_failed_expectations_and_refuses_malformed_timelines() {
    let out = tmp("sequence");
    let strict = out.join("strict.toml");
    std::fs::write(
        &strict,
        "name='strict'\nstop_time=0.2\n[[events]]\ntime=0.0\nevent='run'\n[[expect]]\nstate='servo_lock'\nat=0.1\n",
    )
    .unwrap();
    let o = servo().arg("sequence").arg(&strict).on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stdout));
    assert!(String::from_utf8_lossy(&o.stdout).contains("[FAIL] state servo_lock"));
    assert!(out.join("strict.svg").exists() && out.join("strict.csv").exists() && out.join("strict.json").exists());
    let bad = out.join("bad.toml");
    std::fs::write(&bad, "name='bad'\nstop_time=0.2\n[[events]]\ntime=0.0\nevent='move'\n").unwrap();
    let o = servo().arg("sequence").arg(&bad).on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("needs `target`"));
}

#[test]
fn circle_refuses_what_cannot_make_a_circle_test() {
    for (args, reason) in [
        (vec!["--radius", "0"], "radius must be a positive"),
        (vec!["--radius", "0.001", "--feed", "10"], "at least 8"),
        (vec!["--feed", "6.0"], "whole number of"),
        (vec!["--single", "x", "--feed", "2513.2741228718346"], "multiple of 4"),
        (vec!["--set", "plant.load_coulomb"], "NAME=VALUE"),
        // Over a drive: refused before any port is opened.
        (vec!["--device", "/dev/no-such-port"], "add --single x"),
        (vec!["--single", "x", "--device", "/dev/no-such-port", "--measure", "load"], "no machine-end position sensor"),
        (vec!["--single", "x", "--device", "/dev/no-such-port", "--compare", "ctrl.kp=1"], "are for the FMU"),
    ] {
        let o = servo().arg("circle").args(&args).on_fmu(tmp("circle-bad")).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(reason), "{args:?}: {err}");
    }
}

#[test]
fn circle_writes_plot_points_and_figures() {
    let out = tmp("circle");
    let o = servo()
        .args(["circle", "--json", "--compare", "ctrl.friction_comp_amplitude=0.06"])
        .on_fmu(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["circle"]["runs"].as_array().unwrap().len(), 2);
    assert_eq!(r["circle"]["runs"][0]["feedback"]["protrusions"].as_array().unwrap().len(), 4);
    for f in ["circle.svg", "circle.csv", "circle_compare.csv", "circle.json"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

/// A folder that does not exist yet, for a command that must write nothing.
fn untouched(name: &str) -> std::path::PathBuf {
    let out = tmp(name).join("out");
    let _ = std::fs::remove_dir_all(&out);
    out
}

#[test]
fn circle_refuses_runs_too_long_to_hold_up_front_naming_the_option_and_the_limit() {
    for (args, named) in [
        (vec!["--radius", "1e6"], "--radius 1000000 rad"),
        (vec!["--radius", "1e12"], "--radius 1000000000000 rad"),
        (vec!["--lead-in", "100000"], "--lead-in 100000"),
        (vec!["--lead-in", "125"], "--lead-in 125"),
        (vec!["--single", "x", "--lead-in", "125"], "--lead-in 125"),
    ] {
        let out = untouched("circle-too-long");
        let o = servo().arg("circle").args(&args).on_fmu(&out).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        let limit = err.contains("at most 500000 samples") || err.contains("limit of 500000");
        assert!(err.contains(named) && limit, "{args:?}: {err}");
        assert!(!out.exists(), "{args:?}: wrote {}", out.display());
    }
}

#[test]
fn circle_checks_every_parameter_of_both_runs_before_running_any() {
    for (args, named) in [
        (vec!["--compare", "ctrl.friction_comp_amplitude=-1"], "ctrl.friction_comp_amplitude = -1 N.m is outside"),
        (vec!["--y-set", "ctrl.kp=-3"], "axis y"),
        (vec!["--set", "position_command=1"], "not a parameter"),
        (vec!["--compare", "ctrl.no_such_gain=1"], "no variable `ctrl.no_such_gain`"),
    ] {
        let out = untouched("circle-bad-parameters");
        let o = servo().arg("circle").args(&args).on_fmu(&out).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(named), "{args:?}: {err}");
        assert!(!out.exists(), "{args:?}: wrote {}", out.display());
    }
}

/// Rows `rows` of a trace CSV's column `name`.
fn csv_column(path: &std::path::Path, name: &str, rows: std::ops::Range<usize>) -> Vec<f64> {
    let t = host_tools::fmu::trace::Trace::read_csv(path).unwrap();
    t.column(name).unwrap()[rows].to_vec()
}

#[test]
fn circle_fails_when_a_drive_trips_naming_the_fault_and_when() {
    // 20 revolutions per second on 1 rad: the axes cannot follow, and trip on their following
    // error (a limit of 1 rad, half the default, on both axes).
    let out = tmp("circle-trip");
    let args = ["circle", "--radius", "1", "--feed", "125.66370614359172", "--set", "ctrl.following_error_limit=1"];
    let o = servo().args(args).arg("--json").on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let c = &r["circle"];
    assert_eq!(c["passed"], false, "{c}");
    assert!(c["runs"][0]["feedback"].is_null(), "figures of a tripped run: {c}");
    // The trip as the traces show it: the first row with a fault latched, its time.
    for (i, axis) in ["x", "y"].iter().enumerate() {
        let trace = out.join(format!("circle_{axis}_trace.csv"));
        let (faults, time) = (csv_column(&trace, "faults", 0..401), csv_column(&trace, "time", 0..401));
        let first = faults.iter().position(|&f| f != 0.0).expect("tripped");
        let trip = &c["runs"][0]["axes"][i]["trip"];
        assert_eq!(trip["time_s"].as_f64(), Some(time[first]), "{trip}");
        assert_eq!(trip["bits"].as_f64(), Some(faults[first]), "{trip}");
        let said = c["failures"][i].as_str().unwrap();
        assert!(said.contains(&format!("axis {axis} tripped at t = {:.4} s", time[first])), "{said}");
        assert!(said.contains("following error"), "{said}");
    }
    let o = servo().args(args).on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(text.contains("FAILED: axis x tripped") && text.contains("no figures"), "{text}");
    assert!(["-inf", "inf,", "NaN"].iter().all(|bad| !text.contains(bad)), "{text}");
}

#[test]
fn circle_warns_when_the_torque_command_sits_at_its_limit_with_its_share() {
    // 10 revolutions per second: the start from rest at full feed takes the full 2 N·m on X,
    // the measured revolution none. With 0.05 N·m of torque at 1 revolution per second, the
    // measured revolution reaches the limit too.
    for (args, limit, in_measured) in
        [(vec!["--feed", "62.83185307179586"], 2.0, false), (vec!["--set", "ctrl.torque_limit=0.05"], 0.05, true)]
    {
        let out = tmp("circle-torque-limited");
        let o = servo().arg("circle").args(&args).arg("--json").on_fmu(&out).output().unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let c = &r["circle"];
        let n = c["samples_per_revolution"].as_u64().unwrap() as usize;
        let x = &c["runs"][0]["axes"][0];
        assert_eq!(x["torque_limit_nm"].as_f64(), Some(limit), "{x}");
        // The counts as the trace has them: |torque command| at the limit (f32), over the run
        // (rows 1..=2n: one lead-in revolution) and over the measured revolution.
        let torque = csv_column(&out.join("circle_x_trace.csv"), "torque_command_out", 0..2 * n + 1);
        let at_limit = |rows: std::ops::Range<usize>| rows.filter(|&k| torque[k].abs() >= limit as f32 as f64).count();
        let (run, measured) = (at_limit(1..2 * n + 1), at_limit(n + 1..2 * n + 1));
        assert!(run > 0 && (measured > 0) == in_measured, "{args:?}: {run} {measured}");
        assert_eq!(x["torque_limited_run"]["limited"].as_u64(), Some(run as u64), "{x}");
        assert_eq!(x["torque_limited_measured"]["limited"].as_u64(), Some(measured as u64), "{x}");
        let share = x["torque_limited_run"]["share"].as_f64().unwrap();
        assert!((share - run as f64 / (2 * n) as f64).abs() < 1e-12, "{x}");
        let warning = c["warnings"][0].as_str().unwrap();
        assert!(warning.contains(&format!("axis x's torque command sat at its {limit} N·m limit")), "{warning}");
        assert_eq!(warning.contains("not the linear loop's"), in_measured, "{warning}");
        let o = servo().arg("circle").args(&args).on_fmu(&out).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        assert!(text.contains(&format!("WARNING: {warning}")), "{text}");
    }
}

/// A `servo tune` output directory with these axes (FMU parameters, correction sections).
fn tuned_dir(name: &str, x: serde_json::Value, y: serde_json::Value) -> std::path::PathBuf {
    let dir = tmp(name);
    let json = serde_json::json!({"axes": [x, y]});
    std::fs::write(dir.join("tune.json"), serde_json::to_string(&json).unwrap()).unwrap();
    dir
}

#[test]
fn circle_tuned_says_how_many_times_rounder_and_fails_when_the_correction_makes_it_worse() {
    // A 5 Hz low-pass pole pair lags an axis 16° at 1 Hz. Lagging X alone draws an ellipse;
    // lagging both draws a circle again.
    let lag = serde_json::json!([{"zeros": null, "pole_hz": 5.0, "pole_damping": 0.7}]);
    let lagged = serde_json::json!({"corr.count": 1, "corr.pole_hz_1": 5.0, "corr.pole_damping_1": 0.7});
    let axis = |name: &str, fmu: &serde_json::Value, sections: &serde_json::Value| serde_json::json!({"axis": name, "fmu_parameters": fmu, "correction": {"axis": name, "sections": sections}});
    let none = serde_json::json!({});
    let worse = tuned_dir("tuned-worse", axis("x", &none, &lag), axis("y", &none, &serde_json::json!([])));
    let better = tuned_dir("tuned-better", axis("x", &lagged, &lag), axis("y", &none, &lag));
    for (dir, rounder) in [(worse, false), (better, true)] {
        let out = tmp("circle-tuned");
        let o = servo().arg("circle").arg("--json").arg("--tuned").arg(&dir).on_fmu(&out).output().unwrap();
        assert_eq!(o.status.code(), Some(if rounder { 0 } else { 1 }), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let c = &r["circle"];
        let roundness = |i: usize| c["runs"][i]["feedback"]["roundness"].as_f64().unwrap();
        let ratio = roundness(1) / roundness(0);
        // serde_json's default parser may read a printed float one unit in the last place off.
        let reported = c["roundness_ratio"].as_f64().unwrap();
        assert!((reported / ratio - 1.0).abs() < 1e-12, "{reported} vs {ratio}: {c}");
        assert_eq!(c["improved"], rounder, "{c}");
        assert!(if rounder { ratio < 0.1 } else { ratio > 10.0 }, "{c}");
        let o = servo().arg("circle").arg("--tuned").arg(&dir).on_fmu(&out).output().unwrap();
        let text = String::from_utf8_lossy(&o.stdout);
        let words = if rounder { format!("{:.2}× smaller", 1.0 / ratio) } else { format!("{ratio:.2}× larger") };
        assert!(text.contains(&format!("roundness, second run / first: {ratio:.4} ({words})")), "{text}");
        assert_eq!(text.contains("FAILED: the correction does NOT make the circle rounder"), !rounder, "{text}");
    }
}

#[test]
fn sweep_refuses_bad_settings_with_the_reason() {
    for (args, reason) in [
        (vec!["--point", "current"], "--point must be"),
        (vec!["--stop", "5000"], "Nyquist"),
        (vec!["--acquisition-divider", "3"], "multiple of the velocity"),
        (vec!["--start", "100", "--stop", "50"], "stop_hz"),
        (vec!["--amplitude=-1"], "amplitude"),
        // A negative number reaches its check (clap took it for an unknown option before).
        (vec!["--start", "-5"], "sweep start_hz = -5 is out of range"),
        (vec!["--acquisition-divider", "8"], "once per communication step"),
        // A torque-command sine whose peak reaches the torque limit (2 N·m) would be cut.
        (vec!["--point", "torque", "--amplitude", "2"], "sweep amplitude = 2 is outside [0, 1.997"),
        // Beyond the largest speed set-point the loop takes.
        (vec!["--amplitude", "1e6"], "sweep amplitude = 1000000 is outside [0, 100000]"),
        // The command's options set the sweep: a --set sweep.… would be overwritten silently.
        (
            vec!["--set", "sweep.start_hz=100"],
            "--set sweep.start_hz: the sweep's settings come from this command's options",
        ),
        (vec!["--points", "128"], "sweep points = 128: at most 127"),
        // Two cycles and no shortest measurement: three samples at 3 kHz.
        (vec!["--min-measure", "0"], "a record at 3000 Hz would hold 3 acquisition samples"),
        (vec!["--device", "/dev/no-such-port", "--baud", "0"], "a baud rate is a whole number from 1 200"),
        (vec!["--reference", "/nonexistent/reference.csv"], "/nonexistent/reference.csv"),
    ] {
        let o = servo().arg("sweep").args(&args).on_fmu(tmp("sweep-bad")).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(reason), "{args:?}: {err}");
    }
}

/// A reference curve must be one: rows, positive frequencies, finite values (a negative
/// frequency once put NaN into the Bode plot with exit status 0).
#[test]
fn sweep_refuses_a_reference_that_is_not_a_curve() {
    let dir = tmp("sweep-reference");
    let reference = dir.join("reference.csv");
    for (text, reason) in [
        ("frequency,gain_db,phase_deg\n", "the reference has no rows"),
        ("frequency,gain_db,phase_deg\n10,0,0\n-5,1,1\n", "line 3: frequency -5 is not a positive number"),
        ("frequency,gain_db,phase_deg\n10,NaN,0\n", "line 2: gain_db NaN and phase_deg 0 must be finite"),
        ("frequency,gain\n10,0\n", "needs the columns frequency, gain_db, phase_deg"),
    ] {
        std::fs::write(&reference, text).unwrap();
        let o = servo().args(["sweep", "--points", "2", "--reference"]).arg(&reference).on_fmu(&dir).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{text}: {err}");
        assert!(err.contains(reason), "{text}: {err}");
    }
}

/// What a sweep on the FMU cannot measure makes it fail with the reason, never a NaN or a
/// -inf presented as a result with exit status 0: a drive that faults (its bridge off from
/// there on), a frequency a single unshifted record sees at one phase and its opposite only.
#[test]
fn sweep_fails_with_the_reason_where_it_measured_nothing() {
    let out = tmp("sweep-nothing");
    let sweep = |args: &[&str]| {
        let o = servo()
            .args(["sweep", "--json", "--start", "1000", "--stop", "3000", "--points", "2"])
            .args(args)
            .on_fmu(&out)
            .output()
            .unwrap();
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (o.status.code(), r)
    };
    // An overcurrent trip level under the current limit: the drive latches at once.
    let (code, r) = sweep(&["--set", "ctrl.overcurrent=3", "--set", "ctrl.max_current=2.9"]);
    assert_eq!(code, Some(1), "{r}");
    assert_eq!(r["fault"]["faults"], "overcurrent", "{r}");
    let text = servo()
        .args(["sweep", "--start", "1000", "--stop", "3000", "--points", "2"])
        .args(["--set", "ctrl.overcurrent=3", "--set", "ctrl.max_current=2.9"])
        .on_fmu(&out)
        .output()
        .unwrap();
    assert!(String::from_utf8_lossy(&text.stdout).contains("FAILED: the drive latched a fault"));
    // One record at 2 kHz, half the 4 kHz acquisition rate: phases 0 and π only.
    let (code, r) = sweep(&["--repeats", "1", "--shifts", "1"]);
    assert_eq!(code, Some(1), "{r}");
    assert_eq!(r["unmeasured_hz"], serde_json::json!([2000.0]), "{r}");
    assert_eq!(r["fault"], serde_json::Value::Null);
    // The same with phase shifting (the default) measures every frequency.
    let (code, r) = sweep(&[]);
    assert_eq!(code, Some(0), "{r}");
    assert_eq!(r["unmeasured_hz"], serde_json::json!([]), "{r}");
}

/// At a 32 kHz loop the communication step follows the rate (one acquisition sample per
/// step): the host's estimate from the stream keeps every sample and agrees with the drive's.
/// With the 250 µs step of 16 kHz it kept every other one: 2 kHz had only two phases (no
/// result) and 3 kHz was 0.14 dB off the drive's own result. And the top is dithered although
/// it lies below that loop's 4 kHz threshold: undithered, 3 kHz was 0.28 dB off the oracle.
#[test]
fn sweep_streams_every_sample_at_another_loop_rate() {
    let out = tmp("sweep-32k");
    let o = servo()
        .args(["sweep", "--json", "--oracle", "--start", "1000", "--stop", "3000", "--points", "3"])
        .args(["--set", "ctrl.current_loop_hz=32000"])
        .on_fmu(&out)
        .output()
        .unwrap();
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(o.status.code(), Some(0), "{r}");
    assert!(r["stream_vs_online"][0].as_f64().unwrap() < 1e-3, "{r}");
    assert_eq!(r["stream"].as_array().unwrap().len(), 4, "{r}");
    let e = &r["errors_vs_oracle"];
    assert!(e["below_gain_db"].as_f64().unwrap() <= 0.1 && e["below_phase_deg"].as_f64().unwrap() <= 1.0, "{e}");
}

/// A velocity-command amplitude that pins the torque at the drive's limit: the results are
/// named (the drive's own flag is the voltage circle's only), and a small one names none.
#[test]
fn sweep_names_the_results_measured_at_the_torque_limit() {
    let out = tmp("sweep-torque-limit");
    let run = |amplitude: &str| {
        let o = servo()
            .args(["sweep", "--start", "10", "--stop", "100", "--points", "3", "--amplitude", amplitude])
            .on_fmu(&out)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("sweep.json")).unwrap()).unwrap();
        (String::from_utf8_lossy(&o.stdout).into_owned(), r)
    };
    let (text, r) = run("100");
    assert!(text.contains("WARNING: the torque command reached the drive's limit"), "{text}");
    assert!(!r["torque_limited_hz"].as_array().unwrap().is_empty(), "{r}");
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    assert!(csv.lines().next().unwrap().ends_with(",torque_limited_share"), "{csv}");
    let (text, r) = run("2");
    assert!(!text.contains("torque command reached"), "{text}");
    assert_eq!(r["torque_limited_hz"], serde_json::json!([]), "{r}");
}

/// Without --extra, 2 kHz joins a sweep only where it lies in the range.
#[test]
fn sweep_adds_the_default_extra_frequency_only_inside_its_range() {
    let out = tmp("sweep-extra");
    let points = |args: &[&str]| {
        let o = servo().args(["sweep", "--json", "--points", "3"]).args(args).on_fmu(&out).output().unwrap();
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        r["stream"].as_array().unwrap().iter().map(|p| p["frequency"].as_f64().unwrap()).collect::<Vec<_>>()
    };
    assert_eq!(points(&["--stop", "100"]).len(), 3);
    assert!(points(&["--start", "1000", "--stop", "3000"]).contains(&2000.0));
}

#[test]
fn sweep_writes_csv_bode_and_json() {
    let out = tmp("sweep");
    let o = servo()
        .args(["sweep", "--json", "--start", "100", "--stop", "3000", "--points", "6"])
        .on_fmu(&out)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["stream"].as_array().unwrap().len(), 7, "6 points and 2 kHz");
    for f in ["sweep.csv", "bode.svg", "sweep.json"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
}

/// Riding at 200 rad/s, the back-EMF leaves the 48 V bus too little voltage for 0.2 N·m at
/// the top of the sweep: the results measured while the voltage circle cut the output are
/// named in a warning, in the JSON and in the CSV's share column, and the low ones are not.
#[test]
fn sweep_names_the_results_measured_with_the_output_limited() {
    let out = tmp("sweep-limited");
    // A torque-command sweep of 100 Hz to 3 kHz (6 points and 2 kHz) with `args`: exit 0, stdout.
    let torque_sweep = |args: &[&str]| {
        let o = servo()
            .args(["sweep", "--point", "torque", "--start", "100", "--stop", "3000", "--points", "6"])
            .args(args)
            .on_fmu(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{args:?}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).into_owned()
    };
    let text = torque_sweep(&["--velocity", "200"]);
    assert!(text.contains("WARNING: the drive's output was limited"), "{text}");
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("sweep.json")).unwrap()).unwrap();
    let limited: Vec<f64> = r["limited_hz"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(limited.contains(&3000.0) && !limited.iter().any(|&f| f < 1000.0), "{limited:?}");
    let csv = std::fs::read_to_string(out.join("sweep.csv")).unwrap();
    assert!(csv.lines().next().unwrap().contains(",limited_share,"), "{csv}");
    // Every result's share, as the drive counted it on-line (`sweep_last_limited`, in the
    // JSON), is the share the host counts from the stream's per-sample flags (`acq_limited`)
    // over the samples the fit keeps: what a sweep over a drive's link relies on.
    let trace = host_tools::fmu::trace::Trace::read_csv(&out.join("sweep_trace.csv")).unwrap();
    let settings = control_core::phase_shifted_sweep::SweepParams {
        start_hz: 100.0,
        stop_hz: 3000.0,
        points: 6,
        ..Default::default()
    };
    let streamed = host_tools::sweep::measurement::stream_limited_shares(&trace, &settings).unwrap().unwrap();
    let online: Vec<f64> = r["limited_share"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    let online_hz: Vec<f64> =
        r["online"].as_array().unwrap().iter().map(|p| p["frequency"].as_f64().unwrap()).collect();
    assert_eq!(streamed.len(), online.len());
    for ((&(f, share), &drive), &drive_hz) in streamed.iter().zip(&online).zip(&online_hz) {
        assert!((f - drive_hz).abs() < 1e-3 * f, "{f} Hz vs {drive_hz} Hz");
        assert!((share - drive).abs() < 1e-6, "{f} Hz: stream share {share}, drive's {drive}");
    }
    assert!(streamed.iter().any(|&(_, share)| share > 0.0) && streamed.iter().any(|&(_, share)| share == 0.0));
    // At 50 rad/s and 0.1 N·m nothing is limited: no warning, nothing named. (The 3 kHz
    // result's standard error, a few counts of response, may be named: another warning.)
    let text = torque_sweep(&["--amplitude", "0.1"]);
    assert!(!text.contains("WARNING: the drive's output was limited"), "{text}");
    let r: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("sweep.json")).unwrap()).unwrap();
    assert!(r["limited_hz"].as_array().unwrap().is_empty(), "{r}");
}

#[test]
fn ident_writes_models_and_refuses_unusable_models() {
    let out = tmp("ident");
    let o = servo().args(["ident", "--anti-resonance", "x=40,y=70", "--json"]).on_fmu(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for f in ["x.model.json", "y.model.json", "x.measured.csv", "ident.svg"] {
        assert!(out.join(f).exists(), "{f} missing");
    }
    // An edited model re-plots; one with zeros in the right half plane is refused.
    let o = servo().arg("ident").arg("--model").arg(out.join("x.model.json")).arg("--out").arg(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = std::fs::read_to_string(out.join("y.model.json")).unwrap();
    let mut m: serde_json::Value = serde_json::from_str(&text).unwrap();
    m["anti_resonance"]["damping"] = serde_json::json!(-0.1);
    std::fs::write(out.join("y.model.json"), m.to_string()).unwrap();
    let o = servo().arg("ident").arg("--model").arg(out.join("y.model.json")).arg("--out").arg(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("right half plane"));
    let o = servo().args(["ident", "--anti-resonance", "q=40"]).on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("no axis `q`"));
}

#[test]
fn tune_writes_each_axis_correction_and_refuses_unusable_models() {
    let out = tmp("tune");
    let o = servo().args(["ident", "--anti-resonance", "x=40,y=70"]).on_fmu(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let (x, y) = (out.join("x.model.json"), out.join("y.model.json"));
    // The seed as written: x carries y's numerator (70 Hz) and y carries x's (40 Hz), each
    // over the same F.
    let o =
        servo().args(["tune", "--method", "zeros", "--json", "--model"]).arg(&x).arg(&y).on_fmu(&out).output().unwrap();
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let zero = |axis: usize| r["tuning"]["axes"][axis]["correction"]["sections"][0]["zeros"][0].as_f64().unwrap();
    assert!((zero(0) - 70.0).abs() < 1.0 && (zero(1) - 40.0).abs() < 1.0, "{r}");
    let text = std::fs::read_to_string(out.join("x.corr.toml")).unwrap();
    assert!(text.contains("\"corr.count\" = 2"), "{text}");
    // ...which does not bring these axes closer: reported, and the exit status says so.
    assert_eq!(r["improved"], false, "{r}");
    assert!(!o.status.success());

    // The default (measured models) does, and the circle of the tuned axes gets rounder.
    let o = servo().args(["tune", "--json", "--model"]).arg(&x).arg(&y).on_fmu(&out).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let (before, after) =
        (r["tuning"]["spread_before"][0].as_f64().unwrap(), r["tuning"]["spread_after"][0].as_f64().unwrap());
    assert!(after < before / 10.0, "{r}");
    let circle = tmp("tune-circle");
    let o = servo()
        .args(["circle", "--json", "--radius", "0.05", "--feed", "6.283185307179586", "--lead-in", "30", "--tuned"])
        .arg(&out)
        .on_fmu(&circle)
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let c: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(c["circle"]["roundness_ratio"].as_f64().unwrap() < 0.05, "{c}");

    let o =
        servo().args(["tune", "--method", "poles", "--model"]).arg(&x).arg(&y).arg("--out").arg(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("response or zeros"));
    let o = servo().args(["tune", "--no-check", "--model"]).arg(&x).arg("--out").arg(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&o.stderr).contains("at least two"));
}

/// One check of a model file for `ident --model` and `tune`: values no axis has are refused
/// with the field named, and axis names (which name the files written) cannot leave --out.
#[test]
fn ident_and_tune_refuse_impossible_models_and_unsafe_axis_names() {
    let out = tmp("model-check");
    let model = |axis: &str| {
        serde_json::json!({"axis": axis, "anti_resonance": {"hz": 40.0, "damping": 0.05},
            "resonance": {"hz": 51.4, "damping": 0.064}, "gain": 4003.0, "band": [12.0, 240.0], "fit_error": 0.001})
    };
    let y = out.join("y.model.json");
    std::fs::write(&y, model("y").to_string()).unwrap();
    let edited = out.join("edited.model.json");
    let tune_out = out.join("tune");
    for (field, value, named) in [
        ("/anti_resonance/hz", serde_json::json!(-5.0), "`anti_resonance.hz` = -5"),
        ("/anti_resonance/damping", serde_json::json!(-1.0), "`anti_resonance.damping` = -1"),
        ("/gain", serde_json::json!(0.0), "`gain` = 0"),
        ("/axis", serde_json::json!("../evil"), "letters, digits, _ and -"),
    ] {
        let mut m = model("x");
        *m.pointer_mut(field).unwrap() = value;
        std::fs::write(&edited, m.to_string()).unwrap();
        for command in [&["tune", "--method", "response"][..], &["ident"][..]] {
            let o = servo().args(command).arg("--model").arg(&edited).arg(&y).on_fmu(&tune_out).output().unwrap();
            let err = String::from_utf8_lossy(&o.stderr);
            assert_eq!(o.status.code(), Some(2), "{command:?} {field}: {err}");
            assert!(err.contains(named) && err.contains("edited.model.json"), "{command:?} {field}: {err}");
        }
    }
    assert!(!out.join("evil.corr.toml").exists() && !tune_out.exists(), "nothing written");
    let ident_out = out.join("ident");
    for (axes, reason) in [
        (&["--axes", "../zz"][..], "`../zz` is not allowed"),
        (&["--axes", ""][..], "`` is not allowed"),
        (&["--axes", "x,x"][..], "`x` is given twice"),
        (&["--axes", "x", "--anti-resonance", "x=40,x=70"][..], "already has an anti-resonance"),
    ] {
        let o = servo().arg("ident").args(axes).on_fmu(&ident_out).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{axes:?}: {err}");
        assert!(err.contains(reason), "{axes:?}: {err}");
    }
    assert!(!out.join("zz.model.json").exists() && !ident_out.exists(), "nothing written");
}

/// `--anti-resonance` takes what the identification finds: both ends of the range are found
/// within 1 %, values outside it are refused with the range; a rigid axis's report names the
/// band the notch search looked in.
#[test]
fn ident_finds_anti_resonances_over_its_range_and_refuses_others() {
    let out = tmp("ident-range");
    for hz in [10.0, 450.0] {
        let o = servo()
            .args(["ident", "--axes", "x", "--json", "--anti-resonance"])
            .arg(format!("x={hz}"))
            .on_fmu(&out)
            .output()
            .unwrap();
        assert!(o.status.success(), "{hz}: {}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let found = r["axes"][0]["model"]["anti_resonance"]["hz"].as_f64().unwrap_or(f64::NAN);
        assert!((found / hz - 1.0).abs() < 0.01, "{hz} Hz: found {found}");
    }
    for hz in ["8", "9.9", "480", "1500"] {
        let o = servo()
            .args(["ident", "--axes", "x", "--anti-resonance"])
            .arg(format!("x={hz}"))
            .on_fmu(&out)
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{hz}: {err}");
        assert!(err.contains("from 10 to 450 Hz"), "{hz}: {err}");
    }
    let o = servo().args(["ident", "--axes", "x"]).on_fmu(&out).output().unwrap();
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(o.status.success() && text.contains("the band searched"), "{text}");
    let band = text.split("no clear anti-resonance between ").nth(1).unwrap_or_default();
    let hz: Vec<f64> =
        band.split(" Hz").next().unwrap_or_default().split(" and ").filter_map(|x| x.parse().ok()).collect();
    assert!(hz.len() == 2 && hz[0] < 10.0 && hz[1] > 400.0, "{text}");
}

#[test]
fn device_refuses_what_it_cannot_send_before_touching_a_port() {
    let err = |args: &[&str]| {
        let o = servo().args(["device", "--port", "/nonexistent/tty"]).args(args).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{args:?}");
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    assert!(err(&["load-correction"]).contains("corr.frame"));
    assert!(err(&["stream", "--seconds=-1"]).contains("between 0 and 3600"));
    assert!(err(&["reboot"]).contains("unknown action"));
    let not_a_frame = tmp("device").join("x.corr.toml");
    std::fs::create_dir_all(not_a_frame.parent().unwrap()).unwrap();
    std::fs::write(&not_a_frame, "\"corr.count\" = 2\n").unwrap();
    assert!(err(&["load-correction", not_a_frame.to_str().unwrap()]).contains("not a frame"));
    // A valid request, but no drive there: the port is named in the error.
    assert!(err(&["hello"]).contains("/nonexistent/tty"));
}

#[test]
fn index_gathers_the_experiments_into_one_page() {
    let root = tmp("index");
    let empty = servo().arg("index").arg("--out").arg(&root).output().unwrap();
    assert_eq!(empty.status.code(), Some(2), "an empty folder has nothing to gather");
    assert!(String::from_utf8_lossy(&empty.stderr).contains("no experiment results"));
    let passing = workspace_root().join("scenarios/position_step.toml");
    let o = servo().arg("run").arg(&passing).on_fmu(root.join("run")).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let o = servo().arg("index").arg("--out").arg(&root).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let page = std::fs::read_to_string(root.join("index.html")).unwrap();
    assert!(page.contains("position_step: checks") && page.contains("src=\"run/position_step.svg\""), "{page}");
    // A failing scenario in the same folder: the page says so and the exit status is 1.
    let strict = root.join("strict.toml");
    std::fs::write(
        &strict,
        "name='strict'\nstop_time=0.01\n[[events]]\ntime=0.0\nmode=1\nvelocity_command=10.0\n[[checks]]\nsignal='motor_velocity'\nat=0.01\nmin=1000.0\n",
    )
    .unwrap();
    servo().arg("run").arg(&strict).on_fmu(root.join("run")).output().unwrap();
    let o = servo().arg("index").arg("--out").arg(&root).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    let page = std::fs::read_to_string(root.join("index.html")).unwrap();
    assert!(page.contains("1 of 2 checks"), "{page}");
}

/// A corrupt result file is named, counted as unreadable and gives exit status 1, never a
/// passing experiment; --json prints the summary.
#[test]
fn index_names_unreadable_results_and_prints_json() {
    let root = tmp("index-corrupt");
    std::fs::create_dir_all(root.join("sweep")).unwrap();
    std::fs::create_dir_all(root.join("run")).unwrap();
    std::fs::write(root.join("sweep/sweep.json"), "{bad").unwrap();
    std::fs::write(root.join("run/garbage.json"), "garbage").unwrap();
    let o = servo().arg("index").arg("--out").arg(&root).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(1), "{err}");
    assert!(err.contains("sweep/sweep.json") && err.contains("run/garbage.json"), "{err}");
    assert!(String::from_utf8_lossy(&o.stdout).contains("2 result file(s) that cannot be read"));
    let page = std::fs::read_to_string(root.join("index.html")).unwrap();
    assert!(page.contains("UNREADABLE sweep/sweep.json"), "{page}");
    let o = servo().arg("index").arg("--json").arg("--out").arg(&root).output().unwrap();
    assert_eq!(o.status.code(), Some(1));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(r["unreadable"].as_array().unwrap().len(), 2, "{r}");
    assert_eq!(r["failed_checks"], 0, "{r}");
    // A readable folder: the JSON summary counts its checks.
    std::fs::remove_dir_all(root.join("sweep")).unwrap();
    std::fs::remove_file(root.join("run/garbage.json")).unwrap();
    let passing = workspace_root().join("scenarios/position_step.toml");
    assert!(servo().arg("run").arg(&passing).on_fmu(root.join("run")).output().unwrap().status.success());
    let o = servo().arg("index").arg("--json").arg("--out").arg(&root).output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert!(r["checks"].as_u64().unwrap() >= 1 && r["unreadable"].as_array().unwrap().is_empty(), "{r}");
}

/// `servo bench sweep --random`: plants drawn in the ranges, the same for the same seed (the
/// JSON names them), run against their oracles; refused with a plant index or with
/// --interior, before any FMU runs.
#[test]
fn bench_sweep_runs_random_plants_named_by_their_seed() {
    let run = |seed: &str| {
        let o = servo()
            .args(["bench", "sweep", "--random", "2", "--plant-seed", seed, "--point", "velocity", "--noise", "0"])
            .arg("--json")
            .arg("--fmu")
            .arg(fmu_path())
            .output()
            .unwrap();
        assert!(matches!(o.status.code(), Some(0 | 1)), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        let rows = r["grid"].as_array().unwrap().clone();
        assert_eq!(rows.len(), 2, "{r}");
        for row in &rows {
            assert!(row["measurement_time_s"].as_f64().unwrap() > 1.0, "{row}");
            assert!(row["gain_db"].as_f64().unwrap().is_finite(), "{row}");
        }
        rows.iter().map(|row| row["plant"].as_str().unwrap().to_string()).collect::<Vec<_>>()
    };
    let (a, b, c) = (run("5"), run("5"), run("6"));
    assert_eq!(a, b, "a seed names a draw");
    assert_ne!(a, c);
    for bad in [&["--plant", "0"][..], &["--interior"][..]] {
        let o = servo().args(["bench", "sweep", "--random", "2"]).args(bad).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{bad:?}");
        assert!(String::from_utf8_lossy(&o.stderr).contains("--random"), "{bad:?}");
    }
}

/// `servo bench ident --absorber`/`--random`: the chosen anti-resonances alone, each checked
/// against the plant's truth (frequency and damping), the same draw for the same seed; an
/// anti-resonance outside the measured band or no seeds refused before any FMU runs.
#[test]
fn bench_ident_runs_chosen_and_random_anti_resonances() {
    let run = |args: &[&str]| {
        let o = servo()
            .args(["bench", "ident", "--seeds", "1", "--json", "--fmu"])
            .arg(fmu_path())
            .args(args)
            .output()
            .unwrap();
        assert!(matches!(o.status.code(), Some(0 | 1)), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        (o.status.code(), r)
    };
    let (code, r) = run(&["--absorber", "45.5"]);
    let grid = r["grid"].as_array().unwrap();
    assert_eq!((code, grid.len()), (Some(0), 1), "{r}");
    let truth = grid[0]["truth"]["hz"].as_f64().unwrap();
    let found = grid[0]["found"]["hz"].as_f64().unwrap();
    // The absorber's √(k/J) is 45.5 Hz; the load moves with it, so the zero lies a little off.
    assert!((truth - 45.5).abs() < 1.0 && (found - truth).abs() <= 0.01 * truth, "{truth} {found}");
    assert!(r.get("tunings").is_none(), "the grid alone: {r}");
    let hz = |r: &serde_json::Value| {
        r["grid"].as_array().unwrap().iter().map(|c| c["hz"].as_f64().unwrap()).collect::<Vec<_>>()
    };
    // The draw itself (ranges, a seed naming it) is `random_absorbers`' unit test.
    let (_, r) = run(&["--random", "2", "--plant-seed", "7"]);
    let a = hz(&r);
    assert_eq!((a.len(), r["plant_seed"].as_u64(), r["seeds"].as_u64()), (2, Some(7), Some(1)), "{r}");
    assert!(a.iter().all(|f| (15.0..=300.0).contains(f)), "{a:?}");
    // Refused before the FMU is loaded (the path given does not exist), naming the option.
    let refusals: [(&str, &[&str], &str); 12] = [
        ("sequence", &["--random", "2", "--gradient", "-5"], "--gradient -5"),
        ("sequence", &["--gradient", "500"], "--random"),
        ("ident", &["--damping", "0"], "--damping 0"),
        ("ident", &["--random", "2", "--damping", "NaN"], "--damping NaN"),
        ("ident", &["--absorber", "1000"], "--absorber 1000"),
        ("ident", &["--absorber", "NaN"], "--absorber NaN"),
        ("ident", &["--random", "2", "--seeds", "0"], "--seeds"),
        ("ident", &["--random", "0"], "--random"),
        ("ident", &["--random", "2", "--absorber", "40"], "--absorber"),
        ("ident", &["--plant-seed", "3"], "--random"),
        ("sequence", &["--random", "0"], "--random"),
        ("sequence", &["--random", "2", "--zero-speed", "1"], "--zero-speed"),
    ];
    for (bench, bad, named) in refusals {
        let o = servo().args(["bench", bench, "--fmu", "/nonexistent/axis.fmu"]).args(bad).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{bench} {bad:?}: {err}");
        assert!(err.contains(named) && !err.contains("nonexistent"), "{bench} {bad:?}: {err}");
    }
}

/// `servo bench accdec --random`: drawn moves through the drive's filter against the f64
/// filter, within a count and no pulse lost; the same draw for the same seed, another for
/// another.
#[test]
fn bench_accdec_runs_random_moves_named_by_their_seed() {
    let run = |seed: &str| {
        let o = servo().args(["bench", "accdec", "--random", "300", "--plant-seed", seed, "--json"]).output().unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
        assert_eq!((r["runs"].as_u64(), r["unbalanced_runs"].as_u64()), (Some(300), Some(0)), "{r}");
        let worst = r["worst"]["worst"].as_f64().unwrap();
        assert!(worst <= 1.0 && r["passed"] == true, "{r}");
        (r["ticks"].as_u64().unwrap(), worst)
    };
    let (a, b, c) = (run("5"), run("5"), run("6"));
    assert_eq!(a, b, "a seed names a draw");
    assert_ne!(a, c);
    for (bad, named) in
        [(&["--random", "0"][..], "--random"), (&["--random", "3", "--sequences", "5"][..], "--sequences")]
    {
        let o = servo().args(["bench", "accdec"]).args(bad).output().unwrap();
        assert_eq!(o.status.code(), Some(2), "{bad:?}");
        assert!(String::from_utf8_lossy(&o.stderr).contains(named), "{bad:?}");
    }
}

/// A stop time whose trace would not fit memory (4·10¹² steps here) is refused when the file
/// is loaded, naming stop_time and the limit: not an allocation failure (rc 134) after the
/// FMU started.
#[test]
fn run_and_sequence_refuse_a_stop_time_whose_trace_would_not_fit_memory() {
    let out = tmp("huge_stop_time");
    let scenario = out.join("huge.toml");
    std::fs::write(&scenario, "name='huge'\nstop_time=1e9\n[[events]]\ntime=0.0\nmode=1\n").unwrap();
    let timeline = out.join("huge_timeline.toml");
    std::fs::write(&timeline, "name='huge_timeline'\nstop_time=1e9\n[[events]]\ntime=0.0\nevent='run'\n").unwrap();
    for (command, file) in [("run", &scenario), ("sequence", &timeline)] {
        let o = servo().arg(command).arg(file).on_fmu(&out).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{command}: {err}");
        assert!(err.contains("stop_time = 1000000000 s") && err.contains("1 GiB"), "{command}: {err}");
        // The longest that fits at the default 0.25 ms with every output recorded (633.1 s
        // with today's outputs): from the trace's row size, not a copy of today's count.
        let columns = host_tools::fmu::trace_budget::fmu_output_count() + 1;
        let longest = ((1u64 << 30) as f64 / (8.0 * columns as f64) - 1.0).floor() * 0.25e-3;
        assert!(err.contains(&format!("at most stop_time = {longest:.6} s")), "{command}: {err}");
    }
    // A tiny step is the same explosion, refused the same way.
    std::fs::write(&scenario, "name='huge'\nstop_time=0.3\nstep=1e-12\n[[events]]\ntime=0.0\nmode=1\n").unwrap();
    let o = servo().arg("run").arg(&scenario).on_fmu(&out).output().unwrap();
    assert_eq!(o.status.code(), Some(2), "{}", String::from_utf8_lossy(&o.stderr));
    std::fs::remove_dir_all(&out).ok();
}

/// A check past the stop time is refused when the scenario is loaded, naming the check and
/// both times (it was judged on the last sample and passed, its window shown as [7, 7]).
#[test]
fn run_refuses_a_check_past_the_stop_time() {
    let out = tmp("late_check");
    let text = std::fs::read_to_string(workspace_root().join("scenarios/position_step.toml")).unwrap();
    let late = text.replacen("at = 0.3", "at = 7.0", 1);
    assert_ne!(late, text);
    let scenario = out.join("late.toml");
    std::fs::write(&scenario, late).unwrap();
    let o = servo().arg("run").arg(&scenario).on_fmu(&out).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("check 1 on motor_position") && err.contains("at = 7 s"), "{err}");
    assert!(err.contains("stop_time = 0.3 s"), "{err}");
    assert!(!out.join("position_step.json").exists(), "nothing was run");
    std::fs::remove_dir_all(&out).ok();
}

/// Unknown signals, bounds no value meets and negative counts are refused when the timeline
/// is loaded (exit 2, nothing run), not failed after the run (exit 1).
#[test]
fn sequence_refuses_unknown_signals_reversed_bounds_and_negative_counts_at_load() {
    let out = tmp("sequence_load");
    let timeline = out.join("t.toml");
    for (expect, named) in [
        ("signal='motor_speed'\nat=0.1\nmax=1.0", "signal = \"motor_speed\""),
        ("signal='motor_velocity'\nat=0.1\nmin=2.0\nmax=1.0", "min = 2 is above max = 1"),
        ("refused=-1\nat=0.1", "refused = -1"),
    ] {
        std::fs::write(
            &timeline,
            format!("name='t'\nstop_time=0.2\n[[events]]\ntime=0.0\nevent='run'\n[[expect]]\n{expect}\n"),
        )
        .unwrap();
        let o = servo().arg("sequence").arg(&timeline).on_fmu(&out).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{expect}: {err}");
        assert!(err.contains(named) && err.contains("is invalid"), "{expect}: {err}");
        assert!(!out.join("t.csv").exists(), "{expect}: nothing was run");
    }
    std::fs::remove_dir_all(&out).ok();
}

/// A lowered loop rate (8 kHz, in the documented 1–200 kHz) in a scenario that never sweeps:
/// it runs with the default sweep settings (3 kHz, which only a sweep uses); the step must be
/// whole position-loop periods and the refusal at load says so; a sweep start it cannot run
/// is refused with the reason, shown in the report, and nothing else changes.
#[test]
fn a_lowered_loop_rate_runs_without_touching_the_sweep_settings() {
    let out = tmp("lowered_rate");
    let text = std::fs::read_to_string(workspace_root().join("scenarios/position_step.toml")).unwrap();
    // The table goes in front of the first array of tables (after `plot`, a top-level key).
    let lowered = text.replacen("\n[[events]]", "\n[parameters]\n\"ctrl.current_loop_hz\" = 8000.0\n\n[[events]]", 1);
    assert_ne!(lowered, text);
    let scenario = out.join("lowered.toml");
    std::fs::write(&scenario, &lowered).unwrap();
    let o = servo().arg("run").arg(&scenario).on_fmu(&out).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("step = 0.00025 s (the default") && err.contains("set `step` to a multiple"), "{err}");
    assert!(err.contains("position-loop period 0.0005 s"), "{err}");

    let with_step = lowered.replacen("stop_time = 0.3\n", "stop_time = 0.3\nstep = 0.0005\n", 1);
    std::fs::write(&scenario, &with_step).unwrap();
    let o = servo().arg("run").arg(&scenario).on_fmu(&out).arg("--json").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(summary[0]["passed"], true, "{summary}");
    assert_eq!(summary[0]["fmu_warnings"].as_array().map(Vec::len), Some(0), "{summary}");

    let sweeping = format!(
        "{with_step}\n[[events]]\ntime = 0.1\nmode = 1\nsweep_start = 1\n\n[[checks]]\nsignal = \"sweep_state\"\nfrom = 0.1\nto = 0.3\nmax = 0\n"
    );
    std::fs::write(&scenario, &sweeping).unwrap();
    let o = servo().arg("run").arg(&scenario).on_fmu(&out).output().unwrap();
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        stdout.contains("FMU: sweep_start refused at t = 0.1 s: sweep stop_hz = 3000 Hz is at or above the Nyquist frequency 2000 Hz"),
        "{stdout}"
    );
    std::fs::remove_dir_all(&out).ok();
}

/// An --out that names a file: every command says which folder it could not create.
#[test]
fn an_out_folder_that_is_a_file_is_named() {
    let file = tmp("out-file").join("not-a-folder");
    std::fs::write(&file, "").unwrap();
    let scenario = workspace_root().join("scenarios/position_step.toml");
    for args in [
        vec!["sweep".into(), "--points".into(), "2".into()],
        vec!["run".into(), scenario.display().to_string()],
        vec!["ident".into(), "--axes".into(), "x".into()],
    ] {
        let o = servo().args(&args).on_fmu(&file).output().unwrap();
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {err}");
        assert!(err.contains(&format!("cannot create the output folder {}", file.display())), "{args:?}: {err}");
    }
}

/// An axis whose drive trips during the excitation: the identification names the fault and
/// when, instead of a number.
#[test]
fn ident_names_the_fault_of_an_axis_that_trips() {
    let o = servo()
        .args(["ident", "--axes", "x", "--set", "x:ctrl.overcurrent=3", "--set", "x:ctrl.max_current=2.9"])
        .on_fmu(tmp("ident-trip"))
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert_eq!(o.status.code(), Some(2), "{err}");
    assert!(err.contains("tripped during the excitation") && err.contains("(overcurrent)"), "{err}");
}

/// `servo compare` answers whether two traces are the same: different lengths are a
/// difference (exit 1), a file that is not a trace is bad input (exit 2).
#[test]
fn compare_tells_traces_of_different_lengths_apart() {
    let dir = tmp("compare");
    let (a, b, c) = (dir.join("a.csv"), dir.join("b.csv"), dir.join("c.csv"));
    std::fs::write(&a, "time,x\n0,1\n1,2\n").unwrap();
    std::fs::write(&b, "time,x\n0,1\n1,2\n2,3\n").unwrap();
    std::fs::write(&c, "time,x\n0,1\n1,2\n").unwrap();
    let run = |x: &std::path::Path, y: &std::path::Path| servo().arg("compare").arg(x).arg(y).output().unwrap();
    let o = run(&a, &b);
    assert_eq!(o.status.code(), Some(1), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(String::from_utf8_lossy(&o.stdout).contains("differ: 2 vs 3 rows"));
    assert_eq!(run(&a, &c).status.code(), Some(0));
    assert_eq!(run(&a, &dir.join("missing.csv")).status.code(), Some(2));
}

/// Every result carries its standard error, gain (dB) and phase (deg), in the table, the CSV
/// and the JSON, finite and positive; a quiet, settled sweep stays within twice the precision
/// (no warning), and a noisy one without settling names exactly the results whose error
/// exceeds it (the larger of the gain's and the phase's as a gain of the same relative size).
#[test]
fn sweep_reports_each_results_standard_error_and_names_the_imprecise_ones() {
    let out = tmp("sweep-standard-error");
    let sweep = |args: &[&str]| {
        let o = servo()
            .args(["sweep", "--start", "100", "--stop", "1000", "--points", "3"])
            .args(args)
            .on_fmu(&out)
            .output()
            .unwrap();
        assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
        let text = String::from_utf8_lossy(&o.stdout).to_string();
        let csv = host_tools::fmu::trace::Trace::read_csv(&out.join("sweep.csv")).unwrap();
        let json: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("sweep.json")).unwrap()).unwrap();
        (text, csv, json)
    };
    let se = |csv: &host_tools::fmu::trace::Trace| -> Vec<(f64, f64, f64)> {
        let (f, g, p) = (csv.column("frequency"), csv.column("gain_se_db"), csv.column("phase_se_deg"));
        let (f, g, p) = (f.unwrap(), g.expect("gain_se_db column"), p.expect("phase_se_deg column"));
        (0..f.len()).map(|i| (f[i], g[i], p[i])).collect()
    };
    let (quiet_text, quiet_csv, quiet_json) = sweep(&[]);
    assert!(quiet_text.contains("± dB") && quiet_text.contains("± deg"), "{quiet_text}");
    assert!(!quiet_text.contains("standard error at"), "{quiet_text}");
    let quiet = se(&quiet_csv);
    assert_eq!(quiet.len(), 3);
    for (i, &(f, g, p)) in quiet.iter().enumerate() {
        assert!(g.is_finite() && g > 0.0 && g < 0.06 && p.is_finite() && p > 0.0, "{f} Hz: {g} dB, {p} deg");
        let j = &quiet_json["standard_error"][i];
        let close = |a: &serde_json::Value, b: f64| (a.as_f64().unwrap() - b).abs() <= 1e-9 * b;
        assert!(close(&j["gain_db"], g) && close(&j["phase_deg"], p), "{j} vs {g}, {p}");
    }
    assert_eq!(quiet_json["imprecise_hz"], serde_json::json!([]));
    // The budget the sweep ran with is said, and where --time-budget 0 turns it off, not.
    assert!(quiet_text.contains("(time budget 9.9 s: --time-budget 0 for the caps alone)"), "{quiet_text}");
    assert_eq!(quiet_json["time_budget_s"], serde_json::json!(9.9));
    // Without the time budget: three points leave it nearly all of its 9.9 s, and the
    // records it grants past their cap bring every result within the precision.
    let unsettled = ["--min-measure", "0.003", "--min-settle", "0", "--settle-cycles", "0", "--time-budget", "0"];
    let (text, csv, json) = sweep(&[&unsettled[..], &["--set", "plant.current_noise_std=0.05"]].concat());
    let noisy = se(&csv);
    assert!(!text.contains("time budget") && json["time_budget_s"] == serde_json::json!(0.0), "{text}");
    let as_db = |deg: f64| deg.to_radians() * 20.0 / std::f64::consts::LN_10;
    let named: Vec<f64> = noisy.iter().filter(|&&(_, g, p)| g.max(as_db(p)) > 0.06).map(|&(f, _, _)| f).collect();
    assert!(!named.is_empty(), "{noisy:?}");
    assert_eq!(json["imprecise_hz"], serde_json::json!(named), "{json}");
    let warning = text.lines().find(|l| l.contains("WARNING: the standard error at")).expect("a warning");
    for f in &named {
        assert!(warning.contains(&format!("{f:.1}")), "{warning}");
    }
    for (q, n) in quiet.iter().zip(&noisy) {
        assert!(n.1 > q.1, "noise and no settling make {} Hz less certain: {n:?} vs {q:?}", n.0);
    }
}

/// A closed-loop resonance 17 dB above its neighbours, next to a sweep frequency (the
/// 0.576:1, 59.3 Hz axis of `servo bench sweep --random 24 --plant-seed 6`, torque command,
/// 57.8 Hz): the torque command swings almost through zero in the second half block, whose
/// noise must not let the settling check pass the point at its first comparison. It did: 0.6 dB
/// and 3.6° off the oracle, flagged imprecise (standard error 0.70 dB).
#[test]
fn sweep_waits_for_a_near_resonant_build_up_on_the_torque_command() {
    use host_tools::sweep::bench::PlantCase;
    let out = tmp("sweep-near-resonance");
    let plant = PlantCase { inertia_ratio: 0.576, resonance_hz: Some(59.3) };
    let sets: Vec<String> =
        plant.parameters().iter().flat_map(|(k, v)| ["--set".to_string(), format!("{k}={v}")]).collect();
    let o =
        servo().args(["sweep", "--json", "--oracle", "--point", "torque"]).args(&sets).on_fmu(&out).output().unwrap();
    let r: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(o.status.code(), Some(0), "{}", String::from_utf8_lossy(&o.stderr));
    let e = &r["errors_vs_oracle"];
    assert!(e["below_gain_db"].as_f64().unwrap() <= 0.1 && e["below_phase_deg"].as_f64().unwrap() <= 1.0, "{e}");
    assert!(r["imprecise_hz"].as_array().unwrap().is_empty(), "{}", r["imprecise_hz"]);
    assert!(r["measurement_time_s"].as_f64().unwrap() <= 10.0, "{}", r["measurement_time_s"]);
}
