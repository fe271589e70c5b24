//! A q-axis winding's inductance when its current turns the rotor. The q current makes torque
//! and the rotor, held only by the d current's pull, turns with it: its back-EMF `ψ·p·ω`
//! follows the current's integral (`J·dω/dt = k_t·i`), a series capacitance `1/κ` with
//! `κ = 1.5·p²·ψ²/J`. On a light rotor with a strong magnet its reactance matches the
//! winding's within the chips' band, and a first-order fit ([`super::winding_fit`]) reads
//! the pair as an inductance tens of percent short and a resistance twice the winding's.
//!
//! The branch `R + sL + κ/s` sampled every tick, its voltage held over each tick, is exactly
//! second order: `i[k+1] = (p₁ + p₂)·i[k] − p₁p₂·i[k−1] + c·(v[k] − v[k−1])` (the voltage of a
//! tick applied over the next one, `v[k]` over the tick ending at `i[k+1]`), with `p₁`, `p₂`
//! the poles `e^{s·T}` of `L·s² + R·s + κ` and `c = (p₁ − p₂)/(L·(s₁ − s₂))`. A least-squares
//! fit of that recursion gives `L = T·(p₁ − p₂)/(c·(ln p₁ − ln p₂))` and `R = −L·(ln p₁ + ln
//! p₂)/T`, for real or complex poles; a rotor that does not move (`κ = 0`) puts one pole at 1
//! and leaves the first-order fit's answer. What it does not model — the d current's pull,
//! the rotor sticking on its friction at each reversal — acts mostly at the low end of the
//! chips' band, which [`FreeRotorFit::high_passed`] weighs less, and
//! [`FreeRotorFit::high_passed_twice`] less again.

use super::regression::Regression;
use super::winding_fit::Winding;

/// What the fit found: the winding and the rotor's motion beside it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Branch {
    pub winding: Winding,
    /// The rotor's mechanical time constant as the chips saw it (s): `R/κ`, the sum of the
    /// branch's two time constants (`−1/s₁ − 1/s₂`); `R·J/(1.5·p²·ψ²·sin²δ)` for a rotor
    /// standing `δ` from the chips' axis (the torque and the back-EMF along it both go with
    /// `sin δ`). Infinite for a rotor that does not move.
    pub time_constant: f32,
}

#[derive(Clone, Copy, Debug, Default)]
pub struct FreeRotorFit {
    /// The first current (the samples are taken relative to it).
    origin: Option<f32>,
    /// The two currents read before (the older one once there were two), and the voltage
    /// over the tick before.
    history: (Option<f32>, Option<f32>),
    last_voltage: f32,
    /// Regressors (i[k], i[k] − i[k−1], v[k] − v[k−1]) against y = i[k+1] − i[k].
    sums: Regression<3>,
    /// The sample before (current, voltage) at each stage of differencing.
    raw: [Option<(f32, f32)>; 2],
    /// How many times the samples are differenced before the fit (0: not high-passed).
    differences: u8,
}

impl FreeRotorFit {
    /// The fit of the samples' differences from one tick to the next (`i[k] − i[k−1]`,
    /// `v[k] − v[k−1]`): a linear branch's recursion holds for them as for the samples, and
    /// the difference weighs each frequency by `2·sin(πfT)`, so that what the model misses at
    /// low frequencies (a rotor that sticks on its friction and slips, a slow swing on the d
    /// current's pull) counts for less beside the chips' upper band, where the winding's
    /// inductance shows.
    pub fn high_passed() -> Self {
        Self { differences: 1, ..Self::default() }
    }

    /// The fit of the samples' second differences: each frequency weighed by `4·sin²(πfT)`,
    /// what the model misses at the chips' low and middle frequencies weighed less again (on
    /// a winding faster than a tick, whose current follows each chip within the tick, the
    /// sensors' noise stays small beside the current's changes; on a slow one it would not).
    pub fn high_passed_twice() -> Self {
        Self { differences: 2, ..Self::default() }
    }

    /// One tick: the current read now, and the voltage applied over the tick that ended with
    /// this reading.
    pub fn add(&mut self, current: f32, voltage: f32) {
        let (mut current, mut voltage) = (current, voltage);
        for raw in self.raw.iter_mut().take(self.differences as usize) {
            let Some((i, v)) = raw.replace((current, voltage)) else { return };
            (current, voltage) = (current - i, voltage - v);
        }
        let i0 = *self.origin.get_or_insert(current);
        // A row once three currents are known.
        if let (Some(before), Some(previous)) = self.history {
            self.sums.add([previous - i0, previous - before, voltage - self.last_voltage], current - previous);
        }
        self.history = (self.history.1, Some(current));
        self.last_voltage = voltage;
    }

