//! Frequency response from a sweep run on the FMU (seed 000): the equivalent-time estimate
//! from the acquisition stream, the drive's on-line correlator results, the broadband H1
//! (Welch) estimate of a PRBS run, and their comparison.

use std::collections::BTreeMap;

use anyhow::{anyhow, Result};
use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::SweepParams;
use num_complex::Complex64;
use serde::Serialize;

use crate::analysis::response_point::{difference, same_frequency, ResponsePoint};
use crate::analysis::spectral::welch_h1;
use crate::fmu::sweep_run::{is_done, SweepRun, START_AT};
use crate::fmu::trace::Trace;
use crate::sweep::standard_error::{response_standard_error, FitSample, ResponseStandardError};

/// Simulated time a sweep took in `trace`: from its start to the first step it reports done.
pub fn measured_time(trace: &Trace) -> Result<f64> {
    let [time, state] = columns(trace, ["time", "sweep_state"])?;
    let done = time
        .iter()
        .zip(&state)
        .find(|(t, s)| **t > START_AT && is_done(**s))
        .ok_or_else(|| anyhow!("the sweep never finished"))?;
    Ok(done.0 - START_AT)
}

/// Simulated time each frequency took in `trace` (settling, discarded half blocks, records
/// and their lengthening), in frequency order: from the previous completion (the sweep's
/// start for the first) to its own.
pub fn point_times(trace: &Trace) -> Result<Vec<f64>> {
    let [time, done] = columns(trace, ["time", "sweep_done_points"])?;
    let mut since = START_AT;
    let mut out = Vec::new();
    for i in 1..done.len() {
        if done[i] > done[i - 1] {
            out.push(time[i] - since);
            since = time[i];
        }
    }
    Ok(out)
}

fn columns<const N: usize>(t: &Trace, names: [&str; N]) -> Result<[Vec<f64>; N]> {
    let mut out: [Vec<f64>; N] = std::array::from_fn(|_| Vec::new());
    for (o, n) in out.iter_mut().zip(names) {
        *o = t.column(n).ok_or_else(|| anyhow!("the FMU has no output {n}"))?;
    }
    Ok(out)
}

/// The drive's on-line correlator results, read at each completion.
pub fn online_results(t: &Trace) -> Result<Vec<ResponsePoint>> {
    let [done, f, g, p, q] = columns(
        t,
        [
            "sweep_done_points",
            "sweep_last_frequency",
            "sweep_last_gain_db",
            "sweep_last_phase_deg",
            "sweep_last_quality",
        ],
    )?;
    let mut out = Vec::new();
    for i in 1..done.len() {
        if done[i] > done[i - 1] {
            out.push(ResponsePoint { frequency: f[i], gain_db: g[i], phase_deg: p[i], quality: q[i] });
        }
    }
    Ok(out)
}

/// The frequencies whose on-line result the drive measured with its output limited on any
/// of the samples (`sweep_last_limited`, the share, above 0 at the result's completion: the
/// voltage circle cut what the current loop asked for, and the loop was not linear). No
/// share is small enough to pass over: the error grows with how deep the circle cuts, not
/// with how often, and at the top of the sweep, where the response is a count or two, a
/// little goes a long way (`servo bench sweep`'s riding speeds, with sensor noise: 3.8 % of
/// the samples at 3 kHz left the result 0.16 dB and 2.4° off, while 16 % at 2 kHz on the
/// torque command left another within 0.01 dB). Empty for an FMU without that output.
pub fn limited_frequencies(t: &Trace) -> Vec<f64> {
    flagged(&limited_shares(t))
}

/// The frequencies of [`limited_shares`] with any limited sample.
pub fn flagged(shares: &[(f64, f64)]) -> Vec<f64> {
    shares.iter().filter(|&&(_, share)| share > 0.0).map(|&(f, _)| f).collect()
}

