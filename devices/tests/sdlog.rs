//! The SD card log on an in-memory block device holding a real FAT16/FAT32 file system
//! (made by the `fatfs` crate, read back by it too): records written, read back and
//! decoded; power cuts simulated by snapshots of the card; card errors.

use std::cell::{Cell, RefCell};
use std::io::{Cursor, Read as _};

use embassy_futures::block_on;
use embedded_io_async::Write;
use embedded_sdmmc::{
    Block, BlockCount, BlockDevice, BlockIdx, Mode, TimeSource, Timestamp, VolumeIdx, VolumeManager,
};
use pprz_devices::sdlog::{SdLog, SdLogConfig};
use pprz_transports::{MsgHeader, PprzLog, PprzLogDecoder, TxMeta, write_frame};

/// First block of the partition.
const START: usize = 63;

#[derive(Debug)]
struct CardError;

impl std::fmt::Display for CardError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("injected card error")
    }
}

impl std::error::Error for CardError {}

/// An SD card in RAM that counts block reads and writes and can be made to fail.
struct RamCard {
    image: RefCell<Vec<u8>>,
    reads: Cell<u32>,
    writes: Cell<u32>,
    fail_writes: Cell<bool>,
}

impl BlockDevice for RamCard {
    type Error = CardError;

    fn read(&self, blocks: &mut [Block], start: BlockIdx) -> Result<(), CardError> {
        let image = self.image.borrow();
        for (i, block) in blocks.iter_mut().enumerate() {
            let at = (start.0 as usize + i) * Block::LEN;
            block.copy_from_slice(image.get(at..at + Block::LEN).ok_or(CardError)?);
            self.reads.set(self.reads.get() + 1);
        }
        Ok(())
    }

    fn write(&self, blocks: &[Block], start: BlockIdx) -> Result<(), CardError> {
        if self.fail_writes.get() {
            return Err(CardError);
        }
        let mut image = self.image.borrow_mut();
        for (i, block) in blocks.iter().enumerate() {
            let at = (start.0 as usize + i) * Block::LEN;
            image
                .get_mut(at..at + Block::LEN)
                .ok_or(CardError)?
                .copy_from_slice(&block[..]);
            self.writes.set(self.writes.get() + 1);
        }
        Ok(())
    }

    fn num_blocks(&self) -> Result<BlockCount, CardError> {
        Ok(BlockCount((self.image.borrow().len() / Block::LEN) as u32))
    }
}

struct Clock;

impl TimeSource for Clock {
    fn get_timestamp(&self) -> Timestamp {
        Timestamp::from_calendar(2025, 6, 1, 12, 0, 0).unwrap()
    }
}

/// A card with an MBR and one FAT partition formatted by `fatfs`.
fn card(fat32: bool) -> RamCard {
    let (mib, kind, options) = if fat32 {
        let o = fatfs::FormatVolumeOptions::new()
            .fat_type(fatfs::FatType::Fat32)
            .bytes_per_cluster(512);
        (40, 0x0C, o)
    } else {
        let o = fatfs::FormatVolumeOptions::new().fat_type(fatfs::FatType::Fat16);
        (16, 0x06, o)
    };
    let blocks = mib * 2048;
    let mut image = vec![0u8; blocks * 512];
    fatfs::format_volume(Cursor::new(&mut image[START * 512..]), options).unwrap();
    let entry = &mut image[446..462];
    entry[4] = kind;
    entry[8..12].copy_from_slice(&(START as u32).to_le_bytes());
    entry[12..16].copy_from_slice(&((blocks - START) as u32).to_le_bytes());
    image[510] = 0x55;
    image[511] = 0xAA;
    RamCard {
        image: RefCell::new(image),
        reads: Cell::new(0),
        writes: Cell::new(0),
        fail_writes: Cell::new(false),
    }
}

/// Reads a file of a card image with `fatfs` (an independent FAT implementation).
fn read_back(image: &[u8], name: &str) -> Vec<u8> {
    let fs = fatfs::FileSystem::new(
        Cursor::new(image[START * 512..].to_vec()),
        fatfs::FsOptions::new(),
    )
    .unwrap();
    let mut out = Vec::new();
    fs.root_dir()
        .open_file(name)
        .unwrap()
        .read_to_end(&mut out)
        .unwrap();
    out
}

fn snapshot(volumes: &VolumeManager<RamCard, Clock>) -> Vec<u8> {
    volumes.device(|card| card.image.borrow().clone())
}

