//! The machine's mechanics measured and calibrated on a [`AxisUnderTest`]: a torque-point sweep,
//! refused where it ran into a limit, turned into the plant behind it, the two-inertia model
//! fitted to that and refused where the measurement does not determine it. What `servo
//! autotune`, `servo calibrate` and the autotune bench all start from.

use std::collections::BTreeMap;
use std::sync::Mutex;

use anyhow::{anyhow, Context, Result};
use control_core::excitation::InjectionPoint;
use control_core::Params;
use num_complex::Complex64;

use super::axis_under_test::AxisUnderTest;
use super::calibration::{calibrate, Calibration, PlantPoint};
use super::design::{design, margins_of, Design, MarginGoal, SearchGrid, NEAR_MISS_KEPT_REACH};
use super::design_checks::{
    check_determined, check_linear, check_resonance_measured, check_riding_speed, check_torque_amplitude,
};
use super::drive_dynamics::DriveDynamics;
use super::mechanics::AbsorberMechanics;
use super::position_loop_design::{design_position_loop, position_loop_per_gain, PositionRates, PositionTuning};
use super::refinement::{refine_on, restore_on, FLOOR_HEADROOM_DB};
use super::reserve::Reserve;
use super::sampled_plant::SampledPlant;
use super::velocity_controller::VelocityTuning;
use super::{loop_plant, plant_points};
use crate::analysis::response_point::ResponsePoint;
use crate::fmu::scenario::Value;

/// A calibration and what it was fitted to.
pub struct MeasuredMechanics {
    /// The drive parameters the sweep ran with.
    pub params: Params,
    /// The drive's part of the plant, as those parameters configure it.
    pub drive: DriveDynamics,
    /// The velocity loop that ran during the sweep.
    pub during: VelocityTuning,
    /// The sweep's readings (torque command → velocity estimate, the loop closed beside it).
    pub readings: Vec<ResponsePoint>,
    /// The plant behind them.
    pub points: Vec<PlantPoint>,
    pub calibration: Calibration,
    /// The sweep's drive time (s).
    pub drive_time_s: f64,
    /// The widest design that keeps the goal itself (no reserve) on the calibrated model, once
    /// it was needed, and the goal it keeps ([`Self::design`]).
    pub(crate) at_goal: Mutex<Option<(MarginGoal, Option<Design>)>>,
}

/// The headrooms (dB over −3 dB) the loop at the goal is moved onto a reserve with, tried in
/// turn ([`MeasuredMechanics::moved_from_goal`]): the search's own first, then half of it. On
/// the absorbers draw's machine 10 of 40 (a load of 0.92 times the motor on a 171 Hz shaft, an
/// absorber the calibration does not fit, its load inertia 10.7 % off) the loop at the goal
/// reaches 854 Hz with its anti-resonance dip 0.1–0.2 dB over −3 dB, and no loop near it keeps
/// the dip 0.25 dB over within even the tight reserve: held 0.125 dB over, it keeps the
/// reserve at 850 Hz, where the search with the reserve stays under the dip at 108 Hz. The
/// margins are the reserve's whatever the headroom; a machine that drops the dip back under
/// −3 dB gives the loop the dip's bandwidth, about what the loop under the dip would have had.
const MOVED_HEADROOMS_DB: [f64; 2] = [FLOOR_HEADROOM_DB, 0.5 * FLOOR_HEADROOM_DB];

/// Sweep `target` at the torque point with `amplitude` N·m riding at `velocity` rad/s, and
/// calibrate the mechanics from the response.
pub fn measure_mechanics(
    target: &mut dyn AxisUnderTest,
    parameters: &BTreeMap<String, Value>,
    amplitude: f64,
    velocity: f64,
) -> Result<MeasuredMechanics> {
    check_riding_speed(velocity)?;
    check_torque_amplitude(amplitude)?;
    let params = target.params(parameters)?;
    let sweep = target
        .sweep(&super::sweep_settings(InjectionPoint::TorqueCommand, amplitude), parameters, velocity)
        .with_context(|| format!("the torque-point sweep on {}", target.name()))?;
    check_linear(&sweep, amplitude)?;
    let drive = DriveDynamics::as_configured(&params);
    let during = VelocityTuning::of_params(&params);
    let points = plant_points(&sweep.points, &drive, &during);
    let calibration = calibrate(&points, &drive).context("calibrating the mechanics")?;
    check_determined(&calibration)?;
    Ok(MeasuredMechanics {
        params,
        drive,
        during,
        readings: sweep.points,
        points,
        calibration,
        drive_time_s: sweep.drive_time_s,
        at_goal: Mutex::new(None),
    })
}