/// Every on-line result's frequency and the share of its samples measured with the drive's
/// output limited (`sweep_last_limited`, 0 for an FMU without that output), in order.
pub fn limited_shares(t: &Trace) -> Vec<(f64, f64)> {
    let (Some(done), Some(f)) = (t.column("sweep_done_points"), t.column("sweep_last_frequency")) else {
        return Vec::new();
    };
    let limited = t.column("sweep_last_limited").unwrap_or_else(|| vec![0.0; done.len()]);
    (1..done.len()).filter(|&i| done[i] > done[i - 1]).map(|i| (f[i], limited[i])).collect()
}

/// How a list of frequencies flagged as limited reads in a sentence: "2239.2, 2591.8 and
/// 3000.0 Hz".
pub fn frequency_list(hz: &[f64]) -> String {
    let words: Vec<String> = hz.iter().map(|f| format!("{f:.1}")).collect();
    match words.split_last() {
        None => String::new(),
        Some((last, [])) => format!("{last} Hz"),
        Some((last, rest)) => format!("{} and {last} Hz", rest.join(", ")),
    }
}

/// What a user reads when results were measured with the output limited.
pub fn limited_warning(hz: &[f64]) -> String {
    format!(
        "the drive's output was limited (the voltage circle cut what the current loop asked for) while it measured {}: the loop was not linear there, and the result can be off by tenths of a decibel and degrees. Lower --amplitude, ride slower (the back-EMF takes voltage: --velocity), or give the drive a higher bus voltage",
        frequency_list(hz)
    )
}

/// Three-parameter sine fit (known phase) in f64: complex amplitudes of u and y and the
/// conditioning of the phases, as the drive computes them in f32.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct SineFit {
    n: f64,
    c: f64,
    s: f64,
    cc: f64,
    ss: f64,
    cs: f64,
    u: f64,
    uc: f64,
    us: f64,
    y: f64,
    yc: f64,
    ys: f64,
    /// Σy², for the residual of the fit ([`SineFit::relative_standard_error`]).
    yy: f64,
}

impl SineFit {
    pub(crate) fn add(&mut self, u: f64, y: f64, phase: f64) {
        let (s, c) = phase.sin_cos();
        self.n += 1.0;
        self.c += c;
        self.s += s;
        self.cc += c * c;
        self.ss += s * s;
        self.cs += c * s;
        self.u += u;
        self.uc += u * c;
        self.us += u * s;
        self.y += y;
        self.yc += y * c;
        self.ys += y * s;
        self.yy += y * y;
    }

    /// Standard error of Y's fitted complex amplitude relative to its size, from the residual
    /// of y about the fitted sine (n − 3 degrees of freedom): the relative standard error of
    /// Y/U when U is exact (an injected sine), the scatter of y (noise, quantisation) its source.
    fn relative_standard_error(&self) -> f64 {
        let n = self.n;
        if n <= 3.0 {
            return f64::INFINITY;
        }
        let scc = self.cc - self.c * self.c / n;
        let sss = self.ss - self.s * self.s / n;
        let scs = self.cs - self.c * self.s / n;
        let det = scc * sss - scs * scs;
        let (pc, ps) = (self.yc - self.y * self.c / n, self.ys - self.y * self.s / n);
        let (a, b) = ((sss * pc - scs * ps) / det, (scc * ps - scs * pc) / det);
        let residual = (self.yy - self.y * self.y / n - (a * pc + b * ps)).max(0.0) / (n - 3.0);
        (residual * (sss + scc) / det).sqrt() / a.hypot(b)
    }

