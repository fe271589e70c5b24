//! xorshift64*: a small, reproducible generator for the benches and campaigns (a seed names
//! a run; no statistical claims beyond that).

#[derive(Clone, Debug)]
pub struct XorShift64Star(pub u64);

impl XorShift64Star {
    /// The generator a bench's `--plant-seed` names (any seed, 0 included: the state is
    /// spread over the word and kept odd, never the all-zero state xorshift cannot leave).
    pub fn from_seed(seed: u64) -> Self {
        Self(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15) | 1)
    }

    pub fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_F491_4F6C_DD1D)
    }

    /// A number in 0..n (n > 0).
    pub fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }

    /// A number in [0, 1): the top 53 bits of the next word.
    pub fn uniform(&mut self) -> f64 {
        (self.next() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// A number log-uniform over lo..hi (0 < lo < hi), rounded to three significant digits so
    /// that a printed draw can be run again by hand, and kept within lo..=hi (where a bound has
    /// more digits the rounding could step past it).
    pub fn log_uniform_3_digits(&mut self, lo: f64, hi: f64) -> f64 {
        let u = self.uniform();
        let x = (lo.ln() + u * (hi.ln() - lo.ln())).exp();
        let scale = 10f64.powi(2 - x.log10().floor() as i32);
        ((x * scale).round() / scale).clamp(lo, hi)
    }
}
