//! The section headers of a 32-bit little-endian ELF file (the firmware images): what sizes an
//! image (`firmware::sections`) and what the stack analysis reads words from
//! (`stack_depth`). Two tables of fixed-size records: read here rather than through an ELF
//! parser crate.

/// One section header.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SectionHeader {
    pub name: String,
    /// `sh_type`: [`PROGBITS`] for contents in the file (not `.bss`, `.uninit`).
    pub kind: u32,
    /// `sh_flags`: [`ALLOC`] for a section the image occupies at run time.
    pub flags: u32,
    pub address: u32,
    /// Where the contents start in the file.
    pub offset: usize,
    pub size: u32,
}

/// `SHT_PROGBITS`.
pub const PROGBITS: u32 = 1;
/// `SHF_ALLOC`.
pub const ALLOC: u32 = 0x2;

impl SectionHeader {
    /// The section's bytes in `elf` (None when the file does not hold them: `.bss`, or past
    /// its end).
    pub fn contents<'a>(&self, elf: &'a [u8]) -> Option<&'a [u8]> {
        if self.kind != PROGBITS {
            return None;
        }
        elf.get(self.offset..self.offset.checked_add(self.size as usize)?)
    }
}

/// Every section header of `elf` (none when it is not a 32-bit ELF file).
pub fn section_headers(elf: &[u8]) -> Vec<SectionHeader> {
    let u16_at = |o: usize| u16::from_le_bytes([elf[o], elf[o + 1]]) as usize;
    let u32_at = |o: usize| u32::from_le_bytes([elf[o], elf[o + 1], elf[o + 2], elf[o + 3]]);
    if elf.len() < 0x34 || &elf[..5] != b"\x7fELF\x01" {
        return Vec::new();
    }
    let (shoff, shentsize, shnum, shstrndx) = (u32_at(0x20) as usize, u16_at(0x2E), u16_at(0x30), u16_at(0x32));
    let header = |i: usize| shoff + i * shentsize;
    let strtab = u32_at(header(shstrndx) + 0x10) as usize;
    (0..shnum)
        .map(|i| {
            let h = header(i);
            let name_at = strtab + u32_at(h) as usize;
            let end = elf[name_at..].iter().position(|&b| b == 0).unwrap_or(0);
            SectionHeader {
                name: String::from_utf8_lossy(&elf[name_at..name_at + end]).into_owned(),
                kind: u32_at(h + 0x04),
                flags: u32_at(h + 0x08),
                address: u32_at(h + 0x0C),
                offset: u32_at(h + 0x10) as usize,
                size: u32_at(h + 0x14),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A made-up image: the ELF header, the contents of `.data` (two words) and of the name
    /// table, then four section headers (null, `.data` allocated PROGBITS at 0x2000_0000,
    /// `.bss` allocated NOBITS, the name table).
    fn image() -> Vec<u8> {
        let names = b"\0.data\0.bss\0.shstrtab\0";
        let (data_at, names_at) = (0x34usize, 0x3C);
        let headers_at = names_at + names.len();
        let mut elf = vec![0u8; headers_at + 4 * 40];
        elf[..5].copy_from_slice(b"\x7fELF\x01");
        elf[0x20..0x24].copy_from_slice(&(headers_at as u32).to_le_bytes());
        elf[0x2E..0x30].copy_from_slice(&40u16.to_le_bytes());
        elf[0x30..0x32].copy_from_slice(&4u16.to_le_bytes());
        elf[0x32..0x34].copy_from_slice(&3u16.to_le_bytes());
        elf[data_at..data_at + 8].copy_from_slice(&[1, 0, 0, 0, 0x78, 0x56, 0x34, 0x12]);
        elf[names_at..headers_at].copy_from_slice(names);
        let mut header = |i: usize, fields: [u32; 6]| {
            for (k, f) in fields.iter().enumerate() {
                let at = headers_at + i * 40 + 4 * k;
                elf[at..at + 4].copy_from_slice(&f.to_le_bytes());
            }
        };
        header(1, [1, PROGBITS, ALLOC | 0x1, 0x2000_0000, data_at as u32, 8]);
        header(2, [7, 8, ALLOC | 0x1, 0x2000_0008, headers_at as u32, 64]);
        header(3, [12, 3, 0, 0, names_at as u32, names.len() as u32]);
        elf
    }

    #[test]
    fn the_headers_name_each_section_and_only_file_contents_are_read() {
        let elf = image();
        let s = section_headers(&elf);
        let names: Vec<&str> = s.iter().map(|h| h.name.as_str()).collect();
        assert_eq!(names, ["", ".data", ".bss", ".shstrtab"]);
        assert_eq!((s[1].address, s[1].size, s[1].flags & ALLOC), (0x2000_0000, 8, ALLOC));
        assert_eq!(s[1].contents(&elf), Some(&[1, 0, 0, 0, 0x78, 0x56, 0x34, 0x12][..]));
        // NOBITS: nothing in the file, whatever its offset says.
        assert_eq!(s[2].contents(&elf), None);
        // A section past the file's end reads as none, not a panic.
        let past = SectionHeader { offset: elf.len() - 4, size: 8, ..s[1].clone() };
        assert_eq!(past.contents(&elf), None);
        assert!(section_headers(b"not an ELF file, long enough to have a header if it were one").is_empty());
    }
}
