//! NUCLEO-G474RE with the X-NUCLEO-IHM08M1 power stage: clocks, pins, peripherals and the
//! register-level set-up of the current sampling. Everything board-specific lives here, so a
//! second board is a second module with the same functions.
//!
//! | signal | pin | peripheral |
//! |---|---|---|
//! | phase U high / low | PA8 / PA7 | TIM1 CH1 / CH1N |
//! | phase V high / low | PA9 / PB0 | TIM1 CH2 / CH2N |
//! | phase W high / low | PA10 / PB1 | TIM1 CH3 / CH3N |
//! | overcurrent comparator (break) | PA6 | TIM1 BKIN (AF6), active low |
//! | phase U current | PA0 | ADC1 IN1 (injected rank 1) |
//! | bus voltage | PA1 | ADC1 IN2 (injected rank 2) |
//! | phase V current | PC1 | ADC2 IN7 (injected rank 1) |
//! | encoder A / B | PA15 / PB3 | TIM2 quadrature (32-bit counter) |
//! | host link | PA2 (TX) / PA3 (RX) | USART2, the ST-LINK virtual COM port |
//!
//! Sampling: TIM1 counts up and down (centre-aligned) at the 16 kHz base tick. Channel 4 in
//! PWM mode 2 with CCR4 = ARR − 1 rises near the top of the count, where every high-side
//! switch is off and the low-side shunts carry the phase currents; OC4REF is TIM1's TRGO2,
//! which starts the injected conversions of ADC1 and ADC2 together (RM0440: injected external
//! trigger 8 of ADC1/2 is TIM1_TRGO2). ADC1's end of injected sequence raises ADC1_2, where
//! the control loop runs (`control`).
//!
//! The scales are the IHM08M1's (UM1996): 10 mΩ shunts into an amplifier of gain 5.18 biased
//! at half the 3.3 V reference, and a 169 kΩ / 9.31 kΩ bus divider. They have not been checked
//! on a board yet: compare the first logged offsets and bus voltage with a meter before
//! enabling a motor.

use control_core::current_sensing::SensingScales;
use embassy_stm32::gpio::OutputType;
use embassy_stm32::pac;
use embassy_stm32::peripherals;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::complementary_pwm::{ComplementaryPwm, ComplementaryPwmPin};
use embassy_stm32::timer::low_level::CountingMode;
use embassy_stm32::timer::qei::Qei;
use embassy_stm32::timer::simple_pwm::PwmPin;
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

const SHUNT_OHM: f32 = 0.010;
const AMPLIFIER_GAIN: f32 = 5.18;
const VREF: f32 = 3.3;
const BUS_DIVIDER: f32 = (169.0 + 9.31) / 9.31;

/// ADC counts to amperes and volts for `control_core::current_sensing`. Sign: positive
/// current into the motor is taken to raise the count; if the first run on a board shows the
/// opposite (the current loop runs away at once), the sign here is what changes.
pub const SCALES: SensingScales = SensingScales {
    full_scale: 4095,
    amps_per_count: VREF / 4095.0 / (SHUNT_OHM * AMPLIFIER_GAIN),
    volts_per_count: VREF / 4095.0 * BUS_DIVIDER,
};

/// 170 MHz from the NUCLEO's 24 MHz crystal: 24 / 6 × 85 / 2, range-1 boost.
pub fn clocks() -> embassy_stm32::Config {
    use embassy_stm32::rcc::{Hse, HseMode, Pll, PllMul, PllPreDiv, PllRDiv, PllSource, Sysclk};
    let mut config = embassy_stm32::Config::default();
    config.rcc.hse = Some(Hse { freq: Hertz(24_000_000), mode: HseMode::Oscillator });
    config.rcc.pll = Some(Pll {
        source: PllSource::HSE,
        prediv: PllPreDiv::DIV6,
        mul: PllMul::MUL85,
        divp: None,
        divq: None,
        divr: Some(PllRDiv::DIV2),
    });
    config.rcc.sys = Sysclk::PLL1_R;
    config.rcc.boost = true;
    config
}

pub struct Board {
    /// Kept so that the timer, its pins and its clock stay owned; the loop drives it
    /// through [`write_duties`] and [`set_outputs`].
    pub bridge: ComplementaryPwm<'static, peripherals::TIM1>,
    /// Kept for the same reason; read through [`encoder_count`].
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
    // Off until the control loop has calibrated the current offsets and the core allows it.
    bridge.set_master_output_enable(false);
    let encoder = Qei::new(p.TIM2, p.PA15, p.PB3, Default::default());
    sampling_trigger_and_break();
    adc_injected();
    let mut config = usart::Config::default();
    config.baudrate = 921_600;
    let link = BufferedUart::new(p.USART2, p.PA3, p.PA2, tx, rx, Irqs, config).expect("USART2 configuration");
    Board { bridge, encoder, link }
}

