//! A tuning verified where it is to run: the open loop measured with the new gains by a
//! feedback-point sweep on a [`AxisUnderTest`] (the twin, or the drive), looked at closer
//! wherever it may pass near −1 between the sweep's frequencies, and the margins a
//! sparse measured grid can show — the phase margin at its gain crossovers and the
//! sensitivity peak over its points (the stability and the gain margin need the model's
//! dense grid). A sweep that measured no crossover has not shown a margin: it fails.

use std::collections::BTreeMap;

use anyhow::{Context, Result};
use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::SweepParams;
use num_complex::Complex64;
use serde::Serialize;

use super::axis_under_test::AxisUnderTest;
use super::design::MarginGoal;
use super::margins::crossover_margins;
use super::sweep_settings;
use crate::analysis::response_point::ResponsePoint;
use crate::fmu::scenario::Value;

/// Amplitude of the verification's feedback-point sweep (rad/s).
pub const FEEDBACK_AMPLITUDE: f64 = 2.0;

#[derive(Clone, Debug, Serialize)]
pub struct Verification {
    /// Where it was measured ("the FMU", "the drive at …").
    pub on: String,
    #[serde(skip)]
    pub open_loop: Vec<ResponsePoint>,
    /// NaN where no gain crossover was measured.
    pub phase_margin_deg: f64,
    pub sensitivity_peak: f64,
    /// Frequencies measured with the output at a limit (the drive's voltage circle, or the
    /// torque limit): not the linear loop's response, so the verification fails.
    pub limited_points: usize,
    pub passed: bool,
    pub drive_time_s: f64,
}

/// The open loop of `tuned` (the run's parameters with the tuning in them) measured on
/// `target` riding at `velocity` rad/s, held to `goal`'s phase margin and Ms: the default
/// sweep's frequencies, then a closer look ([`closer_looks`]) wherever the loop between two
/// of them may pass nearer −1 than they show, by the measurement or by `predicted` (the
/// design's loop on the calibrated model).
pub fn verify(
    target: &mut dyn AxisUnderTest,
    tuned: &BTreeMap<String, Value>,
    velocity: f64,
    goal: &MarginGoal,
    predicted: &dyn Fn(f64) -> Complex64,
) -> Result<Verification> {
    let standard = sweep_settings(InjectionPoint::VelocityFeedback, FEEDBACK_AMPLITUDE);
    let sweep = target
        .sweep(&standard, tuned, velocity)
        .with_context(|| format!("the feedback-point sweep with the new gains on {}", target.name()))?;
    let mut points = sweep.points;
    let mut limited_points = sweep.voltage_limited + sweep.torque_limited;
    let mut drive_time_s = sweep.drive_time_s;
    for band in closer_looks(&points, predicted, goal) {
        let settings = SweepParams {
            start_hz: band.start_hz as f32,
            stop_hz: band.stop_hz as f32,
            points: band.points,
            extra_hz: 0.0,
            ..standard
        };
        let closer = target.sweep(&settings, tuned, velocity).with_context(|| {
            format!(
                "the closer look at {:.0}–{:.0} Hz with the new gains on {}",
                band.start_hz,
                band.stop_hz,
                target.name()
            )
        })?;
        points.extend(closer.points);
        limited_points += closer.voltage_limited + closer.torque_limited;
        drive_time_s += closer.drive_time_s;
    }
    points.sort_by(|a, b| a.frequency.total_cmp(&b.frequency));
    let hz: Vec<f64> = points.iter().map(|p| p.frequency).collect();
    let l: Vec<Complex64> = points.iter().map(ResponsePoint::to_complex).collect();
    let (phase_margin_deg, sensitivity_peak) = crossover_margins(&hz, &l);
    // NaN compares false: no crossover measured, not passed.
    let passed =
        phase_margin_deg >= goal.phase_margin_deg && sensitivity_peak <= goal.sensitivity_peak && limited_points == 0;
    Ok(Verification {
        on: target.name(),
        open_loop: points,
        phase_margin_deg,
        sensitivity_peak,
        limited_points,
        passed,
        drive_time_s,
    })
}

