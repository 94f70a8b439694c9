//! The store's flash on the host: an image of the board's two store sectors, in memory or in a
//! file written through at every flash write (a crash leaves what a power cut leaves).

use super::*;

/// The board's store flash on the host: the image of [`STORE_RANGE`] in memory, written
/// through to a file when there is one. NOR semantics: a write can only clear bits, an erase
/// sets a whole sector to 0xFF; both are checked for alignment like the F405's.
pub struct HostFlash {
    image: Vec<u8>,
    file: Option<File>,
}

/// A host flash failure.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HostFlashError {
    /// Outside the store's range.
    OutOfBounds,
    /// Not aligned to a word (write) or a sector (erase).
    NotAligned,
    /// The file could not be written.
    Io,
}

impl NorFlashError for HostFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            HostFlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
            HostFlashError::NotAligned => NorFlashErrorKind::NotAligned,
            HostFlashError::Io => NorFlashErrorKind::Other,
        }
    }
}

/// Bytes of the store's image.
pub const IMAGE_LEN: usize = (STORE_RANGE.end - STORE_RANGE.start) as usize;

impl HostFlash {
    /// An erased flash in memory.
    pub fn in_memory() -> HostFlash {
        HostFlash {
            image: vec![0xFF; IMAGE_LEN],
            file: None,
        }
    }

    /// The flash in `path`: created erased if missing; an existing file must be a store image
    /// ([`IMAGE_LEN`] bytes).
    pub fn open(path: &Path) -> Result<HostFlash, Error> {
        Self::open_inner(path).map_err(Error::Device)
    }

    fn open_inner(path: &Path) -> Result<HostFlash, String> {
        let shown = path.display();
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(false)
            .open(path)
            .map_err(|e| format!("{shown}: {e}"))?;
        let mut image = Vec::new();
        file.read_to_end(&mut image)
            .map_err(|e| format!("{shown}: {e}"))?;
        if image.is_empty() {
            image = vec![0xFF; IMAGE_LEN];
            file.write_all(&image)
                .and_then(|_| file.sync_data())
                .map_err(|e| format!("{shown}: {e}"))?;
        } else if image.len() != IMAGE_LEN {
            return Err(format!(
                "{shown}: not a store image ({} bytes, a store is {IMAGE_LEN}); move it away \
                 to start a fresh store",
                image.len()
            ));
        }
        Ok(HostFlash {
            image,
            file: Some(file),
        })
    }

    /// The image (the store's flash bytes).
    pub fn image(&self) -> &[u8] {
        &self.image
    }

    fn span(&self, offset: u32, len: usize) -> Result<std::ops::Range<usize>, HostFlashError> {
        let start = offset
            .checked_sub(STORE_RANGE.start)
            .ok_or(HostFlashError::OutOfBounds)? as usize;
        let end = start.checked_add(len).ok_or(HostFlashError::OutOfBounds)?;
        if end > self.image.len() {
            return Err(HostFlashError::OutOfBounds);
        }
        Ok(start..end)
    }

    fn persist(&mut self, at: std::ops::Range<usize>) -> Result<(), HostFlashError> {
        let Some(f) = &mut self.file else {
            return Ok(());
        };
        let bytes = self
            .image
            .get(at.clone())
            .ok_or(HostFlashError::OutOfBounds)?;
        f.seek(SeekFrom::Start(at.start as u64))
            .and_then(|_| f.write_all(bytes))
            .and_then(|_| f.sync_data())
            .map_err(|_| HostFlashError::Io)
    }
}

impl ErrorType for HostFlash {
    type Error = HostFlashError;
}

impl ReadNorFlash for HostFlash {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let at = self.span(offset, bytes.len())?;
        bytes.copy_from_slice(self.image.get(at).ok_or(HostFlashError::OutOfBounds)?);
        Ok(())
    }

    fn capacity(&self) -> usize {
        STORE_RANGE.end as usize
    }
}

impl NorFlash for HostFlash {
    const WRITE_SIZE: usize = WORD_SIZE;
    const ERASE_SIZE: usize = SECTOR_SIZE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        if from % SECTOR_SIZE as u32 != 0 || to % SECTOR_SIZE as u32 != 0 || to < from {
            return Err(HostFlashError::NotAligned);
        }
        let at = self.span(from, (to - from) as usize)?;
        self.image
            .get_mut(at.clone())
            .ok_or(HostFlashError::OutOfBounds)?
            .fill(0xFF);
        self.persist(at)
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        if offset % WORD_SIZE as u32 != 0 || bytes.len() % WORD_SIZE != 0 {
            return Err(HostFlashError::NotAligned);
        }
        let at = self.span(offset, bytes.len())?;
        let dst = self
            .image
            .get_mut(at.clone())
            .ok_or(HostFlashError::OutOfBounds)?;
        // NOR: programming only clears bits.
        for (d, s) in dst.iter_mut().zip(bytes) {
            *d &= *s;
        }
        self.persist(at)
    }
}
