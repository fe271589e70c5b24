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
//! damping before has left it little to swing with. A winding's damping can also be far under
//! critical (a heavy rotor on a weak magnet: a tenth of critical on a 4 Hz swing, a few
//! thousandths on a weak magnet on a large resistance), and with little friction such a rotor
//! swings back through the vector for seconds: where the encoder sees the swing turn back (by
//! [`REVERSAL_COUNTS`]) before the wait ends, the damping goes on until the wait sees the rotor
//! still, raised where it turns back under the damping ([`SwingDamping::raise`]); the held
//! current weakened from each of its turning points to its centre damps it too, whatever the
//! winding (`spring_weakening`). A creeping rotor does not turn back while it creeps; released,
//! it may ring on its friction, and is then damped as its winding damps it (and raised where it
//! turns back again under that damping). The passes that turn the vector start from a rotor at
//! rest and are not damped: their smooth start and stop excite little swing, and a damping
//! current's transient as the turn's back-EMF rises would drag the rotor more.

use core::f32::consts::TAU;

/// The estimate's low-pass (Hz): above the swing, below the current loop (at most a fifth of
/// its bandwidth) and below half the winding's corner `R/L` (an inductance misread by the
/// probe then leaves the estimate's own loop a gain under one).
const ESTIMATE_HZ: f32 = 200.0;
const ESTIMATE_SHARE_OF_LOOP: f32 = 0.2;
const ESTIMATE_SHARE_OF_WINDING: f32 = 0.5;
/// The damping current's limit (a share of the test current).
const CURRENT_SHARE: f32 = 0.4;
/// A swing reverses where the encoder turns back by this many counts from its last turning
/// point (a count or two of jitter on a rotor at rest is none).
const REVERSAL_COUNTS: u32 = 3;
/// Once raised, the damping's gain over the winding's own doubles at each reversal, up to
/// this; the resistance it then estimates the back-EMF with is this share of the least of the
/// probe's and the hold's (`raise`).
const MOST_GAIN: f32 = 8.0;
const RAISED_RESISTANCE_SHARE: f32 = 0.9;
/// The probe's and the hold's resistances must agree within this factor for the damping to be
/// raised.
const RESISTANCES_AGREE: f32 = 1.5;
/// The estimate's time constant must be under this share of the swing's half period for the
/// damping to be raised (a lag of at most about 17° at the swing).
const LAG_SHARE: f32 = 0.1;

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
    /// The swing on the encoder: the count at its last turning point (none before the first
    /// count), its direction since (±1, 0 before the first move) and the reversals seen.
    turning_point: Option<i32>,
    direction: i32,
    reversals: u32,
    /// The reversal the damping was raised at (`raise`; none: the winding's own).
    raised_at: Option<u32>,
    /// Ticks since the last reversal (or the first move), and between the last two.
    since_reversal: u32,
    half_period: u32,
    /// Reversals while the damping was on.
    damped_reversals: u32,
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
        let reference = -self.gain() * self.estimate / self.resistance;
        // No winding measured (a resistance of 0): no damping.
        if !reference.is_finite() {
            return 0.0;
        }
        crate::limit(reference, -self.limit, self.limit)
    }

    /// The encoder's count this tick: a reversal where it turns back by [`REVERSAL_COUNTS`]
    /// from its last turning point.
    pub(super) fn observe(&mut self, count: i32, damped: bool) {
        self.since_reversal = self.since_reversal.saturating_add(1);
        let turning_point = *self.turning_point.get_or_insert(count);
        let from_turn = count.wrapping_sub(turning_point);
        if from_turn.signum() == self.direction {
            // Further the same way: the turning point follows.
            self.turning_point = Some(count);
        } else if from_turn.unsigned_abs() >= REVERSAL_COUNTS {
            // The first move, or back from the turning point.
            if self.direction != 0 {
                self.reversals += 1;
                self.damped_reversals += damped as u32;
                self.half_period = self.since_reversal;
            }
            self.since_reversal = 0;
            self.direction = from_turn.signum();
            self.turning_point = Some(count);
        }
    }

    /// Whether the swing has reversed: a rotor that swings through the vector (a heavy rotor
    /// on a weak magnet with little friction), where one that creeps to it under a damping
    /// beyond critical does not.
    pub(super) fn reversed(&self) -> bool {
        self.reversals > 0
    }

    /// For a swing that reversed under the winding's own damping (under critical), a damping
    /// asked at twice the winding's, doubled at each reversal after (up to [`MOST_GAIN`]),
    /// estimating the back-EMF with a resistance [`RAISED_RESISTANCE_SHARE`] of the least of
    /// the probe's and the hold's (its d voltage over its current, which the inverter's dead
    /// time raises), where the two agree within [`RESISTANCES_AGREE`]: where they do not, one of
    /// them is far off (a probe a jittering rotor misled, a dead time large beside a small
    /// resistance's voltage), and a damping raised on it could feed the swing, or ring on its
    /// own loop through the estimate (`R − R̂` of the current it asks for). Asked at `g`, the
    /// damping takes `g·e/(g·R − (g − 1)·R̂)` of a back-EMF `e` on a winding of `R` estimated
    /// as `R̂`: where `R̂` is over `R·g/(g − 1)` it feeds the swing (at `g` = 8 with `R̂` = 0.9
    /// of the resistance given, where that is over 1.27 times the winding's); at `R̂ = 0.9·R`,
    /// 1.8, 3.1 and 4.7 times the winding's damping for `g` = 2, 4 and 8. Nothing where the
    /// swing has not reversed or the resistance is not a positive number, and where the
    /// estimate's low-pass lags the swing (its time constant over [`LAG_SHARE`] of the swing's
    /// half period: a slow winding's, whose corner is under its `R/L`): a damping that lags,
    /// raised, drives the swing it lags.
    pub(super) fn raise(&mut self, probe: f32, hold: f32) {
        let readings = probe > 0.0 && hold > 0.0 && probe.is_finite() && hold.is_finite();
        if !(readings && probe.max(hold) <= RESISTANCES_AGREE * probe.min(hold)) {
            return;
        }
        let resistance = RAISED_RESISTANCE_SHARE * probe.min(hold);
        let lags = (self.half_period as f32) * LAG_SHARE * self.smoothing < 1.0;
        let under_critical = self.damped_reversals > 0;
        if under_critical && !lags && self.raised_at.is_none() {
            (self.resistance, self.raised_at) = (resistance, Some(self.reversals));
        }
    }

    /// The damping's gain over the winding's own: 1, or once raised 2, doubled at each
    /// reversal after, up to [`MOST_GAIN`].
    fn gain(&self) -> f32 {
        match self.raised_at {
            None => 1.0,
            Some(at) => libm::ldexpf(2.0, self.reversals.saturating_sub(at).min(3) as i32).min(MOST_GAIN),
        }
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

    /// The encoder's turning points: a jitter of two counts either way is no reversal, a swing
    /// back by three or more is one. The damping is raised only where the swing reversed
    /// while it was on (a swing that reverses once released is a creeping rotor's ringing), on
    /// a tenth under the least of two positive resistances that agree within a factor of 1.5,
    /// and not where the estimate's low-pass lags the swing (a slow winding's).
    #[test]
    fn a_swing_reverses_by_three_counts_and_is_raised_only_where_it_reversed_under_the_damping() {
        let tick = 1.0 / 16_000.0;
        let swing = |d: &mut SwingDamping, damped: bool| {
            for k in 0..400 {
                d.observe(k / 10, damped);
            }
            for k in 0..400 {
                d.observe(40 - k / 10, damped);
            }
        };
        let mut d = SwingDamping::new(0.5, 1e-4, 2.0, 1500.0, tick);
        for c in [0, 1, 2, 1, 0, 2, 1, 0, -1, 0] {
            d.observe(c, true);
        }
        assert!(!d.reversed(), "{d:?}");
        swing(&mut d, false);
        assert!(d.reversed());
        d.raise(0.5, 0.5);
        assert_eq!(d.gain(), 1.0, "reversed with the damping off: not raised");
        swing(&mut d, true);
        for (probe, hold) in [(f32::NAN, 0.5), (0.5, f32::NAN), (0.0, 0.5), (0.5, -1.0), (0.5, 0.76), (1.6, 1.0)] {
            d.raise(probe, hold);
            assert_eq!(d.gain(), 1.0, "{probe} {hold}");
        }
        d.raise(0.55, 0.5);
        assert_eq!((d.gain(), d.resistance), (2.0, 0.45));
        // A slow winding (0.13 s): its estimate lags a swing of 25 ms half periods.
        let mut slow = SwingDamping::new(0.06, 8e-3, 2.0, 1500.0, tick);
        swing(&mut slow, true);
        swing(&mut slow, true);
        slow.raise(0.06, 0.06);
        assert!(slow.reversed() && slow.gain() == 1.0, "{slow:?}");
    }
}
