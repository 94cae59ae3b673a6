//! A PPRZLOG log sink on a FAT file system: an SD card, or any [`BlockDevice`]
//! (feature `sdlog`, on [`embedded_sdmmc`] 0.10).
//!
//! [`SdLog`] is an `embedded_io_async::Write` over one open file. Give it to a downlink
//! writer task whose device uses the PPRZLOG transport, and every frame the downlink
//! queues for it is appended to the file as a PPRZLOG record, the format the ground log
//! tools read: `0x99 | LEN | SOURCE | TIMESTAMP (u32 LE, 100 µs) | DATA (LEN bytes) | CK`
//! (byte layout in `docs/wire-formats.md` and in `pprz_transports::pprzlog`).
//!
//! ```ignore
//! // Firmware: an SD card on SPI, a log file named PPRZnnnn.LOG per boot.
//! let sd = embedded_sdmmc::SdCard::new(spi_device, delay);
//! let volumes = VOLUMES.init(embedded_sdmmc::VolumeManager::new(sd, clock));
//! let volume = volumes.open_raw_volume(embedded_sdmmc::VolumeIdx(0))?;
//! let (log, number) = SdLog::create_numbered(volumes, volume, SdLogConfig::default())?;
//! spawner.spawn(log_writer(downlink, LOG_DEVICE, log)?); // run_writer(downlink, LOG_DEVICE, &mut log)
//! ```
//!
//! # Buffering
//!
//! Bytes are gathered in a 512-byte RAM buffer aligned on the file's blocks, so each
//! block is written **once, whole** (embedded-sdmmc writes through: a write of a
//! 30-byte frame alone would cost a read and a write of a whole block). A new cluster
//! is linked into the FAT when the file grows into it.
//!
//! # Durability: what a power cut loses
//!
//! The file's length lives in its directory entry, which is rewritten only at a
//! *sync*: every [`SdLogConfig::sync_every_blocks`] blocks, at every `flush`, and at
//! [`close`](SdLog::close). After a power cut the file therefore ends at the last sync:
//!
//! * bytes still in the RAM buffer (at most 511) are lost;
//! * blocks written since the last sync (at most `sync_every_blocks` x 512 bytes) are on
//!   the card, in clusters already chained to the file, but past its recorded length:
//!   the file reads as if they were not there (`fsck.fat` reports the chain as longer
//!   than the file and truncates it);
//! * everything before the last sync is intact: a record cut in two by the end of the
//!   file is skipped by the PPRZLOG decoder (its checksum or length fails), so a
//!   reader loses at most that record.
//!
//! So a power cut loses at most `sync_every_blocks x 512 + 511` bytes: with the default
//! (8 blocks) about 4.5 KiB, a few seconds of telemetry. A downlink device configured to
//! flush after every frame (the writer's per-frame flush option) loses nothing that was
//! flushed, at the cost of two block writes per frame on FAT16 and three on FAT32 (the
//! partial data block, the directory entry, the FSInfo sector, plus the FAT updates of
//! new clusters; measured by the tests): fine for rare, important records, too slow
//! and too much wear for a telemetry stream. A write interrupted by
//! the power cut can leave the block being written corrupt (the card's own guarantee);
//! the FAT and the directory are only rewritten at syncs and cluster allocations.
//!
//! # Blocking
//!
//! embedded-sdmmc is blocking: a block write blocks the executor for the transfer
//! (about 1 ms per block on a 4 MHz SPI bus) plus the card's busy time (occasionally
//! tens of milliseconds). Run the log writer where that jitter does no harm, for
//! example on a lower-priority executor than the radio's.
//!
//! # Errors
//!
//! Errors are embedded-sdmmc's own ([`embedded_sdmmc::Error`], which implements
//! `embedded_io::Error`), counted in [`SdLogStats::errors`]. A write that fails
//! accepted no byte; a full block that could not be written stays buffered and is
//! written again by the next call, so a transient card error loses nothing.
//!
//! A full disk, or a file at its length limit ([`SdLogConfig::max_len`], by default
//! FAT's 4 GiB - 1 byte; embedded-sdmmc would take the bytes past it and drop them),
//! makes the log *full* ([`SdLogStats::full`]): from then on every write fails at once
//! with [`Error::NotEnoughSpace`], counted. At the length limit the bytes accepted
//! before it are still stored by `flush` and [`close`](SdLog::close). On a full disk
//! nothing more is written to the card, not even the bytes still buffered (each
//! attempt would make embedded-sdmmc read the whole FAT in search of a free cluster,
//! blocking the executor); `flush` and `close` still record the length of what is
//! stored. Start a new file (on another card) to log again.

