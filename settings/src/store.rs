//! The persistent store: the snapshot of a settings table in a sequential-storage map.
//!
//! A [`PersistentStore`] owns the flash range, the map's cache and a buffer. It keeps one
//! [record](crate::record) under one key ([`SNAPSHOT_KEY`]): a store writes a new copy,
//! and a power cut at any point leaves either the previous snapshot or the new one.
//!
//! None of its futures may be dropped before they finish (sequential-storage's operations
//! are not cancel-safe: a dropped store leaves the flash to be repaired, and whether the
//! store happened is unknown). Run them to completion: at boot before anything else, and
//! then only in the store's own task ([`run`](crate::task::run)), never in a `select` or
//! under a timeout.

use core::cell::Cell;
use core::fmt;
use core::ops::Range;

use embassy_sync::blocking_mutex::raw::RawMutex;
use embedded_storage_async::nor_flash::NorFlash;
use pprz_messages::settings::{SettingDesc, fnv1a};
use pprz_telemetry::settings::{SettingEntry, Settings};
use sequential_storage::cache::key_pointers::ArrayKeyPointers;
use sequential_storage::cache::page_pointers::ArrayPagePointers;
use sequential_storage::cache::page_states::ArrayPageStates;
use sequential_storage::cache::{Cache, CacheImpl};
use sequential_storage::map::{MapConfig, MapConfigError, MapStorage, SerializationError, Value};

use crate::record::{
    ENTRY_LEN, EncodeError, Entry, HEADER_LEN, MAGIC, MAX_ENTRIES, Record, RecordError,
    RecordWriter, VERSION, record_len,
};

/// The key type of the store's map: no bytes. The map holds one item, the snapshot, so
/// its key says nothing; and an item of length 0 in flash (crafted: its checksums must
/// match) then reads as an empty record, a typed error, where sequential-storage 8
/// subtracts a one-byte key from the zero length and panics.
pub type SnapshotKey = [u8; 0];
/// The map key the snapshot is stored under.
pub const SNAPSHOT_KEY: SnapshotKey = [];
/// Bytes of the key in a stored item.
const KEY_LEN: usize = core::mem::size_of::<SnapshotKey>();
/// The largest flash word sequential-storage supports (STM32H7: 256 bits); buffers are
/// aligned and rounded to it.
const MAX_WORD: usize = 32;

/// Length of a store buffer that holds a snapshot of `max_settings` persistent settings
/// on any flash (word up to 32 bytes): the key and the record, rounded up to 32 bytes.
/// The third parameter of [`PersistentStore`].
pub const fn buffer_len(max_settings: usize) -> usize {
    (KEY_LEN + record_len(max_settings)).next_multiple_of(MAX_WORD)
}

/// A cache of sequential-storage for a range of `PAGES` pages: page states, page pointers
/// and the snapshot's location (32 bytes for 3 pages, about 9 more a page). It saves
/// flash reads; the store also works without one ([`Cache::new_uncached`]).
pub type PageCache<const PAGES: usize> = Cache<
    ArrayPageStates<PAGES>,
    ArrayPagePointers<PAGES>,
    ArrayKeyPointers<SnapshotKey, 1>,
    SnapshotKey,
>;

/// A new, empty [`PageCache`] (what [`PersistentStore::with_page_cache`] uses).
pub fn page_cache<const PAGES: usize>() -> PageCache<PAGES> {
    Cache::new(
        ArrayPageStates::new(),
        ArrayPagePointers::new(),
        ArrayKeyPointers::new(),
    )
}

/// Why a store could not be set up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ConfigError {
    /// The flash range does not suit a sequential-storage map (page-aligned, at least
    /// two pages, flash word at most 32 bytes).
    Map(MapConfigError),
    /// The cache is made for another number of pages.
    PageCount {
        /// Pages of the range.
        pages: usize,
        /// Pages of the cache.
        cache: usize,
    },
    /// The buffer holds less than an empty snapshot.
    Buffer {
        /// Its length.
        len: usize,
        /// The least length that works on this flash.
        min: usize,
    },
}

