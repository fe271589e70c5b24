//! Gains and filters from a plant's response: the velocity PI, the torque low-pass and a notch
//! on the resonance above the crossover (two notches on two resonances), chosen for the widest closed-loop bandwidth whose
//! loop keeps its margins (phase margin, gain margin, sensitivity peak `Ms`).
//!
//! The plant `P` (torque command → velocity estimate, as the torque point of a sweep
//! measures it) is taken on a dense grid from a model (the measured points are too sparse to
//! follow a lightly damped resonance). The search: the rigid body's inertia `J` from the
//! lowest frequencies; candidate filter sets — no low-pass or one of a ladder of cut-offs,
//! no notch or a notch on each resonance peak of `s·P` (the acceleration per torque, flat
//! on a rigid body) with a ladder of depths and widths, and where there are two peaks the best
//! notch's family with a second notch on the other peak; the PI's integral corner set from its
//! proportional gain (`ki = kp²/(n·J)`, the crossover over `n`, for a few `n`). For each set
//! the proportional gain runs up a log ladder, and the widest bandwidth whose margins hold
//! is kept, then refined by a compass search over the continuous parameters. Beside it, for
//! each notch family and integral ratio, the candidate whose closed loop dips below −3 dB at
//! a load's anti-resonance and climbs back over it (the highest such dip, over the low-pass
//! cut-offs) has its dip lifted (`refinement::lift_dip_on`): the bandwidth of such a loop is the
//! dip's, and the loop that lifts it lies past a cliff the bandwidth's refinement does not
//! climb. And each family's loop of the farthest reach (its last gain crossover) that keeps
//! the margins or misses them by a little is moved onto them with its dip lifted
//! (`refinement::restore_on`): on a lightly damped shaft the loops past the resonance that
//! keep the margins lie on a sliver narrower than the ladder's steps (a notch on the
//! resonance, its centre, width and depth and the gain within a few percent), and the ladder
//! sees only the loops beside it. Where the widest loop still falls short of the farthest
//! near misses' reach, those near misses get a second notch that shapes their phase (broad
//! and shallow, below their crossover: `shaping_notches`), their first notch kept, raised
//! above the resonance or replaced by a broad one past their crossover (`first_notches`),
//! and are moved onto the margins with it. The widest loop of all is polished last: refined
//! again from itself and its own dip lifted, the widest of the three kept.

use num_complex::Complex64;
use serde::{Deserialize, Serialize};

use super::margins::{log_grid, margins, Margins};
use super::refinement::{dip, lift_dip_on, reach_hz, refine_on, restore_on, FLOOR_HEADROOM_DB};
use super::reserve::Reserve;
use super::sampled_plant::SampledPlant;
use super::velocity_controller::{Notch, VelocityTuning};

/// The margins a design must keep.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct MarginGoal {
    pub phase_margin_deg: f64,
    pub gain_margin_db: f64,
    pub sensitivity_peak: f64,
}

impl MarginGoal {
    /// `conservative`, `standard` or `aggressive`: Ms 1.3, 1.6, 2.0, with a phase margin of
    /// 45° and a gain margin of 6 dB.
    pub fn named(name: &str) -> Option<Self> {
        let ms = match name {
            "conservative" => 1.3,
            "standard" => 1.6,
            "aggressive" => 2.0,
            _ => return None,
        };
        Some(Self { phase_margin_deg: 45.0, gain_margin_db: 6.0, sensitivity_peak: ms })
    }

    /// The margins a design on a calibrated model aims for: `self` with `reserve` beside it,
    /// for what the model misses of the machine (the loop verified on the machine is held to
    /// `self`).
    pub fn with_reserve(&self, reserve: Reserve) -> Self {
        let (phase_deg, gain_db, sensitivity) = reserve.margins();
        Self {
            phase_margin_deg: self.phase_margin_deg + phase_deg,
            gain_margin_db: self.gain_margin_db + gain_db,
            sensitivity_peak: self.sensitivity_peak - sensitivity,
        }
    }

    pub fn held_by(&self, m: &Margins) -> bool {
        m.stable
            && m.phase_margin_deg >= self.phase_margin_deg
            && m.gain_margin_db >= self.gain_margin_db
            && m.sensitivity_peak <= self.sensitivity_peak
    }
}

/// How fine the search is (the oracle's is finer).
#[derive(Clone, Copy, Debug)]
pub struct SearchGrid {
    pub grid_points: usize,
    pub gains: usize,
    pub low_passes: usize,
    pub notch_depths: &'static [f64],
    pub notch_qs: &'static [f64],
    pub notch_shifts: &'static [f64],
    pub integral_ratios: &'static [f64],
    /// With two resonance peaks, a second notch on the one the best notch leaves.
    pub second_notch: bool,
    /// Where the widest loop falls short of the farthest near misses' reach, a second notch
    /// that shapes their phase ([`shaping_notches`]).
    pub shaping_notch: bool,
    /// Those near misses also moved with a broad first notch past their crossover in place of
    /// their own ([`PAST_CROSSOVER_NOTCH`]).
    pub past_crossover_notch: bool,
}

impl SearchGrid {
    pub const STANDARD: Self = Self {
        grid_points: 2400,
        gains: 48,
        low_passes: 8,
        notch_depths: &[0.0, 0.1, 0.3],
        notch_qs: &[0.5, 1.0, 2.0],
        notch_shifts: &[1.0],
        // Down to 1.5: where the load's anti-resonance dips the closed loop near −3 dB, the
        // integral action that lifts the dip over it (and the bandwidth to the loop's upper
        // reach) lies in a basin of its own, which a refinement from 4 does not reach.
        integral_ratios: &[1.5, 2.0, 3.0, 4.0, 6.0, 10.0],
        second_notch: true,
        shaping_notch: true,
        past_crossover_notch: true,
    };
    pub const FINE: Self = Self {
        grid_points: 4000,
        gains: 160,
        low_passes: 20,
        notch_depths: &[0.0, 0.03, 0.1, 0.2, 0.3, 0.5],
        notch_qs: &[0.35, 0.5, 0.7, 1.0, 1.4, 2.0, 3.0],
        notch_shifts: &[0.85, 0.92, 1.0, 1.08, 1.17],
        integral_ratios: &[3.0, 4.0, 5.0, 6.0, 8.0, 10.0, 15.0],
        second_notch: true,
        shaping_notch: true,
        past_crossover_notch: true,
    };
}

