//! `servo sweep` (its options, the sweep settings they give) and `servo bench sweep` (seed 000).

use anyhow::{bail, Result};

use crate::cli::progress_bar;
use crate::fmu::runner::Fmu;
use crate::paths::{default_fmu, default_out};
use crate::sweep::args::{SweepArgs, SweepBenchArgs};

/// Sweep settings from the command line.
pub fn sweep_settings(args: &SweepArgs) -> Result<control_core::phase_shifted_sweep::SweepParams> {
    let (
        point,
        amplitude,
        start,
        stop,
        points,
        linear,
        extra,
        settle_cycles,
        measure_cycles,
        min_settle,
        min_measure,
        shifts,
        repeats,
        threshold,
        acquisition_divider,
        precision_db,
        max_extensions,
    ) = (
        args.point.as_str(),
        args.amplitude,
        args.start,
        args.stop,
        args.points,
        args.linear,
        args.extra,
        args.settle_cycles,
        args.measure_cycles,
        args.min_settle,
        args.min_measure,
        args.shifts,
        args.repeats,
        args.threshold,
        args.acquisition_divider,
        args.precision_db,
        args.max_extensions,
    );
    use control_core::excitation::InjectionPoint;
    let (point, default_amplitude) = match point {
        "velocity" => (InjectionPoint::VelocityCommand, 2.0),
        "torque" => (InjectionPoint::TorqueCommand, 0.05),
        "feedback" => (InjectionPoint::VelocityFeedback, 2.0),
        other => bail!("--point must be velocity, torque or feedback (got `{other}`)"),
    };
    Ok(control_core::phase_shifted_sweep::SweepParams {
        point,
        signal: control_core::phase_shifted_sweep::SweepSignal::SteppedSine,
        amplitude: amplitude.unwrap_or(default_amplitude) as f32,
        start_hz: start as f32,
        stop_hz: stop as f32,
        points,
        logarithmic: !linear,
        extra_hz: extra as f32,
        settle_cycles: settle_cycles as f32,
        min_settle_s: min_settle as f32,
        measure_cycles: measure_cycles as f32,
        min_measure_s: min_measure as f32,
        shifts,
        repeats,
        threshold_hz: threshold as f32,
        acquisition_divider,
        precision_db: precision_db as f32,
        max_extensions,
        ..Default::default()
    })
}

impl SweepBenchArgs {
    pub fn run(&self) -> Result<bool> {
        bench_sweep(self)
    }
}

