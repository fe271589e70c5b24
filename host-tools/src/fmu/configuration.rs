//! The configuration a run gives the FMU: the FMU's start values with the run's parameters on
//! top, turned into the control core's `Params` and the plant's parameters by the FMU's own
//! `simulation_config` (what `exitInitializationMode` does). Experiments plan with this —
//! loop rates, limits, the plant — never with the defaults in its place, so
//! `--set ctrl.current_loop_hz=…` moves the plan with the loop.

use std::collections::BTreeMap;

use anyhow::{anyhow, bail, Result};
use servo_axis::parameters::simulation_config;
use servo_axis::simulation::SimulationConfig;
use servo_axis::variables::{by_name, check, Causality, Kind, Value as FmuValue, Values};

use crate::fmu::scenario::Value;

/// The FMU's value of `value` for the variable `name`, converted as the runner sets it.
fn fmu_value(name: &str, kind: Kind, value: Value) -> Result<FmuValue> {
    Ok(match (kind, value) {
        (Kind::Float64, v) => FmuValue::Float64(v.as_f64()),
        (Kind::Int32, Value::Int(i)) => {
            FmuValue::Int32(i32::try_from(i).map_err(|_| anyhow!("{name} = {i} does not fit a 32-bit integer"))?)
        }
        // Model files keep every parameter as a number: a whole one sets an integer.
        (Kind::Int32, Value::Float(f)) if f.fract() == 0.0 && f >= i32::MIN as f64 && f <= i32::MAX as f64 => {
            FmuValue::Int32(f as i32)
        }
        (Kind::Boolean, Value::Bool(b)) => FmuValue::Boolean(b),
        (kind, v) => bail!("{name} is {kind:?}; {v:?} is not a value of that type"),
    })
}

/// The configuration the FMU builds from `parameters` (names as in the model description).
pub fn configuration(parameters: &BTreeMap<String, Value>) -> Result<SimulationConfig> {
    let mut values = Values::start();
    for (name, &value) in parameters {
        let d = by_name(name).ok_or_else(|| anyhow!("the FMU has no variable `{name}`"))?;
        // As the runner refuses it: a run sets parameters, not inputs or outputs.
        if d.causality != Causality::Parameter {
            bail!("`{name}` is not a parameter of the FMU (it is {:?})", d.causality);
        }
        let v = fmu_value(name, d.kind, value)?;
        check(d, v).map_err(|e| anyhow!("{e}"))?;
        values.set(d.vr, v).map_err(|e| anyhow!("{e}"))?;
    }
    simulation_config(&values).map_err(|e| anyhow!("invalid parameters: {e}"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_run_parameters_reach_the_configuration() {
        let p: BTreeMap<String, Value> = [
            ("ctrl.current_loop_hz".to_string(), Value::Int(20_000)),
            ("plant.load_inertia".to_string(), Value::Float(3.0e-4)),
        ]
        .into_iter()
        .collect();
        let c = configuration(&p).unwrap();
        assert_eq!(c.control.rates.current_loop_hz, 20_000.0);
        assert_eq!(c.plant.load_inertia, 3.0e-4);
        assert_eq!(c.plant.tick, 1.0 / 20_000.0);
        let defaults = configuration(&BTreeMap::new()).unwrap();
        assert_eq!(defaults.control.rates.current_loop_hz, control_core::Params::default().rates.current_loop_hz);
    }

    #[test]
    fn bad_parameters_are_refused() {
        let one = |n: &str, v: Value| configuration(&[(n.to_string(), v)].into_iter().collect());
        assert!(one("ctrl.no_such_thing", Value::Int(1)).is_err());
        assert!(one("ctrl.current_loop_hz", Value::Float(-5.0)).is_err());
        assert!(one("plant.pole_pairs", Value::Float(2.5)).is_err());
        // An input is set by events, not as a parameter (the runner refuses it too).
        assert!(one("position_command", Value::Float(0.0)).unwrap_err().to_string().contains("not a parameter"));
    }
}
