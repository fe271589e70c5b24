//! `servo bench commission`: the drive's commissioning on the FMU's plant, over motors and
//! mountings drawn log-uniform over the ranges users' motors span, what a real machine hides
//! (where the rotor stands, the encoder's direction, current-sensor offsets and gain errors,
//! the inverter's dead time, sensor noise) on: each measured value against the plant's truth.

use anyhow::Result;
use servo_axis::plant::PlantParams;
use servo_axis::simulation::{AxisSimulation, CommissioningConfig, SimulationConfig, UserInputs};

use crate::bench::figures::Recorder;
use crate::cli::Common;
use crate::random::XorShift64Star;

/// Commissioning over drawn motors and mountings: pole pairs 1–12, R 0.05–10 Ω, L 20 µH–10 mH
/// (time constant at least a third of a tick), flux linkage 2–100 mWb (at least the armature's
/// flux at the test current), rotor inertia 2·10⁻⁶–2·10⁻⁴ kg·m² (the rotor's swing on the
/// commissioning's vector at 4 Hz or more; the rotor's mechanical time constant
/// `R·J/(1.5·p²·ψ²)` at least `--min-mechanical-time-constant`), Coulomb friction 0.5–5 % of
/// the test current's torque, any start angle and either encoder direction, sensor offsets,
/// gain errors, dead time and noise on. Goals: R, Ld, Lq and flux linkage within
/// 3 %, electrical offset within 1°, direction and pole pairs right every time, current-loop
/// bandwidth within 10 % of the target and overshoot ≤ 10 %, at most 5 s of drive time, the
/// rotor within two electrical turns of where it stood and the current within 1.1 times the
/// test current; then the drive runs each commissioned motor in torque mode (reversals at half
/// the test current on the free rotor) without a fault and within 1.1 times the test current.
/// One line per motor, then the worst case (exit 1 when a goal is missed).
#[derive(clap::Args)]
pub struct CommissionBenchArgs {
    /// Motors drawn
    #[arg(long, default_value_t = 100)]
    pub motors: u32,
    /// Seed of the draw (the same seed draws the same motors)
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Run only this motor of the draw (its index in the table, from 0), and print its plant
    #[arg(long)]
    pub motor: Option<u32>,
    /// The least mechanical time constant of a drawn rotor, `R·J/(1.5·p²·ψ²)` (s): the time an
    /// unloaded motor fed a voltage step takes to 63 % of its speed. Catalogue servo motors
    /// have a few tenths of a millisecond to tens of milliseconds; the default, 10 µs, draws
    /// rotors twenty times lighter for their magnet than the lightest of them. 0 draws every
    /// combination of the ranges, rotors of a microsecond among them, whose winding and
    /// inertia resonate at several kilohertz.
    #[arg(long, default_value_t = MIN_MECHANICAL_TIME_CONSTANT)]
    pub min_mechanical_time_constant: f64,
    #[command(flatten)]
    pub common: Common,
}

/// One motor's result: relative errors of R, Ld, Lq, flux linkage; the offset's error (deg);
/// direction and pole pairs right; bandwidth's relative error and overshoot; seconds;
/// excursion (electrical turns); peak current over the test current.
#[derive(Clone, Debug, serde::Serialize)]
pub struct MotorRow {
    pub pole_pairs: u32,
    pub resistance: f64,
    pub inductance: f64,
    pub flux_linkage: f64,
    /// The rotor's inertia (kg·m²).
    pub inertia: f64,
    pub reversed: bool,
    pub failed: Option<String>,
    pub errors: [f64; 4],
    pub offset_deg: f64,
    pub found_right: bool,
    pub bandwidth_error: f64,
    pub overshoot: f64,
    pub seconds: f64,
    pub turns: f64,
    pub current_ratio: f64,
    /// The sequence's stage when the current peaked.
    pub peak_stage: Option<control_core::commissioning::Stage>,
    /// The drive running the motor on what commissioning found ([`run_after_commissioning`]):
    /// the fault that stopped it (None: none), and the peak phase current over the test
    /// current.
    pub run_fault: Option<String>,
    pub run_current_ratio: f64,
}

