//! Closed-loop velocity step of the FMU against the linearised loop, simulated here
//! independently: velocity PI at 8 kHz on a backward-difference velocity estimate (no
//! quantisation), the q-axis current loop linearised (PI at 16 kHz, one tick of computation
//! delay, the winding `L di/dt = v − R i` with the back-EMF cancelled by the decoupling
//! feed-forward) and the linear two-inertia mechanics (friction off).

use cross_checks::{load_fmu, scenario_from_text};

// Small enough that neither the torque limit nor the voltage circle (48 V / √3) is reached:
// the loop stays linear. Velocity quantisation (2^20 counts at 8 kHz) is 0.048 rad/s, 1 %.
const STEP: f64 = 5.0;

fn linear_model(t_end: f64, t_step: f64) -> Vec<(f64, f64)> {
    let (jm, jl, k, c) = (5.0e-5, 1.0e-4, 88.83, 0.009425);
    let (kp, ki) = (0.0942, 11.84);
    let tick = 1.0 / 16_000.0;
    let tv = 2.0 * tick;
    let (r_s, l_q, kt) = (0.3, 0.5e-3, 0.1);
    let (kpi, kii) = (4.7124, 2827.4);
    let sub = 16;
    let h = tick / sub as f64;
    // state: iq, θm, ωm, θL, ωL
    let (mut iq, mut thm, mut wm, mut thl, mut wl) = (0.0, 0.0, 0.0, 0.0, 0.0);
    let (mut integral, mut cmd, mut th_prev, mut w_est) = (0.0, 0.0, 0.0, 0.0);
    let (mut vi, mut pending) = (0.0, 0.0);
    let mut out = Vec::new();
    let ticks = (t_end / tick).round() as usize;
    for n in 0..ticks {
        let t = n as f64 * tick;
        if n % 2 == 0 {
            if n > 0 {
                w_est = (thm - th_prev) / tv;
            }
            th_prev = thm;
            let r = if t >= t_step - 1e-12 { STEP } else { 0.0 };
            let e = r - w_est;
            integral += ki * e * tv;
            cmd = kp * e + integral;
        }
        // Current PI on the sampled current; its voltage acts during the next tick.
        let e_i = cmd / kt - iq;
        vi += kii * e_i * tick;
        let v = kpi * e_i + vi;
        let applied = pending;
        pending = v;
        for _ in 0..sub {
            let shaft = k * (thm - thl) + c * (wm - wl);
            let diq = (applied - r_s * iq) / l_q;
            let dwm = (kt * iq - shaft) / jm;
            let dwl = shaft / jl;
            iq += h * diq;
            thm += h * wm;
            wm += h * dwm;
            thl += h * wl;
            wl += h * dwl;
        }
        if (n + 1) % 4 == 0 {
            out.push(((n + 1) as f64 * tick, wm));
        }
    }
    out
}

#[test]
fn velocity_step_matches_the_linearised_loop() {
    let text = format!(
        r#"name = "velocity_step_linear"
stop_time = 0.1
[parameters]
"plant.motor_coulomb" = 0.0
"plant.load_coulomb" = 0.0
"plant.motor_viscous" = 0.0
"plant.load_viscous" = 0.0
[[events]]
time = 0.0
mode = 1
velocity_command = 0.0
[[events]]
time = 0.01
velocity_command = {STEP:?}
"#
    );
    let s = scenario_from_text("velocity_step_linear", &text);
    let trace = load_fmu().run(&s, |_| {}).unwrap();
    let w = trace.column("motor_velocity").unwrap();
    let model = linear_model(0.1, 0.01);
    let mut worst: f64 = 0.0;
    for (i, (t, wm)) in model.iter().enumerate() {
        let d = (w[i + 1] - wm).abs();
        if d > worst {
            worst = d;
            eprintln!("t = {t:.5} s: FMU {:.4} rad/s, linear {:.4} rad/s", w[i + 1], wm);
        }
    }
    let peak = w.iter().cloned().fold(0.0, f64::max);
    eprintln!(
        "largest difference {:.4} rad/s = {:.2} % of the step; FMU peak {:.3}",
        worst,
        100.0 * worst / STEP,
        peak
    );
    assert!(peak > 1.05 * STEP, "the step response should overshoot (PI on a two-inertia plant)");
    assert!(worst <= 0.03 * STEP, "FMU and linearised loop differ by {:.2} % of the step", 100.0 * worst / STEP);
}
