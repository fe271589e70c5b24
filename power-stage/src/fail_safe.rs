//! What switches the bridge off when the firmware loses control, as register words, and a
//! model of what each loss of control does to the bridge with those words in place.
//!
//! | loss of control | what takes the gates off |
//! |---|---|
//! | panic, HardFault | the handler's first act is a software break (TIM1 EGR.BG: MOE cleared, as by the break input) |
//! | core halted by a debugger (or by a probe after a fault) | DBG_TIM1_STOP: TIM1 stops with the core and its outputs are disabled as with MOE = 0 (RM0440, advanced-control timer debug mode), i.e. driven to their idle levels since OSSI = 1 |
//! | core lockup | SYSCFG CFGR2.CLL connects the Cortex-M4 LOCKUP output to TIM1's break |
//! | control loop stalled (interrupt no longer runs, or runs without finishing) | the independent watchdog, fed only by the loop, resets the chip; after reset the pins are not driven and the L6398's input pulls hold both FETs off |
//!
//! The watchdog is frozen while a debugger halts the core (DBG_IWDG_STOP), so a breakpoint does
//! not reset the chip; the bridge is off then anyway (DBG_TIM1_STOP).

use crate::tim1_words::EGR_BG;

/// DBGMCU_APB2FZR: TIM1 stopped while the core is halted.
pub const DBGMCU_APB2FZR_TIM1_STOP: u32 = 1 << 11;
/// DBGMCU_APB1FZR1: IWDG stopped while the core is halted.
pub const DBGMCU_APB1FZR1_IWDG_STOP: u32 = 1 << 12;
/// SYSCFG_CFGR2: core lockup → break of TIM1/8/15/16/17/20.
pub const SYSCFG_CFGR2_CLL: u32 = 1 << 0;
/// The word the panic and fault handlers write to TIM1_EGR first.
pub const BRIDGE_OFF_EGR: u32 = EGR_BG;

/// IWDG key register values (RM0440).
pub const IWDG_KEY_START: u16 = 0xCCCC;
pub const IWDG_KEY_UNLOCK: u16 = 0x5555;
pub const IWDG_KEY_FEED: u16 = 0xAAAA;
/// Typical LSI frequency, Hz (it spreads by several per cent: the timeout is approximate).
pub const LSI_HZ: u32 = 32_000;
/// The loop must feed the watchdog at least this often; it feeds it every 62.5 µs tick.
pub const WATCHDOG_TIMEOUT_US: u32 = 4_000;

/// IWDG prescaler code (PR: /4 << code) and reload value for a timeout.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct WatchdogWords {
    pub pr: u8,
    pub rlr: u16,
}

/// The shortest prescaler that fits the timeout in the 12-bit reload counter.
pub const fn watchdog_words(timeout_us: u32, lsi_hz: u32) -> WatchdogWords {
    let mut pr = 0u8;
    while pr < 6 {
        let divider = 4u64 << pr;
        let counts = timeout_us as u64 * lsi_hz as u64 / divider / 1_000_000;
        if counts <= 4096 {
            let rlr = if counts == 0 { 0 } else { counts - 1 };
            return WatchdogWords { pr, rlr: rlr as u16 };
        }
        pr += 1;
    }
    WatchdogWords { pr: 6, rlr: 0xFFF }
}

/// The fail-safe words as the firmware leaves them after start-up.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FailSafeWords {
    pub dbgmcu_apb2fzr: u32,
    pub dbgmcu_apb1fzr1: u32,
    pub syscfg_cfgr2: u32,
    /// None: the watchdog is not started.
    pub watchdog: Option<WatchdogWords>,
    /// What the panic and HardFault handlers write to TIM1_EGR before anything else (0: none).
    pub handler_egr: u32,
}

pub const FAIL_SAFE: FailSafeWords = FailSafeWords {
    dbgmcu_apb2fzr: DBGMCU_APB2FZR_TIM1_STOP,
    dbgmcu_apb1fzr1: DBGMCU_APB1FZR1_IWDG_STOP,
    syscfg_cfgr2: SYSCFG_CFGR2_CLL,
    watchdog: Some(watchdog_words(WATCHDOG_TIMEOUT_US, LSI_HZ)),
    handler_egr: BRIDGE_OFF_EGR,
};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LossOfControl {
    PanicOrFault,
    DebuggerHalt,
    Lockup,
    StalledLoop,
}

/// What the hardware does to TIM1 after a loss of control, with these words.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BridgeAfter {
    /// MOE cleared (break or debug halt): the outputs go to their off state.
    MoeCleared,
    /// The chip resets: the pins are no longer driven by the timer.
    ChipReset,
    /// Nothing: the timer keeps switching the last duties.
    KeepsSwitching,
}

pub fn bridge_after(w: &FailSafeWords, event: LossOfControl) -> BridgeAfter {
    let on = |hit: bool, then: BridgeAfter| if hit { then } else { BridgeAfter::KeepsSwitching };
    match event {
        LossOfControl::PanicOrFault => on(w.handler_egr & EGR_BG != 0, BridgeAfter::MoeCleared),
        LossOfControl::DebuggerHalt => on(w.dbgmcu_apb2fzr & DBGMCU_APB2FZR_TIM1_STOP != 0, BridgeAfter::MoeCleared),
        LossOfControl::Lockup => on(w.syscfg_cfgr2 & SYSCFG_CFGR2_CLL != 0, BridgeAfter::MoeCleared),
        LossOfControl::StalledLoop => on(w.watchdog.is_some(), BridgeAfter::ChipReset),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn four_milliseconds_of_watchdog() {
        let w = watchdog_words(4_000, 32_000);
        // /4 → 8 kHz: 32 counts.
        assert_eq!(w, WatchdogWords { pr: 0, rlr: 31 });
        let long = watchdog_words(1_000_000, 32_000);
        let divider = 4u32 << long.pr;
        let us = (long.rlr as u32 + 1) as u64 * divider as u64 * 1_000_000 / 32_000;
        assert!((999_000..=1_001_000).contains(&us), "{long:?}: {us} µs");
    }
}