use embedded_io_async::{ErrorType, Write};
use embedded_sdmmc::{
    Block, BlockDevice, Error, MAX_FILE_SIZE, Mode, RawFile, RawVolume, TimeSource, VolumeManager,
};

/// Block size of the file system (bytes).
pub const BLOCK_LEN: usize = Block::LEN;

/// How often an [`SdLog`] makes its data durable; see the [module docs](self).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SdLogConfig {
    /// Update the directory entry (file length) after this many data blocks; 0: only on
    /// `flush` and `close`.
    pub sync_every_blocks: u32,
    /// The longest the file may grow, in bytes (at most FAT's limit, 4 GiB - 1 byte,
    /// which is also the default): the log is full there (see the [module
    /// docs](self#errors)).
    pub max_len: u32,
}

impl Default for SdLogConfig {
    /// A sync every 8 blocks (4 KiB), files up to FAT's limit.
    fn default() -> Self {
        Self {
            sync_every_blocks: 8,
            max_len: MAX_FILE_SIZE,
        }
    }
}

/// Counters of an [`SdLog`] (all wrap around), and whether it is full.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SdLogStats {
    /// Bytes accepted by `write`.
    pub bytes_accepted: u32,
    /// Bytes written to the file (accepted and no longer in the RAM buffer).
    pub bytes_stored: u32,
    /// Data writes to the card (whole blocks, plus partial ones at `flush`).
    pub block_writes: u32,
    /// Directory entry updates (the data before them survives a power cut).
    pub syncs: u32,
    /// Failed card or file-system operations, and writes refused because the log is
    /// full.
    pub errors: u32,
    /// Whether the log is full (the disk, or the file at its length limit): every
    /// later write fails at once.
    pub full: bool,
}

/// The PPRZLOG log sink; see the [module docs](self).
///
/// The const parameters are those of the [`VolumeManager`].
pub struct SdLog<
    'v,
    D: BlockDevice,
    T: TimeSource,
    const MAX_DIRS: usize = 4,
    const MAX_FILES: usize = 4,
    const MAX_VOLUMES: usize = 1,
> {
    volumes: &'v VolumeManager<D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>,
    /// `None` once closed.
    file: Option<RawFile>,
    /// Bytes from file offset `offset`. Invariant: `offset % BLOCK_LEN + len <= BLOCK_LEN`
    /// (the buffer never crosses a block boundary).
    buf: [u8; BLOCK_LEN],
    len: usize,
    offset: u32,
    blocks_since_sync: u32,
    /// The card reported no free cluster: nothing more is written to it.
    disk_full: bool,
    config: SdLogConfig,
    stats: SdLogStats,
}

/// First name tried by [`SdLog::create_numbered`]; the digits count up.
const NUMBERED: &[u8; 12] = b"PPRZ0000.LOG";

impl<'v, D, T, const MAX_DIRS: usize, const MAX_FILES: usize, const MAX_VOLUMES: usize>
    SdLog<'v, D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>
