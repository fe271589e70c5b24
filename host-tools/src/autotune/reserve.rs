//! How far inside the goal a design on a calibrated model aims, and the step back when a
//! close design misses where it is verified.
//!
//! A design first keeps the goal with a small reserve (the **close design**) and is
//! verified where it is to run (the twin, then the drive). Its reserve is the **tight** one
//! where the calibration is precise enough to carry it (the tight design keeps the goal on
//! the machines at the ends of the fit's principal axes, [`TIGHT_SIGMAS`] standard deviations
//! out), else the **close** one. Where that verification misses, the design that keeps the
//! **full** reserve is verified instead (not the close reserve's after a tight one: one more
//! verification would cost drive time), and its verification decides: the wider of the full
//! reserve's own design and the close design moved onto the full reserve's margins (the loop
//! that missed by a little is stepped back from where it is, where the search with the full
//! reserve can land under a load's dip). Many machines' widest
//! loops lie inside the full reserve: loops that lift a load's anti-resonance dip over −3 dB
//! exist only within a degree or two of the goal's phase margin, some within half a degree.

use anyhow::Result;
use serde::Serialize;

use super::design::{Design, MarginGoal};
use super::measured_mechanics::MeasuredMechanics;
use super::position_loop_design::PositionTuning;

/// The margins a design on a calibrated model keeps beside the goal.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum Reserve {
    /// 0.1° of phase, 0.1 dB of gain, 0.004 of Ms: where the design keeps the goal itself on
    /// the machines at the ends of the calibration's principal axes ([`TIGHT_SIGMAS`]).
    Tight,
    /// 0.5° of phase, 0.25 dB of gain, 0.01 of Ms. A calibrated twin's margins lie within a
    /// few hundredths of a degree of its machine's where the model is optimistic (0.00–0.02°
    /// on seed 1's machines whose widest loops keep 45–46° of phase margin), and the
    /// verification on the machine holds the loop to the goal itself.
    Close,
    /// 3° of phase, 1 dB of gain, 0.02 of Ms: for a machine whose measurement the model
    /// follows less closely than that (the close design missed its verification).
    Full,
}

impl Reserve {
    /// (phase margin °, gain margin dB, Ms) added to the goal's margins (taken off its Ms).
    pub fn margins(self) -> (f64, f64, f64) {
        match self {
            Reserve::Tight => (0.1, 0.1, 0.004),
            Reserve::Close => (0.5, 0.25, 0.01),
            Reserve::Full => (3.0, 1.0, 0.02),
        }
    }

    pub fn name(self) -> &'static str {
        match self {
            Reserve::Tight => "tight",
            Reserve::Close => "close",
            Reserve::Full => "full",
        }
    }
}

/// How far out along the calibration's principal axes (standard deviations) the tight
/// design must keep the goal: the axes' ends of the 99.7 % confidence ellipsoid of the
/// two-inertia fit's four parameters (χ² of 16 on four degrees of freedom; 97.5 % with an
/// absorber's three more). The ends of the axes, not the whole ellipsoid: a margin's worst
/// direction can lie between them. Over the virtual drive, with a drive model that left out
/// the back-EMF path, the calibrated model of seed 1's machine 21 of 40 (shaft 450 Hz, ratio
/// 0.26) was 0.2° optimistic on the tight design, an error the axes' ends three standard
/// deviations out do not cover and four do.
pub const TIGHT_SIGMAS: f64 = 4.0;

/// What became of the close design.
#[derive(Clone, Debug, Serialize)]
#[serde(rename_all = "lowercase")]
pub enum CloseDesign<V> {
    /// The close design held its verification: it is the one taken.
    Held,
    /// What `check` returned for the close design, which missed.
    Missed(V),
    /// No close design was made (the search's or the position loop's refusal).
    Refused(String),
}

