//! A host test as a user writes one: the aircraft's `Link` runs on the Embassy std
//! executor over a loopback TCP connection (a `pprz-devices` host adapter), and the test
//! thread plays the ground. It encodes a PING with the PPRZ v2 encoder, sends it, and
//! reads the answer back through the incremental decoder until the PONG comes.
//!
//! The mock clock is advanced by a task of its own. The test thread only waits for the
//! answer; a read timeout guards against a hang (it is not a timing assertion).

use std::io::{Read as _, Write as _};
use std::net::{TcpListener, TcpStream};
use std::time::Duration as StdDuration;

use embassy_executor::Executor;
use embassy_futures::yield_now;
use embassy_time::{Duration, MockDriver};
use pprz_default::messages::Set;
use pprz_default::messages::datalink::Ping;
use pprz_default::messages::telemetry::Pong;
use pprz_devices::host::{HostConfig, HostDevice, HostRx, HostTx};
use pprz_messages::Message;
use pprz_telemetry::pprz_transports::{Decoder, Encoder, MsgHeader, PprzV2, TxMeta};
use pprz_telemetry::{FrameArena, Link, LinkMutex};
use static_cell::StaticCell;

/// The aircraft's id; the ground is 0.
const AC_ID: u8 = 7;

static ARENA: FrameArena<LinkMutex, 2048> = FrameArena::new();
static LINK: Link<'static, Set> = Link::new(&ARENA, AC_ID);
static EXECUTOR: StaticCell<Executor> = StaticCell::new();

/// Advances embassy-time's mock clock, so timers in the stack fire.
#[embassy_executor::task]
async fn clock() {
    loop {
        MockDriver::get().advance(Duration::from_micros(100));
        yield_now().await;
    }
}

/// The aircraft: writer, reader and services on one device.
#[embassy_executor::task]
async fn radio(tx: HostTx, rx: HostRx) {
    let Err(e) = LINK.run(tx, rx).await;
    panic!("{e}");
}

/// A PPRZ v2 frame from the ground (id 0) to the aircraft.
fn uplink<M: Message>(msg: &M) -> Vec<u8> {
    let mut fields = [0u8; 64];
    let n = msg.encode(&mut fields).unwrap();
    let meta = TxMeta::new(MsgHeader::new(0, AC_ID, M::CLASS_ID, M::ID));
    let mut frame = [0u8; 80];
    let len = PprzV2::new()
        .encode(&meta, &fields[..n], &mut frame)
        .unwrap();
    frame[..len].to_vec()
}

/// Reads the stream until a frame of message `M` arrives; returns its source and
/// destination.
fn wait_for<M: Message>(ground: &mut TcpStream) -> (u8, Option<u8>) {
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut buf = [0u8; 64];
    loop {
        let n = ground.read(&mut buf).expect("the aircraft's bytes");
        assert!(n > 0, "the aircraft closed the link");
        // `feed` takes what it needs from `input` and keeps a partial frame for the
        // next read: call it until it returns None, then read again.
        let mut input = &buf[..n];
        while let Some(frame) = decoder.feed(&mut input) {
            if (frame.class(), frame.msg_id()) == (M::CLASS_ID, M::ID) {
                return (frame.source(), frame.destination());
            }
        }
    }
}

#[test]
fn the_aircraft_answers_a_ping_over_loopback_tcp() {
    let listener = TcpListener::bind("127.0.0.1:0").unwrap();
    let device = HostDevice::tcp_connect(listener.local_addr().unwrap(), HostConfig::default())
        .expect("loopback TCP");
    let (mut ground, _) = listener.accept().unwrap();
    ground
        .set_read_timeout(Some(StdDuration::from_secs(60)))
        .unwrap();

    let (rx, tx) = device.split();
    // The executor never returns: it runs on a thread that the test leaves behind.
    std::thread::spawn(move || {
        let executor = EXECUTOR.init(Executor::new());
        executor.run(|spawner| {
            spawner.spawn(clock().unwrap());
            spawner.spawn(radio(tx, rx).unwrap());
        })
    });

    ground.write_all(&uplink(&Ping)).unwrap();
    let (source, destination) = wait_for::<Pong>(&mut ground);
    assert_eq!(
        (source, destination),
        (AC_ID, Some(0)),
        "PONG from 7 to the ground"
    );
    let stats = LINK.stats();
    assert_eq!(stats.uplink.received, 1, "{stats:?}");
    assert_eq!(stats.services.pings, 1, "{stats:?}");
}

/// docs/host-tests.md shows this file from its first `static` to the end of the test
/// above: the page and the test must not drift apart.
#[test]
fn the_host_tests_page_shows_this_test() {
    let page = include_str!("../../../docs/host-tests.md");
    let this = include_str!("host_ping.rs");
    let from = this.find("static ARENA").unwrap();
    let to = this.find("\n/// docs/host-tests.md shows").unwrap();
    let shown = this[from..to].trim_end();
    assert!(
        page.contains(&format!("```rust,ignore\n{shown}\n```")),
        "docs/host-tests.md must show examples/std/tests/host_ping.rs as it is"
    );
}
