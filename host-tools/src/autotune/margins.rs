//! Stability margins of a velocity loop from its open loop `L = C·P` on a frequency grid:
//! the phase margin at each gain crossover, the gain margin at each phase crossover of
//! −180°, the sensitivity peak `Ms = max |1/(1 + L)|`, the closed loop's bandwidth (where
//! `|L/(1 + L)|` first falls below −3 dB), and whether the closed loop is stable.
//!
//! **Stability.** The loop has two poles at `z = 1` (the PI's integrator and the machine's
//! rigid body) and no others outside the unit circle; by the argument principle its closed
//! loop is stable exactly when the phase of `1 + L` turns by +180° from 0 Hz (where `L ≈
//! −K/ω²`, on the negative real axis) to the highest frequency (where `L` is small). The
//! grid must be fine enough that the phase of `1 + L` moves by less than 90° between
//! neighbours (checked: a coarser grid is refused), and run from well below the crossover to
//! the loop's Nyquist frequency.

use num_complex::Complex64;
use serde::Serialize;

/// What a loop's margins are (degrees, dB, Hz).
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Margins {
    pub stable: bool,
    /// The smallest phase margin over the gain crossovers, the angle from `L` to −1 there
    /// (180 where there is none).
    pub phase_margin_deg: f64,
    /// The first gain crossover (Hz).
    pub crossover_hz: f64,
    /// The smallest gain margin over the phase crossovers with `|L| < 1` (infinite if none).
    pub gain_margin_db: f64,
    pub gain_margin_hz: f64,
    pub sensitivity_peak: f64,
    pub sensitivity_peak_hz: f64,
    /// The closed loop's −3 dB frequency (Hz).
    pub bandwidth_hz: f64,
}

/// The margins of `loop_gain` sampled at `frequencies` (Hz, increasing); `None` when the grid
/// is too coarse to follow the phase of `1 + L`. The loop has two integrators (the velocity
/// loop's: the PI's and the rigid body's); [`margins_with_integrators`] takes another count.
pub fn margins(frequencies: &[f64], loop_gain: &[Complex64]) -> Option<Margins> {
    margins_with_integrators(frequencies, loop_gain, 2)
}

