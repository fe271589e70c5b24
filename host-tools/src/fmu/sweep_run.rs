//! A run of the drive's sweep on the FMU (the stepped sine of seed 000 or the PRBS the
//! identification uses): its scenario, and the run until the drive reports it done.

use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Result};
use control_core::axis::Mode;
use control_core::excitation::InjectionPoint;
use control_core::params::Rates;
use control_core::phase_shifted_sweep::{SweepParams, SweepState};

use crate::fmu::configuration::configuration;
use crate::fmu::runner::Fmu;
use crate::fmu::scenario::{Event, Scenario, Value};
use crate::fmu::trace::Trace;

/// A sweep as run: the FMU parameters, the settings and where it starts.
#[derive(Clone, Debug)]
pub struct SweepRun {
    pub settings: SweepParams,
    /// Other FMU parameters (plant, controller).
    pub parameters: BTreeMap<String, Value>,
    /// Velocity-mode offset (rad/s): a constant speed keeps friction on one side.
    pub velocity: f64,
}

/// When the sweep starts (s): the axis is brought to its riding speed at 0 and rides steadily
/// by then (a soft 5:1 axis takes about 0.4 s to settle within 0.1 rad/s at 50 rad/s); the
/// sweep's measurement time counts from here.
pub const START_AT: f64 = 0.5;

/// Whether a `sweep_state` output value says the sweep is done.
pub fn is_done(sweep_state: f64) -> bool {
    SweepState::from_code(sweep_state as i32) == Some(SweepState::Done)
}

fn sweep_parameters(s: &SweepParams) -> Vec<(String, Value)> {
    servo_axis::parameters::sweep_values(s).into_iter().map(|(n, v)| (n.to_string(), Value::from(v))).collect()
}

impl SweepRun {
    /// The loop rates the FMU runs with these parameters.
    pub fn rates(&self) -> Result<Rates> {
        Ok(configuration(&self.parameters)?.control.rates)
    }

    /// Simulated time the sweep's fixed schedule takes (s): its length when no frequency is
    /// lengthened for precision (see `sweep::measurement::measured_time` for what a run took).
    pub fn measurement_time(&self) -> Result<f64> {
        let fs = self.rates()?.current_loop_hz;
        Ok(self.settings.total_ticks(fs) as f64 / fs as f64)
    }

    /// The longest the sweep can take: every record lengthened by `max_extensions` blocks, or
    /// the time budget where that is longer (`SweepParams::max_total_ticks`).
    pub fn max_measurement_time(&self) -> Result<f64> {
        let fs = self.rates()?.current_loop_hz;
        Ok(self.settings.max_total_ticks(fs) as f64 / fs as f64)
    }

    /// The parameters a drive is given for this sweep: the run's, with the sweep's settings.
    /// The FMU refuses a sweep it cannot run when it starts (logged); these are refused here,
    /// before any run, with the same reason.
    pub fn drive_params(&self) -> Result<control_core::Params> {
        let rates = self.rates()?;
        self.settings.validate(rates.current_loop_hz, rates.velocity_divider).map_err(|e| anyhow!("{e}"))?;
        let control = configuration(&self.fmu_parameters())?.control;
        // What the start would refuse (the limits, the position loop's rate), refused here.
        control.validate_sweep().map_err(|e| anyhow!("{e}"))?;
        Ok(control)
    }

    /// [`SweepRun::drive_params`] as `fmu` runs them: a drive's twin with that drive's motor
    /// and current loop ([`Fmu::twin_parameters`]), the run's own otherwise.
    pub fn params_on(&self, fmu: &Fmu) -> Result<control_core::Params> {
        let mut parameters = self.fmu_parameters();
        for (name, value) in fmu.twin_parameters_for(&parameters) {
            parameters.entry(name).or_insert(value);
        }
        Ok(configuration(&parameters)?.control)
    }

    /// The run's FMU parameters with the sweep's settings.
    fn fmu_parameters(&self) -> BTreeMap<String, Value> {
        let mut parameters = self.parameters.clone();
        parameters.extend(sweep_parameters(&self.settings));
        parameters
    }

    /// The mode the sweep rides in: position (holding where the axis stands) for a
    /// position-command sweep, torque for a torque-command sweep standing still, velocity
    /// otherwise.
    pub fn mode(&self) -> Mode {
        match self.settings.point {
            InjectionPoint::PositionCommand => Mode::Position,
            InjectionPoint::TorqueCommand if self.velocity == 0.0 => Mode::Torque,
            _ => Mode::Velocity,
        }
    }

    pub fn scenario(&self) -> Result<Scenario> {
        let rates = self.drive_params()?.rates;
        let parameters = self.fmu_parameters();
        // One communication step per position-loop period, as a drive's link streams: the
        // stream then carries every acquisition sample (acquisition divider = position
        // divider) at any loop rate. (A fixed 250 µs step at a 32 kHz loop kept every other
        // sample: the host's estimate lost half its samples and, at 2 kHz, all but two phases.)
        let step = rates.position_divider as f64 / rates.current_loop_hz as f64;
        // Long enough for the longest sweep; `run` stops when it is done.
        let stop = ((START_AT + self.max_measurement_time()?) / step).ceil() * step + 4.0 * step;
        let mode = self.mode();
        let mut start: BTreeMap<String, Value> = [
            ("mode".to_string(), Value::code(mode.code())),
            ("velocity_command".to_string(), Value::Float(self.velocity)),
        ]
        .into_iter()
        .collect();
        if mode == Mode::Position {
            // Holding the start (the sine adds to this streamed position).
            start.insert("position_command".into(), Value::Float(0.0));
            start.insert("move_speed".into(), Value::Float(0.0));
        }
        Ok(Scenario {
            name: "sweep".into(),
            description: String::new(),
            stop_time: stop,
            step: Some(step),
            parameters,
            events: vec![
                Event { time: 0.0, inputs: start },
                Event { time: START_AT, inputs: [("sweep_start".to_string(), Value::Int(1))].into_iter().collect() },
            ],
            checks: vec![],
            plot: vec![],
            record: vec![],
        })
    }

    /// Run the sweep until it is done (the trace ends at the first step after it finishes).
    pub fn run(&self, fmu: &Fmu, mut progress: impl FnMut(f64)) -> Result<Trace> {
        let scenario = self.scenario()?;
        let state = 1 + fmu
            .recorded(&scenario.record)?
            .iter()
            .position(|v| v.name == "sweep_state")
            .ok_or_else(|| anyhow!("the FMU has no sweep outputs"))?;
        // Progress against the fixed schedule (the usual length), not the longest possible.
        let scale = scenario.stop_time / (START_AT + self.measurement_time()?);
        let t = fmu.run_until(
            &scenario,
            |f| progress((f * scale).min(0.99)),
            |row| row[0] > START_AT && is_done(row[state]),
        )?;
        progress(1.0);
        if !t.rows.last().is_some_and(|r| is_done(r[state])) {
            match crate::fmu::axis_health::first_trip(&t)? {
                Some(fault) => bail!("the sweep did not finish: {}", fault.sentence()),
                None => bail!("the sweep did not finish within the simulated time"),
            }
        }
        Ok(t)
    }

    /// The scenario as far as `trace` ran it (for another importer to run the same steps).
    pub fn scenario_as_run(&self, trace: &Trace) -> Result<Scenario> {
        let end = trace.rows.last().map(|r| r[0]).ok_or_else(|| anyhow!("empty trace"))?;
        Ok(Scenario { stop_time: end, ..self.scenario()? })
    }
}