/// A design that was verified, the reserve it kept, and what became of the close design.
#[derive(Clone, Debug)]
pub struct Verified<V> {
    pub design: Design,
    pub position: PositionTuning,
    pub reserve: Reserve,
    /// What `check` returned for this design.
    pub outcome: V,
    pub close: CloseDesign<V>,
    /// The close design's reserve (tight or close).
    pub close_reserve: Reserve,
}

impl<V> CloseDesign<V> {
    /// What the close design's verification returned, where it ran and missed.
    pub fn missed(&self) -> Option<&V> {
        match self {
            CloseDesign::Missed(v) => Some(v),
            _ => None,
        }
    }

    pub fn map<W>(self, f: impl FnOnce(V) -> W) -> CloseDesign<W> {
        match self {
            CloseDesign::Held => CloseDesign::Held,
            CloseDesign::Missed(v) => CloseDesign::Missed(f(v)),
            CloseDesign::Refused(e) => CloseDesign::Refused(e),
        }
    }
}

/// The close design (the tight reserve's where the calibration carries it, else the close
/// reserve's) checked by `check` (its outcome and whether it held); where it misses, or no
/// design keeps the close reserve, the full reserve's design checked by `check`, whose
/// outcome then stands whether it held or not; the full reserve's design is the wider of its
/// own and the missed close design moved onto its margins
/// ([`MeasuredMechanics::moved_onto`]). The search with the full reserve can land under a
/// load's dip where the close design lies past it: over the virtual drive, with a drive model
/// that left out the back-EMF path, the close designs of the absorbers draw's machines 15 and
/// 37 of 40 read 44.7° of phase margin on the drive, the full reserve's search found 73 Hz on
/// machine 15, and stepped back, 743 and 730 Hz on the model held their verification. The
/// wider loop is not always the one that verifies (on that model the absorbers draw's machine
/// 19 had its stepped-back loop read 40.1° on the drive, where the full reserve's own,
/// narrower design verified).
/// An error of `check` ends the attempt.
pub fn design_and_verify<V>(
    mechanics: &MeasuredMechanics,
    goal: &MarginGoal,
    margin: &str,
    mut check: impl FnMut(&Design, &PositionTuning) -> Result<(V, bool)>,
) -> Result<Verified<V>> {
    let (close_reserve, close) = close_design(mechanics, goal, margin);
    let close = close.and_then(|d| mechanics.design_position(&d.tuning, goal).map(|p| (d, p)));
    let (close, missed) = match close {
        Ok((design, position)) => {
            let (outcome, held) = check(&design, &position)?;
            if held {
                let reserve = close_reserve;
                return Ok(Verified { design, position, reserve, outcome, close: CloseDesign::Held, close_reserve });
            }
            (CloseDesign::Missed(outcome), Some(design))
        }
        Err(e) => (CloseDesign::Refused(format!("{e:#}")), None),
    };
    let full = mechanics.design(goal, margin, Reserve::Full);
    let stepped_back = missed.and_then(|d| mechanics.moved_onto(&d, &goal.with_reserve(Reserve::Full)));
    let design = match (full, stepped_back) {
        (Ok(f), Some(s)) if s.margins.bandwidth_hz > f.margins.bandwidth_hz => s,
        (Err(_), Some(s)) => s,
        (f, _) => f?,
    };
    let position = mechanics.design_position(&design.tuning, goal)?;
    let (outcome, _) = check(&design, &position)?;
    Ok(Verified { design, position, reserve: Reserve::Full, outcome, close, close_reserve })
}

/// The close design and its reserve: the tight reserve's where its loop is wider than the
/// close reserve's on the model and keeps the goal on the machines at the ends of the
/// calibration's principal axes, else the close reserve's. (The search is not monotone in the goal: the
/// tight reserve's widest loop found can be narrower than the close one's.)
pub fn close_design(mechanics: &MeasuredMechanics, goal: &MarginGoal, margin: &str) -> (Reserve, Result<Design>) {
    let close = mechanics.design(goal, margin, Reserve::Close);
    let wider = |t: &Design| close.as_ref().map_or(true, |c| t.margins.bandwidth_hz > c.margins.bandwidth_hz);
    let tight = mechanics
        .design(goal, margin, Reserve::Tight)
        .ok()
        .filter(|t| wider(t) && mechanics.holds_within_uncertainty(t, goal, TIGHT_SIGMAS));
    match tight {
        Some(t) => (Reserve::Tight, Ok(t)),
        None => (Reserve::Close, close),
    }
}