/// [`margins`] of a loop with `integrators` poles at `z = 1` and no other unstable pole (the
/// position loop around a stable velocity loop has one): its closed loop is stable exactly
/// when the phase of `1 + L` turns by `integrators · 90°` from the lowest frequency, where it
/// starts at `−integrators · 90°`, to the highest.
pub fn margins_with_integrators(frequencies: &[f64], loop_gain: &[Complex64], integrators: u32) -> Option<Margins> {
    assert_eq!(frequencies.len(), loop_gain.len());
    let n = frequencies.len();
    if n < 2 {
        return None;
    }
    let mut m = Margins {
        stable: false,
        phase_margin_deg: 180.0,
        crossover_hz: f64::NAN,
        gain_margin_db: f64::INFINITY,
        gain_margin_hz: f64::NAN,
        sensitivity_peak: 0.0,
        sensitivity_peak_hz: f64::NAN,
        bandwidth_hz: f64::NAN,
    };
    // The phase of 1 + L, unwrapped, counted from −integrators · 90° (where the integrators
    // put it as the frequency goes to 0; below the grid's first point |L| ≫ 1 and it turns
    // from there to its first value without wrapping).
    let quarter_turns = integrators as f64 * std::f64::consts::FRAC_PI_2;
    let mut last = (1.0 + loop_gain[0]).arg();
    let mut turned = wrap(last + quarter_turns);
    // `|1 + L|²` at the sensitivity peak so far: a point whose `|1 + L|²` lies clearly above
    // it cannot be a new peak, and its root and reciprocal are not taken (the search
    // evaluates millions of loops; the peak found is the same, bit for bit).
    let mut peak_norm_sqr = f64::INFINITY;
    for k in 0..n {
        let l = loop_gain[k];
        let f = frequencies[k];
        let one_plus = 1.0 + l;
        if k > 0 {
            let arg = one_plus.arg();
            let step = wrap(arg - last);
            if step.abs() > 0.5 * std::f64::consts::PI {
                return None;
            }
            turned += step;
            last = arg;
        }
        let d = one_plus.norm_sqr();
        if !(d > peak_norm_sqr * CLEARLY) {
            let s = 1.0 / one_plus.norm();
            if !(s <= m.sensitivity_peak) {
                m.sensitivity_peak = s;
                m.sensitivity_peak_hz = f;
                peak_norm_sqr = d;
            }
        }
        // `|L/(1 + L)|² = |L|²/|1 + L|²` against a half: only near it is the ratio taken.
        if m.bandwidth_hz.is_nan()
            && !(l.norm_sqr() > 0.5 * d * CLEARLY)
            && (l / one_plus).norm() < std::f64::consts::FRAC_1_SQRT_2
        {
            m.bandwidth_hz = f;
        }
        if k == 0 {
            continue;
        }
        let (a, b) = (loop_gain[k - 1], l);
        if let Some((x, margin)) = gain_crossover(a, b) {
            if m.crossover_hz.is_nan() {
                m.crossover_hz = frequencies[k - 1] * (frequencies[k] / frequencies[k - 1]).powf(x);
            }
            m.phase_margin_deg = m.phase_margin_deg.min(margin);
        }
        // A phase crossover of −180° (L crossing the negative real axis).
        if (a.im >= 0.0) != (b.im >= 0.0) {
            let x = a.im / (a.im - b.im);
            let at = a + x * (b - a);
            if at.re < 0.0 && at.norm() < 1.0 {
                let db = -20.0 * at.norm().log10();
                if db < m.gain_margin_db {
                    m.gain_margin_db = db;
                    m.gain_margin_hz = frequencies[k - 1] * (frequencies[k] / frequencies[k - 1]).powf(x);
                }
            }
        }
    }
    m.stable = (turned - quarter_turns).abs() < 0.5 * std::f64::consts::PI;
    Some(m)
}

/// On a grid too sparse for [`margins`] (a measured sweep's points): the smallest phase
/// margin over the gain crossovers between neighbouring points and the largest
/// `|1/(1 + L)|` over the points. The phase margin is NaN where no crossover lies between
/// the points (a loop whose crossover was not measured has not shown its margin), and both
/// are NaN when there are no points.
pub fn crossover_margins(frequencies: &[f64], loop_gain: &[Complex64]) -> (f64, f64) {
    if loop_gain.is_empty() || frequencies.len() != loop_gain.len() {
        return (f64::NAN, f64::NAN);
    }
    let pm = loop_gain
        .windows(2)
        .filter_map(|p| gain_crossover(p[0], p[1]))
        .map(|(_, m)| m)
        .reduce(f64::min)
        .unwrap_or(f64::NAN);
    let ms = loop_gain.iter().map(|l| 1.0 / (1.0 + l).norm()).fold(0.0, f64::max);
    (pm, ms)
}

/// A gain crossover between two neighbouring points `a`, `b` of `L` (either way): where it
/// lies between them (0 to 1, interpolated in log |L|) and its phase margin, the angle from
/// `L` to −1 on the unit circle, `180° − |∠L|` (∠L within ±180°: a crossover in a notch's
/// phase lead lies far from −1, whichever side).
fn gain_crossover(a: Complex64, b: Complex64) -> Option<(f64, f64)> {
    // Both points clearly on one side of the unit circle: no crossover, without the roots and
    // logarithms (the same answer as the test below, which decides near the circle).
    let (na, nb) = (a.norm_sqr(), b.norm_sqr());
    if (na > CLEARLY && nb > CLEARLY) || (na * CLEARLY < 1.0 && nb * CLEARLY < 1.0) {
        return None;
    }
    let (ga, gb) = (a.norm().ln(), b.norm().ln());
    if (ga >= 0.0) == (gb >= 0.0) {
        return None;
    }
    let x = ga / (ga - gb);
    let phase = a.arg() + x * wrap(b.arg() - a.arg());
    Some((x, 180.0 - wrap(phase).to_degrees().abs()))
}