    pub(crate) fn solve(&self) -> (Complex64, Complex64, f64) {
        let n = self.n.max(1.0);
        let scc = self.cc - self.c * self.c / n;
        let sss = self.ss - self.s * self.s / n;
        let scs = self.cs - self.c * self.s / n;
        let det = scc * sss - scs * scs;
        let amplitude = |x: f64, xc: f64, xs: f64| {
            let (pc, ps) = (xc - x * self.c / n, xs - x * self.s / n);
            Complex64::new((sss * pc - scs * ps) / det, -(scc * ps - scs * pc) / det)
        };
        (
            amplitude(self.u, self.uc, self.us),
            amplitude(self.y, self.yc, self.ys),
            (det / (0.25 * n * n)).clamp(0.0, 1.0),
        )
    }
}

/// The equivalent-time estimate from the acquisition stream: per frequency, a sine fitted at
/// the excitation phase of every measured sample of every record (f64) that the drive kept
/// after its settling check (from the last half-block index minus one up). Needs one acquisition
/// sample per communication step (acquisition divider = the position divider).
pub fn stream_results(t: &Trace, settings: &SweepParams) -> Result<Vec<ResponsePoint>> {
    Ok(stream_results_with_errors(t, settings)?.into_iter().map(|(p, _)| p).collect())
}

/// As [`stream_results`], each point with the relative standard error of its response from the
/// scatter of y about the fitted sine (see `SineFit::relative_standard_error`).
pub fn stream_results_with_errors(t: &Trace, settings: &SweepParams) -> Result<Vec<(ResponsePoint, f64)>> {
    let [u, y, phase] = columns(t, ["acq_u", "acq_y", "acq_phase"])?;
    let sign = if settings.point == InjectionPoint::VelocityFeedback { -1.0 } else { 1.0 };
    Ok(kept_samples(t)?
        .iter()
        .map(|(&k, rows)| {
            let mut fit = SineFit::default();
            for &i in rows {
                fit.add(u[i], y[i], phase[i]);
            }
            let (uu, yy, quality) = fit.solve();
            let g = if quality > 0.0 { yy / uu * sign } else { Complex64::new(f64::NAN, f64::NAN) };
            (
                ResponsePoint::from_complex(settings.frequency(k as usize) as f64, g, quality),
                fit.relative_standard_error(),
            )
        })
        .collect())
}

/// Standard errors of every result of [`stream_results`] (in its order), from the same samples
/// with their records (`acq_record`): see [`crate::sweep::standard_error`].
pub fn stream_standard_errors(t: &Trace) -> Result<Vec<ResponseStandardError>> {
    let [u, y, phase, record] = columns(t, ["acq_u", "acq_y", "acq_phase", "acq_record"])?;
    Ok(kept_samples(t)?
        .values()
        .map(|rows| {
            let samples: Vec<FitSample> = rows
                .iter()
                .map(|&i| FitSample { u: u[i], y: y[i], phase: phase[i], record: record[i] as i64 })
                .collect();
            response_standard_error(&samples)
        })
        .collect())
}

/// Each frequency's share of the samples its fit keeps (see [`stream_results`]) that the
/// drive acquired with its output limited (`acq_limited`), counted from the stream: the same
/// samples and the same count as the drive's own `sweep_last_limited`, for every result, also
/// those a telemetry poll missed. None for a stream without the flag (an FMU or a drive
/// from before it).
pub fn stream_limited_shares(t: &Trace, settings: &SweepParams) -> Result<Option<Vec<(f64, f64)>>> {
    let Some(limited) = t.column("acq_limited") else { return Ok(None) };
    Ok(Some(
        kept_samples(t)?
            .iter()
            .map(|(&k, rows)| {
                let count = rows.iter().filter(|&&i| limited[i] != 0.0).count();
                (settings.frequency(k as usize) as f64, count as f64 / rows.len().max(1) as f64)
            })
            .collect(),
    ))
}

