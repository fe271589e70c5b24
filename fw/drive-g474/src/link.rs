//! The host link: zero-delimited COBS frames of the core's protocol over USART2. Every frame
//! gets an answer; a frame that does not decode is answered with its error and never acted on.

use control_core::protocol::{decode, encode, handle, FrameError, Request, Response, MAX_FRAME};
use embassy_stm32::usart::BufferedUart;
use embedded_io_async::{Read, Write};

use crate::control::SHARED;

#[embassy_executor::task]
pub async fn link_task(mut uart: BufferedUart<'static>) {
    let mut frame = [0u8; MAX_FRAME + 1];
    let mut len = 0usize;
    let mut byte = [0u8; 1];
    loop {
        if uart.read_exact(&mut byte).await.is_err() {
            continue;
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
                    Some(s) => handle(&mut s.axis, &mut s.commands, request),
                    None => Response::FrameError(FrameError::Message),
                }),
                Err(e) => Response::FrameError(e),
            }
        };
        len = 0;
        let mut out = [0u8; MAX_FRAME + 8];
        if let Ok(n) = encode(&response, &mut out) {
            let _ = uart.write_all(&out[..n]).await;
        }
    }
}
