//! The current loop's PI from the measured winding, for a stated bandwidth, and the step that
//! checks it.
//!
//! **Design.** Sampled every tick, a winding of resistance `R` and inductance `L` driven by a
//! voltage held over a tick follows `i[k+1] = a·i[k] + b·v[k]` with `a = e^{−RT/L}` and
//! `b = (1 − a)/R`; the drive's voltage of a tick is applied over the next one (one tick of
//! computation delay). The PI `u = kp·e + ki·T·Σe` is `C(z) = K·(z − a')/(z − 1)` with
//! `K = kp + ki·T` and its zero `a' = kp/K`. With the zero on the winding's pole (`a' = a`) the
//! loop is `g/(z·(z − 1))`, `g = K·b`, and the closed loop `g/(z² − z + g)`: one number sets
//! its bandwidth. Its magnitude at `θ = 2π·f·T` is `1/√2` where `g² − 2xg − (x² + y²) = 0`,
//! `x + jy = e^{2jθ} − e^{jθ}`, so `g = x + √(2x² + y²)`. Up to `f·T = 0.1` (1.6 kHz at a
//! 16 kHz tick) the step overshoots by under 1 %.
//!
//! **Check.** Steps of the q current, up and down, at rest on the rotor's d axis (held by the
//! d current); their mean response `s[k]` gives the closed loop's frequency response
//! `H(θ) = Σ (s[k] − s[k−1])·e^{−jθk}` (the step's increments are its impulse response), and
//! the measured bandwidth is where `|H|` falls to `1/√2` of its value at rest. The steps are
//! `STEP_SAMPLES` ticks long: eight time constants of the slowest loop allowed (`f·T ≥ 0.02`).

use core::f32::consts::TAU;

/// The d and q PIs' gains (V/A, V/(A·s)) for a winding of `resistance` (Ω) and `inductance`
/// (H) sampled every `tick` (s), for a closed-loop bandwidth of `bandwidth_hz`.
pub fn design(resistance: f32, inductance: f32, tick: f32, bandwidth_hz: f32) -> (f32, f32) {
    let theta = TAU * bandwidth_hz * tick;
    let (s1, c1) = crate::trigonometry::sin_cos(theta);
    let (s2, c2) = crate::trigonometry::sin_cos(2.0 * theta);
    let (x, y) = (c2 - c1, s2 - s1);
    let g = x + libm::sqrtf(2.0 * x * x + y * y);
    let a = libm::expf(-resistance * tick / inductance);
    let k = g * resistance / (1.0 - a);
    (k * a, k * (1.0 - a) / tick)
}

/// Samples of each step's response kept.
pub const STEP_SAMPLES: usize = 64;

/// The mean response of the steps, normalised by each step's size.
#[derive(Clone, Copy, Debug)]
pub struct StepResponse {
    sum: [f32; STEP_SAMPLES],
    steps: u32,
}

impl Default for StepResponse {
    fn default() -> Self {
        Self { sum: [0.0; STEP_SAMPLES], steps: 0 }
    }
}

/// What the step found.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct StepCheck {
    /// The closed loop's bandwidth (Hz).
    pub bandwidth_hz: f32,
    /// The step's largest value over its settled value, less one (0: none).
    pub overshoot: f32,
}

impl StepResponse {
    /// Sample `k` after a step (0: the first reading after the reference changed) of the
    /// current's change from before the step over the step's size.
    pub fn add(&mut self, k: usize, change: f32) {
        if let Some(s) = self.sum.get_mut(k) {
            *s += change;
        }
    }

    pub fn end_step(&mut self) {
        self.steps += 1;
    }

    fn mean(&self, k: usize) -> f32 {
        self.sum[k] / self.steps.max(1) as f32
    }

    /// The settled value: the mean of the last eighth.
    pub fn settled(&self) -> f32 {
        let tail = STEP_SAMPLES / 8;
        (STEP_SAMPLES - tail..STEP_SAMPLES).map(|k| self.mean(k)).sum::<f32>() / tail as f32
    }

