use super::*;

/// xorshift64*: reproducible random sequences without a dependency.
struct Random(u64);

impl Random {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }
    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
    fn unit(&mut self) -> f32 {
        (self.next() >> 40) as f32 / (1u64 << 24) as f32
    }
    fn pulses(&mut self) -> i64 {
        // Mostly moderate rates, sometimes large, both signs, often zero.
        match self.below(4) {
            0 => 0,
            1 => self.below(201) as i64 - 100,
            2 => self.below(40_001) as i64 - 20_000,
            _ => self.below(2_000_001) as i64 - 1_000_000,
        }
    }
}

#[test]
fn seed_example_coefficients_to_its_printed_digits() {
    // Seed 003: 1 kHz cut-off, 0.5 ms: G(z) = 0.3403·z⁻¹(1 + z⁻¹)² /
    // (1 + 0.33626 z⁻¹ + 0.026815 z⁻² − 0.0018674 z⁻³).
    let d = ButterworthDesign::new(3, 1000.0, 0.0005).unwrap();
    let a = d.denominator();
    assert!((d.gain - 0.3403).abs() < 0.5e-4, "gain {}", d.gain);
    // f64 design: the printed digits are the rounding of these.
    assert!((a[1] - 0.33626).abs() < 0.5e-5, "a1 {}", a[1]);
    assert!((a[2] - 0.026815).abs() < 0.5e-6, "a2 {}", a[2]);
    assert!((a[3] + 0.0018674).abs() < 0.5e-7, "a3 {}", a[3]);
    let b = d.numerator();
    assert_eq!(b[0], 0.0);
    assert!((b[1] - d.gain).abs() < 1e-7 && (b[2] - 2.0 * d.gain).abs() < 1e-6 && (b[3] - d.gain).abs() < 1e-7);
}

#[test]
fn the_well_conditioned_values_equal_the_direct_form_ones_and_the_poles_are_stable() {
    // 1 + a1 + a2 and 1 − a2 as the design computes them (expm1, sin², no cancellation) against
    // the same sums of the f64 direct-form coefficients, where those still have digits to
    // spare (at 5 Hz and 0.25 ms, 1 + a1 + a2 ≈ 6·10⁻⁵: ~12 digits left of 16).
    for order in 1..=MAX_ORDER {
        for cutoff in [5.0, 100.0, 1000.0, 1900.0, 2000.0] {
            let d = ButterworthDesign::new(order, cutoff, 0.00025).unwrap();
            for p in d.pole_pairs() {
                let dc = 1.0 + p.a1 + p.a2;
                assert!((p.dc - dc).abs() < 1e-10 * dc, "order {order}, {cutoff} Hz: {p:?}");
                assert!((p.one_minus_a2 - (1.0 - p.a2)).abs() < 1e-10 * (1.0 - p.a2), "{p:?}");
                assert!(p.radius > 0.0 && p.radius < 1.0, "unstable pair {p:?}");
            }
            if let Some(r) = d.real_pole() {
                assert!((r.one_minus_pole - (1.0 - r.pole)).abs() < 1e-12 && r.pole < 1.0, "{r:?}");
            }
            // G(1) = 1 from the printed polynomials (whose sum cancels at low cut-offs: at
            // order 5 and 5 Hz, A(1) ≈ 10⁻¹⁵ from coefficients of ~10).
            if cutoff >= 100.0 {
                let dc = d.numerator().iter().sum::<f64>() / d.denominator().iter().sum::<f64>();
                assert!((dc - 1.0).abs() < 1e-6, "order {order}, {cutoff} Hz: G(1) = {dc}");
            }
        }
    }
}

