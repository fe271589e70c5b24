//! The FMU's parameter values turned into the control core's `Params`, the plant's
//! parameters and the excitation: what `exitInitializationMode` builds the axis from.

use control_core::acc_dec::{AccDecKind, AccDecParams};
use control_core::excitation::InjectionPoint;
use control_core::friction_compensation::FrictionCompensationParams;
use control_core::params::{
    CurrentLoopGains, Limits, MotorModel, PositionLoopGains, Rates, TorqueFilters, VelocityLoopGains,
};
use control_core::phase_shifted_sweep::{SweepMeasure, SweepParams, SweepSignal};
use control_core::response_correction::{CorrectionParams, CorrectionSection, SecondOrder};
use control_core::stop_sequence::SequenceParams;
use control_core::Params;

use crate::plant::PlantParams;
use crate::simulation::{CommissioningConfig, ExcitationConfig, SimulationConfig};
use crate::variables::{name, Value, Values};
use control_core::commissioning::CommissioningSettings;

/// A count parameter (its declared range keeps it non-negative; checked again here).
fn count(name: &str, v: i32) -> Result<u32, String> {
    u32::try_from(v).map_err(|_| format!("{name} must not be negative (got {v})"))
}

/// A count the core keeps in 16 bits (the sweep's shifts and repeats, at most 16).
fn short_count(name: &str, v: i32) -> Result<u16, String> {
    u16::try_from(v).map_err(|_| format!("{name} must be 0 to 65535 (got {v})"))
}

/// The plant's true encoder mounting: the electrical angle at count 0 is `p · rotor_start_angle`.
fn plant_mounting(plant: &PlantParams) -> control_core::params::EncoderMounting {
    let tau = std::f64::consts::TAU;
    let offset = (plant.pole_pairs as f64 * plant.rotor_start_angle).rem_euclid(tau) as f32;
    control_core::params::EncoderMounting {
        reversed: plant.encoder_reversed,
        // Within [0, 2π) after the rounding to f32.
        electrical_offset: if offset >= std::f32::consts::TAU { 0.0 } else { offset },
    }
}

/// The motor the drive is given (`ctrl.motor_*`, each 0 = the plant's own): a commissioned
/// drive's measured set for its twin. A drive that applies what it measures at initialisation
/// is given none: both at once is refused.
fn drive_motor(v: &Values, plant_pole_pairs: u32) -> Result<MotorModel, String> {
    let given = [v.ctrl_motor_resistance, v.ctrl_motor_ld, v.ctrl_motor_lq, v.ctrl_motor_flux_linkage];
    if v.commissioning_at_start
        && v.commissioning_apply_motor
        && (v.ctrl_motor_pole_pairs != 0 || given.iter().any(|&x| x != 0.0))
    {
        return Err(
            "ctrl.motor_* give the drive a motor, while commissioning.at_start with commissioning.apply_motor \
                    runs it with the one it measures: set one or the other"
                .to_string(),
        );
    }
    let or_plant = |x: f64, plant: f64| if x == 0.0 { plant } else { x } as f32;
    Ok(MotorModel {
        pole_pairs: if v.ctrl_motor_pole_pairs == 0 {
            plant_pole_pairs
        } else {
            count("ctrl.motor_pole_pairs", v.ctrl_motor_pole_pairs)?
        },
        resistance: or_plant(v.ctrl_motor_resistance, v.plant_resistance),
        ld: or_plant(v.ctrl_motor_ld, v.plant_ld),
        lq: or_plant(v.ctrl_motor_lq, v.plant_lq),
        flux_linkage: or_plant(v.ctrl_motor_flux_linkage, v.plant_flux_linkage),
    })
}

/// The default axis with its drive given the plant's mounting and motor, commissioned (the
/// FMU with `commissioning.at_start` off): for runs about something else than commissioning.
pub fn default_config_given_mounting() -> Result<SimulationConfig, String> {
    simulation_config(&Values { commissioning_at_start: false, ..Values::start() })
}