/// A factor past every rounding of a root or a square (a few parts in 10¹⁶): a squared
/// magnitude this far beyond a bound lies beyond it whichever way the magnitude is computed.
const CLEARLY: f64 = 1.0 + 1e-9;

fn wrap(x: f64) -> f64 {
    (x + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI
}

/// `n` frequencies log-spaced from `low` to `high` Hz.
pub fn log_grid(low: f64, high: f64, n: usize) -> Vec<f64> {
    (0..n).map(|k| low * (high / low).powf(k as f64 / (n - 1) as f64)).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A continuous PI on a rigid body with a pure delay: its margins against the closed
    /// forms (crossover where |L| = 1, phase margin 180° − 90° − 90° + atan(ω/ωi) − ωτ, gain
    /// margin from the delay's −180° point), stable; with the gain raised past the delay's
    /// limit it is unstable.
    #[test]
    fn margins_of_a_pi_on_a_rigid_body_with_a_delay_match_the_closed_forms() {
        let (j, wi, tau) = (1e-3f64, 2.0 * std::f64::consts::PI * 10.0, 200e-6);
        // The loop of gain `kp` on the grid `f`.
        let loop_on = |f: &[f64], kp: f64| -> Vec<Complex64> {
            f.iter()
                .map(|&f| {
                    let s = Complex64::new(0.0, std::f64::consts::TAU * f);
                    kp * (1.0 + wi / s) / (j * s) * (-s * tau).exp()
                })
                .collect()
        };
        let f = log_grid(0.1, 4000.0, 20_000);
        let kp = 0.5;
        let m = margins(&f, &loop_on(&f, kp)).unwrap();
        assert!(m.stable, "{m:?}");
        // |L| = 1: kp·√(1 + (ωi/ω)²)/(Jω) = 1.
        let wc = {
            let mut w = kp / j;
            for _ in 0..50 {
                w = kp * (1.0 + (wi / w).powi(2)).sqrt() / j;
            }
            w
        };
        assert!((m.crossover_hz / (wc / std::f64::consts::TAU) - 1.0).abs() < 1e-3, "{m:?}");
        let pm = 90.0 - (wi / wc).atan().to_degrees() - (wc * tau).to_degrees();
        assert!((m.phase_margin_deg - pm).abs() < 0.05, "{m:?} vs {pm}");
        assert!(m.gain_margin_db > 6.0 && m.gain_margin_db.is_finite(), "{m:?}");
        assert!(m.sensitivity_peak > 1.0 && m.bandwidth_hz > m.crossover_hz, "{m:?}");
        let unstable = margins(&f, &loop_on(&f, kp * 20.0)).unwrap();
        assert!(!unstable.stable, "{unstable:?}");
        // Too coarse a grid to follow the phase: refused.
        let coarse = log_grid(0.1, 4000.0, 4);
        assert!(margins(&coarse, &loop_on(&coarse, kp)).is_none());
        // The sparse grid's crossover margin: the dense one's within the interpolation.
        let sparse = log_grid(0.1, 4000.0, 60);
        let (pm_sparse, ms_sparse) = crossover_margins(&sparse, &loop_on(&sparse, kp));
        assert!((pm_sparse - m.phase_margin_deg).abs() < 2.0 && ms_sparse <= m.sensitivity_peak + 1e-9, "{pm_sparse}");
        // Points all above the crossover show no margin: NaN, not a pass.
        let above = log_grid(10.0 * m.crossover_hz, 4000.0, 20);
        assert!(crossover_margins(&above, &loop_on(&above, kp)).0.is_nan());
    }
}
