//! The table: one row per variable. The value reference is the row's number.
//!
//! Row: `vr field: Type "name" Causality Variability = start; unit; range; "description"`.
//! Start values of parameters come from the control core's and the plant's defaults
//! (`core`, `plant`), so the model description cannot drift from them. Ranges are what
//! validation accepts for the value alone; rules between values (a filter below the loop's
//! Nyquist frequency, under-voltage below over-voltage, …) are the core's and the plant's.

use control_core::axis::Mode;
use control_core::excitation::InjectionPoint;
use control_core::params::Params;

use super::{Causality, Declaration, Kind, Range, Unit, Value, Variability};
use crate::plant::PlantParams;

macro_rules! rust_type {
    (Float64) => {
        f64
    };
    (Int32) => {
        i32
    };
    (Boolean) => {
        bool
    };
}

macro_rules! declare_variables {
    ($( $vr:literal $field:ident : $kind:ident $name:literal $caus:ident $var:ident = $start:expr ;
        $unit:expr ; $range:expr ; $desc:literal ; )*) => {
        /// The value of every variable (the instance's variables; outputs written after
        /// each step). Field names are the variable names with `.` as `_`.
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub struct Values {
            $( pub $field: rust_type!($kind), )*
        }

        /// Every variable's name, as a constant named like its field: host code writes
        /// `name::sweep_precision_db`, and a misspelt variable does not compile.
        #[allow(non_upper_case_globals)]
        pub mod name {
            $( pub const $field: &str = $name; )*
        }

        /// Every variable, in value-reference order.
        pub static DECLARATIONS: &[Declaration] = &[
            $( Declaration {
                vr: $vr,
                name: $name,
                kind: Kind::$kind,
                causality: Causality::$caus,
                variability: Variability::$var,
                unit: $unit,
                range: $range,
                description: $desc,
            }, )*
        ];

        /// Each variable's type and byte offset in [`Values`], by value reference.
        const LAYOUT: &[(Kind, usize)] = &[ $( (Kind::$kind, std::mem::offset_of!(Values, $field)), )* ];

        /// Per type, the byte offset in [`Values`] of each value reference's field, or
        /// [`NOT_OF_KIND`] where the variable is of another type: the typed getters read a
        /// field with one load of a two-byte entry (the FMI Get path, every step, for every
        /// value).
        static FLOAT64_AT: [u16; LAYOUT.len()] = offsets_of(LAYOUT, Kind::Float64);
        static INT32_AT: [u16; LAYOUT.len()] = offsets_of(LAYOUT, Kind::Int32);
        static BOOLEAN_AT: [u16; LAYOUT.len()] = offsets_of(LAYOUT, Kind::Boolean);

        impl Values {
            /// A Float64 variable's value (None: no such value reference, or another type).
            #[inline]
            pub fn float64(&self, vr: u32) -> Option<f64> {
                match FLOAT64_AT.get(vr as usize) {
                    // SAFETY: the offset is that of an f64 field of Values (generated above).
                    Some(&at) if at != NOT_OF_KIND => Some(unsafe { *((self as *const Self as *const u8).add(at as usize) as *const f64) }),
                    _ => None,
                }
            }

            /// An Int32 variable's value.
            #[inline]
            pub fn int32(&self, vr: u32) -> Option<i32> {
                match INT32_AT.get(vr as usize) {
                    // SAFETY: the offset is that of an i32 field of Values.
                    Some(&at) if at != NOT_OF_KIND => Some(unsafe { *((self as *const Self as *const u8).add(at as usize) as *const i32) }),
                    _ => None,
                }
            }

            /// A Boolean variable's value.
            #[inline]
            pub fn boolean(&self, vr: u32) -> Option<bool> {
                match BOOLEAN_AT.get(vr as usize) {
                    // SAFETY: the offset is that of a bool field of Values.
                    Some(&at) if at != NOT_OF_KIND => Some(unsafe { *((self as *const Self as *const u8).add(at as usize) as *const bool) }),
                    _ => None,
                }
            }

            /// The byte offset in `Values` of `vr`'s field if the variable is of `kind`.
            #[inline]
            pub fn offset_of(kind: Kind, vr: u32) -> Option<usize> {
                let table = match kind {
                    Kind::Float64 => &FLOAT64_AT,
                    Kind::Int32 => &INT32_AT,
                    Kind::Boolean => &BOOLEAN_AT,
                };
                table.get(vr as usize).filter(|&&at| at != NOT_OF_KIND).map(|&at| at as usize)
            }

            /// Whether every Float64 output is finite: each output's field read directly (no
            /// table lookup; the check after every communication step). `x·0` is 0 (of
            /// either sign) for a finite `x` and NaN for an infinite or NaN one, so a sum of
            /// them is 0 exactly when every one is finite: a multiply and an add per output,
            /// in four sums side by side. The other rows fold away at compile time.
            #[inline]
            pub fn float64_outputs_finite(&self) -> bool {
                let mut sums = [0.0f64; 4];
                $( if matches!((Kind::$kind, Causality::$caus), (Kind::Float64, Causality::Output)) {
                    sums[$vr % 4] += FiniteOutput::times_zero(&self.$field);
                } )*
                (sums[0] + sums[1]) + (sums[2] + sums[3]) == 0.0
            }

            fn compute_start() -> Self {
                Self { $( $field: $start, )* }
            }

            /// The value of a variable (None: no such value reference).
            #[inline]
            pub fn get(&self, vr: u32) -> Option<Value> {
                Some(match vr {
                    $( $vr => Value::$kind(self.$field), )*
                    _ => return None,
                })
            }

            /// Store a value of the variable's own type (no range check: see `variables::check`).
            #[inline]
            pub fn set(&mut self, vr: u32, value: Value) -> Result<(), String> {
                match (vr, value) {
                    $( ($vr, Value::$kind(x)) => self.$field = x, )*
                    _ => return Err(match super::declaration(vr) {
                        Some(d) => format!("{} is a {:?} variable, not {:?}", d.name, d.kind, value),
                        None => format!("no variable has value reference {vr}"),
                    }),
                }
                Ok(())
            }
        }
    };
}

/// The entry of a per-type offset table for a variable of another type.
const NOT_OF_KIND: u16 = u16::MAX;

/// The per-type offset table of `kind` from the layout (at compile time; an offset that does
/// not fit the entry fails the build).
const fn offsets_of<const N: usize>(layout: &[(Kind, usize)], kind: Kind) -> [u16; N] {
    let mut table = [NOT_OF_KIND; N];
    let mut vr = 0;
    while vr < N {
        let (k, at) = layout[vr];
        if k as u8 == kind as u8 {
            assert!(at < NOT_OF_KIND as usize, "a field of Values lies beyond the offset tables' reach");
            table[vr] = at as u16;
        }
        vr += 1;
    }
    table
}

/// A field's value times zero, for any variable type: NaN for an infinite or NaN float, 0
/// otherwise (integers and booleans are always finite).
trait FiniteOutput {
    fn times_zero(field: &Self) -> f64;
}

impl FiniteOutput for f64 {
    /// The field is read on its own, 8 bytes: the check runs right after the step wrote the
    /// outputs, one 8-byte store each, and a wider load spanning two of them (which the
    /// optimiser would otherwise make of neighbouring fields) waits for both stores to reach
    /// the cache instead of taking their values from the store buffer: that stall was most of
    /// the check's time.
    #[inline(always)]
    fn times_zero(field: &f64) -> f64 {
        // SAFETY: a reference is valid for reads of its type.
        #[allow(unsafe_code)]
        let value = unsafe { std::ptr::read_volatile(field) };
        value * 0.0
    }
}