/// The whole configuration of the simulated axis.
pub fn simulation_config(v: &Values) -> Result<SimulationConfig, String> {
    let pole_pairs = count("plant.pole_pairs", v.plant_pole_pairs)?;
    let counts = count("plant.encoder_counts_per_rev", v.plant_encoder_counts_per_rev)?;
    let motor = drive_motor(v, pole_pairs)?;
    let plant = PlantParams {
        pole_pairs,
        resistance: v.plant_resistance,
        ld: v.plant_ld,
        lq: v.plant_lq,
        flux_linkage: v.plant_flux_linkage,
        bus_voltage: v.plant_bus_voltage,
        motor_inertia: v.plant_motor_inertia,
        load_inertia: v.plant_load_inertia,
        shaft_stiffness: v.plant_shaft_stiffness,
        shaft_damping: v.plant_shaft_damping,
        motor_coulomb: v.plant_motor_coulomb,
        motor_viscous: v.plant_motor_viscous,
        load_coulomb: v.plant_load_coulomb,
        load_viscous: v.plant_load_viscous,
        absorber_inertia: v.plant_absorber_inertia,
        absorber_stiffness: v.plant_absorber_stiffness,
        absorber_damping: v.plant_absorber_damping,
        coulomb_velocity: v.plant_coulomb_velocity,
        encoder_counts_per_rev: counts,
        rotor_start_angle: v.plant_rotor_start_angle,
        encoder_reversed: v.plant_encoder_reversed,
        current_offset: [v.plant_current_offset_a, v.plant_current_offset_b],
        current_gain: [v.plant_current_gain_a, v.plant_current_gain_b],
        dead_time_voltage: v.plant_dead_time_voltage,
        current_noise_std: v.plant_current_noise_std,
        acceleration_noise_std: v.plant_acceleration_noise_std,
        noise_seed: v.plant_noise_seed as u32 as u64,
        tick: 1.0 / v.ctrl_current_loop_hz,
        substeps: count("plant.substeps", v.plant_substeps)?,
    };
    let point = InjectionPoint::from_code(v.excitation_point)
        .filter(|p| *p != InjectionPoint::VelocityFeedback)
        .ok_or_else(|| format!("excitation.point must be 0, 1 or 2 (got {})", v.excitation_point))?;
    let control = Params {
        motor,
        encoder_counts_per_rev: counts,
        // Measured at power-up (`commissioning`), or given: the plant's own.
        encoder_mounting: if v.commissioning_at_start {
            control_core::params::EncoderMounting::default()
        } else {
            plant_mounting(&plant)
        },
        commissioned: !v.commissioning_at_start,
        rates: Rates {
            current_loop_hz: v.ctrl_current_loop_hz as f32,
            velocity_divider: count("ctrl.velocity_divider", v.ctrl_velocity_divider)?,
            position_divider: count("ctrl.position_divider", v.ctrl_position_divider)?,
        },
        current: CurrentLoopGains {
            kp: v.ctrl_current_kp as f32,
            ki: v.ctrl_current_ki as f32,
            decoupling: v.ctrl_decoupling,
            angle_advance_ticks: v.ctrl_angle_advance_ticks as f32,
            max_current: v.ctrl_max_current as f32,
        },
        velocity: VelocityLoopGains {
            kp: v.ctrl_velocity_kp as f32,
            ki: v.ctrl_velocity_ki as f32,
            torque_limit: v.ctrl_torque_limit as f32,
        },
        position: PositionLoopGains {
            kp: v.ctrl_position_kp as f32,
            velocity_feedforward: v.ctrl_velocity_feedforward as f32,
            velocity_limit: v.ctrl_velocity_limit as f32,
        },
        filters: TorqueFilters {
            low_pass_hz: v.ctrl_low_pass_hz as f32,
            notch_hz: v.ctrl_notch_hz as f32,
            notch_q: v.ctrl_notch_q as f32,
            notch_depth: v.ctrl_notch_depth as f32,
            notch2_hz: v.ctrl_notch2_hz as f32,
            notch2_q: v.ctrl_notch2_q as f32,
            notch2_depth: v.ctrl_notch2_depth as f32,
        },
        limits: Limits {
            overcurrent: v.ctrl_overcurrent as f32,
            bus_undervoltage: v.ctrl_bus_undervoltage as f32,
            bus_overvoltage: v.ctrl_bus_overvoltage as f32,
            following_error: v.ctrl_following_error_limit as f32,
        },
        friction: FrictionCompensationParams {
            amplitude: v.ctrl_friction_comp_amplitude as f32,
            decay: v.ctrl_friction_comp_decay as f32,
        },
        acc_dec: acc_dec(v)?,
        sequence: sequence(v, counts)?,
        sweep: sweep(v)?,
        correction: correction(v)?,
        accelerometer: control_core::accelerometer::AccelerometerParams {
            sensitivity: v.accelerometer_sensitivity as f32,
        },
    };
    let auto = CommissioningSettings::for_encoder(counts, control.rates.tick_period()).current_bandwidth_hz;
    let bandwidth =
        if v.commissioning_current_bandwidth == 0.0 { auto } else { v.commissioning_current_bandwidth as f32 };
    // The test current at most the parameter's, and within the drive's own limits: a third of
    // its trip level (the sequence trips at three times the test current) and its current limit.
    let test_current =
        (v.commissioning_test_current as f32).min(control.limits.overcurrent / 3.0).min(control.current.max_current);
    let commissioning = v.commissioning_at_start.then(|| CommissioningConfig {
        settings: CommissioningSettings {
            test_current,
            max_voltage: v.commissioning_max_voltage as f32,
            overcurrent: 3.0 * test_current,
            current_bandwidth_hz: bandwidth,
            ..CommissioningSettings::for_encoder(counts, control.rates.tick_period())
        },
        apply_motor: v.commissioning_apply_motor,
    });
    Ok(SimulationConfig {
        commissioning,
        control,
        plant,
        excitation: ExcitationConfig {
            point,
            amplitude: v.excitation_amplitude as f32,
            frequency_hz: v.excitation_frequency as f32,
        },
    })
}