#[test]
fn bad_designs_are_refused_with_the_reason() {
    assert_eq!(ButterworthDesign::new(0, 100.0, 0.001), Err(AccDecError::Order(0)));
    assert_eq!(ButterworthDesign::new(7, 100.0, 0.001), Err(AccDecError::Order(7)));
    match ButterworthDesign::new(3, 501.0, 0.001) {
        Err(AccDecError::CutoffAboveNyquist { cutoff_hz, nyquist_hz }) => {
            assert_eq!(cutoff_hz, 501.0);
            assert!((nyquist_hz - 500.0).abs() < 1e-3);
        }
        other => panic!("{other:?}"),
    }
    assert!(ButterworthDesign::new(3, 500.0, 0.001).is_ok(), "exactly at Nyquist is allowed");
    assert_eq!(
        ButterworthDesign::new(3, 0.4, 0.001),
        Err(AccDecError::CutoffBelowMinimum { cutoff_hz: 0.4, minimum_hz: 0.5 })
    );
    assert!(ButterworthDesign::new(6, 0.5, 0.000125).is_ok(), "the corner of the checked range");
    // At a 62.5 µs period the lowest cut-off is 6·10⁻⁵ / period = 0.96 Hz.
    assert!(matches!(
        ButterworthDesign::new(6, 0.9, 0.0000625),
        Err(AccDecError::CutoffBelowMinimum { minimum_hz, .. }) if (minimum_hz - 0.96).abs() < 1e-3
    ));
    assert!(matches!(ButterworthDesign::new(3, f32::NAN, 0.001), Err(AccDecError::Cutoff(_))));
    assert!(matches!(ButterworthDesign::new(3, -1.0, 0.001), Err(AccDecError::Cutoff(_))));
    assert!(matches!(ButterworthDesign::new(3, 10.0, 0.0), Err(AccDecError::SamplePeriod(_))));
    assert_eq!(MovingAverageCascade::new(&[]).unwrap_err(), AccDecError::Stages(0));
    assert_eq!(MovingAverageCascade::new(&[4, 4, 4, 4]).unwrap_err(), AccDecError::Stages(4));
    assert_eq!(MovingAverageCascade::new(&[4, 0]).unwrap_err(), AccDecError::Length { stage: 2, length: 0 });
    assert_eq!(
        MovingAverageCascade::new(&[MAX_MOVING_AVERAGE_LENGTH + 1]).unwrap_err(),
        AccDecError::Length { stage: 1, length: MAX_MOVING_AVERAGE_LENGTH + 1 }
    );
}

#[test]
fn zero_input_gives_zero_output() {
    for order in 1..=MAX_ORDER {
        let mut f = ButterworthPulseFilter::new(ButterworthDesign::new(order, 300.0, 0.0005).unwrap());
        assert!((0..1000).all(|_| f.step(0) == 0));
    }
    let mut m = MovingAverageCascade::new(&[7, 5, 3]).unwrap();
    assert!((0..1000).all(|_| m.step(0) == 0));
}

#[test]
fn no_pulse_is_lost_or_created_over_ten_thousand_random_sequences() {
    let mut rng = Random(0x5EED_0003);
    for case in 0..10_000 {
        let period = 0.00025;
        let order = 1 + rng.below(MAX_ORDER as u64) as u32;
        // Cut-off from 1 % to 99 % of Nyquist.
        let cutoff = (0.01 + 0.98 * rng.unit()) * 0.5 / period;
        let mut bw = ButterworthPulseFilter::new(ButterworthDesign::new(order, cutoff, period).unwrap());
        let lengths: [u32; 3] = core::array::from_fn(|_| 1 + rng.below(40) as u32);
        let stages = 1 + rng.below(3) as usize;
        let mut ma = MovingAverageCascade::new(&lengths[..stages]).unwrap();
        let (mut sum_in, mut sum_bw, mut sum_ma) = (0i64, 0i64, 0i64);
        let n = 1 + rng.below(200);
        for _ in 0..n {
            let x = rng.pulses();
            sum_in += x;
            sum_bw += bw.step(x);
            sum_ma += ma.step(x);
            // Exact bookkeeping at every tick.
            assert_eq!(sum_bw + bw.stock(), sum_in, "case {case}");
        }
        // Settle: the slowest filter here has a time constant of ~30 samples.
        for _ in 0..3000 {
            sum_bw += bw.step(0);
            sum_ma += ma.step(0);
        }
        assert_eq!(bw.stock(), 0, "case {case}: order {order}, {cutoff} Hz did not settle");
        assert_eq!(sum_bw, sum_in, "case {case}: Butterworth order {order}, {cutoff} Hz");
        assert_eq!(sum_ma, sum_in, "case {case}: moving averages {:?}", &lengths[..stages]);
    }
}

