//! The words the firmware writes to TIM1, as pure functions of the configuration (bit
//! positions from RM0440's TIM1 register map; the firmware writes each word whole).
//!
//! Why each gate-drive bit is what it is (channels 1–3, L6398 HIN on CHx, LIN on CHxN):
//!
//! | bit | value | why |
//! |---|---|---|
//! | CCxP | 0 | HIN is active high: OCx active = pin high = high-side on |
//! | CCxNP | 1 | LIN is active low: OCxN active = pin low = low-side on; in the dead time both outputs are inactive, i.e. HIN low and LIN high, which the driver reads as both off |
//! | CCxE, CCxNE | 1 | both outputs of each channel enabled once, at set-up; the bridge is then gated only through MOE |
//! | OSSR | 1 | with MOE = 1 a disabled output would still be driven to its inactive level (unused here: every output is enabled) |
//! | OSSI | 1 | with MOE = 0 (off, break, debug halt) the pins are driven, not left floating: first to their inactive levels at once, then to OISx/OISxN |
//! | OISx | 0 | idle HIN low: high side off |
//! | OISxN | 1 | idle LIN high: low side off. OSSI = 1 with OISxN = 0 would drive every LIN low with MOE = 0, i.e. turn every low side on |
//! | BKE, BKP | 1, 0 | break input enabled, active low like the IHM08M1's comparator output |
//! | AOE | 0 | MOE stays 0 after a break until the firmware sets it again |
//! | MOE | 0 | the bridge starts off; `bdtr_with_moe` gives the word with the bridge on |
//! | LOCK | 2 | polarities, idle levels, OSSI/OSSR, dead time and break settings frozen until reset (RM0440: LOCK level 2); the LOCK field itself is frozen by the first write to BDTR after reset, so this word must be that first write |
//!
//! The timer counts centre-aligned (CMS = 3) with preloaded compare and auto-reload
//! registers; channel 4 in PWM mode 2 with CCR4 = ARR − 1 (no pin) rises just before the top of
//! the count, where every low side conducts; its OC4REF is TRGO2 (MMS2 = 7), the ADCs'
//! injected trigger.

use crate::config::PowerStageConfig;
use crate::dead_time;

/// The TIM1 set-up, one word per register.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Tim1Words {
    pub cr1: u32,
    pub cr2: u32,
    pub ccmr1: u32,
    pub ccmr2: u32,
    pub ccer: u32,
    /// With MOE = 0.
    pub bdtr: u32,
    pub af1: u32,
    pub psc: u32,
    pub arr: u32,
    pub rcr: u32,
    pub ccr4: u32,
}

// CR1
pub const CR1_CEN: u32 = 1 << 0;
pub const CR1_DIR: u32 = 1 << 4;
pub const CR1_CMS_CENTRE_BOTH: u32 = 3 << 5;
pub const CR1_ARPE: u32 = 1 << 7;
// CR2
pub const CR2_MMS2_SHIFT: u32 = 20;
pub const MMS2_OC4REF: u32 = 7;
pub const fn cr2_ois(ch: usize) -> u32 {
    1 << (8 + 2 * ch)
}
pub const fn cr2_oisn(ch: usize) -> u32 {
    1 << (9 + 2 * ch)
}
// CCMRx: output compare mode OCxM[2:0] and preload OCxPE of channel `ch` within its register.
pub const OCM_PWM1: u32 = 0b0110;
pub const OCM_PWM2: u32 = 0b0111;
const fn ccmr_channel(ocm: u32, slot: usize) -> u32 {
    let preload = 1 << 3;
    ((ocm & 0x7) << 4 | preload) << (8 * slot)
}
/// OCxM of channel `ch` (0-based) from CCMR1/CCMR2 (the 4th bit OCxM[3] is kept 0 here).
pub const fn ocm_of(w: &Tim1Words, ch: usize) -> u32 {
    let reg = if ch < 2 { w.ccmr1 } else { w.ccmr2 };
    (reg >> (8 * (ch % 2) + 4)) & 0x7 | ((reg >> (16 + 8 * (ch % 2))) & 1) << 3
}
// CCER
pub const fn ccer_e(ch: usize) -> u32 {
    1 << (4 * ch)
}
pub const fn ccer_p(ch: usize) -> u32 {
    1 << (4 * ch + 1)
}
pub const fn ccer_ne(ch: usize) -> u32 {
    1 << (4 * ch + 2)
}
pub const fn ccer_np(ch: usize) -> u32 {
    1 << (4 * ch + 3)
}
// BDTR
pub const BDTR_DTG_MASK: u32 = 0xFF;
pub const BDTR_LOCK_LEVEL_2: u32 = 2 << 8;
pub const BDTR_OSSI: u32 = 1 << 10;
pub const BDTR_OSSR: u32 = 1 << 11;
pub const BDTR_BKE: u32 = 1 << 12;
pub const BDTR_BKP: u32 = 1 << 13;
pub const BDTR_AOE: u32 = 1 << 14;
pub const BDTR_MOE: u32 = 1 << 15;
pub const BDTR_BKF_SHIFT: u32 = 16;
// AF1: BKIN pin input enabled (its reset value), not inverted (BKINP = 0).
pub const AF1_BKINE: u32 = 1 << 0;
// EGR
pub const EGR_UG: u32 = 1 << 0;
/// Software break: MOE cleared and BIF set, as by the break input.
pub const EGR_BG: u32 = 1 << 7;