impl fmt::Display for ConfigError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ConfigError::Map(e) => write!(f, "flash range unusable for the settings map: {e:?}"),
            ConfigError::PageCount { pages, cache } => {
                write!(f, "the range has {pages} pages, the cache {cache}")
            }
            ConfigError::Buffer { len, min } => {
                write!(f, "store buffer of {len} bytes, {min} needed")
            }
        }
    }
}

impl core::error::Error for ConfigError {}

#[cfg(feature = "defmt")]
impl defmt::Format for ConfigError {
    fn format(&self, f: defmt::Formatter<'_>) {
        match self {
            ConfigError::Map(e) => defmt::write!(f, "Map({})", defmt::Debug2Format(e)),
            ConfigError::PageCount { pages, cache } => {
                defmt::write!(f, "PageCount {{ pages: {}, cache: {} }}", pages, cache)
            }
            ConfigError::Buffer { len, min } => {
                defmt::write!(f, "Buffer {{ len: {}, min: {} }}", len, min)
            }
        }
    }
}

/// A store, load or clear that failed; `E` is the flash's error.
#[derive(Debug, Clone, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum StoreError<E> {
    /// The flash failed.
    Flash(E),
    /// The map is corrupted beyond what sequential-storage repairs; [`clear`] it.
    ///
    /// [`clear`]: PersistentStore::clear
    Corrupted,
    /// No room left for the snapshot (the range is too small for it).
    Full,
    /// The snapshot does not fit in one flash page, or, in a range of two pages, in
    /// half a page (the map copies the current snapshot beside the new one when it
    /// changes pages): nothing is written. Give the range a third page.
    TooBig,
    /// Two persistent settings of different variables have the same key (FNV-1a of the
    /// variable's name): nothing is written. The code generator refuses such tables; a
    /// table built by hand must rename one of the variables.
    KeyCollision {
        /// The key.
        key: u32,
    },
    /// The table has more persistent settings than the store's buffer holds.
    TooManySettings {
        /// Persistent settings of the table.
        persistent: usize,
        /// Entries the buffer holds.
        capacity: usize,
    },
    /// An item in flash is larger than the store's buffer (stored by a firmware with a
    /// larger buffer): [`clear`] the store, or give it a larger buffer.
    ///
    /// [`clear`]: PersistentStore::clear
    BufferTooSmall {
        /// The buffer length the item needs.
        needed: usize,
    },
    /// The stored snapshot does not decode.
    Record(RecordError),
    /// The snapshot read back after a store is not the one written (the flash did not
    /// take it; the previous snapshot is still the stored one). Storing again writes it
    /// elsewhere.
    Verify,
    /// sequential-storage reported an internal error, or the table grew during a store.
    Internal,
}

impl<E> StoreError<E> {
    /// The kind of error, without the flash's error value.
    pub fn kind(&self) -> ErrorKind {
        match self {
            StoreError::Flash(_) => ErrorKind::Flash,
            StoreError::Corrupted => ErrorKind::Corrupted,
            StoreError::Full => ErrorKind::Full,
            StoreError::TooBig => ErrorKind::TooBig,
            StoreError::KeyCollision { .. } => ErrorKind::KeyCollision,
            StoreError::TooManySettings { .. } => ErrorKind::TooManySettings,
            StoreError::BufferTooSmall { .. } => ErrorKind::BufferTooSmall,
            StoreError::Record(_) => ErrorKind::Record,
            StoreError::Verify => ErrorKind::Verify,
            StoreError::Internal => ErrorKind::Internal,
        }
    }

    fn from_map(e: sequential_storage::Error<E>) -> Self {
        use sequential_storage::Error;
        match e {
            Error::Storage { value, .. } => StoreError::Flash(value),
            Error::FullStorage => StoreError::Full,
            Error::Corrupted { .. } => StoreError::Corrupted,
            Error::ItemTooBig => StoreError::TooBig,
            Error::BufferTooSmall(needed) => StoreError::BufferTooSmall { needed },
            _ => StoreError::Internal,
        }
    }
}

