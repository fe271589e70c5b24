//! TIM1's dead-time generator setting DTG[7:0] (RM0440, TIMx_BDTR): with tDTS the timer clock
//! (CKD = 0),
//!
//! | DTG[7:5] | dead time |
//! |---|---|
//! | 0xx | DTG[7:0] × tDTS |
//! | 10x | (64 + DTG[5:0]) × 2 tDTS |
//! | 110 | (32 + DTG[4:0]) × 8 tDTS |
//! | 111 | (32 + DTG[4:0]) × 16 tDTS |

/// The DTG code for `ticks` timer clocks: the shortest setting not below it (saturating at
/// the longest, 1 008 clocks).
pub const fn encode(ticks: u32) -> u8 {
    if ticks <= 127 {
        ticks as u8
    } else if ticks <= 2 * (64 + 63) {
        0x80 | (ticks.div_ceil(2) - 64) as u8
    } else if ticks <= 8 * (32 + 31) {
        0xC0 | (ticks.div_ceil(8) - 32) as u8
    } else if ticks <= 16 * (32 + 31) {
        0xE0 | (ticks.div_ceil(16) - 32) as u8
    } else {
        0xFF
    }
}

/// Dead time in timer clocks of a DTG code.
pub const fn decode(dtg: u8) -> u32 {
    let d = dtg as u32;
    if d & 0x80 == 0 {
        d
    } else if d & 0xC0 == 0x80 {
        (64 + (d & 0x3F)) * 2
    } else if d & 0xE0 == 0xC0 {
        (32 + (d & 0x1F)) * 8
    } else {
        (32 + (d & 0x1F)) * 16
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_code_decodes_to_a_dead_time_that_encodes_back_to_a_code_of_the_same_length() {
        // The table's ranges overlap (e.g. 128 clocks is 0x80 and nothing else, but 0x40 =
        // 64 clocks is also reachable only one way); what must hold is that encoding the
        // decoded length gives that length again.
        for code in 0..=255u8 {
            let ticks = decode(code);
            assert_eq!(decode(encode(ticks)), ticks, "code {code:#04x} = {ticks} clocks");
        }
    }

    #[test]
    fn the_table_of_the_reference_manual() {
        assert_eq!(decode(0x11), 17);
        assert_eq!(decode(0x80), 128);
        assert_eq!(decode(0xBF), 254);
        assert_eq!(decode(0xC0), 256);
        assert_eq!(decode(0xE0), 512);
        assert_eq!(decode(0xFF), 1008);
        // Never shorter than asked.
        for ticks in 0..=1008 {
            assert!(decode(encode(ticks)) >= ticks, "{ticks}");
        }
    }
}