/// The rows of the samples the drive's fit keeps, by frequency index: measured, one per
/// acquisition time, and from the frequency's last half-block index minus one up (the
/// earlier ones were taken before the loop settled; the drive discarded them).
fn kept_samples(t: &Trace) -> Result<BTreeMap<i64, Vec<usize>>> {
    let [point, measuring, time, half_block] =
        columns(t, ["acq_point", "acq_measuring", "acq_time", "acq_half_block"])?;
    let mut last_half: BTreeMap<i64, f64> = BTreeMap::new();
    for i in 0..point.len() {
        if measuring[i] != 0.0 {
            let h = last_half.entry(point[i] as i64).or_insert(0.0);
            *h = h.max(half_block[i]);
        }
    }
    let mut kept: BTreeMap<i64, Vec<usize>> = BTreeMap::new();
    let mut last_time = f64::NEG_INFINITY;
    for i in 0..point.len() {
        let k = point[i] as i64;
        if measuring[i] == 0.0 || time[i] == last_time || half_block[i] + 1.0 < last_half[&k] {
            continue;
        }
        last_time = time[i];
        kept.entry(k).or_default().push(i);
    }
    Ok(kept)
}

/// H1 = S_uy / S_uu (Welch, Hann windows, 50 % overlap) of a PRBS run's acquisition stream,
/// read at `frequencies` (linear interpolation between bins); points above the acquisition
/// Nyquist frequency cannot be estimated and are left out. Between two acquisition samples the
/// loop reads the same chip at each of its m ticks, so H1 (from the sampled u) sees the loop's
/// response times that hold, `(1/m)·Σ e^{−jωiT}`; the known factor is divided out (chips
/// must change only at acquisition ticks: a `prbs_divider` multiple of the acquisition
/// divider).
pub fn prbs_results(t: &Trace, run: &SweepRun, frequencies: &[f64], segment: usize) -> Result<Vec<ResponsePoint>> {
    let (settings, rates) = (&run.settings, run.rates()?);
    let [measuring, u, y, time] = columns(t, ["acq_measuring", "acq_u", "acq_y", "acq_time"])?;
    let (mut us, mut ys) = (Vec::new(), Vec::new());
    let mut last_time = f64::NEG_INFINITY;
    for i in 0..u.len() {
        if measuring[i] != 0.0 && time[i] != last_time {
            us.push(u[i]);
            ys.push(y[i]);
            last_time = time[i];
        }
    }
    let fs = rates.current_loop_hz as f64 / settings.acquisition_divider as f64;
    let (h, coherence) = welch_h1(&us, &ys, segment)?;
    let df = fs / segment as f64;
    let sign = if settings.point == InjectionPoint::VelocityFeedback { -1.0 } else { 1.0 };
    let loop_ticks = if settings.point == InjectionPoint::TorqueCommand { 1 } else { rates.velocity_divider };
    let m = (settings.acquisition_divider / loop_ticks).max(1);
    let loop_period = loop_ticks as f64 / rates.current_loop_hz as f64;
    let hold = |f: f64| {
        (0..m)
            .map(|i| {
                let a = -std::f64::consts::TAU * f * i as f64 * loop_period;
                Complex64::new(a.cos(), a.sin())
            })
            .sum::<Complex64>()
            * (1.0 / m as f64)
    };
    Ok(frequencies
        .iter()
        .filter(|&&f| f < fs / 2.0)
        .map(|&f| {
            let x = f / df;
            let k = (x.floor() as usize).min(h.len() - 2);
            let w = x - k as f64;
            let g = (h[k] * (1.0 - w) + h[k + 1] * w) * sign / hold(f);
            ResponsePoint::from_complex(f, g, coherence[k] * (1.0 - w) + coherence[k + 1] * w)
        })
        .collect())
}

/// Errors of `a` against a reference at the same frequencies, split at `split_hz`:
/// (max |gain| dB, max |phase| deg) below and at-or-above; results either side cannot measure
/// ([`unmeasurable`]) are left out (a caller names them).
#[derive(Clone, Copy, Debug, Default, Serialize)]
pub struct ErrorSummary {
    pub below_gain_db: f64,
    pub below_phase_deg: f64,
    pub above_gain_db: f64,
    pub above_phase_deg: f64,
    /// Results compared (both measurable), and of those at or above the split.
    pub points_compared: usize,
    pub points_above: usize,
}

