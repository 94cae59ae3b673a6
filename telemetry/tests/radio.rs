//! Radios that do not push back, under mock time (deterministic): the writer's
//! transmit-status window on an XBee API device (frame ids set at write time, at most
//! `in_modem` frames awaiting their status, timeouts, unexpected statuses), and pacing
//! by a modelled modem occupancy.

mod common;

use std::cell::RefCell;

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, Instant, Timer};
use pprz_default::messages::telemetry::{Attitude, Payload};
use pprz_messages::{Message, VarArray};
use pprz_telemetry::delivery::{DeliveryStats, DeliveryWindow};
use pprz_telemetry::pprz_transports::xbee::{self, encode_tx_status_24};
use pprz_telemetry::pprz_transports::{AnyTransport, Decoder, PprzV2, XBee24};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Pacing, run_writer};

use common::sim::{SimUart, byte_time_us, mock_time, run_with_mock_time};

const AC_ID: u8 = 7;

fn status_frame(frame_id: u8, status: u8) -> Vec<u8> {
    let mut buf = [0u8; 16];
    let n = encode_tx_status_24(frame_id, status, &mut buf).unwrap();
    buf[..n].to_vec()
}

#[test]
fn xbee_frames_wait_for_their_transmit_status() {
    let _clock = mock_time();
    let arena: FrameArena<M, 2048> = FrameArena::new();
    let transport = AnyTransport::XBee24(XBee24::default());
    let downlink: Downlink<'_, M, 1, 16> = Downlink::new(
        &arena,
        AC_ID,
        [DeviceConfig::new(transport).delivery(Some(DeliveryWindow::new(1, 100)))],
    );
    let [mut port] = downlink.ports().unwrap();
    let device = port.device();
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID);
    let mut reader = Reader::<_, _>::new(&[][..], XBee24::default(), device);
    let log = RefCell::new(Vec::new());
    let attitude = Attitude {
        phi: 0.1,
        psi: 0.2,
        theta: 0.3,
    };
    let written = || log.borrow().len();
    let frame_ids = || -> Vec<u8> {
        log.borrow()
            .iter()
            .map(|(_, _, f): &(Instant, Instant, Vec<u8>)| {
                let id = transport.frame_id(f).unwrap();
                // Every frame still decodes after its id was set (checksum rewritten).
                let mut decoder: Decoder<XBee24> = Decoder::new(XBee24::default());
                let mut input = &f[..];
                assert!(decoder.feed(&mut input).is_some(), "valid frame {f:02X?}");
                id
            })
            .collect()
    };

    let script = async {
        for _ in 0..4 {
            downlink.send(&attitude).unwrap();
        }
        Timer::after(Duration::from_millis(20)).await;
        assert_eq!(written(), 1, "one frame in the modem, the others wait");
        assert_eq!(downlink.stats(0).unwrap().waiting, 3);
        reader.feed(&status_frame(1, xbee::status::SUCCESS), &datalink);
        Timer::after(Duration::from_millis(20)).await;
        assert_eq!(written(), 2);
        // A failure frees the place too, and is counted.
        reader.feed(&status_frame(2, xbee::status::NO_ACK), &datalink);
        Timer::after(Duration::from_millis(20)).await;
        assert_eq!(written(), 3);
        // Unknown, repeated and corrupted statuses change nothing.
        let mut corrupt = status_frame(3, 0);
        *corrupt.last_mut().unwrap() ^= 0xFF;
        for bad in [status_frame(99, 0), status_frame(2, 0), corrupt] {
            reader.feed(&bad, &datalink);
        }
        Timer::after(Duration::from_millis(20)).await;
        assert_eq!(written(), 3, "frame 3 still awaits its status");
        // No status for frame 3: its place is freed after 100 ms.
        Timer::after(Duration::from_millis(100)).await;
        assert_eq!(written(), 4);
        reader.feed(&status_frame(4, 0), &datalink);
        Timer::after(Duration::from_millis(10)).await;
    };
    let writer = async {
        let mut uart = SimUart {
            byte_us: byte_time_us(57_600),
            log: &log,
        };
        run_writer(&mut port, &mut uart).await
    };
    let done = run_with_mock_time(select(script, writer), Duration::from_micros(100), 100_000);
    assert!(matches!(done, Either::First(())));
    assert_eq!(frame_ids(), [1, 2, 3, 4]);
    assert_eq!(
        device.delivery_stats(),
        DeliveryStats {
            delivered: 2,
            failed: 1,
            timeouts: 1,
            unexpected: 2,
        }
    );
    assert_eq!(reader.decoder_stats().checksum_errors, 1);
    assert_eq!(datalink.stats().received, 0, "statuses are not messages");
    let stats = downlink.stats(0).unwrap();
    assert_eq!((stats.sent, stats.queued), (4, 0));
    assert!(stats.is_balanced());
}

