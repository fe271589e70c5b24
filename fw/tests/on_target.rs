//! On-target tests of the board code (NUCLEO-G474RE; the power stage may be absent: the
//! bridge's gate drive stays off throughout).
//!
//! - Registers: after `board::init`, TIM1's, the ADCs' and the fail-safe registers read back
//!   as the words of the `power-stage` crate (the words its host tests feed through the
//!   models of TIM1's output stage and the L6398).
//! - Gate pins with the bridge off: PA8/PA9/PA10 (HIN) low, PA7/PB0/PB1 (LIN) high, driven
//!   by the timer (alternate function) — every FET off.
//! - PWM: TIM1 runs centre-aligned at the 16 kHz base tick with the duties written by
//!   `board::write_duties`, and the gate drive is off after start-up.
//! - ADC timing: injected conversions arrive once per PWM period, finish within 2 µs of the
//!   trigger at the top of the count, and give counts inside the 12-bit range.
//! - QEI: TIM2 counts a quadrature pattern driven on its own pins (PA15/PB3 as outputs;
//!   unplug the encoder first): +4 per cycle one way, −4 the other.
//!
//! Run: `cd fw && cargo test -p board-tests --release` with the board attached (probe-rs).

#![no_std]
#![no_main]

use defmt_rtt as _;
use panic_probe as _;

#[defmt_test::tests]
mod tests {
    use drive_g474::board;
    use embassy_stm32::pac;
    use power_stage::fail_safe::FAIL_SAFE;
    use power_stage::tim1_words::{bdtr_with_moe, CR1_CEN, CR1_DIR};
    use power_stage::{adc_words, config::IHM08M1, tim1_words::tim1_words};
    use static_cell::StaticCell;

    static TX: StaticCell<[u8; 256]> = StaticCell::new();
    static RX: StaticCell<[u8; 256]> = StaticCell::new();

    /// 170 MHz core clock; one PWM period (16 kHz) in core cycles.
    const PERIOD_CYCLES: u32 = 170_000_000 / board::PWM_HZ;

    pub struct Board {
        _board: board::Board,
    }

    #[init]
    fn init() -> Board {
        let p = embassy_stm32::init(board::clocks());
        let b = board::init(p, TX.init([0; 256]), RX.init([0; 256]));
        // The cycle counter for timing.
        let mut cp = unsafe { cortex_m::Peripherals::steal() };
        cp.DCB.enable_trace();
        cp.DWT.enable_cycle_counter();
        Board { _board: b }
    }

    #[test]
    fn tim1_reads_back_as_the_model_s_words_with_the_bridge_off(_b: &mut Board) {
        let t = pac::TIM1;
        let w = tim1_words(&IHM08M1);
        defmt::assert!(w == board::TIM1_WORDS, "the board writes the model's words");
        // CEN is set and DIR is the counter's direction (read-only in centre-aligned mode).
        defmt::assert_eq!(t.cr1().read().0 & !(CR1_CEN | CR1_DIR), w.cr1, "CR1");
        defmt::assert!(t.cr1().read().0 & CR1_CEN != 0, "counter running");
        defmt::assert_eq!(t.cr2().read().0, w.cr2, "CR2");
        defmt::assert_eq!(t.ccmr_output(0).read().0, w.ccmr1, "CCMR1");
        defmt::assert_eq!(t.ccmr_output(1).read().0, w.ccmr2, "CCMR2");
        defmt::assert_eq!(t.ccer().read().0, w.ccer, "CCER");
        defmt::assert_eq!(t.bdtr().read().0, bdtr_with_moe(w.bdtr, false), "BDTR (MOE = 0)");
        defmt::assert_eq!(t.af1().read().0, w.af1, "AF1");
        defmt::assert_eq!(t.psc().read() as u32, w.psc, "PSC");
        defmt::assert_eq!(t.arr().read().0, w.arr, "ARR");
        defmt::assert_eq!(t.rcr().read().0, w.rcr, "RCR");
        defmt::assert_eq!(t.ccr(3).read().0, w.ccr4, "CCR4");
    }

    #[test]
    fn the_adcs_and_the_fail_safe_read_back_as_the_model_s_words(_b: &mut Board) {
        for (adc, seq, name) in
            [(pac::ADC1, &adc_words::ADC1_SEQUENCE[..], "ADC1"), (pac::ADC2, &adc_words::ADC2_SEQUENCE[..], "ADC2")]
        {
            defmt::assert_eq!(adc.jsqr().read().0, adc_words::jsqr(seq), "{} JSQR", name);
            defmt::assert_eq!(adc.smpr().read().0, adc_words::smpr1(seq), "{} SMPR1", name);
            defmt::assert!(adc.cr().read().jadstart(), "{} injected conversions armed", name);
        }
        defmt::assert_eq!(pac::ADC12_COMMON.ccr().read().0 & (3 << 16), adc_words::COMMON_CCR, "ADC12 CKMODE");
        defmt::assert!(pac::ADC1.ier().read().jeosie(), "ADC1 end of injected sequence interrupt");
        let f = FAIL_SAFE;
        defmt::assert_eq!(pac::DBGMCU.apb2fzr().read().0 & f.dbgmcu_apb2fzr, f.dbgmcu_apb2fzr, "DBG_TIM1_STOP");
        defmt::assert_eq!(pac::DBGMCU.apb1lfzr().read().0 & f.dbgmcu_apb1fzr1, f.dbgmcu_apb1fzr1, "DBG_IWDG_STOP");
        defmt::assert_eq!(pac::SYSCFG.cfgr2().read().0 & f.syscfg_cfgr2, f.syscfg_cfgr2, "SYSCFG CFGR2.CLL");
    }