impl FiniteOutput for i32 {
    #[inline(always)]
    fn times_zero(_: &i32) -> f64 {
        0.0
    }
}

impl FiniteOutput for bool {
    #[inline(always)]
    fn times_zero(_: &bool) -> f64 {
        0.0
    }
}

impl Values {
    /// Start values: an instance starts (and `Reset` returns) here.
    pub fn start() -> Self {
        static START: std::sync::OnceLock<Values> = std::sync::OnceLock::new();
        *START.get_or_init(Self::compute_start)
    }
}

/// A control-core default as a start value.
fn core(f: impl Fn(&Params) -> f32) -> f64 {
    super::from_f32(f(&Params::default()))
}
fn core_count(f: impl Fn(&Params) -> u32) -> i32 {
    f(&Params::default()) as i32
}
/// A plant default as a start value.
fn plant(f: impl Fn(&PlantParams) -> f64) -> f64 {
    f(&PlantParams::default())
}
fn plant_count(f: impl Fn(&PlantParams) -> u32) -> i32 {
    f(&PlantParams::default()) as i32
}
/// A sequence soft limit in rad (the core keeps counts).
fn soft_limit(f: impl Fn(&Params) -> i64) -> f64 {
    let p = Params::default();
    f(&p) as f64 / p.encoder_counts_per_rev as f64 * std::f64::consts::TAU
}
/// A response-correction section's setting (the default section is a 100 Hz, ζ = 1 low pass).
fn section(f: impl Fn(&control_core::response_correction::CorrectionSection) -> f32) -> f64 {
    super::from_f32(f(&Params::default().correction.sections[0]))
}

const fn r(min: f64, max: f64) -> Range {
    Range::new(min, max)
}
const ANY: Range = Range::ANY;
const I32: Range = Range::new(i32::MIN as f64, i32::MAX as f64);
/// Largest shaft angle the core can hold in encoder counts far from i64 overflow (rad).
const ANGLE: Range = Range::new(-1.0e9, 1.0e9);
const SPEED: Range = Range::new(-1.0e5, 1.0e5);
const TORQUE: Range = Range::new(-1.0e6, 1.0e6);
const FREQ: Range = Range::new(0.0, 1.0e6);
const POS_FREQ: Range = Range::new(1.0e-3, 1.0e6);
/// Butterworth acc/dec cut-off: from the core's lowest (the upper bound is the position loop's
/// Nyquist frequency, which the core checks against the loop rate).
const ACC_DEC_FREQ: Range = Range::new(control_core::ranges::MIN_ACC_DEC_CUTOFF_HZ as f64, 1.0e6);

const S: Option<Unit> = Some(Unit::Second);
const RAD: Option<Unit> = Some(Unit::Radian);
const RAD_S: Option<Unit> = Some(Unit::RadianPerSecond);
const RAD_S2: Option<Unit> = Some(Unit::RadianPerSecondSquared);
const NM: Option<Unit> = Some(Unit::NewtonMetre);
const A: Option<Unit> = Some(Unit::Ampere);
const V: Option<Unit> = Some(Unit::Volt);
const OHM: Option<Unit> = Some(Unit::Ohm);
const KI: Option<Unit> = Some(Unit::VoltPerAmpereSecond);
const H: Option<Unit> = Some(Unit::Henry);
const WB: Option<Unit> = Some(Unit::Weber);
const KGM2: Option<Unit> = Some(Unit::KilogramMetreSquared);
const STIFF: Option<Unit> = Some(Unit::NewtonMetrePerRadian);
const DAMP: Option<Unit> = Some(Unit::NewtonMetreSecondPerRadian);
const HZ: Option<Unit> = Some(Unit::Hertz);
const PER_S: Option<Unit> = Some(Unit::PerSecond);
const DB: Option<Unit> = Some(Unit::Decibel);
const DEG: Option<Unit> = Some(Unit::Degree);
const NONE: Option<Unit> = None;

