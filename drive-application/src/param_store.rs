//! The parameter set in flash (issue 16 item 3): one record per page, two pages used in turn,
//! so that a power loss during a save leaves the previous record whole.
//!
//! A record: an 8-byte head (magic "SVPR", format, payload length), an 8-byte tail of the
//! head (sequence number, CRC-32C of format, length, sequence and payload), then the payload:
//! the protocol's `Request::SetParams` carrying the set, postcard-encoded as on the link (the
//! drive decodes it with the link's own decoder: no second copy of it in flash), padded with
//! 0xFF to the programming unit. A save erases the page
//! not holding the newest record, programs everything but the head, and the head last: a
//! record without its head is no record, and a head is written only over a complete body.
//! At boot the newest record (highest sequence number, compared with wrap-around) whose check
//! value matches is loaded; with none, the defaults, and the reason
//! ([`control_core::protocol::DefaultsReason`]): nothing stored, a corrupt page, a record of
//! another format.

use control_core::params::Params;
use control_core::protocol::{DefaultsReason, Request, StorageError, MAX_FRAME};

use crate::board::ParamFlash;

/// "SVPR", little-endian.
pub const MAGIC: u32 = u32::from_le_bytes(*b"SVPR");
/// The record format: raise it whenever `Params` changes its serialised layout (a record of
/// another format is refused as foreign, not misread).
pub const FORMAT: u16 = 4; // 4: the second notch (and the encoder mounting); 3: the sweep's time budget; 2: the sweep's measure and the accelerometer's sensitivity
/// Head (magic, format, length) and its tail (sequence, CRC).
pub const HEAD_BYTES: usize = 16;
/// Largest payload (the parameter set is at most a frame).
pub const MAX_PAYLOAD: usize = MAX_FRAME;
/// The head's first half, written last.
const COMMIT_BYTES: usize = 8;
const RECORD_ROOM: usize = HEAD_BYTES + MAX_PAYLOAD + 8;

/// What a page holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum PageContent {
    /// Every byte of the head erased: never written, or a save cut short before its head.
    Empty,
    /// A whole record (its check value matches), of this sequence number.
    Record { sequence: u32 },
    /// A head with another format number.
    Foreign { format: u16 },
    /// Anything else: a head that is no record's, a check value that does not match, a
    /// length beyond the page, a payload that does not decode.
    Corrupt,
}

/// Which page holds the newest record: where the next save does not go.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct StoreState {
    pub newest: Option<(usize, u32)>,
}

impl StoreState {
    /// The page and sequence number of the next save.
    pub fn next(&self) -> (usize, u32) {
        match self.newest {
            Some((page, sequence)) => (1 - page, sequence.wrapping_add(1)),
            None => (0, 1),
        }
    }
}

fn crc_of(format: u16, length: u16, sequence: u32, payload: &[u8]) -> u32 {
    let mut digest = control_core::protocol::FRAME_CRC.digest();
    digest.update(&format.to_le_bytes());
    digest.update(&length.to_le_bytes());
    digest.update(&sequence.to_le_bytes());
    digest.update(payload);
    digest.finalize()
}

/// Read and check one page; with `params`, a record's parameters are decoded into it (left
/// as they were otherwise). The parameters are decoded in place, never returned by value:
/// each move of the set costs the drive's flash a few hundred instructions.
pub fn read_page<F: ParamFlash>(flash: &mut F, page: usize, params: Option<&mut Params>) -> PageContent {
    let mut head = [0u8; HEAD_BYTES];
    if flash.read(page, 0, &mut head).is_err() {
        return PageContent::Corrupt;
    }
    if head[..8].iter().all(|&b| b == 0xFF) {
        return PageContent::Empty;
    }
    let magic = u32::from_le_bytes([head[0], head[1], head[2], head[3]]);
    let format = u16::from_le_bytes([head[4], head[5]]);
    let length = u16::from_le_bytes([head[6], head[7]]);
    let sequence = u32::from_le_bytes([head[8], head[9], head[10], head[11]]);
    let crc = u32::from_le_bytes([head[12], head[13], head[14], head[15]]);
    if magic != MAGIC {
        return PageContent::Corrupt;
    }
    if format != FORMAT {
        return PageContent::Foreign { format };
    }
    let n = length as usize;
    if n > MAX_PAYLOAD || HEAD_BYTES + n > F::PAGE_BYTES {
        return PageContent::Corrupt;
    }
    let mut payload = [0u8; MAX_PAYLOAD];
    if flash.read(page, HEAD_BYTES, &mut payload[..n]).is_err()
        || crc_of(format, length, sequence, &payload[..n]) != crc
    {
        return PageContent::Corrupt;
    }
    match decode_payload(&payload[..n]) {
        Some(Request::SetParams(p)) => {
            if let Some(out) = params {
                *out = p;
            }
            PageContent::Record { sequence }
        }
        _ => PageContent::Corrupt,
    }
}