/// PPRZLOG record `i`: message `i % 200` with a 4-to-23-byte payload, t = 10 i.
fn record(i: u32) -> (TxMeta, Vec<u8>) {
    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, (i % 200) as u8)).at(i * 10);
    let fields = (0..4 + i % 20).map(|k| (i + k) as u8).collect();
    (meta, fields)
}

async fn log_records<W: Write>(w: &mut W, range: std::ops::Range<u32>) -> usize {
    let mut bytes = 0;
    for i in range {
        let (meta, fields) = record(i);
        bytes += write_frame(w, &PprzLog::TELEMETRY, &meta, &fields)
            .await
            .unwrap();
    }
    bytes
}

/// Decodes a log; returns the time stamps of its valid records and the error count.
fn decode(bytes: &[u8]) -> (Vec<u32>, u32) {
    let mut decoder = PprzLogDecoder::new(PprzLog::TELEMETRY);
    let mut stamps = Vec::new();
    let mut input = bytes;
    while let Some(f) = decoder.feed(&mut input) {
        let i = f.timestamp().unwrap() / 10;
        assert_eq!(f.payload(), record(i).1.as_slice(), "record {i}");
        stamps.push(f.timestamp().unwrap());
    }
    while let Some(f) = decoder.flush() {
        stamps.push(f.timestamp().unwrap());
    }
    (stamps, decoder.stats().errors())
}

fn roundtrip(fat32: bool) {
    let volumes = VolumeManager::new(card(fat32), Clock);
    let volume = volumes.open_raw_volume(VolumeIdx(0)).unwrap();
    let mut log = SdLog::open_in_root(
        &volumes,
        volume,
        "FLIGHT.LOG",
        Mode::ReadWriteCreateOrTruncate,
        SdLogConfig::default(),
    )
    .unwrap();
    let writes_before = volumes.device(|c| c.writes.get());
    let bytes = block_on(log_records(&mut log, 0..1000));
    block_on(log.flush()).unwrap();
    let stats = log.stats();
    log.close().unwrap();
    let writes = volumes.device(|c| c.writes.get()) - writes_before;

    let data = read_back(&snapshot(&volumes), "FLIGHT.LOG");
    assert_eq!(data.len(), bytes);
    let (stamps, errors) = decode(&data);
    assert_eq!(stamps, (0..1000).map(|i| i * 10).collect::<Vec<_>>());
    assert_eq!(errors, 0);

    // One write per data block, plus per new cluster two FAT entries in two FAT
    // copies, plus per sync the directory entry (and FSInfo on FAT32): not one write
    // (and read) per record.
    let blocks = bytes.div_ceil(512) as u32;
    assert_eq!(stats.block_writes, blocks);
    assert_eq!(stats.bytes_stored as usize, bytes);
    let image = snapshot(&volumes);
    let cluster_blocks = fatfs::FileSystem::new(
        Cursor::new(image[START * 512..].to_vec()),
        fatfs::FsOptions::new(),
    )
    .unwrap()
    .cluster_size()
        / 512;
    let clusters = blocks.div_ceil(cluster_blocks);
    assert!(
        writes <= blocks + 4 * clusters + 2 * stats.syncs + 4,
        "{writes} block writes for {blocks} data blocks, {clusters} clusters, {} syncs",
        stats.syncs
    );
    assert!(writes < 1000 / 3, "{writes} block writes for 1000 records");
}

#[test]
fn records_read_back_fat16() {
    roundtrip(false);
}

#[test]
fn records_read_back_fat32() {
    roundtrip(true);
}

#[test]
fn power_cut_loses_at_most_the_unsynced_tail() {
    let volumes = VolumeManager::new(card(false), Clock);
    let volume = volumes.open_raw_volume(VolumeIdx(0)).unwrap();
    let config = SdLogConfig {
        sync_every_blocks: 4,
        ..SdLogConfig::default()
    };
    let mut log = SdLog::open_in_root(
        &volumes,
        volume,
        "CUT.LOG",
        Mode::ReadWriteCreateOrTruncate,
        config,
    )
    .unwrap();
    let mut written = 0;
    let mut worst_loss = 0;
    for chunk in 0..20 {
        written += block_on(log_records(&mut log, chunk * 37..(chunk + 1) * 37));
        // Power cut now: what does the card hold?
        let data = read_back(&snapshot(&volumes), "CUT.LOG");
        assert!(data.len() <= written);
        let loss = written - data.len();
        worst_loss = worst_loss.max(loss);
        assert!(loss <= 4 * 512 + 511, "lost {loss} bytes");
        assert_eq!(data.len() % (4 * 512), 0, "the file ends at a sync");
        // What survived is a prefix of the log; only the last record may be cut.
        let (stamps, _) = decode(&data);
        let complete = stamps.len() as u32;
        assert_eq!(stamps, (0..complete).map(|i| i * 10).collect::<Vec<_>>());
        assert_eq!(log.len() as usize, written);
    }
    assert!(worst_loss > 512, "the test did cut into unsynced data");

    // After flush, a power cut loses nothing.
    block_on(log.flush()).unwrap();
    let data = read_back(&snapshot(&volumes), "CUT.LOG");
    assert_eq!(data.len(), written);
    assert_eq!(decode(&data).0.len(), 20 * 37);
    drop(log);
}

