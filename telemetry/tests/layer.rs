//! Link layers (`layer.rs`) in the runtime, with a layer of this test's own (no crypto):
//! the spare bytes a device reserves bound the messages `send` accepts; the writer seals
//! each frame when it takes it for the wire, in its arena block, in priority order;
//! frames the layer refuses are counted as `Refused` drops; the reader's `Layered` inbox
//! delivers what the layer opens, unchanged, rewritten or not at all.
//!
//! Deterministic: futures are polled by hand while embassy-time's mock clock advances.

mod common;

use pprz_telemetry::SendOptions;
use std::cell::RefCell;
use std::sync::Mutex as StdMutex;
use std::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, Timer};
use pprz_default::messages::telemetry::{Attitude, Payload};
use pprz_messages::VarArray;
use pprz_telemetry::Layered;
use pprz_telemetry::layer::{LinkLayer, Opened, Refused};
use pprz_telemetry::pprz_transports::{AnyTransport, Frame, MAX_FRAME_LEN, PprzV2};
use pprz_telemetry::reader::{Datalink, Inbox};
use pprz_telemetry::registry::{Filter, Received};
use pprz_telemetry::{DeviceConfig, Downlink, DropReason, FrameArena, run_writer_with};

use common::frames::uplink_frame;
use common::sim::{SimUart, mock_time, run_with_mock_time};

const AC_ID: u8 = 7;
/// The test layer's overhead: a 3-byte trailer after every frame.
const TRAILER: u8 = 3;

/// Appends a trailer `[n, 0xEE, 0xEE]` (its sequence number) to every frame, and refuses
/// every third one; opens frames by rewriting the message id +1, withholding id 99.
struct Trailer {
    sealed: AtomicU32,
}

impl LinkLayer for Trailer {
    fn seal(&self, buf: &mut [u8], len: usize) -> Result<usize, Refused> {
        let n = self.sealed.fetch_add(1, Ordering::Relaxed);
        if n % 3 == 2 {
            return Err(Refused);
        }
        let out = buf.get_mut(len..len + 3).ok_or(Refused)?;
        out.copy_from_slice(&[n as u8, 0xEE, 0xEE]);
        Ok(len + 3)
    }

    fn open(&self, frame: &Frame<'_>, out: &mut [u8; MAX_FRAME_LEN]) -> Opened {
        match frame.msg_id() {
            99 => Opened::Withheld,
            8 => Opened::Unchanged,
            _ => {
                let raw = frame.raw();
                out[..raw.len()].copy_from_slice(raw);
                out[5] += 1;
                Opened::Rewritten(raw.len())
            }
        }
    }
}

#[test]
fn reserved_bytes_bound_what_send_accepts() {
    static ARENA: FrameArena<M, 4096> = FrameArena::new();
    static DOWNLINK: Downlink<'static, M, 1, 8> = Downlink::new(
        &ARENA,
        AC_ID,
        [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())).reserve(21)],
    );
    // A PPRZ v2 frame carries 247 bytes of fields; with 21 reserved, 226 (a count byte
    // and 225 values).
    let fits = [0u8; 225];
    let too_long = [0u8; 226];
    let tx = DOWNLINK.sender();
    assert!(
        tx.send(&Payload {
            values: VarArray::new(&fits)
        })
        .is_ok()
    );
    let err = tx
        .send(&Payload {
            values: VarArray::new(&too_long),
        })
        .unwrap_err();
    assert_eq!(err.reason, DropReason::TooLarge);
    let stats = DOWNLINK.stats(0).unwrap();
    assert_eq!((stats.queued, stats.dropped.too_large), (1, 1));
    assert!(stats.is_balanced());
}

