//! Issue 20: the checks of `power_stage_model.rs` applied to the power stage as the firmware
//! set it up before the fix must fail, one fault at a time. The old words are written out by
//! hand from the old `board.rs` and embassy-stm32 0.6's `ComplementaryPwm::new` (PWM mode 1
//! with preload on every channel, centre-aligned, MOE set, no channel enabled), so these tests
//! do not depend on the new configuration code.

mod common;

use common::*;
use control_core::current_sensing::SensingScales;
use control_core::reference_frames::{voltage_circle_radius, Dq};
use control_core::Params;
use power_stage::bridge::BridgeModel;
use power_stage::config::IHM08M1;
use power_stage::current_amplifier::IHM08M1 as AMPLIFIER;
use power_stage::fail_safe::{bridge_after, BridgeAfter, FailSafeWords, LossOfControl};
use power_stage::gate_driver::DEAD_TIME_NS;
use power_stage::ratings::{
    limit_violations, OVERCURRENT_BEYOND_CONVERTER, OVERVOLTAGE_ABOVE_RATING, SCALES, UNDERVOLTAGE_REFUSES_RATED_RANGE,
};
use power_stage::sampling::{SampleValidity, AMPLIFIER_SETTLING_NS};
use power_stage::shunt_selection::phase_currents;
use power_stage::tim1_words::{cr2_oisn, tim1_words, Tim1Words};
use power_stage::Pin;

/// TIM1 before the fix, bridge off (MOE = 0 written by `set_master_output_enable(false)`).
fn old_words() -> Tim1Words {
    Tim1Words {
        cr1: 0x00E0,      // centre-aligned mode 3, ARR preloaded
        cr2: 0x0070_0000, // MMS2 = OC4REF; every OISx / OISxN 0
        ccmr1: 0x6868,    // PWM mode 1, preload, channels 1 and 2
        ccmr2: 0x7868,    // channel 3 PWM mode 1, channel 4 PWM mode 2
        ccer: 0x0000,     // no output enabled: `enable()` was never called
        // DTG = 85 (500 ns), BKE, break active low, BKF = 4; OSSI = OSSR = 0; MOE = 0.
        bdtr: 85 | 1 << 12 | 4 << 16,
        af1: 1,
        psc: 0,
        arr: 5312,
        rcr: 0,
        ccr4: 5311,
    }
}

/// The old words as if `enable()` had been called on the three channels: CCxE and CCxNE set,
/// both outputs active high.
fn old_words_enabled() -> Tim1Words {
    Tim1Words { ccer: 0x0555, ..old_words() }
}

const OLD_SCALES: SensingScales = SensingScales { amps_per_count: -SCALES.amps_per_count, ..SCALES };

fn gap() -> u32 {
    IHM08M1.ticks(DEAD_TIME_NS).max(17)
}

#[test]
fn the_outputs_were_never_enabled_so_the_bridge_never_switched() {
    let mut m = bridge_on(old_words(), [0.5, 0.25, 0.75]);
    let t = m.step();
    assert!(t.pins.iter().all(|&p| p == (Pin::Floating, Pin::Floating)), "MOE = 1, CCxE = CCxNE = 0: pins not driven");
    let s = summarise(&mut m, 4);
    assert!(follows_duties(&s, &m, gap()).is_err(), "the check must see it: {s:?}");
    assert_eq!((s.high_on, s.low_on), ([0; 3], [0; 3]), "no gate ever on");
}

#[test]
fn an_active_high_low_side_input_gave_only_dead_time_pulses_of_the_low_side() {
    let mut m = bridge_on(old_words_enabled(), [0.5, 0.25, 0.75]);
    let s = summarise(&mut m, 4);
    assert!(follows_duties(&s, &m, gap()).is_err());
    // HIN = 1 with LIN = 0 is refused by the interlock: the high side never conducts ...
    assert_eq!(s.high_on, [0; 3]);
    // ... and in the timer's 500 ns dead time (both outputs inactive: HIN = 0, LIN = 0) the
    // low side is on: two pulses of 85 clocks a period.
    for k in 0..3 {
        assert!(s.longest_low_pulse[k].abs_diff(85) <= 1, "{s:?}");
        assert!(s.low_on[k].abs_diff(2 * 85 * s.periods) <= 2 * s.periods, "{s:?}");
    }
}

