//! The control loop: the drive application's tick (`drive_application::Drive::tick`: the
//! sampling sequence, offset calibration, fault latch → gate drive off, `Axis::step`,
//! streaming, the watchdog) on this board's power stage, in the ADC's end-of-conversion
//! interrupt at the base tick; a task in the high-priority executor, woken from that
//! interrupt once per position tick, logs what the application's housekeeping notes.

use control_core::faults::Faults;
use drive_application::housekeeping::{Housekeeping, Note};
use drive_application::Drive;
use embassy_stm32::interrupt;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::signal::Signal;

use crate::{board, stack};

/// The drive: what the tick and the link share, and the two axis slots (in `.bss`).
pub static DRIVE: Drive = Drive::new();

/// Woken once per position tick from the interrupt.
static POSITION_TICK: Signal<CriticalSectionRawMutex, Faults> = Signal::new();

/// Enable the sampling interrupt at the highest priority.
pub fn start(priority: interrupt::Priority) {
    use embassy_stm32::interrupt::InterruptExt;
    board::SAMPLE_INTERRUPT.set_priority(priority);
    // SAFETY: the handler below touches only `DRIVE` (its shared part under the critical
    // section) and the board's registers that nothing else writes after `board::init`.
    unsafe { board::SAMPLE_INTERRUPT.enable() };
}

/// One control tick; called from the sampling interrupt (the binary binds it).
#[inline(always)]
pub fn on_sample() {
    if let Some(faults) = DRIVE.tick(&mut board::Stage) {
        POSITION_TICK.signal(faults);
    }
}

/// Position-tick housekeeping in the high-priority executor: the current offsets and the bus
/// voltage once calibrated (to compare with a meter at the first power-up), fault changes
/// when they happen, and a heartbeat with the bus voltage once a second.
#[embassy_executor::task]
pub async fn position_tick_task() {
    let mut housekeeping = Housekeeping::default();
    loop {
        let faults = POSITION_TICK.wait().await;
        housekeeping.on_position_tick(&DRIVE, faults, log);
    }
}

fn log(note: Note) {
    match note {
        Note::OffsetsCalibrated { offsets: o, bus_voltage, accelerometer_zero } => defmt::info!(
            "current offsets U {} V {} W {} counts (mid-scale 2047.5), bus {} V, accelerometer zero {} counts (None: not connected)",
            o[0],
            o[1],
            o[2],
            bus_voltage,
            accelerometer_zero
        ),
        Note::FaultsChanged { faults } => {
            for name in faults.names() {
                defmt::warn!("fault latched: {} (PWM off until ClearFaults)", name);
            }
            if !faults.any() {
                defmt::info!("faults cleared");
            }
        }
        Note::Alive { ticks, faults, bus_voltage } => defmt::info!(
            "control loop alive: {} ticks, faults {:#x}, bus {} V, stack {} bytes never touched",
            ticks,
            faults.0,
            bus_voltage,
            stack::unused_stack_bytes()
        ),
    }
}
