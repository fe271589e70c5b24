//! Whether a measurement can carry a design, refused with the reason where it cannot: a
//! sweep that drove the torque command into its limit (the response read is not the linear
//! loop's), a calibration the measurement does not determine (too noisy: the inertias' or
//! the stiffness's standard error over 5 %, or a model that misses the measurement by more
//! than 3 dB or 20°), and — for a design — a shaft resonance near or above the top of the
//! measured band (the loop's gain there would be a guess); and a sweep riding at 0 rad/s.

use anyhow::{bail, Result};

use super::calibration::Calibration;
use super::MeasuredSweep;

/// The largest standard error of the inertias and the stiffness a design is built on.
const MAX_RELATIVE_ERROR: f64 = 0.05;
/// The largest misfit between the calibrated model and the measurement.
const MAX_MISFIT_DB: f64 = 3.0;
const MAX_MISFIT_DEG: f64 = 20.0;
/// A resonance above this share of the highest measured frequency is too near the top.
const TOP_SHARE: f64 = 0.8;

/// A speed a torque-point sweep rides at (rad/s): finite and not 0. The sweep keeps the
/// velocity loop running at it (friction then stays on one side, and the loop's path beside
/// the injection is what the calibration takes out); at 0 the drive would sweep in torque
/// mode without the loop, which the calibration does not model.
pub fn check_riding_speed(velocity: f64) -> Result<()> {
    if !(velocity.is_finite() && velocity != 0.0) {
        anyhow::bail!("--velocity must be a finite, non-zero speed (rad/s) for the sweep to ride at, got {velocity}");
    }
    Ok(())
}

/// A torque-point sweep's amplitude (N·m): finite and positive.
pub fn check_torque_amplitude(amplitude: f64) -> Result<()> {
    if !(amplitude.is_finite() && amplitude > 0.0) {
        bail!("--amplitude must be a positive torque (N·m), got {amplitude}");
    }
    Ok(())
}

/// The sweep ran below the torque limit and the voltage circle throughout.
pub fn check_linear(sweep: &MeasuredSweep, amplitude: f64) -> Result<()> {
    if sweep.voltage_limited > 0 {
        bail!(
            "the torque-point sweep drove the current loop's output into the voltage circle at {} of its frequencies: the response read there is not the loop's; lower --amplitude (was {amplitude} N·m) or --velocity",
            sweep.voltage_limited
        );
    }
    if sweep.torque_limited > 0 {
        bail!(
            "the torque-point sweep drove the torque command into its {:.2} N·m limit at {} of its frequencies: the response read there is not the loop's; lower --amplitude (was {amplitude} N·m)",
            sweep.torque_limit,
            sweep.torque_limited
        );
    }
    Ok(())
}

/// The calibration is determined by its measurement.
pub fn check_determined(c: &Calibration) -> Result<()> {
    let names = ["motor inertia", "load inertia", "shaft stiffness"];
    for (name, e) in names.iter().zip(c.relative_errors) {
        if !(e <= MAX_RELATIVE_ERROR) {
            bail!(
                "the measurement does not determine the {name}: its standard error is {:.1} % (at most {:.0} %); the response is too noisy (raise --amplitude, or lower the noise) or not a two-inertia machine's",
                100.0 * e,
                100.0 * MAX_RELATIVE_ERROR
            );
        }
    }
    if !(c.worst_gain_db <= MAX_MISFIT_DB && c.worst_phase_deg <= MAX_MISFIT_DEG) {
        bail!(
            "the calibrated model misses the measurement by {:.1} dB / {:.0}° (at most {MAX_MISFIT_DB} dB / {MAX_MISFIT_DEG}°): the response is too noisy or not a two-inertia machine's",
            c.worst_gain_db,
            c.worst_phase_deg
        );
    }
    Ok(())
}

/// The machine's highest resonance (the shaft's, or with an absorber the chain's upper one)
/// lies well inside the measured band (`top_hz` its highest frequency).
pub fn check_resonance_measured(c: &Calibration, top_hz: f64) -> Result<()> {
    let fr = c.mechanics.highest_resonance_hz();
    if c.rigid || !(fr <= TOP_SHARE * top_hz) {
        bail!(
            "the calibration puts the shaft's resonance at {fr:.0} Hz, near or above the top of the measured band ({top_hz:.0} Hz; a design needs it below {:.0} Hz): the loop's gain there would be a guess, so no design is offered",
            TOP_SHARE * top_hz
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autotune::mechanics::Mechanics;

    fn calibration(errors: [f64; 4], misfit_db: f64, rigid: bool) -> Calibration {
        Calibration {
            mechanics: Mechanics {
                motor_inertia: 5e-5,
                load_inertia: 1e-4,
                shaft_stiffness: 88.8,
                shaft_damping: 9e-3,
                motor_viscous: 0.0,
                load_viscous: 0.0,
                absorber: None,
            },
            relative_errors: errors,
            absorber_relative_errors: None,
            worst_gain_db: misfit_db,
            worst_phase_deg: 1.0,
            rigid,
            uncertainty: None,
        }
    }

    /// Each refusal where its figure crosses the line, and a NaN error refused, not passed.
    #[test]
    fn each_check_refuses_past_its_line_and_names_the_reason() {
        let fine = calibration([0.01, 0.01, 0.01, 0.1], 0.2, false);
        assert!(check_determined(&fine).is_ok());
        let noisy = calibration([0.01, 0.08, 0.01, 0.1], 0.2, false);
        assert!(check_determined(&noisy).unwrap_err().to_string().contains("load inertia"));
        let undetermined = calibration([0.01, f64::NAN, 0.01, 0.1], 0.2, false);
        assert!(check_determined(&undetermined).is_err());
        let misfit = calibration([0.01, 0.01, 0.01, 0.1], 4.0, false);
        assert!(check_determined(&misfit).unwrap_err().to_string().contains("misses the measurement"));
        // The resonance of `fine` is at 260 Hz.
        assert!(check_resonance_measured(&fine, 3000.0).is_ok());
        assert!(check_resonance_measured(&fine, 300.0).unwrap_err().to_string().contains("near or above the top"));
        assert!(check_resonance_measured(&calibration([0.01; 4], 0.2, true), 3000.0).is_err());
        let saturated = MeasuredSweep {
            points: vec![],
            drive_time_s: 1.0,
            torque_limited: 3,
            voltage_limited: 0,
            torque_limit: 2.0,
        };
        assert!(check_linear(&saturated, 5.0).unwrap_err().to_string().contains("torque command into its 2.00"));
        let at_the_circle = MeasuredSweep { torque_limited: 0, voltage_limited: 2, ..saturated };
        assert!(check_linear(&at_the_circle, 5.0).unwrap_err().to_string().contains("voltage circle at 2"));
        let linear = MeasuredSweep { voltage_limited: 0, ..at_the_circle };
        assert!(check_linear(&linear, 5.0).is_ok());
    }
}