/// A design and its margins on the plant it was designed on.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Design {
    pub tuning: VelocityTuning,
    pub margins: Margins,
    /// The rigid body's inertia the design read from the plant (kg·m²).
    pub inertia: f64,
}

/// Lowest frequency of the design grid (Hz).
const LOW_HZ: f64 = 0.5;

/// The highest notch centre, as a share of the loop's Nyquist frequency.
pub const NOTCH_LIMIT: f64 = 0.9;

/// The lowest notch centre a design takes (Hz).
pub const LOWEST_NOTCH_HZ: f64 = 1.0;

/// The design grid: `points` frequencies log-spaced from [`LOW_HZ`] to just below the loop's
/// Nyquist frequency, with the plant's `features` (its modes' frequencies, which a lightly
/// damped mode's narrow peak needs) merged in.
pub fn design_grid(period: f64, points: usize, features: &[f64]) -> Vec<f64> {
    let high = 0.999 * 0.5 / period;
    let mut f = log_grid(LOW_HZ, high, points);
    f.extend(features.iter().copied().filter(|&x| x.is_finite() && x > LOW_HZ && x < high));
    f.sort_by(f64::total_cmp);
    f.dedup();
    f
}

/// The widest-bandwidth tuning for `plant` (torque command → velocity estimate at a frequency
/// in Hz) on a loop ticking every `period` s, on the design grid with `features` (Hz) in it;
/// `None` when no candidate keeps the margins.
pub fn design(
    plant: &dyn Fn(f64) -> Complex64,
    period: f64,
    goal: &MarginGoal,
    grid: &SearchGrid,
    features: &[f64],
) -> Option<Design> {
    let nyquist = 0.5 / period;
    let sampled = SampledPlant::new(plant, period, grid.grid_points, features);
    let (f, p) = (&sampled.hz, &sampled.response);
    let inertia = rigid_inertia(f, p)?;
    let peaks = resonance_peaks(f, p, inertia);
    let notches = notch_candidates(&peaks, grid, nyquist);
    let mut low_passes = vec![0.0];
    low_passes.extend(log_grid(150.0, 0.45 * nyquist, grid.low_passes));
    // Proportional gains: crossovers (kp/J) from 2 Hz to a quarter of the loop's rate.
    let gains =
        log_grid(inertia * std::f64::consts::TAU * 2.0, inertia * std::f64::consts::TAU * 0.5 * nyquist, grid.gains);
    let ladders = Ladders { sampled: &sampled, goal, grid, inertia, low_passes: &low_passes, gains: &gains };
    // Each notch family (none, or one centre/width/depth on a peak): its best candidate, and
    // for each integral ratio the candidate whose closed loop climbs out of a dip below −3 dB
    // with the highest floor (the nearest to lifting it: see `refinement`).
    let mut results: Vec<Ladder> = notches.iter().map(|&n| ladders.run((n, None))).collect();
    // Two resonances: the best family with a notch keeps it, and a second notch goes on the
    // other peak (each of the grid's shifts, depths and widths).
    if let (&[a, b], true) = (&peaks[..], grid.second_notch) {
        let best_notched = results
            .iter()
            .filter_map(|r| r.best)
            .filter(|d| d.tuning.notch.is_some())
            .max_by(|x, y| x.margins.bandwidth_hz.total_cmp(&y.margins.bandwidth_hz));
        if let Some(first) = best_notched.and_then(|d| d.tuning.notch) {
            let other = if (first.hz / a).ln().abs() <= (first.hz / b).ln().abs() { b } else { a };
            let seconds = notch_candidates(&[other], grid, nyquist);
            results.extend(seconds.into_iter().flatten().map(|n2| ladders.run((Some(first), Some(n2)))));
        }
    }
    let family_best: Vec<Option<Design>> = results.iter().map(|r| r.best).collect();
    let mut near_misses: Vec<(Design, f64)> = results.iter().filter_map(|r| r.near_miss).collect();
    let family_dip: Vec<Option<(Design, f64)>> = results.into_iter().flat_map(|r| r.dips).collect();
    // The best few families, each refined over the continuous parameters: on a light load the
    // gains that lift the loop over the anti-resonance's dip and still keep Ms lie within a
    // few percent, narrower than the ladder's step, and the family that wins on the ladder
    // is not always the one that wins refined.
    let mut candidates: Vec<Design> = family_best.into_iter().flatten().collect();
    candidates.sort_by(|a, b| b.margins.bandwidth_hz.total_cmp(&a.margins.bandwidth_hz));
    let dips: Vec<(Design, f64)> = family_dip.into_iter().flatten().collect();
    let refined =
        candidates.iter().take(REFINED_FAMILIES).map(|c| (refine_on(&sampled, goal, c, None).unwrap_or(*c), None));
    // Every dip is lifted: which one lifts is not the one nearest to it (the margins bind
    // each start differently).
    let lifted = dips.iter().filter_map(|(c, _)| lift_dip_on(&sampled, goal, c)).map(|(d, floor)| (d, Some(floor)));
    // The widest near misses, each moved onto the margins (see `Ladder::near_miss`).
    near_misses.sort_by(|a, b| b.1.total_cmp(&a.1));
    let restored = near_misses
        .iter()
        .take(RESTORED_NEAR_MISSES)
        .filter_map(|(c, _)| restore_on(&sampled, goal, c, NEAR_MISS_KEPT_REACH, FLOOR_HEADROOM_DB))
        .map(|(d, floor)| (d, Some(floor)));
    let widest = refined.chain(lifted).chain(restored).max_by(|a, b| by_bandwidth(&a.0, &b.0));
    // Where that loop falls short of the farthest near misses' reach, a second notch below
    // their crossover shapes the loop's phase there (see `shaping_notches`), and each such
    // near miss is moved onto the margins with it: the two of the farthest reach, and the
    // next ones in turn until one reaches (see `SHAPED_NEAR_MISSES`).
    let short_of = |reach: f64| widest.is_none_or(|(w, _)| w.margins.bandwidth_hz < NEAR_MISS_KEPT_REACH * reach);
    let mut shaped = Vec::new();
    let (mut tried, mut reached) = (0, false);
    let shaping =
        near_misses.iter().filter(|(c, reach)| grid.shaping_notch && c.tuning.notch2.is_none() && short_of(*reach));
    for &(c, reach) in shaping {
        if tried == SHAPED_NEAR_MISSES_AT_MOST || (tried >= SHAPED_NEAR_MISSES && reached) {
            break;
        }
        tried += 1;
        let starts = first_notches(c.tuning.notch, reach, nyquist, grid.past_crossover_notch).flat_map(|notch| {
            shaping_notches(reach, nyquist)
                .map(move |n2| Design { tuning: VelocityTuning { notch, notch2: Some(n2), ..c.tuning }, ..c })
        });
        for (d, floor) in starts.filter_map(|s| restore_on(&sampled, goal, &s, NEAR_MISS_KEPT_REACH, FLOOR_HEADROOM_DB))
        {
            reached |= d.margins.bandwidth_hz >= NEAR_MISS_KEPT_REACH * reach;
            shaped.push((d, Some(floor)));
        }
    }
    let (widest, floor) = widest.into_iter().chain(shaped).max_by(|a, b| by_bandwidth(&a.0, &b.0))?;
    // The widest polished: its compass search restarted from it with the first steps again
    // (a search that ended on a small step may sit below a cliff its large steps cross),
    // keeping its floor where it is a lifted dip's or a restored near miss's, and its own dip
    // lifted where it has one.
    let polished = [refine_on(&sampled, goal, &widest, floor), lift_dip_on(&sampled, goal, &widest).map(|(d, _)| d)];
    let best = polished.into_iter().flatten().chain([widest]).max_by(by_bandwidth)?;
    Some(Design { tuning: first_notch_first(best.tuning), ..best })
}

