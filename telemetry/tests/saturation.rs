//! A simulated 57600-baud radio saturated 10x by low-priority payload, with mock time
//! (deterministic): no acknowledgement is lost, each waits at most about one frame time
//! behind the frame already on the wire, status telemetry keeps flowing, and the link
//! stays busy.
//!
//! The futures are polled by hand while the mock clock advances in small steps, so the
//! run is the same on every machine. (`executor.rs` runs the same stack on the Embassy
//! std executor.)

use std::cell::RefCell;
use std::convert::Infallible;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_time::{Duration, Instant, Ticker, Timer};
use pprz_default::messages::telemetry::{Attitude, DlValue, Payload};
use pprz_messages::{Message, VarArray, priority};
use pprz_telemetry::pprz_transports::{Decoder, PprzV2};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, run_writer};

mod common;

use common::sim::{SimUart, byte_time_us, mock_time, run_with_mock_time};

/// 57600 baud, 8N1: 10 bits per byte.
const BYTE_TIME_US: u64 = byte_time_us(57_600); // 173 µs

#[test]
fn acknowledgements_survive_a_10x_overloaded_link() {
    const SECONDS: u64 = 6;
    let _serial = mock_time();
    let arena: FrameArena<CriticalSectionRawMutex, 4096> = FrameArena::new();
    let downlink: Downlink<'_, CriticalSectionRawMutex, 1, 32> =
        Downlink::new(&arena, 7, [DeviceConfig::new(PprzV2::new().into())]);
    let [mut port] = downlink.ports().unwrap();
    let log = RefCell::new(Vec::new());
    let acks_sent = RefCell::new(Vec::new());
    let payload_bytes = [0x5Au8; 120];

    let producer = async {
        // Low priority: a 129-byte PAYLOAD frame every 2 ms = 64.5 kB/s, 11x the link.
        // Normal: ATTITUDE at 10 Hz. High: DL_VALUE at 2 Hz.
        let mut ticker = Ticker::every(Duration::from_millis(1));
        for tick in 0..SECONDS * 1000 {
            ticker.next().await;
            if tick % 2 == 0 {
                let msg = Payload {
                    values: VarArray::new(&payload_bytes),
                };
                let _ = downlink.send(&msg);
            }
            if tick % 100 == 0 {
                let _ = downlink.send(&Attitude {
                    phi: 0.1,
                    psi: 0.2,
                    theta: 0.3,
                });
            }
            if tick % 500 == 250 {
                let index = acks_sent.borrow().len() as u8;
                acks_sent.borrow_mut().push(Instant::now());
                downlink
                    .send(&DlValue { index, value: 1.0 })
                    .expect("an acknowledgement is never dropped");
            }
        }
        // Let the queue drain for a moment.
        Timer::after(Duration::from_millis(100)).await;
    };
    let writer = async {
        let mut uart = SimUart {
            byte_us: BYTE_TIME_US,
            log: &log,
        };
        run_writer(&mut port, &mut uart).await
    };
    let done = run_with_mock_time(
        select(producer, writer),
        Duration::from_micros(20),
        SECONDS * 60_000,
    );
    assert!(matches!(done, Either::First(())));

    let log = log.into_inner();
    let acks_sent = acks_sent.into_inner();
    assert_eq!(acks_sent.len() as u64, SECONDS * 2);

    // Decode what went over the wire.
    let mut acks = vec![None; acks_sent.len()];
    let mut attitudes = 0;
    let mut payloads = 0;
    let mut largest_frame = 0;
    for (start, _end, bytes) in &log {
        largest_frame = largest_frame.max(bytes.len());
        let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
        let mut input = &bytes[..];
        let frame = decoder
            .feed(&mut input)
            .expect("every write is one whole frame");
        match frame.msg_id() {
            DlValue::ID => {
                let index = usize::from(frame.payload()[0]);
                assert!(acks[index].is_none(), "ack {index} sent twice");
                acks[index] = Some(*start);
            }
            Attitude::ID => attitudes += 1,
            Payload::ID => payloads += 1,
            other => panic!("unexpected message {other}"),
        }
    }
    // No acknowledgement lost; each waited at most one frame time (the frame already on
    // the wire) plus one simulation step.
    let frame_time = Duration::from_micros(BYTE_TIME_US * largest_frame as u64);
    let tolerance = Duration::from_micros(40);
    for (i, (sent, on_wire)) in acks_sent.iter().zip(&acks).enumerate() {
        let on_wire = on_wire.unwrap_or_else(|| panic!("ack {i} was lost"));
        let waited = on_wire - *sent;
        assert!(
            waited <= frame_time + tolerance,
            "ack {i} waited {} µs, more than one frame time ({} µs)",
            waited.as_micros(),
            frame_time.as_micros()
        );
    }
    // Status telemetry was never shed either (it outranks the payload flood).
    assert_eq!(attitudes, SECONDS * 10);
    let stats = downlink.stats(0).unwrap();
    assert!(stats.is_balanced(), "{stats:?}");
    assert!(stats.lost() > 0, "the payload flood was shed: {stats:?}");
    assert_eq!(
        u64::from(stats.sent),
        acks_sent.len() as u64 + attitudes + payloads
    );
    // The link stayed busy while backlogged.
    let busy_us: u64 = log.iter().map(|(s, e, _)| (*e - *s).as_micros()).sum();
    let span_us = (log.last().unwrap().1 - log.first().unwrap().0).as_micros();
    assert!(
        busy_us * 100 >= span_us * 98,
        "link utilisation {}%",
        busy_us * 100 / span_us
    );
    assert_eq!(Payload::PRIORITY, priority::LOW);
    println!(
        "sent {} frames ({} payload), lost {} payload frames, utilisation {:.1}%",
        stats.sent,
        payloads,
        stats.lost(),
        busy_us as f64 * 100.0 / span_us as f64
    );
}