impl<E: fmt::Debug> fmt::Display for StoreError<E> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            StoreError::Flash(e) => write!(f, "settings flash error: {e:?}"),
            StoreError::Corrupted => f.write_str("stored settings corrupted beyond repair"),
            StoreError::Full => f.write_str("settings flash full"),
            StoreError::TooBig => f.write_str("settings snapshot too large for the flash pages"),
            StoreError::KeyCollision { key } => write!(
                f,
                "two persistent settings of different variables have the key {key:#010x}"
            ),
            StoreError::TooManySettings {
                persistent,
                capacity,
            } => write!(
                f,
                "{persistent} persistent settings, the store holds {capacity}"
            ),
            StoreError::BufferTooSmall { needed } => {
                write!(f, "a stored item needs a {needed}-byte buffer")
            }
            StoreError::Record(e) => write!(f, "stored settings: {e}"),
            StoreError::Verify => f.write_str("settings snapshot did not read back as written"),
            StoreError::Internal => f.write_str("settings storage internal error"),
        }
    }
}

impl<E: fmt::Debug> core::error::Error for StoreError<E> {}

/// [`StoreError`] without the flash's error value (what [`StoreStats`] and
/// [`Outcome`] keep).
///
/// [`StoreStats`]: crate::task::StoreStats
/// [`Outcome`]: crate::task::Outcome
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ErrorKind {
    /// [`StoreError::Flash`].
    Flash,
    /// [`StoreError::Corrupted`].
    Corrupted,
    /// [`StoreError::Full`].
    Full,
    /// [`StoreError::TooBig`].
    TooBig,
    /// [`StoreError::KeyCollision`].
    KeyCollision,
    /// [`StoreError::TooManySettings`].
    TooManySettings,
    /// [`StoreError::BufferTooSmall`].
    BufferTooSmall,
    /// [`StoreError::Record`].
    Record,
    /// [`StoreError::Verify`].
    Verify,
    /// [`StoreError::Internal`].
    Internal,
}

/// What a load did.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LoadReport {
    /// A snapshot was stored (if not, every setting keeps its value).
    pub found: bool,
    /// Entries of the snapshot.
    pub entries: usize,
    /// Entries applied to a setting.
    pub applied: usize,
    /// Entries of a persistent setting whose value the setting refused (out of its
    /// bounds, or not finite): it keeps its value.
    pub refused: usize,
    /// Entries whose key is no persistent setting of the table: ignored.
    pub unknown: usize,
    /// Entries of a persistent setting whose type changed since: ignored.
    pub mismatched: usize,
    /// Persistent settings of the table the snapshot has no entry for: they keep their
    /// value.
    pub missing: usize,
}

/// What a store wrote.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SaveReport {
    /// Entries of the snapshot (one per persistent variable).
    pub entries: usize,
    /// Bytes of the record.
    pub record_bytes: usize,
    /// Bytes the snapshot takes in flash (item header, key, record, padding).
    pub flash_bytes: usize,
}

/// The buffer sequential-storage works in, aligned for flash that needs aligned writes.
#[repr(align(32))]
struct AlignedBuf<const N: usize>([u8; N]);

/// The persistent settings of a table, in a range of NOR flash `S`, with the
/// sequential-storage cache `C` and a buffer of `BUF` bytes (use [`buffer_len`] for the
/// most persistent settings it must hold).
///
/// Its futures must run to completion (see the [module](self) documentation). Each
/// operation works with the cache it takes out of the store, and puts it back when it
/// finishes: an operation dropped mid-way leaves the store with an empty cache, which is
/// always correct.
pub struct PersistentStore<S: NorFlash, C: CacheImpl<SnapshotKey>, const BUF: usize> {
    flash: S,
    range: Range<u32>,
    cache: C,
    new_cache: fn() -> C,
    buf: AlignedBuf<BUF>,
}

/// The map over the store's flash, with the store's cache (an empty one is left in its
/// place until [`close`] puts it back).
fn open<'f, S: NorFlash, C: CacheImpl<SnapshotKey>>(
    flash: &'f mut S,
    range: &Range<u32>,
    cache: &mut C,
    new_cache: fn() -> C,
) -> Result<MapStorage<SnapshotKey, &'f mut S, C>, StoreError<S::Error>> {
    // The range was accepted when the store was made.
    let config = MapConfig::try_new(range.clone()).map_err(|_| StoreError::Internal)?;
    Ok(MapStorage::new(
        flash,
        config,
        core::mem::replace(cache, new_cache()),
    ))
}