fn bench_sweep(args: &SweepBenchArgs) -> Result<bool> {
    let (noise, common) = (args.noise, &args.common);
    if !(noise.is_finite() && noise > 0.0) {
        bail!("--noise must be a positive current (A)");
    }
    let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
    let pb = progress_bar("sweep bench", common.json);
    let r = crate::sweep::bench::bench(&fmu, noise, |f| pb.set_position((f * 1000.0) as u64))?;
    pb.finish_and_clear();
    let e = &r.ours.errors;
    let ok = e.below_gain_db.max(e.above_gain_db) <= 0.1
        && e.below_phase_deg.max(e.above_phase_deg) <= 1.0
        && r.ours.measurement_time_s <= 10.0;
    if common.json {
        println!(
            "{}",
            serde_json::to_string_pretty(&serde_json::json!({"bench": "sweep", "result": r, "passed": ok}))?
        );
        return Ok(ok);
    }
    println!("servo bench sweep — seed 000: velocity loop 8 kHz, acquisition 4 kHz, 10 Hz to 3 kHz (41 points incl. 2 kHz), velocity-command injection 2 rad/s on 50 rad/s");
    println!(
        "  max error against the oracle (acquisition 8 kHz, records 10x longer), current-sensor noise {} A; ours lengthens a point's records until its gain's standard error is {} dB:",
        r.dither_a,
        control_core::phase_shifted_sweep::SweepParams::default().precision_db
    );
    println!("  {:<58} {:>8} {:>22} {:>22}", "method", "time s", "below 2 kHz dB / deg", "2 kHz and up dB / deg");
    for m in [&r.ours, &r.single_phase, &r.prbs] {
        let x = &m.errors;
        println!(
            "  {:<58} {:>8.3} {:>10.3} / {:>9.2} {:>10.3} / {:>9.2}{}",
            m.method,
            m.measurement_time_s,
            x.below_gain_db,
            x.below_phase_deg,
            x.above_gain_db,
            x.above_phase_deg,
            if m.unmeasured.is_empty() {
                String::new()
            } else {
                format!(
                    "   cannot measure {} point(s): {:?} Hz",
                    m.unmeasured.len(),
                    m.unmeasured.iter().map(|f| f.round()).collect::<Vec<_>>()
                )
            }
        );
    }
    let [o, ours, single] = r.at_nyquist;
    println!(
        "  at exactly 2 kHz: oracle {:.3} dB / {:.2} deg; phase shifted {:.3} dB / {:.2} deg (quality {:.3}); single phase {:.3} dB / {:.2} deg (quality {:.3})",
        o.gain_db, o.phase_deg, ours.gain_db, ours.phase_deg, ours.quality, single.gain_db, single.phase_deg, single.quality
    );
    println!(
        "  equivalent-time stream vs the drive's on-line correlator: {:.1e} dB, {:.1e} deg",
        r.stream_vs_online.0, r.stream_vs_online.1
    );
    let row = |x: &crate::sweep::measurement::ErrorSummary| {
        format!(
            "{:.3} / {:.2} below 2 kHz, {:.3} / {:.2} from 2 kHz up (dB / deg)",
            x.below_gain_db, x.below_phase_deg, x.above_gain_db, x.above_phase_deg
        )
    };
    println!("  ours vs oracle without the sensor noise: {}", row(&r.noise_free));
    println!("    (the noise-free encoder's count pattern locks to the excitation: both carry a phase-dependent quantisation error)");
    println!("  the same with a 2^24-count encoder:      {}", row(&r.fine_encoder));
    println!(
        "  worst error over riding speeds {:?} rad/s: fixed records {:.3} dB / {:.2} deg, lengthened for precision {:.3} dB / {:.2} deg",
        r.spread_speeds, r.spread_fixed.0, r.spread_fixed.1, r.spread_lengthened.0, r.spread_lengthened.1
    );
    println!(
        "  analytic linear model vs oracle up to 30 Hz: {:.3} dB, {:.2} deg",
        r.analytic_low_frequency.0, r.analytic_low_frequency.1
    );
    println!(
        "  goal: full Bode in <= 10 s with <= 0.1 dB / 1 deg everywhere: {:.2} s, {:.3} dB, {:.2} deg: {}",
        r.ours.measurement_time_s,
        e.below_gain_db.max(e.above_gain_db),
        e.below_phase_deg.max(e.above_phase_deg),
        if ok { "met" } else { "NOT met" }
    );
    println!("  with current-sensor noise {} A: max error up to 1.9 kHz against measurement time", r.noise_std_a);
    println!("  {:>10} {:>24} {:>24}", "time s", "ours dB / deg", "PRBS H1 dB / deg");
    for n in &r.noise {
        println!(
            "  {:>10.2} {:>12.3} / {:>9.2} {:>12.3} / {:>9.2}",
            n.measurement_time_s, n.ours.0, n.ours.1, n.prbs.0, n.prbs.1
        );
    }
    Ok(ok)
}

impl SweepArgs {
    pub fn run(&self) -> Result<bool> {
        let settings = sweep_settings(self)?;
        let parameters = crate::fmu::assignment::axis_parameters(&self.set, &[])?;
        let run = crate::fmu::sweep_run::SweepRun { settings, parameters, velocity: self.velocity };
        let reference = match &self.reference {
            Some(p) => Some((p.display().to_string(), crate::sweep::report::read_reference(p)?)),
            None => None,
        };
        let common = &self.common;
        let fmu = Fmu::load(&common.fmu.clone().unwrap_or_else(default_fmu))?;
        let out = common.out.clone().unwrap_or_else(|| default_out("sweep"));
        let pb = progress_bar("sweep", common.json);
        let r = crate::sweep::report::run(
            &fmu,
            &run,
            self.oracle,
            reference.as_ref().map(|(l, v)| (l.as_str(), v.clone())),
            &out,
            |label, f| {
                pb.set_prefix(label.to_string());
                pb.set_position((f * 1000.0) as u64)
            },
        )?;
        pb.finish_and_clear();
        if common.json {
            println!("{}", serde_json::to_string_pretty(&r)?);
        } else {
            r.print();
        }
        // The drive's correlator and the host's equivalent-time estimate must agree.
        Ok(r.stream_vs_online.0 <= 0.01 && r.stream_vs_online.1 <= 0.1)
    }
}
