//! A design refined over its continuous parameters (the proportional gain, the integral
//! ratio, the low-pass cut-off, each notch's centre, width and depth) by a compass search that
//! keeps the margins: for the widest bandwidth ([`refine`]), to lift a dip of the closed
//! loop over −3 dB ([`lift_dip_on`]), or to move a loop that misses the margins by a little,
//! or dips, onto them while it keeps its reach ([`restore_on`]).
//!
//! **The dip.** On a load whose anti-resonance lies below the loop's reach, the closed loop
//! `|L/(1 + L)|` can fall below −3 dB near the anti-resonance and rise over it again above. The bandwidth (the first −3 dB
//! frequency) is then the dip's, far below the loop's reach, and a few percent more gain or
//! integral action lifts the dip and moves the bandwidth up to the reach: a cliff that a
//! search for bandwidth does not climb (it sees no gain until it lands past the edge, on a
//! sliver a few percent wide between the dip and the margins). [`lift_dip_on`] climbs the dip's
//! floor instead, then refines for bandwidth with the floor kept [`FLOOR_HEADROOM_DB`] over
//! −3 dB up to where the start's dip ended, so that a model a fraction of a percent off the
//! machine does not drop it back (above that frequency the loop is held to −3 dB only). A
//! closed loop that rolls off and climbs back over −3 dB on a resonance peak counts as a dip
//! too; its lift fails or its loop keeps the margins all the same.

use num_complex::Complex64;

use super::design::{Design, MarginGoal, LOWEST_NOTCH_HZ, NOTCH_LIMIT};
use super::margins::{margins, Margins};
use super::sampled_plant::SampledPlant;
use super::velocity_controller::{Notch, VelocityTuning};

/// How far over −3 dB a lifted dip's floor is kept (dB).
pub const FLOOR_HEADROOM_DB: f64 = 0.25;

/// A point of the search: `(ln kp, ln n, ln f_lp, ln f_notch, ln q, depth)` and the second
/// notch's `(ln f_notch2, ln q2, depth2)`.
type Point = [f64; 9];

/// The continuous parameters of a design around its rigid inertia `j`:
/// a [`Point`] with `ki = kp²/(n·j)`; a filter the start does not have stays absent.
struct Coordinates {
    j: f64,
    has_low_pass: bool,
    has_notch: bool,
    has_notch2: bool,
}

impl Coordinates {
    fn of(start: &Design) -> (Self, Point) {
        let t = &start.tuning;
        let n = t.kp * t.kp / (t.ki.max(1e-30) * start.inertia);
        let x = [
            t.kp.ln(),
            n.ln(),
            t.low_pass_hz.max(1.0).ln(),
            t.notch.map_or(0.0, |n| n.hz.ln()),
            t.notch.map_or(0.0, |n| n.q.ln()),
            t.notch.map_or(0.0, |n| n.depth),
            t.notch2.map_or(0.0, |n| n.hz.ln()),
            t.notch2.map_or(0.0, |n| n.q.ln()),
            t.notch2.map_or(0.0, |n| n.depth),
        ];
        let has = (t.low_pass_hz > 0.0, t.notch.is_some(), t.notch2.is_some());
        (Self { j: start.inertia, has_low_pass: has.0, has_notch: has.1, has_notch2: has.2 }, x)
    }

    fn tuning(&self, x: &Point) -> VelocityTuning {
        let kp = x[0].exp();
        VelocityTuning {
            kp,
            ki: kp * kp / (x[1].exp() * self.j),
            low_pass_hz: if self.has_low_pass { x[2].exp() } else { 0.0 },
            notch: self.has_notch.then(|| Notch { hz: x[3].exp(), q: x[4].exp(), depth: x[5] }),
            notch2: self.has_notch2.then(|| Notch { hz: x[6].exp(), q: x[7].exp(), depth: x[8] }),
        }
    }

    /// The coordinates the search moves.
    fn dims(&self) -> Vec<usize> {
        (0..9)
            .filter(|&d| {
                d < 2
                    || (d == 2 && self.has_low_pass)
                    || ((3..6).contains(&d) && self.has_notch)
                    || (d >= 6 && self.has_notch2)
            })
            .collect()
    }
}

