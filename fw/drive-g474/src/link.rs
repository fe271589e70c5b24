//! The host link: zero-delimited COBS frames of the core's protocol over USART2. Every frame
//! gets an answer; a frame that does not decode is answered with its error and never acted on.
//! While streaming is on (`Request::Stream`), acquisition samples go out unasked as
//! `Response::Samples` frames, a batch every 2 ms or sooner.

use control_core::protocol::{decode, encode, handle, FrameError, Request, Response, MAX_FRAME};
use embassy_futures::select::{select, Either};
use embassy_stm32::usart::BufferedUart;
use embassy_time::{Duration, Ticker};
use embedded_io_async::{Read, Write};

use crate::control::SHARED;

async fn send(uart: &mut BufferedUart<'static>, response: &Response) {
    let mut out = [0u8; MAX_FRAME + 8];
    if let Ok(n) = encode(response, &mut out) {
        let _ = uart.write_all(&out[..n]).await;
    }
}

#[embassy_executor::task]
pub async fn link_task(mut uart: BufferedUart<'static>) {
    let mut frame = [0u8; MAX_FRAME + 1];
    let mut len = 0usize;
    let mut byte = [0u8; 1];
    // A ticker, not a fresh timer per byte: incoming traffic must not hold the stream back.
    let mut ticker = Ticker::every(Duration::from_millis(2));
    loop {
        match select(uart.read(&mut byte), ticker.next()).await {
            Either::First(Ok(1)) => {}
            Either::First(_) => continue,
            Either::Second(()) => {
                while let Some(batch) = SHARED.lock(|s| s.borrow_mut().get().and_then(|s| s.stream.take_batch())) {
                    send(&mut uart, &Response::Samples(batch)).await;
                }
                continue;
            }
        }
        if byte[0] != 0 {
            if len < frame.len() {
                frame[len] = byte[0];
            }
            len += 1;
            continue;
        }
        let response = if len > frame.len() {
            Response::FrameError(FrameError::TooLong)
        } else {
            match decode::<Request>(&mut frame[..len]) {
                Ok(request) => SHARED.lock(|s| match s.borrow_mut().get() {
                    Some(s) => handle(&mut s.axis, &mut s.commands, &mut s.stream, request),
                    None => Response::FrameError(FrameError::Message),
                }),
                Err(e) => Response::FrameError(e),
            }
        };
        len = 0;
        send(&mut uart, &response).await;
    }
}
