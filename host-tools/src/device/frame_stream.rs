//! The host's parsing of the drive's byte stream: zero-delimited frames, each decoded and
//! its count fields checked (`control_core::protocol::decode_response`) before anything
//! uses them, and sample batches turned into rows with their count checked again.
//!
//! Only `std` and `control-core`: the robustness campaign (`robustness/`) compiles this same
//! file with overflow checks on and feeds it mutated streams (`servo bench robustness
//! --campaign stream`).

use control_core::acquisition_stream::SampleBatch;
use control_core::protocol::{decode_response, FrameError, Response, MAX_FRAME};

/// Bytes from the drive in, decoded frames out.
#[derive(Default)]
pub struct FrameStream {
    /// Bytes read but not yet part of a complete frame.
    pending: Vec<u8>,
}

impl FrameStream {
    pub fn push(&mut self, bytes: &[u8]) {
        self.pending.extend_from_slice(bytes);
    }

    /// Bytes of a frame still without its end are waiting.
    pub fn has_bytes(&self) -> bool {
        !self.pending.is_empty()
    }

    /// Drop the bytes of a frame still without its end; whether there were any.
    pub fn discard(&mut self) -> bool {
        let any = !self.pending.is_empty();
        self.pending.clear();
        any
    }

    /// The next complete frame, decoded and checked: None until a delimiter arrives; a run
    /// of more than `MAX_FRAME` bytes without one is dropped and reported as too long.
    /// Empty frames (two delimiters in a row) are skipped.
    pub fn next_frame(&mut self) -> Option<Result<Response, FrameError>> {
        loop {
            match self.pending.iter().position(|&b| b == 0) {
                Some(0) => {
                    self.pending.remove(0);
                }
                Some(end) => {
                    let mut frame: Vec<u8> = self.pending.drain(..=end).collect();
                    return Some(decode_response(&mut frame));
                }
                None if self.pending.len() > MAX_FRAME => {
                    self.pending.clear();
                    return Some(Err(FrameError::TooLong));
                }
                None => return None,
            }
        }
    }
}

/// The samples of a batch, its count checked against its slots.
pub fn batch_samples(b: &SampleBatch) -> Result<&[control_core::phase_shifted_sweep::AcquisitionSample], FrameError> {
    b.samples.get(..b.count as usize).ok_or(FrameError::Count { got: b.count as u32, max: b.samples.len() as u32 })
}

/// Rows of `servo device stream`'s CSV: tick, u, y, phase, measuring, point, record, half
/// block, limited (the drive's output was limited in the sample's acquisition period).
/// The columns of [`sample_rows`].
pub const SAMPLE_COLUMNS: [&str; 9] =
    ["tick", "u", "y", "phase", "measuring", "point", "record", "half_block", "limited"];

pub fn sample_rows(batches: &[SampleBatch]) -> Result<Vec<[f64; 9]>, FrameError> {
    let mut rows = Vec::new();
    for b in batches {
        for s in batch_samples(b)? {
            rows.push([
                s.tick as f64,
                s.u as f64,
                s.y as f64,
                s.phase as f64,
                s.measuring as u8 as f64,
                s.point as f64,
                s.record() as f64,
                s.half_block() as f64,
                s.limited as u8 as f64,
            ]);
        }
    }
    Ok(rows)
}