const TEST_CURRENT: f64 = 2.0;
const TICK: f64 = 1.0 / 16_000.0;
/// The default least mechanical time constant of a drawn rotor (s).
pub const MIN_MECHANICAL_TIME_CONSTANT: f64 = 10e-6;

/// Draw a motor the commissioning's stated conditions hold for, its rotor's mechanical time
/// constant at least `min_mechanical_time_constant` (s) (rejected draws are drawn again: see
/// the arguments' notes).
pub fn draw(rng: &mut XorShift64Star, min_mechanical_time_constant: f64) -> PlantParams {
    loop {
        let mut u = || rng.uniform();
        let log = |u: f64, lo: f64, hi: f64| lo * (hi / lo).powf(u);
        let pole_pairs = 1 + (u() * 12.0) as u32;
        let resistance = log(u(), 0.05, 10.0);
        let ld = log(u(), 20e-6, 10e-3);
        let lq = ld * (1.0 + 0.5 * u());
        let flux_linkage = log(u(), 0.002, 0.1);
        let inertia = log(u(), 2e-6, 2e-4);
        let swing_hz = (1.5 * (pole_pairs * pole_pairs) as f64 * flux_linkage * TEST_CURRENT / inertia).sqrt()
            / std::f64::consts::TAU;
        let mechanical_time_constant =
            resistance * inertia / (1.5 * (pole_pairs * pole_pairs) as f64 * flux_linkage * flux_linkage);
        if ld / resistance < TICK / 3.0
            || lq * TEST_CURRENT > flux_linkage
            || swing_hz < 4.0
            || mechanical_time_constant < min_mechanical_time_constant
        {
            continue;
        }
        let counts = [1024u32, 2000, 4096, 8192, 16384][(u() * 5.0) as usize];
        let load_inertia = 0.1 * inertia;
        let mut p = PlantParams {
            pole_pairs,
            resistance,
            ld,
            lq,
            flux_linkage,
            motor_inertia: inertia,
            load_inertia,
            // A stiff coupling to a light load (a motor on the bench): 1 kHz.
            shaft_stiffness: load_inertia * (std::f64::consts::TAU * 1000.0).powi(2),
            shaft_damping: 2.0 * 0.05 * (load_inertia * load_inertia * (std::f64::consts::TAU * 1000.0).powi(2)).sqrt(),
            motor_coulomb: 0.0,
            motor_viscous: 2e-5,
            load_coulomb: 0.0,
            load_viscous: 0.0,
            encoder_counts_per_rev: counts,
            rotor_start_angle: u() * std::f64::consts::TAU,
            encoder_reversed: u() < 0.5,
            current_offset: [0.01 * (u() - 0.5), 0.01 * (u() - 0.5)],
            current_gain: [1.0 + 0.01 * (u() - 0.5), 1.0 + 0.01 * (u() - 0.5)],
            dead_time_voltage: 0.05 * resistance.min(1.0),
            current_noise_std: 0.002,
            noise_seed: (u() * 1e9) as u64,
            tick: TICK,
            ..PlantParams::default()
        };
        p.motor_coulomb = friction_share(p.noise_seed) * 1.5 * pole_pairs as f64 * flux_linkage * TEST_CURRENT;
        // Sub-steps enough for the plant's explicit terms.
        while p.validate().is_err() && p.substeps < 64 {
            p.substeps *= 2;
        }
        if p.validate().is_ok() {
            return p;
        }
    }
}

/// The Coulomb friction's share of the test current's torque, log-uniform from
/// [`LEAST_FRICTION`] to [`MOST_FRICTION`]: a motor's bearings and seals, from a large motor's
/// half percent to a small one's few percent. Drawn from the motor's own noise seed, so that
/// the draw's other values (and motors) stay what they are for a seed.
fn friction_share(noise_seed: u64) -> f64 {
    LEAST_FRICTION * (MOST_FRICTION / LEAST_FRICTION).powf(XorShift64Star::from_seed(noise_seed).uniform())
}

/// The drawn Coulomb friction's range, as shares of the test current's torque.
pub const LEAST_FRICTION: f64 = 0.005;
pub const MOST_FRICTION: f64 = 0.05;

