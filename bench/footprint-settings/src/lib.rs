//! Minimal STM32F405 firmwares that hold a generated settings table of N settings, to
//! measure what a described setting costs (`bench/settings-size.sh`).
//!
//! Each binary is one firmware, made by a macro of this crate:
//!
//! * `table-<N>` ([`firmware!`]`(N)`): the table pprz-codegen generates from a
//!   `settings.xml` of N settings, registered at boot with the application's bindings
//!   (one variable, getter and setter per setting), then served in the main loop as the
//!   SETTING and GET_SETTING services do (a set and a get by index);
//! * `store-<N>` ([`firmware!`]`(N, store)`): the same, with the settings persistent: the boot
//!   load (`StoreControl::load`, and `PersistentStore::erase` if it fails) and the store
//!   task (`pprz_settings::run`) over `RamFlash` with the geometry of the F405's sectors
//!   1 to 3 (three 16 KiB pages, 4-byte words), a stand-in for the board's flash driver.
//!
//! They are measured, not run: the futures are polled with a no-op waker in the main
//! loop, and the inputs go through `black_box`, so that the linker keeps what a firmware
//! keeps and little else.

#![no_std]

use core::future::Future;
use core::hint::black_box;
use core::pin::pin;
use core::task::{Context, Poll, Waker};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use pprz_settings::embedded_storage_async::nor_flash::NorFlash;
use pprz_settings::sequential_storage::cache::CacheImpl;
use pprz_settings::{PersistentStore, StoreControl};
use pprz_telemetry::settings::Settings;

/// The lock of the table and the store control: an interrupt mask.
pub type Mutex = CriticalSectionRawMutex;

/// Bytes of flash for the settings: three pages.
pub const FLASH_SIZE: usize = 3 * PAGE;
/// A page (an STM32F405's sectors 1 to 3).
pub const PAGE: usize = 16 * 1024;

/// Stops (a set-up that failed).
pub fn halt() -> ! {
    loop {
        cortex_m::asm::wfi();
    }
}

/// What the SETTING and GET_SETTING services do with the table: set and get a setting by
/// index, and read its name.
#[inline(never)]
pub fn serve<const N: usize>(table: &Settings<'_, Mutex, N>) {
    let index = black_box(0u8);
    black_box(table.set(index, black_box(1.0)));
    black_box(table.entry(index).map(|e| (e.name.len(), e.get())));
}

/// The main loop of a firmware without persistence.
pub fn run_table<const N: usize>(table: &Settings<'_, Mutex, N>) -> ! {
    loop {
        serve(table);
    }
}

/// Polls `future` until it is done (the boot load, before anything else runs).
fn finish<F: Future>(future: F) -> F::Output {
    let mut future = pin!(future);
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        if let Poll::Ready(output) = future.as_mut().poll(&mut cx) {
            return output;
        }
    }
}

/// The main loop of a firmware with persistence: the boot load, then the table served
/// and the store task polled; a store is asked when an input says so (as the store flag
/// setting does).
pub fn run_store<S: NorFlash, C: CacheImpl<pprz_settings::SnapshotKey>, const BUF: usize, const N: usize>(
    table: &'static Settings<'static, Mutex, N>,
    control: &'static StoreControl<Mutex>,
    store: &'static mut PersistentStore<S, C, BUF>,
) -> ! {
    if finish(control.load(store, table)).is_err() {
        // Corrupted beyond repair, or stored by a firmware with a larger buffer.
        let _ = finish(store.erase());
    }
    let mut task = pin!(pprz_settings::run(store, control, table));
    let mut cx = Context::from_waker(Waker::noop());
    loop {
        serve(table);
        if black_box(false) {
            control.set_store_flag(1.0);
        }
        let _ = task.as_mut().poll(&mut cx);
    }
}

/// A firmware with the table of `$n` generated settings (`$n` is 0, 10 or 100: the
/// tables `build.rs` generates): `firmware!(10)` without persistence, `firmware!(10,
/// store)` with the boot load and the store task.
#[macro_export]
macro_rules! firmware {
    ($n:literal) => {
        $crate::firmware!(@table $n);

        #[::cortex_m_rt::entry]
        fn main() -> ! {
            register();
            $crate::run_table(&TABLE)
        }
    };
    ($n:literal, store) => {
        $crate::firmware!(@table $n);

        /// Links the table to the store task.
        static CONTROL: ::pprz_settings::StoreControl<$crate::Mutex> =
            ::pprz_settings::StoreControl::new();
        /// The settings' flash: RAM here, a stand-in for the board's flash driver.
        type Flash =
            ::pprz_settings::RamFlash<'static, { $crate::FLASH_SIZE }, 4, { $crate::PAGE }>;
        /// The store, sized for the table.
        type Store = ::pprz_settings::PersistentStore<
            Flash,
            ::pprz_settings::PageCache<3>,
            { ::pprz_settings::buffer_len(settings::COUNT) },
        >;
        /// The memory of the flash stand-in.
        static MEM: ::static_cell::StaticCell<[u8; $crate::FLASH_SIZE]> =
            ::static_cell::StaticCell::new();
        /// The store, handed to the store task.
        static STORE: ::static_cell::StaticCell<Store> = ::static_cell::StaticCell::new();

        #[::cortex_m_rt::entry]
        fn main() -> ! {
            register();
            let mem = MEM.init([0xFF; $crate::FLASH_SIZE]);
            let range = 0..$crate::FLASH_SIZE as u32;
            let Ok(store) = Store::with_page_cache(Flash::new(mem), range) else {
                $crate::halt()
            };
            $crate::run_store(&TABLE, &CONTROL, STORE.init(store))
        }
    };
    (@table $n:literal) => {
        use panic_halt as _;

        /// The settings table generated from the `settings.xml` of `$n` settings.
        mod settings {
            include!(concat!(env!("OUT_DIR"), "/settings_", $n, ".rs"));
        }

        /// The application's variables and their bindings.
        mod variables {
            include!(concat!(env!("OUT_DIR"), "/variables_", $n, ".rs"));
        }

        /// The settings table.
        static TABLE: ::pprz_telemetry::settings::Settings<
            'static,
            $crate::Mutex,
            { settings::COUNT },
        > = ::pprz_telemetry::settings::Settings::new();

        /// Registers the generated settings, first, as a firmware does at boot.
        fn register() {
            if settings::register(&TABLE, &variables::bindings()).is_err() {
                $crate::halt();
            }
        }
    };
}
