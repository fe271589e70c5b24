//! The drive's whole-pulse Butterworth against the same filter computed in f64
//! ([`control_core::acc_dec::reference`]): the commanded position (the running sum of the
//! drive's output pulses) minus the reference's position (input so far minus its lag), at every
//! tick of a move, until both have settled. `servo bench accdec` runs the grid of the issue:
//! orders 1–6 × cut-offs from 0.5 Hz to a quarter of the sampling rate × sample periods
//! 0.125–2 ms × moves of 1 to 10⁹ counts (both signs), each as a one-tick step, a rectangle and a
//! trapezoid of velocity (short and long).

use control_core::acc_dec::reference::ReferenceFilter;
use control_core::acc_dec::{
    ButterworthDesign, ButterworthPulseFilter, ZeroPlacement, MAX_ORDER, MIN_CUTOFF_HZ, MIN_CUTOFF_TIMES_PERIOD,
};
use serde::Serialize;

/// How the move's pulses are spread over the ticks.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub enum Profile {
    /// Every pulse in one tick.
    Step,
    /// Constant velocity for this long (s).
    Rectangle(f64),
    /// Velocity ramps up over a quarter, holds for half and ramps down over the last quarter of
    /// this long (s).
    Trapezoid(f64),
}

impl Profile {
    /// Pulses per tick of a move of `distance` counts at `period` (s).
    pub fn pulses(self, distance: i64, period: f64) -> Vec<i64> {
        let (duration, shape): (f64, fn(f64) -> f64) = match self {
            Self::Step => return vec![distance],
            Self::Rectangle(d) => (d, |s| s),
            Self::Trapezoid(d) => (d, trapezoid_position),
        };
        let ticks = ((duration / period).round() as usize).max(1);
        let at = |k: usize| (distance as f64 * shape(k as f64 / ticks as f64)).round() as i64;
        (1..=ticks).map(|k| at(k) - at(k - 1)).collect()
    }

    pub fn label(self) -> String {
        match self {
            Self::Step => "step (one tick)".into(),
            // To the microsecond: 26.6 ms, not 26.599999999999998.
            Self::Rectangle(d) => format!("rectangle {} ms", (d * 1e6).round() / 1e3),
            Self::Trapezoid(d) => format!("trapezoid {} ms", (d * 1e6).round() / 1e3),
        }
    }
}

/// Normalised position (0 to 1) of the trapezoid at normalised time s: accelerate over
/// [0, ¼], cruise, decelerate over [¾, 1]; peak velocity 4/3.
fn trapezoid_position(s: f64) -> f64 {
    let v = 4.0 / 3.0;
    let a = v / 0.25;
    if s < 0.25 {
        0.5 * a * s * s
    } else if s < 0.75 {
        0.5 * a * 0.0625 + v * (s - 0.25)
    } else {
        let r = 1.0 - s;
        1.0 - 0.5 * a * r * r
    }
}

/// One run of the grid.
#[derive(Clone, Debug, Serialize)]
pub struct Deviation {
    pub order: u32,
    pub cutoff_hz: f32,
    pub sample_period: f32,
    pub distance: i64,
    pub profile: Profile,
    /// Largest |drive position − reference position| over the run (counts).
    pub worst: f64,
    /// Largest |drive lag before rounding − reference lag| (counts): the deviation less the
    /// rounding to whole pulses.
    pub lag_error: f64,
    /// The tick where the worst deviation happened, and the reference's lag then (counts).
    pub worst_tick: usize,
    pub lag_then: f64,
    /// Largest |lag| of the reference over the run (counts).
    pub peak_lag: f64,
    /// Largest state of the drive's filter over the run (counts; the states saturate at 2³¹).
    pub largest_state: f64,
    pub ticks: usize,
    /// Output sum minus input sum once settled (must be 0).
    pub pulse_balance: i64,
}

