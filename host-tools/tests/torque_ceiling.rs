//! The torque ceiling (`control_core::torque_ceiling`) against each hand-written rule it
//! replaced, over a grid of drives (torque limit, current limit, torque constant), dithers,
//! injection points and excitations: the same answer wherever the old rule was right, and a
//! different one only where it named the wrong clamp. Then the two fixes that need the FMU:
//! ident's M-sequence cut by a current limit below the torque limit, and tune's multisine cut
//! by a torque limit below the current limit's torque — both measured through the clamp and
//! accepted before.

use std::collections::BTreeMap;

use control_core::excitation::InjectionPoint;
use control_core::phase_shifted_sweep::{SweepError, SweepParams};
use control_core::torque_ceiling::{ExcitationEntry, TorqueCeiling, TorqueClamp};
use control_core::Params;
use host_tools::fmu::axis_health::{current_near_ceiling, torque_ceiling};
use host_tools::fmu::runner::Fmu;
use host_tools::fmu::scenario::Value;
use host_tools::fmu::trace::Trace;
use host_tools::sweep::torque_limit::TorqueLimits;

const POINTS: [InjectionPoint; 4] = [
    InjectionPoint::TorqueCommand,
    InjectionPoint::VelocityCommand,
    InjectionPoint::VelocityFeedback,
    InjectionPoint::PositionCommand,
];

/// Every drive of the grid: torque limits and current limits on both sides of each other,
/// two torque constants, and for each torque limit one drive whose current limit's torque
/// equals it (the current limit computed from it in f32: the default axis's 2 N·m and 20 A
/// give kt·max_current = 2.0000002, not 2).
fn drives() -> Vec<Params> {
    let mut all = Vec::new();
    for torque_limit in [0.05, 0.4, 1.0, 2.0, 3.0, 12.0] {
        let mut p = Params::default();
        p.velocity.torque_limit = torque_limit;
        // The largest current whose torque does not exceed the limit, and the next one up:
        // one of the two ties in f32 or the grid says so below.
        let kt = p.motor.torque_constant();
        p.current.max_current = torque_limit / kt;
        for _ in 0..4 {
            if kt * p.current.max_current == torque_limit {
                break;
            }
            p.current.max_current = if kt * p.current.max_current < torque_limit {
                f32::from_bits(p.current.max_current.to_bits() + 1)
            } else {
                f32::from_bits(p.current.max_current.to_bits() - 1)
            };
        }
        assert_eq!(p.validate(), Ok(()));
        all.push(p);
    }
    for flux_linkage in [Params::default().motor.flux_linkage, 0.0123] {
        for torque_limit in [0.05, 0.4, 1.0, 2.0, 3.0, 12.0] {
            for max_current in [0.5, 4.0, 10.0, 20.0, 30.0, 100.0] {
                let mut p = Params::default();
                p.motor.flux_linkage = flux_linkage;
                (p.velocity.torque_limit, p.current.max_current) = (torque_limit, max_current);
                assert_eq!(p.validate(), Ok(()));
                all.push(p);
            }
        }
    }
    all
}

const DITHERS: [f32; 5] = [0.0, 0.003, 0.04, 0.7, 5.0];

fn current_torque(p: &Params) -> f32 {
    p.motor.torque_constant() * p.current.max_current
}

/// The sweep's start check, before: the dither refused beyond the torque limit, a
/// torque-command amplitude whose peak with the dither reaches kt·max_current.
fn sweep_start_before(p: &Params) -> Result<(), (&'static str, f32)> {
    if p.sweep.dither > p.velocity.torque_limit {
        return Err(("dither", p.velocity.torque_limit));
    }
    let peak = current_torque(p);
    if p.sweep.point == InjectionPoint::TorqueCommand && p.sweep.amplitude + p.sweep.dither >= peak {
        return Err(("amplitude", peak - p.sweep.dither));
    }
    Ok(())
}