impl MeasuredMechanics {
    /// The calibrated loop plant (command hold, drive, machine) at `f` Hz.
    pub fn model(&self, f: f64) -> Complex64 {
        loop_plant(&self.drive, &self.calibration.mechanics, f)
    }

    /// The velocity loop's open loop with `tuning` on the calibrated model at `f` Hz.
    pub fn open_loop(&self, tuning: &VelocityTuning, f: f64) -> Complex64 {
        tuning.response(f, self.period()) * self.model(f)
    }

    /// The velocity loop's period (s).
    pub fn period(&self) -> f64 {
        self.params.rates.velocity_period() as f64
    }

    /// The highest frequency measured (Hz).
    pub fn top_hz(&self) -> f64 {
        self.points.iter().map(|p| p.hz).fold(0.0, f64::max)
    }

    /// The widest-bandwidth design on the calibrated model that keeps `goal` with `reserve`;
    /// refused where the resonance lies near the top of the measured band (`margin` names the
    /// goal in the message).
    ///
    /// Where the search's widest loop with the reserve stays under the model's highest
    /// anti-resonance (where a load's dip can hold a loop's bandwidth), or where the search
    /// finds none, the widest loop that keeps the goal itself is moved onto the reserve's
    /// margins (`refinement::restore_on`) and taken where it is wider. The loops that lift such
    /// a dip can lie where the search with the reserve does not reach while the search at the
    /// goal does: on the absorbers draw's machine 6 of 40 (a load of 3.1 times the motor on an
    /// 86 Hz shaft, with an absorber) the search with the close reserve stays at 38 Hz, under
    /// the chain's lower anti-resonance, while the loop it finds at the goal (two broad
    /// notches) keeps the close reserve at 838 Hz once moved.
    pub fn design(&self, goal: &MarginGoal, margin: &str, reserve: Reserve) -> Result<Design> {
        check_resonance_measured(&self.calibration, self.top_hz())?;
        let reserved = goal.with_reserve(reserve);
        let found = self.search(&reserved);
        let under_dip = found
            .as_ref()
            .is_none_or(|d| d.margins.bandwidth_hz < self.calibration.mechanics.highest_anti_resonance_hz());
        let moved = if under_dip { self.moved_from_goal(goal, &reserved) } else { None };
        let best = match (found, moved) {
            (Some(f), Some(m)) => Some(if m.margins.bandwidth_hz > f.margins.bandwidth_hz { m } else { f }),
            (f, m) => f.or(m),
        };
        best.ok_or_else(|| {
            anyhow!(
                "no velocity-loop design keeps the {margin} margins with the {} reserve on the calibrated model",
                reserve.name()
            )
        })
    }

    /// The search's widest loop on the calibrated model that keeps `goal`.
    fn search(&self, goal: &MarginGoal) -> Option<Design> {
        let model = |f: f64| self.model(f);
        design(&model, self.period(), goal, &SearchGrid::STANDARD, &self.calibration.mechanics.features_hz())
    }

    /// The widest loop that keeps `goal` itself (searched once per goal, and refined) moved
    /// onto the `reserved` margins as the search's near misses are, its closed loop held
    /// [`FLOOR_HEADROOM_DB`] over −3 dB up to four fifths of its reach, or where that fails
    /// with less headroom ([`MOVED_HEADROOMS_DB`]).
    pub(crate) fn moved_from_goal(&self, goal: &MarginGoal, reserved: &MarginGoal) -> Option<Design> {
        let sampled = self.sampled_model();
        let at_goal = {
            let mut cache = self.at_goal.lock().unwrap_or_else(|e| e.into_inner());
            match cache.as_ref() {
                Some((g, d)) if g == goal => *d,
                _ => {
                    let d = self.search(goal).map(|d| refine_on(&sampled, goal, &d, None).unwrap_or(d));
                    *cache = Some((*goal, d));
                    d
                }
            }
        }?;
        Self::moved_on_sampled(&sampled, &at_goal, reserved)
    }

    /// `design` moved onto the `reserved` margins on the calibrated model as a loop at the
    /// goal is ([`Self::moved_from_goal`]); `None` where it cannot keep them.
    pub(crate) fn moved_onto(&self, design: &Design, reserved: &MarginGoal) -> Option<Design> {
        Self::moved_on_sampled(&self.sampled_model(), design, reserved)
    }

