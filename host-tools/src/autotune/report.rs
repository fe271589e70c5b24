//! What `servo autotune` leaves and prints: the parameter file, the calibrated twin's plant
//! file, autotune.json, the plots (plant, open loop, Nyquist, closed loop, step,
//! disturbance), and the console's summary.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::Result;
use serde_json::json;

use super::design::Design;
use super::margins::log_grid;
use super::measured_mechanics::MeasuredMechanics;
use super::plant_response;
use super::position_loop_design::PositionTuning;
use super::prediction::StepPrediction;
use super::reserve::{CloseDesign, Reserve};
use super::responses::{plot_loops, Responses};
use super::verification::Verification;
use crate::analysis::response_point::ResponsePoint;

/// A finished autotune: what was measured and designed, and where it was verified.
pub struct AutotuneReport<'a> {
    pub margin: &'a str,
    pub goal_ms: f64,
    pub mechanics: &'a MeasuredMechanics,
    pub design: &'a Design,
    pub position: &'a PositionTuning,
    pub reserve: ReserveTaken<'a>,
    pub responses: &'a Responses,
    /// On the twin (the FMU: the plant, or a drive's measured machine).
    pub twin: &'a Verification,
    /// On the drive (`--device`), with the save's sequence number where it was saved.
    pub drive: Option<(&'a Verification, Option<u32>)>,
    /// The machine is a drive's (`--device`): its drive time is the drive's sweeps only.
    pub on_drive: bool,
}

/// The reserve the design kept beside the goal on the calibrated model, and what became of
/// the close design (its verification that missed: the drive's where it ran there).
pub struct ReserveTaken<'a> {
    pub reserve: Reserve,
    pub close: &'a CloseDesign<Verification>,
    /// The close design's reserve (tight or close).
    pub close_reserve: Reserve,
    /// Drive time of the close design's verification on the machine (s): on the FMU the
    /// twin's sweep, on a drive its own only.
    pub close_drive_time_s: f64,
}