/// Motor `motor` of the bench's draw for `seed` (the default least mechanical time constant).
pub fn drawn_motor(seed: u64, motor: usize) -> PlantParams {
    let mut rng = XorShift64Star::from_seed(seed);
    let mut plant = draw(&mut rng, MIN_MECHANICAL_TIME_CONSTANT);
    for _ in 0..motor {
        plant = draw(&mut rng, MIN_MECHANICAL_TIME_CONSTANT);
    }
    plant
}

/// Commission one drawn motor on the plant.
pub fn commission_one(plant: &PlantParams) -> MotorRow {
    let mut control =
        control_core::Params { encoder_counts_per_rev: plant.encoder_counts_per_rev, ..Default::default() };
    control.limits.overcurrent = 30.0;
    let mut settings = control_core::commissioning::CommissioningSettings::for_params(&control);
    settings.test_current = TEST_CURRENT as f32;
    let config = SimulationConfig {
        control,
        plant: *plant,
        commissioning: Some(CommissioningConfig { settings, apply_motor: true }),
        ..SimulationConfig::default()
    };
    let mut row = MotorRow {
        pole_pairs: plant.pole_pairs,
        resistance: plant.resistance,
        inductance: plant.ld,
        flux_linkage: plant.flux_linkage,
        inertia: plant.motor_inertia,
        reversed: plant.encoder_reversed,
        failed: None,
        errors: [f64::NAN; 4],
        offset_deg: f64::NAN,
        found_right: false,
        bandwidth_error: f64::NAN,
        overshoot: f64::NAN,
        seconds: f64::NAN,
        turns: f64::NAN,
        current_ratio: f64::NAN,
        peak_stage: None,
        run_fault: None,
        run_current_ratio: f64::NAN,
    };
    let mut sim = match AxisSimulation::new(&config) {
        Ok(sim) => sim,
        Err(e) => {
            row.failed = Some(e.to_string());
            return row;
        }
    };
    let Some(c) = sim.commissioned else {
        row.failed = Some("no commissioning".into());
        return row;
    };
    let m = c.measured;
    let rel = |got: f32, want: f64| (got as f64 / want - 1.0).abs();
    row.errors = [
        rel(m.resistance, plant.resistance),
        rel(m.ld, plant.ld),
        rel(m.lq, plant.lq),
        rel(m.flux_linkage, plant.flux_linkage),
    ];
    let tau = std::f64::consts::TAU;
    let truth = (plant.pole_pairs as f64 * plant.rotor_start_angle).rem_euclid(tau);
    row.offset_deg = ((m.alignment.offset as f64 - truth + std::f64::consts::PI).rem_euclid(tau)
        - std::f64::consts::PI)
        .abs()
        .to_degrees();
    row.found_right = m.alignment.pole_pairs == plant.pole_pairs && m.alignment.reversed == plant.encoder_reversed;
    row.bandwidth_error = (m.current_step.bandwidth_hz / settings.current_bandwidth_hz - 1.0).abs() as f64;
    row.overshoot = m.current_step.overshoot as f64;
    row.seconds = c.seconds;
    row.turns = c.excursion * plant.pole_pairs as f64 / tau;
    row.current_ratio = c.peak_current / TEST_CURRENT;
    row.peak_stage = c.peak_stage;
    let (fault, peak) = run_after_commissioning(&mut sim, plant);
    row.run_fault = fault;
    row.run_current_ratio = peak / TEST_CURRENT;
    row
}

/// Segments of the torque reversals in [`run_after_commissioning`].
const RUN_SEGMENTS: u64 = 8;