#[test]
fn the_sweep_start_check_is_the_old_one_but_where_the_current_limit_cuts_the_dither() {
    let (mut compared, mut fixed) = (0, 0);
    for drive in drives() {
        let peak = current_torque(&drive);
        for point in POINTS {
            for dither in DITHERS {
                for share in [0.1, 0.5, 0.9, 0.999, 1.0, 1.001, 1.5] {
                    let mut p = drive;
                    let amplitude =
                        if point == InjectionPoint::TorqueCommand { share * (peak - dither) } else { share };
                    if amplitude <= 0.0 {
                        continue;
                    }
                    // Below the position loop's Nyquist frequency, for every point.
                    p.sweep = SweepParams { point, dither, amplitude, stop_hz: 500.0, extra_hz: 0.0, ..p.sweep };
                    let now = p.validate_sweep().map_err(|e| match e {
                        SweepError::Range { field, max, .. } => (field, max),
                        e => panic!("{e}"),
                    });
                    let before = sweep_start_before(&p);
                    compared += 1;
                    let dither_ceiling = drive.velocity.torque_limit.min(peak);
                    if dither > dither_ceiling {
                        // The dither is added after the loop's clamp: where the current clamp
                        // is the lower, it cuts the dither, and bounds it now.
                        assert_eq!(now, Err(("dither", dither_ceiling)), "{p:?}");
                        if dither > drive.velocity.torque_limit {
                            assert_eq!(before, Err(("dither", drive.velocity.torque_limit)), "{p:?}");
                        } else {
                            assert_ne!(before.map_err(|e| e.0), Err("dither"), "{p:?}");
                            fixed += 1;
                        }
                    } else {
                        assert_eq!(now, before, "{p:?}");
                    }
                }
            }
        }
    }
    assert!(fixed > 0 && compared > 10 * fixed, "{compared} compared, {fixed} fixed");
}

/// The sweep's trace rule, before (in f64 from the f32 settings).
fn trace_rule_before(p: &Params, s: &SweepParams, torque: f64) -> bool {
    const ROUNDING: f64 = 1e-5;
    let loop_limit = (s.point != InjectionPoint::TorqueCommand)
        .then_some((p.velocity.torque_limit as f64 - s.dither as f64) * (1.0 - ROUNDING));
    let current_limit = current_torque(p) as f64 * (1.0 - ROUNDING);
    let t = torque.abs();
    t >= current_limit || loop_limit.is_some_and(|l| t >= l)
}

#[test]
fn the_sweep_trace_rule_is_the_old_one() {
    let mut compared = 0;
    for p in drives() {
        for point in POINTS {
            for dither in DITHERS.into_iter().filter(|&d| d < p.velocity.torque_limit) {
                let s = SweepParams { point, dither, ..p.sweep };
                let limits = TorqueLimits::of(&p, &s);
                // Around both clamps as the torque command reads them, and far from them.
                let loop_clamp = p.velocity.torque_limit as f64 - dither as f64;
                let current = current_torque(&p) as f64;
                for clamp in [loop_clamp, current] {
                    for factor in [0.0, 0.5, 0.999, 0.99998, 0.999995, 1.0, 1.0001, 3.0] {
                        for torque in [factor * clamp, -factor * clamp] {
                            // The old rule subtracted the dither in f64, the ceiling in f32 (as
                            // the drive adds it): a part in 10⁷ apart, inside the 10⁻⁵ margin.
                            let sliver = (limits.lowest() - torque.abs()).abs() <= 1e-6 * clamp;
                            if !sliver {
                                assert_eq!(
                                    limits.reached(torque),
                                    trace_rule_before(&p, &s, torque),
                                    "{p:?} {s:?} {torque}"
                                );
                                compared += 1;
                            }
                        }
                    }
                }
                // The clamp it names is the one the old rule's lower limit came from.
                let expected = if point != InjectionPoint::TorqueCommand && loop_clamp < current {
                    TorqueClamp::TorqueLimit
                } else {
                    TorqueClamp::CurrentLimit
                };
                assert_eq!(limits.ceiling.clamp, expected, "{p:?} {s:?}");
            }
        }
    }
    assert!(compared > 10_000, "{compared}");
}

fn fmu_parameters(p: &Params) -> BTreeMap<String, Value> {
    [
        ("ctrl.torque_limit", p.velocity.torque_limit as f64),
        ("ctrl.max_current", p.current.max_current as f64),
        ("plant.flux_linkage", p.motor.flux_linkage as f64),
    ]
    .into_iter()
    .map(|(k, v)| (k.to_string(), Value::Float(v)))
    .collect()
}

/// The circle's ceiling, before: `min(torque_limit, kt·max_current)`, in f32.
#[test]
fn the_circle_ceiling_is_the_old_one() {
    for p in drives() {
        let before = p.velocity.torque_limit.min(current_torque(&p)) as f64;
        let parameters = fmu_parameters(&p);
        let control = host_tools::fmu::configuration::configuration(&parameters).unwrap().control;
        assert_eq!(
            (control.velocity.torque_limit, control.current.max_current),
            (p.velocity.torque_limit, p.current.max_current)
        );
        assert_eq!(control.motor.torque_constant(), p.motor.torque_constant(), "the FMU's ctrl kt is the plant's");
        let now = torque_ceiling(&parameters).unwrap();
        assert_eq!(now.torque as f64, before, "{p:?}");
        assert_eq!(now, TorqueCeiling::of(&p, ExcitationEntry::BeforeTheLoopClamp, 0.0));
    }
}

