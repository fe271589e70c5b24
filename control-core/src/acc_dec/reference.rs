//! The Butterworth acc/dec filter computed in f64, as the reference the drive's integer filter
//! is checked against (unit tests, `servo bench accdec`, the study's ideal profiles). Not used
//! by the drive.
//!
//! Independent of the drive's form and design code: the analogue poles
//! `s_k = ωc·e^{jπ(2k + N − 1)/(2N)}` are mapped by a complex exponential, and each pole pair
//! `c0/((1 − z·z⁻¹)(1 − z̄·z⁻¹))`, `c0 = |1 − z|²`, runs in modal form: one complex state
//! `x ← z·x + u`, output `2·Re(A·x)` with `A = c0·z/(z − z̄)`, lag `2·Re(B·x)` with
//! `B = A·z/(1 − z)` (the partial fractions of `(1 − G)/(1 − z⁻¹)`, whose pole at `z = 1`
//! cancels). The real pole: `x ← p·x + u`, output `(1 − p)·x`, lag `p·x`. The zeros at `z = −1`
//! and the delays come last, as a finite impulse response on the real signal. Nothing here
//! divides by `|1 − z|²`, so the rounding of f64 is not amplified by `1/(ωc·T)²`; the coarsest
//! step is `1 − z` itself (relative error ~10⁻¹⁶/(ωc·T)).

use super::butterworth::{ZeroPlacement, MAX_ORDER};

#[derive(Clone, Copy, Debug, PartialEq)]
struct Complex {
    re: f64,
    im: f64,
}

impl Complex {
    fn new(re: f64, im: f64) -> Self {
        Self { re, im }
    }
    fn mul(self, o: Self) -> Self {
        Self::new(self.re * o.re - self.im * o.im, self.re * o.im + self.im * o.re)
    }
    fn div(self, o: Self) -> Self {
        let d = o.re * o.re + o.im * o.im;
        Self::new((self.re * o.re + self.im * o.im) / d, (self.im * o.re - self.re * o.im) / d)
    }
    fn scale(self, k: f64) -> Self {
        Self::new(self.re * k, self.im * k)
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
struct Mode {
    pole: Complex,
    output: Complex,
    lag: Complex,
    state: Complex,
}

/// The f64 reference filter: pulses (any real number) in, output and lag out.
#[derive(Clone, Debug, PartialEq)]
pub struct ReferenceFilter {
    modes: [Option<Mode>; 3],
    real: Option<(f64, f64)>,
    /// Finite impulse response of the zeros, tap `j` on the input `j` ticks ago (sum 1).
    taps: [f64; MAX_ORDER as usize + 1],
    history: [f64; MAX_ORDER as usize + 1],
}

impl ReferenceFilter {
    /// Order 1 to 6, any cut-off up to Nyquist, any positive period (not checked: a reference).
    pub fn new(order: u32, cutoff_hz: f64, sample_period: f64, zeros: ZeroPlacement) -> Self {
        let n = order as usize;
        let wc = core::f64::consts::TAU * cutoff_hz;
        let mut modes = [None; 3];
        let mut real = None;
        let mut pair = 0;
        for k in 1..=n {
            let angle = core::f64::consts::PI * (2 * k + n - 1) as f64 / (2 * n) as f64;
            let (sr, si) = (wc * libm::cos(angle), wc * libm::sin(angle));
            if si > 1e-9 * wc {
                let r = libm::exp(sr * sample_period);
                let z = Complex::new(r * libm::cos(si * sample_period), r * libm::sin(si * sample_period));
                let one_minus_z = Complex::new(1.0 - z.re, -z.im);
                let c0 = one_minus_z.re * one_minus_z.re + one_minus_z.im * one_minus_z.im;
                let output = z.scale(c0).div(Complex::new(0.0, 2.0 * z.im));
                let lag = output.mul(z).div(one_minus_z);
                modes[pair] = Some(Mode { pole: z, output, lag, state: Complex::new(0.0, 0.0) });
                pair += 1;
            } else if si.abs() <= 1e-9 * wc {
                real = Some((libm::exp(sr * sample_period), 0.0));
            }
        }
        // The zeros: z⁻¹·((1 + z⁻¹)/2)^{N−1} or z⁻ᴺ.
        let mut taps = [0.0; MAX_ORDER as usize + 1];
        match zeros {
            ZeroPlacement::Seed => {
                let mut c = 1.0;
                for j in 0..n {
                    taps[j + 1] = c / (1u32 << (n - 1)) as f64;
                    c = c * (n - 1 - j) as f64 / (j + 1) as f64;
                }
            }
            ZeroPlacement::AllDelays => taps[n] = 1.0,
        }
        Self { modes, real, taps, history: [0.0; MAX_ORDER as usize + 1] }
    }

    /// One tick: returns (output this tick, lag after it): the lag is what the filter would
    /// still give out if the input stopped now.
    pub fn step(&mut self, pulses: f64) -> (f64, f64) {
        let mut x = pulses;
        let mut lag = 0.0;
        for m in self.modes.iter_mut().rev().flatten() {
            m.state = m.pole.mul(m.state);
            m.state.re += x;
            x = 2.0 * m.output.mul(m.state).re;
            lag += 2.0 * m.lag.mul(m.state).re;
        }
        if let Some((p, state)) = &mut self.real {
            *state = *p * *state + x;
            x = (1.0 - *p) * *state;
            lag += *p * *state;
        }
        self.history.rotate_right(1);
        self.history[0] = x;
        let mut output = 0.0;
        let mut left = 1.0;
        for (tap, h) in self.taps.iter().zip(&self.history) {
            output += tap * h;
            left -= tap;
            lag += left * h;
        }
        (output, lag)
    }
}
