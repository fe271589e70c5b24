//! A swing on the commissioning vector damped by the vector's strength, whatever the encoder's
//! direction and the pole pairs.
//!
//! Held on a vector, the rotor is a mass on the magnet's spring, its energy
//! `½·J·ω² + k·I·(1 − cos δ)` at a current `I` and an electrical angle `δ` from the vector.
//! At a turning point the rotor stands still and the energy is all the spring's: weakening the
//! spring there (the held current down to a share `s` of itself) keeps the turning point and
//! takes `(1 − s)` of the energy away; strengthening it again where the rotor passes the
//! swing's centre (`δ = 0`, the spring's energy none) gives nothing back. Each half swing's
//! `1 − cos` then shrinks to `s` of itself (the amplitude to `√s` where it is small), the rotor
//! taking `1/√s` times as long from the turning point to the centre. Only the encoder's
//! turning points are needed, in its own counts: no sign, no pole pairs, no back-EMF (on a
//! weak magnet the swing's back-EMF is lost beside the inverter's and the sensors' errors, and
//! a damping current of the wrong sign feeds the swing).
//!
//! The centre is read from the last three turning points by Aitken's extrapolation (exact on a
//! swing that shrinks by the same ratio each half swing, as an ideal weakening makes it), from
//! the last two (midway) before that. A centre misread by `e` gives back `(1 − s)·(1 − cos e)`
//! of the spring at the full current: the swing still shrinks while `e` is under its
//! amplitude. A rotor that friction holds off the centre at the weak current, or that creeps
//! there, is strengthened once its count stalls or its way takes too long
//! ([`WEAKENED_OVER_STRONG_QUARTER`]).

/// The held current's share from a turning point to the centre. The swing's decay per second,
/// `−ln s / (1 + 1/√s)` of its frequency's, is best at `s` = 0.07; at a quarter it is 83 %
/// of that, with the spring still a quarter of itself against friction (a fourteenth at 0.07).
const WEAK_SHARE: f32 = 0.25;
/// A turning point is seen once the count turns back by two: the spring is weakened within
/// two counts of it (a later weakening takes only the energy left above those counts'
/// `1 − cos`), and a count's dither (a rotor standing on a count's edge) is no turning point.
const TURN_BACK_COUNTS: u32 = 2;
/// The least count of ticks without a count that stalls a weakened rotor (a swing's half
/// period read from dithering counts could be a few ticks).
const LEAST_STALL_TICKS: u32 = 32;
/// Swings under this many counts from the centre are left alone: within a count or two of
/// jitter, or a few counts of quantisation, a centre is not read.
const LEAST_AMPLITUDE_COUNTS: f32 = 4.0;
/// A weakened spring is strengthened at the latest after 1.5 times the rotor's expected way
/// from its turning point to the centre at the weak current: `1/√s` times the last way from
/// the centre to a turning point at the full current (or half the last half period before
/// there is one): this factor, `1.5/√s` (a rotor the winding's damping makes creep at the
/// weak current). It is strengthened too where the count has not moved for a share of the last
/// half period (one that friction holds off the centre).
const WEAKENED_OVER_STRONG_QUARTER: f32 = 3.0;
const STALLED_HALF_PERIOD_SHARE: u32 = 4;

#[derive(Clone, Copy, Debug, Default)]
pub(super) struct SpringWeakening {
    /// The count furthest the rotor has gone in its direction of motion (`way`, ±1; 0 before
    /// the first move).
    furthest: Option<i32>,
    way: i32,
    /// The last three turning points (oldest first), how many there are (at most 3).
    turning_points: [i32; 3],
    seen: usize,
    /// Ticks since the last turning point, and between the last two; ticks the count has kept.
    since_turn: u32,
    unmoved: u32,
    half_period: u32,
    /// Where the spring was strengthened at the centre (ticks since the turning point), and
    /// the ticks from there to the next turning point (0: none yet).
    strengthened_at: Option<u32>,
    strong_quarter: u32,
    weakened: Option<Weakened>,
}

/// A weakened spring: the last turning point, the centre the rotor moves to (counts from it),
/// the way it moves and the ticks it may stay weakened.
#[derive(Clone, Copy, Debug)]
struct Weakened {
    turning_point: i32,
    centre: f32,
    way: i32,
    most_ticks: u32,
}