fn iq_trace(iq: f64) -> Trace {
    let mut t = Trace::new(vec!["iq".to_string()]);
    t.rows.push([0.0]);
    t.rows.push([-iq]);
    t
}

/// Tune's multisine (and the machine-end sweep's twin), before: refused at 0.9 of
/// `max_current` on the measured q current, whichever clamp binds. Now 0.9 of the ceiling's
/// current: the same where the current limit binds; where the torque limit binds, it refuses
/// from 0.9 of `torque_limit / kt` up as well (the current never nears `max_current` there).
#[test]
fn the_multisine_current_rule_is_the_old_one_where_the_current_limit_binds() {
    let (mut same, mut fixed) = (0, 0);
    for p in drives() {
        for (entry, dither) in [(ExcitationEntry::BeforeTheLoopClamp, 0.0), (ExcitationEntry::AfterTheLoopClamp, 0.003)]
        {
            let ceiling = TorqueCeiling::of(&p, entry, dither);
            let max_current = p.current.max_current as f64;
            let torque_limit_current = ((p.velocity.torque_limit - dither) / p.motor.torque_constant()) as f64;
            for share in [0.0, 0.3, 0.5, 0.85, 0.8999, 0.9, 0.95, 1.0, 1.2] {
                for iq in [share * max_current, share * torque_limit_current] {
                    let before = iq >= 0.9 * max_current;
                    let now = current_near_ceiling(&iq_trace(iq), &ceiling).unwrap().is_some();
                    if ceiling.clamp == TorqueClamp::CurrentLimit {
                        assert_eq!(now, before, "{p:?} {iq}");
                        same += 1;
                    } else {
                        // Every old refusal stands; the new ones lie between the two clamps.
                        assert!(now || !before, "{p:?} {iq}");
                        assert_eq!(now, iq >= 0.9 * torque_limit_current, "{p:?} {iq}");
                        fixed += (now && !before) as usize;
                    }
                }
            }
        }
    }
    assert!(same > 100 && fixed > 10, "{same} {fixed}");
}

/// Ident's M-sequence, before: refused when the mean electromagnetic torque reached 0.999 of
/// the torque limit. Now the sweep's rule at the torque-command point: the torque command at
/// the current limit's torque. The two agree where the clamps coincide (the default axis:
/// 2 N·m both), up to their margins; elsewhere the old rule watched the clamp that cannot cut
/// an injection added after it.
#[test]
fn the_prbs_rule_is_the_sweeps_at_the_torque_point_and_the_old_one_where_the_clamps_coincide() {
    let mut ties = 0;
    for p in drives() {
        let prbs = SweepParams { point: InjectionPoint::TorqueCommand, ..p.sweep };
        let limits = TorqueLimits::of(&p, &prbs);
        assert_eq!(limits.ceiling.clamp, TorqueClamp::CurrentLimit);
        assert_eq!(limits.ceiling.torque, current_torque(&p));
        let before = 0.999 * p.velocity.torque_limit as f64;
        if p.velocity.torque_limit == current_torque(&p) {
            ties += 1;
            assert!((limits.lowest() - before).abs() <= 1e-3 * before, "{p:?}");
            // In front of the loop without a dither both clamps cut at the same torque: the
            // current clamp is named.
            let ceiling = TorqueCeiling::of(&p, ExcitationEntry::BeforeTheLoopClamp, 0.0);
            assert_eq!((ceiling.clamp, ceiling.torque), (TorqueClamp::CurrentLimit, p.velocity.torque_limit));
        }
    }
    assert!(ties >= 4, "only {ties} drives whose clamps tie: the comparison above proves little");
}

fn fmu() -> Fmu {
    Fmu::load(&host_tools::paths::default_fmu()).expect("the FMU (cargo run -p xtask -- bundle)")
}

fn peak(trace: &Trace, name: &str) -> f64 {
    trace.column(name).unwrap().iter().fold(0.0f64, |m, x| m.max(x.abs()))
}