/// A tuning's notches with the first slot filled first: a shaping notch where the loop kept
/// no notch on a resonance is the drive's first notch (the two are in series: the loop is
/// the same).
fn first_notch_first(mut t: VelocityTuning) -> VelocityTuning {
    if t.notch.is_none() {
        t.notch = t.notch2.take();
    }
    t
}

/// Designs ordered by their bandwidth.
fn by_bandwidth(a: &Design, b: &Design) -> std::cmp::Ordering {
    a.margins.bandwidth_hz.total_cmp(&b.margins.bandwidth_hz)
}

/// The search's ladders over one notch family: every low-pass cut-off, integral ratio and
/// proportional gain of the grid.
struct Ladders<'a> {
    sampled: &'a SampledPlant,
    goal: &'a MarginGoal,
    grid: &'a SearchGrid,
    inertia: f64,
    low_passes: &'a [f64],
    gains: &'a [f64],
}

/// A family's ladders: the widest candidate that keeps the margins, for each integral ratio
/// the candidate with the highest dip floor, and the widest near miss.
struct Ladder {
    best: Option<Design>,
    dips: Vec<Option<(Design, f64)>>,
    /// The candidate of the farthest reach ([`reach_hz`]) that keeps the margins or misses
    /// them by a little ([`near_miss`]), where its reach is past every bandwidth the family
    /// delivers. On a lightly damped shaft with a notch on its resonance, the loops that keep
    /// the margins and the closed loop over −3 dB through the anti-resonance lie on a sliver
    /// a few percent wide in the gain and the notch's centre, width and depth; the ladder's
    /// steps straddle it and see only the loops beside it, which miss Ms or the phase margin
    /// by a little or dip at the anti-resonance (a bandwidth below the resonance). Moved onto
    /// the margins with the dip lifted ([`restore_on`]), such a loop reaches the sliver.
    near_miss: Option<(Design, f64)>,
}

/// How many near misses (those of the farthest reach) are moved onto the margins.
const RESTORED_NEAR_MISSES: usize = 12;

/// The share of its reach ([`reach_hz`]) a near miss keeps while it is moved (and a loop
/// at the goal moved onto a reserve, `MeasuredMechanics::design`).
pub(crate) const NEAR_MISS_KEPT_REACH: f64 = 0.8;

/// Whether a stable loop keeps `goal` or misses it by a little: Ms within 0.1 over it, the
/// phase margin within 5°, the gain margin within 2 dB under it.
fn near_miss(goal: &MarginGoal, m: &Margins) -> bool {
    m.stable
        && m.sensitivity_peak <= goal.sensitivity_peak + 0.1
        && m.phase_margin_deg >= goal.phase_margin_deg - 5.0
        && m.gain_margin_db >= goal.gain_margin_db - 2.0
}

impl Ladders<'_> {
    fn run(&self, (notch, notch2): (Option<Notch>, Option<Notch>)) -> Ladder {
        let (f, p, period) = (&self.sampled.hz, &self.sampled.response, self.sampled.period);
        let (inertia, goal) = (self.inertia, self.goal);
        let mut best: Option<Design> = None;
        let mut near: Option<(Design, f64)> = None;
        let mut dips: Vec<Option<(Design, f64)>> = vec![None; self.grid.integral_ratios.len()];
        let z = &self.sampled.z;
        for &low_pass_hz in self.low_passes {
            let filters: Vec<Complex64> = {
                let t = VelocityTuning { kp: 1.0, ki: 0.0, low_pass_hz, notch, notch2 }.at_period(period);
                z.iter().map(|&z| t.at(z)).collect()
            };
            for (ni, &n) in self.grid.integral_ratios.iter().enumerate() {
                let best_dip = &mut dips[ni];
                // The whole ladder: on a light load the margins fail while the crossover
                // passes the resonance and hold again above it.
                for &kp in self.gains {
                    let ki = kp * kp / (n * inertia);
                    let l: Vec<Complex64> =
                        (0..f.len()).map(|k| (kp + ki * period * z[k] / (z[k] - 1.0)) * filters[k] * p[k]).collect();
                    let Some(m) = margins(f, &l) else { continue };
                    let tuning = VelocityTuning { kp, ki, low_pass_hz, notch, notch2 };
                    if near_miss(goal, &m) {
                        let reach = reach_hz(f, &l);
                        if near.is_none_or(|(_, r)| reach > r) {
                            near = Some((Design { tuning, margins: m, inertia }, reach));
                        }
                    }
                    if !goal.held_by(&m) {
                        continue;
                    }
                    let candidate = Design { tuning, margins: m, inertia };
                    if best.is_none_or(|b| m.bandwidth_hz > b.margins.bandwidth_hz) {
                        best = Some(candidate);
                    }
                    if let Some(d) = dip(f, &l) {
                        if best_dip.is_none_or(|(_, floor)| d.floor > floor) {
                            *best_dip = Some((candidate, d.floor));
                        }
                    }
                }
            }
        }
        // Only a near miss that reaches past the family's best bandwidth is worth moving.
        let near_miss = near.filter(|(_, reach)| best.is_none_or(|b| *reach > b.margins.bandwidth_hz));
        Ladder { best, dips, near_miss }
    }
}