declare_variables! {
    0 time: Float64 "time" Independent Continuous = 0.0; S; ANY; "Simulation time";

    // Controller parameters (the drive's own settings).
    1 ctrl_current_loop_hz: Float64 "ctrl.current_loop_hz" Parameter Fixed = core(|p| p.rates.current_loop_hz); HZ; r(1000.0, 200_000.0); "Current-loop (base tick) rate";
    2 ctrl_velocity_divider: Int32 "ctrl.velocity_divider" Parameter Fixed = core_count(|p| p.rates.velocity_divider); NONE; r(1.0, 1000.0); "Velocity loop every this many base ticks";
    3 ctrl_position_divider: Int32 "ctrl.position_divider" Parameter Fixed = core_count(|p| p.rates.position_divider); NONE; r(1.0, 1000.0); "Position loop every this many base ticks (multiple of velocity_divider)";
    4 ctrl_current_kp: Float64 "ctrl.current_kp" Parameter Fixed = core(|p| p.current.kp); OHM; r(1.0e-6, 1.0e4); "Current-loop proportional gain";
    5 ctrl_current_ki: Float64 "ctrl.current_ki" Parameter Fixed = core(|p| p.current.ki); KI; r(0.0, 1.0e9); "Current-loop integral gain";
    6 ctrl_decoupling: Boolean "ctrl.decoupling" Parameter Fixed = Params::default().current.decoupling; NONE; ANY; "Cross-coupling and back-EMF feed-forward on (commissioning at initialisation that measures the motor turns it off where one encoder count of it drives more than a tenth of the test current in a tick)";
    7 ctrl_angle_advance_ticks: Float64 "ctrl.angle_advance_ticks" Parameter Fixed = core(|p| p.current.angle_advance_ticks); NONE; r(0.0, 4.0); "Electrical-angle advance of the voltage output, in base ticks";
    8 ctrl_max_current: Float64 "ctrl.max_current" Parameter Fixed = core(|p| p.current.max_current); A; r(1.0e-3, 1.0e4); "Largest commanded current magnitude";
    9 ctrl_velocity_kp: Float64 "ctrl.velocity_kp" Parameter Fixed = core(|p| p.velocity.kp); DAMP; r(1.0e-9, 1.0e4); "Velocity-loop proportional gain";
    10 ctrl_velocity_ki: Float64 "ctrl.velocity_ki" Parameter Fixed = core(|p| p.velocity.ki); STIFF; r(0.0, 1.0e8); "Velocity-loop integral gain";
    11 ctrl_torque_limit: Float64 "ctrl.torque_limit" Parameter Fixed = core(|p| p.velocity.torque_limit); NM; r(1.0e-6, 1.0e5); "Torque limit";
    12 ctrl_position_kp: Float64 "ctrl.position_kp" Parameter Fixed = core(|p| p.position.kp); PER_S; r(1.0e-3, 1.0e5); "Position-loop gain";
    13 ctrl_velocity_feedforward: Float64 "ctrl.velocity_feedforward" Parameter Fixed = core(|p| p.position.velocity_feedforward); NONE; r(0.0, 1.0); "Velocity feed-forward fraction";
    14 ctrl_velocity_limit: Float64 "ctrl.velocity_limit" Parameter Fixed = core(|p| p.position.velocity_limit); RAD_S; r(1.0e-3, 1.0e5); "Velocity command limit";
    15 ctrl_low_pass_hz: Float64 "ctrl.low_pass_hz" Parameter Fixed = core(|p| p.filters.low_pass_hz); HZ; FREQ; "Torque-command low-pass cut-off (0 = off; below the velocity loop's Nyquist frequency)";
    16 ctrl_notch_hz: Float64 "ctrl.notch_hz" Parameter Fixed = core(|p| p.filters.notch_hz); HZ; FREQ; "Torque-command notch centre (0 = off; below the velocity loop's Nyquist frequency)";
    17 ctrl_notch_q: Float64 "ctrl.notch_q" Parameter Fixed = core(|p| p.filters.notch_q); NONE; r(1.0e-3, 1.0e3); "Notch quality factor";
    18 ctrl_notch_depth: Float64 "ctrl.notch_depth" Parameter Fixed = core(|p| p.filters.notch_depth); NONE; r(0.0, 1.0); "Notch gain at the centre (0 = full notch)";
    19 ctrl_overcurrent: Float64 "ctrl.overcurrent" Parameter Fixed = core(|p| p.limits.overcurrent); A; r(1.0e-3, 1.0e4); "Phase current that trips the overcurrent fault";
    20 ctrl_bus_undervoltage: Float64 "ctrl.bus_undervoltage" Parameter Fixed = core(|p| p.limits.bus_undervoltage); V; r(1.0e-3, 1.0e4); "Bus voltage below which the drive trips (below bus_overvoltage)";
    21 ctrl_bus_overvoltage: Float64 "ctrl.bus_overvoltage" Parameter Fixed = core(|p| p.limits.bus_overvoltage); V; r(1.0e-3, 1.0e4); "Bus voltage above which the drive trips";
    22 ctrl_following_error_limit: Float64 "ctrl.following_error_limit" Parameter Fixed = core(|p| p.limits.following_error); RAD; r(1.0e-6, 1.0e6); "Following error that trips in position mode";
    23 ctrl_friction_comp_amplitude: Float64 "ctrl.friction_comp_amplitude" Parameter Fixed = core(|p| p.friction.amplitude); NM; r(0.0, 1.0e4); "Friction-compensation torque pulse at each reversal of the commanded velocity (0 = off)";
    24 ctrl_friction_comp_decay: Float64 "ctrl.friction_comp_decay" Parameter Fixed = core(|p| p.friction.decay); S; r(1.0e-6, 1.0e4); "Decay time constant of that pulse";

    // Motor, mechanics, encoder and sensors of the simulated machine.
    25 plant_pole_pairs: Int32 "plant.pole_pairs" Parameter Fixed = plant_count(|p| p.pole_pairs); NONE; r(1.0, 64.0); "Motor pole pairs";
    26 plant_resistance: Float64 "plant.resistance" Parameter Fixed = plant(|p| p.resistance); OHM; r(1.0e-6, 1.0e3); "Stator resistance";
    27 plant_ld: Float64 "plant.ld" Parameter Fixed = plant(|p| p.ld); H; r(1.0e-6, 10.0); "d-axis inductance (1 µH and up: the winding is solved exactly, a smaller L underflows its exponential)";
    28 plant_lq: Float64 "plant.lq" Parameter Fixed = plant(|p| p.lq); H; r(1.0e-6, 10.0); "q-axis inductance";
    29 plant_flux_linkage: Float64 "plant.flux_linkage" Parameter Fixed = plant(|p| p.flux_linkage); WB; r(1.0e-6, 10.0); "Permanent-magnet flux linkage";
    30 plant_bus_voltage: Float64 "plant.bus_voltage" Parameter Fixed = plant(|p| p.bus_voltage); V; r(1.0e-3, 1.0e4); "DC-bus voltage";
    31 plant_motor_inertia: Float64 "plant.motor_inertia" Parameter Fixed = plant(|p| p.motor_inertia); KGM2; r(1.0e-9, 1.0e3); "Motor (rotor) inertia";
    32 plant_load_inertia: Float64 "plant.load_inertia" Parameter Fixed = plant(|p| p.load_inertia); KGM2; r(1.0e-9, 1.0e3); "Load inertia";
    33 plant_shaft_stiffness: Float64 "plant.shaft_stiffness" Parameter Fixed = plant(|p| p.shaft_stiffness); STIFF; r(1.0e-3, 1.0e9); "Shaft stiffness";
    34 plant_shaft_damping: Float64 "plant.shaft_damping" Parameter Fixed = plant(|p| p.shaft_damping); DAMP; r(0.0, 1.0e6); "Shaft damping";
    35 plant_motor_coulomb: Float64 "plant.motor_coulomb" Parameter Fixed = plant(|p| p.motor_coulomb); NM; r(0.0, 1.0e4); "Motor-side Coulomb friction";
    36 plant_motor_viscous: Float64 "plant.motor_viscous" Parameter Fixed = plant(|p| p.motor_viscous); DAMP; r(0.0, 1.0e4); "Motor-side viscous friction";
    37 plant_load_coulomb: Float64 "plant.load_coulomb" Parameter Fixed = plant(|p| p.load_coulomb); NM; r(0.0, 1.0e4); "Load-side Coulomb friction";
    38 plant_load_viscous: Float64 "plant.load_viscous" Parameter Fixed = plant(|p| p.load_viscous); DAMP; r(0.0, 1.0e4); "Load-side viscous friction";
    39 plant_absorber_inertia: Float64 "plant.absorber_inertia" Parameter Fixed = plant(|p| p.absorber_inertia); KGM2; r(0.0, 1.0e3); "Second mode on the load: absorber inertia (0 = none); anti-resonance sqrt(k/J)";
    40 plant_absorber_stiffness: Float64 "plant.absorber_stiffness" Parameter Fixed = plant(|p| p.absorber_stiffness); STIFF; r(0.0, 1.0e9); "Absorber spring to the load (> 0 with an absorber)";
    41 plant_absorber_damping: Float64 "plant.absorber_damping" Parameter Fixed = plant(|p| p.absorber_damping); DAMP; r(0.0, 1.0e6); "Absorber damping to the load";
    42 plant_coulomb_velocity: Float64 "plant.coulomb_velocity" Parameter Fixed = plant(|p| p.coulomb_velocity); RAD_S; r(1.0e-6, 1.0e3); "Velocity scale of the smoothed Coulomb friction";
    43 plant_encoder_counts_per_rev: Int32 "plant.encoder_counts_per_rev" Parameter Fixed = plant_count(|p| p.encoder_counts_per_rev); NONE; r(4.0, 16_777_216.0); "Encoder counts per motor revolution";
    44 plant_current_noise_std: Float64 "plant.current_noise_std" Parameter Fixed = plant(|p| p.current_noise_std); A; r(0.0, 1.0e3); "Phase-current sensor noise (standard deviation; 0 = off)";
    45 plant_acceleration_noise_std: Float64 "plant.acceleration_noise_std" Parameter Fixed = plant(|p| p.acceleration_noise_std); RAD_S2; r(0.0, 1.0e6); "Machine-end accelerometer noise (standard deviation; 0 = off)";
    46 plant_noise_seed: Int32 "plant.noise_seed" Parameter Fixed = PlantParams::default().noise_seed as i32; NONE; I32; "Seed of the sensor noise";
    47 plant_substeps: Int32 "plant.substeps" Parameter Fixed = plant_count(|p| p.substeps); NONE; r(1.0, 1000.0); "Integration sub-steps per base tick (linear parts exact, couplings held)";

    // A sine added inside the drive at the loop rate.
    48 excitation_point: Int32 "excitation.point" Parameter Fixed = InjectionPoint::Off.code(); NONE; r(0.0, 2.0); "0 off, 1 torque command (N.m), 2 velocity command (rad/s)";
    49 excitation_amplitude: Float64 "excitation.amplitude" Parameter Fixed = 0.0; NONE; r(-1.0e6, 1.0e6); "Amplitude (N.m or rad/s, as the point)";
    50 excitation_frequency: Float64 "excitation.frequency" Parameter Fixed = 0.0; HZ; FREQ; "Frequency (below half the loop rate)";

    // Acceleration/deceleration filter between the position command and the position loop.
    51 accdec_filter: Int32 "accdec.filter" Parameter Fixed = Params::default().acc_dec.kind.code(); NONE; r(0.0, 2.0); "0 none, 1 cascaded moving averages, 2 Butterworth (pole-zero matched)";
    52 accdec_order: Int32 "accdec.order" Parameter Fixed = core_count(|p| p.acc_dec.order); NONE; r(1.0, 6.0); "Butterworth order (1 to 6)";
    53 accdec_cutoff_hz: Float64 "accdec.cutoff_hz" Parameter Fixed = core(|p| p.acc_dec.cutoff_hz); HZ; ACC_DEC_FREQ; "Butterworth cut-off (at least 0.5 Hz and 6e-5 / position-loop period, at most the position loop's Nyquist frequency)";
    54 accdec_ma_stages: Int32 "accdec.ma_stages" Parameter Fixed = core_count(|p| p.acc_dec.ma_stages); NONE; r(1.0, 3.0); "Moving-average stages in use (1 to 3)";
    55 accdec_ma_length_1: Int32 "accdec.ma_length_1" Parameter Fixed = core_count(|p| p.acc_dec.ma_lengths[0]); NONE; r(1.0, 512.0); "Length of moving-average stage 1 (position ticks)";
    56 accdec_ma_length_2: Int32 "accdec.ma_length_2" Parameter Fixed = core_count(|p| p.acc_dec.ma_lengths[1]); NONE; r(1.0, 512.0); "Length of moving-average stage 2 (position ticks)";
    57 accdec_ma_length_3: Int32 "accdec.ma_length_3" Parameter Fixed = core_count(|p| p.acc_dec.ma_lengths[2]); NONE; r(1.0, 512.0); "Length of moving-average stage 3 (position ticks)";

    // Stop / zero-servo / fine-adjust sequence (seed 004), used in mode 3.
    58 seq_target_speed: Float64 "seq.target_speed" Parameter Fixed = core(|p| p.sequence.target_speed); RAD_S; r(1.0e-3, 1.0e5); "Speed of a run, and the speed limit of every positioning move";
    59 seq_acceleration: Float64 "seq.acceleration" Parameter Fixed = core(|p| p.sequence.acceleration); RAD_S2; r(1.0e-3, 1.0e8); "Acceleration/deceleration gradient of the speed reference";
    60 seq_zero_speed: Float64 "seq.zero_speed" Parameter Fixed = core(|p| p.sequence.zero_speed); RAD_S; r(0.0, 1.0e5); "A stop is accepted at or below this speed";
    61 seq_position_gain: Float64 "seq.position_gain" Parameter Fixed = core(|p| p.sequence.position_gain); PER_S; r(1.0e-3, 1.0e5); "Base position gain (speed reference per radian of deviation)";
    62 seq_completion_counts: Int32 "seq.completion_counts" Parameter Fixed = core_count(|p| p.sequence.completion_counts); NONE; r(0.0, 1.0e9); "In position while |deviation| <= this many encoder counts (see seq.completion_hold)";
    63 seq_gain_count: Int32 "seq.gain_count" Parameter Fixed = Params::default().sequence.gain_count as i32; NONE; r(1.0, 8.0); "Entries of the gain table in use (1 to 8)";
    64 seq_gain_1: Float64 "seq.gain_1" Parameter Fixed = core(|p| p.sequence.gains[0]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 1";
    65 seq_gain_2: Float64 "seq.gain_2" Parameter Fixed = core(|p| p.sequence.gains[1]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 2";
    66 seq_gain_3: Float64 "seq.gain_3" Parameter Fixed = core(|p| p.sequence.gains[2]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 3";
    67 seq_gain_4: Float64 "seq.gain_4" Parameter Fixed = core(|p| p.sequence.gains[3]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 4";
    68 seq_gain_5: Float64 "seq.gain_5" Parameter Fixed = core(|p| p.sequence.gains[4]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 5";
    69 seq_gain_6: Float64 "seq.gain_6" Parameter Fixed = core(|p| p.sequence.gains[5]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 6";
    70 seq_gain_7: Float64 "seq.gain_7" Parameter Fixed = core(|p| p.sequence.gains[6]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 7";
    71 seq_gain_8: Float64 "seq.gain_8" Parameter Fixed = core(|p| p.sequence.gains[7]); NONE; r(1.0e-6, 1.0e6); "Gain-table multiplier 8";
    72 seq_soft_limit_min: Float64 "seq.soft_limit_min" Parameter Fixed = soft_limit(|p| p.sequence.soft_limit_min); RAD; ANGLE; "Lowest allowed target (below soft_limit_max)";
    73 seq_soft_limit_max: Float64 "seq.soft_limit_max" Parameter Fixed = soft_limit(|p| p.sequence.soft_limit_max); RAD; ANGLE; "Highest allowed target";

    // Frequency-response sweep (seed 000), started by `sweep_start`.
    74 sweep_point: Int32 "sweep.point" Parameter Fixed = Params::default().sweep.point.code(); NONE; r(1.0, 4.0); "Injection point: 1 torque command, 2 velocity command, 3 velocity feedback (open loop), 4 position command (rad added to the streamed position_command, position mode only; acq_u the injection, acq_y the position, both from position_command)";
    75 sweep_signal: Int32 "sweep.signal" Parameter Fixed = Params::default().sweep.signal.code(); NONE; r(0.0, 1.0); "0 stepped sine (phase shifted above the threshold), 1 PRBS (broadband baseline)";
    76 sweep_amplitude: Float64 "sweep.amplitude" Parameter Fixed = core(|p| p.sweep.amplitude); NONE; r(1.0e-9, 1.0e5); "Sine or PRBS amplitude (rad/s, N.m or rad, as the point; the default 2 is for the velocity points). On the torque command its peak with sweep.dither (the stepped sine's; the PRBS adds none) must stay below the current limit's torque (kt*ctrl.max_current, 2 N.m on the default axis), or the parameters are refused";
    77 sweep_start_hz: Float64 "sweep.start_hz" Parameter Fixed = core(|p| p.sweep.start_hz); HZ; POS_FREQ; "First frequency (below stop_hz)";
    78 sweep_stop_hz: Float64 "sweep.stop_hz" Parameter Fixed = core(|p| p.sweep.stop_hz); HZ; POS_FREQ; "Last frequency";
    79 sweep_points: Int32 "sweep.points" Parameter Fixed = core_count(|p| p.sweep.points); NONE; r(1.0, 127.0); "Frequencies from start to stop, both included (1: start_hz alone)";
    80 sweep_logarithmic: Int32 "sweep.logarithmic" Parameter Fixed = Params::default().sweep.logarithmic as i32; NONE; r(0.0, 1.0); "1 logarithmic, 0 linear spacing";
    81 sweep_extra_hz: Float64 "sweep.extra_hz" Parameter Fixed = core(|p| p.sweep.extra_hz); HZ; FREQ; "One more frequency inserted in order (0 = none)";
    82 sweep_settle_cycles: Float64 "sweep.settle_cycles" Parameter Fixed = core(|p| p.sweep.settle_cycles); NONE; r(0.0, 1.0e4); "Settling before each record, in cycles (at least min_settle_s); a frequency's first record then waits, half block by half block, until its response agrees with the previous half block's and a ring told by their differences leaves at most the precision (the settling check, with precision_db > 0)";
    83 sweep_min_settle_s: Float64 "sweep.min_settle_s" Parameter Fixed = core(|p| p.sweep.min_settle_s); S; r(0.0, 1.0e4); "Shortest settling";
    84 sweep_measure_cycles: Float64 "sweep.measure_cycles" Parameter Fixed = core(|p| p.sweep.measure_cycles); NONE; r(1.0e-3, 1.0e4); "Measurement of each record, in cycles (at least min_measure_s, or half of it below half the threshold while precision control runs)";
    85 sweep_min_measure_s: Float64 "sweep.min_measure_s" Parameter Fixed = core(|p| p.sweep.min_measure_s); S; r(0.0, 1.0e4); "Shortest measurement of a record (half of it below half the phase-shifting threshold while precision control runs and the half keeps 32 samples; the caps of sweep.max_extensions stay the same in time)";
    86 sweep_shifts: Int32 "sweep.shifts" Parameter Fixed = core_count(|p| p.sweep.shifts.into()); NONE; r(1.0, 16.0); "Phase step 2*pi/shifts between the repeats of one frequency";
    87 sweep_repeats: Int32 "sweep.repeats" Parameter Fixed = core_count(|p| p.sweep.repeats.into()); NONE; r(1.0, 16.0); "Records per frequency at and above the threshold";
    88 sweep_threshold_hz: Float64 "sweep.threshold_hz" Parameter Fixed = core(|p| p.sweep.threshold_hz); HZ; FREQ; "Phase shifting from this frequency up (0 = the acquisition Nyquist frequency)";
    89 sweep_acquisition_divider: Int32 "sweep.acquisition_divider" Parameter Fixed = core_count(|p| p.sweep.acquisition_divider); NONE; r(1.0, 1.0e6); "Base ticks per acquisition sample (a multiple of ctrl.velocity_divider; 4 = 4 kHz at 16 kHz)";
    90 sweep_prbs_degree: Int32 "sweep.prbs_degree" Parameter Fixed = core_count(|p| p.sweep.prbs_degree); NONE; r(2.0, 20.0); "PRBS: M-sequence degree (2 to 20; period 2^n - 1 chips)";
    91 sweep_prbs_divider: Int32 "sweep.prbs_divider" Parameter Fixed = core_count(|p| p.sweep.prbs_divider); NONE; r(1.0, 1.0e6); "PRBS: base ticks per chip";
    92 sweep_prbs_seconds: Float64 "sweep.prbs_seconds" Parameter Fixed = core(|p| p.sweep.prbs_seconds); S; r(1.0e-3, 1.0e4); "PRBS: measured duration";
    93 sweep_precision_db: Float64 "sweep.precision_db" Parameter Fixed = core(|p| p.sweep.precision_db); DB; r(0.0, 100.0); "Stepped sine: lengthen a frequency's records by half blocks so that the standard errors of its response G = Y/U, gain and phase (the phase's in the same relative size: 0.03 dB = 0.2 deg), predicted after the first block and, below the threshold, checked against the half blocks' spread, are at most this, and settle each frequency until two half blocks agree within it and a ring told by their differences leaves at most it (0 = fixed records, no settling check)";
    94 sweep_max_extensions: Int32 "sweep.max_extensions" Parameter Fixed = core_count(|p| p.sweep.max_extensions); NONE; r(0.0, 64.0); "At most so many extra measurement blocks (of the full sweep.min_measure_s) per record, and twice as many half blocks discarded while settling (0 to 64); the same time where the block is halved; past it only with sweep.time_budget_s's room";

    // Response-correction filter in front of the position loop (seed 001): `servo tune` writes it.
    95 corr_count: Int32 "corr.count" Parameter Fixed = Params::default().correction.count as i32; NONE; r(0.0, 8.0); "Sections in use (0 = no correction, up to 8)";
    96 corr_zero_hz_1: Float64 "corr.zero_hz_1" Parameter Fixed = 0.0; HZ; FREQ; "Section 1: anti-resonance numerator frequency (0 = no zeros in this section; below the position loop's Nyquist frequency)";
    97 corr_zero_damping_1: Float64 "corr.zero_damping_1" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 1: anti-resonance numerator damping";
    98 corr_pole_hz_1: Float64 "corr.pole_hz_1" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 1: low-pass pole-pair frequency (below the position loop's Nyquist frequency)";
    99 corr_pole_damping_1: Float64 "corr.pole_damping_1" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 1: low-pass pole-pair damping";
    100 corr_zero_hz_2: Float64 "corr.zero_hz_2" Parameter Fixed = 0.0; HZ; FREQ; "Section 2: anti-resonance numerator frequency (0 = no zeros in this section)";
    101 corr_zero_damping_2: Float64 "corr.zero_damping_2" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 2: anti-resonance numerator damping";
    102 corr_pole_hz_2: Float64 "corr.pole_hz_2" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 2: low-pass pole-pair frequency";
    103 corr_pole_damping_2: Float64 "corr.pole_damping_2" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 2: low-pass pole-pair damping";
    104 corr_zero_hz_3: Float64 "corr.zero_hz_3" Parameter Fixed = 0.0; HZ; FREQ; "Section 3: anti-resonance numerator frequency (0 = no zeros in this section)";
    105 corr_zero_damping_3: Float64 "corr.zero_damping_3" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 3: anti-resonance numerator damping";
    106 corr_pole_hz_3: Float64 "corr.pole_hz_3" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 3: low-pass pole-pair frequency";
    107 corr_pole_damping_3: Float64 "corr.pole_damping_3" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 3: low-pass pole-pair damping";
    108 corr_zero_hz_4: Float64 "corr.zero_hz_4" Parameter Fixed = 0.0; HZ; FREQ; "Section 4: anti-resonance numerator frequency (0 = no zeros in this section)";
    109 corr_zero_damping_4: Float64 "corr.zero_damping_4" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 4: anti-resonance numerator damping";
    110 corr_pole_hz_4: Float64 "corr.pole_hz_4" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 4: low-pass pole-pair frequency";
    111 corr_pole_damping_4: Float64 "corr.pole_damping_4" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 4: low-pass pole-pair damping";
    112 corr_zero_hz_5: Float64 "corr.zero_hz_5" Parameter Fixed = 0.0; HZ; FREQ; "Section 5: anti-resonance numerator frequency (0 = no zeros in this section)";
    113 corr_zero_damping_5: Float64 "corr.zero_damping_5" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 5: anti-resonance numerator damping";
    114 corr_pole_hz_5: Float64 "corr.pole_hz_5" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 5: low-pass pole-pair frequency";
    115 corr_pole_damping_5: Float64 "corr.pole_damping_5" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 5: low-pass pole-pair damping";
    116 corr_zero_hz_6: Float64 "corr.zero_hz_6" Parameter Fixed = 0.0; HZ; FREQ; "Section 6: anti-resonance numerator frequency (0 = no zeros in this section)";
    117 corr_zero_damping_6: Float64 "corr.zero_damping_6" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 6: anti-resonance numerator damping";
    118 corr_pole_hz_6: Float64 "corr.pole_hz_6" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 6: low-pass pole-pair frequency";
    119 corr_pole_damping_6: Float64 "corr.pole_damping_6" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 6: low-pass pole-pair damping";
    120 corr_zero_hz_7: Float64 "corr.zero_hz_7" Parameter Fixed = 0.0; HZ; FREQ; "Section 7: anti-resonance numerator frequency (0 = no zeros in this section)";
    121 corr_zero_damping_7: Float64 "corr.zero_damping_7" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 7: anti-resonance numerator damping";
    122 corr_pole_hz_7: Float64 "corr.pole_hz_7" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 7: low-pass pole-pair frequency";
    123 corr_pole_damping_7: Float64 "corr.pole_damping_7" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 7: low-pass pole-pair damping";
    124 corr_zero_hz_8: Float64 "corr.zero_hz_8" Parameter Fixed = 0.0; HZ; FREQ; "Section 8: anti-resonance numerator frequency (0 = no zeros in this section)";
    125 corr_zero_damping_8: Float64 "corr.zero_damping_8" Parameter Fixed = 0.0; NONE; r(0.0, 1.0e3); "Section 8: anti-resonance numerator damping";
    126 corr_pole_hz_8: Float64 "corr.pole_hz_8" Parameter Fixed = section(|s| s.poles.hz); HZ; POS_FREQ; "Section 8: low-pass pole-pair frequency";
    127 corr_pole_damping_8: Float64 "corr.pole_damping_8" Parameter Fixed = section(|s| s.poles.damping); NONE; r(1.0e-6, 1.0e3); "Section 8: low-pass pole-pair damping";

    // Inputs.
    128 mode: Int32 "mode" Input Discrete = Mode::Position.code(); NONE; r(0.0, 3.0); "Control mode: 0 torque, 1 velocity, 2 position, 3 stop sequence (seq_* inputs)";
    129 position_command: Float64 "position_command" Input Continuous = 0.0; RAD; ANGLE; "Motor-side position command: streamed through the acc/dec filter, or the target of a move when move_speed > 0";
    130 move_speed: Float64 "move_speed" Input Continuous = 0.0; RAD_S; r(0.0, 1.0e5); "Positioning speed towards position_command (0: stream position_command)";
    131 jog_velocity: Float64 "jog_velocity" Input Continuous = 0.0; RAD_S; SPEED; "Jog speed in position mode (non-zero overrides position_command)";
    132 velocity_command: Float64 "velocity_command" Input Continuous = 0.0; RAD_S; SPEED; "Motor velocity command";
    133 torque_command: Float64 "torque_command" Input Continuous = 0.0; NM; TORQUE; "Torque command (torque mode)";
    134 disturbance_torque: Float64 "disturbance_torque" Input Continuous = 0.0; NM; TORQUE; "External torque on the load";
    135 fault_reset: Boolean "fault_reset" Input Discrete = false; NONE; ANY; "A change from false to true clears latched faults";
    136 seq_run: Int32 "seq_run" Input Discrete = 0; NONE; r(0.0, 1.0); "Sequence run switch (mode 3): 1 = run at seq.target_speed, 0 = decelerate";
    137 seq_stop: Int32 "seq_stop" Input Discrete = 0; NONE; I32; "Sequence stop key: each increase is one press (accepted at or below seq.zero_speed, held pending while decelerating)";
    138 seq_release: Int32 "seq_release" Input Discrete = 0; NONE; I32; "Sequence position-command blocking release key: each increase is one press";
    139 seq_move: Int32 "seq_move" Input Discrete = 0; NONE; I32; "Sequence move key: each increase moves to seq_target (fine adjust only)";
    140 seq_return: Int32 "seq_return" Input Discrete = 0; NONE; I32; "Sequence return-to-start key: each increase is one press";
    141 seq_target: Float64 "seq_target" Input Discrete = 0.0; RAD; ANGLE; "Target of the sequence move key (motor side)";
    142 sweep_start: Int32 "sweep_start" Input Discrete = 0; NONE; I32; "Frequency-response sweep start key: each increase starts the sweep of the sweep.* parameters (refused with a logged warning in torque mode for a velocity-loop injection point)";
    143 seq_gain_index: Int32 "seq_gain_index" Input Discrete = 0; NONE; I32; "Selected gain-table entry (0-based); a change selects it (outside the table: a logged refusal)";

    // Outputs.
    144 motor_position: Float64 "motor_position" Output Continuous = 0.0; RAD; ANY; "Motor angle (true, not quantised), from where the rotor stood at time 0 (after the commissioning at initialisation)";
    145 motor_velocity: Float64 "motor_velocity" Output Continuous = 0.0; RAD_S; ANY; "Motor velocity (true)";
    146 load_position: Float64 "load_position" Output Continuous = 0.0; RAD; ANY; "Load (machine-end) angle, from where the rotor stood at time 0";
    147 load_velocity: Float64 "load_velocity" Output Continuous = 0.0; RAD_S; ANY; "Load (machine-end) velocity";
    148 load_acceleration: Float64 "load_acceleration" Output Continuous = 0.0; RAD_S2; ANY; "Load (machine-end) acceleration, as the accelerometer reads it (with its noise)";
    149 iq: Float64 "iq" Output Continuous = 0.0; A; ANY; "Measured q-axis current";
    150 id: Float64 "id" Output Continuous = 0.0; A; ANY; "Measured d-axis current";
    151 torque_command_out: Float64 "torque_command_out" Output Continuous = 0.0; NM; ANY; "Torque command into the current loop (after limits, filters and excitation)";
    152 electromagnetic_torque: Float64 "electromagnetic_torque" Output Continuous = 0.0; NM; ANY; "Electromagnetic torque of the motor (true)";
    153 velocity_estimate: Float64 "velocity_estimate" Output Continuous = 0.0; RAD_S; ANY; "Velocity estimated by the drive from the encoder";
    154 following_error: Float64 "following_error" Output Continuous = 0.0; RAD; ANY; "Position command minus encoder position (position mode)";
    155 position_command_out: Float64 "position_command_out" Output Continuous = 0.0; RAD; ANY; "Position command after interpolation and acc/dec filter (position mode)";
    156 command_velocity: Float64 "command_velocity" Output Continuous = 0.0; RAD_S; ANY; "Speed of that command (its pulses per position tick)";
    157 seq_state: Int32 "seq_state" Output Discrete = 0; NONE; r(0.0, 4.0); "Sequence state: 0 idle, 1 running, 2 decelerating, 3 servo lock, 4 fine adjust";
    158 seq_complete: Int32 "seq_complete" Output Discrete = 0; NONE; r(0.0, 1.0); "Zero-servo / fine-adjust completion: in position (|deviation| <= seq.completion_counts, |speed| <= seq.zero_speed) for seq.completion_hold, dropped beyond seq.completion_hysteresis or on a new target";
    159 seq_deviation: Int32 "seq_deviation" Output Discrete = 0; NONE; ANY; "Deviation counter: target minus position, in encoder counts (saturates at the Int32 range)";
    160 seq_hold_position: Float64 "seq_hold_position" Output Discrete = 0.0; RAD; ANY; "Position the sequence holds or moves to (the accepted stop position in servo lock)";
    161 seq_speed_reference: Float64 "seq_speed_reference" Output Continuous = 0.0; RAD_S; ANY; "Speed reference the sequence hands to the velocity loop";
    162 seq_gain: Float64 "seq_gain" Output Discrete = 0.0; NONE; r(0.0, 1.0e6); "Gain multiplier in use";
    163 seq_refused: Int32 "seq_refused" Output Discrete = 0; NONE; r(0.0, 2147483647.0); "Sequence events refused so far";
    164 seq_last_refusal: Int32 "seq_last_refusal" Output Discrete = 0; NONE; r(0.0, 9.0); "Reason of the last refusal: 0 none, 1 already running, 2 not running, 3 stop while running, 4 already stopped, 5 no accepted stop, 6 target blocked, 7 beyond soft limits, 8 gain index, 9 not in sequence mode";
    165 sweep_state: Int32 "sweep_state" Output Discrete = 0; NONE; r(0.0, 3.0); "Sweep state: 0 idle, 1 settling, 2 measuring, 3 done";
    166 sweep_point_index: Int32 "sweep_point" Output Discrete = 0; NONE; ANY; "Index of the frequency being measured";
    167 sweep_record: Int32 "sweep_record" Output Discrete = 0; NONE; ANY; "Record (phase-shifted repeat) of that frequency";
    168 sweep_frequency: Float64 "sweep_frequency" Output Discrete = 0.0; HZ; FREQ; "Frequency being measured";
    169 sweep_done_points: Int32 "sweep_done_points" Output Discrete = 0; NONE; r(0.0, 128.0); "Frequencies measured so far (the on-line correlator's results)";
    170 sweep_last_frequency: Float64 "sweep_last_frequency" Output Discrete = 0.0; HZ; FREQ; "Last measured frequency";
    171 sweep_last_gain_db: Float64 "sweep_last_gain_db" Output Discrete = 0.0; DB; ANY; "Its gain (on-line correlator, on the drive)";
    172 sweep_last_phase_deg: Float64 "sweep_last_phase_deg" Output Discrete = 0.0; DEG; r(-180.0, 180.0); "Its phase";
    173 sweep_last_quality: Float64 "sweep_last_quality" Output Discrete = 0.0; NONE; ANY; "Its quality: fraction of U's AC power at the excitation frequency (0: no result, or none the excitation defines; gain and phase then read 0)";
    174 acq_time: Float64 "acq_time" Output Discrete = 0.0; S; ANY; "Time of the last acquisition sample (the base tick it was taken at)";
    175 acq_u: Float64 "acq_u" Output Discrete = 0.0; NONE; ANY; "Acquired U: the loop signal the sweep relates Y to, per injection point (the book: How it works, the sweep)";
    176 acq_y: Float64 "acq_y" Output Discrete = 0.0; RAD_S; ANY; "Acquired Y (the velocity estimate; the position in rad, from position_command, for a position-command injection)";
    177 acq_phase: Float64 "acq_phase" Output Discrete = 0.0; RAD; ANY; "Excitation phase at that sample";
    178 acq_measuring: Int32 "acq_measuring" Output Discrete = 0; NONE; r(0.0, 1.0); "1 if the sample belongs to a measured record";
    179 acq_point: Int32 "acq_point" Output Discrete = 0; NONE; ANY; "Frequency index the sample belongs to";
    180 acq_record: Int32 "acq_record" Output Discrete = 0; NONE; ANY; "Record (phase-shifted repeat) the sample belongs to";
    181 faults: Int32 "faults" Output Discrete = 0; NONE; r(0.0, 1023.0); "Latched fault bits: 1 overcurrent, 2 undervoltage, 4 overvoltage, 8 following error, 16 non-finite, 32 encoder, 64 the power stage's break input, 128 current sensing not calibrated, 256 a command out of its range, 512 a mode asked of a motor not commissioned";

    // Stop sequence completion signal (seed 004), added after the first release: appended so
    // that every earlier value reference stays.
    182 seq_completion_hold: Float64 "seq.completion_hold" Parameter Fixed = core(|p| p.sequence.completion_hold); S; r(0.0, 10.0); "Completion is raised after |deviation| <= seq.completion_counts and |speed| <= seq.zero_speed held this long, the deviation moving by at most seq.completion_hysteresis (at least 2 counts) over it";
    183 seq_completion_hysteresis: Int32 "seq.completion_hysteresis" Parameter Fixed = core_count(|p| p.sequence.completion_hysteresis); NONE; r(0.0, 1.0e9); "Once raised, completion drops only when |deviation| > seq.completion_counts + this many counts (or on a new target)";

    // Frequency-response dither (seed 000, issue 15), appended so that every earlier value
    // reference stays.
    184 sweep_dither: Float64 "sweep.dither" Parameter Fixed = core(|p| p.sweep.dither); NM; r(0.0, 1000.0); "Stepped sine: pseudo-random +/- dither added to the torque command every tick at and above the threshold (or 2 kHz where the threshold is higher), to break the lock of the encoder count pattern to the excitation (0 = none)";
    // Anti-aliased acquisition for the identification (seed 001), appended likewise.
    185 electromagnetic_torque_mean: Float64 "electromagnetic_torque_mean" Output Continuous = 0.0; NM; ANY; "Mean of electromagnetic_torque over the last communication step (its base ticks' ends): an integrating acquisition, no aliasing from the loops' rates";
    186 load_acceleration_mean: Float64 "load_acceleration_mean" Output Continuous = 0.0; RAD_S2; ANY; "Mean of load_acceleration (the accelerometer, with its noise) over the last communication step, as electromagnetic_torque_mean";
    // The sweep's settling check (seed 000, issue 15), appended likewise.
    187 acq_half_block: Int32 "acq_half_block" Output Discrete = 0; NONE; ANY; "Half block of its frequency's first record the sample belongs to (the settling check; later samples keep the last index): the response is fitted to the samples from the frequency's last index minus one up, the earlier ones were taken before the loop settled";
    // The identification over a drive (seed 001, issue 16), appended likewise.
    188 sweep_measure: Int32 "sweep.measure" Parameter Fixed = Params::default().sweep.measure.code(); NONE; r(0.0, 1.0); "What acq_u and acq_y are: 0 the injection point's signals; 1 the machine-end acceleration (the plant's accelerometer, with its noise) as acq_y, with torque-command injection against acq_u the torque from the measured q current (kt*iq), with position-command injection against acq_u the injected position; both the means over each acquisition period";
    189 accelerometer_sensitivity: Float64 "accelerometer.sensitivity" Parameter Fixed = core(|p| p.accelerometer.sensitivity); NONE; r(1.0e-7, 10.0); "A drive's machine-end accelerometer input: volts per rad/s2 of machine-end angular acceleration (the sensor's V per m/s2 times its radius). The FMU feeds its plant's accelerometer to the core in rad/s2, so it changes nothing here; runs on a drive (--device) carry it to the drive";
    // Whether the loop stayed linear while a frequency was measured (issue 15), appended likewise.
    190 sweep_last_limited: Float64 "sweep_last_limited" Output Discrete = 0.0; NONE; r(0.0, 1.0); "Share (0..1) of the last result's samples whose acquisition period saw the drive's output limited (the voltage circle cut what the current loop asked for). Above 0 the loop was not linear for part of the measurement and the result can be off by tenths of a dB and degrees: lower sweep.amplitude or the riding speed (back-EMF takes voltage), or raise the bus voltage";
    // The limited flag of each acquisition sample (issue 15), appended likewise.
    191 acq_limited: Int32 "acq_limited" Output Discrete = 0; NONE; r(0.0, 1.0); "1 if the drive's output was limited (the voltage circle cut what the current loop asked for) on a tick of the sample's acquisition period: the share of a result's kept samples (those its fit uses, see acq_half_block) is sweep_last_limited, counted from the stream";
    // The sweep's time budget (issue 15), appended likewise.
    192 sweep_time_budget_s: Float64 "sweep.time_budget_s" Parameter Fixed = core(|p| p.sweep.time_budget_s); S; r(0.0, 1.0e4); "Stepped sine with precision control: a frequency's records may take more half blocks than sweep.max_extensions allows (up to 64 blocks) while the whole sweep still ends within this time from its start, every later frequency counted at its own longest; frequencies that finish early leave their time to later ones that need more (in practice the top of the sweep, where the response is a few encoder counts); where earlier frequencies took long, a frequency is cut short so that the sweep still ends within this time (every later one at its shortest); where there is room an extended frequency also measures to 1/1.25 of sweep.precision_db (0 = never)";
    // What a real machine hides from its drive, and the drive's commissioning at power-up
    // (issue 37), appended so that every earlier value reference stays.
    193 plant_rotor_start_angle: Float64 "plant.rotor_start_angle" Parameter Fixed = plant(|p| p.rotor_start_angle); RAD; r(-1.0e3, 1.0e3); "The rotor's mechanical angle from its electrical zero at power-up, where the encoder's counter starts at 0: hidden from the drive, which finds the electrical offset by commissioning";
    194 plant_encoder_reversed: Boolean "plant.encoder_reversed" Parameter Fixed = PlantParams::default().encoder_reversed; NONE; ANY; "The encoder's counter counts down when the rotor turns forward (hidden from the drive: commissioning finds it)";
    195 plant_current_offset_a: Float64 "plant.current_offset_a" Parameter Fixed = plant(|p| p.current_offset[0]); A; r(-1.0e3, 1.0e3); "Phase-a current sensor's offset";
    196 plant_current_offset_b: Float64 "plant.current_offset_b" Parameter Fixed = plant(|p| p.current_offset[1]); A; r(-1.0e3, 1.0e3); "Phase-b current sensor's offset";
    197 plant_current_gain_a: Float64 "plant.current_gain_a" Parameter Fixed = plant(|p| p.current_gain[0]); NONE; r(0.5, 2.0); "Phase-a current sensor's gain (1 = exact)";
    198 plant_current_gain_b: Float64 "plant.current_gain_b" Parameter Fixed = plant(|p| p.current_gain[1]); NONE; r(0.5, 2.0); "Phase-b current sensor's gain (1 = exact)";
    199 plant_dead_time_voltage: Float64 "plant.dead_time_voltage" Parameter Fixed = plant(|p| p.dead_time_voltage); V; r(0.0, 100.0); "Inverter dead-time error: each phase's voltage short by this against its current's sign (0 = ideal inverter)";
    200 commissioning_at_start: Boolean "commissioning.at_start" Parameter Fixed = true; NONE; ANY; "Commission the motor at initialisation (default), as a drive at power-up: the encoder's direction and electrical offset measured and used (see commissioning.apply_motor), time 0 where the commissioning left the axis; a failed commissioning refuses the initialisation by name. Off: the drive is given a commissioned set, the plant's true mounting and the motor of ctrl.motor_* (what the twin of a drive that is already commissioned runs with)";
    201 commissioning_apply_motor: Boolean "commissioning.apply_motor" Parameter Fixed = false; NONE; ANY; "Also run with the measured resistance, inductances, flux linkage, pole pairs and the current-loop gains designed for commissioning.current_bandwidth (off: the motor of ctrl.motor_*, by default the plant's constants, and ctrl.current_kp/ki; the measured values only reported)";
    202 commissioning_test_current: Float64 "commissioning.test_current" Parameter Fixed = 2.0; A; r(1.0e-3, 1.0e3); "Current the commissioning drives, at most (within the motor's ratings): lowered to a third of ctrl.overcurrent (the sequence trips at three times it) and to ctrl.max_current where those are lower";
    203 commissioning_max_voltage: Float64 "commissioning.max_voltage" Parameter Fixed = 12.0; V; r(1.0e-3, 1.0e3); "Highest voltage the commissioning applies";
    204 commissioning_current_bandwidth: Float64 "commissioning.current_bandwidth" Parameter Fixed = 0.0; HZ; r(0.0, 1.0e5); "Closed-loop bandwidth the current-loop gains are designed for (0.02 to 0.1 of the loop rate; 0 = 3/32 of it, 1.5 kHz at 16 kHz, the bandwidth ctrl.current_kp/ki are tuned for by default)";
    205 commissioned_resistance: Float64 "commissioned_resistance" Output Discrete = 0.0; OHM; ANY; "Phase resistance commissioning measured (0: not commissioned at start)";
    206 commissioned_ld: Float64 "commissioned_ld" Output Discrete = 0.0; H; ANY; "d-axis inductance commissioning measured";
    207 commissioned_lq: Float64 "commissioned_lq" Output Discrete = 0.0; H; ANY; "q-axis inductance commissioning measured";
    208 commissioned_flux_linkage: Float64 "commissioned_flux_linkage" Output Discrete = 0.0; WB; ANY; "Flux linkage commissioning measured (from the back-EMF)";
    209 commissioned_pole_pairs: Int32 "commissioned_pole_pairs" Output Discrete = 0; NONE; r(0.0, 64.0); "Pole pairs commissioning found";
    210 commissioned_encoder_offset: Float64 "commissioned_encoder_offset" Output Discrete = 0.0; RAD; r(0.0, core::f64::consts::TAU); "Electrical angle at encoder count 0 commissioning found";
    211 commissioned_encoder_reversed: Int32 "commissioned_encoder_reversed" Output Discrete = 0; NONE; r(0.0, 1.0); "1 if commissioning found the encoder counting down as the rotor turns forward";
    212 commissioned_current_bandwidth: Float64 "commissioned_current_bandwidth" Output Discrete = 0.0; HZ; ANY; "Current-loop bandwidth the commissioning's step measured with its designed gains";
    213 commissioning_time: Float64 "commissioning_time" Output Discrete = 0.0; S; r(0.0, 1.0e4); "Drive time the commissioning took at initialisation";
    // The motor a drive runs with when it is given a commissioned set (issue 37): what a twin of
    // a commissioned drive takes from that drive, appended likewise.
    214 ctrl_motor_pole_pairs: Int32 "ctrl.motor_pole_pairs" Parameter Fixed = 0; NONE; r(0.0, 64.0); "Pole pairs the drive runs with when it is not applying what it measured (commissioning.at_start off, or commissioning.apply_motor off): a commissioned drive's value, for its twin; 0 = the plant's own";
    215 ctrl_motor_resistance: Float64 "ctrl.motor_resistance" Parameter Fixed = 0.0; OHM; r(0.0, 1.0e3); "Phase resistance the drive runs with, as ctrl.motor_pole_pairs; 0 = the plant's own";
    216 ctrl_motor_ld: Float64 "ctrl.motor_ld" Parameter Fixed = 0.0; H; r(0.0, 10.0); "d-axis inductance the drive runs with, as ctrl.motor_pole_pairs; 0 = the plant's own";
    217 ctrl_motor_lq: Float64 "ctrl.motor_lq" Parameter Fixed = 0.0; H; r(0.0, 10.0); "q-axis inductance the drive runs with, as ctrl.motor_pole_pairs; 0 = the plant's own";
    218 ctrl_motor_flux_linkage: Float64 "ctrl.motor_flux_linkage" Parameter Fixed = 0.0; WB; r(0.0, 10.0); "Flux linkage the drive runs with (its torque constant is 1.5 x pole pairs x this), as ctrl.motor_pole_pairs; 0 = the plant's own";
    219 ctrl_notch2_hz: Float64 "ctrl.notch2_hz" Parameter Fixed = core(|p| p.filters.notch2_hz); HZ; FREQ; "Second torque-command notch centre, after the first (0 = off; below the velocity loop's Nyquist frequency): for a second resonance above the crossover, or a broad, shallow notch below it that shapes the loop's phase";
    220 ctrl_notch2_q: Float64 "ctrl.notch2_q" Parameter Fixed = core(|p| p.filters.notch2_q); NONE; r(1.0e-3, 1.0e3); "Second notch's quality factor";
    221 ctrl_notch2_depth: Float64 "ctrl.notch2_depth" Parameter Fixed = core(|p| p.filters.notch2_depth); NONE; r(0.0, 1.0); "Second notch's gain at the centre (0 = full notch)";
}
