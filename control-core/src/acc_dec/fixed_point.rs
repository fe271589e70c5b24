//! Fixed-point arithmetic of the Butterworth pulse filter: states in i64 counts with
//! [`FRACTION_BITS`] fractional bits, and positive coefficients below 4 as a 64-bit mantissa with
//! a binary exponent (every coefficient keeps its 53 significant bits from the f64 design, however
//! small it is). A product is three 32 × 32 → 64-bit multiplies (UMULL/SMULL on a Cortex-M4) and
//! a rounding shift; integer arithmetic gives the same bits on every target.

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

/// A coefficient `mantissa · 2^−(64 + shift)`, `0 < value < 4`, mantissa normalised (top bit set).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) struct Coefficient {
    mantissa: u64,
    /// Right shift after the 64-bit high product; −1 or −2 for values of 1 to 4.
    shift: i32,
    /// Half a unit of the shifted result, added before shifting (round half up).
    half: i64,
}

impl Coefficient {
    /// The exact value of a positive finite f64 below 4 and above 2⁻⁶⁰ (the design checks the
    /// range before building its coefficients).
    pub(super) fn new(value: f64) -> Self {
        debug_assert!(value > 8.7e-19 && value < 4.0, "coefficient {value} outside (2^-60, 4)");
        let bits = value.to_bits();
        let exponent = ((bits >> 52) & 0x7FF) as i32 - 1023;
        // value = 1.f · 2^exponent = (1.f · 2⁶³) · 2^(exponent − 63).
        let mantissa = ((bits & ((1 << 52) - 1)) | (1 << 52)) << 11;
        let shift = -1 - exponent;
        let half = if shift > 0 { 1i64 << (shift - 1) } else { 0 };
        Self { mantissa, shift, half }
    }

    /// `round(n · value)` for |n| ≤ 2⁶²: at most 2⁶² in magnitude below 1, 2⁶¹ from 1 to 4 (a
    /// clamp only pathological inputs reach).
    #[inline]
    pub(super) fn times(self, n: i64) -> i64 {
        let t = mul_high(n, self.mantissa);
        if self.shift >= 0 {
            (t + self.half) >> self.shift
        } else {
            t.clamp(-(1 << 59), 1 << 59) << -self.shift
        }
    }

    /// The value.
    #[cfg(test)]
    pub(super) fn value(self) -> f64 {
        self.mantissa as f64 * libm::exp2(-(64 + self.shift) as f64)
    }
}

/// `⌊n · m / 2⁶⁴⌋` within −3 (the lowest partial product, below 2⁻³² of a unit, is left out).
#[inline]
fn mul_high(n: i64, m: u64) -> i64 {
    let (nh, nl) = (n >> 32, n as u32 as u64);
    let (mh, ml) = ((m >> 32) as i64, m as u32 as i64);
    // nl·mh < 2⁶⁴; |nh·ml| < 2⁶³; |nh·mh| < 2⁶³: none overflows.
    nh * mh + ((nl * mh as u64) >> 32) as i64 + ((nh * ml) >> 32)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ⌊n · value⌋ from the exact product in 128 bits, as the reference.
    fn exact(n: i64, c: Coefficient) -> i128 {
        (n as i128 * c.mantissa as i128) >> (64 + c.shift)
    }

    #[test]
    fn coefficients_keep_the_f64_value_exactly() {
        for v in [1.5e-10, 1.54e-7, 3.9e-4, 0.499, 0.5, 0.75, 1.0, 1.37, 2.0, 3.99] {
            assert_eq!(Coefficient::new(v).value(), v);
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
            let clamp = (1i128 << 59) << (-c.shift).max(0);
            if c.shift < 0 && want.abs() >= clamp {
                // From 1 to 4, products beyond 2⁵⁹·2^−shift (≤ 2⁶¹) clamp there.
                assert_eq!(got.abs(), clamp, "{n} × {v}");
                continue;
            }
            // Rounding (one unit from the floor) and the left-out partial product (3 units
            // before the shift, 12 after a left shift by 2).
            let bound = 1 + (3 >> c.shift.max(0)) + (3 << (-c.shift).max(0));
            assert!((got - want).abs() <= bound, "{n} × {v}: {got} vs {want}");
        }
    }
}