#[cfg(test)]
mod tests {
    use std::cell::Cell;

    use super::*;
    use crate::autotune::bench::{DrawnAbsorber, Machine};
    use crate::autotune::calibration::calibrate;
    use crate::autotune::design::margins_of;
    use crate::autotune::drive_dynamics::DriveDynamics;
    use crate::autotune::mechanics::Mechanics;
    use crate::autotune::velocity_controller::{Notch, VelocityTuning};
    use crate::fmu::configuration::configuration;

    /// `machine` measured through its drive without noise (40 points, 5 Hz to 3 kHz), as the
    /// torque-point sweep gives it, and calibrated.
    fn measured(machine: Machine) -> MeasuredMechanics {
        measured_through(machine, |d| d)
    }

    /// As [`measured`], behind a drive whose feed-forward takes all of the back-EMF off: the
    /// loops these tests were built on lie within a few tenths of a degree of the margins,
    /// where the back-EMF path moves them.
    fn measured_without_back_emf(machine: Machine) -> MeasuredMechanics {
        measured_through(machine, DriveDynamics::without_back_emf)
    }

    fn measured_through(machine: Machine, drive_of: impl Fn(DriveDynamics) -> DriveDynamics) -> MeasuredMechanics {
        let c = configuration(&machine.parameters()).unwrap();
        let drive = drive_of(DriveDynamics::as_configured(&c.control));
        let points = MeasuredMechanics::noiseless_sweep(&drive, &Mechanics::of_plant(&c.plant));
        let calibration = calibrate(&points, &drive).unwrap();
        MeasuredMechanics { drive, ..MeasuredMechanics::of_sweep(c.control, points, calibration) }
    }

    /// A light load on a 142 Hz shaft (seed 1's machine 168): its widest loop lifts the
    /// anti-resonance dip with less than 46° of phase margin. Measured without noise, the
    /// close design keeps the tight reserve; where its verification misses, the full
    /// reserve's design is verified instead (a loop moved onto the full reserve's margins past
    /// the dip, a little narrower) and the close one's outcome is kept beside it.
    #[test]
    fn a_close_design_that_misses_its_verification_gives_way_to_the_full_reserve() {
        let mechanics =
            measured(Machine { inertia_ratio: 0.307, resonance_hz: 142.0, damping_ratio: 0.0617, absorber: None });
        let goal = MarginGoal::named("standard").unwrap();
        let calls = Cell::new(0);
        let held = design_and_verify(&mechanics, &goal, "standard", |d, _| {
            calls.set(calls.get() + 1);
            Ok((d.margins, true))
        })
        .unwrap();
        // Measured without noise, the calibration carries the tight reserve.
        assert_eq!((held.reserve, calls.get()), (Reserve::Tight, 1));
        assert!(matches!(held.close, CloseDesign::Held));
        // The close design uses the room the full reserve would not leave.
        assert!(!goal.with_reserve(Reserve::Full).held_by(&held.outcome), "{:?}", held.outcome);

        calls.set(0);
        let missed = design_and_verify(&mechanics, &goal, "standard", |d, _| {
            calls.set(calls.get() + 1);
            // The close design's verification misses; the full one's holds.
            Ok((d.margins, calls.get() > 1))
        })
        .unwrap();
        assert_eq!((missed.reserve, missed.close_reserve, calls.get()), (Reserve::Full, Reserve::Tight, 2));
        let CloseDesign::Missed(close) = missed.close else { panic!("{:?}", missed.close) };
        assert_eq!(close.bandwidth_hz, held.outcome.bandwidth_hz);
        assert!(goal.with_reserve(Reserve::Full).held_by(&missed.outcome), "{:?}", missed.outcome);
        // The close design is the wider loop; the full reserve's still lifts the dip
        // (its bandwidth the loop's reach, past three times the shaft's resonance).
        assert!(
            held.outcome.bandwidth_hz >= missed.outcome.bandwidth_hz && missed.outcome.bandwidth_hz > 3.0 * 142.0,
            "close {} Hz, full {} Hz",
            held.outcome.bandwidth_hz,
            missed.outcome.bandwidth_hz
        );
    }

