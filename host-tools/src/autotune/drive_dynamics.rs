//! What the drive puts between the velocity loop's torque command and its velocity estimate,
//! beside the machine: the current loop (sampled every tick, its voltage applied over the
//! next one), the back-EMF the machine's motion drives into the winding past the loop's
//! feed-forward, the torque between current samples, the estimate (the encoder's count
//! change over one velocity period, the mean velocity over it), and the command's hold over
//! the velocity period. With the machine's `Mechanics` this is the plant the velocity loop
//! drives; a torque-point sweep reads it through the loop that runs during the sweep
//! (`torque_sweep_reading`).

use num_complex::Complex64;

/// The drive's side of the plant, from its parameters and the winding it drives.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct DriveDynamics {
    /// Base tick and velocity period (s).
    pub tick: f64,
    pub velocity_period: f64,
    /// The current loop's PI (V/A, V/(A·s)).
    pub current_kp: f64,
    pub current_ki: f64,
    /// The winding the current loop drives: resistance (Ω) and q-axis inductance (H).
    pub resistance: f64,
    pub inductance: f64,
    /// Torque made per torque asked for (the motor's torque constant over the drive's).
    pub torque_gain: f64,
    /// The drive's torque constant (N·m/A): the current reference per torque asked for.
    pub torque_constant: f64,
    /// The winding's back-EMF per motor speed, `p·ψ` (V·s/rad).
    pub back_emf: f64,
    /// The back-EMF per estimated speed the current loop's feed-forward takes off (`p·ψ` as
    /// the drive knows it, 0 without the decoupling).
    pub back_emf_feedforward: f64,
}

impl DriveDynamics {
    /// A drive with `params` on a winding of `resistance` and `inductance` whose back-EMF
    /// per motor speed is `back_emf` (V·s/rad) and whose torque constant is `torque_gain`
    /// times the drive's.
    pub fn new(
        params: &control_core::Params,
        resistance: f64,
        inductance: f64,
        back_emf: f64,
        torque_gain: f64,
    ) -> Self {
        let m = &params.motor;
        let drive_back_emf = m.pole_pairs as f64 * m.flux_linkage as f64;
        Self {
            tick: params.rates.tick_period() as f64,
            velocity_period: params.rates.velocity_period() as f64,
            current_kp: params.current.kp as f64,
            current_ki: params.current.ki as f64,
            resistance,
            inductance,
            torque_gain,
            torque_constant: 1.5 * drive_back_emf,
            back_emf,
            back_emf_feedforward: if params.current.decoupling { drive_back_emf } else { 0.0 },
        }
    }

    /// As the drive knows itself: its own (commissioned) motor, a torque gain of 1.
    pub fn as_configured(params: &control_core::Params) -> Self {
        let m = &params.motor;
        Self::new(params, m.resistance as f64, m.lq as f64, m.pole_pairs as f64 * m.flux_linkage as f64, 1.0)
    }

    /// The twin's truth: the plant's winding and torque constant against the drive's.
    pub fn on_plant(params: &control_core::Params, plant: &servo_axis::plant::PlantParams) -> Self {
        let back_emf = plant.pole_pairs as f64 * plant.flux_linkage;
        let gain = back_emf / (params.motor.pole_pairs as f64 * params.motor.flux_linkage as f64);
        Self::new(params, plant.resistance, plant.lq, back_emf, gain)
    }

    /// For tests: this drive with a feed-forward that takes all of the back-EMF off (the
    /// model without its back-EMF path).
    #[cfg(test)]
    pub(crate) fn without_back_emf(self) -> Self {
        Self { back_emf: 0.0, back_emf_feedforward: 0.0, ..self }
    }

    /// The closed current loop, reference → current, sampled every tick: the winding
    /// `b/(z − a)` (`a = e^{−RT/L}`, `b = (1 − a)/R`), one tick of computation delay, the PI
    /// `kp + ki·T·z/(z − 1)`.
    pub fn current_loop(&self, f: f64) -> Complex64 {
        let t = self.tick;
        let z = Complex64::from_polar(1.0, std::f64::consts::TAU * f * t);
        let a = (-self.resistance * t / self.inductance).exp();
        let b = (1.0 - a) / self.resistance;
        let pi = self.current_kp + self.current_ki * t * z / (z - 1.0);
        let open = pi * b / ((z - a) * z);
        open / (1.0 + open)
    }

    /// What the back-EMF path leaves of the machine's motion (and of the current driving it):
    /// the motor's speed drives `p·ψ·ω` into the winding; the current loop's feed-forward
    /// takes off `p·ψ̂` times the velocity estimate, held until the next estimate and applied
    /// over the tick after it is computed (`E·H·e^{−sT}·(1 − e^{−sT})/(sT)`). The rest drives
    /// `1/(R + sL)` against the loop's sensitivity `1 − T_i`, a current whose torque the
    /// machine turns into speed (`motor_velocity_per_torque`, per N·m of the model's torque: the
    /// drive's with `torque_gain` 1, the machine's own with the true torque gain):
    /// `1/(1 + (1 − T_i)·(p·ψ − p·ψ̂·F)/(R + sL)·k_t·m)`. Between 200 and 800 Hz it takes
    /// 0.5–1.5 % off a default motor's current (more behind slower current loops).
    pub fn back_emf_path(&self, f: f64, motor_velocity_per_torque: Complex64) -> Complex64 {
        self.back_emf_path_around(f, motor_velocity_per_torque, self.current_loop(f), self.velocity_estimate(f))
    }

