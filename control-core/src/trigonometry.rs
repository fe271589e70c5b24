//! Sine and cosine in f32 arithmetic only. libm's `sincosf` evaluates its kernels in f64,
//! which a Cortex-M4F has no hardware for (software floating point, hundreds of instructions
//! per call); these run on the single-precision FPU, and give the same bits on every target
//! (plain f32 operations, no fused multiply-add).
//!
//! Reduction by π/2 in three parts (Cody–Waite, exact products for |x| up to about 10⁴; the
//! result is meant for angles, |x| < 2²² at the very most) and
//! the minimax polynomials of Cephes' `sinf`/`cosf` on [−π/4, π/4]: error ≲ 2·10⁻⁷.

/// `(sin x, cos x)`.
pub fn sin_cos(x: f32) -> (f32, f32) {
    ReducedAngle::new(x).sin_cos()
}

pub fn sin(x: f32) -> f32 {
    ReducedAngle::new(x).sin()
}

/// An angle reduced to `[−π/4, π/4]` and its quadrant: the sine or the cosine alone then costs
/// one polynomial (a generator that needs the cosine only on some ticks keeps this and
/// evaluates the cosine when it needs it), with the same bits as [`sin_cos`].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ReducedAngle {
    quadrant: u32,
    r: f32,
    z: f32,
}

impl ReducedAngle {
    #[inline(always)]
    pub fn new(x: f32) -> Self {
        // Cephes' constant as printed: one ulp from core's FRAC_2_PI, and changing it would change
        // the core's output bits (the golden vectors pin them).
        #[allow(clippy::approx_constant)]
        const FRAC_2_PI: f32 = 0.636_619_8;
        const PIO2_1: f32 = 1.570_312_5;
        const PIO2_2: f32 = 4.837_513e-4;
        const PIO2_3: f32 = 7.549_79e-8;
        // Round to the nearest integer with two f32 additions (1.5·2²³ leaves no fraction bits;
        // exact for |x·2/π| < 2²²): no library call, same bits everywhere.
        const ROUNDER: f32 = 12_582_912.0;
        let k = (x * FRAC_2_PI + ROUNDER) - ROUNDER;
        let r = ((x - k * PIO2_1) - k * PIO2_2) - k * PIO2_3;
        Self { quadrant: (k as i32 as u32) & 3, r, z: r * r }
    }

    /// The angle of a phase accumulator's word (one turn is 2³²), reduced in integers: the
    /// nearest quarter turn is the word's top two bits after adding an eighth of a turn, and
    /// the rest is exact in the low 30 bits (sign-extended: ±2²⁹, an eighth of a turn);
    /// only its conversion to radians rounds (relative error ≲ 2⁻²³, against the float
    /// reduction's ~4·10⁻⁷ rad of the angle's own rounding near 2π and its 8 dropped bits).
    #[inline(always)]
    pub fn of_phase_word(word: u32) -> Self {
        // 2π / 2³² (a power-of-two scaling of f32 TAU: exact).
        const RADIANS_PER_UNIT: f32 = core::f32::consts::TAU / 4_294_967_296.0;
        let quadrant = word.wrapping_add(1 << 29) >> 30;
        let rest = ((word << 2) as i32) >> 2;
        let r = rest as f32 * RADIANS_PER_UNIT;
        Self { quadrant, r, z: r * r }
    }

    /// The sine polynomial of the reduced angle.
    #[inline(always)]
    fn sin_r(&self) -> f32 {
        let (r, z) = (self.r, self.z);
        r + r * z * (-1.666_665_5e-1 + z * (8.332_161e-3 + z * -1.951_529_6e-4))
    }

    /// The cosine polynomial of the reduced angle.
    #[inline(always)]
    fn cos_r(&self) -> f32 {
        let z = self.z;
        1.0 - 0.5 * z + z * z * (4.166_664_6e-2 + z * (-1.388_731_6e-3 + z * 2.443_315_7e-5))
    }

    /// The sine: the one polynomial the quadrant needs.
    #[inline(always)]
    pub fn sin(&self) -> f32 {
        match self.quadrant {
            0 => self.sin_r(),
            1 => self.cos_r(),
            2 => -self.sin_r(),
            _ => -self.cos_r(),
        }
    }

    /// The cosine: the one polynomial the quadrant needs.
    #[inline(always)]
    pub fn cos(&self) -> f32 {
        match self.quadrant {
            0 => self.cos_r(),
            1 => -self.sin_r(),
            2 => -self.cos_r(),
            _ => self.sin_r(),
        }
    }

    #[inline(always)]
    pub fn sin_cos(&self) -> (f32, f32) {
        let (s, c) = (self.sin_r(), self.cos_r());
        match self.quadrant {
            0 => (s, c),
            1 => (c, -s),
            2 => (-s, -c),
            _ => (-c, s),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn matches_the_f64_functions_over_many_turns() {
        let mut worst = 0.0f64;
        for i in -200_000..=200_000 {
            let x = i as f32 * 1.0e-3; // ±200 rad: 32 turns either way
            let (s, c) = sin_cos(x);
            let xd = x as f64;
            worst = worst.max((s as f64 - xd.sin()).abs()).max((c as f64 - xd.cos()).abs());
        }
        assert!(worst < 3e-7, "largest error {worst:e}");
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
    }

    #[test]
    fn a_phase_word_reduces_to_the_f64_functions_of_its_angle() {
        let mut worst = 0.0f64;
        let mut check = |word: u32| {
            let a = ReducedAngle::of_phase_word(word);
            let x = word as f64 * (core::f64::consts::TAU / 4_294_967_296.0);
            let (s, c) = a.sin_cos();
            assert_eq!((a.sin().to_bits(), a.cos().to_bits()), (s.to_bits(), c.to_bits()), "word {word:#x}");
            worst = worst.max((s as f64 - x.sin()).abs()).max((c as f64 - x.cos()).abs());
        };
        // Every quadrant's edges (an eighth of a turn either side of a quarter) and the ends.
        for q in 0..8u32 {
            for d in 0..64u32 {
                check((q << 29).wrapping_add(d));
                check((q << 29).wrapping_sub(d + 1));
            }
        }
        // A pseudo-random spread of words.
        let mut x = 0x9E37_79B9u32;
        for _ in 0..400_000 {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            check(x);
        }
        assert!(worst < 2.5e-7, "largest error {worst:e}");
    }

    #[test]
    fn sine_and_cosine_alone_have_the_bits_of_the_pair() {
        for i in -200_000..=200_000 {
            let x = i as f32 * 1.0e-3;
            let a = ReducedAngle::new(x);
            let (s, c) = sin_cos(x);
            assert_eq!((a.sin().to_bits(), a.cos().to_bits()), (s.to_bits(), c.to_bits()), "x = {x}");
        }
    }
}
