//! The simulated radio link under embassy-time's mock clock: byte rate, latency,
//! buffer overflow, receiver overrun, bit errors, determinism.

mod common;

use common::{mock_time, run};
use embassy_futures::join::join;
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant};
use embedded_io_async::{Read, Write};
use pprz_devices::sim::{
    Direction, MAX_OUTAGES, OutageError, Overflow, SimConfig, SimLink, SimStats,
};
use pprz_transports::{MsgHeader, PprzV2, PprzV2Decoder, TxMeta, write_frame};

fn ms(t: Instant) -> f64 {
    t.as_micros() as f64 / 1000.0
}

/// Reads until `n` bytes arrived; returns each byte with its arrival time.
async fn read_n<R: Read>(rx: &mut R, n: usize) -> Vec<(u8, Instant)> {
    let mut got = Vec::with_capacity(n);
    let mut buf = [0u8; 64];
    while got.len() < n {
        let k = rx.read(&mut buf).await.unwrap();
        let now = Instant::now();
        got.extend(buf[..k].iter().map(|&b| (b, now)));
    }
    got
}

#[test]
fn throughput_is_the_byte_rate_and_latency_is_added() {
    let _t = mock_time();
    let config = SimConfig::new(1000)
        .latency(Duration::from_millis(50))
        .buffer(16)
        .overflow(Overflow::Wait);
    let link = SimLink::<NoopRawMutex, 256>::new(config);
    let (mut a, mut b) = link.endpoints();
    let data: Vec<u8> = (0..2000u32).map(|i| i as u8).collect();
    let (_, got) = run(
        join(
            async {
                a.write_all(&data).await.unwrap();
                a.flush().await.unwrap();
                Instant::now()
            },
            read_n(&mut b, data.len()),
        ),
        Duration::from_micros(100),
        100_000,
    );
    let bytes: Vec<u8> = got.iter().map(|&(b, _)| b).collect();
    assert_eq!(bytes, data, "bytes arrive intact and in order");
    // Byte k ends its transmission at (k + 1) ms and arrives 50 ms later.
    for (k, &(_, at)) in got.iter().enumerate() {
        assert_eq!(
            at,
            Instant::from_millis(k as u64 + 1 + 50),
            "arrival of byte {k}"
        );
    }
    let (first, last) = (got[0].1, got[got.len() - 1].1);
    let rate = (data.len() - 1) as f64 / ((last - first).as_micros() as f64 / 1e6);
    assert_eq!(rate, 1000.0, "measured byte rate");
    assert_eq!(ms(first), 51.0);
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (s.bytes_written, s.bytes_sent, s.bytes_delivered),
        (2000, 2000, 2000)
    );
    assert_eq!((s.dropped_bytes, s.overrun_bytes, s.bit_errors), (0, 0, 0));
}

#[test]
fn wait_mode_paces_the_writer_by_the_buffer() {
    let _t = mock_time();
    let config = SimConfig::new(1000).buffer(10).overflow(Overflow::Wait);
    let link = SimLink::<NoopRawMutex, 256>::new(config);
    let (mut a, _b) = link.endpoints();
    // 10 bytes fit at once; the 11th waits for the first to leave (1 ms), the 30th
    // for the 20th (20 ms).
    let done = run(
        async {
            a.write_all(&[0u8; 30]).await.unwrap();
            Instant::now()
        },
        Duration::from_micros(100),
        10_000,
    );
    assert_eq!(done, Instant::from_millis(20));
    let flushed = run(
        async {
            a.flush().await.unwrap();
            Instant::now()
        },
        Duration::from_micros(100),
        10_000,
    );
    assert_eq!(
        flushed,
        Instant::from_millis(30),
        "flush waits for the last byte"
    );
}

#[test]
fn full_buffer_drops_and_counts() {
    let _t = mock_time();
    let config = SimConfig::new(1000).buffer(100);
    let link = SimLink::<NoopRawMutex, 512>::new(config);
    let (mut a, mut b) = link.endpoints();
    let data: Vec<u8> = (0..300u32).map(|i| i as u8).collect();
    let n = run(a.write(&data), Duration::from_micros(100), 1);
    assert_eq!(n.unwrap(), 300, "a radio accepts the bytes it drops");
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (s.bytes_written, s.bytes_sent, s.dropped_bytes),
        (300, 100, 200)
    );
    let got = run(read_n(&mut b, 100), Duration::from_micros(100), 10_000);
    assert_eq!(
        got.iter().map(|&(b, _)| b).collect::<Vec<_>>(),
        data[..100],
        "the first 100 bytes went through"
    );
    assert_eq!(got[99].1, Instant::from_millis(100));
    // The buffer has drained: new bytes go through again.
    let n = run(a.write(&data[..50]), Duration::from_micros(100), 1);
    assert_eq!(n.unwrap(), 50);
    let s = link.stats(Direction::AToB);
    assert_eq!((s.bytes_sent, s.dropped_bytes), (150, 200));
}