fn acc_dec(v: &Values) -> Result<AccDecParams, String> {
    let kind = AccDecKind::from_code(v.accdec_filter).ok_or_else(|| {
        format!("accdec.filter must be 0 (none), 1 (moving averages) or 2 (Butterworth), got {}", v.accdec_filter)
    })?;
    Ok(AccDecParams {
        kind,
        order: count("accdec.order", v.accdec_order)?,
        cutoff_hz: v.accdec_cutoff_hz as f32,
        ma_stages: count("accdec.ma_stages", v.accdec_ma_stages)?,
        ma_lengths: [
            count("accdec.ma_length_1", v.accdec_ma_length_1)?,
            count("accdec.ma_length_2", v.accdec_ma_length_2)?,
            count("accdec.ma_length_3", v.accdec_ma_length_3)?,
        ],
    })
}

fn sequence(v: &Values, counts_per_rev: u32) -> Result<SequenceParams, String> {
    let gains = [
        v.seq_gain_1,
        v.seq_gain_2,
        v.seq_gain_3,
        v.seq_gain_4,
        v.seq_gain_5,
        v.seq_gain_6,
        v.seq_gain_7,
        v.seq_gain_8,
    ]
    .map(|g| g as f32);
    let counts = |name: &str, rad: f64| -> Result<i64, String> {
        if !(rad.is_finite() && rad.abs() <= 1.0e9) {
            return Err(format!("{name} {rad} rad must be a finite angle within ±1e9 rad"));
        }
        Ok((rad / std::f64::consts::TAU * counts_per_rev as f64).round() as i64)
    };
    Ok(SequenceParams {
        target_speed: v.seq_target_speed as f32,
        acceleration: v.seq_acceleration as f32,
        zero_speed: v.seq_zero_speed as f32,
        position_gain: v.seq_position_gain as f32,
        completion_counts: count("seq.completion_counts", v.seq_completion_counts)?,
        completion_hold: v.seq_completion_hold as f32,
        completion_hysteresis: count("seq.completion_hysteresis", v.seq_completion_hysteresis)?,
        gains,
        gain_count: count("seq.gain_count", v.seq_gain_count)? as usize,
        soft_limit_min: counts("seq.soft_limit_min", v.seq_soft_limit_min)?,
        soft_limit_max: counts("seq.soft_limit_max", v.seq_soft_limit_max)?,
    })
}