/// How many near misses (those of the farthest reach) get a shaping second notch
/// ([`shaping_notches`]) where the widest loop falls short of their reach; and where none of
/// those is moved onto the margins with a bandwidth of [`NEAR_MISS_KEPT_REACH`] of its reach,
/// the next ones in turn, up to [`SHAPED_NEAR_MISSES_AT_MOST`], until one is. Whether a near
/// miss is moved that far turns on a compass search's path, not on how far it reaches: on the
/// calibrated model of the absorbers draw's machine 37 of 40 over the virtual drive (with a
/// drive model without the back-EMF path; a load of 2.9 times the motor on a 64 Hz shaft, an
/// absorber at 49 Hz) the two near misses of the
/// farthest reach (327 and 321 Hz) move onto no loop wider than 28 Hz, the third onto
/// 741 Hz; with the winding's resistance and inductance 0.02 % and 0.9 % nearer
/// the truth in the model, the first two move onto 754 and 732 Hz.
const SHAPED_NEAR_MISSES: usize = 2;

/// The most near misses that get a shaping notch, in all ([`SHAPED_NEAR_MISSES`]).
const SHAPED_NEAR_MISSES_AT_MOST: usize = 6;

/// The second notches tried to shape a near miss's loop: centres at a few shares of its
/// reach (its last gain crossover, Hz), each with two widths and depths. On a lightly damped
/// shaft whose loop past the resonance keeps the phase margin only on a sliver, a broad,
/// shallow notch at a third to nine tenths of the crossover lends the loop phase there (a
/// notch's phase rises through its centre and leads above it) at the cost of a little gain
/// below: on seed 1's machine 65 (shaft 54.5 Hz, ζ 0.010) the design with the full reserve
/// stays at 38 Hz without a shaping notch and reaches 938 Hz with one.
fn shaping_notches(reach_hz: f64, nyquist: f64) -> impl Iterator<Item = Notch> {
    const CENTRES: [f64; 4] = [0.3, 0.45, 0.65, 0.9];
    const QS: [f64; 2] = [0.5, 1.0];
    const DEPTHS: [f64; 2] = [0.3, 0.6];
    CENTRES
        .into_iter()
        .map(move |share| share * reach_hz)
        .filter(move |&hz| hz > LOWEST_NOTCH_HZ && hz < NOTCH_LIMIT * nyquist)
        .flat_map(|hz| QS.into_iter().flat_map(move |q| DEPTHS.into_iter().map(move |depth| Notch { hz, q, depth })))
}

/// The first notches a shaped near miss is moved with: its own, and where it has one (on a
/// peak of the response), that notch raised to [`RAISED_FIRST_NOTCH`] times its centre with a gain of
/// one half there (its Q kept), below [`NOTCH_LIMIT`] of the loop's Nyquist frequency. A loop
/// that crosses over past the resonance can keep its phase there with a notch above the
/// resonance rather than on it: on seed 1's machine 43 of 200 (a load of 0.23 times the motor
/// on a 147 Hz shaft, ζ 0.026) the oracle's loop on the truth has its first notch at 1.43
/// times the resonance with a gain of one half, and the shaping notch at 3.5 times. Moved from
/// the near miss with its notch on the resonance, no shaping notch takes a loop past 130 Hz on
/// the calibrated model; with the notch raised, the design reaches 784 Hz (on the model as on
/// the truth). And, with `past_crossover`, with or without a notch of its own, a broad notch
/// past its reach ([`PAST_CROSSOVER_NOTCH`]).
fn first_notches(
    notch: Option<Notch>,
    reach_hz: f64,
    nyquist: f64,
    past_crossover: bool,
) -> impl Iterator<Item = Option<Notch>> {
    let raised = notch.into_iter().flat_map(move |n| {
        RAISED_FIRST_NOTCH
            .into_iter()
            .map(move |k| Notch { hz: k * n.hz, depth: RAISED_FIRST_NOTCH_DEPTH, ..n })
            .filter(move |n| n.hz < NOTCH_LIMIT * nyquist)
            .map(Some)
    });
    let past_crossover = PAST_CROSSOVER_NOTCH
        .into_iter()
        .filter(move |_| past_crossover)
        .map(move |k| Notch { hz: k * reach_hz, q: PAST_CROSSOVER_NOTCH_Q, depth: PAST_CROSSOVER_NOTCH_DEPTH })
        .filter(move |n| n.hz > LOWEST_NOTCH_HZ && n.hz < NOTCH_LIMIT * nyquist)
        .map(Some);
    std::iter::once(notch).chain(raised).chain(past_crossover)
}