/// Puts the map's cache back into the store.
fn close<S: NorFlash, C: CacheImpl<SnapshotKey>>(
    map: MapStorage<SnapshotKey, &mut S, C>,
    cache: &mut C,
) {
    *cache = map.destroy().1;
}

impl<S: NorFlash, C: CacheImpl<SnapshotKey>, const BUF: usize> PersistentStore<S, C, BUF> {
    /// A store over `range` of `flash` (page-aligned, at least two pages). `new_cache`
    /// makes an empty cache, now and whenever the cache cannot follow the flash (after
    /// [`erase`](Self::erase), or an operation dropped mid-way): e.g.
    /// [`page_cache::<PAGES>`](page_cache) with `PAGES` the range's page count (a cache
    /// for fewer pages panics in sequential-storage, which
    /// [`with_page_cache`](Self::with_page_cache) rules out), or
    /// [`Cache::new_uncached`].
    ///
    /// # Errors
    /// [`ConfigError::Map`] for a range sequential-storage refuses, or
    /// [`ConfigError::Buffer`] for a buffer too small for an empty snapshot.
    pub fn new(flash: S, range: Range<u32>, new_cache: fn() -> C) -> Result<Self, ConfigError> {
        map_config::<S>(&range)?;
        let min = (KEY_LEN + HEADER_LEN).next_multiple_of(word::<S>());
        if BUF < min {
            return Err(ConfigError::Buffer { len: BUF, min });
        }
        Ok(Self {
            flash,
            range,
            cache: new_cache(),
            new_cache,
            buf: AlignedBuf([0; BUF]),
        })
    }

    /// Entries (persistent settings) a snapshot in this store may hold.
    pub const fn capacity() -> usize {
        let usable = BUF / word::<S>() * word::<S>();
        let entries = usable.saturating_sub(KEY_LEN + HEADER_LEN) / ENTRY_LEN;
        if entries < MAX_ENTRIES {
            entries
        } else {
            MAX_ENTRIES
        }
    }

    /// Bytes a snapshot of `entries` entries takes in this store's flash.
    pub fn flash_bytes(entries: usize) -> usize {
        Self::record_flash_bytes(record_len(entries))
    }

    /// Bytes a record of `len` bytes takes in this store's flash.
    fn record_flash_bytes(len: usize) -> usize {
        MapStorage::<SnapshotKey, S, C>::item_overhead_size() as usize
            + (KEY_LEN + len).next_multiple_of(word::<S>())
    }

