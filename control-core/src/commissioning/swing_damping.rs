//! Damping of the rotor's swing on the commissioning vector.
//!
//! Held on a vector, the rotor is a mass on the magnet's spring (`1.5·p²·ψ·I` per mechanical
//! radian). A machine with little friction (a load on a soft shaft, an absorber) keeps
//! swinging, and its back-EMF then biases what the holds and the passes measure. A winding
//! fed by a voltage damps that swing by itself: the back-EMF drives a current against the
//! motion (`i_q = −e_q/R`, a torque `−1.5·p²·ψ²·cos²δ·ω/R`, near critical damping on a servo
//! motor). The sequence's current loop is stiff and rejects that back-EMF, so while the vector
//! is held (the current's ramp and the first hold's settling) the damping is put back: the q
//! back-EMF is estimated from the loop's own voltage and current (`e_q = v_q − R·i_q −
//! L·di_q/dt`, less the `ω·L·i_d` of a frame that turns, low-passed) and the q current asked
//! for is `−e_q/R`, within a share of the
//! test current (the loop keeps the current within it however fast the rotor swings).
//! A winding's damping can be far beyond critical (a strong magnet on a small resistance and
//! a light rotor): the rotor then creeps to the vector for tenths of a second, and a creeping
//! rotor's back-EMF would bias the holds. So the damping stops shortly before the first hold
//! waits for a still rotor: a rotor still creeping (held off the vector by the damping's own
//! current) then takes the rest of the way at once, which the wait sees, and friction or the
//! damping before has left it little to swing with. The passes that turn the vector start from a
//! rotor at rest and are not damped: their smooth start and stop excite little swing, and a
//! damping current's transient as the turn's back-EMF rises would drag the rotor more.

use core::f32::consts::TAU;

/// The estimate's low-pass (Hz): above the swing, below the current loop (at most a fifth of
/// its bandwidth) and below half the winding's corner `R/L` (an inductance misread by the
/// probe then leaves the estimate's own loop a gain under one).
const ESTIMATE_HZ: f32 = 200.0;
const ESTIMATE_SHARE_OF_LOOP: f32 = 0.2;
const ESTIMATE_SHARE_OF_WINDING: f32 = 0.5;
/// The damping current's limit (a share of the test current).
const CURRENT_SHARE: f32 = 0.4;

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SwingDamping {
    resistance: f32,
    inductance: f32,
    limit: f32,
    /// The q voltage that drove the current from the last reading to this one (asked for two
    /// calls before), the one asked for on the last call, and the last reading's q current.
    applied: f32,
    asked: f32,
    last_current: Option<f32>,
    /// The low-pass's gain per tick and the filtered back-EMF estimate (V).
    smoothing: f32,
    estimate: f32,
}

impl SwingDamping {
    /// For a winding of `resistance` and `inductance` under a current loop of
    /// `loop_bandwidth_hz` ticking every `tick` s, the damping current within a share of
    /// `test_current`.
    pub(super) fn new(resistance: f32, inductance: f32, test_current: f32, loop_bandwidth_hz: f32, tick: f32) -> Self {
        let corner = (TAU * ESTIMATE_HZ)
            .min(TAU * ESTIMATE_SHARE_OF_LOOP * loop_bandwidth_hz)
            .min(ESTIMATE_SHARE_OF_WINDING * resistance / inductance);
        // The exact first-order step (stable at any tick).
        let smoothing = 1.0 - libm::expf(-corner * tick);
        Self { resistance, inductance, limit: CURRENT_SHARE * test_current, smoothing, ..Self::default() }
    }

    /// The q current to ask for this tick (A) from the q current read now; `turning` (V) is the
    /// q voltage a turning frame adds (`ω·L·i_d`), not the rotor's.
    pub(super) fn reference(&mut self, q_current: f32, turning: f32, tick: f32) -> f32 {
        let Some(previous) = self.last_current.replace(q_current) else {
            return 0.0;
        };
        let back_emf = self.applied
            - turning
            - self.resistance * 0.5 * (q_current + previous)
            - self.inductance * (q_current - previous) / tick;
        self.estimate += self.smoothing * (back_emf - self.estimate);
        let reference = -self.estimate / self.resistance;
        // No winding measured (a resistance of 0): no damping.
        if !reference.is_finite() {
            return 0.0;
        }
        crate::limit(reference, -self.limit, self.limit)
    }

    /// The q voltage asked for on this call (it drives the current between the next reading
    /// and the one after).
    pub(super) fn asked(&mut self, q_voltage: f32) {
        self.applied = self.asked;
        self.asked = q_voltage;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rotor on the magnet's spring (no friction), its winding fed through the damping's q
    /// voltage: the swing dies out, where a stiff current loop holding the q current at 0
    /// leaves it; the q current stays within its band beside the limit's overshoot.
    #[test]
    fn a_swinging_rotor_comes_to_rest() {
        // Electrical angle of the rotor (rad), speed (rad/s); the vector at 0 with 2 A on d.
        let (p, psi, r, l, j, i_d, t) = (4.0f32, 1.0 / 60.0, 0.3, 0.5e-3, 1.5e-4, 2.0, 1.0 / 16_000.0);
        let run = |damped: bool| {
            let mut damping = SwingDamping::new(r, l, 2.0, 1000.0, t);
            let gains = crate::pi_controller::PiGains { kp: 1.8, ki: 1100.0, period: t };
            let mut pi = crate::pi_controller::PiController::new(gains);
            let (mut theta, mut omega, mut i_q) = (2.8f32, 0.0f32, 0.0f32);
            let (mut v_q, mut largest_late, mut largest_current) = (0.0f32, 0.0f32, 0.0f32);
            for k in 0..16_000 {
                // The voltage asked for last tick applies over this one.
                let applied = v_q;
                let reference = if damped { damping.reference(i_q, 0.0, t) } else { 0.0 };
                v_q = pi.update(reference - i_q, 12.0).value;
                damping.asked(v_q);
                for _ in 0..10 {
                    let h = t / 10.0;
                    let e_q = psi * omega * libm::cosf(theta);
                    i_q += h * (applied - r * i_q - e_q) / l;
                    let torque = 1.5 * p * psi * (libm::cosf(theta) * i_q - libm::sinf(theta) * i_d);
                    omega += h * p * torque / j;
                    theta += h * omega;
                }
                largest_current = largest_current.max(i_q.abs());
                if k > 12_000 {
                    largest_late = largest_late.max(libm::remainderf(theta, core::f32::consts::TAU).abs());
                }
            }
            (largest_late, largest_current)
        };
        let (undamped, _) = run(false);
        let (damped, current) = run(true);
        assert!(undamped > 0.5, "undamped: {undamped}");
        assert!(damped < 1e-3, "damped: {damped}");
        assert!(current < 0.4 * 2.0 * 1.5, "{current} A");
    }
}
