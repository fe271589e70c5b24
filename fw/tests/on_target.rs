//! On-target tests of the board code (NUCLEO-G474RE; the power stage may be absent: the
//! bridge's gate drive stays off throughout).
//!
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
                defmt::assert!(cortex_m::peripheral::DWT::cycle_count().wrapping_sub(start) < 4 * PERIOD_CYCLES, "no conversion within four periods");
            }
            let at = cortex_m::peripheral::DWT::cycle_count();
            let counter = pac::TIM1.cnt().read().cnt() as u32;
            let ([a, b], bus) = board::take_sample();
            (at, counter, [a, b, bus])
        };
        wait();
        let (t0, _, _) = wait();
        let (t1, counter, counts) = wait();
        let period = t1.wrapping_sub(t0);
        defmt::assert!(period.abs_diff(PERIOD_CYCLES) < PERIOD_CYCLES / 100, "{} cycles between conversions, {} expected", period, PERIOD_CYCLES);
        // Triggered at ARR − 1 going up; done (polling latency included) within 2 µs, i.e.
        // within 170 timer counts of the top on the way down.
        let top = pac::TIM1.arr().read().arr() as u32;
        defmt::assert!(top - counter.min(top) <= 170, "conversion seen at counter {} (top {})", counter, top);
        for c in counts {
            defmt::assert!(c <= 4095, "12-bit count {}", c);
        }
        defmt::info!("ADC: {} cycles per period, phase/phase/bus counts {}", period, counts);
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
