//! The drive's integer Butterworth against the f64 reference ([`super::super::reference`]):
//! the commanded position (running sum of the whole-pulse output) within one count of the
//! reference's position at every tick, over random settings in the checked range.

extern crate std;
use std::vec::Vec;

use super::super::reference::ReferenceFilter;
use super::*;

/// Pulses per tick of a move: every pulse in one tick, a rectangle or a trapezoid of velocity
/// over `ticks`.
fn move_pulses(distance: i64, kind: u64, ticks: usize) -> Vec<i64> {
    let shape = |s: f64| -> f64 {
        match kind {
            1 => s,
            _ => {
                // Accelerate over a quarter, cruise, decelerate over the last quarter.
                let a = 4.0 / 3.0 / 0.25;
                if s < 0.25 {
                    0.5 * a * s * s
                } else if s < 0.75 {
                    0.5 * a * 0.0625 + 4.0 / 3.0 * (s - 0.25)
                } else {
                    1.0 - 0.5 * a * (1.0 - s) * (1.0 - s)
                }
            }
        }
    };
    if kind == 0 {
        return std::vec![distance];
    }
    let at = |k: usize| (distance as f64 * shape(k as f64 / ticks as f64)).round() as i64;
    (1..=ticks).map(|k| at(k) - at(k - 1)).collect()
}

/// Run a move through both until settled; returns (largest |position difference|, largest
/// |lag difference| before rounding).
fn run(order: u32, cutoff: f32, period: f32, input: &[i64]) -> (f64, f64) {
    let mut drive = ButterworthPulseFilter::new(ButterworthDesign::new(order, cutoff, period).unwrap());
    let mut reference = ReferenceFilter::new(order, cutoff as f64, period as f64, ZeroPlacement::Seed);
    let slowest =
        crate::TAU as f64 * cutoff as f64 * period as f64 * libm::sin(core::f64::consts::PI / (2 * order) as f64);
    let ticks = input.len() + (30.0 / slowest) as usize;
    let (mut position, mut sum, mut worst, mut worst_lag) = (0i64, 0i64, 0.0f64, 0.0f64);
    for k in 0..ticks {
        let u = input.get(k).copied().unwrap_or(0);
        sum += u;
        position += drive.step(u);
        let (_, lag) = reference.step(u as f64);
        worst = worst.max((position as f64 - (sum as f64 - lag)).abs());
        worst_lag = worst_lag.max((drive.pending() - lag).abs());
    }
    assert_eq!(position, sum, "order {order}, {cutoff} Hz, {period} s: every pulse out");
    (worst, worst_lag)
}

#[test]
fn the_commanded_position_stays_within_a_count_of_the_f64_filter_over_random_settings() {
    let mut rng = Random(0x0003_AD0C);
    let log_uniform = |rng: &mut Random, lo: f64, hi: f64| lo * libm::exp(libm::log(hi / lo) * rng.unit() as f64);
    let (mut worst, mut worst_lag) = (0.0f64, 0.0f64);
    for case in 0..60 {
        let order = 1 + rng.below(MAX_ORDER as u64) as u32;
        let period = log_uniform(&mut rng, 0.000125, 0.002) as f32;
        let cutoff = log_uniform(&mut rng, 0.5, 0.25 / period as f64) as f32;
        let distance = log_uniform(&mut rng, 1.0, 1e9).round() as i64 * if rng.below(2) == 0 { 1 } else { -1 };
        let kind = rng.below(3);
        let ticks = 1 + (log_uniform(&mut rng, 0.001, 1.0) / period as f64) as usize;
        let (w, l) = run(order, cutoff, period, &move_pulses(distance, kind, ticks));
        assert!(w <= 1.0, "case {case}: order {order}, {cutoff} Hz, {period} s, {distance} counts: {w}");
        (worst, worst_lag) = (worst.max(w), worst_lag.max(l));
    }
    // Half a count of rounding and a small lag error.
    assert!(worst_lag < 0.01, "lag error {worst_lag}");
    std::eprintln!("random settings: worst position difference {worst:.4} counts, lag error {worst_lag:.2e}");
}

#[test]
fn a_billion_counts_at_the_lowest_cut_off_and_shortest_period() {
    // The corner where f32 states were thousands of counts off: order 6, 0.5 Hz, 0.125 ms
    // (ωc·T = 3.9·10⁻⁴), 10⁹ counts in one tick and as a half-second trapezoid.
    for input in [std::vec![1_000_000_000], move_pulses(-1_000_000_000, 2, 4000)] {
        let (w, l) = run(6, 0.5, 0.000125, &input);
        assert!(w <= 1.0 && l < 0.01, "{w} counts, lag error {l}");
    }
}