#[test]
fn receiver_overrun_is_counted() {
    let _t = mock_time();
    // Unlimited rate: the ring of 64 bytes is the only limit.
    let link = SimLink::<NoopRawMutex, 64>::new(SimConfig::new(0));
    let (mut a, mut b) = link.endpoints();
    run(a.write_all(&[7u8; 100]), Duration::from_micros(100), 1).unwrap();
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (s.bytes_sent, s.overrun_bytes, s.dropped_bytes),
        (64, 36, 0)
    );
    let got = run(read_n(&mut b, 64), Duration::from_micros(100), 10);
    assert_eq!(got.len(), 64);
    assert_eq!(
        got[0].1,
        Instant::from_ticks(0),
        "no rate, no latency: at once"
    );
}

#[test]
fn latency_without_rate_limit() {
    let _t = mock_time();
    let link =
        SimLink::<NoopRawMutex, 64>::new(SimConfig::new(0).latency(Duration::from_millis(30)));
    let (mut a, mut b) = link.endpoints();
    let got = run(
        join(
            async {
                embassy_time::Timer::after(Duration::from_millis(10)).await;
                a.write_all(b"ping").await.unwrap();
            },
            read_n(&mut b, 4),
        ),
        Duration::from_millis(1),
        1000,
    )
    .1;
    assert!(got.iter().all(|&(_, t)| t == Instant::from_millis(40)));
}

#[test]
fn both_directions_are_independent() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 64>::new(SimConfig::new(100));
    let (a, b) = link.endpoints();
    let (mut a_rx, mut a_tx) = a.split();
    let (mut b_rx, mut b_tx) = b.split();
    let (_, _, to_b, to_a) = run(
        async {
            let w = join(a_tx.write_all(b"downlink"), b_tx.write_all(b"up"));
            let r = join(read_n(&mut b_rx, 8), read_n(&mut a_rx, 2));
            let ((wa, wb), (rb, ra)) = join(w, r).await;
            (wa, wb, rb, ra)
        },
        Duration::from_millis(1),
        1000,
    );
    assert_eq!(
        to_b.iter().map(|&(b, _)| b).collect::<Vec<_>>(),
        b"downlink"
    );
    assert_eq!(to_a.iter().map(|&(b, _)| b).collect::<Vec<_>>(), b"up");
    // 100 bytes/s: 10 ms per byte.
    assert_eq!(to_b[7].1, Instant::from_millis(80));
    assert_eq!(to_a[1].1, Instant::from_millis(20));
    assert_eq!(a_tx.stats().bytes_sent, 8);
    assert_eq!(b_rx.stats().bytes_delivered, 8);
    assert_eq!(a_rx.stats().bytes_delivered, 2);
}

/// An outage loses the bytes whose transmission ends in its window, and only in its
/// direction; the modem keeps its pace, so the bytes after the window arrive on time.
#[test]
fn an_outage_loses_what_is_sent_in_its_window() {
    let _t = mock_time();
    let config = SimConfig::new(1000)
        .latency(Duration::from_millis(5))
        .buffer(256)
        .overflow(Overflow::Wait);
    let link = SimLink::<NoopRawMutex, 512>::new(config);
    // Byte k ends its transmission at (k + 1) ms: bytes 19 to 48 end in [20, 50) ms.
    link.add_outage(
        Direction::AToB,
        Instant::from_millis(20),
        Instant::from_millis(50),
    )
    .unwrap();
    let (a, b) = link.endpoints();
    let (mut a_rx, mut a_tx) = a.split();
    let (mut b_rx, mut b_tx) = b.split();
    let data: Vec<u8> = (0..100).collect();
    let (_, down, up) = run(
        async {
            let w = join(a_tx.write_all(&data), b_tx.write_all(&data[..40]));
            let r = join(read_n(&mut b_rx, 70), read_n(&mut a_rx, 40));
            let (_, (down, up)) = join(w, r).await;
            ((), down, up)
        },
        Duration::from_micros(100),
        100_000,
    );
    let expected: Vec<u8> = (0..19).chain(49..100).collect();
    assert_eq!(down.iter().map(|&(b, _)| b).collect::<Vec<_>>(), expected);
    assert_eq!(down[19].1, Instant::from_millis(50 + 5), "byte 49 on time");
    assert_eq!(up.len(), 40, "the other direction is not cut");
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (
            s.bytes_written,
            s.bytes_sent,
            s.outage_bytes,
            s.dropped_bytes
        ),
        (100, 70, 30, 0)
    );
    assert_eq!(s.air_busy_us, 100_000, "lost bytes took their air time");
    assert_eq!(link.stats(Direction::BToA).outage_bytes, 0);
}

