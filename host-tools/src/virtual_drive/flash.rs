//! The virtual drive's parameter flash: the G474's two pages kept in a file, so that a saved
//! parameter set survives a restart of the virtual drive as it survives a power cycle of the
//! board (or in memory only, for a drive run inside the host's own process). Flash rules as on the G474: programming needs erased bytes (a double word already
//! written is refused, as the chip's PROGERR refuses it), erasing sets a page to 0xFF. Every
//! erase and write goes through to the file at once.

use std::fs::{File, OpenOptions};
use std::io::{Read, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use anyhow::{bail, Context, Result};
use drive_application::board::{FlashError, ParamFlash};

/// The G474's flash page.
pub const PAGE_BYTES: usize = 2048;
/// Its programming unit, a double word.
pub const WRITE_BYTES: usize = 8;

pub struct FileFlash {
    /// The file every change goes through to, and its path (none: memory only).
    file: Option<(File, PathBuf)>,
    pages: [Vec<u8>; 2],
}

impl FileFlash {
    /// The flash kept in `path`: created erased if missing; refused if it has another size.
    pub fn open(path: &Path) -> Result<Self> {
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .with_context(|| format!("cannot open the virtual drive's flash file {}", path.display()))?;
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).with_context(|| format!("cannot read {}", path.display()))?;
        if bytes.is_empty() {
            bytes = vec![0xFF; 2 * PAGE_BYTES];
            file.write_all(&bytes).with_context(|| format!("cannot write {}", path.display()))?;
        } else if bytes.len() != 2 * PAGE_BYTES {
            bail!(
                "{} holds {} bytes, not the {} of two flash pages: not a virtual drive's flash (remove it to start erased)",
                path.display(),
                bytes.len(),
                2 * PAGE_BYTES
            );
        }
        let second = bytes.split_off(PAGE_BYTES);
        Ok(Self { file: Some((file, path.to_path_buf())), pages: [bytes, second] })
    }

    /// Erased flash in memory only.
    pub fn in_memory() -> Self {
        Self { file: None, pages: [vec![0xFF; PAGE_BYTES], vec![0xFF; PAGE_BYTES]] }
    }

    pub fn path(&self) -> Option<&Path> {
        self.file.as_ref().map(|(_, p)| p.as_path())
    }

    fn write_through(&mut self, page: usize, offset: usize, len: usize) -> Result<(), FlashError> {
        let at = (page * PAGE_BYTES + offset) as u64;
        let bytes = &self.pages[page][offset..offset + len];
        let Some((file, _)) = &mut self.file else {
            return Ok(());
        };
        file.seek(SeekFrom::Start(at))
            .and_then(|_| file.write_all(bytes))
            .and_then(|_| file.flush())
            .map_err(|_| FlashError::Hardware)
    }
}

fn span(page: usize, offset: usize, len: usize, unit: usize) -> Result<(), FlashError> {
    if page > 1
        || !offset.is_multiple_of(unit)
        || !len.is_multiple_of(unit)
        || offset.checked_add(len).is_none_or(|e| e > PAGE_BYTES)
    {
        return Err(FlashError::Alignment);
    }
    Ok(())
}

impl ParamFlash for FileFlash {
    const PAGE_BYTES: usize = PAGE_BYTES;
    const WRITE_BYTES: usize = WRITE_BYTES;

    fn read(&mut self, page: usize, offset: usize, bytes: &mut [u8]) -> Result<(), FlashError> {
        span(page, offset, bytes.len(), 1)?;
        bytes.copy_from_slice(&self.pages[page][offset..offset + bytes.len()]);
        Ok(())
    }

    fn erase(&mut self, page: usize) -> Result<(), FlashError> {
        span(page, 0, 0, 1)?;
        self.pages[page].fill(0xFF);
        self.write_through(page, 0, PAGE_BYTES)
    }

    fn program(&mut self, page: usize, offset: usize, bytes: &[u8]) -> Result<(), FlashError> {
        span(page, offset, bytes.len(), WRITE_BYTES)?;
        let target = &mut self.pages[page][offset..offset + bytes.len()];
        if target.iter().any(|&b| b != 0xFF) {
            return Err(FlashError::Hardware);
        }
        target.copy_from_slice(bytes);
        self.write_through(page, offset, bytes.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn flash_rules_and_persistence() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("flash.bin");
        let mut f = FileFlash::open(&path).unwrap();
        let mut b = [0u8; 8];
        f.read(1, 8, &mut b).unwrap();
        assert_eq!(b, [0xFF; 8], "a new file is erased");
        f.program(1, 8, &[1, 2, 3, 4, 5, 6, 7, 8]).unwrap();
        assert_eq!(f.program(1, 8, &[0; 8]), Err(FlashError::Hardware), "written once, refused twice");
        assert_eq!(f.program(1, 4, &[0; 8]), Err(FlashError::Alignment));
        assert_eq!(f.program(0, PAGE_BYTES - 8, &[0; 16]), Err(FlashError::Alignment));
        assert_eq!(f.erase(2), Err(FlashError::Alignment));
        drop(f);
        let mut f = FileFlash::open(&path).unwrap();
        f.read(1, 8, &mut b).unwrap();
        assert_eq!(b, [1, 2, 3, 4, 5, 6, 7, 8], "kept over a restart");
        f.erase(1).unwrap();
        f.read(1, 8, &mut b).unwrap();
        assert_eq!(b, [0xFF; 8]);
        std::fs::write(&path, [0u8; 100]).unwrap();
        let e = FileFlash::open(&path).err().unwrap().to_string();
        assert!(e.contains("not a virtual drive's flash"), "{e}");
    }
}
