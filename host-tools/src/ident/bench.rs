//! `servo bench ident`'s grid (seed 001, issue 15): the anti-resonance identified at 20 dB SNR
//! for absorbers from 15 to 300 Hz, each with ten noise seeds, against the plant's true
//! anti-resonance; and the measured record against the analytic plant, point-sampled and as
//! means over the acquisition period (what the aliasing did).

use std::collections::BTreeMap;
use std::path::Path;

use anyhow::Result;
use serde::Serialize;
use servo_axis::plant::PlantParams;

use crate::fmu::runner::Fmu;
use crate::fmu::scenario::Value;
use crate::ident::identification::{
    absorber_parameters, measure_records, true_anti_resonance, Factor, Measured, Notch,
};
use crate::ident::report::identify_axis;
use num_complex::Complex64;

/// Anti-resonances of the grid (Hz): 15–300 Hz, denser where the closed loop makes it hard
/// (low frequencies) and where the axis's own mode masks the absorber's zero (205–220 Hz:
/// the plant's resonance lies within 2 % of it).
pub const GRID_HZ: [f64; 16] =
    [15.0, 20.0, 25.0, 30.0, 40.0, 50.0, 70.0, 100.0, 150.0, 200.0, 205.0, 210.0, 215.0, 220.0, 250.0, 300.0];
/// An anti-resonance the plant itself shows less deeply than this (dB: the notch search's
/// depth on the exact response) is masked by a resonance next to it; reporting it as not
/// clear, undetermined or refused (with the reason) is then the right answer, and a value off
/// by more than the goals is still a miss. On the bench's axis 205–220 Hz show 2.1–3.4 dB; 200
/// and 225 Hz (4.2 and 4.6 dB) must be found.
pub const MASKED_NOTCH_DB: f64 = 4.0;
/// Noise seeds per anti-resonance.
pub const SEEDS: u32 = 10;
/// The range of anti-resonances the goals cover (Hz): `--random` draws from it.
pub const RANGE_HZ: (f64, f64) = (15.0, 300.0);
pub const SNR_DB: f64 = 20.0;
/// Damping of the grid's absorbers (unless `--damping`) and of the demo's.
pub const DAMPING: f64 = 0.05;
pub const AMPLITUDE: f64 = 0.05;
/// Goals: relative error of the frequency and of the damping.
pub const FREQUENCY_GOAL: f64 = 0.01;
pub const DAMPING_GOAL: f64 = 0.2;

/// One identification of the grid.
#[derive(Clone, Debug, Serialize)]
pub struct GridCase {
    pub hz: f64,
    pub seed: u32,
    pub truth: Factor,
    pub found: Option<Factor>,
    pub notch: Option<Notch>,
    pub refusal: Option<String>,
    /// Why a clear notch gave no anti-resonance (the measurement does not determine it).
    pub undetermined: Option<String>,
    /// Depth of the plant's own notch (the search on the exact response, dB).
    pub plant_notch_db: f64,
    /// Relative errors (infinite when nothing was found).
    pub frequency_error: f64,
    pub damping_error: f64,
}

impl GridCase {
    /// Found within the goals; or, where the plant masks its anti-resonance (see
    /// [`MASKED_NOTCH_DB`]), reported without one and with the reason.
    pub fn passed(&self) -> bool {
        match self.found {
            Some(_) => self.frequency_error.abs() <= FREQUENCY_GOAL && self.damping_error.abs() <= DAMPING_GOAL,
            None => self.masked_by_plant(),
        }
    }

    pub fn masked_by_plant(&self) -> bool {
        self.plant_notch_db < MASKED_NOTCH_DB
    }

    /// What was found, for a table cell.
    pub fn outcome(&self) -> String {
        match (&self.found, &self.refusal, &self.undetermined) {
            (Some(_), _, _) => format!("{:+.2}/{:+.0}", self.frequency_error * 100.0, self.damping_error * 100.0),
            (None, Some(_), _) => "refused".into(),
            (None, None, Some(_)) => "undeterm.".into(),
            (None, None, None) => "no notch".into(),
        }
    }
}