/// Run one move through the drive's filter and the reference until both have settled.
pub fn deviation(
    order: u32,
    cutoff_hz: f32,
    sample_period: f32,
    distance: i64,
    profile: Profile,
) -> Result<Deviation, String> {
    let design = ButterworthDesign::new(order, cutoff_hz, sample_period).map_err(|e| e.to_string())?;
    let mut drive = ButterworthPulseFilter::new(design);
    let mut reference = ReferenceFilter::new(order, cutoff_hz as f64, sample_period as f64, ZeroPlacement::Seed);
    let input = profile.pulses(distance, sample_period as f64);
    // Slowest mode: decay rate ωc·sin(π/2N) per second; e⁻³⁰ of it is far below a count.
    let wc_t = std::f64::consts::TAU * cutoff_hz as f64 * sample_period as f64;
    let slowest = wc_t * (std::f64::consts::PI / (2 * order) as f64).sin();
    let limit = input.len() + (40.0 / slowest) as usize + 1000;
    let (mut position, mut input_sum) = (0i64, 0i64);
    let mut result = Deviation {
        order,
        cutoff_hz,
        sample_period,
        distance,
        profile,
        worst: 0.0,
        lag_error: 0.0,
        worst_tick: 0,
        lag_then: 0.0,
        peak_lag: 0.0,
        largest_state: 0.0,
        ticks: 0,
        pulse_balance: 0,
    };
    let mut quiet = 0;
    for k in 0..limit {
        let u = input.get(k).copied().unwrap_or(0);
        input_sum += u;
        position += drive.step(u);
        let (_, lag) = reference.step(u as f64);
        let d = (position as f64 - (input_sum as f64 - lag)).abs();
        if d > result.worst {
            (result.worst, result.worst_tick, result.lag_then) = (d, k, lag);
        }
        result.lag_error = result.lag_error.max((drive.pending() - lag).abs());
        result.peak_lag = result.peak_lag.max(lag.abs());
        result.largest_state = result.largest_state.max(drive.largest_state());
        result.ticks = k + 1;
        quiet = if k >= input.len() && lag.abs() < 1e-3 && drive.stock() == 0 { quiet + 1 } else { 0 };
        if quiet > 64 {
            break;
        }
    }
    result.pulse_balance = position - input_sum;
    Ok(result)
}

/// The grid's settings.
pub const PERIODS: [f32; 5] = [0.000125, 0.00025, 0.0005, 0.001, 0.002];
pub const DISTANCES: [i64; 4] = [1, 1000, 1_000_000, 1_000_000_000];
/// Cut-offs from 0.5 Hz up to a quarter of the sampling rate (which is added).
pub const CUTOFFS_HZ: [f32; 11] = [0.5, 1.0, 2.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0];
pub const PROFILES: [Profile; 5] = [
    Profile::Step,
    Profile::Rectangle(0.02),
    Profile::Rectangle(0.5),
    Profile::Trapezoid(0.02),
    Profile::Trapezoid(0.5),
];

/// Every case of the grid: (order, cut-off, period, distance, profile).
pub fn grid() -> Vec<(u32, f32, f32, i64, Profile)> {
    let mut cases = Vec::new();
    for period in PERIODS {
        let quarter = 0.25 / period;
        let cutoffs: Vec<f32> =
            CUTOFFS_HZ.iter().copied().filter(|&c| c < quarter).chain(std::iter::once(quarter)).collect();
        for order in 1..=MAX_ORDER {
            for &cutoff in &cutoffs {
                for distance in DISTANCES {
                    for sign in [1, -1] {
                        for profile in PROFILES {
                            cases.push((order, cutoff, period, sign * distance, profile));
                        }
                    }
                }
            }
        }
    }
    cases
}

/// The drive's shortest position-loop period (s): a 200 kHz current loop (the most
/// `Params::validate` accepts) with a position divider of 1.
pub const SHORTEST_PERIOD: f32 = 5.0e-6;

/// The region the grid reaches only at its corner, drawn in one case of three by
/// [`random_cases`]: large, fast moves through orders 4–6 with the cut-off × period product
/// near the design's minimum ([`MIN_CUTOFF_TIMES_PERIOD`]), where the poles sit closest to
/// `z = 1` and the lag is largest (up to 2·10⁹ counts, near the states' 2³¹).
pub mod hard {
    /// Orders drawn (uniform).
    pub const ORDERS: (u32, u32) = (4, 6);
    /// Periods (s, log-uniform): the drive's shortest to twice the grid's shortest.
    pub const PERIODS: (f32, f32) = (super::SHORTEST_PERIOD, 0.00025);
    /// Cut-off (log-uniform) from the design's minimum at the period to this many times it.
    pub const CUTOFF_SPAN: f64 = 4.0;
    /// Moves (counts, log-uniform).
    pub const DISTANCES: (f64, f64) = (1.0e6, 2.0e9);
    /// Durations of the rectangles and trapezoids (s, log-uniform; at least one tick).
    pub const DURATIONS: (f64, f64) = (0.0001, 0.2);
}