    /// A close design that misses its verification steps back onto the full reserve's
    /// margins (moved there as a loop at the goal is) where that keeps more bandwidth than
    /// the full reserve's own design: the absorbers draw's machine 15 of 40 (a load of 1.8
    /// times the motor on a 179 Hz shaft, an absorber at 0.73 times the resonance), measured
    /// without noise behind a drive whose feed-forward takes all of the back-EMF off. There
    /// the full reserve's own search lands short of the close design; behind the drive's own
    /// feed-forward both reach about 900 Hz.
    #[test]
    fn a_close_design_that_misses_steps_back_onto_the_full_reserve_where_that_is_wider() {
        let machine = Machine {
            inertia_ratio: 1.8,
            resonance_hz: 179.0,
            damping_ratio: 0.0956,
            absorber: Some(DrawnAbsorber { inertia_share: 0.279, mode_over_resonance: 0.731, damping_ratio: 0.0196 }),
        };
        let mechanics = measured_without_back_emf(machine);
        let goal = MarginGoal::named("standard").unwrap();
        let full_goal = goal.with_reserve(Reserve::Full);
        let calls = Cell::new(0);
        let missed = design_and_verify(&mechanics, &goal, "standard", |d, _| {
            calls.set(calls.get() + 1);
            Ok((d.margins, calls.get() > 1))
        })
        .unwrap();
        assert_eq!((missed.reserve, calls.get()), (Reserve::Full, 2));
        let CloseDesign::Missed(close) = missed.close else { panic!("{:?}", missed.close) };
        let own = mechanics.design(&goal, "standard", Reserve::Full).unwrap();
        let m = &mechanics.calibration.mechanics;
        let model = |f: f64| mechanics.model(f);
        let on_model = margins_of(&missed.design.tuning, &model, mechanics.period(), 4000, &m.features_hz()).unwrap();
        assert!(full_goal.held_by(&on_model), "{on_model:?}");
        assert!(
            on_model.bandwidth_hz > 1.03 * own.margins.bandwidth_hz && on_model.bandwidth_hz > 0.9 * close.bandwidth_hz,
            "stepped back {} Hz, the full reserve's own {} Hz, the close design {} Hz",
            on_model.bandwidth_hz,
            own.margins.bandwidth_hz,
            close.bandwidth_hz
        );
    }