where
    D: BlockDevice,
    T: TimeSource,
{
    /// A log appending to `file`, a file of `volumes` opened for writing. The log owns
    /// the file from now on and closes it in [`close`](Self::close) (or, best effort,
    /// when dropped).
    ///
    /// # Errors
    /// If the file's position cannot be read (a bad handle).
    pub fn new(
        volumes: &'v VolumeManager<D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>,
        file: RawFile,
        config: SdLogConfig,
    ) -> Result<Self, Error<D::Error>> {
        let offset = volumes.file_offset(file)?;
        Ok(Self {
            volumes,
            file: Some(file),
            buf: [0; BLOCK_LEN],
            len: 0,
            offset,
            blocks_since_sync: 0,
            disk_full: false,
            config,
            stats: SdLogStats::default(),
        })
    }

    /// Opens `name` (an 8.3 name) in the root directory of `volume` with `mode` (for
    /// example `Mode::ReadWriteCreateOrAppend` to continue a log across reboots).
    ///
    /// # Errors
    /// If the directory or the file cannot be opened.
    pub fn open_in_root(
        volumes: &'v VolumeManager<D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>,
        volume: RawVolume,
        name: &str,
        mode: Mode,
        config: SdLogConfig,
    ) -> Result<Self, Error<D::Error>> {
        let dir = volumes.open_root_dir(volume)?;
        let file = volumes.open_file_in_dir(dir, name, mode);
        // A file stays usable once its directory is closed.
        let closed = volumes.close_dir(dir);
        let log = Self::new(volumes, file?, config)?;
        closed?;
        Ok(log)
    }

    /// Creates the first free `PPRZnnnn.LOG` (0000 to 9999) in the root directory of
    /// `volume`: one new log per boot. Returns the log and `nnnn`.
    ///
    /// # Errors
    /// [`Error::FileAlreadyExists`] if all 10 000 names are taken, or any error opening
    /// the directory or creating the file.
    pub fn create_numbered(
        volumes: &'v VolumeManager<D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>,
        volume: RawVolume,
        config: SdLogConfig,
    ) -> Result<(Self, u16), Error<D::Error>> {
        let dir = volumes.open_root_dir(volume)?;
        let mut result = Err(Error::FileAlreadyExists);
        for number in 0..10_000u16 {
            let mut name = *NUMBERED;
            let mut n = number;
            for digit in name[4..8].iter_mut().rev() {
                *digit = b'0' + (n % 10) as u8;
                n /= 10;
            }
            // The name is ASCII by construction.
            let name = core::str::from_utf8(&name).unwrap_or("PPRZ0000.LOG");
            match volumes.find_directory_entry(dir, name) {
                Err(Error::NotFound) => {
                    result = volumes
                        .open_file_in_dir(dir, name, Mode::ReadWriteCreate)
                        .map(|file| (file, number));
                    break;
                }
                Ok(_) => {}
                Err(e) => {
                    result = Err(e);
                    break;
                }
            }
        }
        let closed = volumes.close_dir(dir);
        let (file, number) = result?;
        let log = Self::new(volumes, file, config)?;
        closed?;
        Ok((log, number))
    }

    /// The counters.
    pub fn stats(&self) -> SdLogStats {
        SdLogStats {
            full: self.disk_full || self.len() >= self.config.max_len,
            ..self.stats
        }
    }

    /// The configuration.
    pub fn config(&self) -> SdLogConfig {
        self.config
    }

    /// The file's length including the buffered bytes.
    pub fn len(&self) -> u32 {
        self.offset.saturating_add(crate::len_u32(self.len))
    }

    /// Whether nothing was ever written to the file.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Bytes accepted but still in RAM (lost on a power cut).
    pub fn buffered(&self) -> usize {
        self.len
    }

    /// Writes what is buffered, updates the directory entry and closes the file.
    ///
    /// # Errors
    /// As `flush`; the file is closed anyway.
    pub fn close(mut self) -> Result<(), Error<D::Error>> {
        self.close_file()
    }

    fn close_file(&mut self) -> Result<(), Error<D::Error>> {
        let flushed = self.sync();
        let Some(file) = self.file.take() else {
            return flushed;
        };
        let closed = self.volumes.close_file(file);
        flushed.and(closed)
    }

    fn file(&self) -> Result<RawFile, Error<D::Error>> {
        self.file.ok_or(Error::BadHandle)
    }

    /// Room left in the buffer before the block boundary.
    fn room(&self) -> usize {
        BLOCK_LEN - (self.offset as usize % BLOCK_LEN) - self.len
    }

    fn count_error<R>(&mut self, result: Result<R, Error<D::Error>>) -> Result<R, Error<D::Error>> {
        if result.is_err() {
            self.stats.errors = self.stats.errors.wrapping_add(1);
        }
        result
    }

    /// Refuses an operation of a full log (counted).
    fn refuse_full<R>(&mut self) -> Result<R, Error<D::Error>> {
        self.count_error(Err(Error::NotEnoughSpace))
    }

    /// Writes the buffered bytes to the file (no directory update).
    fn store(&mut self) -> Result<(), Error<D::Error>> {
        if self.len == 0 {
            return Ok(());
        }
        if self.disk_full {
            return self.refuse_full();
        }
        let file = self.file()?;
        let written = self.volumes.write(file, &self.buf[..self.len]);
        if matches!(written, Err(Error::NotEnoughSpace | Error::DiskFull)) {
            self.disk_full = true;
        }
        self.count_error(written)?;
        let n = crate::len_u32(self.len);
        // No overflow: `write` keeps the file within `max_len`.
        self.offset = self.offset.saturating_add(n);
        self.stats.bytes_stored = self.stats.bytes_stored.wrapping_add(n);
        self.stats.block_writes = self.stats.block_writes.wrapping_add(1);
        self.len = 0;
        Ok(())
    }

    /// Stores a full buffer, then syncs if `sync_every_blocks` blocks were stored.
    fn store_block(&mut self) -> Result<(), Error<D::Error>> {
        self.store()?;
        self.blocks_since_sync += 1;
        let every = self.config.sync_every_blocks;
        if every > 0 && self.blocks_since_sync >= every {
            self.update_entry()?;
        }
        Ok(())
    }

    /// Rewrites the directory entry (file length).
    fn update_entry(&mut self) -> Result<(), Error<D::Error>> {
        let file = self.file()?;
        let flushed = self.volumes.flush_file(file);
        self.count_error(flushed)?;
        self.stats.syncs = self.stats.syncs.wrapping_add(1);
        self.blocks_since_sync = 0;
        Ok(())
    }

    /// Stores the buffer (a partial block too) and updates the directory entry (also
    /// when the store failed: what is stored becomes durable).
    fn sync(&mut self) -> Result<(), Error<D::Error>> {
        let stored = self.store();
        let updated = self.update_entry();
        stored.and(updated)
    }
}

