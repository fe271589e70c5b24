//! Acc/dec filters (seed 003) against independent references: python-control's pole-zero
//! matched discretisation, and the FMU's filtered command against the core's command path
//! run on its own.

use control_core::acc_dec::{AccDecFilter, ButterworthDesign, ButterworthPulseFilter, ZeroPlacement};
use cross_checks::load_fmu;
use host_tools::accdec::bench::matched_comparison;
use host_tools::accdec::study::{profile, residual_vibration, FilterSpec, PulseMove, Resonance};

#[test]
fn poles_and_gains_match_python_control_for_both_zero_placements() {
    let rows = matched_comparison().unwrap();
    assert_eq!(rows.len(), 24, "orders 1-6 at four cut-offs");
    for r in &rows {
        // An f64 design on both sides; python-control's poles come from the roots of the
        // expanded polynomial, which for six poles clustered near z = 1 (40 Hz at 0.25 ms)
        // are good to ~10⁻⁸.
        assert!(r.pole_error < 1e-7, "{r:?}");
        assert!(r.all_delays_gain_error < 1e-10, "{r:?}");
        assert!(r.seed_gain_error < 1e-10, "{r:?}");
    }
}

#[test]
fn all_delays_filter_follows_python_controls_difference_equation() {
    // python-control's G(z) = K / A(z) as a difference equation in f64, against the drive's
    // whole-pulse filter with every zero at infinity kept as a delay: cumulative pulses within
    // half a pulse (plus the filter's lag error, far below 10⁻³ here), the same total at the end.
    let rows = matched_comparison().unwrap();
    for r in rows.iter().filter(|r| r.cutoff_hz == 300.0) {
        let den = ButterworthDesign::new(r.order, r.cutoff_hz, r.sample_period).unwrap().denominator();
        let n = r.order as usize;
        let d = ButterworthDesign::with_zeros(r.order, r.cutoff_hz, r.sample_period, ZeroPlacement::AllDelays).unwrap();
        let mut filter = ButterworthPulseFilter::new(d);
        let (mut xs, mut ys) = (vec![0.0f64; n + 1], vec![0.0f64; n + 1]);
        let (mut cum_ref, mut cum_out) = (0.0f64, 0i64);
        for k in 0..400 {
            let x = if k < 30 { 100 } else { 0 };
            xs.rotate_right(1);
            ys.rotate_right(1);
            xs[0] = x as f64;
            // y(k) = K·x(k − N) − Σ a_i y(k − i), with python-control's K.
            let y = r.python_gain * xs[n] - (1..=n).map(|i| den[i] * ys[i]).sum::<f64>();
            ys[0] = y;
            cum_ref += y;
            cum_out += filter.step(x);
            assert!((cum_out as f64 - cum_ref).abs() <= 0.5 + 1e-3, "order {n}, tick {k}: {cum_out} vs {cum_ref}");
        }
        assert_eq!(cum_out, 3000);
    }
}

#[test]
fn fmu_command_equals_the_core_command_path_count_for_count() {
    // The FMU's filtered command (rad) against the control core's command path run here on
    // the same move: every position tick, to the count.
    let fmu = load_fmu();
    let period = 0.00025f32;
    let cpr = servo_axis::plant::PlantParams::default().encoder_counts_per_rev;
    let (distance, speed) = (2.0, 50.0);
    let m = PulseMove {
        distance: (distance / std::f64::consts::TAU * cpr as f64).round() as i64,
        speed: speed as f32 * control_core::Params::default().counts_per_position_tick(),
    };
    for spec in [FilterSpec::butterworth(3, 40.0), FilterSpec::MovingAverage { lengths: vec![20, 21, 21] }] {
        let p = profile(&spec, period, m, 64).unwrap();
        let res = Resonance { hz: 60.0, damping_ratio: 0.02 };
        let (_, trace) = residual_vibration(&fmu, &spec, res, period as f64, distance, speed, (0.1, 0.2)).unwrap();
        let command = trace.column("position_command_out").unwrap();
        let mut position = 0i64;
        for (k, pulses) in p.output.iter().enumerate().take(command.len() - 1) {
            position += pulses;
            let fmu_counts = (command[k + 1] / std::f64::consts::TAU * cpr as f64).round() as i64;
            assert_eq!(fmu_counts, position, "{}: tick {k}", spec.label());
        }
        assert_eq!(position, m.distance, "{} ends on target", spec.label());
    }
}

#[test]
fn the_drive_filter_enum_and_the_study_build_the_same_filter() {
    // `servo accdec` builds its filters through FilterSpec; the drive through AccDecParams.
    let params = control_core::acc_dec::AccDecParams {
        kind: control_core::acc_dec::AccDecKind::Butterworth,
        order: 4,
        cutoff_hz: 120.0,
        ..Default::default()
    };
    let drive = AccDecFilter::new(&params, 0.00025).unwrap();
    let study = FilterSpec::butterworth(4, 120.0).build(0.00025).unwrap();
    assert_eq!(drive, study);
}
