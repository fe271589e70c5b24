//! A motor, inverter and encoder for the commissioning tests, in f64 and written here from the
//! textbook equations (not the FMU's plant): what a real machine hides from the drive — the
//! rotor's angle at power-up, the encoder's direction, the current sensors' offsets and gain
//! errors, the inverter's dead-time voltage error, sensor noise — is a parameter here, and the
//! tests check that commissioning finds the motor's constants despite them.
//!
//! Electrical: `v_d = R i_d + L_d di_d/dt − ω L_q i_q` and `v_q = R i_q + L_q di_q/dt + ω (L_d
//! i_d + ψ)`, integrated with 32 sub-steps per tick (the explicit midpoint rule: far finer
//! than any estimator's tolerance). Mechanical: `J dω_m/dt = 1.5 p (ψ i_q + (L_d − L_q) i_d
//! i_q) − b ω_m − T_c sign(ω_m)`. The drive's voltage of a tick is applied over the next tick
//! (one tick of computation delay, as on the board and in the FMU).

extern crate std;

use std::f64::consts::TAU;

#[derive(Clone, Copy, Debug)]
pub struct MotorTruth {
    pub pole_pairs: u32,
    pub resistance: f64,
    pub ld: f64,
    pub lq: f64,
    pub flux_linkage: f64,
    pub inertia: f64,
    pub viscous: f64,
    pub coulomb: f64,
    /// Rotor's mechanical angle at power-up (rad): where the counter starts from 0.
    pub start_angle: f64,
    /// The encoder counts down when the rotor turns in the motor's positive direction.
    pub reversed: bool,
    pub counts_per_rev: u32,
    /// Current-sensor offsets (A) and gains (1 + error) of phases a and b.
    pub sensor_offset: [f64; 2],
    pub sensor_gain: [f64; 2],
    /// The inverter's dead-time error: each phase's voltage falls short by this, against its
    /// current (V).
    pub dead_time_volts: f64,
    /// Standard deviation of the current sensors' noise (A).
    pub noise: f64,
    /// Phase b disconnected (its current is forced to zero).
    pub open_phase_b: bool,
    /// The rotor cannot turn.
    pub locked: bool,
    /// No winding at all (the motor's cable unplugged): no current flows.
    pub disconnected: bool,
}

impl MotorTruth {
    pub fn default_motor() -> Self {
        Self {
            pole_pairs: 4,
            resistance: 0.3,
            ld: 0.5e-3,
            lq: 0.6e-3,
            flux_linkage: 0.1 / 6.0,
            inertia: 2e-5,
            viscous: 2e-5,
            coulomb: 0.002,
            start_angle: 1.234,
            reversed: false,
            counts_per_rev: 4000,
            sensor_offset: [0.0; 2],
            sensor_gain: [1.0; 2],
            dead_time_volts: 0.0,
            noise: 0.0,
            open_phase_b: false,
            locked: false,
            disconnected: false,
        }
    }
}

/// Reproducible unit-variance Gaussian samples (Box–Muller on xorshift64) for the test motor's
/// sensor noise and the fits' tests.
pub struct Gaussian(u64);

impl Gaussian {
    /// From a non-zero seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    pub fn next(&mut self) -> f64 {
        let mut uniform = || {
            self.0 ^= self.0 << 13;
            self.0 ^= self.0 >> 7;
            self.0 ^= self.0 << 17;
            ((self.0 >> 11) as f64 + 0.5) / (1u64 << 53) as f64
        };
        let (u1, u2) = (uniform(), uniform());
        (-2.0 * u1.ln()).sqrt() * (TAU * u2).cos()
    }
}

pub struct MotorModel {
    pub truth: MotorTruth,
    tick: f64,
    /// Rotor-frame currents (A), mechanical speed (rad/s) and angle (rad, from power-up's zero).
    id: f64,
    iq: f64,
    speed: f64,
    angle: f64,
    /// The voltage the drive asked for on the last tick (stator frame, V), applied over this one.
    pending: (f64, f64),
    rng: Gaussian,
    /// Largest |mechanical angle| moved from the start (rad), and the largest |speed|.
    pub excursion: f64,
    pub top_speed: f64,
    /// Largest phase current (A) and largest stator voltage asked for (V).
    pub peak_current: f64,
    pub peak_voltage: f64,
}

impl MotorModel {
    pub fn new(truth: MotorTruth, tick: f64) -> Self {
        Self {
            truth,
            tick,
            id: 0.0,
            iq: 0.0,
            speed: 0.0,
            angle: truth.start_angle,
            pending: (0.0, 0.0),
            rng: Gaussian::new(0x2545_F491_4F6C_DD1D),
            excursion: 0.0,
            top_speed: 0.0,
            peak_current: 0.0,
            peak_voltage: 0.0,
        }
    }

    /// The rotor's mechanical speed (rad/s).
    pub fn speed(&self) -> f64 {
        self.speed
    }

    fn electrical_angle(&self) -> f64 {
        self.truth.pole_pairs as f64 * self.angle
    }

