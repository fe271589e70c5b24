//! Servo drive firmware: the control core (`control-core`) in Embassy tasks on an STM32G474.
//! Board code in `board`, application code in `control` (the loop) and `link` (the host
//! protocol).

#![no_std]
#![no_main]

mod board;
mod control;
mod link;

use defmt_rtt as _;
use embassy_executor::{InterruptExecutor, Spawner};
use embassy_stm32::interrupt;
use embassy_stm32::interrupt::{InterruptExt, Priority};
use panic_probe as _;
use static_cell::StaticCell;

/// The control loop's executor, run from a spare interrupt at the highest priority so that
/// nothing of Embassy's own (time driver, UART) delays it.
static CONTROL_EXECUTOR: InterruptExecutor = InterruptExecutor::new();

#[interrupt]
unsafe fn UART4() {
    CONTROL_EXECUTOR.on_interrupt()
}

static TX: StaticCell<[u8; 1024]> = StaticCell::new();
static RX: StaticCell<[u8; 1024]> = StaticCell::new();

#[embassy_executor::main]
async fn main(spawner: Spawner) {
    let p = embassy_stm32::init(Default::default());
    let board = board::init(p, TX.init([0; 1024]), RX.init([0; 1024]));
    if let Err(e) = control::install(control_core::Params::default()) {
        defmt::error!("default parameters refused: {}", defmt::Debug2Format(&e));
        return;
    }
    interrupt::UART4.set_priority(Priority::P1);
    let control = CONTROL_EXECUTOR.start(interrupt::UART4);
    control.spawn(control::control_loop(board.bridge, board.encoder).expect("control task"));
    spawner.spawn(link::link_task(board.link).expect("link task"));
    defmt::info!("drive-g474 running: control loop at 16 kHz, host link on USART2 (bridge disabled until current sensing exists)");
}
