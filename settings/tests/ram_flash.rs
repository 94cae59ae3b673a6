//! RamFlash: NOR semantics, bounds, alignment, and the store over it across a "reset".

mod common;

use common::*;
use embassy_futures::block_on;
use embedded_storage_async::nor_flash::{NorFlash, NorFlashError, NorFlashErrorKind, ReadNorFlash};
use pprz_settings::{FlashError, PageCache, PersistentStore, RamFlash, buffer_len};

type Flash<'m> = RamFlash<'m, 4096, 4, 1024>;

fn read(flash: &mut Flash<'_>, offset: u32, len: usize) -> Vec<u8> {
    let mut out = vec![0u8; len];
    block_on(flash.read(offset, &mut out)).unwrap();
    out
}

#[test]
fn writes_only_clear_bits_and_erase_sets_a_page() {
    let mut mem = [0u8; 4096];
    let mut flash = Flash::erased(&mut mem);
    assert_eq!(read(&mut flash, 0, 8), [0xFF; 8]);
    block_on(flash.write(4, &[0xF0, 0x0F, 0xAA, 0x00])).unwrap();
    block_on(flash.write(4, &[0x3C, 0xFF, 0x55, 0xFF])).unwrap();
    assert_eq!(read(&mut flash, 4, 4), [0x30, 0x0F, 0x00, 0x00]);
    // Writing ones changes nothing.
    block_on(flash.write(4, &[0xFF; 4])).unwrap();
    assert_eq!(read(&mut flash, 4, 4), [0x30, 0x0F, 0x00, 0x00]);
    // A page erase touches its page only.
    block_on(flash.write(1024, &[0; 4])).unwrap();
    block_on(flash.erase(0, 1024)).unwrap();
    assert_eq!(read(&mut flash, 0, 8), [0xFF; 8]);
    assert_eq!(read(&mut flash, 1024, 4), [0; 4]);
    block_on(flash.erase(0, 4096)).unwrap();
    assert!(flash.as_bytes().iter().all(|b| *b == 0xFF));
}

#[test]
fn reads_start_anywhere_inside() {
    let mut mem = [0u8; 4096];
    let mut flash = Flash::erased(&mut mem);
    block_on(flash.write(0, &[1, 2, 3, 4, 5, 6, 7, 8])).unwrap();
    assert_eq!(read(&mut flash, 3, 3), [4, 5, 6]);
    assert_eq!(read(&mut flash, 4095, 1), [0xFF]);
    assert_eq!(Flash::READ_SIZE, 1);
    assert_eq!(flash.capacity(), 4096);
}

#[test]
fn misaligned_and_outside_operations_change_nothing() {
    let mut mem = [0u8; 4096];
    let mut flash = Flash::erased(&mut mem);
    let mut buf = [0u8; 4];
    let cases = [
        (block_on(flash.write(2, &[0; 4])), FlashError::NotAligned),
        (block_on(flash.write(0, &[0; 3])), FlashError::NotAligned),
        (
            block_on(flash.write(4092, &[0; 8])),
            FlashError::OutOfBounds,
        ),
        (
            block_on(flash.write(u32::MAX - 3, &[0; 4])),
            FlashError::OutOfBounds,
        ),
        (block_on(flash.erase(512, 1024)), FlashError::NotAligned),
        (block_on(flash.erase(0, 1000)), FlashError::NotAligned),
        (block_on(flash.erase(1024, 0)), FlashError::OutOfBounds),
        (block_on(flash.erase(0, 5120)), FlashError::OutOfBounds),
        (
            block_on(flash.read(4093, &mut buf)),
            FlashError::OutOfBounds,
        ),
        (
            block_on(flash.read(u32::MAX, &mut buf)),
            FlashError::OutOfBounds,
        ),
    ];
    for (i, (result, error)) in cases.into_iter().enumerate() {
        assert_eq!(result, Err(error), "case {i}");
    }
    assert!(flash.as_bytes().iter().all(|b| *b == 0xFF));
    assert_eq!(FlashError::NotAligned.kind(), NorFlashErrorKind::NotAligned);
    assert_eq!(
        FlashError::OutOfBounds.kind(),
        NorFlashErrorKind::OutOfBounds
    );
}

#[test]
fn new_keeps_the_contents_as_a_kept_region_does() {
    let mut mem = [0u8; 4096];
    {
        let mut flash = Flash::erased(&mut mem);
        let mut store = PersistentStore::<_, PageCache<4>, { buffer_len(8) }>::with_page_cache(
            &mut flash,
            0..4096,
        )
        .unwrap();
        save(&mut store, &A).unwrap();
        save(&mut store, &B).unwrap();
    }
    // "Reset": a new flash over the same memory, a new store, a fresh table.
    let mut store = PersistentStore::<_, PageCache<4>, { buffer_len(8) }>::with_page_cache(
        Flash::new(&mut mem),
        0..4096,
    )
    .unwrap();
    assert_eq!(load(&mut store).1, loaded(B));
    let mem = store.into_flash().into_inner();
    assert_ne!(mem[0], 0xFF);
}