/// A device that never completes a write.
struct Stalled;

impl embedded_io_async::ErrorType for Stalled {
    type Error = Infallible;
}

impl embedded_io_async::Write for Stalled {
    async fn write(&mut self, _buf: &[u8]) -> Result<usize, Infallible> {
        core::future::pending().await
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        core::future::pending().await
    }
}

/// A device whose every other write fails.
struct Flaky {
    writes: u32,
}

impl embedded_io_async::ErrorType for Flaky {
    type Error = embedded_io_async::ErrorKind;
}

impl embedded_io_async::Write for Flaky {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
        Timer::after(Duration::from_micros(BYTE_TIME_US * buf.len() as u64)).await;
        self.writes += 1;
        if self.writes.is_multiple_of(2) {
            Err(embedded_io_async::ErrorKind::Other)
        } else {
            Ok(buf.len())
        }
    }

    async fn flush(&mut self) -> Result<(), Self::Error> {
        Ok(())
    }
}

/// A device that breaks the `Write` contract in turn: it writes the first byte of a
/// frame only, then claims to have written nothing, then more bytes than it was given,
/// then writes what it is given.
struct Liar {
    writes: u32,
    wire: Vec<u8>,
}

impl embedded_io_async::ErrorType for Liar {
    type Error = Infallible;
}

