//! The square root the loops use every tick.
//!
//! IEEE 754 requires the square root to be correctly rounded, so every conforming
//! implementation gives the same bits: libm's (SSE `sqrtss` on x86-64, a software routine on
//! a Cortex-M4F) and the M4F's `VSQRT` instruction alike. With the `fpu-sqrt` feature the
//! firmware uses the instruction (one instead of about a hundred).

#[inline]
pub fn sqrt(x: f32) -> f32 {
    #[cfg(feature = "fpu-sqrt")]
    {
        core::f32::math::sqrt(x)
    }
    #[cfg(not(feature = "fpu-sqrt"))]
    {
        libm::sqrtf(x)
    }
}

#[cfg(test)]
mod tests {
    /// Correct rounding, checked against the exact square in f64: the result r is the f32
    /// nearest √x when x lies between the squares of the midpoints around r.
    #[test]
    fn square_roots_are_correctly_rounded() {
        let mut x = 1.0e-6f32;
        while x < 1.0e6 {
            let r = super::sqrt(x);
            let (below, above) = (f32::from_bits(r.to_bits() - 1), f32::from_bits(r.to_bits() + 1));
            let (lo, hi) = ((below as f64 + r as f64) / 2.0, (r as f64 + above as f64) / 2.0);
            assert!(lo * lo <= x as f64 && x as f64 <= hi * hi, "sqrt({x}) = {r}");
            x *= 1.000_37;
        }
        assert!(super::sqrt(-1.0).is_nan());
        assert_eq!(super::sqrt(0.0), 0.0);
    }
}
