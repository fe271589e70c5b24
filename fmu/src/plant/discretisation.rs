//! Exact discretisation of linear time-invariant parts of the plant over a fixed step (the
//! matrix exponential and polynomial-hold input matrices built from it), and the fast sine
//! and cosine the per-tick code uses.

/// `exp(M)` by scaling and squaring with a Taylor series (f64; construction time only).
pub fn matrix_exponential<const N: usize>(m: &[[f64; N]; N]) -> [[f64; N]; N] {
    let norm = m.iter().map(|row| row.iter().map(|v| v.abs()).sum::<f64>()).fold(0.0, f64::max);
    // Scale so that the series converges fast: ‖M/2^s‖ ≤ 1/2.
    let mut squarings = 0;
    let mut scale = 1.0;
    while norm * scale > 0.5 {
        scale *= 0.5;
        squarings += 1;
    }
    let a = m.map(|row| row.map(|v| v * scale));
    let mut result = identity::<N>();
    let mut term = identity::<N>();
    // ‖A‖ ≤ 1/2: 18 terms leave a remainder below 2⁻¹⁸/18! ≈ 6e-22.
    for k in 1..=18 {
        term = multiply(&term, &a).map(|row| row.map(|v| v / k as f64));
        for (r, t) in result.iter_mut().zip(term.iter()) {
            for (x, y) in r.iter_mut().zip(t) {
                *x += y;
            }
        }
    }
    for _ in 0..squarings {
        result = multiply(&result, &result);
    }
    result
}

pub fn identity<const N: usize>() -> [[f64; N]; N] {
    let mut i = [[0.0; N]; N];
    for (k, row) in i.iter_mut().enumerate() {
        row[k] = 1.0;
    }
    i
}

pub fn multiply<const N: usize>(a: &[[f64; N]; N], b: &[[f64; N]; N]) -> [[f64; N]; N] {
    let mut c = [[0.0; N]; N];
    for i in 0..N {
        for j in 0..N {
            c[i][j] = (0..N).map(|k| a[i][k] * b[k][j]).sum();
        }
    }
    c
}

/// `x' = A·x + B·u` over a step `h` with a quadratic input
/// `u(s) = u0 + σ·(s/h) + κ·(s/h)²` (`σ = h·u'(0)`, `κ = h²·u''/2`; a ramp from `u0` to `u1`
/// is `σ = u1 − u0`, `κ = 0`): `x(h) = Φ·x(0) + Γ0·u0 + Γσ·σ + Γκ·κ` exactly.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PolynomialHold<const N: usize, const M: usize> {
    pub phi: [[f64; N]; N],
    pub gamma0: [[f64; M]; N],
    pub gamma_slope: [[f64; M]; N],
    pub gamma_curve: [[f64; M]; N],
}

impl<const N: usize, const M: usize> PolynomialHold<N, M> {
    /// Built from the exponential of the augmented system `[x; u; σ + 2κτ; κ]` over the
    /// normalised time `τ = s/h` (`T = N + 3·M`).
    pub fn new<const T: usize>(a: &[[f64; N]; N], b: &[[f64; M]; N], h: f64) -> Self {
        assert_eq!(T, N + 3 * M, "augmented size");
        let mut aug = [[0.0; T]; T];
        for i in 0..N {
            for j in 0..N {
                aug[i][j] = a[i][j] * h;
            }
            for j in 0..M {
                aug[i][N + j] = b[i][j] * h;
            }
        }
        for j in 0..M {
            // du/dτ = σ + 2κτ and d/dτ (σ + 2κτ) = 2κ.
            aug[N + j][N + M + j] = 1.0;
            aug[N + M + j][N + 2 * M + j] = 2.0;
        }
        let e = matrix_exponential(&aug);
        let zero = [[0.0; M]; N];
        let mut hold = Self { phi: [[0.0; N]; N], gamma0: zero, gamma_slope: zero, gamma_curve: zero };
        for i in 0..N {
            hold.phi[i].copy_from_slice(&e[i][..N]);
            hold.gamma0[i].copy_from_slice(&e[i][N..N + M]);
            hold.gamma_slope[i].copy_from_slice(&e[i][N + M..N + 2 * M]);
            hold.gamma_curve[i].copy_from_slice(&e[i][N + 2 * M..N + 3 * M]);
        }
        hold
    }

