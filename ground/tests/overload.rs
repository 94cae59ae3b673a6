//! A loopback flood, replayed deterministically: datagrams of `99 FF` false starts
//! mixed with valid frames arrive much faster than the monitor decodes them. The input
//! queue stays within its bound, drops the oldest input and counts every byte it drops,
//! the monitor shows the count, and the current frames are still decoded.
//!
//! (The issue: a 10 s flood grew the monitor from 119 MB to 838 MB, and only 2,174 of
//! 13,884 valid frames were decoded, late.)

use std::time::Duration;

use pprz_ground::input::{CHUNK_OVERHEAD, InputQueue, Overflow, Pop};
use pprz_ground::monitor::{Decoded, Monitor};
use pprz_ground::set::RuntimeSet;
use pprz_transports::{Encoder, MsgHeader, PprzV2, TxMeta};

const MESSAGES: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../messages.xml");

/// An ALIVE frame numbered `n` (its md5sum holds `n`).
fn alive(n: u16) -> Vec<u8> {
    let [lo, hi] = n.to_le_bytes();
    let mut buf = [0u8; 64];
    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 2));
    let len = PprzV2::new().encode(&meta, &[2, lo, hi], &mut buf).unwrap();
    buf[..len].to_vec()
}

/// Pops one read and decodes it; returns it and the numbers of the ALIVE frames
/// decoded.
fn consume(queue: &InputQueue, monitor: &mut Monitor, now: f64) -> Option<(Vec<u8>, Vec<u16>)> {
    let mut found = Vec::new();
    let mut on_line = |d: &Decoded<'_>| {
        if let Some(md5) = d.line.strip_prefix("7 telemetry ALIVE md5sum=") {
            let v: Vec<u16> = md5.split(',').map(|x| x.parse().unwrap()).collect();
            found.push(v[0] | (v[1] << 8));
        }
    };
    match queue.pop(Duration::ZERO) {
        Pop::Data {
            bytes,
            dropped_before,
        } => {
            monitor.input_gap(now, dropped_before, &mut on_line);
            monitor.feed(now, &bytes, &mut on_line);
            Some((bytes, found))
        }
        Pop::Idle | Pop::End(_) => None,
    }
}

#[test]
fn a_flood_is_bounded_counted_shown_and_current_frames_decoded() {
    const CAPACITY: usize = 256 * 1024;
    const ROUNDS: u16 = 1000;
    let set = RuntimeSet::load(MESSAGES).unwrap();
    let mut monitor = Monitor::new(set, PprzV2::new().into());
    let queue = InputQueue::new(CAPACITY, Overflow::DropOldest);
    let junk: Vec<u8> = [0x99, 0xFF].repeat(700);
    let mut pushed = 0u64;
    let mut seed = 1u64;
    let mut consumed = 0u64;
    let mut decoded = Vec::new();
    // The numbers of the frames that were not dropped.
    let mut good_popped = Vec::new();
    for round in 0..ROUNDS {
        let now = f64::from(round) * 0.001;
        // 10 to 29 datagrams of false starts and one frame arrive...
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        for _ in 0..10 + (seed >> 33) % 20 {
            assert!(queue.push(&junk));
            pushed += junk.len() as u64;
        }
        let good = alive(round);
        assert!(queue.push(&good));
        pushed += good.len() as u64;
        assert!(queue.stats().cost <= CAPACITY);
        // ...while the monitor decodes about 2000 bytes.
        let mut budget = 2000;
        while budget > 0 {
            let Some((read, found)) = consume(&queue, &mut monitor, now) else {
                break;
            };
            budget -= read.len().min(budget);
            consumed += read.len() as u64;
            good_popped.extend(good_number(&read));
            decoded.extend(found);
        }
    }
    // The flood stops: the monitor catches up with what is queued.
    let queued_at_end = queue.stats().queued_reads;
    while let Some((read, found)) = consume(&queue, &mut monitor, 10.0) {
        consumed += read.len() as u64;
        good_popped.extend(good_number(&read));
        decoded.extend(found);
    }
    // The link is silent now: the monitor flushes the decoder (after
    // `monitor::IDLE_FLUSH`), which gives up the last false start of the flood and
    // decodes the frame held behind it.
    let mut on_line = |d: &Decoded<'_>| {
        if let Some(md5) = d.line.strip_prefix("7 telemetry ALIVE md5sum=") {
            let v: Vec<u16> = md5.split(',').map(|x| x.parse().unwrap()).collect();
            decoded.push(v[0] | (v[1] << 8));
        }
    };
    monitor.flush(10.5, &mut on_line);
    let st = queue.stats();
    assert_eq!(st.queued_bytes, 0);

    // Bounded: the queue never held more than its bound (a few hundred reads, not the
    // 20,000 sent).
    assert!(st.peak_cost <= CAPACITY, "{st:?}");
    assert!(
        queued_at_end <= CAPACITY / (junk.len() + CHUNK_OVERHEAD) * 2,
        "{queued_at_end}"
    );
    assert!(
        monitor.retained_bytes() < 64 * 1024,
        "{}",
        monitor.retained_bytes()
    );

    // Every byte is either decoded or counted as dropped, and the monitor shows it.
    let dropped = st.dropped;
    assert!(dropped.reads > 10_000, "{dropped:?}");
    assert_eq!(dropped.bytes + consumed, pushed);
    assert_eq!(monitor.input_dropped(), dropped);
    let shown = format!(
        "input dropped {} B in {} reads",
        dropped.bytes, dropped.reads
    );
    assert!(monitor.render(10.0).contains(&shown));
    assert!(monitor.summary(10.0).contains(&shown));

    // The current frames are decoded: every frame that was not dropped, in order,
    // the last one sent included.
    assert_eq!(decoded, good_popped);
    assert_eq!(decoded.last(), Some(&(ROUNDS - 1)));
    assert!(decoded.len() > 50, "{}", decoded.len());
}

/// The number of the ALIVE frame `read` is, if it is one.
fn good_number(read: &[u8]) -> Option<u16> {
    (read.len() == alive(0).len()).then(|| u16::from_le_bytes([read[7], read[8]]))
}