impl embedded_io_async::Write for Liar {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.writes += 1;
        Ok(match self.writes % 4 {
            1 => {
                self.wire.extend_from_slice(&buf[..1]);
                1
            }
            2 => 0,
            3 => buf.len() + 5,
            _ => {
                self.wire.extend_from_slice(buf);
                buf.len()
            }
        })
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

#[test]
fn a_device_that_reports_no_byte_or_too_many_costs_a_write_error_not_a_panic() {
    let _serial = mock_time();
    let arena: FrameArena<CriticalSectionRawMutex, 2048> = FrameArena::new();
    let downlink: Downlink<'_, CriticalSectionRawMutex, 1, 8> =
        Downlink::new(&arena, 7, [DeviceConfig::new(PprzV2::new().into())]);
    let [mut port] = downlink.ports().unwrap();
    for index in 0..6u8 {
        downlink.send(&DlValue { index, value: 0.0 }).unwrap();
    }
    let mut liar = Liar {
        writes: 0,
        wire: Vec::new(),
    };
    run_with_mock_time(
        select(
            run_writer(&mut port, &mut liar),
            Timer::after(Duration::from_millis(10)),
        ),
        Duration::from_micros(100),
        1_000,
    );
    // Writes 1-2: one byte, then none (a write error); 3: too many (a write error); 4: a
    // whole frame; 5-6: one byte then none; 7: too many; 8: a whole frame.
    let stats = downlink.stats(0).unwrap();
    assert_eq!((stats.sent, stats.dropped.write_error), (2, 4), "{stats:?}");
    assert!(stats.is_balanced(), "{stats:?}");
    assert_eq!(arena.stats().live, 0, "every frame's memory came back");
    // On the wire: the stray first bytes of the failed frames, and two whole frames that
    // decode (behind a false start: the stray start byte reads the next one as a length).
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut input = &liar.wire[..];
    let mut frames = 0;
    while decoder.feed(&mut input).is_some() {
        frames += 1;
    }
    while decoder.flush().is_some() {
        frames += 1;
    }
    assert_eq!(frames, 2);
}

#[test]
fn a_stalled_device_blocks_only_its_own_queue_and_errors_are_counted() {
    let _serial = mock_time();
    let arena: FrameArena<CriticalSectionRawMutex, 8192> = FrameArena::new();
    let downlink: Downlink<'_, CriticalSectionRawMutex, 3, 8> = Downlink::new(
        &arena,
        7,
        [
            DeviceConfig::new(PprzV2::new().into()),
            DeviceConfig::new(PprzV2::new().into()),
            DeviceConfig::new(PprzV2::new().into()),
        ],
    );
    let [mut good_port, mut stalled_port, mut flaky_port] = downlink.ports().unwrap();
    let log = RefCell::new(Vec::new());
    let producer = async {
        for index in 0..50u8 {
            let _ = downlink.send(&DlValue { index, value: 0.0 });
            Timer::after(Duration::from_millis(10)).await;
        }
        Timer::after(Duration::from_millis(50)).await;
    };
    let writers = async {
        let mut good = SimUart {
            byte_us: BYTE_TIME_US,
            log: &log,
        };
        let mut flaky = Flaky { writes: 0 };
        let _ = embassy_futures::join::join3(
            run_writer(&mut good_port, &mut good),
            run_writer(&mut stalled_port, &mut Stalled),
            run_writer(&mut flaky_port, &mut flaky),
        )
        .await;
    };
    run_with_mock_time(
        select(producer, writers),
        Duration::from_micros(100),
        100_000,
    );

    let good = downlink.stats(0).unwrap();
    assert_eq!(good.sent, 50, "the healthy device got everything: {good:?}");
    assert_eq!(log.borrow().len(), 50);
    let stalled = downlink.stats(1).unwrap();
    assert_eq!(stalled.sent, 0);
    // A full queue of 8; the frame stuck in the writer (its `Outgoing`) was reported as a
    // failed write when the writer was dropped at the end of the run.
    assert_eq!(stalled.queued, 8);
    assert_eq!(stalled.dropped.write_error, 1);
    assert_eq!(
        stalled.dropped.queue_full,
        50 - 9,
        "equal priority: new ones dropped"
    );
    let flaky = downlink.stats(2).unwrap();
    assert_eq!((flaky.sent, flaky.dropped.write_error), (25, 25));
    for s in [good, stalled, flaky] {
        assert!(s.is_balanced(), "{s:?}");
    }
    assert_eq!(
        arena.stats().live,
        8,
        "only the stalled device's queue holds frames"
    );

    // The port outlived its cancelled writer: a new writer on a working device drains the
    // 8 frames left behind.
    let relog = RefCell::new(Vec::new());
    let mut replacement = SimUart {
        byte_us: BYTE_TIME_US,
        log: &relog,
    };
    run_with_mock_time(
        select(
            run_writer(&mut stalled_port, &mut replacement),
            Timer::after(Duration::from_millis(100)),
        ),
        Duration::from_micros(100),
        10_000,
    );
    assert_eq!(relog.borrow().len(), 8);
    let stalled = downlink.stats(1).unwrap();
    assert_eq!((stalled.sent, stalled.queued), (8, 0));
    assert!(stalled.is_balanced(), "{stalled:?}");
    assert_eq!(arena.stats().live, 0, "every frame's memory came back");
}
