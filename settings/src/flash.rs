//! NOR flash over RAM: [`RamFlash`], for emulators (a RAM region the emulator keeps
//! across resets, such as QEMU's file-backed memory) and hosts.
//!
//! It behaves as NOR flash does: a write may only clear bits (the stored byte becomes
//! `old & new`), an erase sets a whole page to `0xFF`, and writes and erases must be
//! aligned to the write word and the page. Misaligned or out-of-range operations are
//! [`FlashError`]s and change nothing.
//!
//! ```
//! use embassy_futures::block_on;
//! use pprz_settings::embedded_storage_async::nor_flash::{NorFlash, ReadNorFlash};
//! use pprz_settings::flash::{FlashError, RamFlash};
//!
//! let mut mem = [0u8; 2048];
//! // Two 1 KiB pages, 4-byte words, erased.
//! let mut flash = RamFlash::<2048, 4, 1024>::erased(&mut mem);
//! block_on(async {
//!     flash.write(0, &[0x0F, 0xF0, 0xFF, 0x00]).await.unwrap();
//!     flash.write(0, &[0xFF, 0x3C, 0x00, 0xFF]).await.unwrap();
//!     let mut out = [0u8; 4];
//!     flash.read(0, &mut out).await.unwrap();
//!     assert_eq!(out, [0x0F, 0x30, 0x00, 0x00]); // bits only clear
//!     assert_eq!(flash.write(2, &[0; 4]).await, Err(FlashError::NotAligned));
//!     flash.erase(0, 1024).await.unwrap();
//!     flash.read(0, &mut out).await.unwrap();
//!     assert_eq!(out, [0xFF; 4]);
//! });
//! ```

use core::ops::Range;
use core::sync::atomic::{Ordering, compiler_fence};

use embedded_storage_async::nor_flash::{
    ErrorType, NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash,
};

/// An operation the flash refused (nothing was changed).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FlashError {
    /// An offset or length not aligned to the write word (writes) or page (erases).
    NotAligned,
    /// Outside the flash, or an erase range that ends before it starts.
    OutOfBounds,
}

impl NorFlashError for FlashError {
    fn kind(&self) -> NorFlashErrorKind {
        match self {
            FlashError::NotAligned => NorFlashErrorKind::NotAligned,
            FlashError::OutOfBounds => NorFlashErrorKind::OutOfBounds,
        }
    }
}

impl core::fmt::Display for FlashError {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(match self {
            FlashError::NotAligned => "flash operation not aligned",
            FlashError::OutOfBounds => "flash operation out of bounds",
        })
    }
}

impl core::error::Error for FlashError {}

/// The bytes `offset..offset + len` of a flash of `capacity` bytes.
pub(crate) fn read_range(
    offset: u32,
    len: usize,
    capacity: usize,
) -> Result<Range<usize>, FlashError> {
    let start = usize::try_from(offset).map_err(|_| FlashError::OutOfBounds)?;
    let end = start.checked_add(len).ok_or(FlashError::OutOfBounds)?;
    if end > capacity {
        return Err(FlashError::OutOfBounds);
    }
    Ok(start..end)
}

/// The bytes of a write of `len` bytes at `offset`, whole words of `word` bytes.
pub(crate) fn write_range(
    offset: u32,
    len: usize,
    capacity: usize,
    word: usize,
) -> Result<Range<usize>, FlashError> {
    let range = read_range(offset, len, capacity)?;
    if !range.start.is_multiple_of(word) || !len.is_multiple_of(word) {
        return Err(FlashError::NotAligned);
    }
    Ok(range)
}

/// The bytes of an erase of `from..to`, whole pages of `page` bytes.
pub(crate) fn erase_range(
    from: u32,
    to: u32,
    capacity: usize,
    page: usize,
) -> Result<Range<usize>, FlashError> {
    let len = to.checked_sub(from).ok_or(FlashError::OutOfBounds)?;
    let range = read_range(from, len as usize, capacity)?;
    if !range.start.is_multiple_of(page) || !range.end.is_multiple_of(page) {
        return Err(FlashError::NotAligned);
    }
    Ok(range)
}