impl AutotuneReport<'_> {
    /// Every verification held.
    pub fn passed(&self) -> bool {
        self.twin.passed && self.drive.is_none_or(|(v, _)| v.passed)
    }

    /// Drive time of every sweep and step on the machine (s): on a drive its own sweeps, on
    /// the FMU the twin's sweeps and step.
    pub fn drive_time_s(&self) -> f64 {
        let verification = match (self.on_drive, self.drive) {
            (true, Some((v, _))) => v.drive_time_s,
            (true, None) => 0.0,
            (false, _) => self.twin.drive_time_s + self.responses.measured.drive_time_s,
        };
        self.mechanics.drive_time_s + verification + self.reserve.close_drive_time_s
    }

    pub fn write_files(&self, out: &Path) -> Result<()> {
        let (mech, d) = (self.mechanics, self.design);
        let m = &mech.calibration.mechanics;
        let period = mech.period();
        let mut toml = String::from("# servo autotune: the velocity loop's gains and torque filters, the position loop's gain and\n# feed-forward\n[parameters]\n");
        for (k, v) in d.tuning.parameters().into_iter().chain(self.position.parameters()) {
            writeln!(toml, "\"{k}\" = {v:e}")?;
        }
        std::fs::write(out.join("autotune.toml"), &toml)?;
        crate::fmu::plant_file::write_plant_file(
            &out.join("calibrated-plant.toml"),
            "servo autotune: the twin's mechanics calibrated from the measured response\n\
             (servo calibrate also measures the friction)",
            &mech.plant_parameters(),
        )?;
        let dense = log_grid(1.0, 0.999 * 0.5 / period, 400);
        let model_points: Vec<ResponsePoint> =
            dense.iter().map(|&f| ResponsePoint::from_complex(f, plant_response(&mech.drive, m, f), 1.0)).collect();
        let measured_plant: Vec<ResponsePoint> =
            mech.points.iter().map(|p| ResponsePoint::from_complex(p.hz, p.response, 1.0)).collect();
        crate::plot::bode::plot_bode(
            &out.join("plant.svg"),
            "plant: torque command → velocity estimate",
            &[("measured (torque-point sweep)", &measured_plant), ("calibrated model", &model_points)],
            None,
        )?;
        let designed = |f: f64| mech.open_loop(&d.tuning, f);
        let predicted: Vec<ResponsePoint> =
            dense.iter().map(|&f| ResponsePoint::from_complex(f, designed(f), 1.0)).collect();
        // The open loop as measured where it was finally verified: the drive's, else the twin's.
        let (verified, label) = match self.drive {
            Some((v, _)) => (v, "measured on the drive with the new gains"),
            None => (self.twin, "measured with the new gains (feedback-point sweep)"),
        };
        crate::plot::bode::plot_bode(
            &out.join("open-loop.svg"),
            &format!(
                "open loop: crossover {:.0} Hz, phase margin {:.0}° designed, {:.0}° measured",
                d.margins.crossover_hz, d.margins.phase_margin_deg, verified.phase_margin_deg
            ),
            &[(label, &verified.open_loop), ("designed", &predicted)],
            Some((d.margins.crossover_hz, "crossover")),
        )?;
        self.responses.plot(out)?;
        plot_loops(out, &designed, &verified.open_loop, &d.margins, self.goal_ms, period)?;
        std::fs::write(out.join("autotune.json"), serde_json::to_string_pretty(&self.json())?)?;
        Ok(())
    }

    pub fn json(&self) -> serde_json::Value {
        let mech = self.mechanics;
        let m = &mech.calibration.mechanics;
        let plant_json: Vec<serde_json::Value> = mech
            .points
            .iter()
            .map(|p| {
                let measured = ResponsePoint::from_complex(p.hz, p.response, 1.0);
                let fit = ResponsePoint::from_complex(p.hz, plant_response(&mech.drive, m, p.hz), 1.0);
                json!({"hz": p.hz, "gain_db": measured.gain_db, "phase_deg": measured.phase_deg,
                       "model_gain_db": fit.gain_db, "model_phase_deg": fit.phase_deg})
            })
            .collect();
        let figures = |p: &StepPrediction| {
            json!({"overshoot_percent": p.overshoot_percent, "settling_time_s": p.settling_time_s,
                   "disturbance_peak": p.disturbance_peak, "disturbance_recovery_s": p.disturbance_recovery_s})
        };
        let r = self.responses;
        json!({
            "margin": self.margin,
            "plant": plant_json,
            "calibration": mech.calibration,
            "design": self.design,
            "reserve": self.reserve.reserve,
            "close_design": self.reserve.close,
            "close_reserve": self.reserve.close_reserve,
            "position": self.position,
            "before": mech.during,
            "verification": self.twin,
            "drive_verification": self.drive.map(|(v, _)| v),
            "saved_sequence": self.drive.and_then(|(_, s)| s),
            "passed": self.passed(),
            "drive_time_s": self.drive_time_s(),
            "responses": {
                "tuned": figures(&r.tuned),
                "before": figures(&r.before),
                "measured_step": {"overshoot_percent": r.measured.overshoot_percent,
                                  "settling_time_s": r.measured.settling_time_s,
                                  "rms_difference_from_predicted": r.step_difference()},
            },
        })
    }

    pub fn print(&self, out: &Path) {
        let (mech, d) = (self.mechanics, self.design);
        let (c, before) = (&mech.calibration, &mech.during);
        let m = &c.mechanics;
        let e = c.relative_errors;
        println!("calibrated mechanics (± standard error):");
        println!("  motor inertia   {:.4e} kg·m² ± {:.2} %", m.motor_inertia, 100.0 * e[0]);
        println!("  load inertia    {:.4e} kg·m² ± {:.2} %", m.load_inertia, 100.0 * e[1]);
        println!("  shaft stiffness {:.4e} N·m/rad ± {:.2} %", m.shaft_stiffness, 100.0 * e[2]);
        println!("  shaft damping   {:.4e} N·m·s/rad (damping ratio ± {:.1} %)", m.shaft_damping, 100.0 * e[3]);
        if let (Some(a), Some(ea)) = (m.absorber, c.absorber_relative_errors) {
            let (hz, zeta) = a.own_mode();
            println!(
                "  absorber        {:.4e} kg·m² ± {:.2} %, {:.4e} N·m/rad ± {:.2} %: its own mode {hz:.1} Hz, damping ratio {zeta:.3}",
                a.inertia,
                100.0 * ea[0],
                a.stiffness,
                100.0 * ea[1]
            );
        }
        let (fr, fa) = m.resonance_hz();
        println!(
            "  resonance {fr:.1} Hz, anti-resonance {fa:.1} Hz; fit within {:.2} dB, {:.1}°",
            c.worst_gain_db, c.worst_phase_deg
        );
        let t = &d.tuning;
        let reserve = self.reserve.reserve;
        let (phase, gain, ms) = reserve.margins();
        println!(
            "velocity loop ({} margins, {} reserve on the model: {phase}°, {gain} dB, Ms {ms}):",
            self.margin,
            reserve.name()
        );
        match self.reserve.close {
            CloseDesign::Held => {}
            CloseDesign::Missed(v) => {
                let limited = if v.limited_points > 0 {
                    format!(", {} points at a limit", v.limited_points)
                } else {
                    String::new()
                };
                println!(
                    "  the close design ({} reserve) missed on {}: phase margin {:.2}°, Ms {:.3}{limited}; this \
                     is the full reserve's design",
                    self.reserve.close_reserve.name(),
                    v.on,
                    v.phase_margin_deg,
                    v.sensitivity_peak
                );
            }
            CloseDesign::Refused(e) => {
                println!(
                    "  no close design ({} reserve: {e}); this is the full reserve's",
                    self.reserve.close_reserve.name()
                )
            }
        }
        println!("  kp {:.4} N·m·s/rad (was {:.4}), ki {:.2} N·m/rad (was {:.2})", t.kp, before.kp, t.ki, before.ki);
        match t.notch {
            Some(n) => println!("  notch {:.1} Hz, Q {:.2}, depth {:.2}", n.hz, n.q, n.depth),
            None => println!("  no notch"),
        }
        if let Some(n) = t.notch2 {
            println!("  second notch {:.1} Hz, Q {:.2}, depth {:.2}", n.hz, n.q, n.depth);
        }
        if t.low_pass_hz > 0.0 {
            println!("  torque low-pass {:.0} Hz", t.low_pass_hz);
        } else {
            println!("  no torque low-pass");
        }
        let dm = &d.margins;
        println!(
            "  designed: bandwidth {:.0} Hz, crossover {:.0} Hz, phase margin {:.1}°, gain margin {:.1} dB, Ms {:.2}",
            dm.bandwidth_hz, dm.crossover_hz, dm.phase_margin_deg, dm.gain_margin_db, dm.sensitivity_peak
        );
        let p = self.position;
        println!(
            "position loop: kp {:.1} 1/s (was {:.1}), velocity feed-forward {:.2}; phase margin {:.1}°, gain margin {:.1} dB, Ms {:.2}, bandwidth {:.0} Hz",
            p.kp,
            mech.params.position.kp,
            p.velocity_feedforward,
            p.margins.phase_margin_deg,
            p.margins.gain_margin_db,
            p.margins.sensitivity_peak,
            p.margins.bandwidth_hz
        );
        print_verification("on the twin", self.twin);
        if let Some((v, saved)) = self.drive {
            print_verification("on the drive", v);
            match (v.passed, saved) {
                (true, Some(s)) => println!("  the drive runs the tuning and saved it (record {s})"),
                (true, None) => println!("  the drive runs the tuning (not saved: --no-save)"),
                (false, _) => println!("  the drive's parameters are back as they were; nothing saved"),
            }
        }
        let period = mech.period();
        let (r, b, ms) = (&self.responses.tuned, &self.responses.before, &self.responses.measured);
        let measured_settling = if ms.settling_time_s.is_nan() {
            "not settled".to_string()
        } else {
            format!("settles in {:.1} ms", 1e3 * ms.settling_time_s)
        };
        println!(
            "  velocity step: {} predicted (before: {}); on the twin overshoot {:.1} %, {measured_settling}, {:.1} % of the step from the prediction (RMS)",
            step(r, period),
            step(b, period),
            ms.overshoot_percent,
            100.0 * self.responses.step_difference()
        );
        println!("  load step at the motor: {} (before: {})", load(r), load(b));
        println!("  drive time {:.1} s", self.drive_time_s());
        println!("files: {} (plant, open-loop, nyquist, closed-loop, step, disturbance .svg)", out.display());
    }
}