pub fn errors(a: &[ResponsePoint], reference: &[ResponsePoint], split_hz: f64) -> ErrorSummary {
    let mut s = ErrorSummary::default();
    for p in a {
        let Some(r) = reference.iter().find(|r| same_frequency(r.frequency, p.frequency)) else {
            continue;
        };
        if unmeasurable(p) || unmeasurable(r) {
            continue;
        }
        let (dg, dp) = difference(p, r);
        s.points_compared += 1;
        if p.frequency < split_hz {
            s.below_gain_db = s.below_gain_db.max(dg.abs());
            s.below_phase_deg = s.below_phase_deg.max(dp.abs());
        } else {
            s.above_gain_db = s.above_gain_db.max(dg.abs());
            s.above_phase_deg = s.above_phase_deg.max(dp.abs());
            s.points_above += 1;
        }
    }
    s
}

/// The smallest quality (the conditioning of a fit's phases, 0..1) from which a result tells
/// a response.
pub const MIN_QUALITY: f64 = 0.01;

/// A result that tells no response: a non-finite gain or phase, or phases that cannot tell a
/// sine (quality under [`MIN_QUALITY`]: a single record at a multiple of half the acquisition
/// rate, where every sample sits at one phase or its opposite).
pub fn unmeasurable(p: &ResponsePoint) -> bool {
    !(p.gain_db.is_finite() && p.phase_deg.is_finite() && p.quality >= MIN_QUALITY)
}

/// The frequencies of the [`unmeasurable`] results.
pub fn unmeasured(points: &[ResponsePoint]) -> Vec<f64> {
    points.iter().filter(|p| unmeasurable(p)).map(|p| p.frequency).collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A stream as the drive labels it: point 0 settles after discarding half blocks 0 and 1
    /// (limited while they ran), keeps 2 and 3 (two of their twenty samples limited, one row
    /// repeated at the same time as a trace at a finer step repeats it), and a limited sample
    /// outside the measurement; point 1 keeps its base block, none limited. The shares count
    /// the kept samples only, each once: 2/20 and 0, in point order with their frequencies.
    #[test]
    fn a_results_limited_share_counts_the_samples_its_fit_keeps_once() {
        let mut t = Trace::new(
            ["acq_time", "acq_point", "acq_measuring", "acq_half_block", "acq_limited", "acq_u", "acq_y", "acq_phase"]
                .map(String::from)
                .to_vec(),
        );
        let mut time = 0.0;
        let mut row = |t: &mut Trace, point: f64, measuring: f64, half: f64, limited: f64| {
            time += 1.0;
            t.rows.push([time, point, measuring, half, limited, 1.0, 1.0, time]);
        };
        row(&mut t, 0.0, 0.0, 0.0, 1.0);
        for half in 0..4 {
            for k in 0..10 {
                let limited = half < 2 || (half == 3 && k < 2);
                row(&mut t, 0.0, 1.0, half as f64, limited as u8 as f64);
            }
        }
        let last = t.rows.iter().last().unwrap().to_vec();
        t.rows.push(last);
        for half in 0..2 {
            for _ in 0..10 {
                row(&mut t, 1.0, 1.0, half as f64, 0.0);
            }
        }
        let settings = SweepParams { start_hz: 100.0, stop_hz: 200.0, points: 2, extra_hz: 0.0, ..Default::default() };
        let shares = stream_limited_shares(&t, &settings).unwrap().unwrap();
        assert_eq!(shares, vec![(100.0, 0.1), (200.0, 0.0)]);
        // A stream without the flag (an older FMU or drive) has no shares to tell.
        let mut old = t.clone();
        old.columns[4] = "something_else".into();
        assert_eq!(stream_limited_shares(&old, &settings).unwrap(), None);
    }
}
