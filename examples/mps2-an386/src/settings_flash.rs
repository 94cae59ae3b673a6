//! The settings "flash" of the emulated board: NOR flash emulated in RAM
//! ([`RamFlash`]) over the first 48 KiB of the MPS2's PSRAM (16 MiB at `0x2100_0000`),
//! three 16 KiB pages with 4-byte words, as the STM32F405's sectors 1 to 3.
//!
//! QEMU keeps the PSRAM in a file when started with
//! `-M mps2-an386,memory-backend=psram -object
//! memory-backend-file,id=psram,size=16M,mem-path=PATH,share=on` (the file filled with
//! `0xFF`, erased flash, one file per QEMU): the stored settings then survive QEMU's
//! exit, as flash survives a power cut. Without it the PSRAM is plain RAM, zeroed at
//! start: the store finds no map there, clears it at boot, and what it stores lasts
//! until QEMU exits.

use pprz_example_app::M;
use pprz_settings::{PageCache, PersistentStore, RamFlash, StoreControl, buffer_len};
use static_cell::StaticCell;

/// The PSRAM's address on the MPS2 AN386 image (QEMU `mps2.c`: `mps.ram`).
const PSRAM_BASE: usize = 0x2100_0000;
/// A page: 16 KiB.
const PAGE: usize = 16 * 1024;
/// Bytes of the settings flash: three pages.
const SIZE: usize = 3 * PAGE;

/// The settings flash.
pub type Flash = RamFlash<'static, SIZE, 4, PAGE>;
/// The store: room for 16 persistent settings.
pub type Store = PersistentStore<Flash, PageCache<3>, { buffer_len(16) }>;

/// The store flag's control. The emulated vehicle has no motors to kill: every request
/// is accepted.
pub static CONTROL: StoreControl<M> = StoreControl::new();
static STORE: StaticCell<Store> = StaticCell::new();

/// The store over the settings flash, as the PSRAM holds it. Panics if called twice.
pub fn store() -> &'static mut Store {
    // Taken first: a second call panics here, before a second reference to the PSRAM
    // exists.
    let slot = STORE.uninit();
    // Safety: `PSRAM_BASE..PSRAM_BASE + SIZE` lies in the machine's PSRAM (16 MiB of RAM
    // at 0x2100_0000, mapped for the whole program), outside the linker script's memory
    // (`memory.x`: FLASH 0x0 4M, RAM 0x2000_0000 4M), so no static, stack or heap is
    // there, and nothing else in the firmware uses the address. The reference is made
    // once (`STORE.uninit()` above panics on a second call) and lives in the store, so
    // it is the only access. Any byte pattern is a valid `[u8; SIZE]`, of alignment 1.
    let memory = unsafe { &mut *(PSRAM_BASE as *mut [u8; SIZE]) };
    let Ok(store) = Store::with_page_cache(Flash::new(memory), 0..SIZE as u32) else {
        panic!("the settings flash suits the store: three whole pages");
    };
    slot.write(store)
}
