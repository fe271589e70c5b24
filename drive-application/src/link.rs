//! The host link's frames: zero-delimited COBS frames of the core's protocol
//! (`control_core::protocol`). Bytes come in one at a time ([`FrameAssembler::push`]); every
//! frame gets an answer; a frame that does not decode is answered with its error and never
//! acted on. While streaming is on, sample batches go out unasked
//! ([`crate::drive::Host::stream_frame`]); the board's link task polls for them every 2 ms.

use control_core::protocol::{decode, encode, FrameError, Request, Response, MAX_FRAME};

/// Room for one encoded answer (a frame and its terminator, with margin).
pub const OUT_BYTES: usize = MAX_FRAME + 8;

/// Collects the bytes of one frame up to its zero terminator.
pub struct FrameAssembler {
    frame: [u8; MAX_FRAME + 1],
    len: usize,
}

impl Default for FrameAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl FrameAssembler {
    pub const fn new() -> Self {
        Self { frame: [0; MAX_FRAME + 1], len: 0 }
    }

    /// One byte; at a terminator, the frame's request or why it does not decode.
    pub fn push(&mut self, byte: u8) -> Option<Result<Request, FrameError>> {
        if byte != 0 {
            if self.len < self.frame.len() {
                self.frame[self.len] = byte;
            }
            self.len = self.len.saturating_add(1);
            return None;
        }
        let len = core::mem::take(&mut self.len);
        if len == 0 {
            // An empty frame: a lone delimiter, which a host sends to end whatever partial
            // frame a corrupted terminator left behind. Nothing to answer.
            return None;
        }
        if len > self.frame.len() {
            return Some(Err(FrameError::TooLong));
        }
        Some(decode::<Request>(&mut self.frame[..len]))
    }
}

/// `response` as a frame in `out`; its length (`None` if it does not fit, which no answer of
/// the protocol does in [`OUT_BYTES`]).
pub fn encode_response(response: &Response, out: &mut [u8]) -> Option<usize> {
    encode(response, out).ok()
}