    /// `design` moved onto the `reserved` margins on `sampled` (the calibrated model on the
    /// search's grid): with the closed loop held [`MOVED_HEADROOMS_DB`] over −3 dB in turn.
    fn moved_on_sampled(sampled: &SampledPlant, design: &Design, reserved: &MarginGoal) -> Option<Design> {
        MOVED_HEADROOMS_DB
            .iter()
            .find_map(|&headroom| restore_on(sampled, reserved, design, NEAR_MISS_KEPT_REACH, headroom))
            .map(|(d, _)| d)
    }

    /// The calibrated model on the search's grid.
    fn sampled_model(&self) -> SampledPlant {
        let model = |f: f64| self.model(f);
        let features = self.calibration.mechanics.features_hz();
        SampledPlant::new(&model, self.period(), SearchGrid::STANDARD.grid_points, &features)
    }

    /// For tests: the mechanics measured with `params` as `points` and calibrated as
    /// `calibration`, no readings or drive time kept.
    #[cfg(test)]
    pub(crate) fn of_sweep(params: Params, points: Vec<PlantPoint>, calibration: Calibration) -> Self {
        MeasuredMechanics {
            params,
            drive: DriveDynamics::as_configured(&params),
            during: VelocityTuning::of_params(&params),
            readings: Vec::new(),
            points,
            calibration,
            drive_time_s: 0.0,
            at_goal: Default::default(),
        }
    }

    /// For tests: `mechanics` behind `drive` swept without noise as the torque-point sweep
    /// sweeps them (40 points, 5 Hz to 3 kHz).
    #[cfg(test)]
    pub(crate) fn noiseless_sweep(drive: &DriveDynamics, mechanics: &super::mechanics::Mechanics) -> Vec<PlantPoint> {
        super::margins::log_grid(5.0, 3000.0, 40)
            .into_iter()
            .map(|hz| PlantPoint { hz, response: super::plant_response(drive, mechanics, hz) })
            .collect()
    }

    /// Whether `design` keeps `goal` on every machine at the ends of the calibration's
    /// principal axes, `sigmas` standard deviations out; false where the calibration does not
    /// determine every value (a rigid machine's split of its inertia, say).
    pub fn holds_within_uncertainty(&self, design: &Design, goal: &MarginGoal, sigmas: f64) -> bool {
        let c = &self.calibration;
        let Some(extremes) = c.uncertainty.filter(|_| !c.rigid).and_then(|u| u.principal_extremes(sigmas)) else {
            return false;
        };
        extremes.into_iter().all(|mut m| {
            (m.motor_viscous, m.load_viscous) = (c.mechanics.motor_viscous, c.mechanics.load_viscous);
            let plant = |f: f64| loop_plant(&self.drive, &m, f);
            margins_of(&design.tuning, &plant, self.period(), SearchGrid::STANDARD.grid_points, &m.features_hz())
                .is_some_and(|margins| goal.held_by(&margins))
        })
    }

    /// The position loop's gain and feed-forward around the velocity loop of `tuning` on the
    /// calibrated model, keeping `goal` with the full reserve (the position loop is not
    /// verified on its own: its margins stand on the model).
    pub fn design_position(&self, tuning: &VelocityTuning, goal: &MarginGoal) -> Result<PositionTuning> {
        let per_gain = |f: f64| self.position_loop_per_gain(tuning, f);
        design_position_loop(&per_gain, &PositionRates::of(&self.params), &goal.with_reserve(Reserve::Full))
            .ok_or_else(|| anyhow!("no position-loop gain keeps the margins around the tuned velocity loop"))
    }

    /// The position loop per unit gain around `tuning` on the calibrated model.
    pub fn position_loop_per_gain(&self, tuning: &VelocityTuning, f: f64) -> Complex64 {
        let closed = |f: f64| {
            let l = self.open_loop(tuning, f);
            l / (1.0 + l)
        };
        position_loop_per_gain(&closed, &|f| self.drive.velocity_estimate(f), &PositionRates::of(&self.params), f)
    }