    /// `|H(θ)|` over its value at rest. The sum's phasor `e^{−jθk}` is turned by `e^{−jθ}` from
    /// one sample to the next (one sine and cosine a call, in f32 only: `libm`'s evaluate in
    /// f64, which the Cortex-M4F does in software, and one pair a sample took a quarter of a
    /// million instructions in one tick); over the 64 samples it drifts by a few parts in
    /// 10⁶.
    pub fn gain_at(&self, theta: f32) -> f32 {
        let (mut re, mut im, mut last) = (0.0f32, 0.0f32, 0.0f32);
        let (turn_sin, turn_cos) = crate::trigonometry::sin_cos(theta);
        let (mut sin, mut cos) = (0.0f32, 1.0f32);
        for k in 0..STEP_SAMPLES {
            let s = self.mean(k);
            let h = s - last;
            last = s;
            re += h * cos;
            im -= h * sin;
            (sin, cos) = (sin * turn_cos + cos * turn_sin, cos * turn_cos - sin * turn_sin);
        }
        libm::sqrtf(re * re + im * im) / self.settled()
    }

    pub fn overshoot(&self) -> f32 {
        let peak = (0..STEP_SAMPLES).map(|k| self.mean(k)).fold(f32::MIN, f32::max);
        (peak / self.settled() - 1.0).max(0.0)
    }
}

/// A bisection for the frequency where the step's gain falls to `1/√2`, one evaluation a tick
/// (each is `STEP_SAMPLES` terms: the drive's tick has no room for the whole search).
#[derive(Clone, Copy, Debug)]
pub struct BandwidthSearch {
    /// Bracket (rad per tick): the gain above `1/√2` at `low`, below at `high`.
    low: f32,
    high: f32,
    evaluations: u32,
}

/// Bisections: the bracket's width over 2²⁰.
const BISECTIONS: u32 = 20;

impl BandwidthSearch {
    /// A search over `[target/4, 4·target]` (Hz) at `tick` (s).
    pub fn new(target_hz: f32, tick: f32) -> Self {
        let theta = TAU * target_hz * tick;
        Self { low: 0.25 * theta, high: (4.0 * theta).min(core::f32::consts::PI), evaluations: 0 }
    }

    /// One evaluation; the bandwidth (Hz) once the bracket is narrow, `Err` when the gain at
    /// the bracket's ends does not cross `1/√2` (no bandwidth within a factor of 4 of the
    /// target).
    pub fn step(&mut self, response: &StepResponse, tick: f32) -> Option<Result<f32, ()>> {
        let half_power = core::f32::consts::FRAC_1_SQRT_2;
        // No response at all (nothing settled), or one that is not a number: no bandwidth.
        if !(response.settled().is_finite() && response.settled() > 0.0) {
            return Some(Err(()));
        }
        if self.evaluations == 0 {
            self.evaluations = 1;
            return (!(response.gain_at(self.low) >= half_power)).then_some(Err(()));
        }
        if self.evaluations == 1 {
            self.evaluations = 2;
            return (!(response.gain_at(self.high) <= half_power)).then_some(Err(()));
        }
        let middle = 0.5 * (self.low + self.high);
        if response.gain_at(middle) > half_power {
            self.low = middle;
        } else {
            self.high = middle;
        }
        self.evaluations += 1;
        (self.evaluations >= BISECTIONS + 2).then(|| Ok(0.5 * (self.low + self.high) / (TAU * tick)))
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;

    /// The designed loop on the exact sampled winding with one tick of delay: its step's
    /// bandwidth is the target, its overshoot under 1 %, over windings from a time constant of
    /// a third of a tick to thousands of ticks and targets to a tenth of the tick rate.
    #[test]
    fn the_designed_loop_has_the_target_bandwidth_on_the_sampled_winding() {
        let tick = 1.0 / 16_000.0;
        for (r, l) in [(0.3f64, 0.5e-3f64), (10.0, 20e-3), (0.05, 10e-3), (3.0, 62.5e-6)] {
            for target in [320.0f32, 1000.0, 1600.0] {
                let (kp, ki) = design(r as f32, l as f32, tick, target);
                let a = (-r * tick as f64 / l).exp();
                let b = (1.0 - a) / r;
                let mut response = StepResponse::default();
                let (mut i, mut integral, mut pending) = (0.0f64, 0.0f64, 0.0f64);
                for k in 0..STEP_SAMPLES {
                    // Read, compute, and apply over the next tick.
                    response.add(k, i as f32);
                    let e = 1.0 - i;
                    integral += ki as f64 * tick as f64 * e;
                    let v = kp as f64 * e + integral;
                    i = a * i + b * pending;
                    pending = v;
                }
                response.end_step();
                let mut search = BandwidthSearch::new(target, tick);
                let found = loop {
                    if let Some(r) = search.step(&response, tick) {
                        break r.unwrap();
                    }
                };
                assert!((found / target - 1.0).abs() < 0.02, "R {r} L {l} target {target}: {found}");
                assert!(response.overshoot() < 0.01, "{}", response.overshoot());
            }
        }
    }
}