#[test]
fn the_writer_seals_in_priority_order_and_counts_refusals() {
    let _clock = mock_time();
    static ARENA: FrameArena<M, 4096> = FrameArena::new();
    static DOWNLINK: Downlink<'static, M, 1, 8> = Downlink::new(
        &ARENA,
        AC_ID,
        [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())).reserve(TRAILER)],
    );
    let layer = Trailer {
        sealed: AtomicU32::new(0),
    };
    let [mut port] = DOWNLINK.ports().unwrap();
    let device = port.device();
    let attitude = Attitude {
        phi: 1.0,
        psi: 2.0,
        theta: 3.0,
    };
    // Queued before the writer runs: it takes them most important first.
    for priority in [10, 200, 100, 50, 150, 20] {
        device
            .send_with(&attitude, SendOptions::new().priority(priority))
            .unwrap();
    }
    let log = RefCell::new(Vec::new());
    let uart = SimUart {
        byte_us: 10,
        log: &log,
    };
    let done = async {
        while device.stats().queued > 0 {
            Timer::after(Duration::from_millis(1)).await;
        }
    };
    let run = select(run_writer_with(&mut port, uart, &layer), done);
    match run_with_mock_time(run, Duration::from_millis(1), 1000) {
        Either::First(never) => match never {},
        Either::Second(()) => {}
    }
    let written: Vec<Vec<u8>> = log.into_inner().into_iter().map(|(_, _, b)| b).collect();
    // Sealed in the order taken (200, 150, 100, 50, 20, 10): numbers 0, 1, 3, 4 went out,
    // 2 and 5 were refused.
    let trailers: Vec<u8> = written.iter().map(|f| f[f.len() - 3]).collect();
    assert_eq!(trailers, [0, 1, 3, 4]);
    for frame in &written {
        assert_eq!(frame.len(), 8 + 12 + 3, "plain frame + trailer");
        assert_eq!(&frame[frame.len() - 2..], &[0xEE, 0xEE]);
    }
    let stats = device.stats();
    assert_eq!(stats.sent, 4);
    assert_eq!(stats.dropped.refused, 2);
    assert_eq!(stats.bytes_sent, 4 * 23, "sealed lengths counted");
    assert!(stats.is_balanced(), "{stats:?}");
    assert_eq!(
        DOWNLINK.arena_stats().live,
        0,
        "every frame's memory released"
    );
}

/// (message id, payload length) of what the subscriber got.
static GOT: StdMutex<Vec<(u8, usize)>> = StdMutex::new(Vec::new());

fn record(rx: &Received<'_, '_>) {
    GOT.lock()
        .unwrap()
        .push((rx.msg_id(), rx.frame.payload().len()));
}

#[test]
fn the_layered_inbox_delivers_what_the_layer_opens() {
    static ARENA: FrameArena<M, 1024> = FrameArena::new();
    static DOWNLINK: Downlink<'static, M, 1, 8> = Downlink::new(
        &ARENA,
        AC_ID,
        [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))],
    );
    let datalink: Datalink<'_, M, 2> = Datalink::new(AC_ID);
    datalink.subscribe(Filter::All, &record).unwrap();
    let layer = Trailer {
        sealed: AtomicU32::new(0),
    };
    let inbox = Layered::new(&layer, &datalink);
    let [port] = DOWNLINK.ports().unwrap();
    let mut reader =
        pprz_telemetry::reader::Reader::<&[u8], PprzV2>::new(&[], PprzV2::new(), port.device());
    let frame = |id: u8| {
        let mut f = uplink_frame(&pprz_default::messages::datalink::Ping {}, AC_ID);
        f[5] = id;
        let n = f.len();
        let (a, b) = pprz_telemetry::pprz_transports::checksum::pprz(&f[1..n - 2]);
        f[n - 2] = a;
        f[n - 1] = b;
        f
    };
    // PING (8) unchanged, id 20 rewritten to 21, id 99 withheld.
    for id in [8, 20, 99] {
        reader.feed(&frame(id), &inbox);
    }
    inbox.read_error();
    assert_eq!(*GOT.lock().unwrap(), [(8, 0), (21, 0)]);
    let stats = datalink.stats();
    assert_eq!((stats.received, stats.read_errors), (2, 1));
}
