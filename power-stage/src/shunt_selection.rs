//! Which two of the three shunts to believe in a period. A shunt carries its phase current
//! only while its low side conducts, a window around the top of the count that shrinks to
//! nothing as the duty approaches 1. In every voltage sector one phase has the largest duty;
//! the other two are read and the third follows from Kirchhoff (the three sum to zero).
//!
//! The figure that makes this enough: with the current loop's voltage limit (the circle of
//! radius v_bus/√3, `control_core::reference_frames::voltage_circle_radius`) and min-max
//! space-vector modulation, the largest duty reaches 1 but the second largest never exceeds
//! 1/2 + √3/4 = 0.933; the two phases read keep at least (1 − 0.933) × 31.25 µs = 2.1 µs of
//! low-side conduction on each side of the top of the count (less the 0.32 µs dead time on the
//! way in) — more than the 0.88 µs the ADC needs to sample its second rank.

/// The largest second-largest duty at the linear limit: 1/2 + √3/4.
pub const SECOND_DUTY_AT_LINEAR_LIMIT: f32 = 0.5 + 0.433_012_7;

/// The phase not read: the one with the largest duty (the first of equals).
pub fn phase_not_read(duties: [f32; 3]) -> usize {
    let mut k = 0;
    if duties[1] > duties[k] {
        k = 1;
    }
    if duties[2] > duties[k] {
        k = 2;
    }
    k
}

/// Phase currents U and V for the core from the three shunt readings (A, positive into the
/// motor) and the duties that were in force when they were sampled.
pub fn phase_currents(shunts: [f32; 3], duties: [f32; 3]) -> [f32; 2] {
    let [u, v, w] = shunts;
    match phase_not_read(duties) {
        0 => [-(v + w), v],
        1 => [u, -(u + w)],
        _ => [u, v],
    }
}

/// The duty of the phase read with the shorter window.
pub fn largest_read_duty(duties: [f32; 3]) -> f32 {
    let skip = phase_not_read(duties);
    let mut m = 0.0f32;
    for (k, d) in duties.into_iter().enumerate() {
        if k != skip && d > m {
            m = d;
        }
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_phase_with_the_largest_duty_is_reconstructed() {
        let shunts = [3.0, -1.0, -2.0];
        // U highest: U from V and W; the bogus U reading (0: its low side did not conduct) is
        // never used.
        assert_eq!(phase_currents([0.0, -1.0, -2.0], [0.99, 0.5, 0.1]), [3.0, -1.0]);
        assert_eq!(phase_currents(shunts, [0.5, 0.99, 0.1]), [3.0, -1.0]);
        assert_eq!(phase_currents(shunts, [0.1, 0.5, 0.99]), [3.0, -1.0]);
        assert_eq!(phase_not_read([0.5, 0.5, 0.5]), 0);
    }
}