/// A payload's request, every byte used. Not generic, so that it is compiled here once, with
/// the link's decoder (a generic caller would instantiate a second copy of it in the board's
/// crate: 6 KiB of the G474's flash).
#[inline(never)]
fn decode_payload(payload: &[u8]) -> Option<Request> {
    match postcard::take_from_bytes::<Request>(payload) {
        Ok((request, [])) => Some(request),
        _ => None,
    }
}

/// Boot: the newest record of the two pages decoded into `params` (its sequence number), or
/// why there is none (`params` untouched); and where the next save goes.
#[inline(never)]
pub fn load<F: ParamFlash>(flash: &mut F, params: &mut Params) -> (Result<u32, DefaultsReason>, StoreState) {
    let pages = [read_page(flash, 0, None), read_page(flash, 1, None)];
    let mut newest: Option<(usize, u32)> = None;
    for (page, content) in pages.iter().enumerate() {
        if let PageContent::Record { sequence } = *content {
            let newer = match newest {
                None => true,
                Some((_, s)) => (sequence.wrapping_sub(s) as i32) > 0,
            };
            if newer {
                newest = Some((page, sequence));
            }
        }
    }
    if let Some((page, sequence)) = newest {
        if read_page(flash, page, Some(params)) == (PageContent::Record { sequence }) {
            return (Ok(sequence), StoreState { newest: Some((page, sequence)) });
        }
    }
    let reason = if let Some(format) =
        pages.iter().find_map(|c| if let PageContent::Foreign { format } = c { Some(*format) } else { None })
    {
        DefaultsReason::Foreign { format }
    } else if pages.contains(&PageContent::Corrupt) {
        DefaultsReason::Corrupt
    } else {
        DefaultsReason::NothingStored
    };
    (Err(reason), StoreState::default())
}

/// Encode `params` as a record of `sequence` into `out` (padded with 0xFF to the programming
/// unit); returns its length.
pub fn encode_record(params: &Params, sequence: u32, unit: usize, out: &mut [u8]) -> Result<usize, StorageError> {
    if out.len() < HEAD_BYTES {
        return Err(StorageError::TooLarge);
    }
    let room = (out.len() - HEAD_BYTES).min(MAX_PAYLOAD);
    let n = postcard::to_slice(&Request::SetParams(*params), &mut out[HEAD_BYTES..HEAD_BYTES + room])
        .map_err(|_| StorageError::TooLarge)?
        .len();
    let length = n as u16;
    let crc = crc_of(FORMAT, length, sequence, &out[HEAD_BYTES..HEAD_BYTES + n]);
    out[0..4].copy_from_slice(&MAGIC.to_le_bytes());
    out[4..6].copy_from_slice(&FORMAT.to_le_bytes());
    out[6..8].copy_from_slice(&length.to_le_bytes());
    out[8..12].copy_from_slice(&sequence.to_le_bytes());
    out[12..16].copy_from_slice(&crc.to_le_bytes());
    let total = (HEAD_BYTES + n).div_ceil(unit) * unit;
    if total > out.len() {
        return Err(StorageError::TooLarge);
    }
    out[HEAD_BYTES + n..total].fill(0xFF);
    Ok(total)
}

/// Save `params` as the newest record: erase the other page, write the body, then the head;
/// read it back. On success `state` names the new record (its sequence number is returned); on
/// failure it is unchanged (the previous record stays the newest).
pub fn save<F: ParamFlash>(flash: &mut F, state: &mut StoreState, params: &Params) -> Result<u32, StorageError> {
    let (page, sequence) = state.next();
    let mut record = [0xFFu8; RECORD_ROOM];
    // The head's first 8 bytes (magic, format, length) are the commit, written last: the
    // programming unit must divide them.
    let unit = F::WRITE_BYTES;
    if unit == 0 || !COMMIT_BYTES.is_multiple_of(unit) {
        return Err(StorageError::Flash);
    }
    let n = encode_record(params, sequence, unit, &mut record)?;
    if n > F::PAGE_BYTES {
        return Err(StorageError::TooLarge);
    }
    let commit = COMMIT_BYTES;
    flash.erase(page).map_err(|_| StorageError::Flash)?;
    flash.program(page, commit, &record[commit..n]).map_err(|_| StorageError::Flash)?;
    flash.program(page, 0, &record[..commit]).map_err(|_| StorageError::Flash)?;
    // Read back byte for byte, a unit at a time.
    let mut unit_back = [0u8; COMMIT_BYTES];
    for (k, chunk) in record[..n].chunks(COMMIT_BYTES).enumerate() {
        let back = &mut unit_back[..chunk.len()];
        flash.read(page, k * COMMIT_BYTES, back).map_err(|_| StorageError::Flash)?;
        if back != chunk {
            return Err(StorageError::Flash);
        }
    }
    state.newest = Some((page, sequence));
    Ok(sequence)
}
