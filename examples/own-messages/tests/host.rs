//! The firmware of this example on the Embassy std executor (mock clock advanced by a
//! task of its own): the ground's PING, SETTING, GET_SETTING and LIGHTS go in as PPRZ v2
//! bytes, and the answers come back as this set's own generated PONG and DL_VALUE.
//!
//! The test thread only waits for the answers (with a generous guard against a hang, not
//! a timing assertion).

use std::convert::Infallible;
use std::sync::Mutex as StdMutex;
use std::sync::atomic::Ordering;
use std::time::{Duration as StdDuration, Instant as StdInstant};

use embassy_executor::Executor;
use embassy_futures::yield_now;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use embassy_sync::pipe::Pipe;
use embassy_time::{Duration, MockDriver};
use pprz_example_own_messages::messages::datalink::{GetSetting, Lights, Ping, Setting, values};
use pprz_example_own_messages::messages::telemetry::{DlValue, Pong, WindEstimate};
use pprz_example_own_messages::{AC_ID, LIGHTS, LINK, setup};
use pprz_messages::{Decode, Message};
use pprz_transports::{Decoder, Encoder, MsgHeader, PprzV2, TxMeta};

/// Bytes from the ground to the aircraft.
static UPLINK: Pipe<CriticalSectionRawMutex, 512> = Pipe::new();
/// Bytes the aircraft wrote.
static DOWNLINK: StdMutex<Vec<u8>> = StdMutex::new(Vec::new());

/// The radio's transmit side: takes every write at once.
struct Radio;

impl embedded_io_async::ErrorType for Radio {
    type Error = Infallible;
}

impl embedded_io_async::Write for Radio {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        DOWNLINK.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

#[embassy_executor::task]
async fn clock() {
    loop {
        MockDriver::get().advance(Duration::from_micros(100));
        yield_now().await;
    }
}

#[embassy_executor::task]
async fn radio() {
    let Err(e) = LINK.run(Radio, &UPLINK).await;
    panic!("{e}");
}

/// A PPRZ v2 frame from the ground (id 0) to our aircraft.
fn uplink<M: Message>(msg: &M) -> Vec<u8> {
    let mut fields = [0u8; 64];
    let n = msg.encode(&mut fields).unwrap();
    let mut frame = [0u8; 80];
    let meta = TxMeta::new(MsgHeader::new(0, AC_ID, M::CLASS_ID, M::ID));
    let len = PprzV2::new()
        .encode(&meta, &fields[..n], &mut frame)
        .unwrap();
    frame[..len].to_vec()
}

/// Sends `bytes` to the aircraft and waits until it has written `frames` frames in all;
/// returns them as (class, id, payload).
fn exchange(bytes: &[u8], frames: usize) -> Vec<(u8, u8, Vec<u8>)> {
    let mut rest = bytes;
    while !rest.is_empty() {
        let n = UPLINK.try_write(rest).unwrap_or(0);
        rest = &rest[n..];
    }
    let start = StdInstant::now();
    loop {
        let decoded = decode_all();
        if decoded.len() >= frames {
            return decoded;
        }
        assert!(
            start.elapsed() < StdDuration::from_secs(60),
            "no answer: {decoded:?}"
        );
        std::thread::sleep(StdDuration::from_millis(1));
    }
}

fn decode_all() -> Vec<(u8, u8, Vec<u8>)> {
    let bytes = DOWNLINK.lock().unwrap().clone();
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut input = &bytes[..];
    let mut out = Vec::new();
    while let Some(frame) = decoder.feed(&mut input) {
        assert_eq!(frame.source(), AC_ID);
        out.push((frame.class(), frame.msg_id(), frame.payload().to_vec()));
    }
    out
}

fn decode<'p, M: Decode<'p>>(frame: &'p (u8, u8, Vec<u8>)) -> M {
    assert_eq!(
        (frame.0, frame.1),
        (M::CLASS_ID, M::ID),
        "not a {}",
        M::NAME
    );
    M::decode(&frame.2).unwrap()
}

#[test]
fn own_message_set_answers_the_ground() {
    setup().unwrap();
    std::thread::spawn(|| {
        let executor: &'static mut Executor = Box::leak(Box::new(Executor::new()));
        executor.run(|spawner| {
            spawner.spawn(clock().unwrap());
            spawner.spawn(radio().unwrap());
        })
    });

    // PING -> this set's PONG.
    let frames = exchange(&uplink(&Ping), 1);
    let _: Pong = decode(&frames[0]);

    // SETTING(0, 2.5) -> DL_VALUE(0, 2.5); out of range -> clamped, reported.
    let frames = exchange(
        &uplink(&Setting {
            index: 0,
            ac_id: AC_ID,
            value: 2.5,
        }),
        2,
    );
    assert_eq!(
        decode::<DlValue>(&frames[1]),
        DlValue {
            index: 0,
            value: 2.5
        }
    );
    let frames = exchange(
        &uplink(&Setting {
            index: 0,
            ac_id: AC_ID,
            value: 9.0,
        }),
        3,
    );
    assert_eq!(
        decode::<DlValue>(&frames[2]),
        DlValue {
            index: 0,
            value: 5.0
        }
    );
    // A careless or hostile value: NaN is refused, the acknowledgement says what holds.
    let nan = Setting {
        index: 0,
        ac_id: AC_ID,
        value: f32::NAN,
    };
    let frames = exchange(&uplink(&nan), 4);
    assert_eq!(
        decode::<DlValue>(&frames[3]),
        DlValue {
            index: 0,
            value: 5.0
        }
    );

    // GET_SETTING -> DL_VALUE; an unknown index and another aircraft get no answer.
    let ignored = [
        uplink(&GetSetting {
            index: 7,
            ac_id: AC_ID,
        }),
        uplink(&Setting {
            index: 0,
            ac_id: AC_ID + 1,
            value: 1.0,
        }),
        uplink(&GetSetting {
            index: 0,
            ac_id: AC_ID,
        }),
    ]
    .concat();
    let frames = exchange(&ignored, 5);
    assert_eq!(
        decode::<DlValue>(&frames[4]),
        DlValue {
            index: 0,
            value: 5.0
        }
    );

    // The firmware's own datalink message reaches its subscriber.
    let lights = Lights {
        ac_id: AC_ID,
        mode: values::LightsMode::Strobe.raw(),
    };
    let ping = uplink(&Ping);
    let frames = exchange(&[uplink(&lights), ping].concat(), 6);
    let _: Pong = decode(&frames[5]);
    assert_eq!(LIGHTS.load(Ordering::Relaxed), 2);

    // Its own telemetry goes out through the same link.
    LINK.send(&WindEstimate {
        east: 1.5,
        north: 0.5,
        confidence: 90,
    })
    .unwrap();
    let frames = exchange(&[], 7);
    assert_eq!(
        decode::<WindEstimate>(&frames[6]),
        WindEstimate {
            east: 1.5,
            north: 0.5,
            confidence: 90
        }
    );

    let stats = LINK.stats();
    assert_eq!((stats.services.pings, stats.services.settings), (2, 2));
    assert_eq!(stats.services.non_finite, 1, "the NaN SETTING");
    assert_eq!(stats.services.get_settings, 1);
    assert_eq!(
        (stats.services.unknown_index, stats.services.wrong_ac_id),
        (1, 1)
    );
    assert_eq!(stats.uplink.received, 9);
    assert_eq!(stats.uplink.unhandled, 0);
    assert_eq!(stats.downlink.sent, 7);
    assert!(stats.downlink.is_balanced(), "{:?}", stats.downlink);
}