/// Frequencies a closer look measures: `points` log-spaced from `start_hz` to `stop_hz`, both
/// included (strictly between two measured points).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Band {
    pub start_hz: f64,
    pub stop_hz: f64,
    pub points: u32,
}

/// A closer look's spacing: neighbouring frequencies at most this ratio apart (1.5 %: the
/// default sweep's 15.7 % in ten).
pub const CLOSER_SPACING: f64 = 1.015;
/// Points a closer look takes at most (one band).
pub const CLOSER_MOST_POINTS: u32 = 40;
/// The model's loop is read at so many frequencies across each gap between measured points.
pub const MODEL_READINGS_PER_GAP: usize = 16;
/// A gap whose phase margin is less than this over the goal's is looked at closer (deg).
pub const PHASE_MARGIN_SLACK_DEG: f64 = 5.0;
/// A gap whose `|1/(1 + L)|` reaches this share of the goal's Ms is looked at closer.
pub const NEAR_SHARE_OF_MS: f64 = 0.95;
/// The model's loop hides a margin between two points when, read densely, its phase margin
/// there is this much less than the points' interpolation shows (deg), or its Ms this share
/// more.
pub const HIDDEN_PHASE_DEG: f64 = 0.5;
pub const HIDDEN_MS_SHARE: f64 = 1.01;

/// Where between the measured `points` (increasing frequency) the loop may keep less margin
/// than they show: every gap whose margins (the phase margin interpolated at a crossover
/// between its two points, the `|1/(1 + L)|` of either where it peaks) come within
/// [`PHASE_MARGIN_SLACK_DEG`] or [`NEAR_SHARE_OF_MS`] of `goal`'s, and every gap where
/// `predicted` (the design's loop on the calibrated model), read densely, keeps less than its
/// values at the two points show (a phase that dips between them, a crossover pair or a
/// sensitivity peak between them) and comes as near the goal. Neighbouring gaps make one
/// band, measured [`CLOSER_SPACING`] apart between the points that bound it (at most
/// [`CLOSER_MOST_POINTS`]: a wider band is measured wider apart).
pub fn closer_looks(points: &[ResponsePoint], predicted: &dyn Fn(f64) -> Complex64, goal: &MarginGoal) -> Vec<Band> {
    // NaN (no crossover) compares false: not near.
    let near = |(pm, ms): (f64, f64)| {
        pm < goal.phase_margin_deg + PHASE_MARGIN_SLACK_DEG || ms > NEAR_SHARE_OF_MS * goal.sensitivity_peak
    };
    // |1/(1 + L)| at each point, and whether it is a peak (no less than its neighbours'):
    // a gap beside a peak may hold a higher one.
    let sensitivity: Vec<f64> = points.iter().map(|p| 1.0 / (1.0 + p.to_complex()).norm()).collect();
    let peak = |k: usize| {
        (k == 0 || sensitivity[k] >= sensitivity[k - 1])
            && sensitivity.get(k + 1).is_none_or(|&next| sensitivity[k] >= next)
    };
    let close_gap = |k: usize| {
        let ends = [points[k].frequency, points[k + 1].frequency];
        let (measured_pm, _) = crossover_margins(&ends, &[points[k].to_complex(), points[k + 1].to_complex()]);
        let measured_ms = [k, k + 1].into_iter().filter(|&i| peak(i)).map(|i| sensitivity[i]).fold(0.0, f64::max);
        if near((measured_pm, measured_ms)) {
            return true;
        }
        let hz: Vec<f64> = (0..=MODEL_READINGS_PER_GAP)
            .map(|i| ends[0] * (ends[1] / ends[0]).powf(i as f64 / MODEL_READINGS_PER_GAP as f64))
            .collect();
        let model: Vec<Complex64> = hz.iter().map(|&f| predicted(f)).collect();
        let (pm, ms) = crossover_margins(&hz, &model);
        let (ends_pm, ends_ms) = crossover_margins(&ends, &[model[0], model[MODEL_READINGS_PER_GAP]]);
        // A crossover the ends do not show (NaN) is hidden.
        let hidden_pm = pm.is_finite() && !(pm >= ends_pm - HIDDEN_PHASE_DEG);
        let hidden_ms = ms > HIDDEN_MS_SHARE * ends_ms;
        (hidden_pm || hidden_ms) && near((if hidden_pm { pm } else { f64::NAN }, if hidden_ms { ms } else { 0.0 }))
    };
    let mut bands = Vec::new();
    let mut k = 0;
    while k + 1 < points.len() {
        if !close_gap(k) {
            k += 1;
            continue;
        }
        let first = k;
        while k + 1 < points.len() && close_gap(k) {
            k += 1;
        }
        let (low, high) = (points[first].frequency, points[k].frequency);
        let points =
            (((high / low).ln() / CLOSER_SPACING.ln()).ceil() as u32).saturating_sub(1).clamp(1, CLOSER_MOST_POINTS);
        let step = (high / low).powf(1.0 / (points + 1) as f64);
        bands.push(Band { start_hz: low * step, stop_hz: high / step, points });
        // Gap k is not close (or the last point is reached).
        k += 1;
    }
    bands
}