/// A 4000 B/s radio behind an instant UART (no flow control, a 2048-byte FIFO that
/// drops what overflows): unpaced, the writer fills the modem and a DL_VALUE waits
/// behind the whole FIFO; paced with a 300-byte budget, the modem never holds more than
/// the budget, so nothing overflows and the acknowledgement waits about two frame times.
#[test]
fn pacing_keeps_the_backlog_in_our_queue() {
    use pprz_default::messages::telemetry::DlValue;
    const AIR_RATE: u64 = 4000;
    const FIFO: u64 = 2048;
    struct Modem<'a> {
        /// Time (µs) at which the FIFO will be empty, bytes dropped, most ever held.
        state: &'a RefCell<(u64, u64, u64)>,
        /// The air end time (µs) of each frame's last byte, and its bytes.
        air: &'a RefCell<Vec<(u64, Vec<u8>)>>,
    }
    impl embedded_io_async::ErrorType for Modem<'_> {
        type Error = core::convert::Infallible;
    }
    impl embedded_io_async::Write for Modem<'_> {
        async fn write(&mut self, buf: &[u8]) -> Result<usize, Self::Error> {
            let now = Instant::now().as_micros();
            let mut s = self.state.borrow_mut();
            let held = s.0.saturating_sub(now) * AIR_RATE / 1_000_000;
            let fits = (FIFO - held).min(buf.len() as u64);
            s.1 += buf.len() as u64 - fits;
            s.0 = s.0.max(now) + fits * 1_000_000 / AIR_RATE;
            s.2 = s.2.max(held + fits);
            if fits == buf.len() as u64 {
                self.air.borrow_mut().push((s.0, buf.to_vec()));
            }
            Ok(buf.len())
        }
        async fn flush(&mut self) -> Result<(), Self::Error> {
            Ok(())
        }
    }

    let run = |pacing: Option<Pacing>| {
        let _clock = mock_time();
        let arena: FrameArena<M, 8192> = FrameArena::new();
        let downlink: Downlink<'_, M, 1, 32> = Downlink::new(
            &arena,
            AC_ID,
            [DeviceConfig::new(PprzV2::new().into()).pacing(pacing)],
        );
        let [mut port] = downlink.ports().unwrap();
        let state = RefCell::new((0, 0, 0));
        let air = RefCell::new(Vec::new());
        let bytes = [0x5Au8; 120];
        let ack_sent = RefCell::new(0u64);
        let load = async {
            // 10x the air rate of low-priority payload for 2 s, a DL_VALUE at 1.5 s.
            for ms in 0..2000u64 {
                for _ in 0..3 {
                    let _ = downlink.send(&Payload {
                        values: VarArray::new(&bytes),
                    });
                }
                if ms == 1500 {
                    *ack_sent.borrow_mut() = Instant::now().as_micros();
                    downlink
                        .send(&DlValue {
                            index: 1,
                            value: 2.0,
                        })
                        .unwrap();
                }
                Timer::after(Duration::from_millis(1)).await;
            }
            Timer::after(Duration::from_millis(1500)).await;
        };
        let writer = async {
            let mut modem = Modem {
                state: &state,
                air: &air,
            };
            run_writer(&mut port, &mut modem).await
        };
        let done = run_with_mock_time(select(load, writer), Duration::from_micros(250), 20_000);
        assert!(matches!(done, Either::First(())));
        let ack_on_air = air
            .borrow()
            .iter()
            .find(|(_, f)| f[5] == DlValue::ID)
            .map(|(end, _)| end - *ack_sent.borrow());
        let (_, dropped, most_held) = *state.borrow();
        (dropped, most_held, ack_on_air, air.borrow().len())
    };

    let (dropped, most_held, ack, delivered) = run(None);
    assert!(dropped > 10_000, "unpaced, the FIFO overflows: {dropped} B");
    assert!(
        ack.is_none_or(|us| us > 300_000),
        "the ack waits behind the FIFO: {ack:?}"
    );
    println!(
        "unpaced: {dropped} B dropped, most held {most_held} B, ack {ack:?} µs, {delivered} frames"
    );

    let (dropped, most_held, ack, delivered) = run(Some(Pacing::new(AIR_RATE as u32, 300)));
    assert_eq!(dropped, 0, "paced, the modem never overflows");
    assert!(most_held <= 300, "{most_held} B held");
    // The frame on the air and its own: two 129-byte frame times at 4000 B/s (65 ms).
    let ack = ack.expect("the acknowledgement is delivered");
    assert!(
        ack <= 2 * 129 * 1_000_000 / AIR_RATE + 1_000,
        "ack after {ack} µs"
    );
    // The air stayed busy: 2 s of backlog at 4000 B/s is about 62 frames of 129 bytes.
    assert!(delivered >= 60, "{delivered} frames delivered");
    println!("paced: most held {most_held} B, ack after {ack} µs, {delivered} frames");
}