    /// The stored snapshot, if any.
    ///
    /// # Errors
    /// [`StoreError`]: the flash failed, the map is corrupted beyond repair, or the
    /// snapshot does not decode ([`StoreError::Record`]).
    pub async fn snapshot(&mut self) -> Result<Option<Record<'_>>, StoreError<S::Error>> {
        let mut map = open(
            &mut self.flash,
            &self.range,
            &mut self.cache,
            self.new_cache,
        )?;
        let fetched = map
            .fetch_item::<&[u8]>(&mut self.buf.0, &SNAPSHOT_KEY)
            .await;
        close(map, &mut self.cache);
        fetched
            .map_err(StoreError::from_map)?
            .map(Record::decode)
            .transpose()
            .map_err(StoreError::Record)
    }

    /// Applies the stored snapshot to `table` (see [`apply`]): every entry whose key and
    /// type match a persistent setting of the table is set through
    /// [`Settings::try_set`], so the setting's bounds apply. Without a snapshot every
    /// setting keeps its value.
    ///
    /// # Errors
    /// As [`snapshot`](Self::snapshot); the table is unchanged.
    pub async fn load<M: RawMutex, const N: usize>(
        &mut self,
        table: &Settings<'_, M, N>,
    ) -> Result<LoadReport, StoreError<S::Error>> {
        Ok(match self.snapshot().await? {
            Some(record) => apply(&record, table),
            None => LoadReport {
                missing: persistent_count(table),
                ..LoadReport::default()
            },
        })
    }

    /// Stores the value of every persistent setting of `table` as one snapshot.
    ///
    /// # Errors
    /// [`StoreError::TooManySettings`] (nothing written) if the table has more persistent
    /// settings than [`capacity`](Self::capacity); [`StoreError::Verify`] if the snapshot
    /// did not read back as written (each store reads it back as a reboot would); else a
    /// failure of the map or the flash. After an error, the previous snapshot is still
    /// the stored one, or the new one if the failure came after it was complete.
    pub async fn save<M: RawMutex, const N: usize>(
        &mut self,
        table: &Settings<'_, M, N>,
    ) -> Result<SaveReport, StoreError<S::Error>> {
        let capacity = Self::capacity();
        let area = self
            .buf
            .0
            .get_mut(KEY_LEN..KEY_LEN + record_len(capacity))
            .ok_or(StoreError::Internal)?;
        let record_bytes = encode_table(table, area).map_err(|e| match e {
            EncodeError::DuplicateKey { key } => StoreError::KeyCollision { key },
            EncodeError::Full { .. } => StoreError::TooManySettings {
                persistent: persistent_count(table),
                capacity,
            },
        })?;
        // In a range of two pages, the map copies the current snapshot into the page the
        // new one goes to when it changes pages: two must fit in one, or every store
        // after the first fails (each failure erasing pages).
        let usable = S::ERASE_SIZE.saturating_sub(2 * word::<S>());
        if pages::<S>(&self.range) == 2 && 2 * Self::record_flash_bytes(record_bytes) > usable {
            return Err(StoreError::TooBig);
        }
        let item = TableRecord {
            table,
            capacity,
            written: Cell::new(None),
        };
        self.store_record(&item).await?;
        // Read back as a reboot would (an empty cache): the flash may not have taken
        // every byte (sequential-storage does not check), and the map then serves the
        // previous snapshot.
        let mut fresh = (self.new_cache)();
        let mut map = open(&mut self.flash, &self.range, &mut fresh, self.new_cache)?;
        let read = map
            .fetch_item::<&[u8]>(&mut self.buf.0, &SNAPSHOT_KEY)
            .await;
        // The store keeps the cache that found what a reboot finds.
        close(map, &mut self.cache);
        let read = read.map_err(StoreError::from_map)?;
        let Some((record_bytes, sum)) = item.written.get() else {
            return Err(StoreError::Internal);
        };
        if read.map(|r| (r.len(), fnv1a(r))) != Some((record_bytes, sum)) {
            return Err(StoreError::Verify);
        }
        let entries = record_bytes.saturating_sub(HEADER_LEN) / ENTRY_LEN;
        Ok(SaveReport {
            entries,
            record_bytes,
            flash_bytes: Self::flash_bytes(entries),
        })
    }

    /// Writes `record` under the snapshot key: the map opened, the item stored, the map
    /// closed (its cache kept for the next operation).
    async fn store_record<'v, V: Value<'v>>(
        &mut self,
        record: &V,
    ) -> Result<(), StoreError<S::Error>> {
        let mut map = open(
            &mut self.flash,
            &self.range,
            &mut self.cache,
            self.new_cache,
        )?;
        let stored = map.store_item(&mut self.buf.0, &SNAPSHOT_KEY, record).await;
        close(map, &mut self.cache);
        stored.map_err(StoreError::from_map)
    }

    /// Forgets the stored snapshot: stores an empty one, so the next boot keeps every
    /// default (settings keep their values until then). As a store, a power cut leaves
    /// either the previous snapshot or the empty one. If the map cannot be read or take
    /// a new snapshot (corrupted beyond repair, or an item larger than the buffer), the
    /// range is [erased](Self::erase) instead.
    ///
    /// # Errors
    /// [`StoreError::Flash`].
    pub async fn clear(&mut self) -> Result<(), StoreError<S::Error>> {
        const EMPTY: [u8; HEADER_LEN] = [MAGIC[0], MAGIC[1], VERSION, 0];
        match self.snapshot().await {
            Ok(_) | Err(StoreError::Record(_)) => {}
            Err(StoreError::Flash(e)) => return Err(StoreError::Flash(e)),
            Err(_) => return self.erase().await,
        }
        let empty = Record::decode(&EMPTY).map_err(|_| StoreError::Internal)?;
        match self.store_record(&empty).await {
            Ok(()) => Ok(()),
            Err(StoreError::Flash(e)) => Err(StoreError::Flash(e)),
            Err(_) => self.erase().await,
        }
    }

    /// Erases the whole range, page by page: the way out of a map corrupted beyond
    /// repair. Before a page is erased, its last word is written as sequential-storage's
    /// page marker (if it is erased), so a power cut in the middle of the page's erase
    /// leaves a page that sequential-storage recognizes as half-erased and erases again.
    /// A cut during `erase` may leave an older snapshot readable: erase again.
    ///
    /// (sequential-storage's own `erase_all` does not mark pages: a cut in the erase of
    /// the page being written leaves a page that reads as erased and is not, and the
    /// next store there fails or is lost.)
    ///
    /// # Errors
    /// [`StoreError::Flash`].
    pub async fn erase(&mut self) -> Result<(), StoreError<S::Error>> {
        // The cache cannot follow an erase: start again with an empty one.
        self.cache = (self.new_cache)();
        let word = word::<S>();
        let page = S::ERASE_SIZE;
        let marker = AlignedBuf([0u8; MAX_WORD]);
        let mut end_word = AlignedBuf([0u8; MAX_WORD]);
        for start in self.range.clone().step_by(page) {
            // `new` checked the range: whole pages, words of at most 32 bytes.
            let end = start + (page - word) as u32;
            let end_word = &mut end_word.0[..word];
            self.flash
                .read(end, end_word)
                .await
                .map_err(StoreError::Flash)?;
            if end_word.iter().all(|b| *b == 0xFF) {
                self.flash
                    .write(end, &marker.0[..word])
                    .await
                    .map_err(StoreError::Flash)?;
            }
            self.flash
                .erase(start, start + page as u32)
                .await
                .map_err(StoreError::Flash)?;
        }
        Ok(())
    }

    /// The flash range the store uses.
    pub fn flash_range(&self) -> Range<u32> {
        self.range.clone()
    }

    /// The flash, back (e.g. to build a new store over it, as after a reboot).
    pub fn into_flash(self) -> S {
        self.flash
    }
}