fn sweep(v: &Values) -> Result<SweepParams, String> {
    let point = InjectionPoint::from_code(v.sweep_point).filter(|p| *p != InjectionPoint::Off).ok_or_else(|| {
        format!("sweep.point must be 1 (torque), 2 (velocity command), 3 (velocity feedback) or 4 (position command), got {}", v.sweep_point)
    })?;
    let signal = match SweepSignal::from_code(v.sweep_signal) {
        Some(signal) => signal,
        None => return Err(format!("sweep.signal must be 0 (stepped sine) or 1 (PRBS), got {}", v.sweep_signal)),
    };
    Ok(SweepParams {
        point,
        signal,
        amplitude: v.sweep_amplitude as f32,
        start_hz: v.sweep_start_hz as f32,
        stop_hz: v.sweep_stop_hz as f32,
        points: count("sweep.points", v.sweep_points)?,
        logarithmic: v.sweep_logarithmic != 0,
        extra_hz: v.sweep_extra_hz as f32,
        settle_cycles: v.sweep_settle_cycles as f32,
        min_settle_s: v.sweep_min_settle_s as f32,
        measure_cycles: v.sweep_measure_cycles as f32,
        min_measure_s: v.sweep_min_measure_s as f32,
        shifts: short_count("sweep.shifts", v.sweep_shifts)?,
        repeats: short_count("sweep.repeats", v.sweep_repeats)?,
        threshold_hz: v.sweep_threshold_hz as f32,
        acquisition_divider: count("sweep.acquisition_divider", v.sweep_acquisition_divider)?,
        prbs_degree: count("sweep.prbs_degree", v.sweep_prbs_degree)?,
        prbs_divider: count("sweep.prbs_divider", v.sweep_prbs_divider)?,
        prbs_seconds: v.sweep_prbs_seconds as f32,
        precision_db: v.sweep_precision_db as f32,
        max_extensions: count("sweep.max_extensions", v.sweep_max_extensions)?,
        dither: v.sweep_dither as f32,
        time_budget_s: v.sweep_time_budget_s as f32,
        measure: SweepMeasure::from_code(v.sweep_measure).ok_or_else(|| {
            format!(
                "sweep.measure must be 0 (the point's signals) or 1 (torque → machine-end acceleration), got {}",
                v.sweep_measure
            )
        })?,
    })
}

fn correction(v: &Values) -> Result<CorrectionParams, String> {
    let raw = [
        (v.corr_zero_hz_1, v.corr_zero_damping_1, v.corr_pole_hz_1, v.corr_pole_damping_1),
        (v.corr_zero_hz_2, v.corr_zero_damping_2, v.corr_pole_hz_2, v.corr_pole_damping_2),
        (v.corr_zero_hz_3, v.corr_zero_damping_3, v.corr_pole_hz_3, v.corr_pole_damping_3),
        (v.corr_zero_hz_4, v.corr_zero_damping_4, v.corr_pole_hz_4, v.corr_pole_damping_4),
        (v.corr_zero_hz_5, v.corr_zero_damping_5, v.corr_pole_hz_5, v.corr_pole_damping_5),
        (v.corr_zero_hz_6, v.corr_zero_damping_6, v.corr_pole_hz_6, v.corr_pole_damping_6),
        (v.corr_zero_hz_7, v.corr_zero_damping_7, v.corr_pole_hz_7, v.corr_pole_damping_7),
        (v.corr_zero_hz_8, v.corr_zero_damping_8, v.corr_pole_hz_8, v.corr_pole_damping_8),
    ];
    let mut p = CorrectionParams { count: count("corr.count", v.corr_count)? as usize, ..Default::default() };
    for (s, (zh, zd, ph, pd)) in p.sections.iter_mut().zip(raw) {
        *s = CorrectionSection {
            zeros: (zh != 0.0).then_some(SecondOrder { hz: zh as f32, damping: zd as f32 }),
            poles: SecondOrder { hz: ph as f32, damping: pd as f32 },
        };
    }
    Ok(p)
}

/// The names of the parameters of correction section i (0-based): zero frequency, zero
/// damping, pole frequency, pole damping — in the order `correction` reads them.
pub const CORRECTION_SECTIONS: [[&str; 4]; 8] = [
    [name::corr_zero_hz_1, name::corr_zero_damping_1, name::corr_pole_hz_1, name::corr_pole_damping_1],
    [name::corr_zero_hz_2, name::corr_zero_damping_2, name::corr_pole_hz_2, name::corr_pole_damping_2],
    [name::corr_zero_hz_3, name::corr_zero_damping_3, name::corr_pole_hz_3, name::corr_pole_damping_3],
    [name::corr_zero_hz_4, name::corr_zero_damping_4, name::corr_pole_hz_4, name::corr_pole_damping_4],
    [name::corr_zero_hz_5, name::corr_zero_damping_5, name::corr_pole_hz_5, name::corr_pole_damping_5],
    [name::corr_zero_hz_6, name::corr_zero_damping_6, name::corr_pole_hz_6, name::corr_pole_damping_6],
    [name::corr_zero_hz_7, name::corr_zero_damping_7, name::corr_pole_hz_7, name::corr_pole_damping_7],
    [name::corr_zero_hz_8, name::corr_zero_damping_8, name::corr_pole_hz_8, name::corr_pole_damping_8],
];

