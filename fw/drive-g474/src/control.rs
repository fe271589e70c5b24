//! The control loop: `Axis::step` at the base tick, the same function the FMU calls.
//!
//! Status: the encoder is read (its 16-bit counter extended to the core's wrapping 32 bits)
//! and the core runs at 16 kHz from a high-priority executor; the phase currents and the bus
//! voltage are NOT measured yet (the ADC injected conversions triggered by TIM1 are still to
//! be written). Until they are, the bridge stays disabled whatever the core computes: a
//! current loop fed with made-up currents must never drive a motor.

use core::cell::RefCell;
use core::mem::MaybeUninit;

use control_core::{Axis, AxisInputs, Commands, Params, Telemetry};
use embassy_stm32::timer::complementary_pwm::ComplementaryPwm;
use embassy_stm32::timer::qei::Qei;
use embassy_stm32::{peripherals, timer::Channel};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_time::{Duration, Ticker};

/// What the link and the loop share.
pub struct Shared {
    pub axis: Axis,
    pub commands: Commands,
    pub telemetry: Telemetry,
}

/// The shared state, filled once by [`install`]. Uninitialised until then, so that its 16 KB
/// (the axis holds room for the largest acc/dec filter) go to `.bss`, not into flash as an
/// initial image (an `Option` would have put them in `.data`).
pub struct Slot {
    installed: bool,
    value: MaybeUninit<Shared>,
}

impl Slot {
    pub fn get(&mut self) -> Option<&mut Shared> {
        // SAFETY: `value` is written by `install` before `installed` is set, and never after.
        self.installed.then(|| unsafe { self.value.assume_init_mut() })
    }
}

pub static SHARED: Mutex<CriticalSectionRawMutex, RefCell<Slot>> =
    Mutex::new(RefCell::new(Slot { installed: false, value: MaybeUninit::uninit() }));

pub fn install(params: Params) -> Result<(), control_core::ParamError> {
    let axis = Axis::new(params)?;
    SHARED.lock(|s| {
        let mut s = s.borrow_mut();
        if !s.installed {
            s.value.write(Shared { axis, commands: Commands::default(), telemetry: Telemetry::default() });
            s.installed = true;
        }
    });
    Ok(())
}

/// The 16-bit quadrature counter extended to a wrapping 32-bit count.
struct EncoderCount {
    last: u16,
    count: i32,
}

impl EncoderCount {
    fn update(&mut self, raw: u16) -> i32 {
        self.count = self.count.wrapping_add(raw.wrapping_sub(self.last) as i16 as i32);
        self.last = raw;
        self.count
    }
}

#[embassy_executor::task]
pub async fn control_loop(mut bridge: ComplementaryPwm<'static, peripherals::TIM1>, encoder: Qei<'static, peripherals::TIM2>) {
    let period = Duration::from_hz(control_core::Params::default().rates.current_loop_hz as u64);
    let mut ticker = Ticker::every(period);
    let mut count = EncoderCount { last: encoder.count(), count: 0 };
    let max = bridge.get_max_duty();
    let mut ticks: u32 = 0;
    loop {
        ticker.next().await;
        let raw = count.update(encoder.count());
        let duties = SHARED.lock(|s| {
            let mut s = s.borrow_mut();
            let s = s.get()?;
            // Not measured yet (see the module doc): zero currents, nominal bus.
            let inputs = AxisInputs { phase_currents: [0.0, 0.0], encoder_count: raw, bus_voltage: 48.0 };
            let commands = s.commands;
            let pwm = s.axis.step(&inputs, &commands);
            s.telemetry = *s.axis.telemetry();
            Some(pwm.duties)
        });
        if let Some(d) = duties {
            for (ch, duty) in [Channel::Ch1, Channel::Ch2, Channel::Ch3].into_iter().zip(d) {
                bridge.set_duty(ch, (duty.clamp(0.0, 1.0) * max as f32) as u32);
            }
        }
        // The bridge stays off until the currents are measured (see the module doc).
        bridge.set_master_output_enable(false);
        ticks = ticks.wrapping_add(1);
        if ticks % 16_000 == 0 {
            defmt::info!("control loop alive, encoder {}", raw);
        }
    }
}