/// The drive on what commissioning found, running the motor: torque mode, the q current
/// reversed between plus and minus half the test current on the free rotor, each segment the
/// time the command's torque takes to bring the rotor from rest to a quarter of the bus
/// voltage's back-EMF, at least 8 ticks and at most 50 ms (the first half as long: the speed
/// swings around zero, up to about an eighth of the bus's back-EMF either way). The torque
/// limit is raised to the command's torque. `sim` runs on what commissioning found (built
/// with `apply_motor`: its parameters are the commissioned motor's). Returns the fault that
/// stopped the run (None: none) and the largest phase current the plant carried (A).
pub fn run_after_commissioning(sim: &mut AxisSimulation, plant: &PlantParams) -> (Option<String>, f64) {
    let mut params = *sim.axis.params();
    let amplitude = 0.5 * TEST_CURRENT;
    // The torque constant the drive runs on: the commissioned motor's.
    let kt = params.motor.torque_constant() as f64;
    params.velocity.torque_limit = (1.25 * kt * amplitude) as f32;
    if let Err(e) = sim.axis.rebuild(&params) {
        return (Some(format!("parameters refused: {e}")), 0.0);
    }
    let true_kt = 1.5 * plant.pole_pairs as f64 * plant.flux_linkage;
    let acceleration = true_kt * amplitude / (plant.motor_inertia + plant.load_inertia);
    let speed = 0.25 * plant.bus_voltage / (plant.pole_pairs as f64 * plant.flux_linkage);
    let segment = (speed / acceleration / TICK).clamp(8.0, 0.05 / TICK) as u64;
    let mut inputs = UserInputs { mode: control_core::Mode::Torque, ..UserInputs::default() };
    sim.apply_mode(&inputs);
    let mut peak = 0.0f64;
    for k in 0..RUN_SEGMENTS * segment {
        let sign = if ((k + segment / 2) / segment).is_multiple_of(2) { 1.0 } else { -1.0 };
        inputs.torque_command = sign * kt * amplitude;
        sim.tick(&inputs);
        let current = sim.plant.phase_current_peak();
        if !current.is_finite() {
            return (Some(format!("a phase current of {current} A after {k} ticks")), current);
        }
        peak = peak.max(current);
        let faults = sim.telemetry().faults;
        if faults.any() {
            return (Some(format!("{faults} after {k} ticks")), peak);
        }
    }
    (None, peak)
}