/// The shares of a shaped near miss's reach (its last gain crossover) where a broad first
/// notch past it is tried in place of its own ([`first_notches`]). Such a notch takes gain off
/// where the loop's phase crosses −180° (the gain margin and Ms) for little phase at the
/// crossover, and the loop can then carry the proportional and integral gain that lift a
/// heavy load's anti-resonance dip: on seed 1's machine 9 of 200 (a load of 3.5 times the
/// motor on a 51 Hz shaft, ζ 0.011) the near misses reach 367 Hz with the dip's floor at
/// 0.13, and moved with a shaping notch and their own first notch (on a peak at 2 kHz, raised
/// or not) they reach no wider loop: without a broad notch past their reach the design stays
/// under the anti-resonance at 23 Hz. Started at 2 and 3 times the reach, the broad notch and
/// the shaping notch move to about 1.4 kHz and 240 Hz, and the loop reaches past 900 Hz on
/// the calibrated model and on the truth.
const PAST_CROSSOVER_NOTCH: [f64; 2] = [2.0, 3.0];
/// The broad notch past the crossover: its width and its gain at its centre.
const PAST_CROSSOVER_NOTCH_Q: f64 = 0.5;
const PAST_CROSSOVER_NOTCH_DEPTH: f64 = 0.5;

/// The shares of its centre a shaped near miss's first notch is raised to ([`first_notches`]).
const RAISED_FIRST_NOTCH: [f64; 2] = [1.2, 1.45];
/// The raised first notch's gain at its centre ([`Notch::depth`]).
const RAISED_FIRST_NOTCH_DEPTH: f64 = 0.5;

/// How many of the search's best notch families are refined.
const REFINED_FAMILIES: usize = 4;

/// The notches the search tries: none, and on each resonance peak (Hz) each of the grid's
/// shifts, depths and widths whose centre lies below [`NOTCH_LIMIT`] of the loop's Nyquist
/// frequency (above it, it would alias onto a lower one).
fn notch_candidates(peaks: &[f64], grid: &SearchGrid, nyquist: f64) -> Vec<Option<Notch>> {
    let mut notches = vec![None];
    for &fr in peaks {
        for shift in grid.notch_shifts.iter().copied().filter(|s| fr * s < NOTCH_LIMIT * nyquist) {
            for &depth in grid.notch_depths {
                for &q in grid.notch_qs {
                    notches.push(Some(Notch { hz: fr * shift, q, depth }));
                }
            }
        }
    }
    notches
}

/// The margins of `tuning` on `plant` over the design grid with `features`.
pub fn margins_of(
    tuning: &VelocityTuning,
    plant: &dyn Fn(f64) -> Complex64,
    period: f64,
    points: usize,
    features: &[f64],
) -> Option<Margins> {
    SampledPlant::new(plant, period, points, features).margins_of(tuning)
}

/// The rigid body's inertia of `plant` as `design` reads it.
pub fn rigid_inertia_of(plant: &dyn Fn(f64) -> Complex64, period: f64) -> f64 {
    let f = log_grid(LOW_HZ, 0.999 * 0.5 / period, SearchGrid::STANDARD.grid_points);
    let p: Vec<Complex64> = f.iter().map(|&f| plant(f)).collect();
    rigid_inertia(&f, &p).unwrap_or(f64::NAN)
}

/// The rigid body's inertia: `1/|s·P|` over the lowest decade of the grid (median).
fn rigid_inertia(f: &[f64], p: &[Complex64]) -> Option<f64> {
    let mut j: Vec<f64> = f
        .iter()
        .zip(p)
        .take_while(|(&f, _)| f <= 10.0 * LOW_HZ)
        .map(|(&f, p)| 1.0 / (std::f64::consts::TAU * f * p.norm()))
        .filter(|j| j.is_finite() && *j > 0.0)
        .collect();
    if j.is_empty() {
        return None;
    }
    j.sort_by(f64::total_cmp);
    Some(j[j.len() / 2])
}

