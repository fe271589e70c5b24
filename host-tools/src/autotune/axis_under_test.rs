//! Where autotune's and calibrate's measurements run: the FMU (the plant a run's parameters
//! describe, or a drive's twin) or a drive over its link (`--device`). Either gives a
//! sweep's measured points ([`MeasuredSweep`]), the constant-speed runs' points, and the
//! drive parameters they ran with (what the calibration takes the loops out with: on a drive
//! its commissioned motor and current-loop gains, not the plant's).

use std::collections::BTreeMap;

use anyhow::{Context, Result};
use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::SweepParams;
use control_core::Params;

use super::{sweep_on_fmu, MeasuredSweep};
use crate::calibrate::friction::SpeedPoint;
use crate::calibrate::friction_runs::FrictionRuns;
use crate::device::link::DrivePort;
use crate::device::session::DriveSession;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::fmu::sweep_run::{SweepRun, START_AT};
use crate::fmu::trace::Trace;
use crate::sweep::torque_limit::TorqueLimits;

/// A machine the sweeps measure.
pub trait AxisUnderTest {
    /// The drive parameters a run of `parameters` runs with.
    fn params(&mut self, parameters: &BTreeMap<String, Value>) -> Result<Params>;
    /// A stepped-sine sweep of `settings` (its point, amplitude and frequencies), riding at
    /// `velocity` rad/s.
    fn sweep(
        &mut self,
        settings: &SweepParams,
        parameters: &BTreeMap<String, Value>,
        velocity: f64,
    ) -> Result<MeasuredSweep>;
    /// The constant-speed runs friction is read from: one point per speed and direction, and
    /// the drive time they took (s).
    fn constant_speeds(
        &mut self,
        runs: &FrictionRuns,
        parameters: &BTreeMap<String, Value>,
    ) -> Result<(Vec<SpeedPoint>, f64)>;
    /// Where the measurements ran, for messages ("the FMU", "the drive at /dev/ttyACM0").
    fn name(&self) -> String;
}

/// The FMU: the plant of the run's parameters, or the twin of a drive while the FMU is one.
pub struct OnFmu<'a>(pub &'a Fmu);

impl AxisUnderTest for OnFmu<'_> {
    fn params(&mut self, parameters: &BTreeMap<String, Value>) -> Result<Params> {
        let run = SweepRun { settings: SweepParams::default(), parameters: parameters.clone(), velocity: 0.0 };
        run.params_on(self.0)
    }

    fn sweep(
        &mut self,
        settings: &SweepParams,
        parameters: &BTreeMap<String, Value>,
        velocity: f64,
    ) -> Result<MeasuredSweep> {
        sweep_on_fmu(self.0, settings, parameters, velocity)
    }

    fn constant_speeds(
        &mut self,
        runs: &FrictionRuns,
        parameters: &BTreeMap<String, Value>,
    ) -> Result<(Vec<SpeedPoint>, f64)> {
        Ok((runs.run(self.0, parameters)?.0, runs.duration()))
    }

    fn name(&self) -> String {
        "the FMU".into()
    }
}

/// A drive over its link: the run's parameters with the drive's own commissioning in place
/// (`DriveSession::set_params`), the sweep the drive's own (`sweep::device`).
pub struct OnDrive<'a, T: DrivePort> {
    pub session: &'a mut DriveSession<T>,
    pub port: String,
}

impl<T: DrivePort> AxisUnderTest for OnDrive<'_, T> {
    fn params(&mut self, parameters: &BTreeMap<String, Value>) -> Result<Params> {
        crate::fmu::runner::refuse_drive_owned(parameters.keys())?;
        let control = crate::fmu::configuration::configuration(parameters)?.control;
        self.session.with_drive_commissioning(&power_stage::ratings::with_board_limits(control))
    }

    fn sweep(
        &mut self,
        settings: &SweepParams,
        parameters: &BTreeMap<String, Value>,
        velocity: f64,
    ) -> Result<MeasuredSweep> {
        crate::fmu::runner::refuse_drive_owned(parameters.keys())?;
        let (settings, point) = (*settings, settings.point);
        let run = SweepRun { settings, parameters: parameters.clone(), velocity };
        let sweep = crate::sweep::device::sweep_on_drive(self.session, &run, |_| {})
            .with_context(|| format!("the sweep on the drive at {}", self.port))?;
        if sweep.dropped > 0 {
            anyhow::bail!(
                "the drive at {} dropped {} samples of the sweep (its link too slow for the stream): the response \
                 would be read from a gapped record",
                self.port,
                sweep.dropped
            );
        }
        let limits = TorqueLimits::of(&self.params(parameters)?, &settings);
        Ok(MeasuredSweep {
            points: sweep.stream.into_iter().filter(|p| p.gain_db.is_finite() && p.phase_deg.is_finite()).collect(),
            drive_time_s: START_AT + sweep.measurement_time_s,
            // The stream's U is the torque command at the torque point only (a velocity at the
            // feedback point): the feedback sweep's torque is not read there.
            torque_limited: match point {
                InjectionPoint::TorqueCommand => torque_limited_points(&sweep.trace, &limits),
                _ => 0,
            },
            voltage_limited: sweep.limited_hz.len(),
            torque_limit: limits.lowest(),
        })
    }

    fn constant_speeds(
        &mut self,
        runs: &FrictionRuns,
        parameters: &BTreeMap<String, Value>,
    ) -> Result<(Vec<SpeedPoint>, f64)> {
        let params = self.params(parameters)?;
        crate::calibrate::friction_runs_on_drive::run_on_drive(self.session, runs, &params)
            .with_context(|| format!("the constant-speed runs on the drive at {}", self.port))
    }

    fn name(&self) -> String {
        format!("the drive at {}", self.port)
    }
}

/// How many of a drive's streamed sweep points have a sample whose torque (the stream's U:
/// the torque command, averaged over the acquisition period) reached `limits`. An average at
/// the limit means the command sat there; a clamp shorter than the period can hide in it, so
/// this counts no more than the FMU's per-tick count would.
fn torque_limited_points(trace: &Trace, limits: &TorqueLimits) -> usize {
    let (Some(point), Some(measuring), Some(u)) =
        (trace.column("acq_point"), trace.column("acq_measuring"), trace.column("acq_u"))
    else {
        return 0;
    };
    let mut limited: Vec<i64> =
        (0..point.len()).filter(|&i| measuring[i] != 0.0 && limits.reached(u[i])).map(|i| point[i] as i64).collect();
    limited.dedup();
    limited.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_point_counts_once_however_many_of_its_samples_sat_at_the_limit() {
        let limits = TorqueLimits::of(&Params::default(), &SweepParams::default());
        let at = limits.lowest() * 1.001;
        let mut t = Trace::new(["acq_point", "acq_measuring", "acq_u"].map(String::from).to_vec());
        for &(p, m, u) in &[(0.0, 1.0, at), (0.0, 1.0, -at), (1.0, 1.0, 0.1), (2.0, 0.0, at), (3.0, 1.0, -at)] {
            t.rows.push([p, m, u]);
        }
        // Point 0 twice, point 2 not measuring, point 3 once.
        assert_eq!(torque_limited_points(&t, &limits), 2);
    }
}