/// TIM1 channel 4 as the sampling trigger (TRGO2) and the break input on PA6.
fn sampling_trigger_and_break() {
    use pac::gpio::vals::{Moder, Pupdr};
    use pac::timer::vals::{Bkp, FilterValue, Mms2, Ocm};
    let t = pac::TIM1;
    let top = t.arr().read().arr();
    t.ccr(3).write(|w| w.set_ccr(top.saturating_sub(1)));
    t.ccmr_output(1).modify(|w| w.set_ocm(1, Ocm::PWM_MODE2));
    t.ccer().modify(|w| w.set_cce(3, false)); // internal only: no pin
    t.cr2().modify(|w| w.set_mms2(Mms2::COMPARE_OC4));
    // PA6 = TIM1_BKIN (AF6), pulled up: the IHM08M1's comparator pulls it low.
    pac::GPIOA.pupdr().modify(|w| w.set_pupdr(6, Pupdr::PULL_UP));
    pac::GPIOA.afr(0).modify(|w| w.set_afr(6, 6));
    pac::GPIOA.moder().modify(|w| w.set_moder(6, Moder::ALTERNATE));
    t.bdtr().modify(|w| {
        w.set_bkp(0, Bkp::ACTIVE_LOW);
        w.set_bkf(0, FilterValue::FDTS_DIV2_N6);
        w.set_bke(0, true);
        w.set_aoe(false); // stays off after a break until the core clears its fault
    });
    t.sr().modify(|w| w.set_bif(0, false));
}

/// ADC1 (phase U, bus) and ADC2 (phase V): injected sequences on TIM1_TRGO2, 12 bits,
/// synchronous clock HCLK/4 = 42.5 MHz, 12.5-cycle sampling (conversion of both ranks
/// about 0.6 µs).
fn adc_injected() {
    use pac::adc::vals::{Adcaldif, Exten, SampleTime};
    use pac::adccommon::vals::Ckmode;
    pac::RCC.ahb2enr().modify(|w| w.set_adc12en(true));
    pac::ADC12_COMMON.ccr().modify(|w| w.set_ckmode(Ckmode::SYNC_DIV4));
    for (adc, channels) in [(pac::ADC1, &[1u8, 2][..]), (pac::ADC2, &[7u8][..])] {
        adc.cr().modify(|w| {
            w.set_deeppwd(false);
            w.set_advregen(true);
        });
        cortex_m::asm::delay(170 * 25); // regulator start-up, 20 µs
        adc.cr().modify(|w| {
            w.set_adcaldif(Adcaldif::SINGLE_ENDED);
            w.set_adcal(true);
        });
        while adc.cr().read().adcal() {}
        cortex_m::asm::delay(100); // ADEN at least 4 ADC clocks after the calibration
        adc.isr().write(|w| w.set_adrdy(true));
        adc.cr().modify(|w| w.set_aden(true));
        while !adc.isr().read().adrdy() {}
        for &ch in channels {
            adc.smpr().modify(|w| w.set_smp(ch as usize, SampleTime::CYCLES12_5));
        }
        adc.jsqr().write(|w| {
            w.set_jl(channels.len() as u8 - 1);
            w.set_jextsel(8); // TIM1_TRGO2
            w.set_jexten(Exten::RISING_EDGE);
            for (rank, &ch) in channels.iter().enumerate() {
                w.set_jsq(rank, ch);
            }
        });
        adc.cr().modify(|w| w.set_jadstart(true));
    }
    pac::ADC1.isr().write(|w| w.set_jeos(true));
    pac::ADC1.ier().modify(|w| w.set_jeosie(true));
}

/// One sample: phase U and V current counts, bus voltage count. Acknowledges ADC1's end of
/// sequence; ADC2 was triggered together and has finished (one rank against two).
pub fn take_sample() -> ([u16; 2], u16) {
    let (a1, a2) = (pac::ADC1, pac::ADC2);
    a1.isr().write(|w| w.set_jeos(true));
    a2.isr().write(|w| w.set_jeos(true));
    ([a1.jdr(0).read().jdata(), a2.jdr(0).read().jdata()], a1.jdr(1).read().jdata())
}

/// The encoder's 32-bit quadrature count.
pub fn encoder_count() -> i32 {
    pac::TIM2.cnt().read() as i32
}

/// Duty cycles 0..1 of the three half-bridges (clamped: the core gives 0..1 already).
pub fn write_duties(d: [f32; 3]) {
    let top = pac::TIM1.arr().read().arr() as f32;
    for (n, duty) in d.into_iter().enumerate() {
        pac::TIM1.ccr(n).write(|w| w.set_ccr((duty.clamp(0.0, 1.0) * top) as u16));
    }
}

/// Gate drive on or off (main output enable). Off takes effect at once.
pub fn set_outputs(on: bool) {
    pac::TIM1.bdtr().modify(|w| w.set_moe(on));
}

/// The break input switched the bridge off since the last call (clears the flag; the flag
/// comes back while the input stays active).
pub fn break_tripped() -> bool {
    let t = pac::TIM1;
    let tripped = t.sr().read().bif(0);
    if tripped {
        t.sr().modify(|w| w.set_bif(0, false));
    }
    tripped
}

/// Interrupt of the injected end of sequence, for `control` to enable.
pub const SAMPLE_INTERRUPT: embassy_stm32::interrupt::Interrupt = embassy_stm32::interrupt::ADC1_2;
