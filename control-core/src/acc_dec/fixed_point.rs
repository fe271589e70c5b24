//! Fixed-point arithmetic of the Butterworth pulse filter: states in i64 counts with
//! [`FRACTION_BITS`] fractional bits, positive coefficients below 4 as a whole part and a 62-bit
//! fraction. A product is three signed 32 × 32 → 64-bit multiplies (SMULL/SMLAL on a
//! Cortex-M4) and one shift; integer arithmetic gives the same bits on every target.

/// Fractional bits of the states: 2⁻³⁰ counts (9.3·10⁻¹⁰).
pub(super) const FRACTION_BITS: u32 = 30;
/// Largest magnitude of a state: 2³¹ counts. With inputs, states and coefficients bounded
/// like this no intermediate sum of a tick can overflow (see `ButterworthPulseFilter::step`).
pub(super) const STATE_LIMIT: i64 = 1 << 61;

/// Keep a state within ±[`STATE_LIMIT`] (never reached by the moves of up to 10⁹ counts the
/// filter is checked on; beyond, the filter's lag saturates and the excess pulses pass
/// straight through, still counted).
#[inline]
pub(super) fn limit(x: i64) -> i64 {
    // Within ±2⁶¹ exactly when the high word is in [−2²⁹, 2²⁹): one add and compare.
    if (((x >> 32) as i32).wrapping_add(1 << 29) as u32) < 1 << 30 {
        x
    } else {
        clamp_state(x)
    }
}

#[cold]
#[inline(never)]
fn clamp_state(x: i64) -> i64 {
    x.clamp(-STATE_LIMIT, STATE_LIMIT - 1)
}

/// A positive coefficient below 4: a whole part (0 to 3) and a fraction in units of 2⁻⁶², held
/// as two 31-bit halves so that every partial product is a signed 32 × 32 → 64-bit multiply
/// (SMULL/SMLAL). A coefficient of 1.4·10⁻⁷ (the smallest the design makes) keeps 39
/// significant bits, a relative error of 2·10⁻¹²: 2·10⁻³ count on a lag of 10⁹.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Coefficient {
    whole: i32,
    high: i32,
    low: i32,
}

impl Coefficient {
    /// A positive finite f64 below 4 (the design's range).
    pub(super) fn new(value: f64) -> Self {
        debug_assert!(value > 0.0 && value < 4.0, "coefficient {value} outside (0, 4)");
        let whole = libm::floor(value);
        // value − whole is exact and below 1 − 2⁻⁵²: its 2⁶² multiple rounds below 2⁶².
        let fraction = libm::round((value - whole) * 4_611_686_018_427_387_904.0) as u64;
        Self { whole: whole as i32, high: (fraction >> 31) as i32, low: (fraction & 0x7FFF_FFFF) as i32 }
    }

    /// `n · value` within a unit, for |n| < 2⁶²: at most 2⁶² in magnitude below 1, clamped to
    /// ±2⁶¹ from 1 to 4 (which only pathological inputs reach).
    #[inline]
    pub(super) fn times(self, n: i64) -> i64 {
        // n = nh·2³¹ + nl with 0 ≤ nl < 2³¹; fraction = high·2³¹ + low.
        let (nh, nl) = ((n >> 31) as i32 as i64, (n & 0x7FFF_FFFF) as i32 as i64);
        let (high, low) = (self.high as i64, self.low as i64);
        // The cross products at 2⁻³¹ of a unit, plus half a unit to round and half a unit for
        // the left-out nl·low (below one unit, half on average): unbiased.
        let cross = (1i64 << 31) + nh * low + nl * high;
        let f = nh * high + (cross >> 31);
        if self.whole == 0 {
            f
        } else {
            n.saturating_mul(self.whole as i64).saturating_add(f).clamp(-(1 << 61), 1 << 61)
        }
    }

    /// The value.
    #[cfg(test)]
    pub(super) fn value(self) -> f64 {
        self.whole as f64 + (((self.high as u64) << 31) | self.low as u64) as f64 * libm::exp2(-62.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// n · value from the exact product in 128 bits, as the reference.
    fn exact(n: i64, c: Coefficient) -> i128 {
        let fraction = ((c.high as i128) << 31) | c.low as i128;
        n as i128 * c.whole as i128 + ((n as i128 * fraction) >> 62)
    }

    #[test]
    fn coefficients_keep_the_f64_value_to_2_to_the_minus_62() {
        for v in [1.5e-10, 1.54e-7, 3.9e-4, 0.499, 0.5, 0.75, 1.0, 1.37, 2.0, 3.99] {
            let c = Coefficient::new(v);
            assert!((c.value() - v).abs() <= libm::exp2(-62.0) + v * 1e-16, "{v}: {}", c.value());
        }
    }

    #[test]
    fn products_are_within_a_unit_of_the_exact_product() {
        let mut x = 0x1234_5678_9ABC_DEF1u64;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let n = (x as i64) >> (2 + (x % 40)); // magnitudes from 2²² to just below 2⁶²
            let v = libm::exp2(-(((x >> 20) % 40) as f64)) * (1.0 + (x >> 44) as f64 / (1u64 << 20) as f64) * 1.9;
            let c = Coefficient::new(v);
            let (got, want) = (c.times(n) as i128, exact(n, c));
            if v >= 1.0 && want.abs() >= 1 << 61 {
                // From 1 to 4, products beyond 2⁶¹ clamp there.
                assert_eq!(got.abs(), 1 << 61, "{n} × {v}");
                continue;
            }
            // The floor in `exact` (1), the two rounded cross products and the left-out one.
            assert!((got - want).abs() <= 2, "{n} × {v}: {got} vs {want}");
        }
    }
}
