//! The two semihosting calls used: SYS_WRITE0 (0x04) and SYS_EXIT (0x18).

fn call(op: u32, arg: *const u8) -> u32 {
    let r: u32;
    // SAFETY: the semihosting ABI: r0 = operation, r1 = argument, bkpt 0xAB traps to the host.
    unsafe { core::arch::asm!("bkpt 0xAB", inout("r0") op => r, in("r1") arg, options(nostack)) };
    r
}

/// Print a string (copied into a zero-terminated buffer in pieces).
pub fn write(s: &str) {
    let mut buf = [0u8; 129];
    for chunk in s.as_bytes().chunks(128) {
        buf[..chunk.len()].copy_from_slice(chunk);
        buf[chunk.len()] = 0;
        call(0x04, buf.as_ptr());
    }
}

pub fn exit(ok: bool) -> ! {
    // ADP_Stopped_ApplicationExit (0x20026) or ADP_Stopped_InternalError (0x20024).
    let reason: u32 = if ok { 0x20026 } else { 0x20024 };
    call(0x18, reason as usize as *const u8);
    loop {}
}