impl<S: NorFlash, const PAGES: usize, const BUF: usize> PersistentStore<S, PageCache<PAGES>, BUF> {
    /// A store over `range` with a [`PageCache`] of `PAGES` pages.
    ///
    /// # Errors
    /// As [`new`](Self::new), and [`ConfigError::PageCount`] if the range does not have
    /// `PAGES` pages.
    pub fn with_page_cache(flash: S, range: Range<u32>) -> Result<Self, ConfigError> {
        map_config::<S>(&range)?;
        let pages = pages::<S>(&range);
        if pages != PAGES {
            return Err(ConfigError::PageCount {
                pages,
                cache: PAGES,
            });
        }
        Self::new(flash, range, page_cache::<PAGES>)
    }
}

/// Checks `range` as sequential-storage does, and first that it is not reversed (which
/// sequential-storage does not check).
fn map_config<S: NorFlash>(range: &Range<u32>) -> Result<(), ConfigError> {
    if range.start >= range.end {
        return Err(ConfigError::Map(MapConfigError::RangeTooSmall));
    }
    MapConfig::<S>::try_new(range.clone())
        .map(|_| ())
        .map_err(ConfigError::Map)
}

/// Pages of `range` (checked by [`map_config`]: not reversed).
fn pages<S: NorFlash>(range: &Range<u32>) -> usize {
    (range.end - range.start) as usize / S::ERASE_SIZE
}

/// The flash word sequential-storage writes in: the larger of the read and write sizes
/// (at least 1).
const fn word<S: NorFlash>() -> usize {
    let word = if S::WRITE_SIZE > S::READ_SIZE {
        S::WRITE_SIZE
    } else {
        S::READ_SIZE
    };
    if word > 0 { word } else { 1 }
}

/// The description of `entry` if it is persistent.
fn persistent<'a>(entry: &SettingEntry<'a>) -> Option<&'a SettingDesc<'a>> {
    entry.desc.filter(|d| d.persistent)
}

/// Whether a persistent setting of `table` before `index` is bound to the variable `var`.
fn bound_before<M: RawMutex, const N: usize>(
    table: &Settings<'_, M, N>,
    index: u8,
    var: &str,
) -> bool {
    (0..index).any(|i| {
        table
            .entry(i)
            .is_some_and(|e| persistent(&e).is_some_and(|d| d.var == var))
    })
}

