//! `servo bench sweep`'s check of the sweep's limited-output flag: at riding speeds where the
//! back-EMF leaves the 48 V bus too little voltage for the excitation at the top of the sweep,
//! the voltage circle cuts what the current loop asks for, the loop is not linear there, and
//! a result is not its frequency response (0.3–0.6 dB and 2–4° off at 200 rad/s on the torque
//! command). The drive counts the samples it measured while limited (`sweep_last_limited`);
//! the goal is that no result off the goals goes unflagged.

use std::collections::BTreeMap;

use anyhow::Result;
use control_core::phase_shifted_sweep::SweepParams;
use serde::Serialize;

use crate::analysis::response_point::ResponsePoint;
use crate::fmu::runner::Fmu;
use crate::fmu::sweep_run::SweepRun;
use crate::sweep::bench::{point_name, worst, GOAL_DB, GOAL_DEG, POINTS};
use crate::sweep::measurement::{limited_frequencies, online_results, stream_results};
use crate::sweep::report::oracle_run;

/// Riding speeds of the check (rad/s): twice and four times the grid's 50 rad/s. At 200 rad/s
/// the back-EMF takes 13 V of the 27.7 V the 48 V bus gives.
pub const RIDING_SPEEDS: [f64; 2] = [100.0, 200.0];

/// One injection point at one riding speed on the default axis, without sensor noise.
#[derive(Clone, Debug, Serialize)]
pub struct LimitCase {
    pub point: String,
    pub amplitude: f32,
    pub riding_rad_s: f64,
    /// Frequencies the sweep flagged as measured with the output limited, and those the
    /// oracle (same axis, speed and amplitude) flagged.
    pub flagged_hz: Vec<f64>,
    pub oracle_flagged_hz: Vec<f64>,
    /// Worst |gain| (dB) and |phase| (deg) error against the oracle over the frequencies
    /// neither flagged, and over those the sweep flagged.
    pub unflagged: (f64, f64),
    pub flagged: (f64, f64),
    /// Every frequency neither flagged is within the goals: no wrong result goes unflagged.
    pub met: bool,
}

/// Every injection point of the grid at each of [`RIDING_SPEEDS`].
pub fn limit_cases(fmu: &Fmu) -> Result<Vec<LimitCase>> {
    let mut cases = Vec::new();
    for &riding_rad_s in &RIDING_SPEEDS {
        for &(point, amplitude) in &POINTS {
            let run = SweepRun {
                settings: SweepParams { point, amplitude, ..SweepParams::default() },
                parameters: BTreeMap::new(),
                velocity: riding_rad_s,
            };
            let trace = run.run(fmu, |_| {})?;
            let ours = stream_results(&trace, &run.settings)?;
            let oracle_trace = oracle_run(&run)?.run(fmu, |_| {})?;
            let oracle = online_results(&oracle_trace)?;
            let (flagged_hz, oracle_flagged_hz) = (limited_frequencies(&trace), limited_frequencies(&oracle_trace));
            // Our flagged results, and the others but where only the oracle was limited (the
            // reference is not the linear loop's there: nothing to compare).
            let (flagged_points, others): (Vec<ResponsePoint>, Vec<ResponsePoint>) =
                ours.iter().partition(|p| flagged_hz.contains(&p.frequency));
            let unflagged_points: Vec<ResponsePoint> =
                others.into_iter().filter(|p| !oracle_flagged_hz.contains(&p.frequency)).collect();
            let worst_of = |points: &[ResponsePoint]| {
                let (g, _, p, _) = worst(points, &oracle);
                (g, p)
            };
            let (unflagged, flagged) = (worst_of(&unflagged_points), worst_of(&flagged_points));
            let met = unflagged.0 <= GOAL_DB && unflagged.1 <= GOAL_DEG && all_finite(&ours, &flagged_hz);
            cases.push(LimitCase {
                point: point_name(point).to_string(),
                amplitude,
                riding_rad_s,
                flagged_hz,
                oracle_flagged_hz,
                unflagged,
                flagged,
                met,
            });
        }
    }
    Ok(cases)
}

/// Every unflagged result has a finite gain and phase (a NaN would hide in the maxima).
fn all_finite(points: &[ResponsePoint], flagged_hz: &[f64]) -> bool {
    points
        .iter()
        .filter(|p| !flagged_hz.contains(&p.frequency))
        .all(|p| p.gain_db.is_finite() && p.phase_deg.is_finite())
}