/// The names of the moving-average stage lengths, stage 1 to 3.
pub const MOVING_AVERAGE_LENGTHS: [&str; 3] =
    [name::accdec_ma_length_1, name::accdec_ma_length_2, name::accdec_ma_length_3];

/// The FMU parameter values of a sweep's settings: the inverse of the conversion above, kept
/// beside it (a test turns one into the other and back).
pub fn sweep_values(s: &SweepParams) -> Vec<(&'static str, Value)> {
    let f = |x: f32| Value::Float64(crate::variables::from_f32(x));
    let i = |x: u32| Value::Int32(x.min(i32::MAX as u32) as i32);
    vec![
        (name::sweep_point, Value::Int32(s.point.code())),
        (name::sweep_signal, Value::Int32(s.signal.code())),
        (name::sweep_amplitude, f(s.amplitude)),
        (name::sweep_start_hz, f(s.start_hz)),
        (name::sweep_stop_hz, f(s.stop_hz)),
        (name::sweep_points, i(s.points)),
        (name::sweep_logarithmic, Value::Int32(s.logarithmic as i32)),
        (name::sweep_extra_hz, f(s.extra_hz)),
        (name::sweep_settle_cycles, f(s.settle_cycles)),
        (name::sweep_min_settle_s, f(s.min_settle_s)),
        (name::sweep_measure_cycles, f(s.measure_cycles)),
        (name::sweep_min_measure_s, f(s.min_measure_s)),
        (name::sweep_shifts, i(s.shifts.into())),
        (name::sweep_repeats, i(s.repeats.into())),
        (name::sweep_threshold_hz, f(s.threshold_hz)),
        (name::sweep_acquisition_divider, i(s.acquisition_divider)),
        (name::sweep_prbs_degree, i(s.prbs_degree)),
        (name::sweep_prbs_divider, i(s.prbs_divider)),
        (name::sweep_prbs_seconds, f(s.prbs_seconds)),
        (name::sweep_precision_db, f(s.precision_db)),
        (name::sweep_max_extensions, i(s.max_extensions)),
        (name::sweep_dither, f(s.dither)),
        (name::sweep_time_budget_s, f(s.time_budget_s)),
        (name::sweep_measure, Value::Int32(s.measure.code())),
    ]
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::variables::by_name;

    #[test]
    fn the_section_and_stage_name_tables_reach_the_fields_the_conversion_reads() {
        let mut v = Values::start();
        let set = |v: &mut Values, n: &str, x: Value| v.set(by_name(n).unwrap().vr, x).unwrap();
        set(&mut v, name::corr_count, Value::Int32(8));
        for (i, names) in CORRECTION_SECTIONS.iter().enumerate() {
            for (j, n) in names.iter().enumerate() {
                set(&mut v, n, Value::Float64(10.0 * (i + 1) as f64 + j as f64));
            }
        }
        set(&mut v, name::accdec_filter, Value::Int32(1));
        for (i, n) in MOVING_AVERAGE_LENGTHS.iter().enumerate() {
            set(&mut v, n, Value::Int32(5 + i as i32));
        }
        let c = simulation_config(&v).unwrap().control;
        for (i, s) in c.correction.sections.iter().enumerate() {
            let base = 10.0 * (i + 1) as f32;
            let z = s.zeros.unwrap();
            assert_eq!([z.hz, z.damping, s.poles.hz, s.poles.damping], [base, base + 1.0, base + 2.0, base + 3.0]);
        }
        assert_eq!(c.acc_dec.ma_lengths, [5, 6, 7]);
    }

    #[test]
    fn sweep_settings_go_to_parameter_values_and_back_unchanged() {
        let mut s = Params::default().sweep;
        s.point = InjectionPoint::TorqueCommand;
        s.signal = SweepSignal::Prbs;
        s.precision_db = 0.07;
        s.points = 25;
        s.stop_hz = 2500.0;
        s.logarithmic = false;
        let mut v = Values::start();
        let items = sweep_values(&s);
        assert_eq!(items.len(), crate::variables::DECLARATIONS.iter().filter(|d| d.name.starts_with("sweep.")).count());
        for (n, x) in items {
            v.set(by_name(n).unwrap().vr, x).unwrap();
        }
        assert_eq!(simulation_config(&v).unwrap().control.sweep, s);
    }
}
