//! The board's ratings and what the firmware derives from them: the sensing scales (with the
//! amplifier's sign) and the protective limits the drive runs with on this board (they
//! replace `Params::default()`'s, which were set for another power stage).
//!
//! - Bus voltage: the IHM08M1 is rated 8–48 V (UM1996; its data brief says 10–48 V). The
//!   drive trips below 10 V (the data brief's figure, also above the L6398's supply
//!   under-voltage lock-out, about 9.5 V to turn on) and above 50 V (48 V plus 2 V for the
//!   divider's and the reference's tolerances).
//! - Phase current: the converter shows ±31.9 A around its offset
//!   ([`crate::current_amplifier::ShuntAmplifier::range_amps`]); calibration accepts an offset
//!   up to 10 % of full scale (6.4 A) from mid-scale, leaving 25.5 A on the short side. The
//!   software overcurrent trip (24 A) sits below that, so the converter cannot saturate
//!   before the trip is seen, and above the board's 15 A rms (21.2 A peak).

use control_core::current_sensing::{SensingScales, OFFSET_WINDOW};
use control_core::params::{Limits, Params};

pub const SHUNT_OHM: f32 = 0.010;
/// Magnitude of the amplifier's gain; the sign is in [`SCALES`].
pub const AMPLIFIER_GAIN: f32 = 5.18;
pub const VREF: f32 = 3.3;
pub const FULL_SCALE: u16 = 4095;
/// 169 kΩ over 9.31 kΩ (UM1996).
pub const BUS_DIVIDER: f32 = (169.0 + 9.31) / 9.31;

pub const BUS_RATED_MIN_V: f32 = 8.0;
pub const BUS_RATED_MAX_V: f32 = 48.0;
pub const PHASE_RATED_RMS_A: f32 = 15.0;

pub const BUS_UNDERVOLTAGE_V: f32 = 10.0;
pub const BUS_OVERVOLTAGE_V: f32 = 50.0;
pub const OVERCURRENT_A: f32 = 24.0;

/// ADC counts to amperes and volts. Negative amperes per count: the board's amplifier
/// inverts, so a current into the motor lowers the count (phase current = (offset − count) ×
/// 15.6 mA).
pub const SCALES: SensingScales = SensingScales {
    full_scale: FULL_SCALE,
    amps_per_count: -(VREF / FULL_SCALE as f32) / (SHUNT_OHM * AMPLIFIER_GAIN),
    volts_per_count: VREF / FULL_SCALE as f32 * BUS_DIVIDER,
};

/// The machine-end accelerometer's input (`adc_words::ACCELEROMETER`): the sensor's output
/// straight into the converter, 0 to VREF (a ratiometric sensor supplied from the same 3.3 V).
pub const ACCELEROMETER_VOLTS_PER_COUNT: f32 = VREF / FULL_SCALE as f32;

/// The limits of this board, the following error kept as given.
pub fn board_limits(given: Limits) -> Limits {
    Limits {
        overcurrent: OVERCURRENT_A,
        bus_undervoltage: BUS_UNDERVOLTAGE_V,
        bus_overvoltage: BUS_OVERVOLTAGE_V,
        ..given
    }
}

/// `p` with this board's limits: what the firmware installs as its defaults, and what the
/// host gives a drive on this board (the virtual drive's too).
pub fn with_board_limits(p: Params) -> Params {
    Params { limits: board_limits(p.limits), ..p }
}

/// Ways a set of limits does not fit this board (bits of the result).
pub const OVERVOLTAGE_ABOVE_RATING: u32 = 1 << 0;
pub const UNDERVOLTAGE_REFUSES_RATED_RANGE: u32 = 1 << 1;
pub const UNDERVOLTAGE_BELOW_RATING: u32 = 1 << 2;
pub const OVERCURRENT_BEYOND_CONVERTER: u32 = 1 << 3;
pub const OVERCURRENT_BELOW_RATING: u32 = 1 << 4;

/// Checks `l` against the ratings: the over-voltage trip at most 2 V above the rated maximum,
/// the under-voltage trip between the rated minimum and the data brief's 10 V, the
/// overcurrent trip between the rated peak and the converter's range less the offset window.
pub fn limit_violations(l: &Limits, converter_range_a: f32) -> u32 {
    let offset_window_a = OFFSET_WINDOW * FULL_SCALE as f32 * -SCALES.amps_per_count;
    let rated_peak = PHASE_RATED_RMS_A * core::f32::consts::SQRT_2;
    let mut v = 0;
    if l.bus_overvoltage > BUS_RATED_MAX_V + 2.0 {
        v |= OVERVOLTAGE_ABOVE_RATING;
    }
    if l.bus_undervoltage > 10.0 {
        v |= UNDERVOLTAGE_REFUSES_RATED_RANGE;
    }
    if l.bus_undervoltage < BUS_RATED_MIN_V {
        v |= UNDERVOLTAGE_BELOW_RATING;
    }
    if l.overcurrent >= converter_range_a - offset_window_a {
        v |= OVERCURRENT_BEYOND_CONVERTER;
    }
    if l.overcurrent < rated_peak {
        v |= OVERCURRENT_BELOW_RATING;
    }
    v
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::current_amplifier::IHM08M1;
    use control_core::Params;

    #[test]
    fn the_board_limits_fit_the_board_and_the_default_ones_do_not() {
        let range = IHM08M1.range_amps();
        let board = board_limits(Params::default().limits);
        assert_eq!(limit_violations(&board, range), 0);
        assert_eq!(board.following_error, Params::default().limits.following_error);
        // Params::default(): 60 V, 20 V, 30 A — set for another board.
        let v = limit_violations(&Params::default().limits, range);
        assert_eq!(v, OVERVOLTAGE_ABOVE_RATING | UNDERVOLTAGE_REFUSES_RATED_RANGE | OVERCURRENT_BEYOND_CONVERTER);
    }

    #[test]
    fn the_scales_agree_with_the_amplifier_model() {
        // 200 counts below the bias are +200 × 15.56 mA into the motor.
        let counts = IHM08M1.counts(0.0) - 200;
        let amps = (counts as f32 - IHM08M1.counts(0.0) as f32) * SCALES.amps_per_count;
        assert!((amps - 3.111).abs() < 0.01, "{amps}");
        let back = IHM08M1.counts(amps);
        assert!(back.abs_diff(counts) <= 1);
        assert!((SCALES.volts_per_count * 4095.0 - 63.2).abs() < 0.1, "bus full scale 63.2 V");
    }
}