    /// The winding at `tick` (s); `None` when the sums do not determine one (too few samples,
    /// no excitation, or poles no resistance–inductance–capacitance branch gives).
    pub fn winding(&self, tick: f32) -> Option<Winding> {
        self.branch(tick).map(|branch| branch.winding)
    }

    /// The winding and the rotor's motion beside it.
    pub fn branch(&self, tick: f32) -> Option<Branch> {
        self.branch_less_noise(tick, 0.0)
    }

    /// The branch with the bias of white sensor noise of `variance` (A², on the fitted axis's
    /// current) on every sample taken out.
    pub fn branch_less_noise(&self, tick: f32, variance: f32) -> Option<Branch> {
        if self.sums.samples() < 16.0 {
            return None;
        }
        // The noise's autocovariance at lags 0, 1, 2 once differenced as the samples are.
        let [r0, r1, r2] = match self.differences {
            0 => [1.0, 0.0, 0.0],
            1 => [2.0, -1.0, 0.0],
            _ => [6.0, -4.0, 1.0],
        }
        .map(|r: f32| r * variance);
        // Regressors e[k], e[k] − e[k−1] and the response e[k+1] − e[k] of the noise e.
        let noise_xx = [[r0, r0 - r1, 0.0], [r0 - r1, 2.0 * (r0 - r1), 0.0], [0.0; 3]];
        let noise_xy = [r1 - r0, 2.0 * r1 - r0 - r2, 0.0];
        // y = c0·i[k] + c1·(i[k] − i[k−1]) + c·Δv: c0 = −(1 − p₁)(1 − p₂), c1 = p₁p₂.
        let [c0, c1, c] = self.sums.coefficients_less(3, noise_xx, noise_xy)?;
        if !(c1 > 0.0 && c1 < 1.0 && c > 0.0) {
            return None;
        }
        let sum = 1.0 + c0 + c1;
        // (p₁ + p₂)² − 4p₁p₂, written so that a rotor at rest (c0 → 0) loses no digits.
        let discriminant = (1.0 - c1) * (1.0 - c1) + c0 * (2.0 * (1.0 + c1) + c0);
        let (inductance_times_c, log_sum, log_product) = if discriminant >= 0.0 {
            let root = libm::sqrtf(discriminant);
            let high = 0.5 * (sum + root);
            let low = c1 / high;
            if !(low > 0.0 && high > 0.0) {
                return None;
            }
            // ln p_high from 1 − p_high = −c0/(1 − p_low): exact near 1.
            let log_high = libm::log1pf(c0 / (1.0 - low));
            let log_low = libm::logf(low);
            let span = log_high - log_low;
            let ratio = if span > 1e-4 { root / span } else { high };
            (tick * ratio, log_high + log_low, log_high * log_low)
        } else {
            // Complex poles r·e^{±jθ}: L·c = T·r·sin θ/θ.
            let r = libm::sqrtf(c1);
            let theta = libm::acosf(crate::limit(0.5 * sum / r, -1.0, 1.0));
            let ratio = if theta > 1e-4 { crate::trigonometry::sin(theta) / theta } else { 1.0 };
            let log_r = libm::logf(r);
            (tick * r * ratio, 2.0 * log_r, log_r * log_r + theta * theta)
        };
        let inductance = inductance_times_c / c;
        let resistance = -inductance * log_sum / tick;
        // −(1/s₁ + 1/s₂) = −T·(ln p₁ + ln p₂)/(ln p₁·ln p₂): a pole at 1 (no motion) makes it
        // infinite, a pole outside the unit circle (no branch of this kind) negative.
        let time_constant = -tick * log_sum / log_product;
        let time_constant = if time_constant > 0.0 { time_constant } else { f32::INFINITY };
        (inductance > 0.0 && inductance.is_finite() && resistance > 0.0)
            .then_some(Branch { winding: Winding { inductance, resistance }, time_constant })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A resistance–inductance branch in series with a capacitance (a rotor's back-EMF), driven
    /// by ±1 V chips held over each tick and integrated finely: its L and R recovered from a
    /// rotor at rest (no capacitance) to one whose reactance matches the winding's at 2.3 kHz;
    /// the first-order fit is far off on the latter.
    #[test]
    fn a_winding_in_series_with_a_turning_rotor_is_fitted() {
        let tick = 62.5e-6f64;
        for (r, l, kappa) in [
            (1.176, 1.9e-4, 40_600.0),
            (1.176, 1.9e-4, 1085.0),
            (0.3, 6e-4, 1e4),
            (0.3, 6e-4, 0.0),
            (10.0, 1e-2, 0.0),
            (1.0, 2e-5, 5e3),
        ] {
            let mut fit = FreeRotorFit::default();
            let mut first_order = super::super::winding_fit::WindingFit::default();
            let mut chips = crate::m_sequence::MSequence::new(12).unwrap();
            let (mut i, mut q, mut v_prev, mut v) = (0.3f64, 0.0f64, 0.0f64, 0.0f64);
            let sub = 64;
            let h = tick / sub as f64;
            fit.add(i as f32 + 0.02, 0.0);
            for _ in 0..4095 {
                let before = i;
                for _ in 0..sub {
                    // Midpoint rule.
                    let di = (v_prev + 0.05 - r * i - kappa * q) / l;
                    let (im, qm) = (i + 0.5 * h * di, q + 0.5 * h * i);
                    q += h * im;
                    i += h * (v_prev + 0.05 - r * im - kappa * qm) / l;
                }
                fit.add(i as f32 + 0.02, v_prev as f32);
                first_order.add(before as f32, i as f32, v_prev as f32);
                v_prev = v;
                v = 1.0 + chips.next_chip() as f64;
            }
            let w = fit.winding(tick as f32).expect("a fit");
            assert!((w.inductance as f64 / l - 1.0).abs() < 0.01, "R {r} L {l} κ {kappa}: {w:?}");
            assert!((w.resistance as f64 / r - 1.0).abs() < 0.02, "R {r} L {l} κ {kappa}: {w:?}");
            // The motional time constant R/κ (a rotor at rest: far above a light rotor's).
            let time_constant = fit.branch(tick as f32).unwrap().time_constant as f64;
            if kappa > 0.0 {
                assert!((time_constant * kappa / r - 1.0).abs() < 0.05, "R {r} L {l} κ {kappa}: {time_constant} s");
            } else {
                assert!(time_constant > 0.1, "R {r} L {l}: {time_constant} s");
            }
            if kappa > 1e4 {
                let f = first_order.winding(tick as f32).unwrap();
                assert!((f.inductance as f64 / l - 1.0).abs() > 0.1, "{f:?}");
            }
        }
    }

    /// The inductance errors of the plain, high-passed and twice high-passed fits on a rotor
    /// held by the d current's pull (half the test current) under ±0.5·R·I chips, with
    /// Coulomb friction of `share` of the test current's torque: stuck while the drive stays
    /// within it, else sliding against it (integrated finely, the voltage held over each tick).
    fn sticking_rotor(r: f64, l: f64, p: f64, psi: f64, j: f64, share: f64) -> [f64; 3] {
        let (tick, test_current) = (62.5e-6f64, 2.0);
        let torque_constant = 1.5 * p * psi;
        let spring = 1.5 * p * p * psi * 0.5 * test_current;
        let coulomb = share * torque_constant * test_current;
        let mut fits = [FreeRotorFit::default(), FreeRotorFit::high_passed(), FreeRotorFit::high_passed_twice()];
        let mut chips = crate::m_sequence::MSequence::new(12).unwrap();
        let (mut i, mut w, mut angle, mut v_prev, mut v) = (0.0f64, 0.0f64, 0.0f64, 0.0f64, 0.0f64);
        let sub = 64;
        let h = tick / sub as f64;
        for _ in 0..4095 {
            for _ in 0..sub {
                let drive = torque_constant * i - spring * angle;
                let friction = if w != 0.0 { coulomb * w.signum() } else { drive.clamp(-coulomb, coulomb) };
                let w_next = w + h * (drive - friction) / j;
                w = if w != 0.0 && w_next.signum() != w.signum() { 0.0 } else { w_next };
                angle += h * w;
                // Exact over the sub-step for the winding (a fast one is stiff at this step).
                let settled = (v_prev - p * psi * w) / r;
                i = settled + (i - settled) * (-r * h / l).exp();
            }
            for fit in fits.iter_mut() {
                fit.add(i as f32, v_prev as f32);
            }
            v_prev = v;
            v = 0.5 * r * test_current * chips.next_chip() as f64;
        }
        fits.map(|fit| fit.winding(tick as f32).map_or(f64::INFINITY, |w| (w.inductance as f64 / l - 1.0).abs()))
    }

    /// A light rotor with a strong magnet (6 pole pairs, 82.6 mWb, 5.7·10⁻⁶ kg·m², a motor of
    /// `servo bench commission`) under chips whose q current makes about as much torque as
    /// the rotor's Coulomb friction: without friction the plain and high-passed fits hold the
    /// inductance within 0.2 %; with a twentieth of the test current's torque the rotor sticks
    /// and slips, and the high-passed fit's error is at most 60 % of the plain fit's (3.6 %
    /// against 6.7 % here; `servo bench commission` measures the sequence on the drawn
    /// motors).
    #[test]
    fn a_rotor_that_sticks_and_slips_is_fitted_better_high_passed() {
        let (r, l, p, psi, j) = (0.379, 1.26e-4, 6.0, 0.0826, 5.74e-6);
        let [free_plain, free_high_passed, _] = sticking_rotor(r, l, p, psi, j, 0.0);
        let [sticking_plain, sticking_high_passed, _] = sticking_rotor(r, l, p, psi, j, 0.05);
        assert!(free_high_passed < 0.002 && free_plain < 0.002, "{free_plain} {free_high_passed}");
        assert!(
            sticking_plain > 0.03 && sticking_high_passed < 0.6 * sticking_plain,
            "{sticking_plain} {sticking_high_passed}"
        );
    }

    /// A winding faster than a tick (0.4 of one: 5.6 Ω, 143 µH) on a light rotor with a strong
    /// magnet (5 pole pairs, 89.9 mWb, 3.9·10⁻⁶ kg·m², a motor of `servo bench commission`)
    /// that sticks and slips on a twentieth of the test current's torque: the second
    /// differences hold the inductance within 3 % and closer than the first (1.9 % against
    /// 3.4 % here), the plain fit is off by more than 5 % (9.3 %); without friction all three
    /// hold it within 1 %.
    #[test]
    fn a_fast_winding_on_a_sticking_rotor_is_fitted_on_second_differences() {
        let (r, l, p, psi, j) = (5.63, 1.43e-4, 5.0, 0.0899, 3.9e-6);
        let free = sticking_rotor(r, l, p, psi, j, 0.0);
        assert!(free.iter().all(|e| *e < 0.01), "{free:?}");
        let [plain, once, twice] = sticking_rotor(r, l, p, psi, j, 0.05);
        assert!(plain > 0.05 && twice < 0.03 && twice < once, "{plain} {once} {twice}");
    }

    #[test]
    fn no_excitation_fits_nothing() {
        let mut fit = FreeRotorFit::default();
        for _ in 0..100 {
            fit.add(1.0, 0.5);
        }
        assert_eq!(fit.winding(62.5e-6), None);
    }

    /// A slow winding (0.069 Ω, 495 µH: 114 ticks) in series with a light rotor's motion
    /// (κ = 4 600 Ω/s, a 15 µs rotor), under ±0.32 V chips, its current read with 2 mA of white
    /// noise and fitted high-passed: the noise, in the regressors and the response alike,
    /// reads the plain fit's resistance several times the winding's (5.5 times here), which
    /// the sequence's choice between its fits goes by; with the noise's variance taken out,
    /// the resistance is within a fifth (5 % here) and the inductance within 0.5 %.
    #[test]
    fn the_sensors_noise_is_taken_out_of_a_slow_windings_fit() {
        let (tick, r, l, kappa, sigma) = (62.5e-6f64, 0.069, 4.95e-4, 4600.0, 0.002f64);
        let mut fit = FreeRotorFit::high_passed();
        let mut chips = crate::m_sequence::MSequence::new(12).unwrap();
        let mut noise = super::super::motor_model::Gaussian::new(0x9E37_79B9_7F4A_7C15);
        let (mut i, mut q, mut v) = (0.0f64, 0.0f64, 0.0f64);
        let sub = 64;
        let h = tick / sub as f64;
        for _ in 0..2 * 4095 {
            for _ in 0..sub {
                let di = (v - r * i - kappa * q) / l;
                let (im, qm) = (i + 0.5 * h * di, q + 0.5 * h * i);
                q += h * im;
                i += h * (v - r * im - kappa * qm) / l;
            }
            fit.add((i + sigma * noise.next()) as f32, v as f32);
            v = 0.32 * chips.next_chip() as f64;
        }
        let plain = fit.branch(tick as f32).unwrap().winding;
        let less = fit.branch_less_noise(tick as f32, (sigma * sigma) as f32).unwrap().winding;
        let off = |got: f32, want: f64| (got as f64 / want - 1.0).abs();
        assert!(off(plain.resistance, r) > 2.0, "{plain:?}");
        assert!(off(less.inductance, l) < 0.005 && off(less.resistance, r) < 0.2, "{less:?} (plain {plain:?})");
    }
}
