//! `servo circle` and `servo bench circle` (seed 002).

use anyhow::{bail, Result};

use crate::circle::args::{CircleArgs, CircleBenchArgs};
use crate::cli::progress_bar;
use crate::fmu::fmpy;
use crate::fmu::runner::Fmu;
use crate::paths::{default_fmu, default_out};

impl CircleArgs {
    pub fn run(&self) -> Result<bool> {
        circle(self)
    }
}

fn circle(args: &CircleArgs) -> Result<bool> {
    let (axes, single, radius, feed, cw, lead_in, measure, set, x_set, y_set, compare, tuned, with_fmpy, common) = (
        args.axes.as_str(),
        &args.single,
        args.radius,
        args.feed,
        args.cw,
        args.lead_in,
        args.measure.as_deref().unwrap_or(if args.target.device.is_some() { "motor" } else { "load" }),
        &args.set,
        &args.x_set,
        &args.y_set,
        &args.compare,
        &args.tuned,
        args.fmpy,
        &args.common,
    );
    use crate::circle::report::run;
    use crate::fmu::assignment::{axis_parameters, parse_assignment};
    use crate::fmu::circle::{CircleRequest, Direction, Measure};
    if axes.replace(' ', "") != "x,y" {
        bail!("--axes: the XY test runs the axes x,y (got `{axes}`)");
    }
    let measure = match measure {
        "load" => Measure::Load,
        "motor" => Measure::Motor,
        other => bail!("--measure must be load or motor (got `{other}`)"),
    };
    let (mut xp, mut yp) = (axis_parameters(set, x_set)?, axis_parameters(set, y_set)?);
    let mut comparison = crate::circle::report::Comparison::default();
    let mut labels = ("as given".to_string(), String::new());
    if let Some(dir) = tuned {
        // The axes as `servo tune` measured them (--set / --x-set / --y-set still apply on
        // top); the second run adds each axis's correction.
        let [(x_base, x_corr), (y_base, y_corr)] = crate::correction::tuned_axes(dir)?;
        xp = x_base.into_iter().chain(xp).collect();
        yp = y_base.into_iter().chain(yp).collect();
        comparison.x = x_corr;
        comparison.y = y_corr;
        comparison.shape_only = true;
        comparison.must_be_rounder = true;
        labels = ("without correction".into(), "with correction".into());
    }
    let (x_parameters, y_parameters) = match single.as_deref() {
        None | Some("x") => (xp, yp),
        Some("y") => (yp.clone(), yp),
        Some(other) => bail!("--single takes x or y (got `{other}`)"),
    };
    if lead_in == 0 && single.is_some() {
        bail!("--lead-in must be at least 1 for the single-axis test (the quarter-period copy needs history)");
    }
    let request = CircleRequest {
        radius,
        feed,
        direction: if cw { Direction::Clockwise } else { Direction::CounterClockwise },
        lead_in,
        measure,
        x_parameters,
        y_parameters,
    };
    comparison.both = compare.iter().map(|s| parse_assignment(s)).collect::<Result<_>>()?;
    if tuned.is_some() && !comparison.both.is_empty() {
        bail!("--tuned compares without and with the correction: leave out --compare");
    }
    let out = common.out.clone().unwrap_or_else(|| default_out("circle"));
    let fmu_path = common.fmu.clone().unwrap_or_else(default_fmu);
    if args.target.device.is_some() {
        if single.is_none() {
            bail!("--device runs the single-axis pseudo-circle (add --single x): a drive is one axis");
        }
        if tuned.is_some() || !comparison.both.is_empty() || with_fmpy {
            bail!("--compare, --tuned and --fmpy are for the FMU; with --device the FMU runs the drive's twin");
        }
        // Checked before the port is opened: a bad request touches no drive.
        crate::circle::device::pseudo_circle_sweep(&request)?;
    }
    let fmu = Fmu::load(&fmu_path)?;
    if let Some(mut session) = args.target.session()? {
        let port = args.target.device.as_deref().unwrap_or_default();
        let pb = progress_bar("circle", common.json);
        let r = crate::circle::device::run_on_device(
            &*fmu.as_twin_of(&session.params_for_twin()?)?,
            &request,
            (port, &mut session),
            &out,
            |label, f| {
                pb.set_prefix(label.to_string());
                pb.set_position((f * 1000.0) as u64)
            },
        )?;
        pb.finish_and_clear();
        if common.json {
            println!("{}", serde_json::to_string_pretty(&serde_json::json!({ "circle": r }))?);
        } else {
            r.print();
        }
        return Ok(r.passed);
    }
    if tuned.is_none() {
        labels.1 = comparison.both.iter().map(|(k, v)| format!("{k} = {}", v.as_f64())).collect::<Vec<_>>().join(", ");
    }
    let pb = progress_bar("circle", common.json);
    pb.set_position(100);
    let (report, pseudo) = run(&fmu, &request, single.is_some(), &comparison, (&labels.0, &labels.1), &out)?;
    pb.finish_and_clear();
    let mut ok = report.passed;
    let mut fmpy_note = None;
    if with_fmpy {
        let Some((_, first)) = pseudo.first() else {
            bail!("--fmpy cross-checks the single-axis run: add --single x");
        };
        let inputs = out.join("pseudo_circle.inputs.toml");
        std::fs::write(&inputs, first.scenario.to_toml())?;
        let csv = out.join("pseudo_circle.fmpy.csv");
        let (verdict, _) = fmpy::fmpy_cross_check(&fmu_path, &inputs, &first.trace, &csv)?;
        ok &= verdict.is_ok();
        fmpy_note = Some(verdict);
    }
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(
                &serde_json::json!({"circle": report, "fmpy": fmpy_note.as_ref().map(fmpy::verdict_json)})
            )?
        );
    } else {
        report.print();
        if let Some(v) = &fmpy_note {
            fmpy::print_verdict("fmpy cross-check of the single-axis feedback", v);
        }
    }
    Ok(ok)
}