/// NOR flash of `SIZE` bytes over RAM, written in words of `WRITE` bytes and erased in
/// pages of `ERASE` bytes (`ERASE` a multiple of `WRITE`, `SIZE` a multiple of `ERASE`;
/// checked when the program is built). Reads may start anywhere.
///
/// It borrows its memory, so the memory can be a region kept across resets (the
/// contents are the flash's contents: [`new`](Self::new) keeps them) or a plain array.
#[derive(Debug)]
pub struct RamFlash<'m, const SIZE: usize, const WRITE: usize, const ERASE: usize> {
    mem: &'m mut [u8; SIZE],
}

impl<'m, const SIZE: usize, const WRITE: usize, const ERASE: usize>
    RamFlash<'m, SIZE, WRITE, ERASE>
{
    const GEOMETRY: () = assert!(
        WRITE > 0 && ERASE > 0 && ERASE.is_multiple_of(WRITE) && SIZE.is_multiple_of(ERASE),
        "RamFlash: ERASE must be a multiple of WRITE, and SIZE a multiple of ERASE"
    );

    /// A flash over `mem`, as it is (what a region kept across a reset holds).
    pub const fn new(mem: &'m mut [u8; SIZE]) -> Self {
        let () = Self::GEOMETRY;
        Self { mem }
    }

    /// A flash over `mem`, erased (every byte `0xFF`).
    pub fn erased(mem: &'m mut [u8; SIZE]) -> Self {
        mem.fill(0xFF);
        Self::new(mem)
    }

    /// The flash's contents.
    pub fn as_bytes(&self) -> &[u8; SIZE] {
        self.mem
    }

    /// The memory back.
    pub fn into_inner(self) -> &'m mut [u8; SIZE] {
        self.mem
    }
}

impl<const SIZE: usize, const WRITE: usize, const ERASE: usize> ErrorType
    for RamFlash<'_, SIZE, WRITE, ERASE>
{
    type Error = FlashError;
}

impl<const SIZE: usize, const WRITE: usize, const ERASE: usize> ReadNorFlash
    for RamFlash<'_, SIZE, WRITE, ERASE>
{
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), Self::Error> {
        let range = read_range(offset, bytes.len(), SIZE)?;
        bytes.copy_from_slice(&self.mem[range]);
        Ok(())
    }

    fn capacity(&self) -> usize {
        SIZE
    }
}

impl<const SIZE: usize, const WRITE: usize, const ERASE: usize> NorFlash
    for RamFlash<'_, SIZE, WRITE, ERASE>
{
    const WRITE_SIZE: usize = WRITE;
    const ERASE_SIZE: usize = ERASE;

    async fn erase(&mut self, from: u32, to: u32) -> Result<(), Self::Error> {
        let range = erase_range(from, to, SIZE, ERASE)?;
        self.mem[range].fill(0xFF);
        // The bytes reach memory before the operation reports its end (a RAM region
        // that outlives the program sees every finished operation).
        compiler_fence(Ordering::SeqCst);
        Ok(())
    }

    async fn write(&mut self, offset: u32, bytes: &[u8]) -> Result<(), Self::Error> {
        let range = write_range(offset, bytes.len(), SIZE, WRITE)?;
        for (cell, byte) in self.mem[range].iter_mut().zip(bytes) {
            *cell &= *byte;
        }
        compiler_fence(Ordering::SeqCst);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ranges_check_bounds_alignment_and_overflow() {
        assert_eq!(read_range(0, 16, 16), Ok(0..16));
        assert_eq!(read_range(1, 16, 16), Err(FlashError::OutOfBounds));
        assert_eq!(read_range(u32::MAX, 2, 16), Err(FlashError::OutOfBounds));
        assert_eq!(read_range(16, 0, 16), Ok(16..16));
        assert_eq!(write_range(4, 8, 16, 4), Ok(4..12));
        assert_eq!(write_range(2, 4, 16, 4), Err(FlashError::NotAligned));
        assert_eq!(write_range(4, 3, 16, 4), Err(FlashError::NotAligned));
        assert_eq!(write_range(12, 8, 16, 4), Err(FlashError::OutOfBounds));
        assert_eq!(erase_range(0, 8, 16, 8), Ok(0..8));
        assert_eq!(erase_range(8, 0, 16, 8), Err(FlashError::OutOfBounds));
        assert_eq!(erase_range(4, 8, 16, 8), Err(FlashError::NotAligned));
        assert_eq!(erase_range(0, 24, 16, 8), Err(FlashError::OutOfBounds));
        assert_eq!(erase_range(8, 8, 16, 8), Ok(8..8));
    }
}