/// `n` anti-resonances drawn with `seed`, log-uniform over [`RANGE_HZ`], in rising order
/// (three significant digits, so that a printed one can be run again with `--absorber`).
pub fn random_absorbers(n: u32, seed: u64) -> Vec<f64> {
    let mut rng = crate::random::XorShift64Star::from_seed(seed);
    let mut hz: Vec<f64> = (0..n).map(|_| rng.log_uniform_3_digits(RANGE_HZ.0, RANGE_HZ.1)).collect();
    hz.sort_by(f64::total_cmp);
    hz
}

/// Identify every anti-resonance of `grid` (Hz), absorbers of damping ratio `damping`, with
/// noise seeds 1..=`seeds`.
pub fn run_grid(
    fmu: &Fmu,
    out: &Path,
    grid: &[f64],
    damping: f64,
    seeds: u32,
    mut progress: impl FnMut(f64),
) -> Result<Vec<GridCase>> {
    let load = PlantParams::default().load_inertia;
    let mut cases = Vec::new();
    let total = grid.len() * seeds as usize;
    for (i, &hz) in grid.iter().enumerate() {
        let axis = axis_with_absorber(hz, damping);
        let truth = true_anti_resonance(axis.absorber_inertia, axis.absorber_stiffness, axis.absorber_damping);
        let plant_notch_db = plant_notch(hz, damping).map_or(0.0, |n| n.depth_db);
        for seed in 1..=seeds {
            progress((i * seeds as usize + seed as usize - 1) as f64 / total.max(1) as f64);
            let mut parameters = absorber_parameters(hz, damping, load);
            parameters.insert("plant.noise_seed".into(), Value::Int(seed as i64));
            let dir = out.join(format!("grid/{hz}hz_seed{seed}"));
            let r = identify_axis(fmu, "x", &parameters, AMPLITUDE, Some(SNR_DB), &dir)?;
            let found = r.model.as_ref().and_then(|m| m.anti_resonance);
            let (frequency_error, damping_error) = found.map_or((f64::INFINITY, f64::INFINITY), |z| {
                ((z.hz - truth.hz) / truth.hz, (z.damping - truth.damping) / truth.damping)
            });
            cases.push(GridCase {
                hz,
                seed,
                truth,
                found,
                notch: r.notch,
                refusal: r.refusal,
                undetermined: r.undetermined,
                plant_notch_db,
                frequency_error,
                damping_error,
            });
        }
    }
    progress(1.0);
    Ok(cases)
}

/// Whether the bench's axis with a `hz` absorber ([`DAMPING`]) masks its anti-resonance: the
/// plant's own notch is under [`MASKED_NOTCH_DB`].
pub fn masked_by_plant(hz: f64) -> bool {
    plant_notch(hz, DAMPING).is_none_or(|n| n.depth_db < MASKED_NOTCH_DB)
}

/// The bench's axis with an absorber at `hz` (damping ratio `damping`, inertia equal to the
/// load's).
fn axis_with_absorber(hz: f64, damping: f64) -> PlantParams {
    let load = PlantParams::default().load_inertia;
    let w = std::f64::consts::TAU * hz;
    PlantParams {
        absorber_inertia: load,
        absorber_stiffness: load * w * w,
        absorber_damping: 2.0 * damping * load * w,
        ..PlantParams::default()
    }
}

/// The notch search on the exact response of the bench's axis with a `hz` absorber, on the
/// measurement's frequencies (how deep the plant itself shows its anti-resonance).
pub fn plant_notch(hz: f64, damping: f64) -> Option<Notch> {
    let plant = axis_with_absorber(hz, damping);
    let rate =
        control_core::Params::default().rates.current_loop_hz as f64 / crate::ident::identification::DIVIDER as f64;
    let df = rate / crate::ident::identification::samples_per_period() as f64;
    let (lo, hi) = crate::ident::report::BAND;
    let frequencies: Vec<f64> = crate::ident::averaged_response::bins(df, (lo, hi)).map(|k| k as f64 * df).collect();
    let response: Vec<Complex64> = frequencies.iter().map(|&f| analytic_response(&plant, f)).collect();
    let n = frequencies.len();
    crate::ident::identification::deepest_notch(&Measured {
        frequencies,
        response,
        input_power: vec![1.0; n],
        standard_error: vec![0.0; n],
    })
}

