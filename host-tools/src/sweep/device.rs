//! The sweep on a drive over its link (`servo sweep --device`): the drive's own sweep (seed
//! 000) started with the run's parameters, its acquisition samples streamed and fitted as on
//! the FMU (`measurement::stream_results`), its on-line results read from the telemetry.
//!
//! Sequence: handshake; at rest (no faults latched, or the run stops with them named); the
//! parameters (the run's, the sweep's settings included, the IHM08M1's protective limits);
//! the riding speed (a position-command sweep: velocity 0 until the axis rests, then a hold
//! where it stands); `START_AT` of the drive's time; streaming on; `StartSweep`; telemetry
//! polled until the drive says done (bounded by the longest the sweep can take, in the drive's
//! time, and by a drive that stops ticking); streaming off; the axis ramped to 0 and at rest.

use std::path::Path;

use anyhow::{anyhow, Result};
use control_core::phase_shifted_sweep::{SweepSignal, SweepState};
use control_core::protocol::Request;
use control_core::response_correction::CorrectionParams;
use control_core::{Commands, Mode};
use serde::Serialize;

use crate::analysis::response_point::{same_frequency, ResponsePoint};
use crate::device::frame_stream::{sample_rows, SAMPLE_COLUMNS};
use crate::device::session::DriveSession;
use crate::fmu::sweep_run::{SweepRun, START_AT};
use crate::fmu::trace::Trace;
use crate::sweep::device_report::save_partial;
use crate::sweep::measurement::{flagged, stream_limited_shares, stream_results, stream_standard_errors};
use crate::sweep::standard_error::ResponseStandardError;
use power_stage::ratings::with_board_limits;

/// What a sweep over the link brought back.
#[derive(Clone, Debug, Serialize)]
pub struct DeviceSweep {
    /// The drive's time from `StartSweep` to done (s).
    pub measurement_time_s: f64,
    /// Frequency response from the streamed samples (a stepped sine's; empty for a PRBS).
    pub stream: Vec<ResponsePoint>,
    /// The drive's on-line results as the telemetry polls caught them (a point finished and
    /// overwritten between two polls is missing here, not in `stream`).
    pub online: Vec<ResponsePoint>,
    /// Frequencies the drive measured while its output was limited (the voltage circle cut
    /// what the current loop asked for): not the loop's response there. Those of
    /// `limited_share` above 0, and any the telemetry caught limited that the stream lacks.
    pub limited_hz: Vec<f64>,
    /// Each result of `stream`'s share of samples acquired with the output limited (paired by
    /// index with `stream`): counted from the
    /// stream's flags over the samples its fit keeps, as the drive counts them (every result,
    /// protocol version 8), or the drive's own share where the telemetry caught the result
    /// and it is larger (a limited sample the link lost).
    pub limited_share: Vec<f64>,
    /// Each result of `stream`'s standard error (paired by index; see
    /// [`crate::sweep::standard_error`]).
    pub standard_error: Vec<ResponseStandardError>,
    pub samples: usize,
    /// Samples the drive could not send (its ring full: the link too slow).
    pub dropped: u32,
    /// Frames that did not decode during the sweep (corrupted on the line: a sample batch or
    /// an answer lost).
    pub corrupt_frames: u64,
    /// Bytes a second received from the drive during the sweep (its time), and the line's
    /// capacity at the baud rate.
    pub link_bytes_per_s: f64,
    /// The samples as received (`acq_*` columns, as the FMU's trace has them).
    #[serde(skip)]
    pub trace: Trace,
}

/// Run `run` on the drive behind `session`; `progress` gets 0..1 by points done.
pub fn sweep_on_drive<T: crate::device::link::DrivePort>(
    session: &mut DriveSession<T>,
    run: &SweepRun,
    progress: impl FnMut(f64),
) -> Result<DeviceSweep> {
    sweep_on_drive_after(session, run, |_| Ok(()), progress)
}

/// As [`sweep_on_drive`], with `correction` (if any) loaded once the drive has the run's
/// parameters (see [`sweep_on_drive_after`]); a failed run saves what the drive sent as
/// `<out>/<name>_partial.csv` and returns the error that says so.
pub fn sweep_on_drive_loading<T: crate::device::link::DrivePort>(
    session: &mut DriveSession<T>,
    run: &SweepRun,
    correction: Option<&CorrectionParams>,
    (out, name): (&Path, &str),
    progress: impl FnMut(f64),
) -> Result<DeviceSweep> {
    let load = |s: &mut DriveSession<T>| match correction {
        Some(c) => s.order(Request::LoadCorrection(*c), "the correction (LoadCorrection)"),
        None => Ok(()),
    };
    sweep_on_drive_after(session, run, load, progress).map_err(|e| save_partial(session, out, name, e))
}

