//! Maximum-length binary sequences (M-sequences) from a Fibonacci linear-feedback shift
//! register: period `2^n − 1` chips for a degree `n` of 2 to 20, a flat spectrum up to the
//! chip rate's first null. Used as the identification excitation of seed 001 (added to the
//! torque command) and as the broadband baseline of the frequency-response sweep.

use core::fmt;

pub const MIN_DEGREE: u32 = 2;
pub const MAX_DEGREE: u32 = 20;

/// Feedback taps (1-based register positions) of a primitive polynomial per degree.
const TAPS: [&[u32]; 19] = [
    &[2, 1],
    &[3, 2],
    &[4, 3],
    &[5, 3],
    &[6, 5],
    &[7, 6],
    &[8, 6, 5, 4],
    &[9, 5],
    &[10, 7],
    &[11, 9],
    &[12, 6, 4, 1],
    &[13, 4, 3, 1],
    &[14, 5, 3, 1],
    &[15, 14],
    &[16, 15, 13, 4],
    &[17, 14],
    &[18, 11],
    &[19, 6, 2, 1],
    &[20, 17],
];

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DegreeError(pub u32);

impl fmt::Display for DegreeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "M-sequence degree {} is outside {MIN_DEGREE}..={MAX_DEGREE}", self.0)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MSequence {
    degree: u32,
    mask: u32,
    state: u32,
}

impl MSequence {
    /// Degree 15 (x^15 + x^14 + 1): 32767 chips.
    pub const DEGREE_15: Self = Self { degree: 15, mask: (1 << 14) | (1 << 13), state: 1 };

    pub fn new(degree: u32) -> Result<Self, DegreeError> {
        if !(MIN_DEGREE..=MAX_DEGREE).contains(&degree) {
            return Err(DegreeError(degree));
        }
        let mask = TAPS[(degree - MIN_DEGREE) as usize].iter().fold(0u32, |m, t| m | 1 << (t - 1));
        Ok(Self { degree, mask, state: 1 })
    }

    /// Chips before the sequence repeats.
    pub fn period(&self) -> u32 {
        (1u32 << self.degree) - 1
    }

    /// Back to the first chip.
    pub fn restart(&mut self) {
        self.state = 1;
    }

    /// Next chip: +1 or −1.
    pub fn next_chip(&mut self) -> i8 {
        let bit = (self.state & self.mask).count_ones() & 1;
        self.state = ((self.state << 1) | bit) & ((1u32 << self.degree) - 1);
        if bit == 1 {
            1
        } else {
            -1
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_degree_has_the_maximum_period_and_balance() {
        for degree in MIN_DEGREE..=16 {
            let mut m = MSequence::new(degree).unwrap();
            let start = m.state;
            let mut ones = 0i64;
            let mut n = 0u32;
            loop {
                ones += (m.next_chip() == 1) as i64;
                n += 1;
                if m.state == start {
                    break;
                }
                assert!(n <= m.period(), "degree {degree} runs past 2^n - 1");
            }
            assert_eq!(n, m.period(), "degree {degree}");
            // An M-sequence has one more +1 than −1 per period.
            assert_eq!(ones, (n as i64 + 1) / 2, "degree {degree}");
        }
        assert_eq!(MSequence::new(15), Ok(MSequence::DEGREE_15));
        assert_eq!(MSequence::new(1), Err(DegreeError(1)));
        assert_eq!(MSequence::new(21), Err(DegreeError(21)));
    }
}