#[test]
fn card_errors_are_counted_and_nothing_is_lost_after_recovery() {
    let volumes = VolumeManager::new(card(false), Clock);
    let volume = volumes.open_raw_volume(VolumeIdx(0)).unwrap();
    let mut log = SdLog::open_in_root(
        &volumes,
        volume,
        "ERR.LOG",
        Mode::ReadWriteCreateOrTruncate,
        SdLogConfig::default(),
    )
    .unwrap();
    let mut written = block_on(log_records(&mut log, 0..10));

    volumes.device(|c| c.fail_writes.set(true));
    // Fill the block: the bytes are accepted, the block write fails (counted) and
    // stays buffered; then every write fails fast, accepting nothing.
    let mut refused = 0;
    block_on(async {
        for i in 10..100 {
            let (meta, fields) = record(i);
            match write_frame(&mut log, &PprzLog::TELEMETRY, &meta, &fields).await {
                Ok(n) => written += n,
                Err(_) => {
                    refused += 1;
                    break;
                }
            }
        }
    });
    assert_eq!(refused, 1);
    let failed_at = log.stats();
    assert!(failed_at.errors >= 1);
    assert!(block_on(log.write(&[0x99])).is_err());
    assert!(block_on(log.flush()).is_err());
    assert!(log.stats().errors > failed_at.errors);

    // The card recovers: the buffered block goes out and logging goes on.
    volumes.device(|c| c.fail_writes.set(false));
    let (stamps_before, _) = {
        block_on(log.flush()).unwrap();
        decode(&read_back(&snapshot(&volumes), "ERR.LOG"))
    };
    let complete = stamps_before.len() as u32;
    assert!(complete >= 10);
    written += block_on(log_records(&mut log, 1000..1010));
    // The refused record had its first bytes accepted (a stream keeps what it took;
    // the decoder skips the torn record).
    let accepted = log.stats().bytes_accepted as usize;
    assert!(accepted > written && accepted < written + 8 + 23);
    log.close().unwrap();
    let data = read_back(&snapshot(&volumes), "ERR.LOG");
    assert_eq!(data.len(), accepted, "no accepted byte was lost");
    let (stamps, _) = decode(&data);
    assert!(stamps.ends_with(&(1000..1010).map(|i| i * 10).collect::<Vec<_>>()));
}

#[test]
fn numbered_logs_and_append() {
    let volumes = VolumeManager::new(card(false), Clock);
    let volume = volumes.open_raw_volume(VolumeIdx(0)).unwrap();
    let (mut first, n0) = SdLog::create_numbered(&volumes, volume, SdLogConfig::default()).unwrap();
    block_on(first.write_all(b"first")).unwrap();
    first.close().unwrap();
    let (second, n1) = SdLog::create_numbered(&volumes, volume, SdLogConfig::default()).unwrap();
    drop(second); // closes the (empty) file
    assert_eq!((n0, n1), (0, 1));

    // Appending continues an existing log, across a block boundary it did not start on.
    let mut log = SdLog::open_in_root(
        &volumes,
        volume,
        "PPRZ0000.LOG",
        Mode::ReadWriteAppend,
        SdLogConfig::default(),
    )
    .unwrap();
    assert_eq!(log.len(), 5);
    let tail = vec![0xA5u8; 1500];
    block_on(log.write_all(&tail)).unwrap();
    assert_eq!(log.buffered(), (5 + 1500) % 512);
    log.close().unwrap();
    let image = snapshot(&volumes);
    let data = read_back(&image, "PPRZ0000.LOG");
    assert_eq!(&data[..5], b"first");
    assert_eq!(&data[5..], tail.as_slice());
    assert!(read_back(&image, "PPRZ0001.LOG").is_empty());
}