    /// The calibrated mechanics as plant parameters (a twin of the measured machine).
    pub fn plant_parameters(&self) -> [(&'static str, Value); 7] {
        let m = &self.calibration.mechanics;
        // No absorber fitted: none in the twin either (0 inertia), whatever the base had.
        let a = m.absorber.unwrap_or(AbsorberMechanics { inertia: 0.0, stiffness: 0.0, damping: 0.0 });
        [
            ("plant.motor_inertia", Value::Float(m.motor_inertia)),
            ("plant.load_inertia", Value::Float(m.load_inertia)),
            ("plant.shaft_stiffness", Value::Float(m.shaft_stiffness)),
            ("plant.shaft_damping", Value::Float(m.shaft_damping)),
            ("plant.absorber_inertia", Value::Float(a.inertia)),
            ("plant.absorber_stiffness", Value::Float(a.stiffness)),
            ("plant.absorber_damping", Value::Float(a.damping)),
        ]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autotune::bench::draw_with_absorbers;
    use crate::autotune::mechanics::Mechanics;
    use crate::fmu::configuration::configuration;

    /// Seed 1's machine 10 of the absorbers draw (a load of 0.92 times the motor on a 171 Hz
    /// shaft, ζ 0.061, an absorber on the load) as the bench calibrated it through a model
    /// whose feed-forward takes all of the back-EMF off: no absorber fitted, the load inertia
    /// 10.7 % off. The search with the tight reserve stays under the model's anti-resonance;
    /// the loop at the goal cannot be moved onto the reserve with the
    /// search's floor headroom and can with half of it, and the design then reaches past five
    /// times the anti-resonance, keeps the reserve on a dense grid and the bench's goals on
    /// the true machine, absorber and all.
    #[test]
    fn a_loop_at_the_goal_is_moved_onto_the_reserve_with_less_floor_headroom() {
        let machine = draw_with_absorbers(40, 1)[10];
        assert_eq!((machine.inertia_ratio, machine.resonance_hz), (0.92, 171.0), "{machine:?}");
        let c = configuration(&machine.parameters()).unwrap();
        let m = Mechanics {
            motor_inertia: 5.01678e-5,
            load_inertia: 5.09103e-5,
            shaft_stiffness: 27.1426,
            shaft_damping: 4.2359e-3,
            motor_viscous: 0.0,
            load_viscous: 0.0,
            absorber: None,
        };
        let calibration = Calibration {
            mechanics: m,
            relative_errors: [0.0; 4],
            absorber_relative_errors: None,
            worst_gain_db: 0.0,
            worst_phase_deg: 0.0,
            rigid: false,
            uncertainty: None,
        };
        // The sweep's band, as the calibrated model gives it.
        let drive = DriveDynamics::as_configured(&c.control).without_back_emf();
        let points = MeasuredMechanics::noiseless_sweep(&drive, &m);
        let mechanics = MeasuredMechanics { drive, ..MeasuredMechanics::of_sweep(c.control, points, calibration) };
        let fa = m.highest_anti_resonance_hz();
        let goal = MarginGoal::named("standard").unwrap();
        let reserved = goal.with_reserve(Reserve::Tight);
        let searched = mechanics.search(&reserved).unwrap();
        assert!(searched.margins.bandwidth_hz < fa, "{searched:?}");
        let d = mechanics.design(&goal, "standard", Reserve::Tight).unwrap();
        // The loop at the goal (found by the design above), moved with each headroom.
        let at_goal = mechanics.at_goal.lock().unwrap().unwrap().1.unwrap();
        let sampled = mechanics.sampled_model();
        let moved = |headroom| restore_on(&sampled, &reserved, &at_goal, NEAR_MISS_KEPT_REACH, headroom);
        assert!(moved(FLOOR_HEADROOM_DB).is_none());
        let (half, _) = moved(0.5 * FLOOR_HEADROOM_DB).expect("moved with half the headroom");
        assert_eq!(half.tuning, d.tuning);
        let model = |f: f64| mechanics.model(f);
        let dense = margins_of(&d.tuning, &model, mechanics.period(), 20_000, &m.features_hz()).unwrap();
        assert!(reserved.held_by(&dense) && dense.bandwidth_hz > 5.0 * fa, "{dense:?} {d:?}");
        let (period, true_drive, truth) = machine.axis();
        let true_plant = |f: f64| loop_plant(&true_drive, &truth, f);
        let on_truth = margins_of(&d.tuning, &true_plant, period, 20_000, &truth.features_hz()).unwrap();
        let bench_goal = MarginGoal { sensitivity_peak: 1.7, ..goal };
        assert!(bench_goal.held_by(&on_truth) && on_truth.bandwidth_hz > 5.0 * fa, "{on_truth:?}");
    }
}