    #[test]
    fn with_the_bridge_off_the_gate_pins_hold_every_fet_off(_b: &mut Board) {
        use pac::gpio::vals::Moder;
        defmt::assert!(!pac::TIM1.bdtr().read().moe(), "MOE = 0");
        // HIN pins low, LIN pins high, and the timer drives them (alternate function).
        for (port, pin, high, name) in [
            (pac::GPIOA, 8usize, false, "PA8 U HIN"),
            (pac::GPIOA, 9, false, "PA9 V HIN"),
            (pac::GPIOA, 10, false, "PA10 W HIN"),
            (pac::GPIOA, 7, true, "PA7 U LIN"),
            (pac::GPIOB, 0, true, "PB0 V LIN"),
            (pac::GPIOB, 1, true, "PB1 W LIN"),
        ] {
            defmt::assert!(port.moder().read().moder(pin) == Moder::ALTERNATE, "{} in alternate function", name);
            for _ in 0..100 {
                defmt::assert_eq!(port.idr().read().idr(pin) == pac::gpio::vals::Idr::HIGH, high, "{} level", name);
                cortex_m::asm::delay(1_700); // 10 µs: sixteen samples a PWM period
            }
        }
    }

    #[test]
    fn pwm_is_centre_aligned_at_the_base_tick_with_the_written_duties_and_the_gates_off(_b: &mut Board) {
        let t = pac::TIM1;
        let top = t.arr().read().arr() as u32;
        // Centre-aligned: the counter goes up and down, one period = 2·ARR timer clocks.
        let expected = 170_000_000 / (2 * board::PWM_HZ);
        defmt::assert!(top.abs_diff(expected) <= 1, "ARR {} for {} Hz", top, board::PWM_HZ);
        defmt::assert!(t.cr1().read().cms() as u8 != 0, "centre-aligned counting");
        board::write_duties([0.25, 0.5, 0.75]);
        for (n, d) in [0.25f32, 0.5, 0.75].into_iter().enumerate() {
            let ccr = t.ccr(n).read().ccr() as f32;
            defmt::assert!((ccr - d * top as f32).abs() <= 1.0, "CCR{} = {}", n + 1, ccr);
        }
        defmt::assert!(!t.bdtr().read().moe(), "gate drive off after start-up");
        board::write_duties([0.0; 3]);
    }

    #[test]
    fn injected_conversions_come_once_per_period_right_after_the_top_of_the_count(_b: &mut Board) {
        let adc = pac::ADC1;
        let wait = || {
            let start = cortex_m::peripheral::DWT::cycle_count();
            while !adc.isr().read().jeos() {
                defmt::assert!(
                    cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start) < 4 * PERIOD_CYCLES,
                    "no conversion within four periods"
                );
            }
            let at = cortex_m::peripheral::DWT::cycle_count();
            let counter = pac::TIM1.cnt().read().cnt() as u32;
            let sample = board::take_sample();
            let [u, v, w] = sample.shunts;
            (at, counter, [u, v, w, sample.bus, sample.accelerometer])
        };
        wait();
        let (t0, _, _) = wait();
        let (t1, counter, counts) = wait();
        let period = t1.wrapping_sub(t0);
        defmt::assert!(
            period.abs_diff(PERIOD_CYCLES) < PERIOD_CYCLES / 100,
            "{} cycles between conversions, {} expected",
            period,
            PERIOD_CYCLES
        );
        // Triggered at ARR − 1 going up; done (polling latency included) within 270 timer
        // counts of the top on the way down: 170 with two ranks, and ADC1's third rank (the
        // accelerometer) adds 25 ADC clocks, 100 counts of the 170 MHz timer
        // (`power_stage::adc_words::sampling_window`).
        let top = pac::TIM1.arr().read().arr() as u32;
        defmt::assert!(top - counter.min(top) <= 270, "conversion seen at counter {} (top {})", counter, top);
        for c in counts {
            defmt::assert!(c <= 4095, "12-bit count {}", c);
        }
        defmt::info!("ADC: {} cycles per period, U/V/W/bus/accelerometer counts {}", period, counts);
    }

    #[test]
    fn the_quadrature_counter_follows_a_pattern_on_its_own_pins(_b: &mut Board) {
        use pac::gpio::vals::Moder;
        // A = PA15, B = PB3 as outputs; the timer's inputs still see the pins.
        let set = |a: bool, b: bool| {
            pac::GPIOA.bsrr().write(|w| if a { w.set_bs(15, true) } else { w.set_br(15, true) });
            pac::GPIOB.bsrr().write(|w| if b { w.set_bs(3, true) } else { w.set_br(3, true) });
            cortex_m::asm::delay(1_000);
        };
        set(false, false);
        pac::GPIOA.moder().modify(|w| w.set_moder(15, Moder::OUTPUT));
        pac::GPIOB.moder().modify(|w| w.set_moder(3, Moder::OUTPUT));
        let start = board::encoder_count();
        let forward = [(true, false), (true, true), (false, true), (false, false)];
        for _ in 0..10 {
            for (a, b) in forward {
                set(a, b);
            }
        }
        let up = board::encoder_count().wrapping_sub(start);
        for _ in 0..10 {
            for (a, b) in forward.iter().rev().skip(1).chain(core::iter::once(&(false, false))) {
                set(*a, *b);
            }
        }
        let back = board::encoder_count().wrapping_sub(start);
        pac::GPIOA.moder().modify(|w| w.set_moder(15, Moder::ALTERNATE));
        pac::GPIOB.moder().modify(|w| w.set_moder(3, Moder::ALTERNATE));
        defmt::assert!(up.abs() == 40, "ten cycles counted {} (want ±40)", up);
        defmt::assert_eq!(back, 0, "the way back returns to the start");
    }
}