fn print_verification(on: &str, v: &Verification) {
    if v.limited_points > 0 {
        println!(
            "  verified {on}: {} frequencies measured with the output at a limit (voltage circle or torque): not the loop's response, FAILS",
            v.limited_points
        );
    } else if v.phase_margin_deg.is_nan() {
        println!("  verified {on}: NO gain crossover among the measured points, the margin is not shown");
    } else {
        println!(
            "  verified {on}: phase margin {:.1}°, Ms {:.2} over the measured points: {}",
            v.phase_margin_deg,
            v.sensitivity_peak,
            if v.passed { "holds" } else { "MISSES the margins" }
        );
    }
}

/// A step figure: its value, or what its NaN means.
fn step(p: &StepPrediction, period: f64) -> String {
    if !p.stable {
        "unstable".to_string()
    } else if p.settling_time_s.is_nan() {
        format!(
            "overshoot {:.1} %, not settled within {:.0} ms",
            p.overshoot_percent,
            1e3 * p.time.len() as f64 * period
        )
    } else {
        format!("overshoot {:.1} %, settles in {:.1} ms", p.overshoot_percent, 1e3 * p.settling_time_s)
    }
}

fn load(p: &StepPrediction) -> String {
    if !p.stable {
        "unstable".to_string()
    } else {
        format!(
            "peak {:.4} rad/s per N·m, back within 10 % in {:.1} ms",
            p.disturbance_peak,
            1e3 * p.disturbance_recovery_s
        )
    }
}
