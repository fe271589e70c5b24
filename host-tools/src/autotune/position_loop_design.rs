//! The position loop's gain and feed-forward, designed around the tuned velocity loop.
//!
//! The drive's position loop is a P controller with velocity feed-forward
//! (`control_core::position_loop`): velocity reference = `kp · (command − position) + ff ·
//! d(command)/dt`, computed every position period and held over the velocity loop's ticks
//! until the next. The loop it closes is
//! `L = kp · H(f) · T(f) / (j2πf · E(f))`:
//! - `T` the closed velocity loop, velocity reference → velocity estimate, on the calibrated
//!   model with the tuning;
//! - `E` the velocity estimate's mean over its period (`DriveDynamics::velocity_estimate`):
//!   the position is the true velocity's integral, the estimate its mean;
//! - `H` the reference's hold over the position period's velocity ticks.
//!
//! The gain is the largest of a log ladder whose loop keeps the same margins as the velocity
//! loop (with the full reserve) and is stable; the feed-forward is 1 (the whole command
//! speed: no following error at a constant speed, the feedback left to correct only what the
//! velocity loop does not follow).

use num_complex::Complex64;
use serde::Serialize;

use super::design::MarginGoal;
use super::margins::{log_grid, margins_with_integrators, Margins};

/// Lowest and highest gain tried (1/s), and the ladder's steps between them.
const GAINS: (f64, f64, usize) = (1.0, 1.0e4, 161);
/// Frequencies the position loop's margins are read at, up to its Nyquist frequency.
const GRID_POINTS: usize = 1500;

#[derive(Clone, Copy, Debug, Serialize, PartialEq)]
pub struct PositionTuning {
    /// rad/s of velocity reference per rad of error (1/s).
    pub kp: f64,
    /// Share of the command's speed fed forward (0–1).
    pub velocity_feedforward: f64,
    /// The loop's margins on the model (its bandwidth: the feedback's alone, without the
    /// feed-forward).
    pub margins: Margins,
}

impl PositionTuning {
    /// The FMU parameters (and `--set` names) that give this tuning.
    pub fn parameters(&self) -> [(String, f64); 2] {
        [
            ("ctrl.position_kp".to_string(), self.kp),
            ("ctrl.velocity_feedforward".to_string(), self.velocity_feedforward),
        ]
    }
}

/// The position loop's rates: its period, and how many velocity periods it holds the
/// reference for.
#[derive(Clone, Copy, Debug)]
pub struct PositionRates {
    pub period: f64,
    pub velocity_period: f64,
}

impl PositionRates {
    pub fn of(params: &control_core::Params) -> Self {
        let r = params.rates;
        Self { period: r.position_period() as f64, velocity_period: r.velocity_period() as f64 }
    }

    /// The mean of the delays over the held velocity ticks.
    fn hold(&self, f: f64) -> Complex64 {
        let n = (self.period / self.velocity_period).round().max(1.0) as usize;
        let z1 = Complex64::from_polar(1.0, -std::f64::consts::TAU * f * self.velocity_period);
        let mut sum = Complex64::new(0.0, 0.0);
        let mut zk = Complex64::new(1.0, 0.0);
        for _ in 0..n {
            sum += zk;
            zk *= z1;
        }
        sum / n as f64
    }
}

/// The position loop per unit gain at `f`: `H · T / (j2πf · E)`.
pub fn position_loop_per_gain(
    velocity_closed_loop: &dyn Fn(f64) -> Complex64,
    velocity_estimate: &dyn Fn(f64) -> Complex64,
    rates: &PositionRates,
    f: f64,
) -> Complex64 {
    let jw = Complex64::new(0.0, std::f64::consts::TAU * f);
    rates.hold(f) * velocity_closed_loop(f) / (jw * velocity_estimate(f))
}

/// The margins of the position loop of gain `kp` (1/s) over the design grid.
pub fn position_margins(per_gain: &dyn Fn(f64) -> Complex64, rates: &PositionRates, kp: f64) -> Option<Margins> {
    let f = log_grid(0.1, 0.999 * 0.5 / rates.period, GRID_POINTS);
    let l: Vec<Complex64> = f.iter().map(|&f| kp * per_gain(f)).collect();
    margins_with_integrators(&f, &l, 1)
}

