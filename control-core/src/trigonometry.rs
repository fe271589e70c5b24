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
    let z = r * r;
    let s = r + r * z * (-1.666_665_5e-1 + z * (8.332_161e-3 + z * -1.951_529_6e-4));
    let c = 1.0 - 0.5 * z + z * z * (4.166_664_6e-2 + z * (-1.388_731_6e-3 + z * 2.443_315_7e-5));
    match (k as i32) & 3 {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

pub fn sin(x: f32) -> f32 {
    sin_cos(x).0
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
}
