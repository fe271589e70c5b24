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

/// A line buffer for `write!` (what does not fit is cut off).
pub struct Line {
    buf: [u8; 160],
    len: usize,
}

impl Line {
    pub const fn new() -> Self {
        Self { buf: [0; 160], len: 0 }
    }

    /// The text so far (`fallback` if a cut split a character).
    pub fn as_str<'a>(&'a self, fallback: &'a str) -> &'a str {
        core::str::from_utf8(&self.buf[..self.len]).unwrap_or(fallback)
    }
}

impl Default for Line {
    fn default() -> Self {
        Self::new()
    }
}

impl core::fmt::Write for Line {
    fn write_str(&mut self, s: &str) -> core::fmt::Result {
        let b = s.as_bytes();
        let n = b.len().min(self.buf.len() - self.len);
        self.buf[self.len..self.len + n].copy_from_slice(&b[..n]);
        self.len += n;
        Ok(())
    }
}

/// Format one line and print it.
pub fn print(args: core::fmt::Arguments) {
    let mut line = Line::new();
    let _ = core::fmt::Write::write_fmt(&mut line, args);
    write(line.as_str("?\n"));
}

pub fn exit(ok: bool) -> ! {
    // ADP_Stopped_ApplicationExit (0x20026) or ADP_Stopped_InternalError (0x20024).
    let reason: u32 = if ok { 0x20026 } else { 0x20024 };
    call(0x18, reason as usize as *const u8);
    loop {}
}
