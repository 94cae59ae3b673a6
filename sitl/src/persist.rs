//! Persistent settings (`--settings-flash`) and the ground's timed SETTINGs
//! (`--setting`): the aircraft keeps its persistent settings (the gain) in a file that
//! behaves as the F405's three 16 KiB flash sectors, loads them at start and stores them
//! when the ground sets the store flag (setting 4). Without the option nothing persists,
//! so runs stay reproducible.

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use pprz_settings::{FileFlash, PageCache, PersistentStore, StoreControl, buffer_len};
use static_cell::StaticCell;

use crate::options::{Args, TimedSetting};

/// Bytes of the simulated flash: three pages.
const FLASH_SIZE: usize = 3 * PAGE;
/// A page (a sector of the F405's sectors 1 to 3).
const PAGE: usize = 16 * 1024;

/// The flash file of `--settings-flash`: 4-byte words, 16 KiB pages, as the F405's.
pub type SitlFlash = FileFlash<FLASH_SIZE, 4, PAGE>;
/// The aircraft's store: room for 16 persistent settings.
pub type SitlStore = PersistentStore<SitlFlash, PageCache<3>, { buffer_len(16) }>;

/// Aircraft 7's store flag: every request is accepted (the simulated vehicle has no
/// motors to kill).
pub static CONTROL: StoreControl<CriticalSectionRawMutex> = StoreControl::new();
static STORE: StaticCell<SitlStore> = StaticCell::new();

/// Most `--setting` options.
pub const MAX_TIMED_SETTINGS: usize = 16;

/// The checks of `--settings-flash` and `--setting` with the other options; the message
/// of a usage error.
pub fn check(args: &Args) -> Result<(), String> {
    if args.settings_flash.is_some() && args.fleet > 1 {
        return Err(format!(
            "--settings-flash keeps the settings of one aircraft: drop --fleet {}",
            args.fleet
        ));
    }
    if !args.setting.is_empty() && args.headless {
        return Err(
            "--setting is sent by the in-process ground: drop --headless (or send SETTINGs from your ground)"
                .to_owned(),
        );
    }
    if args.setting.len() > MAX_TIMED_SETTINGS {
        return Err(format!(
            "--setting: {} given, at most {MAX_TIMED_SETTINGS}",
            args.setting.len()
        ));
    }
    Ok(())
}

/// What `--setting` asks for after the end of the run: one message per option.
pub fn after_the_end(args: &Args) -> Vec<String> {
    let end = args.duration;
    args.setting
        .iter()
        .filter(|s| s.at_s >= end)
        .map(|s| {
            format!(
                "--setting {}:{}={} is at or after the end of the run (--duration {end}): it has no effect",
                s.at_s, s.index, s.value
            )
        })
        .collect()
}

/// The store of `--settings-flash`, if given: the file opened (created erased when
/// absent); fails with the message to print.
pub fn open(args: &Args) -> Result<Option<&'static mut SitlStore>, String> {
    let Some(path) = &args.settings_flash else {
        return Ok(None);
    };
    let fail = |e: &dyn std::fmt::Display| format!("--settings-flash {}: {e}", path.display());
    let flash = SitlFlash::open(path).map_err(|e| fail(&e))?;
    let store = SitlStore::with_page_cache(flash, 0..FLASH_SIZE as u32).map_err(|e| fail(&e))?;
    Ok(Some(STORE.init(store)))
}

/// The summary's line about the store (with `--settings-flash`).
pub fn summary_line(args: &Args) -> Option<String> {
    let path = args.settings_flash.as_ref()?;
    let s = CONTROL.stats();
    Some(format!(
        "Settings flash {}: loaded {} setting(s) at start ({} load(s) failed); stored {} time(s), {} failed, {} refused\n",
        path.display(),
        s.entries_applied,
        s.load_failures,
        s.stores,
        s.failures,
        s.refusals,
    ))
}

/// The `--setting` options in time order (those of the same time in the order given).
pub fn timed_settings(args: &Args) -> Vec<TimedSetting> {
    let mut all = args.setting.clone();
    all.sort_by(|a, b| a.at_s.total_cmp(&b.at_s));
    all
}
