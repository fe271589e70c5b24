//! The encoder against the electrical angle: while a current vector turns slowly forward and
//! back, the rotor follows it and the counter moves `counts_per_rev / pole_pairs` counts per
//! electrical turn, up or down. A straight-line fit of the counts against the vector's angle
//! on each pass gives the counts per electrical radian (its sign the encoder's direction, its
//! size the pole pairs); the rotor lags the vector by the same angle on both passes, one way
//! and then the other, so the mean of the two passes' intercepts is where the rotor's d axis
//! sits: the electrical angle at count 0.

use core::f32::consts::TAU;

/// The statistics of one pass: the vector's angle (rad, from the pass's start) against the
/// counts (from the sequence's first count), as means and co-moments updated one sample at a
/// time (Welford): the counts' scatter about a line through the pass's means is a small share
/// of their spread over a pass, which raw sums of squares would lose in f32.
#[derive(Clone, Copy, Debug, Default)]
pub struct Pass {
    n: f32,
    /// The vector's angle at the pass's start (rad).
    start: f32,
    /// Smallest and largest count seen.
    lowest: i32,
    highest: i32,
    mean_angle: f32,
    mean_counts: f32,
    angle_moment: f32,
    cross_moment: f32,
    counts_moment: f32,
}

impl Pass {
    pub fn new(start: f32) -> Self {
        Self { start, lowest: i32::MAX, highest: i32::MIN, ..Self::default() }
    }

    pub fn add(&mut self, angle: f32, counts: i32) {
        let x = angle - self.start;
        let y = counts as f32;
        self.n += 1.0;
        self.lowest = self.lowest.min(counts);
        self.highest = self.highest.max(counts);
        let dx = x - self.mean_angle;
        let dy = y - self.mean_counts;
        self.mean_angle += dx / self.n;
        self.mean_counts += dy / self.n;
        self.angle_moment += dx * (x - self.mean_angle);
        self.cross_moment += dx * (y - self.mean_counts);
        self.counts_moment += dy * (y - self.mean_counts);
    }

    /// The variance of the counts (counts²) about a line of `slope` counts per radian through
    /// the pass's means: about the exact counts per electrical radian, the rotor's swing on
    /// the turning vector. (About the pass's own fitted line a swing of a couple of periods
    /// would lose the share the fitted slope leans into it.) 0 for fewer than three samples.
    pub fn scatter_about(&self, slope: f32) -> f32 {
        if self.n < 3.0 {
            return 0.0;
        }
        let residual = self.counts_moment - 2.0 * slope * self.cross_moment + slope * slope * self.angle_moment;
        (residual / self.n).max(0.0)
    }

    /// Counts per electrical radian: the fitted line's slope.
    fn slope(&self) -> Option<f32> {
        if self.n < 2.0 || !(self.angle_moment > 0.0) {
            return None;
        }
        Some(self.cross_moment / self.angle_moment)
    }

    /// The counts at the vector's angle 0 on a line of `slope` (counts per electrical radian)
    /// through the pass's means.
    fn intercept(&self, slope: f32) -> f32 {
        self.mean_counts + slope * (-self.start - self.mean_angle)
    }

    /// Counts the rotor moved over the pass.
    pub fn travel(&self) -> i32 {
        self.highest.saturating_sub(self.lowest)
    }
}

/// What the two passes found.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Alignment {
    pub pole_pairs: u32,
    /// The counter counts down when the rotor turns the way the electrical angle increases.
    pub reversed: bool,
    /// The electrical angle (rad, in [0, 2π)) at count 0 of the direction-corrected counter.
    pub offset: f32,
    /// How far the rotor lagged the turning vector (rad, electrical): half the two passes'
    /// intercepts apart.
    pub lag: f32,
}

impl Alignment {
    /// The counts per electrical radian of an encoder of `counts_per_rev` on this motor,
    /// signed as the counter runs against the electrical angle.
    pub fn counts_per_radian(&self, counts_per_rev: u32) -> f32 {
        exact_counts_per_radian(counts_per_rev, self.pole_pairs as f32, self.reversed)
    }
}

/// `counts_per_rev` over `pole_pairs` electrical turns of 2π, negative for a reversed counter.
fn exact_counts_per_radian(counts_per_rev: u32, pole_pairs: f32, reversed: bool) -> f32 {
    let exact = counts_per_rev as f32 / (pole_pairs * TAU);
    if reversed {
        -exact
    } else {
        exact
    }
}

