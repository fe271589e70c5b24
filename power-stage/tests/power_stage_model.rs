//! The power stage as the firmware sets it up, through the models: TIM1's output stage
//! (RM0440), the L6398's truth table and dead time, the shunt amplifiers and the ADC's
//! sampling instants.

mod common;

use common::*;
use control_core::reference_frames::{voltage_circle_radius, Dq};
use power_stage::bridge::BridgeModel;
use power_stage::config::IHM08M1;
use power_stage::fail_safe::{bridge_after, BridgeAfter, LossOfControl, FAIL_SAFE};
use power_stage::gate_driver::{GateDriver, DEAD_TIME_NS};
use power_stage::ratings::SCALES;
use power_stage::sampling::{SampleValidity, AMPLIFIER_SETTLING_NS};
use power_stage::shunt_selection::{largest_read_duty, phase_currents, phase_not_read, SECOND_DUTY_AT_LINEAR_LIMIT};
use power_stage::tim1_words::tim1_words;
use power_stage::Pin;

fn words() -> power_stage::tim1_words::Tim1Words {
    tim1_words(&IHM08M1)
}

/// Clocks per PWM period.
const PERIOD: u32 = 2 * tim1_words(&IHM08M1).arr;

/// The gap at each edge: the longer of the timer's and the driver's dead times.
fn expected_gap() -> u32 {
    IHM08M1.ticks(IHM08M1.timer_dead_time_ns).max(IHM08M1.ticks(DEAD_TIME_NS))
}

#[test]
fn the_two_fets_of_a_leg_are_never_on_together() {
    // Duties from 0 to 1 including the extremes and pulses shorter than the dead times,
    // switched on and off and broken in the middle of periods.
    let arr = words().arr as f32;
    let duties = [0.0, 1.0 / arr, 10.0 / arr, 60.0 / arr, 0.25, 0.5, 0.97, 1.0 - 30.0 / arr, 1.0];
    for (n, &d) in duties.iter().enumerate() {
        let set = [d, duties[(n + 3) % duties.len()], duties[(n + 6) % duties.len()]];
        let mut m = bridge_on(words(), set);
        let mut both = 0;
        for k in 0..6 * PERIOD {
            if k % 3_001 == 0 {
                let on = !m.moe();
                m.set_moe(on);
            }
            if k == 4 * PERIOD + 777 {
                m.trip_break();
            }
            let t = m.step();
            both += t.gates.iter().filter(|g| g.high && g.low).count();
        }
        assert_eq!(both, 0, "duties {set:?}");
    }
}

#[test]
fn with_moe_0_after_a_break_and_at_reset_every_fet_is_off() {
    // After set-up (MOE = 0), with duties already written.
    let mut m = BridgeModel::new(words(), CLOCK);
    m.set_duties([0.3, 0.5, 0.7]);
    assert!(all_off_for(&mut m, 3 * PERIOD), "MOE = 0 after set-up");
    // The pins are driven, not left to the driver's pulls: HIN low, LIN high.
    let t = m.step();
    assert!(t.pins.iter().all(|&p| p == (Pin::Low, Pin::High)), "{:?}", t.pins);
    // Switching, then a break in the middle of a period: off within the clock.
    m.set_moe(true);
    let mut switched = false;
    run(&mut m, 2 * PERIOD + 1234, |t| switched |= t.gates.iter().any(|g| g.high));
    assert!(switched);
    m.trip_break();
    assert!(all_off_for(&mut m, 3 * PERIOD), "after a break");
    // At reset the pins are not driven (GPIO analog, timer off): the L6398's pull-down on HIN
    // and pull-up on LIN hold both gates off.
    let mut d = GateDriver::new(IHM08M1.ticks(DEAD_TIME_NS));
    assert!((0..100).all(|_| d.step(Pin::Floating, Pin::Floating) == Default::default()));
}

