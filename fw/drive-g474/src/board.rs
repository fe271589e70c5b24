//! NUCLEO-G474RE with the X-NUCLEO-IHM08M1 power stage: clocks, pins and peripherals, and the
//! drive application's board interface on them ([`Stage`]: `drive_application::PowerStage`,
//! [`ParamPages`]: `drive_application::ParamFlash`). The register words come from the
//! `power-stage` crate (pure functions of its `IHM08M1` configuration, tested on the host
//! against models of TIM1's output stage, the L6398 and the shunt amplifiers); this module
//! writes them. Everything board-specific lives here and there, so a second board is a second
//! module implementing the same two traits.
//!
//! | signal | pin | peripheral |
//! |---|---|---|
//! | phase U high / low (L6398 HIN / LIN) | PA8 / PA7 | TIM1 CH1 / CH1N |
//! | phase V high / low | PA9 / PB0 | TIM1 CH2 / CH2N |
//! | phase W high / low | PA10 / PB1 | TIM1 CH3 / CH3N |
//! | overcurrent comparator (break) | PA6 | TIM1 BKIN (AF6), active low |
//! | phase U current / bus voltage | PA0 / PA1 | ADC1 IN1 / IN2 (injected ranks 1 / 2) |
//! | phase V current / phase W current | PC1 / PC0 | ADC2 IN7 / IN6 (injected ranks 1 / 2) |
//! | machine-end accelerometer (removable; seed 001) | PC3, morpho CN7 pin 37 | ADC1 IN9 (injected rank 3) |
//! | encoder A / B | PA15 / PB3 | TIM2 quadrature (32-bit counter) |
//! | host link | PA2 (TX) / PA3 (RX) | USART2, the ST-LINK virtual COM port |
//!
//! Gate drive (`power_stage::tim1_words` says why each bit is what it is): HIN active high,
//! LIN active low (CCxNP = 1), every output enabled once at set-up, the bridge gated only by
//! MOE; with MOE = 0 (start, break, software break, debug halt) the pins are driven HIN low,
//! LIN high (OSSI = 1, OISx = 0, OISxN = 1): every FET off.
//!
//! Sampling: TIM1 counts up and down (centre-aligned) at the 16 kHz base tick. Channel 4 in
//! PWM mode 2 with CCR4 = ARR − 1 rises near the top of the count, where the low sides
//! conduct and the shunts carry the phase currents; OC4REF is TRGO2, which starts the injected
//! sequences of ADC1 and ADC2 together. All three shunts are converted; the control loop
//! believes the two whose low sides conducted longest (`power_stage::shunt_selection`).
//! ADC1's end of injected sequence raises ADC1_2, where the control loop runs (`control`).
//!
//! Fail-safe (`power_stage::fail_safe`): TIM1 stops and its outputs go to their off state
//! while a debugger halts the core; a core lockup breaks TIM1; the control loop feeds an
//! independent watchdog (started by [`start_watchdog`]); the panic and HardFault handlers of
//! the binary call [`bridge_off_now`] first.
//!
//! Parameter storage: the last two 4 KiB pages of the flash (single-bank mode), at offsets
//! 0x7E000 and 0x7F000. The G474 has one flash bank here: an erase or a write stalls every
//! fetch from flash, the control interrupt's included, for up to 40 ms (page erase). So
//! [`ParamPages`] switches the gate drive off and lengthens the watchdog around each
//! operation (the application allows `SaveParams` only at rest and keeps the gate drive off
//! until the save is over).

use control_core::current_sensing::SensingScales;
use drive_application::board::{FlashError, ParamFlash, PowerStage, Sample};
use embassy_stm32::flash::{Blocking, Flash};
use embassy_stm32::pac;
use embassy_stm32::peripherals;
use embassy_stm32::time::Hertz;
use embassy_stm32::timer::qei::Qei;
use embassy_stm32::usart::{self, BufferedUart};
use embassy_stm32::{bind_interrupts, Peri, Peripherals};
use power_stage::adc_words;
use power_stage::config::IHM08M1;
use power_stage::fail_safe::{self, WatchdogWords, FAIL_SAFE};
use power_stage::ratings;
use power_stage::tim1_words::{self, bdtr_with_moe, compare_value, Tim1Words, CR1_CEN, EGR_UG};

