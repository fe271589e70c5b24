//! Servo drive firmware: the drive application (`drive-application`, around the control core)
//! on an STM32G474. The library holds the board code (`board`: registers, and the board
//! interface the application uses) and binds the application's two sides to this board's
//! contexts (`control`: the tick in the sampling interrupt and the housekeeping task, `link`:
//! the host link task); this binary wires interrupts and tasks. On-target tests: `fw/tests`.
//!
//! Interrupt priorities (lower number = more urgent): the sampling interrupt that runs the
//! loop P0; the high-priority executor (position-tick housekeeping) P1; Embassy's own time
//! driver (TIM4) and the link's USART2 P3, so nothing of theirs delays a control tick.
//!
//! Loss of control: the panic and HardFault handlers switch the bridge off before anything
//! else (`board::bridge_off_now`: a software break); the watchdog, fed by the control loop,
//! resets the chip if the loop stops.

#![no_std]
#![no_main]

use drive_g474::{board, control, link, stack};

use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use static_cell::StaticCell;

/// Bridge off first; then interrupts masked (the control interrupt sets MOE every tick, so it
/// must not run again) and the bridge switched off once more in case it ran in between; then
/// the location, and a HardFault as panic-probe does (a probe halts there; without one the
/// HardFault handler waits for the watchdog).
#[panic_handler]
fn panic(info: &core::panic::PanicInfo) -> ! {
    board::bridge_off_now();
    cortex_m::interrupt::disable();
    board::bridge_off_now();
    // Where, not the message: formatting panic messages on the target would link core's
    // float formatting (about 17 KiB of flash) for the few messages that carry a float; the
    // location names the check, and the host-side tests give the message.
    match info.location() {
        Some(l) => defmt::error!("panic at {=str}:{=u32}", l.file(), l.line()),
        None => defmt::error!("panic"),
    }
    cortex_m::asm::udf()
}

/// Bridge off first (nothing preempts a HardFault but NMI); then wait for the watchdog.
#[cortex_m_rt::exception]
unsafe fn HardFault(_frame: &cortex_m_rt::ExceptionFrame) -> ! {
    board::bridge_off_now();
    loop {
        cortex_m::asm::nop();
    }
}

static CONTROL_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART4() {
    CONTROL_EXECUTOR.on_interrupt()
}

/// ADC1's end of injected sequence: one control tick.
#[interrupt]
fn ADC1_2() {
    control::on_sample()
}

fn install_error(e: drive_application::InstallError) -> &'static str {
    match e {
        drive_application::InstallError::Params(field) => field,
        drive_application::InstallError::Scales => "the board's ADC scales are refused",
        drive_application::InstallError::Twice => "installed twice",
    }
}

/// Where the parameters came from (the answer to Hello says the same to the host).
fn log_boot_params(origin: control_core::protocol::ParamsOrigin) {
    use control_core::protocol::{DefaultsReason, ParamsOrigin};
    match origin {
        ParamsOrigin::Stored { sequence } => defmt::info!("parameters loaded from flash (record {})", sequence),
        ParamsOrigin::Defaults(DefaultsReason::NoStorage) => defmt::warn!("default parameters: no storage"),
        ParamsOrigin::Defaults(DefaultsReason::NothingStored) => {
            defmt::info!("default parameters: nothing saved yet")
        }
        ParamsOrigin::Defaults(DefaultsReason::Corrupt) => {
            defmt::warn!("default parameters: the stored record is corrupt (check value mismatch)")
        }
        ParamsOrigin::Defaults(DefaultsReason::Foreign { format }) => {
            defmt::warn!("default parameters: the stored record has format {}, this firmware reads another", format)
        }
        ParamsOrigin::Defaults(DefaultsReason::Invalid(field)) => {
            defmt::warn!("default parameters: the stored set is refused ({=str})", field.as_str())
        }
    }
}

static TX: StaticCell<[u8; 1024]> = StaticCell::new();
static RX: StaticCell<[u8; 1024]> = StaticCell::new();

/// Boot in three steps, each out of line: the task's own frame (its future's poll) then holds
/// only the board and the link side between them, and each step's temporaries (the clock
/// configuration, the defaults, the link task's arguments) are on the stack only while it runs,
/// never under the drive's install.
#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let mut board = start_board();
    let mut host = match install_drive(&mut board.flash) {
        Ok(host) => host,
        Err(e) => {
            defmt::error!("drive not installed: {=str}", install_error(e));
            return;
        }
    };
    report_boot(&mut host);
    start_tasks(spawner, board, host);
}

/// Clocks, interrupt priorities, the board's peripherals.
#[inline(never)]
fn start_board() -> board::Board {
    let p = embassy_stm32::init(board::clocks());
    interrupt::TIM4.set_priority(Priority::P3);
    interrupt::USART2.set_priority(Priority::P3);
    board::init(p, TX.init([0; 1024]), RX.init([0; 1024]))
}

/// The drive installed with the stored parameters (or the board's defaults): its link side,
/// returned straight from the install (no copy of it here).
#[inline(never)]
fn install_drive(
    flash: &mut board::ParamPages,
) -> Result<drive_application::Host<'static>, drive_application::InstallError> {
    control::DRIVE.install::<board::Stage, _>(board::with_board_limits(control_core::Params::default()), flash)
}

/// Where the parameters came from, the stack the boot left untouched; the telemetry reports
/// the stack's measure from now on.
#[inline(never)]
fn report_boot(host: &mut drive_application::Host<'static>) {
    log_boot_params(host.boot_params());
    // The boot's deepest calls (the axis built and checked) are behind us: their mark stands.
    defmt::info!(
        "stack: {} of {} bytes never touched after the drive's install",
        stack::unused_stack_bytes(),
        stack::stack_bytes()
    );
    host.report_stack_with(stack::unused_stack_bytes);
}

/// The housekeeping and link tasks, the watchdog and the control interrupt.
#[inline(never)]
fn start_tasks(spawner: Spawner, board: board::Board, host: drive_application::Host<'static>) {
    interrupt::UART4.set_priority(Priority::P1);
    let housekeeping = CONTROL_EXECUTOR.start(interrupt::UART4);
    housekeeping.spawn(control::position_tick_task().expect("position-tick task"));
    spawner.spawn(link::link_task(board.link, host, board.flash).expect("link task"));
    board::start_watchdog();
    control::start(Priority::P0);
    defmt::info!(
        "drive-g474 running: loop at 16 kHz in ADC1_2 (bridge off until the current offsets are calibrated), host link on USART2 at 921600 Bd"
    );
    // The timer and encoder stay owned for the program's life.
    core::mem::forget((board.bridge, board.encoder));
}