/// `n` cases drawn with `seed` (cases the project does not ship). Two cases in three: order
/// 1–6, either sign and a step, rectangle or trapezoid, each uniform; sample period (0.125–2
/// ms), cut-off (0.5 Hz to a quarter of the sampling rate), move (1–10⁹ counts) and duration
/// (1 ms–2 s), each log-uniform. One in three from the [`hard`] region: order 4–6, either sign
/// and shape uniform; period 5 µs–0.25 ms, cut-off from the design's minimum at that period
/// (0.5 Hz and 6·10⁻⁵ / period) to 4 times it, move 10⁶–2·10⁹ counts and duration 0.1 ms–0.2
/// s, each log-uniform.
pub fn random_cases(n: u32, seed: u64) -> Vec<(u32, f32, f32, i64, Profile)> {
    random_cases_marked(n, seed).into_iter().map(|(case, _)| case).collect()
}

/// A case: (order, cut-off, period, distance, profile).
pub type Case = (u32, f32, f32, i64, Profile);

/// [`random_cases`], each with whether it was drawn from the [`hard`] region.
pub fn random_cases_marked(n: u32, seed: u64) -> Vec<(Case, bool)> {
    let mut rng = crate::random::XorShift64Star::from_seed(seed);
    (0..n)
        .map(|_| {
            if rng.below(3) == 0 {
                return (hard_case(&mut rng), true);
            }
            let order = 1 + rng.below(MAX_ORDER as u64) as u32;
            let period = rng.log_uniform_3_digits(PERIODS[0] as f64, PERIODS[PERIODS.len() - 1] as f64) as f32;
            let cutoff = rng.log_uniform_3_digits(CUTOFFS_HZ[0] as f64, 0.25 / period as f64) as f32;
            let distance = rng.log_uniform_3_digits(1.0, DISTANCES[DISTANCES.len() - 1] as f64).round() as i64;
            let sign = if rng.below(2) == 0 { 1 } else { -1 };
            let duration = rng.log_uniform_3_digits(0.001, 2.0);
            let profile = match rng.below(3) {
                0 => Profile::Step,
                1 => Profile::Rectangle(duration),
                _ => Profile::Trapezoid(duration),
            };
            ((order, cutoff, period, sign * distance.max(1), profile), false)
        })
        .collect()
}

/// One case of the [`hard`] region.
fn hard_case(rng: &mut crate::random::XorShift64Star) -> Case {
    let order = hard::ORDERS.0 + rng.below((hard::ORDERS.1 - hard::ORDERS.0 + 1) as u64) as u32;
    let period = rng.log_uniform_3_digits(hard::PERIODS.0 as f64, hard::PERIODS.1 as f64) as f32;
    // The design's own minimum, computed as it computes it (f32), so that every draw is
    // accepted; the three-digit draw keeps within its bounds.
    let minimum = MIN_CUTOFF_HZ.max(MIN_CUTOFF_TIMES_PERIOD / period) as f64;
    let cutoff = rng.log_uniform_3_digits(minimum, minimum * hard::CUTOFF_SPAN) as f32;
    let distance = rng.log_uniform_3_digits(hard::DISTANCES.0, hard::DISTANCES.1).round() as i64;
    let sign = if rng.below(2) == 0 { 1 } else { -1 };
    let duration = rng.log_uniform_3_digits(hard::DURATIONS.0, hard::DURATIONS.1);
    let profile = match rng.below(3) {
        0 => Profile::Step,
        1 => Profile::Rectangle(duration),
        _ => Profile::Trapezoid(duration),
    };
    (order, cutoff, period, sign * distance, profile)
}

/// Run the whole grid (on every core); the rows in grid order.
pub fn run_grid(progress: impl Fn(f64) + Sync) -> Result<Vec<Deviation>, String> {
    run_cases(&grid(), progress)
}

/// Run `cases` (on every core); the rows in their order.
pub fn run_cases(
    cases: &[(u32, f32, f32, i64, Profile)],
    progress: impl Fn(f64) + Sync,
) -> Result<Vec<Deviation>, String> {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).min(8);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let chunks: Vec<Result<Vec<Deviation>, String>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..threads)
            .map(|t| {
                let (done, progress) = (&done, &progress);
                s.spawn(move || {
                    cases
                        .iter()
                        .skip(t)
                        .step_by(threads)
                        .map(|&(order, cutoff, period, distance, profile)| {
                            let r = deviation(order, cutoff, period, distance, profile);
                            let n = done.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
                            progress(n as f64 / cases.len() as f64);
                            r
                        })
                        .collect()
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().expect("grid thread")).collect()
    });
    let chunks = chunks.into_iter().collect::<Result<Vec<_>, _>>()?;
    let mut rows: Vec<Option<Deviation>> = vec![None; cases.len()];
    for (t, chunk) in chunks.into_iter().enumerate() {
        for (i, row) in chunk.into_iter().enumerate() {
            rows[t + i * threads] = Some(row);
        }
    }
    Ok(rows.into_iter().map(|r| r.expect("every case ran")).collect())
}
