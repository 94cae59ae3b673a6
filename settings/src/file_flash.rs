//! NOR flash over a file: [`FileFlash`], for the SITL and host tools (feature `std`).
//!
//! The file holds the flash's bytes, and behaves as NOR flash does (as
//! [`RamFlash`](crate::flash::RamFlash)): writes clear bits only, erases set pages to
//! `0xFF`, both aligned. A missing file is created erased. A process killed at any time
//! leaves every finished write in the file (the operating system keeps it); nothing is
//! synced to the disk, so a crash of the machine itself may lose recent writes.
//!
//! ```
//! use embassy_futures::block_on;
//! use pprz_settings::embedded_storage_async::nor_flash::{NorFlash, ReadNorFlash};
//! use pprz_settings::FileFlash;
//!
//! let dir = tempfile::tempdir().unwrap();
//! let path = dir.path().join("settings.flash");
//! // Three 4 KiB pages, 4-byte words.
//! let mut flash = FileFlash::<12288, 4, 4096>::open(&path).unwrap();
//! block_on(flash.write(8, &[1, 2, 3, 4])).unwrap();
//! drop(flash);
//!
//! let mut flash = FileFlash::<12288, 4, 4096>::open(&path).unwrap();
//! let mut out = [0u8; 6];
//! block_on(flash.read(6, &mut out)).unwrap();
//! assert_eq!(out, [0xFF, 0xFF, 1, 2, 3, 4]);
//! ```

use std::fs::{File, OpenOptions};
use std::io::{self, Read, Seek, SeekFrom, Write};
use std::path::Path;

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

use crate::flash::{FlashError, erase_range, read_range, write_range};

/// A flash operation that failed.
#[derive(Debug)]
pub enum FileFlashError {
    /// Refused (misaligned or out of bounds); nothing was changed.
    Flash(FlashError),
    /// The file could not be read or written; the operation may be partly done (as a
    /// power cut would leave it).
    Io(io::Error),
}

impl NorFlashError for FileFlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FileFlashError::Flash(e) => e.kind(),
            FileFlashError::Io(_) => NorFlashErrorKind::Other,
        }
    }
}

impl From<FlashError> for FileFlashError {
    fn from(e: FlashError) -> Self {
        FileFlashError::Flash(e)
    }
}

impl From<io::Error> for FileFlashError {
    fn from(e: io::Error) -> Self {
        FileFlashError::Io(e)
    }
}

impl core::fmt::Display for FileFlashError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        match self {
            FileFlashError::Flash(e) => write!(f, "{e}"),
            FileFlashError::Io(e) => write!(f, "flash file: {e}"),
        }
    }
}

impl std::error::Error for FileFlashError {}

/// Bytes moved per file access.
const CHUNK: usize = 256;

/// NOR flash of `SIZE` bytes in a file, written in words of `WRITE` bytes and erased in
/// pages of `ERASE` bytes (as [`RamFlash`](crate::flash::RamFlash)).
#[derive(Debug)]
pub struct FileFlash<const SIZE: usize, const WRITE: usize, const ERASE: usize> {
    file: File,
}

impl<const SIZE: usize, const WRITE: usize, const ERASE: usize> FileFlash<SIZE, WRITE, ERASE> {
    const GEOMETRY: () = assert!(
        WRITE > 0 && ERASE > 0 && ERASE.is_multiple_of(WRITE) && SIZE.is_multiple_of(ERASE),
        "FileFlash: ERASE must be a multiple of WRITE, and SIZE a multiple of ERASE"
    );

    /// Opens the flash in `path`, creating it erased (`SIZE` bytes of `0xFF`) when the
    /// file does not exist. The file is complete or absent: it is filled under a
    /// temporary name first.
    ///
    /// # Errors
    /// The file's I/O errors, or [`io::ErrorKind::InvalidData`] if it is not `SIZE`
    /// bytes long (a flash of another geometry).
    pub fn open(path: impl AsRef<Path>) -> io::Result<Self> {
        let () = Self::GEOMETRY;
        let path = path.as_ref();
        let file = match OpenOptions::new().read(true).write(true).open(path) {
            Ok(file) => file,
            Err(e) if e.kind() == io::ErrorKind::NotFound => Self::create(path)?,
            Err(e) => return Err(e),
        };
        let len = file.metadata()?.len();
        if len != SIZE as u64 {
            return Err(io::Error::new(
                io::ErrorKind::InvalidData,
                std::format!("{}: {len} bytes, a flash of {SIZE}", path.display()),
            ));
        }
        Ok(Self { file })
    }

    fn create(path: &Path) -> io::Result<File> {
        let mut name = std::ffi::OsString::from(path.as_os_str());
        name.push(".new");
        let temp = Path::new(&name);
        let mut file = OpenOptions::new()
            .read(true)
            .write(true)
            .create(true)
            .truncate(true)
            .open(temp)?;
        let erased = [0xFF; CHUNK];
        let mut left = SIZE;
        while left > 0 {
            let n = left.min(CHUNK);
            file.write_all(&erased[..n])?;
            left -= n;
        }
        file.sync_all()?;
        std::fs::rename(temp, path)?;
        Ok(file)
    }

    /// The file.
    pub fn file(&self) -> &File {
        &self.file
    }
}

impl<const SIZE: usize, const WRITE: usize, const ERASE: usize> ErrorType
    for FileFlash<SIZE, WRITE, ERASE>
{
    type Error = FileFlashError;
}

impl<const SIZE: usize, const WRITE: usize, const ERASE: usize> ReadNorFlash
    for FileFlash<SIZE, WRITE, ERASE>
{
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let range = read_range(offset, bytes.len(), SIZE)?;
        self.file.seek(SeekFrom::Start(range.start as u64))?;
        self.file.read_exact(bytes)?;
        Ok(())
    }

    fn capacity(&self) -> usize {
        SIZE
    }
}

impl<const SIZE: usize, const WRITE: usize, const ERASE: usize> NorFlash
    for FileFlash<SIZE, WRITE, ERASE>
{
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let range = erase_range(from, to, SIZE, ERASE)?;
        self.file.seek(SeekFrom::Start(range.start as u64))?;
        let erased = [0xFF; CHUNK];
        let mut left = range.len();
        while left > 0 {
            let n = left.min(CHUNK);
            self.file.write_all(&erased[..n])?;
            left -= n;
        }
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let range = write_range(offset, bytes.len(), SIZE, WRITE)?;
        let mut at = range.start as u64;
        for chunk in bytes.chunks(CHUNK) {
            let mut cells = [0u8; CHUNK];
            let cells = &mut cells[..chunk.len()];
            self.file.seek(SeekFrom::Start(at))?;
            self.file.read_exact(cells)?;
            for (cell, byte) in cells.iter_mut().zip(chunk) {
                *cell &= *byte;
            }
            self.file.seek(SeekFrom::Start(at))?;
            self.file.write_all(cells)?;
            at += chunk.len() as u64;
        }
        Ok(())
    }
}