impl CircleBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_circle(self)
    }
}

fn bench_circle(args: &CircleBenchArgs) -> Result<bool> {
    let common = &args.common;
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let r = crate::circle::bench::bench(&fmu)?;
    let ok = r.pseudo_vs_two_axis_relative <= 1e-3 && r.protrusion_ratio < 1.0;
    crate::bench::figures::Recorder::new("circle")
        .at_most(
            "pseudo-circle vs two-axis circle, friction-free axis: largest radial difference, share of the radius",
            100.0 * r.pseudo_vs_two_axis_relative,
            0.1,
            "%",
        )
        .at_most("largest quadrant protrusion with friction compensation over without", r.protrusion_ratio, 1.0, "")
        .verdict(r.protrusion_ratio < 1.0)
        .write(common.out.as_deref(), ok)?;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({"bench": "circle", "result": r, "passed": ok}))?
        );
        return Ok(ok);
    }
    println!(
        "servo bench circle — seed 002, radius {} rad, feed {} rad/s (1 revolution per second), machine-end positions",
        r.radius, r.feed
    );
    println!("  demo axis (default Coulomb friction 0.01 N·m motor, 0.02 N·m load), two-axis circle:");
    println!(
        "    compensation off: largest quadrant protrusion {:.3e} rad, roundness {:.3e} rad",
        r.protrusion_off, r.roundness_off
    );
    println!(
        "    compensation on ({}): largest quadrant protrusion {:.3e} rad, roundness {:.3e} rad",
        crate::circle::bench::COMPENSATION.map(|(k, v)| format!("{k} = {v}")).join(", "),
        r.protrusion_on,
        r.roundness_on
    );
    println!("    ratio on / off: {:.3}", r.protrusion_ratio);
    println!(
        "  friction-free axis: pseudo-circle (x(t), x(t - T/4)) vs two-axis circle of two identical axes: largest radial difference {:.3e} rad = {:.5} % of the radius (goal <= 0.1 %)",
        r.pseudo_vs_two_axis,
        r.pseudo_vs_two_axis_relative * 100.0
    );
    Ok(ok)
}
