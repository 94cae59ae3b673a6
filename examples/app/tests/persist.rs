//! The application's persistent settings: the gain the ground sets and stores (setting 4,
//! the store flag) is the gain the aircraft starts with after a reboot, before the
//! ground asks anything.

mod common;

use std::cell::RefCell;
use std::convert::Infallible;
use std::sync::Mutex;

use embassy_futures::select::{Either3, select3};
use embassy_time::{Instant, MockDriver, Timer};
use pprz_example_app::settings::index::{GAIN, SETTINGS_STORE_FLAG};
use pprz_example_app::{AC_ID, Config, M, run_aircraft_with_store};
use pprz_settings::embedded_storage_async::nor_flash::{ErrorType, NorFlash, ReadNorFlash};
use pprz_settings::sequential_storage::cache::CacheImpl;
use pprz_settings::{
    FlagState, FlashError, PageCache, PersistentStore, RamFlash, SnapshotKey, StoreControl,
    buffer_len,
};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, run_writer};
use pprz_transports::PprzV2;

use common::{Air, dl_values, get_setting_frame, run_on_mock_clock, setting_frame};

/// Four 1 KiB pages of 4-byte words, in RAM (the boards use 16 or 128 KiB pages).
const FLASH: usize = 4096;
type Flash<'m> = RamFlash<'m, FLASH, 4, 1024>;
type Store<'m> = PersistentStore<Flash<'m>, PageCache<4>, { buffer_len(4) }>;

/// The mock clock is the process's: the tests boot one at a time.
static CLOCK: Mutex<()> = Mutex::new(());

/// The ground's radio: delivers each frame at its time (ms after boot), then nothing.
struct Ground {
    frames: Vec<(u64, Vec<u8>)>,
    next: usize,
}

impl embedded_io_async::ErrorType for Ground {
    type Error = Infallible;
}

impl embedded_io_async::Read for Ground {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        let Some((at_ms, frame)) = self.frames.get(self.next) else {
            return core::future::pending().await;
        };
        Timer::at(Instant::from_millis(*at_ms)).await;
        self.next += 1;
        buf[..frame.len()].copy_from_slice(frame);
        Ok(frame.len())
    }
}

/// Boots the aircraft with `store` and `control` on a fresh mock clock, the ground
/// sending `frames`, until `until_ms`; returns every DL_VALUE it sent (time, index,
/// value).
fn boot<S: NorFlash, C: CacheImpl<SnapshotKey>, const BUF: usize>(
    store: &mut PersistentStore<S, C, BUF>,
    control: &StoreControl<M>,
    frames: Vec<(u64, Vec<u8>)>,
    until_ms: u64,
) -> Vec<(Instant, u8, f32)> {
    // One mock clock for the process: one boot at a time.
    let _clock = CLOCK.lock().unwrap_or_else(|e| e.into_inner());
    MockDriver::get().reset();
    let arena: FrameArena<M, 8192> = FrameArena::new();
    let radio = DeviceConfig::new(PprzV2::new().into());
    let downlink: Downlink<'_, M, 1, 32> = Downlink::new(&arena, AC_ID, [radio]);
    let [mut port] = downlink.ports().unwrap();
    let written = RefCell::new(Vec::new());
    let ground = Ground { frames, next: 0 };
    let app = run_aircraft_with_store(port.device(), ground, Config::default(), store, control);
    let writer = run_writer(&mut port, Air(&written));
    let end = Timer::at(Instant::from_millis(until_ms));
    match run_on_mock_clock(select3(app, writer, end)) {
        Either3::First(Err(e)) => panic!("the application did not start: {e}"),
        Either3::First(Ok(never)) => match never {},
        Either3::Second(never) => match never {},
        Either3::Third(()) => {}
    }
    dl_values(&written.into_inner())
}

/// The values of setting `index` in `values`, sent at or after `from_ms` and before
/// `to_ms`.
fn values_of(values: &[(Instant, u8, f32)], index: u8, from_ms: u64, to_ms: u64) -> Vec<f32> {
    let (from, to) = (Instant::from_millis(from_ms), Instant::from_millis(to_ms));
    values
        .iter()
        .filter(|(t, i, _)| *i == index && *t >= from && *t < to)
        .map(|&(_, _, v)| v)
        .collect()
}