impl SpringWeakening {
    /// The encoder's count this tick.
    pub(super) fn observe(&mut self, count: i32) {
        self.since_turn = self.since_turn.saturating_add(1);
        let furthest = *self.furthest.get_or_insert(count);
        let from_furthest = count.wrapping_sub(furthest);
        self.unmoved = if from_furthest == 0 { self.unmoved.saturating_add(1) } else { 0 };
        if let Some(w) = self.weakened {
            let past_centre = (count.wrapping_sub(w.turning_point) as f32 - w.centre) * w.way as f32 >= 0.0;
            let too_long = self.since_turn >= w.most_ticks;
            let stalled = self.unmoved >= (self.half_period / STALLED_HALF_PERIOD_SHARE).max(LEAST_STALL_TICKS);
            if past_centre {
                self.strengthened_at = Some(self.since_turn);
            }
            if past_centre || too_long || stalled {
                self.weakened = None;
            }
        }
        if from_furthest.signum() == self.way {
            self.furthest = Some(count);
        } else if from_furthest.unsigned_abs() >= TURN_BACK_COUNTS {
            if self.way != 0 {
                self.turned_at(furthest, from_furthest.signum());
            }
            self.way = from_furthest.signum();
            self.furthest = Some(count);
        }
    }

    /// A turning point at `count`, the rotor now moving `way`.
    fn turned_at(&mut self, count: i32, way: i32) {
        if let Some(at) = self.strengthened_at.take() {
            self.strong_quarter = self.since_turn.saturating_sub(at);
        }
        self.half_period = self.since_turn;
        self.since_turn = 0;
        if self.seen == self.turning_points.len() {
            self.turning_points.rotate_left(1);
            self.seen -= 1;
        }
        self.turning_points[self.seen] = count;
        self.seen += 1;
        let strong_quarter = if self.strong_quarter > 0 { self.strong_quarter } else { self.half_period / 2 };
        let most_ticks = (WEAKENED_OVER_STRONG_QUARTER * strong_quarter as f32) as u32;
        self.weakened = self.centre().filter(|centre| centre.abs() >= LEAST_AMPLITUDE_COUNTS).map(|centre| Weakened {
            turning_point: count,
            centre,
            way,
            most_ticks,
        });
    }

    /// The swing's centre in counts from the last turning point: Aitken's extrapolation of
    /// the last three, midway to the one before while there are two. In differences: counts may
    /// lie far from 0, where an `f32` does not hold them to the count.
    fn centre(&self) -> Option<f32> {
        let [a, b, c] = self.turning_points;
        let (first, second) = (b.wrapping_sub(a) as f32, c.wrapping_sub(b) as f32);
        match self.seen {
            2 => Some(-0.5 * first),
            // A swing's turning points alternate sides: the two differences have opposite signs
            // and the denominator is never 0; where they do not (a rotor that went on the
            // same way), midway.
            3 if first * second < 0.0 => Some(-second * second / (second - first)),
            3 => Some(-0.5 * second),
            _ => None,
        }
    }

    /// The share of the held current to ask for.
    pub(super) fn share(&self) -> f32 {
        if self.weakened.is_some() {
            WEAK_SHARE
        } else {
            1.0
        }
    }

