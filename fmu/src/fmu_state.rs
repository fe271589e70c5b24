//! Saved FMU states (Get/Set/Free/Serialize/Deserialize FMUState of both versions).
//!
//! A saved state is a copy of the model's state and the phase of the state machine;
//! restoring it and stepping on gives the same bits as the uninterrupted run. The model's
//! state is `Copy` (plain numbers, no pointers), so its serialised form is its byte image
//! behind a header: a magic, this build's fingerprint (the variables' token, the sources'
//! hash and the state's size) and a CRC-32 of everything after the header. A buffer from
//! another build, of another size, or corrupt, is refused with the reason — a byte image is
//! only meaningful to the build that wrote it, which is exactly what the fingerprint pins
//! (sources, compiler version, target, profile and flags; see build.rs). A serialized state
//! is trusted input: the CRC catches corruption, not forgery.
//! (serde over every core type would make it portable across builds, at the price of a
//! derive on each of the core's ~60 state types; an importer restores states into the FMU
//! that saved them.)

use std::mem::{size_of, MaybeUninit};

use crate::co_simulation::ModelState;
use crate::fmi::instance::Phase;
use crate::variables::{self, DECLARATIONS};

const MAGIC: &[u8; 8] = b"SRVAXST1";
const CRC: crc::Crc<u32> = crc::Crc::<u32>::new(&crc::CRC_32_ISO_HDLC);

/// A state saved by GetFMUState. `repr(C)` with the tag first: a pointer is checked by
/// reading one word before any reference is made.
#[derive(Clone)]
#[repr(C)]
pub struct Snapshot {
    tag: u64,
    pub model: ModelState,
    pub phase: Phase,
    pub stop_time: Option<f64>,
}

const SNAPSHOT_TAG: u64 = 0x5354_4154_4553_4e50;

impl Snapshot {
    pub fn new(model: ModelState, phase: Phase, stop_time: Option<f64>) -> Self {
        Self { tag: SNAPSHOT_TAG, model, phase, stop_time }
    }

    /// Free a snapshot made by this library; its tag is cleared first, so a second free of
    /// the same pointer is refused instead of freeing twice.
    ///
    /// # Safety
    /// As [`Self::from_ptr`].
    pub unsafe fn free(p: *mut std::ffi::c_void) -> Result<(), String> {
        unsafe {
            Self::from_ptr(p)?;
            std::ptr::write_volatile(p as *mut u64, 0);
            drop(Box::from_raw(p as *mut Snapshot));
        }
        Ok(())
    }

    /// The snapshot behind an FMUState pointer, if it is one of ours.
    ///
    /// # Safety
    /// A non-NULL pointer must come from this library's GetFMUState / DeserializeFMUState.
    pub unsafe fn from_ptr<'a>(p: *mut std::ffi::c_void) -> Result<&'a mut Snapshot, String> {
        if p.is_null() {
            return Err("the FMU state is NULL".into());
        }
        if unsafe { std::ptr::read(p as *const u64) } != SNAPSHOT_TAG {
            return Err("the FMU state pointer is not a (live) state of this FMU".into());
        }
        Ok(unsafe { &mut *(p as *mut Snapshot) })
    }
}

/// This build's fingerprint: what a serialised state must carry to be read back.
pub fn build_fingerprint() -> u64 {
    const CRC64: crc::Crc<u64> = crc::Crc::<u64>::new(&crc::CRC_64_XZ);
    let mut h = CRC64.digest();
    h.update(crate::model_description::instantiation_token().as_bytes());
    h.update(env!("SERVO_FMU_SOURCE_HASH").as_bytes());
    h.update(&(size_of::<ModelState>() as u64).to_le_bytes());
    h.finalize()
}

const HEADER: usize = 8 + 8 + 8 + 4;

/// Header, phase (1 byte), stop time (flag byte + 8 bytes), the model's image.
const BODY_PREFIX: usize = 1 + 1 + 8;

pub fn serialized_size() -> usize {
    HEADER + BODY_PREFIX + size_of::<ModelState>()
}