bind_interrupts!(pub struct Irqs {
    USART2 => usart::BufferedInterruptHandler<peripherals::USART2>;
});

/// PWM frequency: the control core's base tick.
pub const PWM_HZ: u32 = IHM08M1.pwm_hz;
/// TIM1's set-up, word by word.
pub const TIM1_WORDS: Tim1Words = tim1_words::tim1_words(&IHM08M1);

/// ADC counts to amperes and volts for `control_core::current_sensing` (the IHM08M1's
/// amplifier inverts: a current into the motor lowers the count).
pub const SCALES: SensingScales = ratings::SCALES;

/// The parameters with this board's protective limits (bus 10–50 V, 24 A).
pub use power_stage::ratings::with_board_limits;

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

/// TIM1 and the six gate pins, owned for the program's life; set up by [`init`] from the
/// words, driven through [`write_duties`] and [`set_outputs`].
pub struct Bridge {
    _timer: Peri<'static, peripherals::TIM1>,
    _high_sides: (Peri<'static, peripherals::PA8>, Peri<'static, peripherals::PA9>, Peri<'static, peripherals::PA10>),
    _low_sides: (Peri<'static, peripherals::PA7>, Peri<'static, peripherals::PB0>, Peri<'static, peripherals::PB1>),
    _break_input: Peri<'static, peripherals::PA6>,
}

pub struct Board {
    pub bridge: Bridge,
    pub flash: ParamPages,
    /// Kept so that TIM2, its pins and its clock stay owned; read through [`encoder_count`].
    pub encoder: Qei<'static, peripherals::TIM2>,
    pub link: BufferedUart<'static>,
}

pub fn init(p: Peripherals, tx: &'static mut [u8], rx: &'static mut [u8]) -> Board {
    loss_of_control_to_break();
    // Until `gate_drive` hands the pins to the timer they are not driven (analog after
    // reset), and the L6398's own input pulls (HIN down, LIN up) keep both FETs off.
    gate_drive();
    let bridge = Bridge {
        _timer: p.TIM1,
        _high_sides: (p.PA8, p.PA9, p.PA10),
        _low_sides: (p.PA7, p.PB0, p.PB1),
        _break_input: p.PA6,
    };
    let encoder = Qei::new(p.TIM2, p.PA15, p.PB3, Default::default());
    adc_injected();
    let mut config = usart::Config::default();
    config.baudrate = 921_600;
    let link = BufferedUart::new(p.USART2, p.PA3, p.PA2, tx, rx, Irqs, config).expect("USART2 configuration");
    Board { bridge, flash: ParamPages { flash: Flash::new_blocking(p.FLASH) }, encoder, link }
}

/// DBG_TIM1_STOP (and DBG_IWDG_STOP: a breakpoint does not reset the chip), and the core's
/// lockup wired to TIM1's break (SYSCFG CFGR2.CLL, set until reset).
fn loss_of_control_to_break() {
    pac::DBGMCU.apb2fzr().modify(|w| w.0 |= FAIL_SAFE.dbgmcu_apb2fzr);
    pac::DBGMCU.apb1lfzr().modify(|w| w.0 |= FAIL_SAFE.dbgmcu_apb1fzr1);
    pac::RCC.apb2enr().modify(|w| w.set_syscfgen(true));
    pac::SYSCFG.cfgr2().modify(|w| w.0 |= FAIL_SAFE.syscfg_cfgr2);
}

/// TIM1 from its words, then its pins: clock on and timer reset; BDTR first (MOE = 0; the first
/// write after reset, so that its LOCK level takes), everything else, the outputs enabled
/// (off levels: HIN low, LIN high), preloads loaded, counter started. Only then the six gate
/// pins (pulls that agree with the off levels) and the break input on PA6 (pulled up: the
/// comparator pulls it low) go to alternate function 6, TIM1.
fn gate_drive() {
    use pac::gpio::vals::{Moder, Ospeedr, Pupdr};
    pac::RCC.apb2enr().modify(|w| w.set_tim1en(true));
    pac::RCC.apb2rstr().modify(|w| w.set_tim1rst(true));
    pac::RCC.apb2rstr().modify(|w| w.set_tim1rst(false));
    let t = pac::TIM1;
    let w = TIM1_WORDS;
    t.bdtr().write(|r| r.0 = w.bdtr); // MOE = 0, LOCK, whole word at once
    t.cr1().write(|r| r.0 = w.cr1); // CEN = 0
    t.cr2().write(|r| r.0 = w.cr2);
    t.ccmr_output(0).write(|r| r.0 = w.ccmr1);
    t.ccmr_output(1).write(|r| r.0 = w.ccmr2);
    t.psc().write_value(w.psc as u16);
    t.arr().write(|r| r.0 = w.arr);
    t.rcr().write(|r| r.0 = w.rcr);
    for n in 0..3 {
        t.ccr(n).write(|r| r.0 = 0);
    }
    t.ccr(3).write(|r| r.0 = w.ccr4);
    t.af1().write(|r| r.0 = w.af1);
    t.ccer().write(|r| r.0 = w.ccer);
    t.egr().write(|r| r.0 = EGR_UG);
    t.sr().write(|r| r.0 = 0);
    t.cr1().write(|r| r.0 = w.cr1 | CR1_CEN);
    const TIM1_AF: u8 = 6;
    for (port, pin, pull) in [
        (pac::GPIOA, 8, Pupdr::PULL_DOWN),
        (pac::GPIOA, 9, Pupdr::PULL_DOWN),
        (pac::GPIOA, 10, Pupdr::PULL_DOWN),
        (pac::GPIOA, 7, Pupdr::PULL_UP),
        (pac::GPIOB, 0, Pupdr::PULL_UP),
        (pac::GPIOB, 1, Pupdr::PULL_UP),
        (pac::GPIOA, 6, Pupdr::PULL_UP),
    ] {
        port.pupdr().modify(|r| r.set_pupdr(pin, pull));
        port.ospeedr().modify(|r| r.set_ospeedr(pin, Ospeedr::HIGH_SPEED));
        port.afr(pin / 8).modify(|r| r.set_afr(pin % 8, TIM1_AF));
        port.moder().modify(|r| r.set_moder(pin, Moder::ALTERNATE));
    }
    t.sr().write(|r| r.0 = 0); // a break flag from the pin's switch-over
}

/// ADC1 (phase U, bus, accelerometer) and ADC2 (phase V, phase W): injected sequences on TIM1_TRGO2, 12
/// bits, synchronous clock HCLK/4 = 42.5 MHz, 12.5-cycle sampling (`power_stage::adc_words`).
fn adc_injected() {
    pac::RCC.ahb2enr().modify(|w| w.set_adc12en(true));
    pac::ADC12_COMMON.ccr().modify(|w| w.0 = (w.0 & !(3 << 16)) | adc_words::COMMON_CCR);
    for (adc, sequence) in [(pac::ADC1, &adc_words::ADC1_SEQUENCE[..]), (pac::ADC2, &adc_words::ADC2_SEQUENCE[..])] {
        use pac::adc::vals::Adcaldif;
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
        adc.smpr().write(|w| w.0 = adc_words::smpr1(sequence));
        adc.jsqr().write(|w| w.0 = adc_words::jsqr(sequence));
        adc.cr().modify(|w| w.set_jadstart(true));
    }
    pac::ADC1.isr().write(|w| w.set_jeos(true));
    pac::ADC1.ier().modify(|w| w.set_jeosie(true));
}

/// One sample: the three shunt counts (U, V, W), the bus voltage count and the
/// accelerometer's count (why PC3: `power_stage::adc_words`). Acknowledges both ADCs' end of
/// sequence; ADC2 was triggered with ADC1 and converts fewer ranks, so it has finished too
/// (waited for, a few clocks at most).
#[inline(always)]
pub fn take_sample() -> Sample {
    let (a1, a2) = (pac::ADC1, pac::ADC2);
    let mut spins = 0;
    while !a2.isr().read().jeos() && spins < 64 {
        spins += 1;
    }
    a1.isr().write(|w| w.set_jeos(true));
    a2.isr().write(|w| w.set_jeos(true));
    Sample {
        shunts: [a1.jdr(0).read().jdata(), a2.jdr(0).read().jdata(), a2.jdr(1).read().jdata()],
        bus: a1.jdr(1).read().jdata(),
        accelerometer: a1.jdr(2).read().jdata(),
    }
}

/// The encoder's 32-bit quadrature count.
#[inline(always)]
pub fn encoder_count() -> i32 {
    pac::TIM2.cnt().read() as i32
}

/// Duty cycles 0..1 of the three half-bridges (clamped: the core gives 0..1 already).
#[inline(always)]
pub fn write_duties(d: [f32; 3]) {
    for (n, duty) in d.into_iter().enumerate() {
        pac::TIM1.ccr(n).write(|w| w.0 = compare_value(duty, TIM1_WORDS.arr));
    }
}

/// Gate drive on or off (main output enable; the whole BDTR word). Off takes effect at once.
#[inline(always)]
pub fn set_outputs(on: bool) {
    pac::TIM1.bdtr().write(|w| w.0 = bdtr_with_moe(TIM1_WORDS.bdtr, on));
}

/// Every FET off now, from any context: a software break (MOE cleared by the hardware, as by
/// the break input), then MOE cleared by a write in case the break is not taken.
#[inline(always)]
pub fn bridge_off_now() {
    pac::TIM1.egr().write(|w| w.0 = fail_safe::BRIDGE_OFF_EGR);
    pac::TIM1.bdtr().write(|w| w.0 = TIM1_WORDS.bdtr);
}

/// Start the independent watchdog (about 4 ms; it cannot be stopped until reset). Call right
/// before the control loop starts: from then on the loop feeds it every tick.
pub fn start_watchdog() {
    let Some(w) = FAIL_SAFE.watchdog else { return };
    let iwdg = pac::IWDG;
    iwdg.kr().write(|k| k.0 = fail_safe::IWDG_KEY_START as u32);
    iwdg.kr().write(|k| k.0 = fail_safe::IWDG_KEY_UNLOCK as u32);
    iwdg.pr().write(|r| r.0 = w.pr as u32);
    iwdg.rlr().write(|r| r.0 = w.rlr as u32);
    while iwdg.sr().read().0 != 0 {}
    feed_watchdog();
}

/// One feed of the independent watchdog.
#[inline(always)]
pub fn feed_watchdog() {
    pac::IWDG.kr().write(|k| k.0 = fail_safe::IWDG_KEY_FEED as u32);
}

/// The break input switched the bridge off since the last call (clears the flag; the flag
/// comes back while the input stays active).
#[inline(always)]
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

/// The power stage as the drive application's control tick uses it: the functions above.
pub struct Stage;

impl PowerStage for Stage {
    const SCALES: SensingScales = SCALES;
    const TICK_HZ: f32 = power_stage::config::IHM08M1.pwm_hz as f32;
    const ACCELEROMETER_VOLTS_PER_COUNT: f32 = ratings::ACCELEROMETER_VOLTS_PER_COUNT;
    #[inline(always)]
    fn take_sample(&mut self) -> Sample {
        take_sample()
    }
    #[inline(always)]
    fn encoder_count(&mut self) -> i32 {
        encoder_count()
    }
    #[inline(always)]
    fn break_tripped(&mut self) -> bool {
        break_tripped()
    }
    /// Believe the two shunts whose low sides conducted longest under `duties_in_force`.
    #[inline(always)]
    fn phase_currents(&self, shunt_amps: [f32; 3], duties_in_force: [f32; 3]) -> [f32; 2] {
        power_stage::shunt_selection::phase_currents(shunt_amps, duties_in_force)
    }
    #[inline(always)]
    fn write_duties(&mut self, duties: [f32; 3]) {
        write_duties(duties)
    }
    #[inline(always)]
    fn set_outputs(&mut self, on: bool) {
        set_outputs(on)
    }
    #[inline(always)]
    fn feed_watchdog(&mut self) {
        feed_watchdog()
    }
}

/// Offset (from the start of flash) of the first parameter page; the second follows.
pub const PARAM_PAGES_OFFSET: u32 = 0x7_E000;
/// The G474's page in single-bank mode.
pub const PARAM_PAGE_BYTES: u32 = 4096;

/// The two parameter pages, through Embassy's blocking flash driver (its calls that take no
/// critical section: the stall itself already holds everything off).
pub struct ParamPages {
    flash: Flash<'static, Blocking>,
}

impl ParamPages {
    fn offset(page: usize, offset: usize, len: usize) -> Result<u32, FlashError> {
        if page > 1 || offset + len > PARAM_PAGE_BYTES as usize || !image_below_param_pages() {
            return Err(FlashError::Alignment);
        }
        Ok(PARAM_PAGES_OFFSET + page as u32 * PARAM_PAGE_BYTES + offset as u32)
    }
}

/// The program image (code, read-only data and the initial image of `.data`) ends below the
/// parameter pages (the linker's memory map gives the whole flash to the program).
fn image_below_param_pages() -> bool {
    extern "C" {
        static __sidata: u32;
        static __sdata: u32;
        static __edata: u32;
    }
    // Addresses of cortex-m-rt's linker symbols, not their contents.
    let (load, start, end) = (
        core::ptr::addr_of!(__sidata) as u32,
        core::ptr::addr_of!(__sdata) as u32,
        core::ptr::addr_of!(__edata) as u32,
    );
    load + (end - start) <= 0x0800_0000 + PARAM_PAGES_OFFSET
}

/// `f` with the gate drive off and the watchdog at about 200 ms (the flash stalls the
/// control interrupt; a page erase takes up to 40 ms), then the watchdog as before.
fn stalling<R>(f: impl FnOnce() -> R) -> R {
    set_outputs(false);
    let normal = FAIL_SAFE.watchdog;
    if normal.is_some() {
        set_watchdog(FLASH_WATCHDOG);
    }
    let r = f();
    if let Some(w) = normal {
        set_watchdog(w);
    }
    r
}

/// The watchdog while the flash stalls the processor: 200 ms.
const FLASH_WATCHDOG: WatchdogWords = fail_safe::watchdog_words(200_000, fail_safe::LSI_HZ);

/// New prescaler and reload of the running watchdog (waits for the previous update), fed.
fn set_watchdog(w: WatchdogWords) {
    let iwdg = pac::IWDG;
    feed_watchdog();
    while iwdg.sr().read().0 != 0 {}
    iwdg.kr().write(|k| k.0 = fail_safe::IWDG_KEY_UNLOCK as u32);
    iwdg.pr().write(|r| r.0 = w.pr as u32);
    iwdg.rlr().write(|r| r.0 = w.rlr as u32);
    while iwdg.sr().read().0 != 0 {}
    feed_watchdog();
}

impl ParamFlash for ParamPages {
    const PAGE_BYTES: usize = PARAM_PAGE_BYTES as usize;
    const WRITE_BYTES: usize = 8;
    fn read(&mut self, page: usize, offset: usize, bytes: &mut [u8]) -> Result<(), FlashError> {
        let at = Self::offset(page, offset, bytes.len())?;
        self.flash.blocking_read(at, bytes).map_err(|_| FlashError::Hardware)
    }
    fn erase(&mut self, page: usize) -> Result<(), FlashError> {
        let at = Self::offset(page, 0, PARAM_PAGE_BYTES as usize)?;
        stalling(|| self.flash.blocking_erase(at, at + PARAM_PAGE_BYTES)).map_err(|_| FlashError::Hardware)
    }
    fn program(&mut self, page: usize, offset: usize, bytes: &[u8]) -> Result<(), FlashError> {
        if !offset.is_multiple_of(8) || !bytes.len().is_multiple_of(8) {
            return Err(FlashError::Alignment);
        }
        let at = Self::offset(page, offset, bytes.len())?;
        stalling(|| self.flash.blocking_write(at, bytes)).map_err(|_| FlashError::Hardware)
    }
}
