//! A tuned velocity loop's time responses predicted from its frequency response: the step
//! of the velocity command (`T = L/(1 + L)`) and the step of a torque disturbance at the motor
//! (`P_d/(1 + L)`, velocity per N·m, `P_d` the path from a torque at the motor to the
//! velocity estimate), each from its response on a uniform grid up to the loop's Nyquist
//! frequency by an inverse FFT (the loop is sampled at the velocity period; the grid is twice
//! the predicted span, so an impulse response that has died out by then does not wrap round
//! into it). An unstable loop has no step response: the inverse FFT would give a bounded one
//! running backwards in time, so its figures are NaN and `stable` is false. A figure the span
//! does not reach (a step that has not settled by its end) is NaN too, not the span.

use num_complex::Complex64;
use serde::Serialize;

use super::velocity_controller::VelocityTuning;

/// The predicted responses and their figures.
#[derive(Clone, Debug, Serialize)]
pub struct StepPrediction {
    /// Sample times (s), one velocity period apart.
    pub time: Vec<f64>,
    /// Velocity per unit step of the velocity command.
    pub command_step: Vec<f64>,
    /// Velocity per N·m step of torque at the motor (rad/s per N·m).
    pub disturbance_step: Vec<f64>,
    /// The command step's overshoot (%).
    pub overshoot_percent: f64,
    /// When the command step last leaves ±2 % of its final value (s).
    pub settling_time_s: f64,
    /// The disturbance step's largest velocity deviation (rad/s per N·m).
    pub disturbance_peak: f64,
    /// When the disturbance's deviation last leaves 10 % of its peak (s).
    pub disturbance_recovery_s: f64,
    /// The closed loop is stable (the figures are NaN otherwise).
    pub stable: bool,
}

/// The time after the last sample of `y` outside `band` (NaN where the last sample is still
/// outside: the span did not reach it; 0 where none is).
pub fn settled_after(time: &[f64], y: &[f64], outside: impl Fn(f64) -> bool) -> f64 {
    match y.iter().rposition(|&v| outside(v)) {
        None => 0.0,
        Some(k) if k + 1 < y.len() => time[k + 1],
        Some(_) => f64::NAN,
    }
}