#[test]
fn a_stored_gain_is_the_gain_after_a_reboot() {
    let mut mem = vec![0xFF_u8; FLASH];
    let mem: &mut [u8; FLASH] = mem.as_mut_slice().try_into().unwrap();

    // First boot: nothing stored, the gain starts at 1 (GET_SETTING at 0.5 s). The
    // ground sets it to 4.5 at 1 s, and the store flag at 2 s.
    let mut store = Store::with_page_cache(Flash::new(mem), 0..FLASH as u32).unwrap();
    let control = StoreControl::<M>::new();
    let frames = vec![
        (505, get_setting_frame(GAIN)),
        (1_005, setting_frame(GAIN, 4.5)),
        (2_005, setting_frame(SETTINGS_STORE_FLAG, 1.0)),
    ];
    let first = boot(&mut store, &control, frames, 3_000);
    let stats = control.stats();
    assert_eq!((stats.loads, stats.load_failures), (1, 0));
    assert_eq!(stats.entries_applied, 0, "nothing was stored yet");
    assert_eq!(values_of(&first, GAIN, 0, 1_005), [1.0], "{first:?}");
    assert_eq!(values_of(&first, GAIN, 1_005, 1_055), [4.5], "{first:?}");
    // The flag: the acknowledgement (1: the store is asked), then the store task's
    // DL_VALUE once it is done (1: stored).
    assert_eq!(
        values_of(&first, SETTINGS_STORE_FLAG, 2_005, 2_055),
        [1.0, 1.0],
        "{first:?}"
    );
    assert_eq!(control.store_state(), FlagState::Done);
    assert_eq!((control.stats().stores, control.stats().failures), (1, 0));

    // Reboot: a new store over the same flash, a new control, a new table. The first
    // DL_VALUE of the gain, periodic, shows the stored value; so does GET_SETTING.
    let mem = store.into_flash().into_inner();
    let mut store = Store::with_page_cache(Flash::new(mem), 0..FLASH as u32).unwrap();
    let control = StoreControl::<M>::new();
    let frames = vec![(4_005, get_setting_frame(GAIN))];
    let second = boot(&mut store, &control, frames, 4_100);
    let gains = values_of(&second, GAIN, 0, 4_100);
    assert!(
        gains.len() >= 2,
        "a periodic DL_VALUE and the reply: {second:?}"
    );
    assert!(gains.iter().all(|&g| g == 4.5), "{second:?}");
    assert_eq!(values_of(&second, GAIN, 4_005, 4_055), [4.5], "{second:?}");
    let stats = control.stats();
    assert_eq!((stats.loads, stats.entries_applied), (1, 1));
    // A new control: its flag reads 0 until the ground sets it.
    assert_eq!(control.store_state(), FlagState::Idle);
    let flags = values_of(&second, SETTINGS_STORE_FLAG, 0, 4_100);
    assert!(flags.iter().all(|&f| f == 0.0), "{second:?}");
}

/// A flash whose reads work (an erased flash: nothing stored) and whose writes and
/// erases all fail.
struct Broken<'m>(Flash<'m>);

impl ErrorType for Broken<'_> {
    type Error = FlashError;
}

impl ReadNorFlash for Broken<'_> {
    const READ_SIZE: usize = 1;

    async fn read(&mut self, offset: u32, bytes: &mut [u8]) -> Result<(), FlashError> {
        self.0.read(offset, bytes).await
    }

    fn capacity(&self) -> usize {
        self.0.capacity()
    }
}

impl NorFlash for Broken<'_> {
    const WRITE_SIZE: usize = 4;
    const ERASE_SIZE: usize = 1024;

    async fn erase(&mut self, _from: u32, _to: u32) -> Result<(), FlashError> {
        Err(FlashError::OutOfBounds)
    }

    async fn write(&mut self, _offset: u32, _bytes: &[u8]) -> Result<(), FlashError> {
        Err(FlashError::OutOfBounds)
    }
}

/// A store the flash does not take: the flag's acknowledgement says 1 (asked), the store
/// task's DL_VALUE says 0 (failed), and the failure is counted.
#[test]
fn a_failed_store_reads_0() {
    let mut mem = vec![0xFF_u8; FLASH];
    let mem: &mut [u8; FLASH] = mem.as_mut_slice().try_into().unwrap();
    let flash = Broken(Flash::new(mem));
    let mut store =
        PersistentStore::<_, PageCache<4>, { buffer_len(4) }>::with_page_cache(flash, 0..4096)
            .unwrap();
    let control = StoreControl::<M>::new();
    let frames = vec![(1_005, setting_frame(SETTINGS_STORE_FLAG, 1.0))];
    let values = boot(&mut store, &control, frames, 1_500);
    assert_eq!(
        values_of(&values, SETTINGS_STORE_FLAG, 1_005, 1_055),
        [1.0, 0.0],
        "{values:?}"
    );
    assert_eq!(control.store_state(), FlagState::Failed);
    assert_eq!((control.stats().stores, control.stats().failures), (0, 1));
    assert_eq!(control.stats().load_failures, 0);
}

/// A flash that holds no map (all zeros, as the emulated board's PSRAM without a file):
/// the boot load fails (counted), the store is cleared, and storing then works.
#[test]
fn a_flash_without_a_map_is_cleared_at_boot() {
    let mut mem = vec![0_u8; FLASH];
    let mem: &mut [u8; FLASH] = mem.as_mut_slice().try_into().unwrap();
    let mut store = Store::with_page_cache(Flash::new(mem), 0..FLASH as u32).unwrap();
    let control = StoreControl::<M>::new();
    let frames = vec![
        (1_005, setting_frame(GAIN, 4.5)),
        (1_505, setting_frame(SETTINGS_STORE_FLAG, 1.0)),
    ];
    let values = boot(&mut store, &control, frames, 2_000);
    let stats = control.stats();
    assert_eq!((stats.loads, stats.load_failures), (1, 1));
    assert_eq!((stats.stores, stats.failures), (1, 0), "{values:?}");

    let mem = store.into_flash().into_inner();
    let mut store = Store::with_page_cache(Flash::new(mem), 0..FLASH as u32).unwrap();
    let control = StoreControl::<M>::new();
    let values = boot(
        &mut store,
        &control,
        vec![(505, get_setting_frame(GAIN))],
        600,
    );
    assert_eq!(values_of(&values, GAIN, 505, 600), [4.5], "{values:?}");
    assert_eq!(control.stats().load_failures, 0);
}