/// The widest-gain position loop that keeps `goal` around the velocity loop `per_gain`
/// describes; `None` when no gain of the ladder does.
pub fn design_position_loop(
    per_gain: &dyn Fn(f64) -> Complex64,
    rates: &PositionRates,
    goal: &MarginGoal,
) -> Option<PositionTuning> {
    let (low, high, steps) = GAINS;
    // The per-unit-gain loop sampled once; each gain scales it.
    let f = log_grid(0.1, 0.999 * 0.5 / rates.period, GRID_POINTS);
    let unit: Vec<Complex64> = f.iter().map(|&f| per_gain(f)).collect();
    log_grid(low, high, steps)
        .into_iter()
        .filter_map(|kp| {
            let l: Vec<Complex64> = unit.iter().map(|u| kp * u).collect();
            margins_with_integrators(&f, &l, 1).filter(|m| m.stable && goal.held_by(m)).map(|m| (kp, m))
        })
        .next_back()
        .map(|(kp, margins)| PositionTuning { kp, velocity_feedforward: 1.0, margins })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Around an ideal velocity loop (T = 1, no delay: L = kp/(j2πf)), every gain keeps
    /// 90° of phase margin and Ms = 1, so the design takes the ladder's top; around a velocity
    /// loop of bandwidth fb (T = 1/(1 + jf/fb)), L = kp/(jω(1 + jω/ωb)) is a second-order
    /// loop whose phase margin reaches 45° + reserve at the analytic crossover: the design's
    /// gain lies within one ladder step below that gain, and the next step misses.
    #[test]
    fn the_gain_meets_the_analytic_margin_of_a_first_order_velocity_loop() {
        let rates = PositionRates { period: 1.0 / 4000.0, velocity_period: 1.0 / 8000.0 };
        let one = |_: f64| Complex64::new(1.0, 0.0);
        let ideal = |f: f64| position_loop_per_gain(&one, &one, &PositionRates { period: 1e-6, ..rates }, f);
        let goal = MarginGoal::named("standard").unwrap().with_reserve(crate::autotune::reserve::Reserve::Full);
        let top = design_position_loop(&ideal, &PositionRates { period: 1e-6, ..rates }, &goal);
        assert!(top.is_some_and(|t| t.margins.phase_margin_deg > 89.0));
        let fb = 100.0;
        let first_order = |f: f64| Complex64::new(1.0, 0.0) / Complex64::new(1.0, f / fb);
        let no_hold = PositionRates { period: 1e-5, velocity_period: 1e-5 };
        let per_gain = |f: f64| position_loop_per_gain(&first_order, &one, &no_hold, f);
        let t = design_position_loop(&per_gain, &no_hold, &goal).unwrap();
        // PM = 90° − atan(ωc/ωb) ⇒ ωc = ωb·tan(90° − PM); |L(ωc)| = 1 ⇒ kp = ωc·√(1 + (ωc/ωb)²).
        let pm = goal.phase_margin_deg.to_radians();
        let wb = std::f64::consts::TAU * fb;
        let wc = wb * (std::f64::consts::FRAC_PI_2 - pm).tan();
        let kp_pm = wc * (1.0 + (wc / wb).powi(2)).sqrt();
        // Ms may bind first: the design is no higher than the phase margin allows.
        let step = (GAINS.1 / GAINS.0).powf(1.0 / (GAINS.2 - 1) as f64);
        assert!(t.kp <= kp_pm * 1.001, "kp {} above the phase margin's {kp_pm}", t.kp);
        let next = position_margins(&per_gain, &no_hold, t.kp * step).unwrap();
        assert!(!goal.held_by(&next), "the next step {} still holds: {next:?}", t.kp * step);
        // Here the phase margin binds (Ms of a 48° second-order loop is below 1.55).
        assert!(t.kp * step > kp_pm * 0.999, "kp {}, analytic {kp_pm}", t.kp);
        assert!(t.margins.stable && goal.held_by(&t.margins));
        assert_eq!(t.velocity_feedforward, 1.0);
    }

    /// One integrator counted right: `kp/(jω)` with a pure delay is stable below the gain
    /// that puts its phase crossover at −1, unstable above.
    #[test]
    fn a_delayed_integrator_is_stable_below_its_critical_gain_only() {
        let delay = 1e-3;
        let loop_at = |kp: f64| {
            let f = log_grid(0.1, 499.0, 3000);
            let l: Vec<Complex64> = f
                .iter()
                .map(|&f| {
                    let w = std::f64::consts::TAU * f;
                    kp * Complex64::from_polar(1.0, -w * delay) / Complex64::new(0.0, w)
                })
                .collect();
            margins_with_integrators(&f, &l, 1).unwrap()
        };
        // Critical: phase −180° at ω·delay = π/2, |L| = 1 there ⇒ kp = π/(2·delay).
        let critical = std::f64::consts::FRAC_PI_2 / delay;
        assert!(loop_at(0.8 * critical).stable);
        assert!(!loop_at(1.25 * critical).stable);
    }
}