    /// `Φ·x + Γ0·u0 + Γσ·σ + Γκ·κ` when only the first input has a slope and a curve (`σ`,
    /// `κ`) and the others are held. The curve is added last: it is the input known last (the
    /// torque at the step's end, on the simulation's critical path).
    pub fn step_shaping_first(&self, x: &[f64; N], u0: &[f64; M], slope: f64, curve: f64) -> [f64; N] {
        let mut y = [0.0; N];
        for (i, yi) in y.iter_mut().enumerate() {
            let mut acc = 0.0;
            for j in 0..N {
                acc += self.phi[i][j] * x[j];
            }
            acc += self.gamma0[i][0] * u0[0] + self.gamma_slope[i][0] * slope;
            for j in 1..M {
                acc += self.gamma0[i][j] * u0[j];
            }
            *yi = acc + self.gamma_curve[i][0] * curve;
        }
        y
    }

    /// `Γσ·σ` alone (a correction of the slope after a first [`step`](Self::step)).
    pub fn slope_response(&self, slope: &[f64; M]) -> [f64; N] {
        let mut y = [0.0; N];
        for (i, yi) in y.iter_mut().enumerate() {
            *yi = (0..M).map(|j| self.gamma_slope[i][j] * slope[j]).sum();
        }
        y
    }
}

/// `(sin x, cos x)` within a few ulp for |x| < 1e6 rad (beyond: the `libm` crate):
/// Cody–Waite reduction by π/2, then Taylor polynomials on [−π/4, π/4].
pub fn sin_cos(x: f64) -> (f64, f64) {
    if !(x.abs() < 1.0e6) {
        return libm::sincos(x);
    }
    // π/2 in three parts, the first two with 33 significant bits, so that k·part is exact
    // for |k| < 2²⁰ (Cody–Waite reduction).
    const PI_2_A: f64 = 1.570_796_326_734_125_6;
    const PI_2_B: f64 = 6.077_100_506_303_966e-11;
    const PI_2_C: f64 = 2.022_266_248_795_950_6e-21;
    // Nearest quadrant by truncating conversion (no library call for `round`).
    let q = x * std::f64::consts::FRAC_2_PI;
    let quadrant = (q + if q < 0.0 { -0.5 } else { 0.5 }) as i64;
    let k = quadrant as f64;
    let r = ((x - k * PI_2_A) - k * PI_2_B) - k * PI_2_C;
    let r2 = r * r;
    // Taylor coefficients 1/n!; remainders below (π/4)¹⁷/17! ≈ 5e-17.
    const S: [f64; 8] = [
        1.0,
        -1.0 / 6.0,
        1.0 / 120.0,
        -1.0 / 5040.0,
        1.0 / 362_880.0,
        -1.0 / 39_916_800.0,
        1.0 / 6_227_020_800.0,
        -1.0 / 1_307_674_368_000.0,
    ];
    const C: [f64; 9] = [
        1.0,
        -1.0 / 2.0,
        1.0 / 24.0,
        -1.0 / 720.0,
        1.0 / 40_320.0,
        -1.0 / 3_628_800.0,
        1.0 / 479_001_600.0,
        -1.0 / 87_178_291_200.0,
        1.0 / 20_922_789_888_000.0,
    ];
    // Estrin's scheme: the same polynomials in a shallow tree instead of Horner's chain of
    // eight dependent multiply-adds (the sine and cosine are on the plant's critical path).
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    let pair = |k: [f64; 2]| k[0] + k[1] * r2;
    let s_low = pair([S[0], S[1]]) + pair([S[2], S[3]]) * r4;
    let s_high = pair([S[4], S[5]]) + pair([S[6], S[7]]) * r4;
    let s = r * (s_low + s_high * r8);
    let c_low = pair([C[0], C[1]]) + pair([C[2], C[3]]) * r4;
    let c_high = pair([C[4], C[5]]) + pair([C[6], C[7]]) * r4;
    let c = c_low + (c_high + C[8] * r8) * r8;
    match quadrant.rem_euclid(4) {
        0 => (s, c),
        1 => (c, -s),
        2 => (-s, -c),
        _ => (-c, s),
    }
}