/// Persistent settings of `table` (a variable bound twice counts twice).
fn persistent_count<M: RawMutex, const N: usize>(table: &Settings<'_, M, N>) -> usize {
    let mut count = 0;
    table.for_each(|_, entry| count += usize::from(persistent(&entry).is_some()));
    count
}

/// Applies `record` to `table`: each entry goes to the first persistent setting with its
/// key, if the types match, through [`Settings::try_set`] (bounds apply). Entries of
/// other keys, or of another type, are counted and ignored.
///
/// One walk of the table: each setting finds its entry at the position the walk expects
/// (a record saved by the same table is in the table's order), else by a search, so
/// loading a record of the same firmware takes time linear in the settings.
pub fn apply<M: RawMutex, const N: usize>(
    record: &Record<'_>,
    table: &Settings<'_, M, N>,
) -> LoadReport {
    let mut report = LoadReport {
        found: true,
        entries: record.len(),
        ..LoadReport::default()
    };
    // Record entries already given to a setting (at most 255 entries).
    let mut used = [0u32; 8];
    let mut next = 0;
    table.for_each(|index, setting| {
        let Some(desc) = persistent(&setting) else {
            return;
        };
        let Some((at, entry)) = record.position(desc.key(), next) else {
            report.missing += 1;
            return;
        };
        next = at + 1;
        let (word, bit) = (at / 32, 1u32 << (at % 32));
        let Some(slot) = used.get_mut(word) else {
            return;
        };
        if *slot & bit != 0 {
            // A variable bound to a second setting: given to the first only.
            return;
        }
        *slot |= bit;
        if entry.ty != desc.ty {
            report.mismatched += 1;
        } else if table.try_set(index, entry.value).is_ok() {
            report.applied += 1;
        } else {
            report.refused += 1;
        }
    });
    let matched: u32 = used.iter().map(|w| w.count_ones()).sum();
    report.unknown = record.len() - matched as usize;
    report
}

/// Writes the record of `table`'s persistent settings (one entry per variable) into
/// `buf`; returns its length.
fn encode_table<M: RawMutex, const N: usize>(
    table: &Settings<'_, M, N>,
    buf: &mut [u8],
) -> Result<usize, EncodeError> {
    let mut writer = RecordWriter::new(buf)?;
    let mut result = Ok(());
    table.for_each(|index, setting| {
        let Some(desc) = persistent(&setting) else {
            return;
        };
        if result.is_err() {
            return;
        }
        let entry = Entry {
            key: desc.key(),
            ty: desc.ty,
            value: setting.get(),
        };
        match writer.push(entry) {
            Ok(()) => {}
            // A variable bound to two settings is stored once.
            Err(EncodeError::DuplicateKey { .. }) if bound_before(table, index, desc.var) => {}
            Err(e) => result = Err(e),
        }
    });
    result.map(|()| writer.finish())
}

/// The snapshot of a table as a map value: encoded from the table's values each time the
/// map serializes it (no copy of the record). Write-only: a stored snapshot is read back
/// as a [`Record`].
struct TableRecord<'t, 'a, M: RawMutex, const N: usize> {
    table: &'t Settings<'a, M, N>,
    capacity: usize,
    /// Length and FNV-1a of the record last serialized (the one written), to check the
    /// read-back.
    written: Cell<Option<(usize, u32)>>,
}

impl<'d, M: RawMutex, const N: usize> Value<'d> for TableRecord<'_, '_, M, N> {
    fn serialize_into(&self, buffer: &mut [u8]) -> Result<usize, SerializationError> {
        let len = record_len(self.capacity).min(buffer.len());
        let area = buffer
            .get_mut(..len)
            .ok_or(SerializationError::BufferTooSmall)?;
        let n = encode_table(self.table, area).map_err(|_| SerializationError::BufferTooSmall)?;
        let record = area.get(..n).ok_or(SerializationError::BufferTooSmall)?;
        self.written.set(Some((n, fnv1a(record))));
        Ok(n)
    }

    fn deserialize_from(_buffer: &'d [u8]) -> Result<(Self, usize), SerializationError> {
        Err(SerializationError::InvalidFormat)
    }
}