/// The responses of `tuning` on `plant` (torque command → velocity estimate at a frequency in
/// Hz), with `disturbance` the path from a torque at the motor to the velocity estimate,
/// sampled every `period` s, over `span_s` seconds.
pub fn predict(
    tuning: &VelocityTuning,
    plant: &dyn Fn(f64) -> Complex64,
    disturbance: &dyn Fn(f64) -> Complex64,
    period: f64,
    span_s: f64,
) -> StepPrediction {
    let samples = ((span_s / period).ceil() as usize).max(16);
    let n = (2 * samples).next_power_of_two();
    let half = n / 2;
    let mut command = vec![Complex64::new(0.0, 0.0); n];
    let mut load = vec![Complex64::new(0.0, 0.0); n];
    for k in 0..=half {
        let (t, d) = if k == 0 {
            // The limits at 0 Hz on an integrating plant: T = 1; P_d/(1 + L) = 0 with the
            // PI's integrator, 1/kp (the ratio of the two integrations) without it.
            let d = if tuning.ki > 0.0 { 0.0 } else { 1.0 / tuning.kp };
            (Complex64::new(1.0, 0.0), Complex64::new(d, 0.0))
        } else {
            let f = k as f64 / (n as f64 * period);
            let l = tuning.response(f, period) * plant(f);
            (l / (1.0 + l), disturbance(f) / (1.0 + l))
        };
        // The Nyquist bin of a real signal is real.
        let (t, d) = if k == half { (Complex64::new(t.re, 0.0), Complex64::new(d.re, 0.0)) } else { (t, d) };
        command[k] = t;
        load[k] = d;
        if k > 0 && k < half {
            command[n - k] = t.conj();
            load[n - k] = d.conj();
        }
    }
    let mut planner = rustfft::FftPlanner::new();
    let inverse = planner.plan_fft_inverse(n);
    inverse.process(&mut command);
    inverse.process(&mut load);
    // Impulse responses (scaled by 1/n) summed into steps.
    let step = |impulse: &[Complex64]| -> Vec<f64> {
        let mut sum = 0.0;
        impulse[..samples]
            .iter()
            .map(|h| {
                sum += h.re / n as f64;
                sum
            })
            .collect()
    };
    let command_step = step(&command);
    let disturbance_step = step(&load);
    let time: Vec<f64> = (0..samples).map(|k| k as f64 * period).collect();
    // Stable: the margins' argument-principle count on a grid fine enough for it.
    let f = super::margins::log_grid(0.5, 0.999 * 0.5 / period, 4000);
    let l: Vec<Complex64> = f.iter().map(|&f| tuning.response(f, period) * plant(f)).collect();
    let stable = super::margins::margins(&f, &l).is_some_and(|m| m.stable);
    let nan_unless = |x: f64| if stable { x } else { f64::NAN };
    let overshoot = 100.0 * (command_step.iter().copied().fold(f64::NEG_INFINITY, f64::max) - 1.0).max(0.0);
    let settling = settled_after(&time, &command_step, |y| (y - 1.0).abs() > 0.02);
    let peak = disturbance_step.iter().map(|v| v.abs()).fold(0.0, f64::max);
    let recovery = settled_after(&time, &disturbance_step, |v| v.abs() > 0.1 * peak);
    let (overshoot_percent, settling_time_s, disturbance_peak, disturbance_recovery_s) =
        (nan_unless(overshoot), nan_unless(settling), nan_unless(peak), nan_unless(recovery));
    StepPrediction {
        time,
        command_step,
        disturbance_step,
        overshoot_percent,
        settling_time_s,
        disturbance_peak,
        disturbance_recovery_s,
        stable,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A PI on a rigid body with the loop's period (no delay, no filters): the predicted
    /// command step against a direct simulation of the same discrete loop (the PI as the
    /// drive runs it, the rigid body sampled exactly with a held torque), and the disturbance
    /// step against it too; the steps settle at 1 and 0.
    #[test]
    fn steps_match_a_direct_simulation_of_a_discrete_loop() {
        let (j, period) = (2e-4f64, 1.0 / 8000.0);
        let tuning = VelocityTuning { kp: 0.05, ki: 5.0, low_pass_hz: 0.0, notch: None, notch2: None };
        // The rigid body with a zero-order hold, as a discrete transfer T/(J(z − 1)), at f.
        let plant = |f: f64| {
            let z = Complex64::from_polar(1.0, std::f64::consts::TAU * f * period);
            period / (j * (z - 1.0))
        };
        let p = predict(&tuning, &plant, &plant, period, 0.1);
        // Direct simulation: u[k] = kp·e[k] + ki·T·Σ e (as the tuning's response models it:
        // kp + ki·T·z/(z − 1)), v[k+1] = v[k] + T/J·(u[k] + d).
        let simulate = |r: f64, d: f64| -> Vec<f64> {
            let (mut v, mut integral) = (0.0, 0.0);
            let mut out = Vec::new();
            for _ in 0..p.time.len() {
                out.push(v);
                let e = r - v;
                integral += tuning.ki * period * e;
                let u = tuning.kp * e + integral;
                v += period / j * (u + d);
            }
            out
        };
        let sim_command = simulate(1.0, 0.0);
        let sim_disturbance = simulate(0.0, 1.0);
        let worst = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
        assert!(worst(&p.command_step, &sim_command) < 1e-3, "{}", worst(&p.command_step, &sim_command));
        let scale = p.disturbance_peak;
        assert!(worst(&p.disturbance_step, &sim_disturbance) < 1e-3 * scale);
        assert!(
            (p.command_step.last().unwrap() - 1.0).abs() < 1e-3
                && p.disturbance_step.last().unwrap().abs() < 0.01 * scale
        );
        assert!(p.stable && p.settling_time_s > 0.0 && p.settling_time_s < 0.1 && p.overshoot_percent > 0.0);
        // Without the integrator the load step settles at 1/kp, as the simulation does.
        let p_only = VelocityTuning { ki: 0.0, ..tuning };
        let q = predict(&p_only, &plant, &plant, period, 0.1);
        assert!((q.disturbance_step.last().unwrap() - 1.0 / p_only.kp).abs() < 0.01 / p_only.kp);
        // Too short a span to settle: NaN, not the span; an unstable loop: no figures.
        let short = predict(&tuning, &plant, &plant, period, 0.002);
        assert!(short.settling_time_s.is_nan());
        let reckless = VelocityTuning { kp: 50.0, ..tuning };
        let u = predict(&reckless, &plant, &plant, period, 0.1);
        assert!(!u.stable && u.settling_time_s.is_nan() && u.disturbance_peak.is_nan());
    }
}