/// The widest notch quality factor the drive takes: the upper end of `ctrl.notch_q`'s declared
/// range (`ctrl.notch2_q` has the same). A compass search can drive an ineffective notch's Q
/// far past it.
static MAX_NOTCH_Q: std::sync::LazyLock<f64> = std::sync::LazyLock::new(|| {
    servo_axis::variables::by_name(servo_axis::variables::name::ctrl_notch_q)
        .and_then(|d| d.range.max)
        .expect("the FMU declares ctrl.notch_q with an upper bound")
});

/// A tuning the drive can run on a loop whose Nyquist frequency is `nyquist`.
fn admissible(t: &VelocityTuning, nyquist: f64) -> bool {
    let fits = |n: &Notch| {
        n.hz > LOWEST_NOTCH_HZ
            && n.hz < NOTCH_LIMIT * nyquist
            && n.q > 0.05
            && n.q < *MAX_NOTCH_Q
            && (0.0..=1.0).contains(&n.depth)
    };
    let filters_fit = t.notch.iter().chain(&t.notch2).all(fits);
    t.kp > 0.0 && t.ki >= 0.0 && t.low_pass_hz >= 0.0 && t.low_pass_hz < nyquist && filters_fit
}

/// A compass search from `x` (scored `score0`) along `dims` (and, with `diagonals`, the four
/// diagonals of the gain and the integral ratio): each pass tries a step either way on each
/// coordinate and keeps a move that `better` prefers, until none does; then the
/// steps halve, six times. Stops early once `done` holds for the best score.
fn compass<S: Copy>(
    mut x: Point,
    score0: S,
    dims: &[usize],
    score: &dyn Fn(&Point) -> Option<S>,
    better: &dyn Fn(&S, &S) -> bool,
    done: &dyn Fn(&S) -> bool,
    diagonals: bool,
) -> (Point, S) {
    let mut best = score0;
    let mut steps = [0.1, 0.2, 0.1, 0.05, 0.2, 0.1, 0.05, 0.2, 0.1];
    for _ in 0..6 {
        let mut moved = true;
        while moved && !done(&best) {
            moved = false;
            for &d in dims {
                for sign in [1.0, -1.0] {
                    let mut y = x;
                    y[d] += sign * steps[d];
                    if let Some(s) = score(&y).filter(|s| better(s, &best)) {
                        (x, best) = (y, s);
                        moved = true;
                    }
                }
            }
            if diagonals {
                for (a, b) in [(1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)] {
                    let mut y = x;
                    y[0] += a * steps[0];
                    y[1] += b * steps[1];
                    if let Some(s) = score(&y).filter(|s| better(s, &best)) {
                        (x, best) = (y, s);
                        moved = true;
                    }
                }
            }
        }
        for s in steps.iter_mut() {
            *s *= 0.5;
        }
    }
    (x, best)
}

/// The closed loop's magnitude `|L/(1 + L)|`.
fn closed(l: Complex64) -> f64 {
    (l / (1.0 + l)).norm()
}

/// A dip of the closed loop below −3 dB that it climbs out of.
#[derive(Clone, Copy, Debug)]
pub struct Dip {
    /// The first frequency (Hz) past the bandwidth where `|L/(1 + L)|` is back at −3 dB.
    pub end_hz: f64,
    /// The least `|L/(1 + L)|` below it.
    pub floor: f64,
}

/// The dip of the loop `l` on the grid `f`; `None` when its closed loop does not climb back
/// to −3 dB past its bandwidth.
pub fn dip(f: &[f64], l: &[Complex64]) -> Option<Dip> {
    let b = l.iter().position(|&l| closed(l) < std::f64::consts::FRAC_1_SQRT_2)?;
    let e = (b..l.len()).find(|&k| closed(l[k]) >= std::f64::consts::FRAC_1_SQRT_2)?;
    Some(Dip { end_hz: f[e], floor: floor_up_to(f, l, f[e]) })
}

