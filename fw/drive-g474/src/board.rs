//! NUCLEO-G474RE with the X-NUCLEO-IHM08M1 power stage: pins and peripherals. Everything
//! board-specific lives here, so a second board is a second module.
//!
//! | signal | pin | peripheral |
//! |---|---|---|
//! | phase U high / low | PA8 / PA7 | TIM1 CH1 / CH1N |
//! | phase V high / low | PA9 / PB0 | TIM1 CH2 / CH2N |
//! | phase W high / low | PA10 / PB1 | TIM1 CH3 / CH3N |
//! | encoder A / B | PA15 / PB3 | TIM2 quadrature |
//! | host link | PA2 (TX) / PA3 (RX) | USART2, the ST-LINK virtual COM port |

use embassy_stm32::peripherals;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin};
use embassy_stm32::timer::qei::Qei;
use embassy_stm32::timer::simple_pwm::PwmPin;
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::gpio::OutputType;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, Peripherals};

bind_interrupts!(pub struct Irqs {
    USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
});

/// PWM frequency: the control core's base tick (centre-aligned: the counter period is two
/// ticks of the carrier, so the carrier is set to the tick rate).
pub const PWM_HZ: u32 = 16_000;
/// Dead time in timer clocks (170 MHz: about 500 ns).
pub const DEAD_TIME: u16 = 85;

pub struct Board {
    pub bridge: ComplementaryPwm<'static, peripherals::TIM1>,
    pub encoder: Qei<'static, peripherals::TIM2>,
    pub link: BufferedUart<'static>,
}

pub fn init(p: Peripherals, tx: &'static mut [u8], rx: &'static mut [u8]) -> Board {
    let mut bridge = ComplementaryPwm::new(
        p.TIM1,
        Some(PwmPin::new(p.PA8, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PA7, OutputType::PushPull)),
        Some(PwmPin::new(p.PA9, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PB0, OutputType::PushPull)),
        Some(PwmPin::new(p.PA10, OutputType::PushPull)),
        Some(ComplementaryPwmPin::new(p.PB1, OutputType::PushPull)),
        None,
        None,
        Hertz(PWM_HZ),
        CountingMode::CenterAlignedBothInterrupts,
    );
    bridge.set_dead_time(DEAD_TIME);
    // The bridge stays off: see `control` (no current sensing yet).
    bridge.set_master_output_enable(false);
    let encoder = Qei::new(p.TIM2, p.PA15, p.PB3, Default::default());
    let mut config = usart::Config::default();
    config.baudrate = 921_600;
    let link = BufferedUart::new(p.USART2, p.PA3, p.PA2, tx, rx, Irqs, config).expect("USART2 configuration");
    Board { bridge, encoder, link }
}