/// Torque → load acceleration of the plant (motor, shaft, load, absorber on the load; viscous
/// friction; Coulomb friction is constant at the identification's speed), in closed form.
pub fn analytic_response(p: &PlantParams, f: f64) -> Complex64 {
    let s = Complex64::new(0.0, std::f64::consts::TAU * f);
    let s2 = s * s;
    let shaft = p.shaft_stiffness + s * p.shaft_damping;
    let absorber = p.absorber_stiffness + s * p.absorber_damping;
    // The absorber seen from the load: Za·Ja·s²/(Ja·s² + Za) (nothing without one).
    let absorber_load = if p.absorber_inertia > 0.0 {
        let ja = s2 * p.absorber_inertia;
        absorber * ja / (ja + absorber)
    } else {
        Complex64::new(0.0, 0.0)
    };
    let motor = s2 * p.motor_inertia + s * p.motor_viscous + shaft;
    let load = s2 * p.load_inertia + s * p.load_viscous + shaft + absorber_load;
    // θL = T·Zs / (M·L − Zs²); a = s²·θL.
    let theta = shaft / (motor * load - shaft * shaft);
    s2 * theta
}

/// Largest relative error of a measured response against the analytic plant over `band`.
pub fn record_error(m: &Measured, plant: &PlantParams, band: (f64, f64)) -> f64 {
    m.frequencies
        .iter()
        .zip(&m.response)
        .filter(|(f, _)| **f >= band.0 && **f <= band.1)
        .map(|(&f, &h)| {
            let a = analytic_response(plant, f);
            (h - a).norm() / a.norm()
        })
        .fold(0.0, f64::max)
}

/// The record's error against the analytic plant, noise-free, with a `hz` absorber.
#[derive(Clone, Debug, Serialize)]
pub struct RecordCheck {
    pub hz: f64,
    /// (band, largest error of the point-sampled record, of the means record).
    pub bands: Vec<((f64, f64), f64, f64)>,
}