/// As [`sweep_on_drive`], with `after_params` given the session once the drive has the run's
/// parameters and stands at rest (a `LoadCorrection`, for one: `SetParams` replaces the
/// correction with the parameters').
pub fn sweep_on_drive_after<T: crate::device::link::DrivePort>(
    session: &mut DriveSession<T>,
    run: &SweepRun,
    after_params: impl FnOnce(&mut DriveSession<T>) -> Result<()>,
    mut progress: impl FnMut(f64),
) -> Result<DeviceSweep> {
    // The telemetry shares the drive's transmit line with the stream (about 75 kB/s of the
    // 92 kB/s at 921 600 Bd): poll it at 50 Hz, not faster.
    session.poll = session.poll.max(std::time::Duration::from_millis(20));
    let params = with_board_limits(run.drive_params()?);
    session.set_params(&params)?;
    after_params(session)?;
    let commands = match run.mode() {
        // A position-command sweep: the axis holds where it stands, the sine adds to that. It
        // is brought to rest first (velocity 0): an axis left at zero torque after a sweep
        // coasts, and on a machine without friction it would keep turning between the reading
        // of its position and the command to hold it there, which then arrives as a step.
        Mode::Position => {
            Commands { mode: Mode::Position, position: session.hold_zero()?.position, ..Commands::default() }
        }
        mode => Commands { mode, velocity: run.velocity as f32, ..Commands::default() },
    };
    session.order(Request::SetCommands(commands), "the riding speed")?;
    session.wait(START_AT)?;
    session.order(Request::Stream { enabled: true }, "streaming on")?;
    session.take_samples();
    let (bytes_before, corrupt_before) = (session.link.bytes_read, session.link.corrupt_frames);
    session.order(Request::StartSweep, "the sweep's start")?;
    let start = session.telemetry()?.tick;
    let points = run.settings.points.max(1) as f64;
    let longest = run.max_measurement_time()? * 1.2 + 1.0;
    let (session_hz, planned) = (session.tick_hz, run.measurement_time()?.max(1e-9));
    let mut online = Vec::new();
    let mut telemetry_shares = Vec::new();
    let mut seen = 0;
    let end = session.wait_until(longest, |t| {
        if t.faults.any() {
            return Err(anyhow!("the drive latched a fault during the sweep: {}", t.faults));
        }
        if t.sweep.done_points > seen {
            seen = t.sweep.done_points;
            let l = t.sweep.last;
            telemetry_shares.push((l.frequency as f64, t.sweep.last_limited as f64));
            online.push(ResponsePoint::from_complex(
                l.frequency as f64,
                num_complex::Complex64::new(l.re as f64, l.im as f64),
                l.quality as f64,
            ));
            progress(seen as f64 / points);
        }
        if run.settings.signal == SweepSignal::Prbs {
            progress((t.tick.saturating_sub(start) as f64 / session_hz / planned).min(1.0));
        }
        Ok(t.sweep.state == SweepState::Done)
    });
    // Whatever happened, the axis stops streaming and goes back to rest (ramped down from its
    // riding speed where it rides without a fault).
    let streaming_off = session.order(Request::Stream { enabled: false }, "streaming off");
    let stop = session.stop_and_rest().map(|_| ()).and(streaming_off);
    let end = end?;
    stop?;
    let batches = session.take_samples();
    let dropped = batches.iter().map(|b| b.dropped).max().unwrap_or(0);
    let rows = sample_rows(&batches).map_err(|e| anyhow!("corrupt sample batch from the drive: {e}"))?;
    // The FMU's names for the stream's columns (`acq_time` in seconds where the drive sends ticks).
    let mut trace =
        Trace::new(SAMPLE_COLUMNS.map(|c| if c == "tick" { "acq_time".into() } else { format!("acq_{c}") }).to_vec());
    for r in &rows {
        let mut row = r.to_vec();
        row[0] /= session.tick_hz;
        trace.rows.push(row);
    }
    // A stepped sine's response per frequency; a PRBS (the identification's) has none here:
    // its caller analyses the samples.
    let (stream, streamed_shares, standard_error) = match run.settings.signal {
        SweepSignal::SteppedSine => (
            stream_results(&trace, &run.settings)?,
            stream_limited_shares(&trace, &run.settings)?.unwrap_or_default(),
            stream_standard_errors(&trace)?,
        ),
        SweepSignal::Prbs => (Vec::new(), Vec::new(), Vec::new()),
    };
    let shares: Vec<(f64, f64)> = streamed_shares
        .iter()
        .map(|&(f, share)| {
            let caught = telemetry_shares.iter().filter(|&&(g, _)| same_frequency(g, f)).map(|&(_, s)| s);
            (f, caught.fold(share, f64::max))
        })
        .collect();
    let mut limited_hz = flagged(&shares);
    // A result the drive said was limited but whose samples the stream lacks (lost on the
    // line) is named all the same.
    for &(f, share) in &telemetry_shares {
        if share > 0.0 && !shares.iter().any(|&(g, _)| same_frequency(g, f)) {
            limited_hz.push(f);
        }
    }
    limited_hz.sort_by(f64::total_cmp);
    let limited_share = shares.iter().map(|&(_, share)| share).collect();
    let measurement_time_s = (end.tick - start) as f64 / session.tick_hz;
    Ok(DeviceSweep {
        measurement_time_s,
        stream,
        online,
        limited_hz,
        limited_share,
        standard_error,
        samples: rows.len(),
        dropped,
        corrupt_frames: session.link.corrupt_frames - corrupt_before,
        link_bytes_per_s: (session.link.bytes_read - bytes_before) as f64 / measurement_time_s.max(1e-9),
        trace,
    })
}