/// `cosh(√z)` and `sinh(√z)/√z` for any real `z` (negative `z`: `cos` and `sin(x)/x`).
/// Series near zero, where the closed forms lose precision.
pub fn cosh_sinhc(z: f64) -> (f64, f64) {
    if z.abs() < 0.25 {
        // Remainders below 0.25⁶/12! ≈ 5e-13 relative.
        // Coefficients 1/(2k)! and 1/(2k+1)!.
        const C: [f64; 6] = [1.0, 1.0 / 2.0, 1.0 / 24.0, 1.0 / 720.0, 1.0 / 40_320.0, 1.0 / 3_628_800.0];
        const S: [f64; 6] = [1.0, 1.0 / 6.0, 1.0 / 120.0, 1.0 / 5040.0, 1.0 / 362_880.0, 1.0 / 39_916_800.0];
        // Estrin's scheme (a shallow tree, not a chain: this is on the plant's critical path).
        let z2 = z * z;
        let z4 = z2 * z2;
        let poly = |k: [f64; 6]| (k[0] + k[1] * z) + (k[2] + k[3] * z) * z2 + (k[4] + k[5] * z) * z4;
        (poly(C), poly(S))
    } else if z > 0.0 {
        let r = z.sqrt();
        (libm::cosh(r), libm::sinh(r) / r)
    } else {
        let r = (-z).sqrt();
        let (s, c) = libm::sincos(r);
        (c, s / r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exponential_of_a_rotation_generator_is_a_rotation() {
        // exp([[0, w], [−w, 0]]) = [[cos w, sin w], [−sin w, cos w]], here with ‖M‖ ≫ 1.
        let w = 37.3;
        let e = matrix_exponential(&[[0.0, w], [-w, 0.0]]);
        let want = [[w.cos(), w.sin()], [-w.sin(), w.cos()]];
        for i in 0..2 {
            for j in 0..2 {
                assert!((e[i][j] - want[i][j]).abs() < 1e-11, "{e:?} vs {want:?}");
            }
        }
    }

    #[test]
    fn polynomial_hold_matches_the_closed_form_of_a_first_order_lag() {
        // x' = −a·x + u with u(s) = u0 + d1·s + d2·s². By parts, with
        // U(s) = u(s)/a − u'(s)/a² + u''/a³: x(h) = e^{−ah}·x0 + U(h) − e^{−ah}·U(0).
        let (a, h, x0, u0, d1, d2) = (3.0f64, 0.2f64, 0.7, 1.5, -4.0, 9.0);
        let hold = PolynomialHold::<1, 1>::new::<4>(&[[-a]], &[[1.0]], h);
        let got = hold.step_shaping_first(&[x0], &[u0], d1 * h, d2 * h * h)[0];
        let e = (-a * h).exp();
        let big_u = |s: f64| (u0 + d1 * s + d2 * s * s) / a - (d1 + 2.0 * d2 * s) / (a * a) + 2.0 * d2 / (a * a * a);
        let want = e * x0 + big_u(h) - e * big_u(0.0);
        assert!((got - want).abs() < 1e-14, "{got} vs {want}");
        let split = hold.step_shaping_first(&[x0], &[u0], 0.0, d2 * h * h)[0] + hold.slope_response(&[d1 * h])[0];
        assert!((split - want).abs() < 1e-14, "{split} vs {want}");
    }

    #[test]
    fn fast_sine_and_cosine_match_the_standard_library() {
        let mut worst: f64 = 0.0;
        for i in -200_000..200_000 {
            let x = i as f64 * 0.013_7 + 0.001;
            let (s, c) = sin_cos(x);
            worst = worst.max((s - x.sin()).abs()).max((c - x.cos()).abs());
        }
        assert!(worst < 2e-15, "worst difference {worst:e}");
    }

    #[test]
    fn hyperbolic_helpers_agree_with_the_closed_forms_across_the_switch() {
        for z in [-3.0, -0.26, -0.24, -1e-3, 0.0, 1e-3, 0.24, 0.26, 2.0] {
            let (c, s) = cosh_sinhc(z);
            let (wc, ws) = if z > 0.0 {
                (z.sqrt().cosh(), z.sqrt().sinh() / z.sqrt())
            } else if z < 0.0 {
                ((-z).sqrt().cos(), (-z).sqrt().sin() / (-z).sqrt())
            } else {
                (1.0, 1.0)
            };
            assert!((c - wc).abs() < 1e-12 && (s - ws).abs() < 1e-12, "z = {z}: {c} {s} vs {wc} {ws}");
        }
    }
}