#[test]
fn large_fast_moves_at_the_lowest_cut_off_times_period_stay_within_a_count() {
    // Orders 4-6 at exactly the design's minimum cut-off (0.5 Hz and 6·10⁻⁵ / period) from the
    // drive's shortest position period (5 µs: 200 kHz, divider 1) to the grid's shortest
    // (0.125 ms), where the poles sit closest to z = 1 (ωc·T = 3.8·10⁻⁴): moves of up to
    // 2·10⁹ counts (lags near the states' 2³¹) in one tick, a 1 ms rectangle and a 20 ms
    // trapezoid, either sign. The lag's error is held well below the half count of room the
    // rounding leaves, so that a regression shows before a move crosses one count.
    let (mut worst, mut worst_lag) = (0.0f64, 0.0f64);
    for order in 4..=MAX_ORDER {
        for period in [5.0e-6f32, 1.79e-5, 6.25e-5, 0.00012, 0.000125] {
            let cutoff = MIN_CUTOFF_HZ.max(MIN_CUTOFF_TIMES_PERIOD / period);
            for (distance, kind, seconds) in
                [(2_000_000_000i64, 0, 0.0), (-1_000_000_000, 1, 0.001), (1_500_000_000, 2, 0.02)]
            {
                let ticks = ((seconds / period as f64).round() as usize).max(1);
                let (w, l) = run(order, cutoff, period, &move_pulses(distance, kind, ticks));
                assert!(w <= 1.0, "order {order}, {cutoff} Hz, {period} s, {distance} counts, shape {kind}: {w}");
                (worst, worst_lag) = (worst.max(w), worst_lag.max(l));
            }
        }
    }
    assert!(worst_lag < 0.05, "lag error {worst_lag}");
    std::eprintln!("lowest cut-off × period: worst position difference {worst:.4} counts, lag error {worst_lag:.2e}");
}

#[test]
fn the_reference_equals_a_direct_form_simulation_where_that_is_accurate() {
    // The reference's modal form against y = (B(z)/A(z))·u in f64 from the printed polynomials
    // at 300 Hz and 0.5 ms (poles far from z = 1): output and lag (input sum − output sum).
    for zeros in [ZeroPlacement::Seed, ZeroPlacement::AllDelays] {
        for order in 1..=MAX_ORDER {
            let d = ButterworthDesign::with_zeros(order, 300.0, 0.0005, zeros).unwrap();
            let (a, b) = (d.denominator(), d.numerator());
            let mut reference = ReferenceFilter::new(order, 300.0, 0.0005f32 as f64, zeros);
            let (mut xs, mut ys) = ([0.0f64; 7], [0.0f64; 7]);
            let (mut sum_in, mut sum_out) = (0.0, 0.0);
            for k in 0..300 {
                let x = [1000.0, -250.0, 0.0][(k / 20).min(2)];
                xs.rotate_right(1);
                ys.rotate_right(1);
                xs[0] = x;
                ys[0] = (0..7).map(|i| b[i] * xs[i]).sum::<f64>() - (1..7).map(|i| a[i] * ys[i]).sum::<f64>();
                sum_in += x;
                sum_out += ys[0];
                let (y, lag) = reference.step(x);
                assert!((y - ys[0]).abs() < 1e-9, "{zeros:?} order {order} tick {k}: {y} vs {}", ys[0]);
                assert!((lag - (sum_in - sum_out)).abs() < 1e-8, "{zeros:?} order {order} tick {k}: lag {lag}");
            }
        }
    }
}

#[test]
fn the_all_delays_placement_follows_its_reference_too() {
    for order in 1..=MAX_ORDER {
        let d = ButterworthDesign::with_zeros(order, 2.0, 0.00025, ZeroPlacement::AllDelays).unwrap();
        let mut drive = ButterworthPulseFilter::new(d);
        let mut reference = ReferenceFilter::new(order, 2.0, 0.00025f32 as f64, ZeroPlacement::AllDelays);
        let (mut position, mut sum) = (0i64, 0i64);
        for k in 0..40_000 {
            let u = if k == 0 { 123_456_789 } else { 0 };
            sum += u;
            position += drive.step(u);
            let lag = reference.step(u as f64).1;
            assert!((position as f64 - (sum as f64 - lag)).abs() <= 1.0, "order {order}, tick {k}");
        }
        assert_eq!(position, sum);
    }
}

#[test]
fn jumps_beyond_the_filtered_range_pass_through_counted_and_never_overflow() {
    // Streamed positions may jump by up to 2⁵⁴ counts in a tick: the part beyond 2³¹ passes
    // unfiltered; nothing wraps or panics (overflow checks are on in the robustness profile)
    // and every pulse comes out once the filter settles.
    let mut rng = Random(54);
    for order in 1..=MAX_ORDER {
        for cutoff in [0.5, 50.0, 2000.0] {
            let mut f = ButterworthPulseFilter::new(ButterworthDesign::new(order, cutoff, 0.00025).unwrap());
            let (mut sum_in, mut sum_out) = (0i128, 0i128);
            for k in 0..200 {
                let x = match k % 4 {
                    0 => (1i64 << 54) * if rng.below(2) == 0 { 1 } else { -1 },
                    1 => i64::MAX / 4,
                    2 => -(rng.below(1 << 40) as i64),
                    _ => 0,
                };
                sum_in += x as i128;
                sum_out += f.step(x) as i128;
                assert_eq!(sum_in - sum_out, f.stock() as i128, "order {order}, {cutoff} Hz, tick {k}");
            }
            for _ in 0..(40.0 / (cutoff * 0.00025 * 0.26 * crate::TAU)) as usize {
                sum_out += f.step(0) as i128;
            }
            assert_eq!(f.stock(), 0, "order {order}, {cutoff} Hz settles");
            assert_eq!(sum_out, sum_in, "order {order}, {cutoff} Hz");
        }
    }
}