#[test]
fn with_the_bridge_on_each_leg_follows_its_duty_with_dead_time() {
    for duties in [[0.5, 0.25, 0.75], [0.1, 0.9, 0.5], [0.933, 0.067, 0.5]] {
        let mut m = bridge_on(words(), duties);
        let s = summarise(&mut m, 4);
        follows_duties(&s, &m, expected_gap()).unwrap_or_else(|e| panic!("{duties:?}: {e}"));
        assert_eq!(s.triggers, 4, "one ADC trigger per period");
    }
    // The gap is the driver's 320 ns (54 clocks), not the sum with the timer's 100 ns.
    assert_eq!(expected_gap(), 54);
}

#[test]
fn a_positive_q_voltage_gives_a_positive_measured_q_current() {
    let (bus, ohms) = (24.0, 0.5);
    let sensing = calibrated(SCALES);
    for step in 0..12 {
        let theta = step as f32 * core::f32::consts::FRAC_PI_6 + 0.1;
        let duties = duties_for(Dq { d: 0.0, q: 2.0 }, theta, bus);
        let mut m = bridge_on(words(), duties);
        let true_currents = steady_currents(&mut m, bus, ohms);
        let counts = sampled_counts(&mut m, true_currents);
        let (shunts, _) = sensing.convert(counts, 2000).unwrap();
        let [ia, ib] = phase_currents(shunts, duties);
        let measured = dq_of(ia, ib, theta);
        let truth = dq_of(true_currents[0], true_currents[1], theta);
        // 2 V over 0.5 Ω is 4 A; the dead time takes a little of the voltage.
        assert!(truth.q > 3.0 && truth.q < 4.1, "θ {theta}: true q current {}", truth.q);
        assert!(measured.q > 0.0, "θ {theta}: measured q current {} for a positive q voltage", measured.q);
        assert!(
            (measured.q - truth.q).abs() < 0.05 && (measured.d - truth.d).abs() < 0.05,
            "θ {theta}: {measured:?} vs {truth:?}"
        );
    }
}

#[test]
fn at_full_modulation_the_two_phases_read_are_always_sampled_inside_their_low_side_window() {
    let bus = 24.0;
    let radius = voltage_circle_radius(bus) * 0.9999;
    let settle = IHM08M1.ticks(AMPLIFIER_SETTLING_NS);
    let mut worst = 0.0f32;
    for step in 0..120 {
        let theta = step as f32 * core::f32::consts::TAU / 120.0;
        let duties = duties_for(Dq { d: 0.0, q: radius }, theta, bus);
        worst = worst.max(largest_read_duty(duties));
        let mut m = bridge_on(words(), duties);
        let mut v = SampleValidity::new(settle);
        let mut verdicts = Vec::new();
        run(&mut m, 3 * PERIOD, |t| verdicts.extend(v.step(t.trigger, t.gates)));
        let skip = phase_not_read(duties);
        for verdict in &verdicts[1..] {
            for k in (0..3).filter(|&k| k != skip) {
                assert!(verdict[k], "θ {theta}: phase {k} read outside its window, duties {duties:?}");
            }
        }
    }
    assert!(worst <= SECOND_DUTY_AT_LINEAR_LIMIT + 1e-4, "second-largest duty {worst}");
    assert!(worst > SECOND_DUTY_AT_LINEAR_LIMIT - 1e-3, "the sweep reached the vertices: {worst}");
}

#[test]
fn every_loss_of_control_takes_the_gates_off() {
    for event in
        [LossOfControl::PanicOrFault, LossOfControl::DebuggerHalt, LossOfControl::Lockup, LossOfControl::StalledLoop]
    {
        let mut m = bridge_on(words(), [0.2, 0.5, 0.8]);
        run(&mut m, 1000, |_| {});
        match bridge_after(&FAIL_SAFE, event) {
            BridgeAfter::MoeCleared => {
                m.trip_break();
                assert!(all_off_for(&mut m, 2 * PERIOD), "{event:?}");
            }
            BridgeAfter::ChipReset => {
                // Pins no longer driven: both drivers' inputs float.
                let mut d = GateDriver::new(IHM08M1.ticks(DEAD_TIME_NS));
                assert_eq!(d.step(Pin::Floating, Pin::Floating), Default::default(), "{event:?}");
            }
            BridgeAfter::KeepsSwitching => panic!("{event:?} leaves the bridge switching"),
        }
    }
}
