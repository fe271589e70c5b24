//! The drive's latched faults as an FMU trace shows them (`faults`, the bit set of
//! `control_core::faults::Faults`): a run whose drive latched one switched its bridge off there,
//! and nothing it measured afterwards is the loop's response.

use control_core::faults::Faults;
use serde::Serialize;

use crate::fmu::trace::Trace;

/// The first fault the drive latched in a run: when, and which bits.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FaultEvent {
    pub time_s: f64,
    pub bits: u32,
    /// The bits' names ("following error, overcurrent").
    pub names: String,
}

impl FaultEvent {
    /// What a user reads: what happened, and what it means for the run's results.
    pub fn sentence(&self) -> String {
        format!(
            "the drive latched a fault at t = {:.4} s ({}) and switched its bridge off: nothing measured from there on is the loop's response",
            self.time_s, self.names
        )
    }
}

/// The first row of `trace` with a latched fault (None without faults or without the output).
pub fn first_fault(trace: &Trace) -> Option<FaultEvent> {
    let (time, faults) = (trace.column("time")?, trace.column("faults")?);
    let i = faults.iter().position(|&f| f != 0.0)?;
    let bits = faults[i] as u32;
    Some(FaultEvent { time_s: time[i], bits, names: Faults(bits).to_string() })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_first_latched_fault_is_named_with_its_time() {
        let mut t = Trace::new(vec!["time".into(), "faults".into()]);
        for (time, f) in [(0.0, 0.0), (0.25, 0.0), (0.5, 8.0), (0.75, 9.0)] {
            t.rows.push([time, f]);
        }
        let e = first_fault(&t).unwrap();
        assert_eq!((e.time_s, e.bits, e.names.as_str()), (0.5, 8, "following error"));
        assert!(e.sentence().contains("t = 0.5000 s (following error)"), "{}", e.sentence());
        let mut clean = Trace::new(vec!["time".into(), "faults".into()]);
        clean.rows.push([0.0, 0.0]);
        assert_eq!(first_fault(&clean), None);
    }
}