fn phase_code(p: Phase) -> u8 {
    match p {
        Phase::Instantiated => 0,
        Phase::InitializationMode => 1,
        Phase::StepMode => 2,
        Phase::Terminated => 3,
    }
}

fn phase_from(c: u8) -> Option<Phase> {
    Some(match c {
        0 => Phase::Instantiated,
        1 => Phase::InitializationMode,
        2 => Phase::StepMode,
        3 => Phase::Terminated,
        _ => return None,
    })
}

/// Write a snapshot into `out` (exactly [`serialized_size`] bytes).
pub fn serialize(s: &Snapshot, out: &mut [u8]) -> Result<(), String> {
    let n = serialized_size();
    if out.len() < n {
        return Err(format!(
            "the buffer holds {} bytes; a serialized state takes {n} (SerializedFMUStateSize)",
            out.len()
        ));
    }
    let out = &mut out[..n];
    let body_len = n - HEADER;
    out[..8].copy_from_slice(MAGIC);
    out[8..16].copy_from_slice(&build_fingerprint().to_le_bytes());
    out[16..24].copy_from_slice(&(body_len as u64).to_le_bytes());
    let body = &mut out[HEADER..];
    body[0] = phase_code(s.phase);
    body[1] = s.stop_time.is_some() as u8;
    body[2..10].copy_from_slice(&s.stop_time.unwrap_or(0.0).to_le_bytes());
    // SAFETY: ModelState is Copy (no pointers, no Drop); its bytes are read as a plain
    // image, padding included (its value is never interpreted, only copied back).
    let image =
        unsafe { std::slice::from_raw_parts(&s.model as *const ModelState as *const u8, size_of::<ModelState>()) };
    body[BODY_PREFIX..].copy_from_slice(image);
    let crc = CRC.checksum(&out[HEADER..]);
    out[24..28].copy_from_slice(&crc.to_le_bytes());
    Ok(())
}

/// Read a serialized state back; refuse one from another build, of another size or corrupt.
pub fn deserialize(bytes: &[u8]) -> Result<Snapshot, String> {
    let n = serialized_size();
    if bytes.len() < HEADER || &bytes[..8] != MAGIC {
        return Err("the buffer is not a serialized state of this FMU (no servo-axis header)".into());
    }
    let fingerprint = u64::from_le_bytes(bytes[8..16].try_into().unwrap());
    if fingerprint != build_fingerprint() {
        return Err(format!(
            "the serialized state comes from another build of the FMU (fingerprint {fingerprint:016x}, this build {:016x})",
            build_fingerprint()
        ));
    }
    if bytes.len() != n || u64::from_le_bytes(bytes[16..24].try_into().unwrap()) != (n - HEADER) as u64 {
        return Err(format!("the serialized state has {} bytes; this build's take {n}", bytes.len()));
    }
    let crc = u32::from_le_bytes(bytes[24..28].try_into().unwrap());
    if CRC.checksum(&bytes[HEADER..]) != crc {
        return Err("the serialized state is corrupt (CRC-32 mismatch)".into());
    }
    let body = &bytes[HEADER..];
    let phase = phase_from(body[0]).ok_or("the serialized state names no known phase")?;
    let stop = f64::from_le_bytes(body[2..10].try_into().unwrap());
    let stop_time = match body[1] {
        0 => None,
        1 if stop.is_finite() => Some(stop),
        _ => return Err("the serialized state holds no valid stop time".into()),
    };
    let mut model = MaybeUninit::<ModelState>::uninit();
    // SAFETY: the image was written by `serialize` of this very build (fingerprint and CRC
    // checked), from a valid ModelState of the same layout.
    let model = unsafe {
        std::ptr::copy_nonoverlapping(
            body[BODY_PREFIX..].as_ptr(),
            model.as_mut_ptr() as *mut u8,
            size_of::<ModelState>(),
        );
        model.assume_init()
    };
    // Belt and braces: every settable value within its declared range.
    for d in DECLARATIONS.iter().filter(|d| d.settable()) {
        if let Some(v) = model.values.get(d.vr) {
            variables::check(d, v).map_err(|e| format!("the serialized state holds a value outside its range: {e}"))?;
        }
    }
    Ok(Snapshot::new(model, phase, stop_time))
}
