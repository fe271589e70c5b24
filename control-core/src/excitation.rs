//! Test-signal generation inside the drive.
//!
//! A sine generator at the loop rate whose phase is accumulated and wrapped every tick, so
//! that long runs do not lose precision. Used for the plant checks and, later, the
//! phase-shifted frequency sweep (seed 000).

use crate::trigonometry::ReducedAngle;
use crate::TAU;

/// Where an excitation signal is added in the loop.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum InjectionPoint {
    #[default]
    Off,
    /// Added to the torque command after the velocity loop and filters (Nm).
    TorqueCommand,
    /// Added to the velocity command in front of the velocity loop (rad/s).
    VelocityCommand,
    /// Added to the velocity feedback the velocity loop sees (rad/s): the open loop.
    VelocityFeedback,
    /// Added to the streamed position command in front of the command path (rad of the
    /// axis; position mode only): the closed position loop, for instance the single-axis
    /// pseudo-circle of seed 002 with the sine generated in the drive.
    PositionCommand,
}

impl InjectionPoint {
    pub fn from_code(code: i32) -> Option<Self> {
        match code {
            0 => Some(Self::Off),
            1 => Some(Self::TorqueCommand),
            2 => Some(Self::VelocityCommand),
            3 => Some(Self::VelocityFeedback),
            4 => Some(Self::PositionCommand),
            _ => None,
        }
    }

    /// The inverse of [`Self::from_code`].
    pub fn code(self) -> i32 {
        match self {
            Self::Off => 0,
            Self::TorqueCommand => 1,
            Self::VelocityCommand => 2,
            Self::VelocityFeedback => 3,
            Self::PositionCommand => 4,
        }
    }
}

/// `amplitude · sin(phase)` from a 32-bit phase accumulator (numerically controlled
/// oscillator): the phase advances by an integer increment each tick, so it never drifts, and
/// a frequency that divides the tick rate repeats exactly. Frequency resolution: `fs / 2³²`.
#[derive(Clone, Copy, Debug, Default)]
pub struct SineGenerator {
    pub amplitude: f32,
    increment: u32,
    phase: u32,
}

/// One turn of the phase accumulator.
const TURN: f64 = 4_294_967_296.0;

impl SineGenerator {
    pub fn new(amplitude: f32, frequency_hz: f32, sample_rate_hz: f32, initial_phase: f32) -> Self {
        let turns = frequency_hz as f64 / sample_rate_hz as f64;
        let start = initial_phase as f64 / core::f64::consts::TAU;
        Self { amplitude, increment: to_accumulator(turns), phase: to_accumulator(start) }
    }

    /// Current phase in `[0, 2π)`.
    pub fn phase(&self) -> f32 {
        phase_angle(self.phase)
    }

    /// Current phase as the accumulator's word (one turn is 2³²): [`phase_angle`] converts it,
    /// for a caller that needs the angle on some ticks only.
    pub fn phase_word(&self) -> u32 {
        self.phase
    }

    /// Ticks until the phase is nearest a peak of the sine (π/2 or 3π/2), at most half a
    /// period. A frequency changed there keeps both the value and the slope of the input
    /// continuous (both sines are at ±amplitude with zero slope), which cancels, to first
    /// order, the transient the change excites in every loop mode away from the excitation
    /// (see `PhaseShiftedSweep`). 0 when the sine does not advance.
    pub fn ticks_to_peak(&self) -> u32 {
        if self.increment == 0 {
            return 0;
        }
        const QUARTER: u32 = 1 << 30;
        const HALF_TURN_MASK: u32 = (1 << 31) - 1;
        let distance = QUARTER.wrapping_sub(self.phase) & HALF_TURN_MASK;
        // The nearest tick: the distance in increments, rounded (u64: no overflow).
        ((distance as u64 + (self.increment as u64 >> 1)) / self.increment as u64) as u32
    }

    /// The most [`Self::ticks_to_peak`] can return at this frequency, from any phase: half a
    /// turn over the increment, rounded as it rounds (at least one tick: a stage lasts one).
    /// Not `ceil(fs/(2f)) + 1`: the increment is rounded to an integer, and at 0.01 Hz and
    /// 16 kHz (2 684 rounded down from 2 684.35) the wait reaches 105 ticks more than that.
    pub fn longest_wait_to_peak(&self) -> u32 {
        if self.increment == 0 {
            return 1;
        }
        let most = ((1u64 << 31) - 1 + (self.increment as u64 >> 1)) / self.increment as u64;
        most.clamp(1, u32::MAX as u64) as u32
    }

