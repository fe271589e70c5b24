//! The power stage of the drive — NUCLEO-G474RE (STM32G474, TIM1, ADC1/2) with the
//! X-NUCLEO-IHM08M1 (three L6398 half-bridge gate drivers, six MOSFETs, three 10 mΩ low-side
//! shunts with their amplifiers, a bus divider and an overcurrent comparator on TIM1's break
//! input) — as data and as models:
//!
//! - the register words the firmware writes (`tim1_words`, `adc_words`, `fail_safe`) are
//!   pure `const fn`s of one configuration ([`config::IHM08M1`]), so the firmware and the
//!   host tests use the same numbers;
//! - host models of what those words do: TIM1's complementary outputs with dead time and
//!   break (`output_stage`, RM0440's table of output control bits), the L6398's input truth
//!   table, interlock and dead time (`gate_driver`), a centre-aligned period of the three legs
//!   (`bridge`), the shunt amplifiers and the ADC's sampling instants (`current_amplifier`,
//!   `sampling`);
//! - the board's side of current sensing: the phase pair read in each voltage sector
//!   (`shunt_selection`), the sensing scales and the protective limits (`ratings`).
//!
//! `no_std`, no allocation, integer and `f32` arithmetic only: the firmware links the words,
//! the scales and the phase-pair choice; the models are plain code the host tests (and a
//! future simulated board) run. Sources are named where each fact is used; where one could not
//! be checked against a document, the comment says so.
#![no_std]
#![forbid(unsafe_code)]

pub mod adc_words;
pub mod bridge;
pub mod config;
pub mod current_amplifier;
pub mod dead_time;
pub mod fail_safe;
pub mod gate_driver;
pub mod output_stage;
pub mod ratings;
pub mod sampling;
pub mod shunt_selection;
pub mod tim1_words;

/// Level of an MCU pin as the gate driver's input sees it: driven low or high by the timer,
/// or not driven (the timer's output disabled, or the pin not yet switched to the timer).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pin {
    Low,
    High,
    Floating,
}

impl Pin {
    pub const fn from_level(high: bool) -> Pin {
        if high {
            Pin::High
        } else {
            Pin::Low
        }
    }
}