#[test]
fn ossi_1_with_oisxn_0_would_turn_every_low_side_on_with_the_bridge_off() {
    let good = tim1_words(&IHM08M1);
    let bad = Tim1Words { cr2: good.cr2 & !(cr2_oisn(0) | cr2_oisn(1) | cr2_oisn(2)), ..good };
    let mut m = BridgeModel::new(bad, CLOCK);
    assert!(!all_off_for(&mut m, 100));
    let t = m.step();
    assert!(t.gates.iter().all(|g| g.low && !g.high), "{}", gates_string(t.gates));
}

#[test]
fn the_old_current_sign_measured_a_negative_q_current_for_a_positive_q_voltage() {
    let (bus, ohms) = (24.0, 0.5);
    let sensing = calibrated(OLD_SCALES);
    let theta = 0.7;
    let duties = duties_for(Dq { d: 0.0, q: 2.0 }, theta, bus);
    let mut m = bridge_on(tim1_words(&IHM08M1), duties);
    let currents = steady_currents(&mut m, bus, ohms);
    let (shunts, _) = sensing.convert(sampled_counts(&mut m, currents), 2000).unwrap();
    let [ia, ib] = phase_currents(shunts, duties);
    let measured = dq_of(ia, ib, theta);
    assert!(dq_of(currents[0], currents[1], theta).q > 3.0);
    assert!(measured.q < -3.0, "positive feedback: the loop would raise the voltage further ({measured:?})");
}

#[test]
fn fixed_u_and_v_sampling_misread_at_high_modulation() {
    let (bus, ohms) = (24.0, 2.0);
    let radius = voltage_circle_radius(bus) * 0.9999;
    let sensing = calibrated(SCALES);
    // The angle where phase U's duty reaches 1 (its low side never conducts).
    let theta = (0..360)
        .map(|k| k as f32 * core::f32::consts::TAU / 360.0)
        .max_by(|a, b| {
            let da = duties_for(Dq { d: 0.0, q: radius }, *a, bus)[0];
            let db = duties_for(Dq { d: 0.0, q: radius }, *b, bus)[0];
            da.total_cmp(&db)
        })
        .unwrap();
    let duties = duties_for(Dq { d: 0.0, q: radius }, theta, bus);
    assert!(duties[0] > 0.999, "{duties:?}");
    let mut m = bridge_on(tim1_words(&IHM08M1), duties);
    let currents = steady_currents(&mut m, bus, ohms);
    let counts = sampled_counts(&mut m, currents);
    let (shunts, _) = sensing.convert(counts, 2000).unwrap();
    // The old reading: U and V straight from their shunts.
    let old_error = (shunts[0] - currents[0]).abs().max((shunts[1] - currents[1]).abs());
    assert!(old_error > 1.0, "U's shunt carries nothing at the sampling instant: error {old_error} A");
    let [ia, ib] = phase_currents(shunts, duties);
    let new_error = (ia - currents[0]).abs().max((ib - currents[1]).abs());
    assert!(new_error < 0.05, "by sector: error {new_error} A");
    let mut v = SampleValidity::new(IHM08M1.ticks(AMPLIFIER_SETTLING_NS));
    let mut verdicts = Vec::new();
    run(&mut m, 2 * 2 * 5312, |t| verdicts.extend(v.step(t.trigger, t.gates)));
    assert!(!verdicts[0][0] && verdicts[0][1] && verdicts[0][2], "{verdicts:?}");
    assert!(AMPLIFIER.counts(0.0) == counts[0], "U read the bias: no current");
}

#[test]
fn nothing_took_the_gates_off_when_control_was_lost() {
    // panic-probe only faulted; no DBG_TIM1_STOP, no CLL, no watchdog.
    let old = FailSafeWords { dbgmcu_apb2fzr: 0, dbgmcu_apb1fzr1: 0, syscfg_cfgr2: 0, watchdog: None, handler_egr: 0 };
    for event in
        [LossOfControl::PanicOrFault, LossOfControl::DebuggerHalt, LossOfControl::Lockup, LossOfControl::StalledLoop]
    {
        assert_eq!(bridge_after(&old, event), BridgeAfter::KeepsSwitching, "{event:?}");
    }
    // And the last duties stay on the motor.
    let mut m = bridge_on(tim1_words(&IHM08M1), [0.2, 0.5, 0.8]);
    assert!(!all_off_for(&mut m, 2 * 2 * 5312));
}

#[test]
fn the_old_limits_belonged_to_another_board() {
    let v = limit_violations(&Params::default().limits, AMPLIFIER.range_amps());
    assert_eq!(v, OVERVOLTAGE_ABOVE_RATING | UNDERVOLTAGE_REFUSES_RATED_RANGE | OVERCURRENT_BEYOND_CONVERTER);
}
