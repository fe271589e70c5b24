//! The control loop: `Axis::step` in the ADC's end-of-conversion interrupt at the base tick,
//! the same function the FMU calls; a task in the high-priority executor, woken from that
//! interrupt once per position tick, does what may wait a little (fault logs, health).
//!
//! Per tick, in the interrupt:
//! 1. take the three sampled shunt currents and the bus voltage, the encoder count and the
//!    break flag;
//! 2. until the current offsets are calibrated (bridge off), feed the calibration instead;
//!    implausible offsets latch a sensing fault and the bridge never comes on;
//! 3. of the three shunts, believe the two whose low sides conducted longest under the duties
//!    that were in force when they were sampled (`board::phase_currents`);
//! 4. a break (the power stage's own overcurrent comparator) latches a core fault;
//! 5. `Axis::step`; the duties go to TIM1 and the gate drive follows the core's `enabled`
//!    at once, so any fault the core sees (overcurrent, bus over/under-voltage, following
//!    error, encoder jump, a non-finite value) switches the PWM off within the tick;
//! 6. the latest acquisition sample is offered to the link's stream;
//! 7. the independent watchdog is fed: a loop that stops running resets the chip.

use core::cell::RefCell;
use core::mem::MaybeUninit;
use core::sync::atomic::{AtomicU32, Ordering};

use control_core::acquisition_stream::AcquisitionStream;
use control_core::current_sensing::CurrentSensing;
use control_core::faults::Faults;
use control_core::{Axis, AxisInputs, Commands, Params};
use embassy_stm32::interrupt;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::signal::Signal;

use crate::board;

/// What the link and the loop share.
pub struct Shared {
    pub axis: Axis,
    pub commands: Commands,
    pub sensing: CurrentSensing<{ board::CURRENT_CHANNELS }>,
    pub stream: AcquisitionStream,
    /// The duties written last tick: in force when this tick's currents were sampled (the
    /// compare registers are preloaded and take new values at the next update event, before
    /// the top of the count where the ADCs sample).
    pub duties_in_force: [f32; 3],
    /// The bus voltage of the last tick (V), for the log.
    pub bus_voltage: f32,
}

/// The shared state, filled once by [`install`]. Uninitialised until then, so that its
/// kilobytes (the axis holds room for the largest acc/dec filter) go to `.bss`, not into
/// flash as an initial image (an `Option` would have put them in `.data`).
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

/// Woken once per position tick from the interrupt.
static POSITION_TICK: Signal<CriticalSectionRawMutex, Faults> = Signal::new();
/// Interrupts since start (health: the link can read it in logs).
static TICKS: AtomicU32 = AtomicU32::new(0);

pub fn install(params: Params) -> Result<(), &'static str> {
    let axis = Axis::new(params).map_err(|_| "parameters refused by the core")?;
    let sensing = CurrentSensing::new(board::SCALES).map_err(|_| "sensing scales refused by the core")?;
    SHARED.lock(|s| {
        let mut s = s.borrow_mut();
        if !s.installed {
            s.value.write(Shared {
                axis,
                commands: Commands::default(),
                sensing,
                stream: AcquisitionStream::default(),
                duties_in_force: [0.0; 3],
                bus_voltage: 0.0,
            });
            s.installed = true;
        }
    });
    Ok(())
}

/// Enable the sampling interrupt at the highest priority.
pub fn start(priority: interrupt::Priority) {
    use embassy_stm32::interrupt::InterruptExt;
    board::SAMPLE_INTERRUPT.set_priority(priority);
    // SAFETY: the handler below touches only `SHARED` (under its mutex) and the board's
    // registers that nothing else writes after `board::init`.
    unsafe { board::SAMPLE_INTERRUPT.enable() };
}

/// One control tick; called from the sampling interrupt (the binary binds it).
pub fn on_sample() {
    let (shunts, bus) = board::take_sample();
    let count = board::encoder_count();
    let broke = board::break_tripped();
    let position_tick = SHARED.lock(|s| {
        let mut s = s.borrow_mut();
        let Some(s) = s.get() else {
            board::set_outputs(false);
            return None;
        };
        // The break flag is read (and cleared) every tick: latch it even while calibrating.
        if broke {
            s.axis.latch_fault(Faults::HARDWARE_BREAK);
        }
        let Some((shunt_amps, bus_voltage)) = s.sensing.convert(shunts, bus) else {
            // Calibrating with the bridge off; a failure latches a fault for good.
            board::set_outputs(false);
            if s.sensing.calibrate(shunts).is_err() {
                s.axis.latch_fault(Faults::SENSING);
            }
            return None;
        };
        s.bus_voltage = bus_voltage;
        let phase_currents = board::phase_currents(shunt_amps, s.duties_in_force);
        let inputs = AxisInputs { phase_currents, encoder_count: count, bus_voltage };
        let commands = s.commands;
        let pwm = s.axis.step(&inputs, &commands);
        board::write_duties(pwm.duties);
        board::set_outputs(pwm.enabled);
        s.duties_in_force = pwm.duties;
        // The link reads the axis's own telemetry under the lock: no per-tick copy (a
        // memcpy of a few hundred instructions on the M4).
        let t = s.axis.telemetry();
        s.stream.offer(&t.sweep.sample);
        let divider = s.axis.params().rates.position_divider;
        // A u32 counter: a 64-bit modulo is a library call on the Cortex-M4.
        (TICKS.load(Ordering::Relaxed) % divider == 0).then_some(t.faults)
    });
    TICKS.fetch_add(1, Ordering::Relaxed);
    board::feed_watchdog();
    if let Some(faults) = position_tick {
        POSITION_TICK.signal(faults);
    }
}

/// Position-tick housekeeping in the high-priority executor: the current offsets and the bus
/// voltage once calibrated (to compare with a meter at the first power-up), fault changes
/// when they happen, and a heartbeat with the bus voltage once a second.
#[embassy_executor::task]
pub async fn position_tick_task() {
    let mut last = Faults::default();
    let mut n: u32 = 0;
    let mut offsets_logged = false;
    loop {
        let faults = POSITION_TICK.wait().await;
        if !offsets_logged {
            let seen =
                SHARED.lock(|s| s.borrow_mut().get().and_then(|s| s.sensing.offsets().map(|o| (o, s.bus_voltage))));
            if let Some((o, bus)) = seen {
                defmt::info!(
                    "current offsets U {} V {} W {} counts (mid-scale 2047.5), bus {} V",
                    o[0],
                    o[1],
                    o[2],
                    bus
                );
                offsets_logged = true;
            }
        }
        if faults != last {
            for name in faults.names() {
                defmt::warn!("fault latched: {} (PWM off until ClearFaults)", name);
            }
            if !faults.any() {
                defmt::info!("faults cleared");
            }
            last = faults;
        }
        n = n.wrapping_add(1);
        if n % 4_000 == 0 {
            let bus = SHARED.lock(|s| s.borrow_mut().get().map_or(0.0, |s| s.bus_voltage));
            defmt::info!(
                "control loop alive: {} ticks, faults {:#x}, bus {} V",
                TICKS.load(Ordering::Relaxed),
                faults.0,
                bus
            );
        }
    }
}