#[test]
fn outage_windows_are_checked() {
    let link = SimLink::<NoopRawMutex, 16>::new(SimConfig::new(100));
    let t = Instant::from_millis;
    assert_eq!(
        link.add_outage(Direction::BToA, t(10), t(10)),
        Err(OutageError::Empty)
    );
    assert_eq!(
        link.add_outage(Direction::BToA, t(10), t(5)),
        Err(OutageError::Empty)
    );
    for i in 0..MAX_OUTAGES as u64 {
        link.add_outage(Direction::BToA, t(i), t(i + 1)).unwrap();
    }
    assert_eq!(
        link.add_outage(Direction::BToA, t(100), t(200)),
        Err(OutageError::Full)
    );
    // The other direction has its own windows.
    assert_eq!(link.add_outage(Direction::AToB, t(100), t(200)), Ok(()));
}

/// Sends `len` zero bytes over a link with `ber`, returns (flipped bits seen, stats).
fn bit_errors(ber: f64, seed: u64, len: usize) -> (u32, SimStats) {
    let link = SimLink::<NoopRawMutex, 4096>::new(
        SimConfig::new(0)
            .bit_error_rate(ber)
            .seed(seed)
            .overflow(Overflow::Wait),
    );
    let (mut a, mut b) = link.endpoints();
    let zeros = vec![0u8; len];
    let (_, got) = run(
        join(a.write_all(&zeros), read_n(&mut b, len)),
        Duration::from_micros(100),
        10_000,
    );
    let seen = got.iter().map(|&(b, _)| b.count_ones()).sum();
    (seen, link.stats(Direction::AToB))
}

#[test]
fn bit_error_rate_statistics() {
    let _t = mock_time();
    // 100 000 bytes = 800 000 bits at BER 1e-3: 800 flips expected, sigma ~ 28.
    let (seen, stats) = bit_errors(1e-3, 7, 100_000);
    assert_eq!(seen, stats.bit_errors, "every flip is counted");
    assert!((700..=900).contains(&seen), "{seen} flips for 800 expected");
    assert!(stats.corrupted_bytes <= stats.bit_errors && stats.corrupted_bytes > 700);
    // Same seed, same errors; another seed, other errors.
    assert_eq!(bit_errors(1e-3, 7, 100_000).1, stats);
    assert_ne!(bit_errors(1e-3, 8, 100_000).1, stats);
    // No BER, no flips.
    assert_eq!(bit_errors(0.0, 7, 10_000).0, 0);
}

#[test]
fn pprz_frames_over_a_noisy_link() {
    let _t = mock_time();
    // 57600-baud radio, 20 ms latency, BER 2e-4.
    let config = SimConfig::new(5760)
        .latency(Duration::from_millis(20))
        .buffer(512)
        .bit_error_rate(2e-4)
        .seed(3)
        .overflow(Overflow::Wait);
    let link = SimLink::<NoopRawMutex, 1024>::new(config);
    let (mut air, mut ground) = link.endpoints();
    const FRAMES: usize = 300;
    let fields = [0x55u8; 20];
    let (_, (good, decoder_errors)) = run(
        join(
            async {
                for i in 0..FRAMES {
                    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, (i % 200) as u8));
                    write_frame(&mut air, &PprzV2::new(), &meta, &fields)
                        .await
                        .unwrap();
                }
            },
            async {
                let mut decoder = PprzV2Decoder::new(PprzV2::new());
                let total = FRAMES * (20 + 8);
                let mut seen = 0;
                let mut good = 0;
                let mut buf = [0u8; 64];
                while seen < total {
                    let n = ground.read(&mut buf).await.unwrap();
                    seen += n;
                    let mut input = &buf[..n];
                    while let Some(f) = decoder.feed(&mut input) {
                        good += usize::from(f.payload() == fields);
                    }
                }
                while decoder.flush().is_some() {
                    good += 1;
                }
                (good, decoder.stats().checksum_errors)
            },
        ),
        Duration::from_micros(500),
        1_000_000,
    );
    let s = link.stats(Direction::AToB);
    // 8400 bytes, 67 200 bits: about 13 flips, each spoiling at most a frame or two.
    assert!(s.bit_errors > 0 && s.corrupted_bytes > 0);
    assert!(good < FRAMES, "some frames are lost to bit errors");
    assert!(
        good + 2 * s.corrupted_bytes as usize >= FRAMES,
        "{good} good frames, {} corrupted bytes",
        s.corrupted_bytes
    );
    assert!(decoder_errors > 0);
}