impl CommissionBenchArgs {
    pub fn run(&self) -> Result<bool> {
        if self.motors == 0 {
            anyhow::bail!("--motors must be at least 1");
        }
        let mut rng = XorShift64Star::from_seed(self.seed);
        if !(self.min_mechanical_time_constant.is_finite() && (0.0..=1e-3).contains(&self.min_mechanical_time_constant))
        {
            anyhow::bail!(
                "--min-mechanical-time-constant {} s: give 0 to 0.001 s (catalogue motors have 0.0002 s or more)",
                self.min_mechanical_time_constant
            );
        }
        let mut plants: Vec<PlantParams> =
            (0..self.motors).map(|_| draw(&mut rng, self.min_mechanical_time_constant)).collect();
        if let Some(k) = self.motor {
            let Some(plant) = plants.get(k as usize).copied() else {
                anyhow::bail!("--motor {k}: the draw has motors 0 to {}", self.motors - 1);
            };
            eprintln!("motor {k} of seed {}: {plant:?}", self.seed);
            plants = vec![plant];
        }
        let pb = crate::cli::progress_bar("commissioning", self.common.json);
        let rows: Vec<MotorRow> = plants
            .iter()
            .enumerate()
            .map(|(k, p)| {
                pb.set_position((1000 * k as u64) / self.motors as u64);
                commission_one(p)
            })
            .collect();
        pb.finish_and_clear();
        // The worst over the motors the sequence finished (the others are counted apart).
        let worst = |f: &dyn Fn(&MotorRow) -> f64| {
            let finished = rows.iter().filter(|r| r.failed.is_none());
            finished.map(f).fold(0.0f64, |a, b| if b.is_nan() { f64::INFINITY } else { a.max(b) })
        };
        let failed = rows.iter().filter(|r| r.failed.is_some()).count();
        let wrong = rows.iter().filter(|r| r.failed.is_none() && !r.found_right).count();
        let run_faults = rows.iter().filter(|r| r.failed.is_none() && r.run_fault.is_some()).count();
        let mut rec = Recorder::new("commission");
        rec.equal("motors refused or failed", failed as f64, 0.0, "motors");
        rec.at_most("resistance error", 100.0 * worst(&|r| r.errors[0]), 3.0, "%");
        rec.at_most("d-axis inductance error", 100.0 * worst(&|r| r.errors[1]), 3.0, "%");
        rec.at_most("q-axis inductance error", 100.0 * worst(&|r| r.errors[2]), 3.0, "%");
        rec.at_most("flux linkage error", 100.0 * worst(&|r| r.errors[3]), 3.0, "%");
        rec.at_most("electrical offset error", worst(&|r| r.offset_deg), 1.0, "deg");
        rec.equal("direction or pole pairs wrong", wrong as f64, 0.0, "motors");
        rec.at_most("current-loop bandwidth error", 100.0 * worst(&|r| r.bandwidth_error), 10.0, "%");
        rec.at_most("current-loop overshoot", 100.0 * worst(&|r| r.overshoot), 10.0, "%");
        rec.at_most("drive time", worst(&|r| r.seconds), 5.0, "s");
        rec.at_most("rotor's travel from where it stood", worst(&|r| r.turns), 2.0, "electrical turns");
        rec.at_most("peak current over the test current", worst(&|r| r.current_ratio), 1.1, "x");
        rec.equal("drive faulted running the motor after", run_faults as f64, 0.0, "motors");
        rec.at_most("its peak current over the test current", worst(&|r| r.run_current_ratio), 1.1, "x");
        // How much of its half test current the run drove, at the least: a light rotor on a
        // strong magnet whose back-EMF the loop takes with its integrator (the feed-forward
        // off on a coarse encoder) follows a torque reversal late.
        let least = rows
            .iter()
            .filter(|r| r.failed.is_none() && r.run_fault.is_none())
            .map(|r| 2.0 * r.run_current_ratio)
            .fold(f64::INFINITY, f64::min);
        let least = if least.is_finite() { least } else { f64::NAN };
        rec.info("its least peak current over the command", least, "x");
        let passed = rec.all_met();
        rec.write(self.common.out.as_deref(), passed)?;
        if self.common.json {
            println!(
                "{}",
                serde_json::to_string_pretty(&serde_json::json!({
                    "bench": "commission",
                    "seed": self.seed,
                    "min_mechanical_time_constant": self.min_mechanical_time_constant,
                    "rows": rows,
                    "figures": rec.figures()
                }))?
            );
        } else {
            println!(
                "{:>3} {:>2} {:>8} {:>9} {:>8} {:>3} {:>6} {:>6} {:>6} {:>6} {:>6} {:>5} {:>5} {:>5} {:>5}",
                "#",
                "p",
                "R ohm",
                "L H",
                "psi Wb",
                "rev",
                "R %",
                "Ld %",
                "Lq %",
                "psi %",
                "off °",
                "bw %",
                "t s",
                "I/It",
                "run"
            );
            for (k, r) in rows.iter().enumerate() {
                match &r.failed {
                    Some(e) => println!("{k:>3} {:>2} {:>8.3} {:>9.2e} {:>8.4} {:>3}  FAILED: {e}", r.pole_pairs, r.resistance, r.inductance, r.flux_linkage, r.reversed as u8),
                    None => println!(
                        "{k:>3} {:>2} {:>8.3} {:>9.2e} {:>8.4} {:>3} {:>6.2} {:>6.2} {:>6.2} {:>6.2} {:>6.2} {:>5.1} {:>5.2} {:>5.2} {:>5.2}{}{}",
                        r.pole_pairs, r.resistance, r.inductance, r.flux_linkage, r.reversed as u8,
                        100.0 * r.errors[0], 100.0 * r.errors[1], 100.0 * r.errors[2], 100.0 * r.errors[3],
                        r.offset_deg, 100.0 * r.bandwidth_error, r.seconds, r.current_ratio, r.run_current_ratio,
                        if r.found_right { "" } else { "  WRONG direction or pole pairs" },
                        r.run_fault.as_ref().map_or(String::new(), |f| format!("  RUN FAULTED: {f}"))
                    ),
                }
            }
            rec.print_worst(&format!(
                "worst over {} motors (seed {}, mechanical time constants of {} µs or more):",
                rows.len(),
                self.seed,
                1e6 * self.min_mechanical_time_constant
            ));
        }
        Ok(passed)
    }
}