/// A loop's reach: the highest frequency of the grid `f` where `|L| ≥ 1` (its last gain
/// crossover; 0 when there is none). A loop whose `|L|` falls under 1 at a load's
/// anti-resonance and rises over it again has its first crossover there, below its reach.
pub fn reach_hz(f: &[f64], l: &[Complex64]) -> f64 {
    f.iter().zip(l).rev().find(|(_, l)| l.norm_sqr() >= 1.0).map_or(0.0, |(&f, _)| f)
}

/// The least `|L/(1 + L)|` at frequencies up to `hz`.
fn floor_up_to(f: &[f64], l: &[Complex64], hz: f64) -> f64 {
    f.iter().zip(l).take_while(|(&f, _)| f <= hz).map(|(_, &l)| closed(l)).fold(f64::INFINITY, f64::min)
}

/// The widest-bandwidth design near `start` on `plant` over `points` grid points with
/// `features` (Hz), keeping `goal`. `None` when the start itself does not keep them on
/// that grid.
pub fn refine(
    plant: &dyn Fn(f64) -> Complex64,
    period: f64,
    goal: &MarginGoal,
    start: &Design,
    points: usize,
    features: &[f64],
) -> Option<Design> {
    refine_on(&SampledPlant::new(plant, period, points, features), goal, start, None)
}

/// [`refine`] on a sampled plant, keeping `floor` where given.
pub fn refine_on(plant: &SampledPlant, goal: &MarginGoal, start: &Design, floor: Option<Floor>) -> Option<Design> {
    let f = &plant.hz;
    let (c, x) = Coordinates::of(start);
    let evaluate = |t: &VelocityTuning| -> Option<Margins> {
        if !admissible(t, 0.5 / plant.period) {
            return None;
        }
        let l = plant.loop_of(t);
        if floor.is_some_and(|(hz, least)| floor_up_to(f, &l, hz) < least) {
            return None;
        }
        margins(f, &l).filter(|m| goal.held_by(m))
    };
    let m0 = evaluate(&start.tuning)?;
    let (x, m) = compass(
        x,
        m0,
        &c.dims(),
        &|x| evaluate(&c.tuning(x)),
        &|a, b| a.bandwidth_hz > b.bandwidth_hz * (1.0 + 1e-4),
        &|_| false,
        false,
    );
    Some(Design { tuning: c.tuning(&x), margins: m, inertia: c.j })
}

/// The floor a lifted dip is kept at: `|L/(1 + L)|` at or over `.1` up to `.0` Hz.
pub type Floor = (f64, f64);

/// `start` with its closed loop's dip (see the module) lifted over −3 dB by
/// [`FLOOR_HEADROOM_DB`] within `goal` on `plant`, then refined for bandwidth with the dip
/// kept lifted; with the floor it keeps. `None` when `start` has no dip, does not keep
/// `goal`, or the dip cannot be lifted within it.
pub fn lift_dip_on(plant: &SampledPlant, goal: &MarginGoal, start: &Design) -> Option<(Design, Floor)> {
    let f = &plant.hz;
    let end = dip(f, &plant.loop_of(&start.tuning))?.end_hz;
    let target = std::f64::consts::FRAC_1_SQRT_2 * 10f64.powf(FLOOR_HEADROOM_DB / 20.0);
    let (c, x) = Coordinates::of(start);
    let floor = |t: &VelocityTuning| -> Option<f64> {
        if !admissible(t, 0.5 / plant.period) {
            return None;
        }
        let l = plant.loop_of(t);
        margins(f, &l).filter(|m| goal.held_by(m))?;
        Some(floor_up_to(f, &l, end))
    };
    let floor0 = floor(&start.tuning)?;
    let (x, lifted) =
        compass(x, floor0, &c.dims(), &|x| floor(&c.tuning(x)), &|a, b| *a > *b + 1e-6, &|s| *s >= target, true);
    if lifted < target {
        return None;
    }
    let at = Design { tuning: c.tuning(&x), ..*start };
    refine_on(plant, goal, &at, Some((end, target))).map(|d| (d, (end, target)))
}

