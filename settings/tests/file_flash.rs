//! FileFlash (feature `std`): created erased, NOR semantics, bounds, alignment, geometry,
//! and the store across a restart of the process that uses it.

mod common;

use common::*;
use embassy_futures::block_on;
use embedded_storage_async::nor_flash::{NorFlash, ReadNorFlash};
use pprz_settings::{
    FileFlash, FileFlashError, FlashError, PageCache, PersistentStore, buffer_len,
};

type Flash = FileFlash<4096, 4, 1024>;

fn read(flash: &mut Flash, offset: u32, len: usize) -> Vec<u8> {
    let mut out = vec![0u8; len];
    block_on(flash.read(offset, &mut out)).unwrap();
    out
}

#[test]
fn a_missing_file_is_created_erased() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flash.bin");
    let mut flash = Flash::open(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), vec![0xFF; 4096]);
    assert_eq!(read(&mut flash, 4000, 96), vec![0xFF; 96]);
    // Only the flash file is left.
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().collect();
    assert_eq!(names.len(), 1);
}

#[test]
fn writes_only_clear_bits_and_erase_sets_a_page() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flash.bin");
    let mut flash = Flash::open(&path).unwrap();
    block_on(flash.write(4, &[0xF0, 0x0F, 0xAA, 0x00])).unwrap();
    block_on(flash.write(4, &[0x3C, 0xFF, 0x55, 0xFF])).unwrap();
    assert_eq!(read(&mut flash, 4, 4), [0x30, 0x0F, 0x00, 0x00]);
    // A long write (several chunks) ANDs too.
    let ones = vec![0x0Fu8; 600];
    let zeros_high = vec![0xF3u8; 600];
    block_on(flash.write(1024, &ones)).unwrap();
    block_on(flash.write(1024, &zeros_high)).unwrap();
    assert_eq!(read(&mut flash, 1024, 600), vec![0x03; 600]);
    block_on(flash.erase(1024, 2048)).unwrap();
    assert_eq!(read(&mut flash, 1024, 1024), vec![0xFF; 1024]);
    assert_eq!(read(&mut flash, 4, 4), [0x30, 0x0F, 0x00, 0x00]);
    drop(flash);
    let bytes = std::fs::read(&path).unwrap();
    assert_eq!(bytes[4..8], [0x30, 0x0F, 0x00, 0x00]);
}

#[test]
fn misaligned_and_outside_operations_change_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flash.bin");
    let mut flash = Flash::open(&path).unwrap();
    let mut buf = [0u8; 4];
    let flash_error = |r: Result<(), FileFlashError>| match r {
        Err(FileFlashError::Flash(e)) => Some(e),
        _ => None,
    };
    let cases = [
        (block_on(flash.write(2, &[0; 4])), FlashError::NotAligned),
        (block_on(flash.write(0, &[0; 3])), FlashError::NotAligned),
        (
            block_on(flash.write(4092, &[0; 8])),
            FlashError::OutOfBounds,
        ),
        (block_on(flash.erase(512, 1024)), FlashError::NotAligned),
        (block_on(flash.erase(1024, 0)), FlashError::OutOfBounds),
        (block_on(flash.erase(0, 5120)), FlashError::OutOfBounds),
        (
            block_on(flash.read(4093, &mut buf)),
            FlashError::OutOfBounds,
        ),
    ];
    for (i, (result, error)) in cases.into_iter().enumerate() {
        assert_eq!(flash_error(result), Some(error), "case {i}");
    }
    drop(flash);
    assert_eq!(std::fs::read(&path).unwrap(), vec![0xFF; 4096]);
}

#[test]
fn a_file_of_another_size_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("flash.bin");
    std::fs::write(&path, vec![0xFF; 1000]).unwrap();
    let err = Flash::open(&path).unwrap_err();
    assert_eq!(err.kind(), std::io::ErrorKind::InvalidData);
    assert!(err.to_string().contains("1000 bytes"), "{err}");
}

#[test]
fn settings_survive_a_restart() {
    type Store = PersistentStore<Flash, PageCache<4>, { buffer_len(8) }>;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("settings.flash");
    let open = || Store::with_page_cache(Flash::open(&path).unwrap(), 0..4096).unwrap();
    let (report, values) = load(&mut open());
    assert!(!report.unwrap().found);
    assert_eq!(values, DEFAULTS);
    for snapshot in [A, B, C, A] {
        save(&mut open(), &snapshot).unwrap();
    }
    assert_eq!(load(&mut open()).1, loaded(A));
    block_on(open().clear()).unwrap();
    assert_eq!(load(&mut open()).1, DEFAULTS);
    block_on(open().erase()).unwrap();
    assert!(!load(&mut open()).0.unwrap().found);
}
