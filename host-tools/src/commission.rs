//! `servo commission`: measure the motor and the encoder's mounting, as a drive at its first
//! power-up — on the FMU's twin (default: its plant hides what a real machine hides, and the
//! report puts each measured value beside the plant's truth) or on a drive (`--device`), whose
//! parameters then hold the result (`--save` keeps them in its flash). Writes the
//! commissioned parameter set (`params.json`) and the measured values (`commission.json`).

use std::path::PathBuf;

use anyhow::{bail, Context, Result};
use control_core::commissioning::{CommissioningSettings, MeasuredMotor};
use control_core::Params;
use serde_json::json;

use crate::cli::Common;

/// Commission a motor: phase resistance, d- and q-axis inductance, flux linkage (back-EMF),
/// pole pairs, the encoder's direction and electrical offset, and the current loop's gains for
/// a stated bandwidth, checked by a current step (`control_core::commissioning`). The bridge
/// stays under --test-current and --max-voltage throughout; any fault ends it with the bridge
/// off and nothing kept. On the FMU (default) each value is printed beside the twin's plant's
/// truth; with --device on the drive, which runs with the result from then on (--save also
/// writes it to its flash, loaded at every boot).
#[derive(clap::Args)]
pub struct CommissionArgs {
    /// Current the measurements drive (A): within the motor's and the drive's ratings
    #[arg(long, default_value_t = 2.0)]
    pub test_current: f32,
    /// Highest voltage applied (V)
    #[arg(long, default_value_t = 12.0)]
    pub max_voltage: f32,
    /// Current-loop bandwidth the gains are designed for (Hz; 0.02 to 0.1 of the loop rate;
    /// default 3/32 of it, 1.5 kHz at 16 kHz, as the default gains)
    #[arg(long)]
    pub bandwidth: Option<f32>,
    /// Save the result in the drive's flash (with --device)
    #[arg(long)]
    pub save: bool,
    /// FMU parameter NAME=VALUE (repeatable), e.g. plant.rotor_start_angle=2.1 or
    /// plant.encoder_reversed=true: the twin's machine
    #[arg(long = "set")]
    pub set: Vec<String>,
    #[command(flatten)]
    pub target: crate::device::args::TargetArgs,
    #[command(flatten)]
    pub common: Common,
}

