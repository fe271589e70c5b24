//! The semihosting calls used: SYS_WRITE0 (0x04), SYS_EXIT (0x18), and for a vector file read
//! from the host as it is replayed SYS_OPEN (0x01), SYS_READ (0x06) and SYS_CLOSE (0x02).

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

/// A host file read through semihosting, in blocks.
pub struct HostFile {
    handle: u32,
    block: [u8; 4096],
    at: usize,
    len: usize,
}

impl HostFile {
    /// Open `path` (without its terminating zero, at most 255 bytes) for reading in binary.
    pub fn open(path: &str) -> Option<Self> {
        let mut name = [0u8; 256];
        let bytes = path.as_bytes();
        if bytes.len() >= name.len() {
            return None;
        }
        name[..bytes.len()].copy_from_slice(bytes);
        // Mode 1: "rb".
        let block = [name.as_ptr() as u32, 1, bytes.len() as u32];
        let handle = call(0x01, block.as_ptr() as *const u8);
        (handle != u32::MAX).then_some(Self { handle, block: [0; 4096], at: 0, len: 0 })
    }

    /// The next bytes into `buf`; `false` at the file's end before `buf` is full.
    pub fn fill(&mut self, buf: &mut [u8]) -> bool {
        let mut done = 0;
        while done < buf.len() {
            if self.at == self.len {
                let args = [self.handle, self.block.as_mut_ptr() as u32, self.block.len() as u32];
                // The call returns how many bytes it did not read.
                let missed = call(0x06, args.as_ptr() as *const u8) as usize;
                self.len = self.block.len().saturating_sub(missed);
                self.at = 0;
                if self.len == 0 {
                    return false;
                }
            }
            let n = (buf.len() - done).min(self.len - self.at);
            buf[done..done + n].copy_from_slice(&self.block[self.at..self.at + n]);
            self.at += n;
            done += n;
        }
        true
    }
}

impl Drop for HostFile {
    fn drop(&mut self) {
        let args = [self.handle];
        call(0x02, args.as_ptr() as *const u8);
    }
}
