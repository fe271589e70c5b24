//! The one configuration every register word and model is derived from.
//!
//! Gate-drive polarities are the L6398's (datasheet, input truth table): HIN is active high
//! (internal pull-down), LIN is active low (internal pull-up). The timer's channel x drives
//! HIN, its complementary output xN drives LIN (UM1996 pin map: PA8/PA9/PA10 high sides,
//! PA7/PB0/PB1 low sides).
//!
//! Dead time: the L6398 inserts its own (about 320 ns, [`crate::gate_driver::DEAD_TIME_NS`])
//! between one gate turning off and the other turning on, whatever its inputs do, and its
//! interlock refuses both on. The gap the motor sees is therefore the longer of the two, not
//! their sum. The timer's dead time is kept short (100 ns): it makes sure the driver never
//! sees its two inputs switch at the same instant (between them there is always the
//! "both off" input state), and the driver's 320 ns sets the gap the current loop sees; a
//! longer timer dead time would only shorten the low-side window the shunts are sampled in
//! and add distortion. Apache NuttX's IHM08M1 board support makes the same choice (a short
//! timer dead time on top of the driver's).

/// Active level of a logic input.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Polarity {
    ActiveHigh,
    ActiveLow,
}

impl Polarity {
    /// The pin level that means "asserted".
    pub const fn active_level(self) -> bool {
        matches!(self, Polarity::ActiveHigh)
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PowerStageConfig {
    /// TIM1's kernel clock (APB2 timer clock), Hz.
    pub timer_clock_hz: u32,
    /// PWM frequency, Hz (centre-aligned: one up-and-down count per period).
    pub pwm_hz: u32,
    /// Dead time the timer inserts, ns.
    pub timer_dead_time_ns: u32,
    /// Gate driver's high-side input (HIN), driven by channel x.
    pub high_side_input: Polarity,
    /// Gate driver's low-side input (LIN), driven by channel xN.
    pub low_side_input: Polarity,
    /// The overcurrent comparator's output on BKIN (PA6).
    pub break_input: Polarity,
    /// BKF code of the break filter (4: fDTS/2, 6 samples: about 70 ns at 170 MHz).
    pub break_filter: u8,
}

/// NUCLEO-G474RE at 170 MHz with the X-NUCLEO-IHM08M1. The IHM08M1's comparator pulls BKIN
/// low on an overcurrent (as the firmware had it; the board's schematic was not at hand to
/// recheck the comparator's output stage).
pub const IHM08M1: PowerStageConfig = PowerStageConfig {
    timer_clock_hz: 170_000_000,
    pwm_hz: 16_000,
    timer_dead_time_ns: 100,
    high_side_input: Polarity::ActiveHigh,
    low_side_input: Polarity::ActiveLow,
    break_input: Polarity::ActiveLow,
    break_filter: 4,
};

impl PowerStageConfig {
    /// `ns` in timer clocks, rounded to nearest.
    pub const fn ticks(&self, ns: u32) -> u32 {
        ((ns as u64 * self.timer_clock_hz as u64 + 500_000_000) / 1_000_000_000) as u32
    }

    /// Timer clocks per ADC clock (the ADCs run synchronously at HCLK/4, `adc_words`).
    pub const fn ticks_per_adc_clock(&self) -> u32 {
        crate::adc_words::HCLK_DIVIDER
    }
}