    /// The generator `ticks` samples on (the phase wraps as the accumulator does).
    pub fn advanced(self, ticks: u64) -> Self {
        let phase = self.phase.wrapping_add((self.increment as u64).wrapping_mul(ticks) as u32);
        Self { phase, ..self }
    }

    pub fn next_sample(&mut self) -> f32 {
        self.next_with_angle().0
    }

    /// The sample, and its phase reduced for the sine and cosine (for a correlator on the same
    /// tick: one reduction, and the cosine's polynomial only on the ticks that need it).
    #[inline(always)]
    pub fn next_with_angle(&mut self) -> (f32, ReducedAngle) {
        let angle = ReducedAngle::of_phase_word(self.phase);
        self.phase = self.phase.wrapping_add(self.increment);
        (self.amplitude * angle.sin(), angle)
    }
}

/// A phase accumulator's word as an angle in `[0, 2π)`.
pub fn phase_angle(word: u32) -> f32 {
    // The top 24 bits convert to f32 exactly.
    (word >> 8) as f32 * (TAU / 16_777_216.0)
}

fn to_accumulator(turns: f64) -> u32 {
    let frac = turns - libm::floor(turns);
    (libm::round(frac * TURN) as u64 & 0xFFFF_FFFF) as u32
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The longest wait is what `ticks_to_peak` returns from the worst phase (half a turn less
    /// one from the peak), and no phase waits longer.
    #[test]
    fn the_longest_wait_to_peak_is_the_worst_phases_wait() {
        let mut state = 0x9E37_79B9u32;
        for (f, rate) in
            [(0.01f32, 16_000.0f32), (0.001, 200_000.0), (10.0, 16_000.0), (2999.0, 8_000.0), (3.7, 32_000.0)]
        {
            let g = SineGenerator::new(1.0, f, rate, 0.0);
            let longest = g.longest_wait_to_peak();
            // Distance (2³¹ − 1) from the quarter turn, modulo half a turn.
            let worst = SineGenerator { phase: (1u32 << 30).wrapping_sub((1 << 31) - 1), ..g };
            assert_eq!(worst.ticks_to_peak(), longest, "{f} Hz at {rate} Hz");
            for _ in 0..10_000 {
                state ^= state << 13;
                state ^= state >> 17;
                state ^= state << 5;
                let any = SineGenerator { phase: state, ..g };
                assert!(any.ticks_to_peak() <= longest, "{f} Hz at {rate} Hz, phase {state}");
            }
        }
    }

    #[test]
    fn the_phase_reaches_a_peak_after_ticks_to_peak() {
        // Property: after the ticks it names, the sine is within half a tick's phase step of
        // ±amplitude (the nearest tick to a peak), and no earlier tick is nearer.
        for (f, start) in [(10.0, 0.0), (43.2, 1.0), (777.0, 2.5), (3000.0, 4.0), (18.0, 1.55)] {
            let g = SineGenerator::new(1.0, f, 16_000.0, start);
            let n = g.ticks_to_peak();
            let step = TAU * f / 16_000.0;
            assert!((n as f32) <= 0.5 * 16_000.0 / f + 1.0, "{f} {start}: {n} ticks is over half a period");
            let mut h = g;
            for _ in 0..n {
                h.next_sample();
            }
            let phase = h.phase();
            let off_peak = libm::fabsf(libm::cosf(phase));
            assert!(off_peak <= libm::sinf(0.5 * step) + 1e-4, "{f} {start}: phase {phase} after {n} ticks");
        }
        assert_eq!(SineGenerator::new(1.0, 0.0, 16_000.0, 0.3).ticks_to_peak(), 0);
    }

    #[test]
    fn sine_matches_the_analytic_wave_after_many_periods() {
        let fs = 16_000.0;
        let mut g = SineGenerator::new(2.0, 1000.0, fs, 0.0);
        // 1 kHz at 16 kHz repeats every 16 samples exactly.
        for k in 0..160_000u32 {
            let y = g.next_sample();
            let expect = 2.0 * libm::sinf(TAU * ((k % 16) as f32) / 16.0);
            assert!((y - expect).abs() < 1e-5, "sample {k}: {y} vs {expect}");
        }
    }
}