    /// [`Self::back_emf_path`] with the closed current loop and the velocity estimate at `f`
    /// already computed (by [`Self::around_machine`], which takes both again).
    fn back_emf_path_around(
        &self,
        f: f64,
        motor_velocity_per_torque: Complex64,
        current_loop: Complex64,
        velocity_estimate: Complex64,
    ) -> Complex64 {
        let s = Complex64::new(0.0, std::f64::consts::TAU * f);
        let delay = (-s * self.tick).exp();
        let zero_order_hold =
            if f * self.tick < 1e-12 { Complex64::new(1.0, 0.0) } else { (1.0 - delay) / (s * self.tick) };
        let fed_forward = velocity_estimate * self.command_hold(f) * delay * zero_order_hold;
        let residual = self.back_emf - self.back_emf_feedforward * fed_forward;
        let winding = 1.0 / (self.resistance + s * self.inductance);
        let speed_per_current = motor_velocity_per_torque * self.torque_constant * self.torque_gain;
        1.0 / (1.0 + (1.0 - current_loop) * winding * residual * speed_per_current)
    }

    /// Velocity estimate over the current loop's torque reference (set every tick), without
    /// the machine's own response: the current loop with the back-EMF path the machine
    /// `motor_velocity_per_torque` closes around it ([`Self::back_emf_path`]), the torque
    /// between two current samples (the current nearly linear over a tick: the samples'
    /// linear interpolation, `sinc²(πfT)` without a phase), the estimate's mean over the
    /// velocity period (`(1 − e^{−sT_v})/(sT_v)`), the torque gain.
    pub fn around_machine(&self, f: f64, motor_velocity_per_torque: Complex64) -> Complex64 {
        let x = 0.5 * std::f64::consts::TAU * f * self.tick;
        let sinc = if x < 1e-9 { 1.0 } else { x.sin() / x };
        let (current_loop, velocity_estimate) = (self.current_loop(f), self.velocity_estimate(f));
        current_loop
            * self.back_emf_path_around(f, motor_velocity_per_torque, current_loop, velocity_estimate)
            * (sinc * sinc)
            * velocity_estimate
            * self.torque_gain
    }

    /// The velocity estimate over the motor's velocity: its mean over the velocity period,
    /// `(1 − e^{−sT_v})/(sT_v)`.
    pub fn velocity_estimate(&self, f: f64) -> Complex64 {
        let wt = std::f64::consts::TAU * f * self.velocity_period;
        if wt < 1e-9 {
            Complex64::new(1.0, 0.0)
        } else {
            let s = Complex64::new(0.0, wt);
            (1.0 - (-s).exp()) / s
        }
    }

    /// The velocity loop's torque command, held over the velocity period's two ticks, as the
    /// current loop's per-tick reference sees it: `(1 + e^{−sT})/2` (the velocity divider of 2).
    pub fn command_hold(&self, f: f64) -> Complex64 {
        let z1 = Complex64::from_polar(1.0, -std::f64::consts::TAU * f * self.tick);
        let n = (self.velocity_period / self.tick).round().max(1.0);
        // The mean of the delays 0 … n − 1 ticks.
        let mut sum = Complex64::new(0.0, 0.0);
        let mut zk = Complex64::new(1.0, 0.0);
        for _ in 0..n as usize {
            sum += zk;
            zk *= z1;
        }
        sum / n
    }

    /// The plant a torque-point sweep reports, `Y/U`, for the plant `p` (torque reference →
    /// velocity estimate) under the velocity controller `c` running during the sweep: the
    /// injected sine changes every tick while U is read on velocity ticks only, so the loop's
    /// held command closes a path U does not see: `G = P/(1 − g·C·P)` with `g` the held
    /// command's share the reference misses (`1 − command_hold`).
    pub fn torque_sweep_reading(&self, f: f64, p: Complex64, c: Complex64) -> Complex64 {
        let g = 1.0 - self.command_hold(f);
        p / (1.0 - g * c * p)
    }

    /// The plant behind a torque-point sweep's reading `reading` under controller `c`:
    /// `P = G/(1 + g·C·G)` (the inverse of [`Self::torque_sweep_reading`]).
    pub fn plant_of_torque_sweep(&self, f: f64, reading: Complex64, c: Complex64) -> Complex64 {
        let g = 1.0 - self.command_hold(f);
        reading / (1.0 + g * c * reading)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Gains from the commissioning's design for 1.5 kHz (its zero on the winding's pole:
    /// the closed loop `g/(z² − z + g)`, whose bandwidth the design sets in closed form): the
    /// model's −3 dB point is that bandwidth, unity at rest.
    #[test]
    fn a_loop_designed_for_a_bandwidth_has_it_in_the_model() {
        let mut p = control_core::Params::default();
        for (r, l) in [(1.2f32, 4e-4f32), (0.1, 2e-3), (5.0, 1e-4)] {
            let (kp, ki) = control_core::commissioning::design_current_loop(r, l, p.rates.tick_period(), 1500.0);
            (p.current.kp, p.current.ki) = (kp, ki);
            let d = DriveDynamics::new(&p, r as f64, l as f64, 0.0, 1.0);
            assert!((d.current_loop(0.5).norm() - 1.0).abs() < 1e-3);
            let bw = (1..40_000).map(|k| k as f64 * 0.1).find(|&f| d.current_loop(f).norm() < 0.5f64.sqrt()).unwrap();
            assert!((bw / 1500.0 - 1.0).abs() < 0.01, "R {r} L {l}: {bw} Hz");
        }
    }
}