#[test]
fn flush_per_record_loses_nothing_and_costs_a_few_writes() {
    for fat32 in [false, true] {
        let volumes = VolumeManager::new(card(fat32), Clock);
        let volume = volumes.open_raw_volume(VolumeIdx(0)).unwrap();
        let mut log = SdLog::open_in_root(
            &volumes,
            volume,
            "ACK.LOG",
            Mode::ReadWriteCreateOrTruncate,
            SdLogConfig::default(),
        )
        .unwrap();
        let before = volumes.device(|c| c.writes.get());
        let mut written = 0;
        for i in 0..100 {
            written += block_on(log_records(&mut log, i..i + 1));
            block_on(log.flush()).unwrap();
            if i % 10 == 0 {
                // A power cut right after a flush loses nothing.
                let data = read_back(&snapshot(&volumes), "ACK.LOG");
                assert_eq!(data.len(), written);
            }
        }
        let writes = volumes.device(|c| c.writes.get()) - before;
        // Data block + directory entry (+ FSInfo on FAT32) per record, plus the FAT
        // updates of the few new clusters.
        let per_record = f64::from(writes) / 100.0;
        let expected = if fat32 { 3.0 } else { 2.0 };
        assert!(
            per_record >= expected && per_record <= expected + 0.3,
            "{per_record} block writes per record (FAT32: {fat32})"
        );
        drop(log);
    }
}

/// Block reads and writes of the card so far.
fn card_io(volumes: &VolumeManager<RamCard, Clock>) -> (u32, u32) {
    volumes.device(|c| (c.reads.get(), c.writes.get()))
}

#[test]
fn at_its_length_limit_the_log_is_full_and_keeps_what_it_took() {
    let volumes = VolumeManager::new(card(false), Clock);
    let volume = volumes.open_raw_volume(VolumeIdx(0)).unwrap();
    let config = SdLogConfig {
        max_len: 3000,
        ..SdLogConfig::default()
    };
    let mut log =
        SdLog::open_in_root(&volumes, volume, "MAX.LOG", Mode::ReadWriteCreate, config).unwrap();
    let refused = block_on(async {
        for i in 0..1000 {
            let (meta, fields) = record(i);
            if let Err(e) = write_frame(&mut log, &PprzLog::TELEMETRY, &meta, &fields).await {
                return Some(e);
            }
        }
        None
    });
    assert!(refused.is_some(), "the limit stops the log");
    assert_eq!(log.len(), 3000);
    let stats = log.stats();
    assert!(stats.full);
    assert_eq!(stats.bytes_accepted, 3000);
    // Every later write fails at once, counted, without a card access.
    let io = card_io(&volumes);
    for _ in 0..3 {
        assert!(matches!(
            block_on(log.write(&[0x99; 30])),
            Err(embedded_sdmmc::Error::NotEnoughSpace)
        ));
    }
    assert_eq!(card_io(&volumes), io);
    assert_eq!(log.stats().errors, stats.errors + 3);
    // What was accepted is stored.
    log.close().unwrap();
    assert_eq!(read_back(&snapshot(&volumes), "MAX.LOG").len(), 3000);
}

#[test]
fn on_a_full_card_later_writes_fail_without_touching_it() {
    let card = card(false);
    {
        // Fill the card with another file.
        let mut image = card.image.borrow_mut();
        let fs = fatfs::FileSystem::new(
            Cursor::new(&mut image[START * 512..]),
            fatfs::FsOptions::new(),
        )
        .unwrap();
        let mut fill = fs.root_dir().create_file("FILL.BIN").unwrap();
        let chunk = [0x11u8; 4096];
        while std::io::Write::write(&mut fill, &chunk).is_ok_and(|n| n > 0) {}
    }
    let volumes = VolumeManager::new(card, Clock);
    let volume = volumes.open_raw_volume(VolumeIdx(0)).unwrap();
    let mut log = SdLog::open_in_root(
        &volumes,
        volume,
        "FULL.LOG",
        Mode::ReadWriteCreate,
        SdLogConfig::default(),
    )
    .unwrap();
    // A whole block: accepted, then its store finds no free cluster (counted).
    assert_eq!(block_on(log.write(&[0xAB; 512])).unwrap(), 512);
    let stats = log.stats();
    assert!(stats.full);
    assert_eq!((stats.errors, stats.bytes_stored), (1, 0));
    let io = card_io(&volumes);
    for _ in 0..3 {
        assert!(matches!(
            block_on(log.write(&[0x99; 30])),
            Err(embedded_sdmmc::Error::NotEnoughSpace)
        ));
    }
    assert_eq!(card_io(&volumes), io, "no FAT scan per refused write");
    assert_eq!(log.stats().errors, 4);
    assert_eq!(
        log.buffered(),
        512,
        "the block that found no room stays counted"
    );
}