/// Why the passes give no alignment.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub enum AlignmentError {
    /// The counter hardly moved: an encoder not connected, or a rotor that cannot turn.
    EncoderStill { counts: i32 },
    /// The counts per electrical turn are not `counts_per_rev` over a whole number of pole
    /// pairs in range: a wrong counts-per-revolution setting, or a slipping rotor.
    CountsPerTurn { counts_per_electrical_turn: f32 },
    /// The two passes disagree on the counts per turn (by more than a fifth): the rotor did
    /// not follow the vector (a load too heavy or too stiff for the test current).
    RotorDidNotFollow { forward: f32, backward: f32 },
}

/// Direction, pole pairs and offset from a forward and a backward pass over the same angles,
/// for an encoder of `counts_per_rev`; the pole pairs must lie in `1..=max_pole_pairs`.
/// `start_count` is the raw count the passes' counts are taken from.
pub fn align(
    forward: &Pass,
    backward: &Pass,
    counts_per_rev: u32,
    max_pole_pairs: u32,
    start_count: i32,
) -> Result<Alignment, AlignmentError> {
    let travel = forward.travel().min(backward.travel());
    let (Some(k1), Some(k2)) = (forward.slope(), backward.slope()) else {
        return Err(AlignmentError::EncoderStill { counts: travel });
    };
    // Less than an eighth of the counts a single pole pair's turn would give.
    if (travel as f32) < 0.125 * counts_per_rev as f32 / max_pole_pairs as f32 {
        return Err(AlignmentError::EncoderStill { counts: travel });
    }
    if !(k1 * k2 > 0.0 && (k1 - k2).abs() <= 0.2 * k1.abs().max(k2.abs())) {
        return Err(AlignmentError::RotorDidNotFollow { forward: k1 * TAU, backward: k2 * TAU });
    }
    let slope = 0.5 * (k1 + k2);
    let per_turn = slope * TAU;
    let pole_pairs_estimate = counts_per_rev as f32 / per_turn.abs();
    let pole_pairs = libm::roundf(pole_pairs_estimate);
    // Within a quarter of a pole pair: a rotor that swings on a soft coupling (a load behind
    // a compliant shaft, little friction) bends the lines' slopes by several percent, while a
    // wrong counts-per-revolution setting is off by a factor (quadrature ×4, 1000 for 1024 on
    // a many-pole motor) that lands between whole numbers.
    if !(pole_pairs >= 1.0 && pole_pairs <= max_pole_pairs as f32 && (pole_pairs_estimate - pole_pairs).abs() < 0.25) {
        return Err(AlignmentError::CountsPerTurn { counts_per_electrical_turn: per_turn });
    }
    let reversed = slope < 0.0;
    // Counts (direction-corrected, from the raw count 0) where the electrical angle is 0:
    // the passes' mean intercept, each on the line of the exact counts per radian through its
    // pass's means (a swing that bends a fitted slope by a few percent would move a fitted
    // intercept, extrapolated to the angle 0 turns away, by as much of the pass's angle).
    let signed = exact_counts_per_radian(counts_per_rev, pole_pairs, reversed);
    let (exact, sign) = (signed.abs(), signed.signum());
    let (c1, c2) = (forward.intercept(signed), backward.intercept(signed));
    let cpr = counts_per_rev as i64;
    // The start count within a revolution keeps the numbers small.
    let start = (start_count as i64).rem_euclid(cpr) as f32;
    // A count n stands for the interval [n, n + 1) in the counter's own direction: its middle.
    let at_zero = sign * (start + 0.5 * (c1 + c2) + 0.5);
    // Electrical angle at direction-corrected count 0: −at_zero / exact, within a turn.
    let offset = -at_zero / exact;
    let offset = offset - TAU * libm::floorf(offset / TAU);
    let lag = 0.5 * (c2 - c1).abs() / exact;
    // In f32 the reduction can land a few µrad either side of the turn: both ends are 0.
    let offset = if (0.0..TAU).contains(&offset) { offset } else { 0.0 };
    Ok(Alignment { pole_pairs: pole_pairs as u32, reversed, offset, lag })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A rotor that follows the vector with a lag: every direction, pole-pair count and offset
    /// comes back.
    #[test]
    fn direction_pole_pairs_and_offset_come_back_from_a_lagging_rotor() {
        for &(cpr, pp) in &[(4000u32, 4u32), (1024, 1), (16384, 12), (2000, 7)] {
            for reversed in [false, true] {
                for offset in [0.0f32, 1.0, 3.0, 6.0] {
                    let start_count: i32 = -123_457;
                    let counts_at = |theta: f32, lag: f32| {
                        // Direction-corrected counts where the rotor's electrical angle is θ − lag.
                        let corrected = (theta - lag - offset) * cpr as f32 / (pp as f32 * TAU);
                        let raw = if reversed { -corrected } else { corrected };
                        libm::floorf(raw) as i32 - start_count.rem_euclid(cpr as i32)
                    };
                    let (mut f, mut b) = (Pass::new(0.0), Pass::new(4.0 * TAU));
                    for k in 0..4000 {
                        let theta = 4.0 * TAU * k as f32 / 4000.0;
                        f.add(theta, counts_at(theta, 0.1));
                        let back = 4.0 * TAU - theta;
                        b.add(back, counts_at(back, -0.1));
                    }
                    let a = align(&f, &b, cpr, 64, start_count).unwrap();
                    assert_eq!((a.pole_pairs, a.reversed), (pp, reversed));
                    assert!((a.lag - 0.1).abs() < 0.01, "lag {}", a.lag);
                    let error = libm::remainderf(a.offset - offset, TAU).abs();
                    assert!(error < 0.5f32.to_radians(), "cpr {cpr} pp {pp} rev {reversed} offset {offset}: {a:?}");
                }
            }
        }
    }

    /// A rotor swinging on the turning vector by ±0.3 rad (electrical) about its lag, twelve
    /// or two periods over a pass: the counts' scatter about the exact counts-per-radian line
    /// is the swing's variance, `A²/2`, in counts, over 20 000 samples of counts in the tens of
    /// thousands. (About the pass's own fitted line two periods would lose `6/(π²·2²)`, 15 %,
    /// of it: the fitted slope leans into the swing.) A rotor that follows without a swing
    /// scatters by its counter's steps alone (a twelfth of a count², which f32 moments of
    /// counts spread over two turns resolve only to within a few counts²).
    #[test]
    fn the_scatter_about_a_pass_is_the_rotors_swing() {
        let (cpr, pp, amplitude) = (16384u32, 1u32, 0.3f32);
        let per_radian = cpr as f32 / (pp as f32 * TAU);
        let want = 0.5 * amplitude * amplitude * per_radian * per_radian;
        for periods in [12.0f32, 2.0] {
            let mut pass = Pass::new(0.0);
            let mut still = Pass::new(0.0);
            for k in 0..20_000 {
                let theta = 2.0 * TAU * k as f32 / 20_000.0;
                let swing = amplitude * libm::sinf(TAU * periods * k as f32 / 20_000.0);
                pass.add(theta, libm::floorf((theta - 0.1 + swing) * per_radian) as i32 + 5000);
                still.add(theta, libm::floorf((theta - 0.1) * per_radian) as i32 + 5000);
            }
            let (swinging, still) = (pass.scatter_about(per_radian), still.scatter_about(per_radian));
            assert!((swinging / want - 1.0).abs() < 0.01, "{periods} periods: {swinging} vs {want}");
            assert!(still < 1e-4 * want, "{still} vs {want}");
            // The pass's own fitted line takes part of a slow swing.
            let fitted = pass.scatter_about(pass.slope().unwrap());
            let lost = 6.0 / ((core::f32::consts::PI * periods) * (core::f32::consts::PI * periods));
            assert!((fitted / (want * (1.0 - lost)) - 1.0).abs() < 0.01, "{periods} periods: {fitted} vs {want}");
        }
    }

    #[test]
    fn a_still_counter_and_a_wrong_count_per_turn_are_named() {
        let (mut f, mut b) = (Pass::new(0.0), Pass::new(TAU));
        for k in 0..100 {
            let theta = TAU * k as f32 / 100.0;
            f.add(theta, 0);
            b.add(TAU - theta, 1);
        }
        assert!(matches!(align(&f, &b, 4000, 64, 0), Err(AlignmentError::EncoderStill { .. })));
        // 4000 counts per revolution told, 4000 / 2.5 = 1 600 per electrical turn seen.
        let (mut f, mut b) = (Pass::new(0.0), Pass::new(TAU));
        for k in 0..100 {
            let theta = TAU * k as f32 / 100.0;
            f.add(theta, (1600.0 * theta / TAU) as i32);
            b.add(TAU - theta, (1600.0 * (TAU - theta) / TAU) as i32);
        }
        assert!(matches!(align(&f, &b, 4000, 64, 0), Err(AlignmentError::CountsPerTurn { .. })));
    }
}