/// `parameters` with the velocity loop's `tuning` and the position loop's (where designed)
/// in them.
pub fn with_tuning(
    parameters: &BTreeMap<String, Value>,
    tuning: &super::velocity_controller::VelocityTuning,
    position: Option<&super::position_loop_design::PositionTuning>,
) -> BTreeMap<String, Value> {
    let mut tuned = parameters.clone();
    for (k, v) in tuning.parameters() {
        tuned.insert(k, Value::Float(v));
    }
    for (k, v) in position.map(|p| p.parameters()).into_iter().flatten() {
        tuned.insert(k, Value::Float(v));
    }
    tuned
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autotune::margins::{log_grid, margins};
    use crate::autotune::MeasuredSweep;
    use crate::calibrate::friction::SpeedPoint;
    use crate::calibrate::friction_runs::FrictionRuns;
    use control_core::Params;
    use std::f64::consts::TAU;

    /// An axis whose open loop is `loop_gain`, read exactly at each sweep's frequencies (the
    /// core's frequency plan), one second of drive time a sweep.
    struct AnalyticAxis<F: Fn(f64) -> Complex64> {
        loop_gain: F,
    }

    impl<F: Fn(f64) -> Complex64> AxisUnderTest for AnalyticAxis<F> {
        fn params(&mut self, _: &BTreeMap<String, Value>) -> Result<Params> {
            Ok(Params::default())
        }

        fn sweep(&mut self, settings: &SweepParams, _: &BTreeMap<String, Value>, _: f64) -> Result<MeasuredSweep> {
            let points = (0..settings.count())
                .map(|i| {
                    let f = settings.frequency(i) as f64;
                    ResponsePoint::from_complex(f, (self.loop_gain)(f), 1.0)
                })
                .collect();
            Ok(MeasuredSweep { points, drive_time_s: 1.0, torque_limited: 0, voltage_limited: 0, torque_limit: 1.0 })
        }

        fn constant_speeds(&mut self, _: &FrictionRuns, _: &BTreeMap<String, Value>) -> Result<(Vec<SpeedPoint>, f64)> {
            anyhow::bail!("an analytic loop runs no constant speeds")
        }

        fn name(&self) -> String {
            "an analytic loop".into()
        }
    }

    /// A PI (`kp`, integral corner 40 Hz) on a rigid body (1e-3) behind 150 µs, with a phase
    /// dip at `dip_hz` where given: `(s² + 2ζ₁ωs + ω²)/(s² + 2ζ₂ωs + ω²)` (ζ₁ < ζ₂: the phase
    /// falls just under ω and rises past it, the gain dips to ζ₁/ζ₂).
    fn pi_loop(kp: f64, dip: Option<(f64, f64, f64)>) -> impl Fn(f64) -> Complex64 {
        move |f: f64| {
            let s = Complex64::new(0.0, TAU * f);
            let d = dip.map_or(Complex64::new(1.0, 0.0), |(hz, z1, z2)| {
                let w = TAU * hz;
                (s * s + 2.0 * z1 * w * s + w * w) / (s * s + 2.0 * z2 * w * s + w * w)
            });
            kp * (1.0 + TAU * 40.0 / s) / (1e-3 * s) * (-s * 150e-6).exp() * d
        }
    }

    fn dense_margins(l: &dyn Fn(f64) -> Complex64) -> super::super::margins::Margins {
        let f = log_grid(5.0, 3500.0, 40_000);
        let l: Vec<Complex64> = f.iter().map(|&f| l(f)).collect();
        margins(&f, &l).expect("a fine grid")
    }

    /// The phase margin the default sweep's points show of `l` (their interpolation).
    fn on_the_sweeps_points(l: &dyn Fn(f64) -> Complex64) -> f64 {
        let s = sweep_settings(InjectionPoint::VelocityFeedback, FEEDBACK_AMPLITUDE);
        let f: Vec<f64> = (0..s.count()).map(|i| s.frequency(i) as f64).collect();
        let l: Vec<Complex64> = f.iter().map(|&f| l(f)).collect();
        crossover_margins(&f, &l).0
    }

    fn standard() -> MarginGoal {
        MarginGoal::named("standard").unwrap()
    }

    /// The goal whose Ms (2.0) the loops below keep on every point: whether they pass turns on
    /// the phase margin (or, for the resonance, on the model's reading) alone.
    fn aggressive() -> MarginGoal {
        MarginGoal::named("aggressive").unwrap()
    }

    /// A phase dip at the crossover between two of the sweep's points: the points show 60.7°
    /// where the loop keeps 40.3°; the model (here the loop itself) shows the dip, the closer
    /// look measures it and the verification reads the loop's margin and fails (on it alone:
    /// the loop's Ms is inside the goal's).
    #[test]
    fn a_phase_dip_the_model_shows_between_the_sweeps_points_is_measured_closer() {
        let l = pi_loop(3.75, Some((200.0, 0.05, 0.2)));
        let truth = dense_margins(&l);
        let sparse = on_the_sweeps_points(&l);
        let goal = aggressive();
        assert!(truth.phase_margin_deg < 45.0 && sparse > 55.0, "premise: {truth:?} {sparse}");
        assert!(truth.sensitivity_peak < 0.95 * goal.sensitivity_peak, "premise: {truth:?}");
        let v = verify(&mut AnalyticAxis { loop_gain: &l }, &BTreeMap::new(), 0.0, &goal, &l).unwrap();
        assert!((v.phase_margin_deg - truth.phase_margin_deg).abs() < 0.5, "{v:?} vs {truth:?}");
        assert!(!v.passed && v.drive_time_s > 1.0);
    }

    /// The same where the model misses the dip (the loop without it): the points' own margin,
    /// 49.7°, lies within the slack of the goal, and the closer look finds 41.4°.
    #[test]
    fn a_margin_near_the_goal_is_measured_closer_where_the_model_shows_nothing() {
        let l = pi_loop(3.75, Some((288.45, 0.1, 0.3)));
        let model = pi_loop(3.75, None);
        let truth = dense_margins(&l);
        let sparse = on_the_sweeps_points(&l);
        let goal = aggressive();
        let pm = truth.phase_margin_deg;
        assert!(pm < 45.0 && sparse > 45.0 && sparse < 45.0 + PHASE_MARGIN_SLACK_DEG, "premise: {pm} {sparse}");
        assert!(truth.sensitivity_peak < 0.95 * goal.sensitivity_peak, "premise: {truth:?}");
        let v = verify(&mut AnalyticAxis { loop_gain: &l }, &BTreeMap::new(), 0.0, &goal, &model).unwrap();
        assert!((v.phase_margin_deg - pm).abs() < 0.5, "{v:?} vs {truth:?}");
        assert!(!v.passed);
    }

    /// A loop well inside its margins (67°, Ms 1.3) is measured once, on the sweep's points,
    /// and passes with the margin they show.
    #[test]
    fn a_loop_well_inside_its_margins_takes_no_closer_look() {
        let l = pi_loop(1.0, None);
        let truth = dense_margins(&l);
        assert!(truth.phase_margin_deg > 60.0 && truth.sensitivity_peak < 1.4, "premise: {truth:?}");
        let v = verify(&mut AnalyticAxis { loop_gain: &l }, &BTreeMap::new(), 0.0, &standard(), &l).unwrap();
        assert!(v.passed && v.drive_time_s == 1.0, "{v:?}");
        assert!((v.phase_margin_deg - truth.phase_margin_deg).abs() < 1.0, "{v:?} vs {truth:?}");
    }

    /// A narrow resonance between two points lifts the loop over `|L| = 1` and back (two
    /// crossovers the points do not show, nor an Ms near the goal's): the model's reading
    /// finds the band, a model without the resonance does not (with the
    /// skirts' gaps beside it), and the bands' frequencies lie between the measured points,
    /// at most the spacing apart.
    #[test]
    fn a_crossover_pair_between_two_points_is_found_from_the_model() {
        // The sweep's points near 2.2 kHz, a resonance (ζ 0.004) midway between two of them.
        let s = sweep_settings(InjectionPoint::VelocityFeedback, FEEDBACK_AMPLITUDE);
        let f: Vec<f64> = (0..s.count()).map(|i| s.frequency(i) as f64).collect();
        let k = f.iter().position(|&x| x > 2200.0).unwrap();
        let at = (f[k] * f[k + 1]).sqrt();
        let l = move |x: f64| {
            let s = Complex64::new(0.0, TAU * x);
            let w = TAU * at;
            pi_loop(1.0, None)(x) * (w * w) / (s * s + 2.0 * 0.004 * w * s + w * w)
        };
        let points: Vec<ResponsePoint> = f.iter().map(|&x| ResponsePoint::from_complex(x, l(x), 1.0)).collect();
        let high: Vec<Complex64> = points[k - 3..].iter().map(ResponsePoint::to_complex).collect();
        let (pm_points, _) = crossover_margins(&f[k - 3..], &high);
        assert!(pm_points.is_nan(), "premise: the points show no crossover near the resonance ({pm_points})");
        assert!(l(at).norm() > 1.0, "premise: the resonance lifts the loop over 1");
        // The points show no Ms near the goal's either: only the model's reading finds it.
        let goal = aggressive();
        let most = points.iter().map(|p| 1.0 / (1.0 + p.to_complex()).norm()).fold(0.0, f64::max);
        assert!(most < NEAR_SHARE_OF_MS * goal.sensitivity_peak, "premise: the points' Ms {most}");
        let over = |b: &&Band| b.start_hz < at && at < b.stop_hz;
        let blind = closer_looks(&points, &pi_loop(1.0, None), &goal);
        assert!(!blind.iter().any(|b| over(&b)), "a model without the resonance finds no band over it: {blind:?}");
        let bands = closer_looks(&points, &l, &goal);
        let band = bands.iter().find(over).expect("a band over the resonance");
        assert!(band.start_hz > f[k - 2] && band.stop_hz < f[k + 2], "{band:?}");
        for b in &bands {
            // No measured frequency measured again.
            assert!(
                f.iter().all(|&x| (x / b.start_hz - 1.0).abs() > 1e-3 && (x / b.stop_hz - 1.0).abs() > 1e-3),
                "{b:?}"
            );
            let step = (b.stop_hz / b.start_hz).powf(1.0 / (b.points.max(2) - 1) as f64);
            // Wider apart only where the band holds the most points a band takes.
            assert!(b.points <= CLOSER_MOST_POINTS, "{b:?}");
            assert!(step <= CLOSER_SPACING * 1.000_001 || b.points == CLOSER_MOST_POINTS, "{b:?}");
        }
    }
}