/// A current limit of 0.6 A (0.06 N·m) below the 2 N·m torque limit: a 0.05 N·m M-sequence
/// passes the start check (0.053 with the dither), but with the riding torque on top the
/// current clamp cuts it (and the velocity loop winds up to its own clamp behind it). The old
/// rule watched the electromagnetic torque against 0.999 of the 2 N·m torque limit: it stays
/// near 0.06 N·m, and the data were accepted; now they are refused, naming the clamp.
#[test]
fn an_m_sequence_cut_by_a_current_limit_below_the_torque_limit_is_refused_naming_it() {
    use host_tools::ident::identification::{absorber_parameters, excitation, excitation_within_ceiling, measure};
    let fmu = fmu();
    let mut p = absorber_parameters(40.0, 0.05, 1.0e-4);
    p.insert("plant.motor_coulomb".into(), Value::Float(0.01));
    p.insert("ctrl.max_current".into(), Value::Float(0.6));
    let run = excitation(&p, 0.05, 1.0);
    let trace = run.run(&fmu, |_| {}).unwrap();
    let drive = run.drive_params().unwrap();
    // A tenth of what the old rule watched for.
    assert!(peak(&trace, "electromagnetic_torque_mean") < 0.999 * drive.velocity.torque_limit as f64 / 10.0);
    let limits = TorqueLimits::of(&drive, &run.settings);
    let e = excitation_within_ceiling(&limits, &trace.column("torque_command_out").unwrap()).unwrap_err();
    assert!(format!("{e}").contains("current.max_current = 0.6 A"), "{e}");
    let e = format!("{:#}", measure(&fmu, &p, 0.05, 5.0, 500.0).unwrap_err());
    assert!(e.contains("saturated") && e.contains("current.max_current = 0.6 A"), "{e}");
    // With the default current limit the same excitation is measured.
    p.insert("ctrl.max_current".into(), Value::Float(20.0));
    measure(&fmu, &p, 0.05, 5.0, 500.0).unwrap();
}

/// A torque limit of 0.02 N·m (0.2 A) far below the current limit's 2 N·m: tune's multisine
/// is clamped by the velocity loop while the current stays near 0.2 A, far from the 18 A (0.9
/// of max_current) the old rule watched, which accepted it. Refused now, naming the torque
/// limit; the default axis is measured as before.
#[test]
fn a_multisine_cut_by_a_torque_limit_below_the_current_limit_is_refused_naming_it() {
    use host_tools::fmu::scenario::{Scenario, DEFAULT_STEP};
    use host_tools::ident::tuning::{command_to_load, multisine, MULTISINE_AMPLITUDE};
    let fmu = fmu();
    let frequencies: Vec<u32> = (1..=40).collect();
    let low = BTreeMap::from([("ctrl.torque_limit".to_string(), Value::Float(0.02))]);
    let second = (1.0 / DEFAULT_STEP).round() as usize;
    let command = multisine(&frequencies, MULTISINE_AMPLITUDE, second);
    let trace = fmu.run(&Scenario::streamed_position("multisine", &low, &command), |_| {}).unwrap();
    assert!(peak(&trace, "torque_command_out") >= 0.02f32 as f64, "the loop's clamp is reached");
    assert!(peak(&trace, "iq") < 0.9 * 20.0 / 10.0, "a tenth of the old rule's 18 A");
    let e = format!("{:#}", command_to_load(&fmu, &low, &frequencies).unwrap_err());
    assert!(e.contains("near the") && e.contains("velocity.torque_limit = 0.02 N·m"), "{e}");
    command_to_load(&fmu, &BTreeMap::new(), &frequencies).unwrap();
}

/// A drive's twin runs the drive's measured motor and current loop (`Fmu::as_twin_of`): its
/// torque limits are built from them (its torque constant, the current a torque takes), not
/// from the plant's constants the plan has. With the defaults the current limit's torque
/// (kt · 20 A) equals the 2 N·m torque limit: a flux linkage measured a little off moves
/// where the current limit lies against it.
#[test]
fn a_twins_torque_limits_come_from_the_drives_motor() {
    let fmu = fmu();
    let run = host_tools::fmu::sweep_run::SweepRun {
        settings: SweepParams::default(),
        parameters: BTreeMap::new(),
        velocity: 0.0,
    };
    let plan = run.drive_params().unwrap();
    assert_eq!(run.params_on(&fmu).unwrap(), plan);
    let mut drive = plan.commissioned_as(plan.encoder_mounting);
    drive.motor.flux_linkage *= 0.999;
    drive.motor.resistance *= 1.01;
    drive.current.kp = 2.25;
    drive.current.ki = 1370.0;
    {
        let twin = fmu.as_twin_of(&drive).unwrap();
        let on_twin = run.params_on(&twin).unwrap();
        assert_eq!(on_twin.motor, drive.motor);
        assert_eq!((on_twin.current.kp, on_twin.current.ki), (2.25, 1370.0));
        let (ours, plans) = (TorqueLimits::of(&on_twin, &run.settings), TorqueLimits::of(&plan, &run.settings));
        assert_eq!(ours.ceiling.kt, drive.motor.torque_constant(), "{ours:?}");
        assert_ne!(ours.ceiling.current, plans.ceiling.current, "{ours:?} vs {plans:?}");
    }
    // The guard dropped: the plan's own again.
    assert_eq!(run.params_on(&fmu).unwrap(), plan);
}
