//! The host link on USART2: received bytes go to the drive application's link side
//! (`drive_application::Host`), its answers and, while streaming is on, its sample batches
//! (polled every 2 ms) go out.

use drive_application::link::OUT_BYTES;
use drive_application::Host;
use embassy_futures::select::{select, Either};
use embassy_stm32::usart::BufferedUart;
use embassy_time::{Duration, Ticker};
use embedded_io_async::{Read, Write};

use crate::board::ParamPages;

#[embassy_executor::task]
pub async fn link_task(mut uart: BufferedUart<'static>, mut host: Host<'static>, mut flash: ParamPages) {
    let mut out = [0u8; OUT_BYTES];
    let mut byte = [0u8; 1];
    // A ticker, not a fresh timer per byte: incoming traffic must not hold the stream back.
    let mut ticker = Ticker::every(Duration::from_millis(2));
    loop {
        match select(uart.read(&mut byte), ticker.next()).await {
            Either::First(Ok(1)) => {
                if let Some(n) = host.receive(byte[0], &mut flash, &mut out) {
                    let _ = uart.write_all(&out[..n]).await;
                }
            }
            Either::First(_) => {}
            Either::Second(()) => {
                while let Some(n) = host.stream_frame(&mut out) {
                    let _ = uart.write_all(&out[..n]).await;
                }
            }
        }
    }
}
