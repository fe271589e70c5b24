//! Clarke and Park transforms and space-vector modulation.

/// 1/√3
const INV_SQRT3: f32 = 0.577_350_26;
/// √3/2
const SQRT3_HALF: f32 = 0.866_025_4;

/// A two-component vector in the stationary (α, β) frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct AlphaBeta {
    pub alpha: f32,
    pub beta: f32,
}

/// A two-component vector in the rotor (d, q) frame.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Dq {
    pub d: f32,
    pub q: f32,
}

/// Amplitude-invariant Clarke transform from two measured phase currents
/// (the third is `-(a + b)` for a star connection without neutral).
pub fn clarke(a: f32, b: f32) -> AlphaBeta {
    AlphaBeta { alpha: a, beta: (a + 2.0 * b) * INV_SQRT3 }
}

/// Park transform with precomputed `sin θe`, `cos θe`.
pub fn park(v: AlphaBeta, sin: f32, cos: f32) -> Dq {
    Dq { d: v.alpha * cos + v.beta * sin, q: -v.alpha * sin + v.beta * cos }
}

/// Inverse Park transform.
pub fn inverse_park(v: Dq, sin: f32, cos: f32) -> AlphaBeta {
    AlphaBeta { alpha: v.d * cos - v.q * sin, beta: v.d * sin + v.q * cos }
}

/// Space-vector PWM by min-max zero-sequence injection.
///
/// Returns the three duty cycles in `[0, 1]` for a voltage vector that lies inside the
/// hexagon's inscribed circle (`|v| ≤ v_bus / √3`); the current loop guarantees that.
pub fn space_vector_duties(v: AlphaBeta, bus_voltage: f32) -> [f32; 3] {
    let va = v.alpha;
    let vb = -0.5 * v.alpha + SQRT3_HALF * v.beta;
    let vc = -0.5 * v.alpha - SQRT3_HALF * v.beta;
    // Plain comparisons, not f32::max/min: those also pick the number out of a NaN pair,
    // which costs a chain of extra instructions; a non-finite voltage latches a fault and the
    // bridge is off in the same tick, so the duties of that case are never applied.
    let larger = |a: f32, b: f32| if a > b { a } else { b };
    let smaller = |a: f32, b: f32| if a < b { a } else { b };
    let max = larger(larger(va, vb), vc);
    let min = smaller(smaller(va, vb), vc);
    let common = 0.5 * (max + min);
    let inv = 1.0 / bus_voltage;
    [clamp01(0.5 + (va - common) * inv), clamp01(0.5 + (vb - common) * inv), clamp01(0.5 + (vc - common) * inv)]
}

/// `x.clamp(0.0, 1.0)`, NaN included, without the library's NaN-preserving min/max chain.
fn clamp01(x: f32) -> f32 {
    if x < 0.0 {
        0.0
    } else if x > 1.0 {
        1.0
    } else {
        x
    }
}

/// Radius of the largest voltage circle SVPWM can produce linearly: `v_bus / √3`.
pub fn voltage_circle_radius(bus_voltage: f32) -> f32 {
    bus_voltage * INV_SQRT3
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clarke_of_balanced_set_is_a_rotating_vector_of_same_amplitude() {
        for k in 0..36 {
            let th = k as f32 * 10.0f32.to_radians();
            let a = libm::cosf(th);
            let b = libm::cosf(th - 2.094_395_1);
            let ab = clarke(a, b);
            assert!((ab.alpha - libm::cosf(th)).abs() < 1e-5);
            assert!((ab.beta - libm::sinf(th)).abs() < 1e-5);
        }
    }

    #[test]
    fn park_and_inverse_park_round_trip() {
        let v = Dq { d: 0.3, q: -1.7 };
        let (s, c) = (libm::sinf(0.7), libm::cosf(0.7));
        let back = park(inverse_park(v, s, c), s, c);
        assert!((back.d - v.d).abs() < 1e-6 && (back.q - v.q).abs() < 1e-6);
    }

    #[test]
    fn svpwm_reproduces_the_line_voltages() {
        let vbus = 48.0;
        for k in 0..72 {
            let th = k as f32 * 5.0f32.to_radians();
            let r = voltage_circle_radius(vbus) * 0.999;
            let v = AlphaBeta { alpha: r * libm::cosf(th), beta: r * libm::sinf(th) };
            let d = space_vector_duties(v, vbus);
            // Reconstruct α/β from the pole voltages.
            let alpha = vbus * (2.0 * d[0] - d[1] - d[2]) / 3.0;
            let beta = vbus * (d[1] - d[2]) * INV_SQRT3;
            assert!((alpha - v.alpha).abs() < 1e-3, "alpha at {k}");
            assert!((beta - v.beta).abs() < 1e-3, "beta at {k}");
            assert!(d.iter().all(|x| (0.0..=1.0).contains(x)));
        }
    }
}