    /// Phase currents a, b, c (A).
    fn phase_currents(&self) -> [f64; 3] {
        let (s, c) = self.electrical_angle().sin_cos();
        let alpha = self.id * c - self.iq * s;
        let beta = self.id * s + self.iq * c;
        let a = alpha;
        let b = -0.5 * alpha + 0.75f64.sqrt() * beta;
        [a, b, -a - b]
    }

    /// What the drive reads at the start of a tick: phase currents a and b (A) and the
    /// encoder's counter.
    pub fn sample(&mut self) -> ([f32; 2], i32) {
        let [a, b, _] = self.phase_currents();
        let t = self.truth;
        let mut read = [0.0f32; 2];
        for (k, i) in [a, b].into_iter().enumerate() {
            let n = if t.noise > 0.0 { t.noise * self.rng.next() } else { 0.0 };
            read[k] = (i * t.sensor_gain[k] + t.sensor_offset[k] + n) as f32;
        }
        // A quadrature counter: whole counts in its own direction.
        let turned = (self.angle - t.start_angle) / TAU * t.counts_per_rev as f64;
        let counts = (if t.reversed { -turned } else { turned }).floor();
        (read, counts as i64 as i32)
    }

    /// The drive's stator-frame voltage for the next tick (V); then one tick passes.
    pub fn apply(&mut self, alpha: f32, beta: f32) {
        let applied = self.pending;
        self.pending = (alpha as f64, beta as f64);
        self.peak_voltage = self.peak_voltage.max((alpha as f64).hypot(beta as f64));
        let t = self.truth;
        let n = 32;
        let h = self.tick / n as f64;
        let p = t.pole_pairs as f64;
        for _ in 0..n {
            // Dead time: each phase short by `dead_time_volts` against its current; the phase
            // voltages' error in the stator frame (the common mode drops out).
            let (mut va, mut vb) = applied;
            if t.dead_time_volts > 0.0 {
                let [ia, ib, ic] = self.phase_currents();
                let e = |i: f64| -t.dead_time_volts * i.signum();
                let (ea, eb, ec) = (e(ia), e(ib), e(ic));
                va += (2.0 * ea - eb - ec) / 3.0;
                vb += (eb - ec) / 3.0f64.sqrt();
            }
            let derivative = |id: f64, iq: f64, speed: f64, angle: f64| {
                let theta = p * angle;
                let (s, c) = theta.sin_cos();
                let vd = va * c + vb * s;
                let vq = -va * s + vb * c;
                let w = p * speed;
                let did = (vd - t.resistance * id + w * t.lq * iq) / t.ld;
                let diq = (vq - t.resistance * iq - w * (t.ld * id + t.flux_linkage)) / t.lq;
                let torque = 1.5 * p * (t.flux_linkage * iq + (t.ld - t.lq) * id * iq);
                let friction = t.viscous * speed + if speed.abs() > 1e-9 { t.coulomb * speed.signum() } else { 0.0 };
                let accel = if t.locked { 0.0 } else { (torque - friction) / t.inertia };
                (did, diq, accel, speed)
            };
            let (d1, q1, a1, w1) = derivative(self.id, self.iq, self.speed, self.angle);
            let (d2, q2, a2, w2) = derivative(
                self.id + 0.5 * h * d1,
                self.iq + 0.5 * h * q1,
                self.speed + 0.5 * h * a1,
                self.angle + 0.5 * h * w1,
            );
            self.id += h * d2;
            self.iq += h * q2;
            // Coulomb friction holds a rotor at rest below its breakaway torque.
            let new_speed = self.speed + h * a2;
            self.speed = if self.speed != 0.0 && new_speed.signum() != self.speed.signum() { 0.0 } else { new_speed };
            if self.speed == 0.0 && !t.locked {
                let torque = 1.5 * p * (t.flux_linkage * self.iq + (t.ld - t.lq) * self.id * self.iq);
                if torque.abs() > t.coulomb {
                    self.speed = h * (torque - t.coulomb * torque.signum()) / t.inertia;
                }
            }
            self.angle += h * w2;
            if t.open_phase_b {
                // No current through phase b: the stator current keeps to the a–c line, the
                // direction (cos 30°, sin 30°) of the stationary frame (where b = 0).
                let (s, c) = self.electrical_angle().sin_cos();
                let (alpha, beta) = (self.id * c - self.iq * s, self.id * s + self.iq * c);
                let (ux, uy) = (0.75f64.sqrt(), 0.5);
                let along = alpha * ux + beta * uy;
                let (alpha, beta) = (along * ux, along * uy);
                self.id = alpha * c + beta * s;
                self.iq = -alpha * s + beta * c;
            }
        }
        if t.disconnected {
            (self.id, self.iq) = (0.0, 0.0);
        }
        let [a, b, c] = self.phase_currents();
        self.peak_current = self.peak_current.max(a.abs().max(b.abs()).max(c.abs()));
        self.excursion = self.excursion.max((self.angle - t.start_angle).abs());
        self.top_speed = self.top_speed.max(self.speed.abs());
    }
}
