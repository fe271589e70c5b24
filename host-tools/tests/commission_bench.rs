//! `servo bench commission` on a small draw of motors the bench does not ship (its own seed):
//! one row per motor, each refusal named, and on every motor it commissions every figure
//! checked row by row against the plant's truth the bench drew, at its goal (the bench's
//! misses over seeds 1–7 and 2026, 100 motors each, are two refusals and one ramp's peak of
//! 1.18 times the test current on seed 2's motor 89; none is in this draw, and the misses over
//! seeds 1–30 are listed on the book's commissioning page). Each commissioned motor is then
//! run by the drive (torque reversals) without a fault and within 1.1 times the test current.

#[allow(dead_code)] // the helpers other tests use
mod common;

use common::{servo, tmp};

const MOTORS: usize = 16;

#[test]
fn a_small_draw_commissions_within_the_figures_row_by_row_and_names_each_refusal() {
    let out = tmp("commission-bench");
    let o = servo()
        .args(["bench", "commission", "--motors", &MOTORS.to_string(), "--seed", "2026", "--json", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    assert!(matches!(o.status.code(), Some(0 | 1)), "{stderr}");
    let j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let rows = j["rows"].as_array().unwrap();
    assert_eq!(rows.len(), MOTORS);
    let f = |r: &serde_json::Value, k: &str| r[k].as_f64().unwrap_or(f64::NAN);
    let mut refused = 0;
    for (k, r) in rows.iter().enumerate() {
        if let Some(why) = r["failed"].as_str() {
            // Named: a fault the drive reports, not an empty or generic string.
            assert!(why.len() > 3 && !why.contains("unknown"), "motor {k}: {why}");
            refused += 1;
            continue;
        }
        let e: Vec<f64> = r["errors"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let at = format!("motor {k}: {r}");
        assert_eq!(r["found_right"], true, "direction or pole pairs wrong, {at}");
        assert!(f(r, "offset_deg") <= 1.0, "offset, {at}");
        assert!(e[0] <= 0.03 && e[1] <= 0.03 && e[3] <= 0.03, "R, Ld or flux linkage beyond 3 %, {at}");
        assert!(e[2] <= 0.03, "Lq beyond 3 %, {at}");
        assert!(f(r, "bandwidth_error") <= 0.10 && f(r, "overshoot") <= 0.10, "current loop, {at}");
        assert!(f(r, "seconds") <= 5.0, "drive time, {at}");
        assert!(f(r, "turns") <= 2.0, "travel, {at}");
        assert!(f(r, "current_ratio") <= 1.1, "peak current, {at}");
        // The drive then runs the motor on what it found: torque reversals on the free rotor
        // without a fault and within the commissioning's current (the draw's first motors
        // include coarse encoders under strong magnets, where the back-EMF feed-forward's
        // steps drove 1.16 times the test current with the feed-forward left on).
        assert!(r["run_fault"].is_null(), "the drive faulted running the motor, {at}");
        assert!(f(r, "run_current_ratio") <= 1.1, "the run's peak current, {at}");
    }
    assert_eq!(refused, 0, "{refused} of {MOTORS} motors refused");
    // The exit status says whether every figure met its goal, as the figures do.
    // (A figure printed for information has no goal: `met` null.)
    let all_met = j["figures"]["figures"].as_array().unwrap().iter().all(|g| g["met"] != false);
    assert_eq!(o.status.code(), Some(if all_met { 0 } else { 1 }), "{stderr}");
    // The figures are also written for the book's figures page.
    assert!(out.join("commission.json").exists());
}

/// Motors of the bench's draws on slow windings (7–68 ticks) under light rotors (mechanical
/// time constants of 10–27 µs) on strong magnets: the q chips' torque turns the rotor, which
/// sticks and slips on its friction at each reversal. With chips peaking at half the test
/// current these read their q inductance 3.1–3.7 % off; with chips at 0.65 of it, within 3 %,
/// each commissioning's phase current within 1.1 times the test current.
#[test]
fn light_rotors_on_strong_magnets_with_friction_give_their_q_inductance_within_3_percent() {
    for (seed, motor) in [(14, 55), (23, 56), (26, 59)] {
        let r = &commissioned_row(seed, motor);
        let lq_error = r["errors"][2].as_f64().unwrap();
        assert!(lq_error <= 0.03, "seed {seed} motor {motor}: Lq {:.2} % off ({r})", 100.0 * lq_error);
        assert!(r["current_ratio"].as_f64().unwrap() <= 1.1, "seed {seed} motor {motor}: peak current ({r})");
    }
}

/// Motors of the bench's draws whose rotors (light, on strong magnets, 10–50 µs) start ahead
/// of the ramp's turning vector by more than a quarter turn and chase it on the unstable side:
/// a vector that started from rest led them until both stopped near the antipode, and they
/// fell at half the test current or more, at 1.20–1.54 times the test current. The vector
/// turns fastest at the start, where the current is least, and passes them while it is small:
/// within 1.1 times the test current.
#[test]
fn rotors_that_chase_the_ramps_vector_fall_back_to_it_within_the_current() {
    for (seed, motor) in [(8, 1), (10, 13), (24, 6), (27, 32)] {
        let r = &commissioned_row(seed, motor);
        let peak = r["current_ratio"].as_f64().unwrap();
        assert!(peak <= 1.1, "seed {seed} motor {motor}: peak current {peak:.3} x ({r})");
    }
}

/// A heavy rotor on a weak magnet (seed 36's motor 36: 2 pole pairs, 8.6 mWb, 1.6·10⁻⁴
/// kg·m² with its load) on a winding faster than a tick (0.57 Ω, 24 µH): it still swings
/// on the vector while the holds average, and its back-EMF read as dead time half as large
/// again as the inverter's, which the q fits then took off their chips (Lq 3.8 % high). With
/// the holds read again without the swing once the alignment knows the rotor's angle, within
/// 3 %.
#[test]
fn a_heavy_rotor_swinging_through_the_holds_gives_its_q_inductance_within_3_percent() {
    let r = &commissioned_row(36, 36);
    let errors: Vec<f64> = r["errors"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!(errors.iter().all(|e| *e <= 0.03), "R, Ld, Lq, flux {errors:?} ({r})");
}

/// Seed 14's motor 54: 12 pole pairs on a 1 024-count encoder (a count is 4.2° electrical),
/// friction 0.65 % of the test current's torque. The d chips and the current step run on the
/// rotor's frame from the encoder; on a count's end, that frame sat up to a count behind the
/// rotor, its d current pulled the rotor over the end, the frame stepped a count on, and the
/// rotor ran 30 electrical turns as a stepper motor does. On the count's middle, it stays
/// within two.
#[test]
fn a_frame_on_a_coarse_encoder_does_not_step_a_many_pole_rotor_round() {
    let r = &commissioned_row(14, 54);
    let turns = r["turns"].as_f64().unwrap();
    assert!(turns <= 2.0, "{turns} electrical turns ({r})");
}

/// Heavy rotors on weak magnets with little friction (seed 23's motor 65: 4 pole pairs,
/// 2.3 mWb, 0.8 % friction; seed 31's motor 32: 2 pole pairs, 3.1 mWb, 0.6 %; seed 23's motor
/// 82: 3 pole pairs, 2.6 mWb on 8.1 Ω), whose windings damp their swing on the vector far under
/// critical: released after the first hold's first part, the first two swung on through the
/// holds and the passes, and the passes' counts per electrical turn were refused (1 228 and 438
/// counts). Damped until still where the swing turns back under the damping, and more strongly
/// once it has, the third still swung through the passes at 0.3 % of critical (flux linkage
/// 42 % low, 5.85 s) and the first two took 5.1–5.2 s. With the held current weakened from
/// each turning point to the swing's centre: every value within its goal, within 5 s.
#[test]
fn heavy_rotors_on_weak_magnets_with_little_friction_are_found() {
    for (seed, motor) in [(23, 65), (31, 32), (23, 82)] {
        let r = &commissioned_row(seed, motor);
        let errors: Vec<f64> = r["errors"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
        let at = format!("seed {seed} motor {motor}");
        assert!(errors.iter().all(|e| *e <= 0.03), "{at}: R, Ld, Lq, flux {errors:?} ({r})");
        assert!(r["offset_deg"].as_f64().unwrap() <= 1.0, "{at}: offset ({r})");
        assert!(r["found_right"] == true, "{at}: direction or pole pairs ({r})");
        assert!(r["seconds"].as_f64().unwrap() <= 5.0, "{at}: drive time ({r})");
    }
}

/// Light rotors on strong magnets on windings faster than a tick (seed 36's motor 46: 11 pole
/// pairs, 34 mWb, a rotor of 15 µs on a 0.7-tick winding, friction 0.65 % of the test
/// current's torque; seed 4's motor 85: 7 pole pairs, 89 mWb, 36 µs, 0.4 tick, 1.8 %): under
/// zero-mean q chips the rotor sticks and slips on its friction at each reversal, and the
/// second differences' fit, whose resistance agrees with the holds', read Lq 8.0 % and 6.6 %
/// low (without friction, within 1 %). The free rotor's fit read 31 % and 15 % under it: run
/// again with the rotor turned through the chips (its friction a constant torque), within 3 %.
#[test]
fn light_rotors_whose_q_fits_disagree_are_turned_through_the_chips() {
    for (seed, motor) in [(36, 46), (4, 85)] {
        let r = &commissioned_row(seed, motor);
        let lq_error = r["errors"][2].as_f64().unwrap();
        assert!(lq_error <= 0.03, "seed {seed} motor {motor}: Lq {:.2} % off ({r})", 100.0 * lq_error);
        assert!(r["seconds"].as_f64().unwrap() <= 5.0, "seed {seed} motor {motor}: drive time ({r})");
    }
}

/// One motor of the bench's draw (`--seed`, `--motor`) commissioned: its row, which must not
/// be a refusal.
fn commissioned_row(seed: u64, motor: usize) -> serde_json::Value {
    let o = servo()
        .args(["bench", "commission", "--seed", &seed.to_string(), "--motor", &motor.to_string(), "--json"])
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&o.stderr);
    let mut j: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_else(|e| panic!("{e}: {stderr}"));
    let r = j["rows"][0].take();
    assert!(r["failed"].is_null(), "seed {seed} motor {motor}: {r}");
    r
}