impl<D, T, const MAX_DIRS: usize, const MAX_FILES: usize, const MAX_VOLUMES: usize> Drop
    for SdLog<'_, D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>
where
    D: BlockDevice,
    T: TimeSource,
{
    /// Best effort: stores the buffer, syncs and closes the file, ignoring errors. Call
    /// [`close`](SdLog::close) to see them.
    fn drop(&mut self) {
        let _ = self.close_file();
    }
}

impl<D, T, const MAX_DIRS: usize, const MAX_FILES: usize, const MAX_VOLUMES: usize> ErrorType
    for SdLog<'_, D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>
where
    D: BlockDevice,
    T: TimeSource,
{
    type Error = Error<D::Error>;
}

impl<D, T, const MAX_DIRS: usize, const MAX_FILES: usize, const MAX_VOLUMES: usize> Write
    for SdLog<'_, D, T, MAX_DIRS, MAX_FILES, MAX_VOLUMES>
where
    D: BlockDevice,
    T: TimeSource,
{
    /// Buffers bytes up to the next block boundary and writes the block once it is
    /// full. Blocks the executor while a block is written.
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        if buf.is_empty() {
            return Ok(0);
        }
        self.file()?;
        if self.disk_full {
            return self.refuse_full();
        }
        if self.room() == 0 {
            // A full block left by an earlier failure: nothing is accepted until it is
            // stored.
            self.store_block()?;
        }
        let left = self.config.max_len.saturating_sub(self.len());
        if left == 0 {
            return self.refuse_full();
        }
        let n = buf.len().min(self.room()).min(left as usize);
        self.buf[self.len..self.len + n].copy_from_slice(&buf[..n]);
        self.len += n;
        self.stats.bytes_accepted = self.stats.bytes_accepted.wrapping_add(crate::len_u32(n));
        if self.room() == 0 {
            // The bytes are accepted either way; a failure is counted here and
            // reported by the next call, which retries the block.
            let _ = self.store_block();
        }
        Ok(n)
    }

    /// Writes the buffered bytes and updates the directory entry: everything written
    /// so far survives a power cut once this returns.
    async fn flush(&mut self) -> Result<(), Self::Error> {
        self.sync()
    }
}