pub fn record_check(fmu: &Fmu, hz: f64, bands: &[(f64, f64)]) -> Result<RecordCheck> {
    let load = PlantParams::default().load_inertia;
    let parameters: BTreeMap<String, Value> = absorber_parameters(hz, DAMPING, load);
    let plant = axis_with_absorber(hz, DAMPING);
    let span = (bands.iter().map(|b| b.0).fold(f64::INFINITY, f64::min), bands.iter().map(|b| b.1).fold(0.0, f64::max));
    let point = measure_records(fmu, &parameters, AMPLITUDE, span, ("electromagnetic_torque", "load_acceleration"))?;
    let mean = measure_records(
        fmu,
        &parameters,
        AMPLITUDE,
        span,
        (crate::ident::identification::INPUT_SIGNAL, crate::ident::identification::OUTPUT_SIGNAL),
    )?;
    let bands = bands.iter().map(|&b| (b, record_error(&point, &plant, b), record_error(&mean, &plant, b))).collect();
    Ok(RecordCheck { hz, bands })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn random_absorbers_cover_the_goals_range_in_order_and_a_seed_names_a_draw() {
        let draw = random_absorbers(400, 3);
        assert!(draw.windows(2).all(|w| w[0] <= w[1]));
        assert!(draw.iter().all(|&hz| (RANGE_HZ.0..=RANGE_HZ.1).contains(&hz)), "{draw:?}");
        // Log-uniform: about half below the range's geometric middle (67 Hz), and both ends reached.
        let middle = (RANGE_HZ.0 * RANGE_HZ.1).sqrt();
        let below = draw.iter().filter(|&&hz| hz < middle).count();
        assert!((150..250).contains(&below), "{below} of 400 below {middle} Hz");
        assert!(draw[0] < 17.0 && draw[399] > 260.0, "{} .. {}", draw[0], draw[399]);
        assert_eq!(random_absorbers(400, 3), draw);
        assert_ne!(random_absorbers(400, 4), draw);
    }

    /// The closed form against the two- and three-mass limits worked by hand: the response
    /// (nearly) vanishes at a lightly damped absorber's √(k/J) and has its rigid-body value
    /// 1/ΣJ far below.
    #[test]
    fn analytic_plant_has_its_anti_resonance_and_rigid_gain() {
        let base = PlantParams { motor_viscous: 0.0, load_viscous: 0.0, shaft_damping: 0.0, ..PlantParams::default() };
        let ja = 1.0e-4;
        let w = std::f64::consts::TAU * 40.0;
        let p = PlantParams {
            absorber_inertia: ja,
            absorber_stiffness: ja * w * w,
            absorber_damping: 2.0 * 1e-4 * ja * w,
            ..base
        };
        let rigid = 1.0 / (p.motor_inertia + p.load_inertia + ja);
        assert!(analytic_response(&p, 40.0).norm() < 1e-3 * rigid, "{:?}", analytic_response(&p, 40.0));
        let low = analytic_response(&p, 0.01);
        assert!((low.re - rigid).abs() < 1e-3 * rigid && low.im.abs() < 1e-3 * rigid, "{low:?} vs {rigid}");
        // Without the absorber, the two-inertia resonance √(k(1/Jm + 1/JL)) is a pole.
        let wr = (base.shaft_stiffness * (1.0 / base.motor_inertia + 1.0 / base.load_inertia)).sqrt();
        assert!(analytic_response(&base, wr / std::f64::consts::TAU).norm() > 1e9);
    }

    /// The anti-resonance fitted to the analytic plant's response under white noise is
    /// unbiased: a well-damped absorber (damping 0.15, a notch under 3 dB deep) at 23.1 Hz,
    /// forty noise realisations, each part (real, imaginary) of a tenth of the notch's level
    /// on every frequency (the found frequencies scatter by 0.3 %). The linearised
    /// (Sanathanan–Koerner) solution alone lies 0.69 % high on average in frequency and 4.2 %
    /// in damping here; the refined fit −0.01 % and −0.4 % (the frequency mean's own standard
    /// error is 0.05 %).
    #[test]
    fn the_fitted_anti_resonance_is_unbiased_under_noise() {
        let hz = 23.1;
        let plant = axis_with_absorber(hz, 0.15);
        let truth = true_anti_resonance(plant.absorber_inertia, plant.absorber_stiffness, plant.absorber_damping);
        let df = 1000.0 / 2047.0;
        let frequencies: Vec<f64> = (11..1024).map(|k| k as f64 * df).collect();
        let exact: Vec<Complex64> = frequencies.iter().map(|&f| analytic_response(&plant, f)).collect();
        let noise = 0.1 * exact.iter().map(|h| h.norm()).fold(f64::INFINITY, f64::min);
        let mut rng = crate::random::XorShift64Star(7);
        let mut normal = move || crate::ident::anti_resonance_error::normal(&mut rng);
        let n = frequencies.len();
        let errors: Vec<(f64, f64)> = (0..40)
            .map(|_| {
                let response = exact.iter().map(|h| h + noise * Complex64::new(normal(), normal())).collect();
                let m = Measured {
                    frequencies: frequencies.clone(),
                    response,
                    input_power: vec![1.0; n],
                    standard_error: vec![0.0; n],
                };
                let fit = crate::ident::identification::fit_rational(&m, (0.3 * hz, 6.0 * hz), 3, 4).unwrap();
                let zeros = fit.zeros().0;
                let z = zeros.iter().min_by(|a, b| (a.hz - hz).abs().total_cmp(&(b.hz - hz).abs())).unwrap();
                (z.hz / truth.hz - 1.0, z.damping / truth.damping - 1.0)
            })
            .collect();
        let damping = errors.iter().map(|e| e.1).sum::<f64>() / errors.len() as f64;
        let errors: Vec<f64> = errors.iter().map(|e| e.0).collect();
        let mean = errors.iter().sum::<f64>() / errors.len() as f64;
        let spread = (errors.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / (errors.len() - 1) as f64).sqrt();
        assert!(spread > 0.001 && spread < 0.006, "{spread}");
        assert!(mean.abs() < 0.0015, "mean {:.3} %, spread {:.3} %", mean * 100.0, spread * 100.0);
        assert!(damping.abs() < 0.015, "damping's mean error {:.2} %", damping * 100.0);
    }
}