/// ARR for a centre-aligned period of `pwm_hz` (one period = 2 × ARR clocks), rounded down.
pub const fn period_counts(c: &PowerStageConfig) -> u32 {
    c.timer_clock_hz / (2 * c.pwm_hz)
}

pub const fn tim1_words(c: &PowerStageConfig) -> Tim1Words {
    let arr = period_counts(c);
    let high_polarity = !c.high_side_input.active_level(); // CCxP = 1 inverts
    let low_polarity = !c.low_side_input.active_level(); // CCxNP = 1 inverts
    let mut ccer = 0;
    let mut cr2 = MMS2_OC4REF << CR2_MMS2_SHIFT;
    let mut ch = 0;
    while ch < 3 {
        ccer |= ccer_e(ch) | ccer_ne(ch);
        if high_polarity {
            ccer |= ccer_p(ch);
        }
        if low_polarity {
            ccer |= ccer_np(ch);
        }
        // Idle levels are pin levels: each input's inactive level.
        if !c.high_side_input.active_level() {
            cr2 |= cr2_ois(ch);
        }
        if !c.low_side_input.active_level() {
            cr2 |= cr2_oisn(ch);
        }
        ch += 1;
    }
    let mut bdtr = dead_time::encode(c.ticks(c.timer_dead_time_ns)) as u32
        | BDTR_LOCK_LEVEL_2
        | BDTR_OSSI
        | BDTR_OSSR
        | BDTR_BKE
        | ((c.break_filter as u32 & 0xF) << BDTR_BKF_SHIFT);
    if c.break_input.active_level() {
        bdtr |= BDTR_BKP;
    }
    Tim1Words {
        cr1: CR1_CMS_CENTRE_BOTH | CR1_ARPE,
        cr2,
        ccmr1: ccmr_channel(OCM_PWM1, 0) | ccmr_channel(OCM_PWM1, 1),
        ccmr2: ccmr_channel(OCM_PWM1, 0) | ccmr_channel(OCM_PWM2, 1),
        ccer,
        bdtr,
        af1: AF1_BKINE,
        psc: 0,
        arr,
        rcr: 0,
        ccr4: arr - 1,
    }
}

/// The BDTR word with the gate drive on or off.
pub const fn bdtr_with_moe(bdtr: u32, on: bool) -> u32 {
    if on {
        bdtr | BDTR_MOE
    } else {
        bdtr & !BDTR_MOE
    }
}

/// Compare value of a duty cycle 0..1 (clamped; NaN gives 0).
pub fn compare_value(duty: f32, arr: u32) -> u32 {
    let d = if duty > 1.0 {
        1.0
    } else if duty > 0.0 {
        duty
    } else {
        0.0
    };
    (d * arr as f32) as u32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::IHM08M1;

    #[test]
    fn the_words_of_the_ihm08m1_bit_by_bit() {
        let w = tim1_words(&IHM08M1);
        assert_eq!(w.arr, 5312, "170 MHz / (2 × 16 kHz)");
        assert_eq!(w.ccr4, 5311);
        // CC1E CC1NE CC1NP, same for channels 2 and 3; channel 4 internal only.
        assert_eq!(w.ccer, 0x0DDD);
        // OIS1N, OIS2N, OIS3N; MMS2 = OC4REF.
        assert_eq!(w.cr2, 0x0070_2A00);
        assert_eq!(w.ccmr1, 0x6868);
        assert_eq!(w.ccmr2, 0x7868);
        // 17 clocks (100 ns), LOCK 2, OSSI, OSSR, BKE, active low, BKF = 4, MOE = 0.
        assert_eq!(w.bdtr, 0x0004_1E11);
        assert_eq!(bdtr_with_moe(w.bdtr, true), 0x0004_9E11);
        assert_eq!(w.cr1, 0xE0);
        assert_eq!(ocm_of(&w, 0), OCM_PWM1);
        assert_eq!(ocm_of(&w, 3), OCM_PWM2);
    }

    #[test]
    fn duties_become_compare_values_clamped() {
        assert_eq!(compare_value(0.5, 5312), 2656);
        assert_eq!(compare_value(1.5, 5312), 5312);
        assert_eq!(compare_value(-0.1, 5312), 0);
        assert_eq!(compare_value(f32::NAN, 5312), 0);
    }
}