    /// A heavy load with an absorber (seed 1's machine 6 of the absorbers' 40, measured
    /// behind a drive whose feed-forward takes all of the back-EMF off), and a loop that
    /// keeps the goal on its model but not the close reserve (two broad notches, past
    /// 600 Hz: the kind of loop the search at the goal finds where the search with the
    /// reserve stays under the chain's anti-resonance). Moved onto the close reserve's
    /// margins it keeps them and most of its bandwidth, and the goal on the true plant.
    #[test]
    fn a_loop_at_the_goal_moves_onto_the_reserve_and_keeps_its_reach() {
        let machine = Machine {
            inertia_ratio: 3.13,
            resonance_hz: 86.2,
            damping_ratio: 0.042,
            absorber: Some(DrawnAbsorber { inertia_share: 0.0804, mode_over_resonance: 1.45, damping_ratio: 0.0267 }),
        };
        let mechanics = measured_without_back_emf(machine);
        let goal = MarginGoal::named("standard").unwrap();
        let reserved = goal.with_reserve(Reserve::Close);
        let m = &mechanics.calibration.mechanics;
        let (period, features) = (mechanics.period(), m.features_hz());
        let model = |f: f64| mechanics.model(f);
        let notch = |hz, q, depth| Some(Notch { hz, q, depth });
        let tuning = VelocityTuning {
            kp: 0.1259,
            ki: 198.0,
            low_pass_hz: 0.0,
            notch: notch(143.5, 1.22, 0.3),
            notch2: notch(346.0, 0.335, 0.6),
        };
        let margins = margins_of(&tuning, &model, period, 2400, &features).unwrap();
        assert!(goal.held_by(&margins) && !reserved.held_by(&margins), "{margins:?}");
        assert!(margins.bandwidth_hz > 5.0 * m.highest_anti_resonance_hz(), "{margins:?}");
        let at_goal = Design { tuning, margins, inertia: crate::autotune::design::rigid_inertia_of(&model, period) };
        *mechanics.at_goal.lock().unwrap() = Some((goal, Some(at_goal)));

        let moved = mechanics.moved_from_goal(&goal, &reserved).expect("moved onto the close reserve");
        let on_model = margins_of(&moved.tuning, &model, period, 4000, &features).unwrap();
        assert!(reserved.held_by(&on_model), "{on_model:?}");
        assert!(on_model.bandwidth_hz > 0.9 * margins.bandwidth_hz, "{on_model:?} from {margins:?}");
        let c = configuration(&machine.parameters()).unwrap();
        let truth = Mechanics::of_plant(&c.plant);
        let true_plant = |f: f64| crate::autotune::loop_plant(&mechanics.drive, &truth, f);
        let on_truth = margins_of(&moved.tuning, &true_plant, period, 4000, &truth.features_hz()).unwrap();
        assert!(goal.held_by(&on_truth), "{on_truth:?}");
    }

    /// The tight reserve where the calibration is precise enough to carry it, the close one
    /// where it is not: the same machine, its calibration's errors 0.001 % and then 2 % on
    /// every parameter (four standard deviations of 2 % move the shaft's stiffness or an
    /// inertia by 8 %, its resonance by 4 %, which a loop kept 0.1° inside the goal does not
    /// survive).
    #[test]
    fn the_tight_reserve_is_taken_only_where_the_calibration_carries_it() {
        let goal = MarginGoal::named("standard").unwrap();
        let mut mechanics =
            measured(Machine { inertia_ratio: 0.307, resonance_hz: 142.0, damping_ratio: 0.0617, absorber: None });
        let uncertainty = mechanics.calibration.uncertainty.expect("a determined fit");
        let (close_reserve, close) = {
            mechanics.calibration.uncertainty = Some(uncertainty.with_relative_errors(0.02));
            close_design(&mechanics, &goal, "standard")
        };
        mechanics.calibration.uncertainty = Some(uncertainty.with_relative_errors(1e-5));
        let (tight_reserve, tight) = close_design(&mechanics, &goal, "standard");
        assert_eq!((close_reserve, tight_reserve), (Reserve::Close, Reserve::Tight));
        let (close, tight) = (close.unwrap(), tight.unwrap());
        assert!(goal.with_reserve(Reserve::Close).held_by(&close.margins), "{:?}", close.margins);
        assert!(goal.with_reserve(Reserve::Tight).held_by(&tight.margins), "{:?}", tight.margins);
        assert!(tight.margins.bandwidth_hz > close.margins.bandwidth_hz);
        // The tight design on the machines four standard deviations of 2 % out: one misses.
        mechanics.calibration.uncertainty = Some(uncertainty.with_relative_errors(0.02));
        assert!(!mechanics.holds_within_uncertainty(&tight, &goal, TIGHT_SIGMAS));
    }
}