#[test]
fn whole_pulse_output_follows_the_direct_form_transfer_function() {
    // The drive's filter against an f64 direct-form simulation of G(z) built from the printed
    // polynomials (accurate at this cut-off): cumulative pulses within half a pulse, for both
    // placements of the zeros at infinity.
    for (order, zeros) in (1..=MAX_ORDER).flat_map(|n| [(n, ZeroPlacement::Seed), (n, ZeroPlacement::AllDelays)]) {
        let d = ButterworthDesign::with_zeros(order, 700.0, 0.0005, zeros).unwrap();
        let b_sum: f64 = d.numerator().iter().sum();
        let a_sum: f64 = d.denominator().iter().sum();
        assert!((b_sum - a_sum).abs() < 1e-12, "G(1) = 1: {b_sum} vs {a_sum}");
        let first_nonzero = d.numerator().iter().position(|&c| c != 0.0).unwrap();
        let delay = if zeros == ZeroPlacement::Seed { 1 } else { order as usize };
        assert_eq!(first_nonzero, delay, "dead time of {zeros:?}");
        let (a, b) = (d.denominator(), d.numerator());
        let mut f = ButterworthPulseFilter::new(d);
        let (mut xs, mut ys) = ([0.0f64; 7], [0.0f64; 7]);
        let (mut cum_ref, mut cum_out) = (0.0f64, 0i64);
        for k in 0..200 {
            let x = if k < 30 { 100 } else { 0 };
            xs.rotate_right(1);
            ys.rotate_right(1);
            xs[0] = x as f64;
            let y = (0..7).map(|i| b[i] * xs[i]).sum::<f64>() - (1..7).map(|i| a[i] * ys[i]).sum::<f64>();
            ys[0] = y;
            cum_ref += y;
            cum_out += f.step(x);
            assert!(
                (cum_out as f64 - cum_ref).abs() <= 0.5 + 1e-6,
                "order {order} {zeros:?}, k {k}: {cum_out} vs {cum_ref}"
            );
        }
        assert_eq!(cum_out, 3000);
    }
}

#[test]
fn one_moving_average_ramps_linearly() {
    // 100 pulses per tick through a 4-sample average: 25, 50, 75, 100, …, then down.
    let mut m = MovingAverageCascade::new(&[4]).unwrap();
    let out: [i64; 10] = core::array::from_fn(|k| m.step(if k < 6 { 100 } else { 0 }));
    assert_eq!(out, [25, 50, 75, 100, 100, 100, 75, 50, 25, 0]);
}

#[test]
fn reset_gives_back_a_fresh_filter() {
    let mut rng = Random(99);
    for kind in [AccDecKind::MovingAverage, AccDecKind::Butterworth] {
        let params = AccDecParams { kind, ma_lengths: [5, 9, 3], ..Default::default() };
        let fresh = AccDecFilter::new(&params, 0.00025).unwrap();
        let mut f = fresh;
        for _ in 0..50 {
            f.step(rng.pulses());
        }
        assert_ne!(f, fresh);
        f.reset();
        assert_eq!(f, fresh, "{kind:?}");
    }
}

mod against_the_f64_reference;

/// `check` (what `Params::validate` runs) refuses exactly what `new` refuses, with the same
/// error, over random settings around every bound: stages 0 to 4, lengths 0 to 513, orders
/// 0 to 7, cut-offs from zero and negative to beyond Nyquist, NaN and infinities, three kinds.
#[test]
fn check_refuses_exactly_what_new_refuses() {
    let mut r = Random(0x9E37_79B9_7F4A_7C15);
    let periods = [0.00025f32, 0.001, 0.000_062_5];
    let cutoffs = [0.0f32, -1.0, f32::NAN, f32::INFINITY, 0.001, 0.05, 1.0, 40.0, 1999.0, 2000.0, 2001.0, 8000.0, 1e6];
    let (mut refused, mut accepted) = (0, 0);
    for _ in 0..20_000 {
        let p = AccDecParams {
            kind: [AccDecKind::None, AccDecKind::MovingAverage, AccDecKind::Butterworth][r.below(3) as usize],
            order: r.below(8) as u32,
            cutoff_hz: if r.below(2) == 0 {
                cutoffs[r.below(cutoffs.len() as u64) as usize]
            } else {
                r.unit() * 3000.0
            },
            ma_stages: r.below(5) as u32,
            ma_lengths: core::array::from_fn(|_| {
                if r.below(4) == 0 {
                    [0, 512, 513][r.below(3) as usize]
                } else {
                    r.below(600) as u32
                }
            }),
        };
        let period = periods[r.below(3) as usize];
        let built = AccDecFilter::new(&p, period).map(|_| ());
        let checked = AccDecFilter::check(&p, period);
        // The same error, a NaN cut-off by its bits (NaN != NaN).
        let same = match (checked, built) {
            (Err(AccDecError::Cutoff(a)), Err(AccDecError::Cutoff(b))) => a.to_bits() == b.to_bits(),
            _ => checked == built,
        };
        assert!(same, "{p:?} at {period} s: check {checked:?}, new {built:?}");
        if built.is_err() {
            refused += 1;
        } else {
            accepted += 1;
        }
    }
    // Both outcomes well represented.
    assert!(refused > 2_000 && accepted > 2_000, "refused {refused}, accepted {accepted}");
}
