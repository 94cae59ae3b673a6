#![doc = include_str!("../README.md")]
#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]

#[cfg(feature = "std")]
extern crate std;

#[cfg(feature = "std")]
pub mod file_flash;
pub mod flash;
pub mod record;
pub mod store;
pub mod task;

/// The flash traits the store works on (version 0.4), for flash drivers.
pub use embedded_storage_async;
/// The storage engine (version 8): its caches and map configuration errors.
pub use sequential_storage;

#[cfg(feature = "std")]
pub use file_flash::{FileFlash, FileFlashError};
pub use flash::{FlashError, RamFlash};
pub use record::{Entry, Record, RecordError};
pub use store::{
    ConfigError, ErrorKind, LoadReport, PageCache, PersistentStore, SNAPSHOT_KEY, SaveReport,
    SnapshotKey, StoreError, buffer_len, page_cache,
};
pub use task::{FlagState, Outcome, Refused, Request, StoreControl, StoreStats, run};
