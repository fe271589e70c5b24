//! The ADC words: all three shunts and the bus voltage in injected sequences of ADC1 and
//! ADC2, started together by TIM1's TRGO2 (injected trigger 8 of ADC1/2, rising edge; RM0440).
//!
//! | ADC | rank 1 | rank 2 | rank 3 |
//! |---|---|---|---|
//! | ADC1 | phase U current (PA0, ADC12_IN1) | bus voltage (PA1, ADC12_IN2) | accelerometer (PC3, ADC12_IN9) |
//! | ADC2 | phase V current (PC1, ADC12_IN7) | phase W current (PC0, ADC12_IN6) | |
//!
//! The accelerometer (seed 001's removable measuring instrument, machine-end acceleration for
//! the identification over a drive) is on PC3: the STM32G474's datasheet (DS12288, pin
//! definitions) gives PC3 the additional function ADC12_IN9, a channel ADC1 converts in the
//! same injected sequence as the phase currents, so it is sampled at the same trigger (the
//! identification relates it to the measured current: no delay between the two but the
//! ranks'); the NUCLEO-G474RE (UM2505, ST morpho connector) brings PC3 out on CN7 pin 37,
//! not on an Arduino header, where the X-NUCLEO-IHM08M1 takes its signals (its phase
//! currents, bus voltage and gate drive use PA0, PA1, PC0, PC1, PA6–PA10, PB0, PB1). Before
//! wiring, check UM1996 (the IHM08M1's manual) that none of its solder-bridge options
//! (BEMF or temperature sensing) is routed to PC3 on the board at hand. Rank 3 adds 25 ADC
//! clocks (0.59 µs) to ADC1's sequence after the ranks the currents use: their sampling
//! windows do not move, the end of sequence (the control interrupt) comes 0.59 µs later.
//!
//! Clock: synchronous HCLK/4 = 42.5 MHz (CKMODE = 3, ADC12_CCR), every channel sampled for
//! 12.5 ADC clocks; a 12-bit conversion takes another 12.5. Rank 1 samples during the first
//! 12.5 clocks after the trigger (0–0.29 µs), rank 2 from 25 to 37.5 clocks (0.59–0.88 µs):
//! phase W is read later than U and V, which `sampling` accounts for.

/// Phase current and bus channels (ADC12_INx).
pub const PHASE_U: u8 = 1;
pub const PHASE_V: u8 = 7;
pub const PHASE_W: u8 = 6;
pub const BUS: u8 = 2;
/// The machine-end accelerometer (PC3, see the module's documentation).
pub const ACCELEROMETER: u8 = 9;

pub const ADC1_SEQUENCE: [u8; 3] = [PHASE_U, BUS, ACCELEROMETER];
pub const ADC2_SEQUENCE: [u8; 2] = [PHASE_V, PHASE_W];

/// Timer (HCLK) clocks per ADC clock.
pub const HCLK_DIVIDER: u32 = 4;
/// ADC12_CCR: CKMODE = 3, synchronous HCLK/4.
pub const COMMON_CCR: u32 = 3 << 16;
/// SMPx code of 12.5 ADC clocks.
pub const SAMPLE_TIME_CODE: u32 = 0b010;
/// Sampling and conversion times in half ADC clocks.
pub const SAMPLE_HALF_CLOCKS: u32 = 25;
pub const CONVERSION_HALF_CLOCKS: u32 = 25;
/// JEXTSEL of TIM1_TRGO2 for ADC1/2, JEXTEN rising edge.
pub const JEXTSEL_TIM1_TRGO2: u32 = 8;
pub const JEXTEN_RISING: u32 = 1;

/// JSQR: length, trigger, channels by rank.
pub const fn jsqr(channels: &[u8]) -> u32 {
    let mut w = (channels.len() as u32 - 1) | JEXTSEL_TIM1_TRGO2 << 2 | JEXTEN_RISING << 7;
    let mut rank = 0;
    while rank < channels.len() {
        w |= (channels[rank] as u32 & 0x1F) << (9 + 6 * rank);
        rank += 1;
    }
    w
}

/// SMPR1 (channels 0–9): the sampling time of each listed channel, the others left at 0.
pub const fn smpr1(channels: &[u8]) -> u32 {
    let mut w = 0;
    let mut k = 0;
    while k < channels.len() {
        w |= SAMPLE_TIME_CODE << (3 * channels[k] as u32);
        k += 1;
    }
    w
}

/// Where a phase current is converted: ADC (0 = ADC1, 1 = ADC2) and rank (0-based).
pub const fn phase_slot(phase: usize) -> (usize, usize) {
    match phase {
        0 => (0, 0),
        1 => (1, 0),
        _ => (1, 1),
    }
}

/// Timer clocks from the trigger to the start and the end of sampling at `rank`.
pub const fn sampling_window(rank: usize) -> (u32, u32) {
    let start = rank as u32 * (SAMPLE_HALF_CLOCKS + CONVERSION_HALF_CLOCKS) * HCLK_DIVIDER / 2;
    (start, start + SAMPLE_HALF_CLOCKS * HCLK_DIVIDER / 2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_sequences_bit_by_bit() {
        // JL = 2, JEXTSEL = 8, JEXTEN = 1, JSQ1 = 1, JSQ2 = 2, JSQ3 = 9.
        assert_eq!(jsqr(&ADC1_SEQUENCE), 2 | 8 << 2 | 1 << 7 | 1 << 9 | 2 << 15 | 9 << 21);
        assert_eq!(smpr1(&ADC1_SEQUENCE), 0b010 << 3 | 0b010 << 6 | 0b010 << 27);
        assert_eq!(jsqr(&ADC2_SEQUENCE), 1 | 8 << 2 | 1 << 7 | 7 << 9 | 6 << 15);
        assert_eq!(smpr1(&ADC2_SEQUENCE), 0b010 << 21 | 0b010 << 18);
        assert_eq!(sampling_window(0), (0, 50));
        assert_eq!(sampling_window(1), (100, 150));
        // Each phase channel sits in exactly one slot of the two sequences.
        let seqs = [&ADC1_SEQUENCE[..], &ADC2_SEQUENCE[..]];
        for (phase, ch) in [PHASE_U, PHASE_V, PHASE_W].into_iter().enumerate() {
            let (adc, rank) = phase_slot(phase);
            assert_eq!(seqs[adc][rank], ch);
        }
    }
}