/// Resonances: local peaks of `|s·P|·J` (1 on a rigid body) at least 3 dB up, above 10 Hz.
fn resonance_peaks(f: &[f64], p: &[Complex64], inertia: f64) -> Vec<f64> {
    let a: Vec<f64> = f.iter().zip(p).map(|(&f, p)| std::f64::consts::TAU * f * p.norm() * inertia).collect();
    let mut peaks: Vec<usize> = (1..a.len() - 1)
        .filter(|&k| f[k] > 10.0 && a[k] > a[k - 1] && a[k] >= a[k + 1] && a[k] > std::f64::consts::SQRT_2)
        .collect();
    // The two highest.
    peaks.sort_by(|&x, &y| a[y].total_cmp(&a[x]));
    peaks.truncate(2);
    peaks.into_iter().map(|k| f[k]).collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autotune::drive_dynamics::DriveDynamics;
    use crate::autotune::mechanics::Mechanics;
    use crate::autotune::refinement::refine;

    /// Notch candidates on peaks near the loop's Nyquist frequency: every centre lies below
    /// 0.9 of it (a shifted one above is dropped, the peak's own kept where it fits), and a
    /// design on a resonance just below Nyquist keeps its margins on a denser grid.
    #[test]
    fn a_notch_never_lands_at_or_above_the_nyquist_frequency() {
        let params = control_core::Params::default();
        let period = params.rates.velocity_period() as f64;
        let nyquist = 0.5 / period;
        let grid = SearchGrid { notch_shifts: &[1.0, 1.17], ..SearchGrid::STANDARD };
        let per_shift = grid.notch_depths.len() * grid.notch_qs.len();
        // At 0.8 of Nyquist the shift 1.17 lands above the limit: only the peak's own centre.
        let c = notch_candidates(&[0.8 * nyquist], &grid, nyquist);
        assert_eq!(c.len(), 1 + per_shift);
        assert!(c
            .iter()
            .flatten()
            .all(|n| n.hz < NOTCH_LIMIT * nyquist && (n.hz / (0.8 * nyquist) - 1.0).abs() < 1e-12));
        // At 0.95, none; at 0.5, both shifts.
        assert_eq!(notch_candidates(&[0.95 * nyquist], &grid, nyquist).len(), 1);
        assert_eq!(notch_candidates(&[0.5 * nyquist], &grid, nyquist).len(), 1 + 2 * per_shift);
        let drive = DriveDynamics::as_configured(&params);
        let goal = MarginGoal::named("standard").unwrap();
        let m = Mechanics::two_inertia(1.5e-4, 1e-4, 0.8 * nyquist, 0.01);
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f);
        let d = design(&plant, period, &goal, &grid, &m.features_hz()).unwrap();
        assert!(d.tuning.notch.is_none_or(|n| n.hz < NOTCH_LIMIT * nyquist), "{d:?}");
        let dense = margins_of(&d.tuning, &plant, period, 12_000, &m.features_hz()).unwrap();
        assert!(goal.held_by(&dense), "{dense:?}");
    }

    /// A machine with a second mode above the shaft's (an absorber's resonance and
    /// anti-resonance on the load): the design puts a notch on each peak and reaches a wider
    /// loop than the best single notch does, and the two-notch loop keeps its margins on a
    /// dense grid.
    #[test]
    fn a_second_resonance_gets_a_second_notch_and_a_wider_loop() {
        let params = control_core::Params::default();
        let drive = DriveDynamics::as_configured(&params);
        let period = params.rates.velocity_period() as f64;
        let goal = MarginGoal::named("standard").unwrap();
        let m = Mechanics::two_inertia(1.5e-4, 0.6e-4, 420.0, 0.02);
        // The second mode: a pole pair at 1.3 kHz over a zero pair at 1.1 kHz (unit gain at
        // DC), lightly damped.
        let mode = |f: f64| {
            let s = Complex64::new(0.0, std::f64::consts::TAU * f);
            let (wz, wp) = (std::f64::consts::TAU * 1100.0, std::f64::consts::TAU * 1300.0);
            let (zz, zp) = (0.02, 0.02);
            (s * s + 2.0 * zz * wz * s + wz * wz) / (s * s + 2.0 * zp * wp * s + wp * wp) * (wp * wp / (wz * wz))
        };
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f) * mode(f);
        let mut features = m.features_hz().to_vec();
        features.extend([1100.0, 1300.0, 1100.0 * 0.98, 1100.0 * 1.02, 1300.0 * 0.98, 1300.0 * 1.02]);
        let two = design(&plant, period, &goal, &SearchGrid::STANDARD, &features).unwrap();
        let one_grid = SearchGrid { second_notch: false, shaping_notch: false, ..SearchGrid::STANDARD };
        let one = design(&plant, period, &goal, &one_grid, &features).unwrap();
        assert!(one.tuning.notch2.is_none());
        let (n1, n2) = (two.tuning.notch.expect("a first notch"), two.tuning.notch2.expect("a second notch"));
        // One notch near the shaft's resonance, the other nearer the second mode's peak than
        // its zero.
        let on_shaft = |n: Notch| (n.hz / 420.0).ln().abs() < 0.3;
        let on_second = |n: Notch| (n.hz / 1300.0).ln().abs() < (n.hz / 1100.0).ln().abs();
        assert!(on_shaft(n1) && on_second(n2) || on_second(n1) && on_shaft(n2), "{two:?}");
        eprintln!("one notch: {:.0} Hz; two: {:.0} Hz", one.margins.bandwidth_hz, two.margins.bandwidth_hz);
        assert!(two.margins.bandwidth_hz > 1.1 * one.margins.bandwidth_hz, "{two:?} against {one:?}");
        let dense = margins_of(&two.tuning, &plant, period, 50_000, &features).unwrap();
        assert!(goal.held_by(&dense), "{dense:?}");
    }

    /// A lightly damped shaft whose loops past the resonance keep the phase margin only with
    /// a shaping notch (seed 1's machine 65 of 200 on the default axis: load 0.98 times the
    /// motor, shaft at 54.5 Hz, ζ 0.010). Without a shaping notch the design with the full
    /// reserve (48°) stays below the resonance; with one, a broad shallow notch well above the
    /// shaft's resonance and below the crossover shapes the loop's phase, and the design
    /// reaches past ten times the resonance. Checked on a 20 000-point grid: the margins
    /// held, and the closed loop over −3 dB from 0.5 Hz up to its bandwidth.
    #[test]
    fn a_shaping_notch_takes_a_lightly_damped_shaft_past_its_resonance() {
        use crate::autotune::bench::Machine;
        use crate::autotune::margins::log_grid;
        let machine = Machine { inertia_ratio: 0.98, resonance_hz: 54.5, damping_ratio: 0.0101, absorber: None };
        let (period, drive, m) = machine.axis();
        let (fr, _) = m.resonance_hz();
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f);
        let goal = MarginGoal::named("standard").unwrap().with_reserve(crate::autotune::reserve::Reserve::Full);
        let unshaped = design(
            &plant,
            period,
            &goal,
            &SearchGrid { shaping_notch: false, ..SearchGrid::STANDARD },
            &m.features_hz(),
        )
        .unwrap();
        assert!(unshaped.margins.bandwidth_hz < fr, "{unshaped:?}");
        let d = design(&plant, period, &goal, &SearchGrid::STANDARD, &m.features_hz()).unwrap();
        // A shaping notch: well above the resonance, below the loop's bandwidth, broad and
        // shallow, in the second slot; the first holds the resonance's notch (on it or raised
        // above it) or a broad one past the crossover (`first_notches`), or the shaping one
        // alone.
        let n = d.tuning.notch.expect("a notch");
        let shaping = d.tuning.notch2.unwrap_or(n);
        let on_resonance = n.hz > 0.8 * fr && n.hz < 2.0 * fr;
        let past_crossover = n.hz > d.margins.crossover_hz && n.q < 1.0;
        assert!(d.tuning.notch2.is_none() || on_resonance || past_crossover, "{d:?}");
        assert!(shaping.hz > 1.5 * fr, "{d:?}");
        assert!(shaping.hz < d.margins.bandwidth_hz && shaping.q < 2.0 && shaping.depth > 0.1, "{d:?}");
        let dense = margins_of(&d.tuning, &plant, period, 20_000, &m.features_hz()).unwrap();
        assert!(goal.held_by(&dense) && dense.bandwidth_hz > 10.0 * fr, "{dense:?}");
        let t = |f: f64| {
            let l = d.tuning.response(f, period) * plant(f);
            (l / (1.0 + l)).norm()
        };
        let least = log_grid(0.5, dense.bandwidth_hz, 20_000).into_iter().map(t).fold(1.0, f64::min);
        assert!(least > 0.99 * std::f64::consts::FRAC_1_SQRT_2, "{least}");
    }

    /// Seed 1's machine 43 of 200 as its calibration saw it (a load of 0.23 times the motor
    /// on a 147 Hz shaft, ζ 0.026; inertias and stiffness within 0.4 % of the truth), designed
    /// at the goal itself: the near misses past the resonance, moved with a shaping notch and
    /// their first notch raised above the resonance, give a bandwidth past five times the
    /// resonance, with the first notch above it. (With the notch on the resonance alone the
    /// design gives 129.5 Hz.) Checked on a 20 000-point grid, without the broad notch past
    /// the near misses' crossover (with it, that loop is wider still: 886 Hz).
    #[test]
    fn a_first_notch_raised_above_the_resonance_takes_the_loop_past_it() {
        use crate::autotune::bench::Machine;
        let machine = Machine { inertia_ratio: 0.232, resonance_hz: 147.0, damping_ratio: 0.0256, absorber: None };
        let (period, drive, _) = machine.axis();
        let m = Mechanics {
            motor_inertia: 5.00894806317959e-5,
            load_inertia: 1.1556370451877894e-5,
            shaft_stiffness: 8.002308482278258,
            shaft_damping: 0.0005063215457419144,
            motor_viscous: 0.0,
            load_viscous: 0.0,
            absorber: None,
        };
        let (fr, _) = m.resonance_hz();
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f);
        let goal = MarginGoal::named("standard").unwrap();
        let grid = SearchGrid { past_crossover_notch: false, ..SearchGrid::STANDARD };
        let d = design(&plant, period, &goal, &grid, &m.features_hz()).unwrap();
        let dense = margins_of(&d.tuning, &plant, period, 20_000, &m.features_hz()).unwrap();
        assert!(goal.held_by(&dense) && dense.bandwidth_hz > 5.0 * fr, "{dense:?} {d:?}");
        let first = d.tuning.notch.expect("a notch");
        assert!(first.hz > 1.1 * fr && first.hz < 1.6 * fr, "{d:?}");
        let broad = design(&plant, period, &goal, &SearchGrid::STANDARD, &m.features_hz()).unwrap();
        assert!(broad.margins.bandwidth_hz >= d.margins.bandwidth_hz, "{broad:?} against {d:?}");
    }

    /// Seed 1's machine 9 of 200 as its calibration saw it (a load of 3.46 times the motor on
    /// a 51 Hz shaft, ζ 0.011; inertias and stiffness within 0.15 % of the truth), designed at
    /// the goal: its near misses reach about 367 Hz with the anti-resonance dip's floor at
    /// 0.13, and without a broad notch past their crossover the design stays under the
    /// anti-resonance (23 Hz, the shipped gains' bandwidth). With it, the loop crosses over
    /// past the resonance with the dip lifted: a bandwidth past ten times the resonance, the
    /// margins kept on a 20 000-point grid and the closed loop over −3 dB up to there; its
    /// first notch broad and past the crossover (under five times it, where the near misses'
    /// own notch on the response peak at 2 kHz lies past six times). On the true plant the
    /// same loop keeps the bench's goals (`Ms` ≤ 1.7: designed at the goal itself, with no
    /// reserve for the model's errors, its `Ms` there is 1.601).
    #[test]
    fn a_broad_notch_past_the_crossover_lifts_a_heavy_loads_dip() {
        use crate::autotune::bench::Machine;
        use crate::autotune::margins::log_grid;
        let machine = Machine { inertia_ratio: 3.46, resonance_hz: 51.2, damping_ratio: 0.0111, absorber: None };
        let (period, drive, truth) = machine.axis();
        let m = Mechanics {
            motor_inertia: 5.0074695200617426e-5,
            load_inertia: 0.00017313769743618836,
            shaft_stiffness: 4.0177662350979295,
            shaft_damping: 0.0005878590116012501,
            motor_viscous: 0.0,
            load_viscous: 0.0,
            absorber: None,
        };
        let (fr, fa) = m.resonance_hz();
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f);
        let goal = MarginGoal::named("standard").unwrap();
        let without = SearchGrid { past_crossover_notch: false, ..SearchGrid::STANDARD };
        let under = design(&plant, period, &goal, &without, &m.features_hz()).unwrap();
        assert!(under.margins.bandwidth_hz < fa, "{under:?}");
        let d = design(&plant, period, &goal, &SearchGrid::STANDARD, &m.features_hz()).unwrap();
        let dense = margins_of(&d.tuning, &plant, period, 20_000, &m.features_hz()).unwrap();
        assert!(goal.held_by(&dense) && dense.bandwidth_hz > 10.0 * fr, "{dense:?} {d:?}");
        // The first notch broad and past the crossover.
        let first = d.tuning.notch.expect("a notch");
        assert!(first.hz > dense.crossover_hz && first.hz < 5.0 * dense.crossover_hz && first.q < 1.0, "{d:?}");
        let t = |f: f64| {
            let l = d.tuning.response(f, period) * plant(f);
            (l / (1.0 + l)).norm()
        };
        let least = log_grid(0.5, dense.bandwidth_hz, 20_000).into_iter().chain([fa]).map(t).fold(1.0, f64::min);
        assert!(least > 0.99 * std::f64::consts::FRAC_1_SQRT_2, "{least}");
        let true_plant = |f: f64| crate::autotune::loop_plant(&drive, &truth, f);
        let on_truth = margins_of(&d.tuning, &true_plant, period, 20_000, &truth.features_hz()).unwrap();
        let on_truth_goal = MarginGoal { sensitivity_peak: 1.7, ..goal };
        assert!(on_truth_goal.held_by(&on_truth) && on_truth.bandwidth_hz > 10.0 * fr, "{on_truth:?}");
    }

    /// The absorbers draw's machine 37 of 40 (a load of 2.9 times the motor on a 64 Hz shaft,
    /// an absorber at 49 Hz) as the virtual drive calibrated it behind its commissioned
    /// current loop, through a drive model without the back-EMF path: the two near misses of
    /// the farthest reach move onto no wide loop with a shaping notch (alone, the search stays
    /// at 28 Hz, under the anti-resonance); the next
    /// ones are shaped until one is moved past the dip. The loop keeps the goal on a dense
    /// grid of the model, and on the true machine behind the true winding.
    #[test]
    fn the_next_near_misses_are_shaped_where_the_first_two_are_not_moved_past_the_dip() {
        use crate::autotune::mechanics::AbsorberMechanics;
        let commissioned = DriveDynamics {
            tick: 6.25000029685907e-5,
            velocity_period: 0.0001250000059371814,
            current_kp: 2.257260322570801,
            current_ki: 1367.7857666015625,
            resistance: 0.2999332547187805,
            inductance: 0.0005042956909164786,
            torque_gain: 1.0,
            torque_constant: 0.1,
            // The model it was calibrated through: the feed-forward taking all of the
            // back-EMF off.
            back_emf: 0.0,
            back_emf_feedforward: 0.0,
        };
        let m = Mechanics {
            motor_inertia: 5.001457150322367e-5,
            load_inertia: 0.00014405105055556076,
            shaft_stiffness: 5.93032920622497,
            shaft_damping: 0.0008615566865860638,
            motor_viscous: 0.0,
            load_viscous: 0.0,
            absorber: Some(AbsorberMechanics {
                inertia: 1.583488284111101e-5,
                stiffness: 1.5124185661640939,
                damping: 0.00036355405956877866,
            }),
        };
        let period = commissioned.velocity_period;
        let plant = |f: f64| crate::autotune::loop_plant(&commissioned, &m, f);
        let goal = MarginGoal::named("standard").unwrap();
        let d = design(&plant, period, &goal, &SearchGrid::STANDARD, &m.features_hz()).unwrap();
        let dense = margins_of(&d.tuning, &plant, period, 20_000, &m.features_hz()).unwrap();
        let dip = m.highest_anti_resonance_hz();
        assert!(goal.held_by(&dense) && dense.bandwidth_hz > 10.0 * dip, "{dense:?} {d:?}");
        let truth = Mechanics {
            motor_inertia: 5e-5,
            load_inertia: 1.445e-4,
            shaft_stiffness: 5.950546415821113,
            shaft_damping: 0.0008914273010070632,
            motor_viscous: 1e-5,
            load_viscous: 2e-5,
            absorber: Some(AbsorberMechanics {
                inertia: 1.5895e-5,
                stiffness: 1.5175175917316122,
                damping: 0.00036736580679521097,
            }),
        };
        let winding = DriveDynamics {
            resistance: 0.3,
            inductance: 0.5e-3,
            torque_gain: 1.0005,
            back_emf: 0.4 / 6.0,
            back_emf_feedforward: 0.4 / 6.0,
            ..commissioned
        };
        let true_plant = |f: f64| crate::autotune::loop_plant(&winding, &truth, f);
        let on_truth = margins_of(&d.tuning, &true_plant, period, 20_000, &truth.features_hz()).unwrap();
        let on_truth_goal = MarginGoal { sensitivity_peak: 1.7, ..goal };
        assert!(on_truth_goal.held_by(&on_truth) && on_truth.bandwidth_hz > 10.0 * dip, "{on_truth:?}");
    }

    /// A design's only notch is in the drive's first slot; two notches keep their slots.
    #[test]
    fn a_lone_shaping_notch_is_the_first_notch() {
        let n = |hz| Notch { hz, q: 0.5, depth: 0.3 };
        let t = VelocityTuning { kp: 0.1, ki: 50.0, low_pass_hz: 0.0, notch: None, notch2: Some(n(130.0)) };
        let moved = first_notch_first(t);
        assert_eq!((moved.notch, moved.notch2), (Some(n(130.0)), None));
        let two = VelocityTuning { notch: Some(n(50.0)), ..t };
        assert_eq!(first_notch_first(two), two);
        let none = VelocityTuning { notch2: None, ..t };
        assert_eq!(first_notch_first(none), none);
    }

    /// The design grid holds a lightly damped mode (ζ = 0.002): its features are grid points,
    /// the grid stays increasing, and the sensitivity peak read on a sparse grid with them is
    /// the dense grid's; a start that does not keep the margins is not refined, and a start
    /// that does is refined to at least its own bandwidth.
    #[test]
    fn the_grid_holds_a_narrow_mode_and_refine_refuses_a_failing_start() {
        let params = control_core::Params::default();
        let drive = DriveDynamics::as_configured(&params);
        let period = params.rates.velocity_period() as f64;
        let goal = MarginGoal::named("standard").unwrap();
        let m = Mechanics::two_inertia(1.5e-4, 3e-4, 300.0, 0.002);
        let plant = |f: f64| crate::autotune::loop_plant(&drive, &m, f);
        let d = design(&plant, period, &goal, &SearchGrid::STANDARD, &m.features_hz()).unwrap();
        let with = margins_of(&d.tuning, &plant, period, 400, &m.features_hz()).unwrap();
        let dense = margins_of(&d.tuning, &plant, period, 50_000, &[]).unwrap();
        assert!((with.sensitivity_peak - dense.sensitivity_peak).abs() < 0.02, "{with:?} vs {dense:?}");
        let g = design_grid(period, 400, &m.features_hz());
        assert!(m.features_hz().iter().all(|x| g.contains(x)) && g.windows(2).all(|w| w[0] < w[1]));
        let mut reckless = d;
        reckless.tuning.kp *= 30.0;
        assert!(refine(&plant, period, &goal, &reckless, 2000, &m.features_hz()).is_none());
        let refined = refine(&plant, period, &goal, &d, 2000, &m.features_hz()).unwrap();
        // At least its own bandwidth, to the interpolation between the two grids' points
        // (0.35 % apart on the design's grid).
        assert!(
            refined.margins.bandwidth_hz >= 0.995 * d.margins.bandwidth_hz && goal.held_by(&refined.margins),
            "{refined:?} from {d:?}"
        );
    }
}