    /// Whether the spring is weakened (a rotor standing on it is not at rest).
    pub(super) fn weakened(&self) -> bool {
        self.weakened.is_some()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_longest_weakening_is_half_again_the_expected_way() {
        assert_eq!(WEAKENED_OVER_STRONG_QUARTER, 1.5 / libm::sqrtf(WEAK_SHARE));
    }

    /// A rotor on the magnet's spring (a pendulum in the electrical angle, 3 Hz at the full
    /// current, Coulomb friction `friction` of the full spring's peak torque, no other damping),
    /// counted `counts` per electrical radian either way (with a count's dither on the read
    /// counts where `dither`): its largest angle from the vector over the last half second of
    /// 3 s, and the longest the spring stayed weakened (s).
    fn swing(start: f32, counts: f32, way: f32, friction: f32, weakened: bool, dither: bool) -> (f32, f32) {
        let (w0, tick) = (core::f32::consts::TAU * 3.0, 1.0 / 16_000.0);
        let (mut theta, mut omega) = (start, 0.0f32);
        let mut weakening = SpringWeakening::default();
        let (mut largest_late, mut weak_ticks, mut longest) = (0.0f32, 0u32, 0u32);
        for k in 0..48_000 {
            // A count's dither: the read one count up on about a third of the ticks.
            let up = dither && (k as u32).wrapping_mul(2_654_435_761) >> 30 == 0;
            weakening.observe(libm::floorf(way * counts * theta) as i32 + up as i32);
            let share = if weakened { weakening.share() } else { 1.0 };
            assert!(share == 1.0 || share == WEAK_SHARE);
            weak_ticks = if share < 1.0 { weak_ticks + 1 } else { 0 };
            longest = longest.max(weak_ticks);
            for _ in 0..4 {
                let h = tick / 4.0;
                let spring = -w0 * w0 * share * libm::sinf(theta);
                let stuck = omega == 0.0 && spring.abs() <= friction * w0 * w0;
                let drag = if omega == 0.0 { 0.0 } else { -friction * w0 * w0 * omega.signum() };
                let next = if stuck { 0.0 } else { omega + h * (spring + drag) };
                // Friction stops the rotor; it does not reverse it.
                omega = if omega != 0.0 && next * omega < 0.0 { 0.0 } else { next };
                theta += h * omega;
            }
            if k > 40_000 {
                largest_late = largest_late.max(theta.abs());
            }
        }
        (largest_late, longest as f32 * tick)
    }

    /// Undamped, a swing from 2.5 rad (143° electrical) keeps its amplitude; weakened at its
    /// turning points it dies within a few counts, whichever way the encoder counts and on a
    /// coarse or a fine one.
    #[test]
    fn a_swing_weakened_at_its_turning_points_dies_out_whichever_way_the_encoder_counts() {
        for counts in [15.0, 130.0, 2600.0] {
            for way in [1.0, -1.0] {
                for start in [2.5, -1.2, 0.4] {
                    let (undamped, _) = swing(start, counts, way, 0.0, false, false);
                    assert!(undamped > 0.95 * libm::fabsf(start), "{undamped} from {start}");
                    let (damped, _) = swing(start, counts, way, 0.0, true, false);
                    assert!(
                        damped < 0.02 * libm::fabsf(start) + 4.0 / counts,
                        "{damped} rad from {start} ({counts} counts/rad, way {way})"
                    );
                }
            }
        }
    }

    /// With Coulomb friction of 1–4 % of the full spring's torque, a rotor the weak spring
    /// cannot pull the rest of the way stalls: the spring is strengthened again (within a
    /// fraction of a second) and the swing still dies, to within what friction holds.
    #[test]
    fn a_rotor_friction_stalls_on_the_weak_spring_is_strengthened() {
        for friction in [0.01, 0.02, 0.04] {
            for start in [2.5, 0.8] {
                let (damped, longest) = swing(start, 130.0, 1.0, friction, true, false);
                // Friction holds the rotor anywhere its spring's `sin` is under it.
                assert!(damped < 2.0 * friction + 4.0 / 130.0, "{damped} rad (friction {friction}, from {start})");
                // At most 1.5 times the weak way of the first weakening (a half period, 0.17 s).
                assert!(longest < 0.27, "weakened for {longest} s (friction {friction}, from {start})");
            }
        }
    }

    /// A count's dither (a third of the ticks one count up): a rotor at rest on a count's
    /// edge is never weakened, and a swing still dies out to within a few counts.
    #[test]
    fn a_counts_dither_is_no_turning_point() {
        let (_, longest) = swing(0.0, 130.0, 1.0, 0.0, true, true);
        assert_eq!(longest, 0.0, "a rotor at rest weakened for {longest} s");
        for start in [2.5, 0.4] {
            let (damped, _) = swing(start, 130.0, 1.0, 0.0, true, true);
            assert!(damped < 0.02 * start + 6.0 / 130.0, "{damped} rad from {start}");
        }
    }
}