/// `start`, a loop that misses `goal` on `plant` by a little or dips below −3 dB within its
/// reach ([`reach_hz`]), moved onto the margins with its closed loop kept `headroom_db` over
/// −3 dB (the search's own is [`FLOOR_HEADROOM_DB`]) up to `keep` of its reach: a compass
/// search for the least shortfall (Ms over its limit, the phase and gain margins under theirs
/// and the closed loop's floor under its target, in units of 0.01, 1°, 0.1 dB and 0.01 alike)
/// among stable loops that reach that far, then refined for bandwidth with the floor kept.
/// `None` when no such loop keeps it all.
pub fn restore_on(
    plant: &SampledPlant,
    goal: &MarginGoal,
    start: &Design,
    keep: f64,
    headroom_db: f64,
) -> Option<(Design, Floor)> {
    let f = &plant.hz;
    let (c, x) = Coordinates::of(start);
    let reach = reach_hz(f, &plant.loop_of(&start.tuning));
    let floor: Floor = (keep * reach, std::f64::consts::FRAC_1_SQRT_2 * 10f64.powf(headroom_db / 20.0));
    let shortfall = |m: &Margins, l: &[Complex64]| {
        (m.sensitivity_peak - goal.sensitivity_peak).max(0.0)
            + 0.01 * (goal.phase_margin_deg - m.phase_margin_deg).max(0.0)
            + 0.1 * (goal.gain_margin_db - m.gain_margin_db).max(0.0)
            + (floor.1 - floor_up_to(f, l, floor.0)).max(0.0)
    };
    let score = |x: &Point| -> Option<f64> {
        let t = c.tuning(x);
        if !admissible(&t, 0.5 / plant.period) {
            return None;
        }
        let l = plant.loop_of(&t);
        let m = margins(f, &l)?;
        (m.stable && reach_hz(f, &l) >= floor.0).then(|| shortfall(&m, &l))
    };
    let s0 = score(&x)?;
    let (x, s) = compass(x, s0, &c.dims(), &score, &|a, b| *a < *b - 1e-9, &|s| *s <= 0.0, true);
    if s > 0.0 {
        return None;
    }
    let tuning = c.tuning(&x);
    let m = margins(f, &plant.loop_of(&tuning)).filter(|m| goal.held_by(m))?;
    let at = Design { tuning, margins: m, inertia: c.j };
    Some((refine_on(plant, goal, &at, Some(floor)).unwrap_or(at), floor))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autotune::bench::Machine;
    use crate::autotune::design::{design, margins_of, SearchGrid};
    use crate::autotune::margins::log_grid;

    /// A dip is found where the closed loop climbs back to −3 dB, with its floor; a loop that
    /// rolls off for good has none.
    #[test]
    fn a_dip_is_where_the_closed_loop_climbs_back_over_minus_3_db() {
        let f: Vec<f64> = (1..=6).map(|k| k as f64 * 10.0).collect();
        // |T| = |L/(1 + L)| for a real L: 0.9, 0.6, 0.5, 0.8, 0.6, 0.3.
        let t = [0.9, 0.6, 0.5, 0.8, 0.6, 0.3];
        let l: Vec<Complex64> = t.iter().map(|&t| Complex64::new(t / (1.0 - t), 0.0)).collect();
        let d = dip(&f, &l).unwrap();
        assert_eq!(d.end_hz, 40.0);
        assert!((d.floor - 0.5).abs() < 1e-12, "{d:?}");
        assert!(dip(&f[..3], &l[..3]).is_none());
    }

    /// A heavy load (4.22 times the motor, shaft at 55.7 Hz, ζ 0.05: seed 7's machine 29 on
    /// the default axis): its anti-resonance dips the closed loop below −3 dB at about 24 Hz
    /// at every gain of the ladder that keeps the margins. The design lifts it, with the
    /// standard margins and with the calibrated model's reserve: on a dense grid its closed
    /// loop stays over −3 dB from 0.5 Hz to beyond ten times the anti-resonance, and its
    /// margins hold there.
    #[test]
    fn the_design_lifts_a_heavy_loads_anti_resonance_dip_and_keeps_its_margins() {
        let machine = Machine { inertia_ratio: 4.22, resonance_hz: 55.7, damping_ratio: 0.0508, absorber: None };
        let (period, drive, m) = machine.axis();
        let (_, fa) = m.resonance_hz();
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f);
        let standard = MarginGoal::named("standard").unwrap();
        for goal in [standard, standard.with_reserve(crate::autotune::reserve::Reserve::Full)] {
            let d = design(&plant, period, &goal, &SearchGrid::STANDARD, &m.features_hz()).unwrap();
            let dense = margins_of(&d.tuning, &plant, period, 20_000, &m.features_hz()).unwrap();
            assert!(goal.held_by(&dense), "{dense:?}");
            assert!(dense.bandwidth_hz > 10.0 * fa, "{} Hz, the anti-resonance at {fa} Hz", dense.bandwidth_hz);
            // The closed loop itself, beside `margins`: over −3 dB through the anti-resonance.
            let t = |f: f64| {
                let l = d.tuning.response(f, period) * plant(f);
                (l / (1.0 + l)).norm()
            };
            let least = log_grid(0.5, 10.0 * fa, 20_000).into_iter().map(t).fold(1.0, f64::min);
            assert!(least > std::f64::consts::FRAC_1_SQRT_2, "{least}");
        }
    }

    /// A shaft whose loops past the resonance keep the margins only on a sliver (seed 1's
    /// machine 52 on the default axis: load 1.10 times the motor, shaft at 91 Hz, ζ 0.05): a
    /// loop of the ladder beside it, with a notch on the resonance, dips below −3 dB at the
    /// anti-resonance and misses Ms by a little. Moved onto the margins with the reserve a
    /// calibrated model is designed with, it reaches past the resonance: a bandwidth of more
    /// than five times the shaft's resonance, the margins kept on a denser grid, and the
    /// closed loop over the floor it was given up to there.
    #[test]
    fn a_near_miss_beside_the_sliver_is_moved_onto_the_margins_past_the_resonance() {
        let machine = Machine { inertia_ratio: 1.10, resonance_hz: 91.0, damping_ratio: 0.05, absorber: None };
        let (period, drive, m) = machine.axis();
        let (fr, _) = m.resonance_hz();
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f);
        let goal = MarginGoal::named("standard").unwrap().with_reserve(crate::autotune::reserve::Reserve::Close);
        let sampled = SampledPlant::new(&plant, period, 2400, &m.features_hz());
        let inertia = crate::autotune::design::rigid_inertia_of(&plant, period);
        let tuning = VelocityTuning {
            kp: 0.1085,
            ki: 74.7,
            low_pass_hz: 0.0,
            notch: Some(Notch { hz: fr, q: 2.0, depth: 0.1 }),
            notch2: None,
        };
        let l = sampled.loop_of(&tuning);
        let start_margins = margins(&sampled.hz, &l).unwrap();
        assert!(!goal.held_by(&start_margins), "the start misses the margins: {start_margins:?}");
        assert!(start_margins.bandwidth_hz < fr && reach_hz(&sampled.hz, &l) > 3.0 * fr, "{start_margins:?}");
        let start = Design { tuning, margins: start_margins, inertia };
        let (d, (up_to, least)) = restore_on(&sampled, &goal, &start, 0.8, FLOOR_HEADROOM_DB).expect("restored");
        assert!(goal.held_by(&d.margins) && d.margins.bandwidth_hz > 5.0 * fr, "{:?}", d.margins);
        let dense = margins_of(&d.tuning, &plant, period, 20_000, &m.features_hz()).unwrap();
        assert!(goal.held_by(&dense) && dense.bandwidth_hz > 5.0 * fr, "{dense:?}");
        let t = |f: f64| {
            let l = d.tuning.response(f, period) * plant(f);
            (l / (1.0 + l)).norm()
        };
        let floor = log_grid(0.5, up_to, 20_000).into_iter().map(t).fold(1.0, f64::min);
        assert!(floor > 0.99 * least && least > std::f64::consts::FRAC_1_SQRT_2, "{floor} against {least}");
    }
}