impl CommissionArgs {
    pub fn run(&self) -> Result<bool> {
        if self.save && self.target.device.is_none() {
            bail!("--save writes a drive's flash: give the drive with --device PORT");
        }
        let out = self.common.out.clone().unwrap_or_else(|| PathBuf::from("out/commission"));
        std::fs::create_dir_all(&out).with_context(|| format!("cannot create {}", out.display()))?;
        let settings = |p: &Params| {
            let mut s = CommissioningSettings::for_params(p);
            s.test_current = self.test_current;
            s.max_voltage = self.max_voltage;
            s.overcurrent = (3.0 * self.test_current).min(p.limits.overcurrent);
            if let Some(b) = self.bandwidth {
                s.current_bandwidth_hz = b;
            }
            s
        };
        // Whether the current loop fed the back-EMF forward before (commissioning only turns it
        // off, and says why when it does).
        let decoupling_before;
        let (measured, seconds, params, truth) = match self.target.session()? {
            Some(mut session) => {
                let drive = session.params()?;
                // The drive's commissioning decides the feed-forward afresh.
                decoupling_before = true;
                let s = settings(&drive);
                s.validate().map_err(|field| anyhow::anyhow!("commissioning setting {field} is out of range"))?;
                let c = session.commission(&s)?;
                if self.save {
                    let record = session.save_params()?;
                    eprintln!("saved in the drive's flash (record {record})");
                }
                (c.measured, c.seconds, c.params, None)
            }
            None => {
                let mut parameters = crate::fmu::assignment::axis_parameters(&self.set, &[])?;
                let mut config = crate::fmu::configuration::configuration(&parameters)?;
                decoupling_before = config.control.current.decoupling;
                let given = settings(&config.control);
                parameters.insert("commissioning.at_start".into(), crate::fmu::scenario::Value::Bool(true));
                parameters.insert("commissioning.apply_motor".into(), crate::fmu::scenario::Value::Bool(true));
                parameters.insert(
                    "commissioning.test_current".into(),
                    crate::fmu::scenario::Value::Float(given.test_current as f64),
                );
                parameters.insert(
                    "commissioning.max_voltage".into(),
                    crate::fmu::scenario::Value::Float(given.max_voltage as f64),
                );
                parameters.insert(
                    "commissioning.current_bandwidth".into(),
                    crate::fmu::scenario::Value::Float(given.current_bandwidth_hz as f64),
                );
                config = crate::fmu::configuration::configuration(&parameters)?;
                let sim = servo_axis::simulation::AxisSimulation::new(&config)
                    .map_err(|e| anyhow::anyhow!("on the twin: {e}"))?;
                let c = sim.commissioned.context("the twin did not commission")?;
                let (m, seconds) = (c.measured, c.seconds);
                (m, seconds, *sim.axis.params(), Some(config.plant))
            }
        };
        let rows = report(&measured, truth.as_ref());
        let worst = rows.iter().filter_map(|r| r.3).fold(0.0f64, f64::max);
        let params_file = out.join("params.json");
        std::fs::write(&params_file, serde_json::to_string_pretty(&params)?)?;
        let figures = json!({
            "seconds": seconds,
            "measured": measured,
            "truth": truth.map(|t| json!({
                "resistance": t.resistance, "ld": t.ld, "lq": t.lq, "flux_linkage": t.flux_linkage,
                "pole_pairs": t.pole_pairs, "encoder_reversed": t.encoder_reversed,
                "electrical_offset": electrical_offset(&t),
            })),
            "params": params_file,
        });
        std::fs::write(out.join("commission.json"), serde_json::to_string_pretty(&figures)?)?;
        if self.common.json {
            println!("{}", serde_json::to_string_pretty(&figures)?);
        } else {
            println!("commissioned in {seconds:.2} s of drive time");
            println!("{:<28} {:>14} {:>14} {:>9}", "quantity", "measured", "truth", "error");
            for (name, got, want, error) in &rows {
                let want = want.map_or("-".to_string(), |w| format!("{w:.6}"));
                let error = error.map_or("-".to_string(), |e| format!("{:.2} %", 100.0 * e));
                println!("{name:<28} {got:>14.6} {want:>14} {error:>9}");
            }
            if truth.is_some() {
                println!("worst relative error of the constants {:.2} %", 100.0 * worst);
            }
            let step = measured.current_step;
            let target = settings(&params).current_bandwidth_hz;
            if (step.bandwidth_hz / target - 1.0).abs() > 0.1 || step.overshoot > 0.1 {
                println!(
                    "warning: the current loop's step measured {:.0} Hz against {target:.0} Hz with {:.1} % overshoot \
                     (goal: within 10 %, at most 10 %): the winding may not be what was measured (a rotor that \
                     kept swinging, a load on a soft shaft)",
                    step.bandwidth_hz,
                    100.0 * step.overshoot
                );
            }
            if decoupling_before && !params.current.decoupling {
                println!(
                    "the current loop's back-EMF feed-forward is off: one encoder count per velocity period of it \
                     would drive more than a tenth of the test current ({:.2} A) into the winding in a tick \
                     (a coarse encoder under a strong magnet); the loop's integrator takes the back-EMF",
                    measured.test_current
                );
            }
            println!("parameters written to {}", params_file.display());
        }
        Ok(true)
    }
}

/// The plant's electrical angle at encoder count 0 (rad, in [0, 2π)).
fn electrical_offset(t: &servo_axis::plant::PlantParams) -> f64 {
    (t.pole_pairs as f64 * t.rotor_start_angle).rem_euclid(std::f64::consts::TAU)
}

/// Rows of quantity, measured, truth and relative error (the offset's error in degrees
/// instead, as a share of a full turn would say nothing).
type Row = (&'static str, f64, Option<f64>, Option<f64>);

fn report(m: &MeasuredMotor, truth: Option<&servo_axis::plant::PlantParams>) -> Vec<Row> {
    let relative = |got: f64, want: f64| Some((got / want - 1.0).abs());
    let t = truth;
    let mut rows: Vec<Row> = vec![
        ("resistance (ohm)", m.resistance as f64, t.map(|t| t.resistance), None),
        ("d-axis inductance (H)", m.ld as f64, t.map(|t| t.ld), None),
        ("q-axis inductance (H)", m.lq as f64, t.map(|t| t.lq), None),
        ("flux linkage (Wb)", m.flux_linkage as f64, t.map(|t| t.flux_linkage), None),
    ];
    for r in &mut rows {
        r.3 = r.2.and_then(|want| relative(r.1, want));
    }
    rows.push(("pole pairs", m.alignment.pole_pairs as f64, t.map(|t| t.pole_pairs as f64), None));
    rows.push((
        "encoder reversed (1 = yes)",
        m.alignment.reversed as u8 as f64,
        t.map(|t| t.encoder_reversed as u8 as f64),
        None,
    ));
    rows.push((
        "electrical offset (deg)",
        (m.alignment.offset as f64).to_degrees(),
        t.map(|t| electrical_offset(t).to_degrees()),
        None,
    ));
    rows.push(("current kp (V/A)", m.current_kp as f64, None, None));
    rows.push(("current ki (V/(A s))", m.current_ki as f64, None, None));
    rows.push(("current bandwidth (Hz)", m.current_step.bandwidth_hz as f64, None, None));
    rows.push(("current overshoot (%)", 100.0 * m.current_step.overshoot as f64, None, None));
    rows
}
