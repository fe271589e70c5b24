//! Fixed-point arithmetic of the Butterworth pulse filter: states in i64 counts with
//! [`FRACTION_BITS`] fractional bits, positive coefficients below 4 as a whole part and a 64-bit
//! fraction. A product is three 32 × 32 → 64-bit multiplies (UMULL/SMULL on a Cortex-M4) and no
//! shift; integer arithmetic gives the same bits on every target.

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
    // x >> 61 is 0 or −1 exactly when −2⁶¹ ≤ x < 2⁶¹: one compare of the high word.
    if ((x >> 61) + 1) as u64 > 1 {
        x.clamp(-STATE_LIMIT, STATE_LIMIT)
    } else {
        x
    }
}

/// A positive coefficient below 4: a whole part (0 to 3) and a fraction in units of 2⁻⁶⁴. A
/// coefficient of 1.4·10⁻⁷ (the smallest the design makes) keeps 41 significant bits, a relative
/// error of 5·10⁻¹³: 5·10⁻⁴ count on a lag of 10⁹.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Coefficient {
    whole: i64,
    fraction: u64,
}

impl Coefficient {
    /// A positive finite f64 below 4 (the design's range).
    pub(super) fn new(value: f64) -> Self {
        debug_assert!(value > 0.0 && value < 4.0, "coefficient {value} outside (0, 4)");
        let whole = libm::floor(value);
        // value − whole is exact; below 1, so its 2⁶⁴ multiple rounds to at most 2⁶⁴ − 2¹¹.
        let fraction = libm::round((value - whole) * 18_446_744_073_709_551_616.0) as u64;
        Self { whole: whole as i64, fraction }
    }

    /// `n · value` within a unit, for |n| ≤ 2⁶²: at most 2⁶² in magnitude below 1, clamped to
    /// ±2⁶¹ from 1 to 4 (which only pathological inputs reach).
    #[inline]
    pub(super) fn times(self, n: i64) -> i64 {
        let f = mul_high(n, self.fraction);
        if self.whole == 0 {
            f
        } else {
            n.saturating_mul(self.whole).saturating_add(f).clamp(-(1 << 61), 1 << 61)
        }
    }

    /// The value.
    #[cfg(test)]
    pub(super) fn value(self) -> f64 {
        self.whole as f64 + self.fraction as f64 * libm::exp2(-64.0)
    }
}

/// `n · m / 2⁶⁴` rounded, within a unit (the lowest partial product, below one unit, is left
/// out; the two cross products are rounded): three 32 × 32 → 64-bit multiplies.
#[inline]
fn mul_high(n: i64, m: u64) -> i64 {
    const HALF: u64 = 1 << 31;
    let (nh, nl) = (n >> 32, n as u32 as u64);
    let (mh, ml) = (m >> 32, m as u32 as u64);
    // nl·mh + 2³¹ < 2⁶⁴; |nh·ml| + 2³¹ < 2⁶³; |nh·mh| < 2⁶³ (|nh| < 2³¹): none overflows.
    nh * mh as i64 + ((nl * mh + HALF) >> 32) as i64 + ((nh * ml as i64 + HALF as i64) >> 32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// n · value from the exact product in 128 bits, as the reference.
    fn exact(n: i64, c: Coefficient) -> i128 {
        n as i128 * c.whole as i128 + ((n as i128 * c.fraction as i128) >> 64)
    }

    #[test]
    fn coefficients_keep_the_f64_value_to_2_to_the_minus_64() {
        for v in [1.5e-10, 1.54e-7, 3.9e-4, 0.499, 0.5, 0.75, 1.0, 1.37, 2.0, 3.99] {
            let c = Coefficient::new(v);
            assert!((c.value() - v).abs() <= libm::exp2(-64.0) + v * 1e-16, "{v}: {}", c.value());
        }
    }

    #[test]
    fn products_are_within_a_unit_of_the_exact_product() {
        let mut x = 0x1234_5678_9ABC_DEF1u64;
        for _ in 0..100_000 {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            let n = (x as i64) >> (2 + (x % 40)); // magnitudes from 2²² to 2⁶¹
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
