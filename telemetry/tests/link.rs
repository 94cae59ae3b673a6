//! What the reshaped runtime API adds: the one-link facade (`Link`) end to end over a
//! simulated radio, the device ports handed out once, the `Device` handles that route
//! replies back to the device a request came in on, the `Outgoing` frame that counts a
//! failed write when dropped unfinished, and the telemetry mode as a setting of the
//! services (`Settings::add_mode`).
//!
//! Deterministic: futures are polled by hand while embassy-time's mock clock advances.

mod common;

use pprz_telemetry::SendOptions;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::sync::Mutex as StdMutex;
use std::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, Timer};
use pprz_default::messages::Set;
use pprz_default::messages::datalink::{Block, GetSetting, MoveWp, Ping, Setting};
use pprz_default::messages::telemetry::{Attitude, DlValue};
use pprz_default::periodic::{self, main};
use pprz_messages::{Decode, Message, priority};
use pprz_telemetry::pprz_transports::{AnyTransport, Decoder, PprzV1, PprzV2};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::registry::{Filter, Received};
use pprz_telemetry::scheduler::{ModeError, Modes, Scheduler};
use pprz_telemetry::services::Services;
use pprz_telemetry::{
    DeviceConfig, Downlink, DropReason, FrameArena, Link, LinkMutex, PortsTaken, Targets,
};

use common::frames::{PING_7, PONG_7, dl_value_frame, service_requests, uplink_frame, v2_frame};
use common::sim::{ScriptedRx, SimUart, byte_time_us, mock_time, run_with_mock_time};

const AC_ID: u8 = 7;

fn v2() -> DeviceConfig {
    DeviceConfig::new(PprzV2::new().into())
}

/// The ground's frames as bytes on the radio: each frame 50 ms after the previous one,
/// split across two reads.
fn script(frames: &[Vec<u8>]) -> ScriptedRx {
    let mut chunks = VecDeque::new();
    for frame in frames {
        let (a, b) = frame.split_at(3);
        chunks.push_back((Duration::from_millis(50), a.to_vec()));
        chunks.push_back((Duration::from_millis(1), b.to_vec()));
    }
    ScriptedRx { chunks }
}

/// The frames written to a simulated UART, in order.
fn wire(
    log: RefCell<Vec<(embassy_time::Instant, embassy_time::Instant, Vec<u8>)>>,
) -> Vec<Vec<u8>> {
    log.into_inner().into_iter().map(|(_, _, b)| b).collect()
}

static GAIN: AtomicU32 = AtomicU32::new(0);

fn get_gain() -> f32 {
    f32::from_bits(GAIN.load(Ordering::Relaxed))
}

fn set_gain(v: f32) {
    GAIN.store(v.to_bits(), Ordering::Relaxed);
}

fn get_constant() -> f32 {
    42.0
}

fn set_constant(_: f32) {}

/// (block id, device index) of every BLOCK the link's user subscriber got.
static BLOCKS: StdMutex<Vec<(u8, usize)>> = StdMutex::new(Vec::new());

fn on_block(rx: &Received<'_, '_>) {
    let block = rx.decode::<Block>().unwrap();
    BLOCKS
        .lock()
        .unwrap()
        .push((block.block_id, rx.device.index()));
}

#[test]
fn the_link_answers_the_ground_and_feeds_subscribers_over_a_simulated_radio() {
    let _clock = mock_time();
    static ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
    static LINK: Link<'static, Set> = Link::new(&ARENA, AC_ID);
    assert_eq!(LINK.ac_id(), AC_ID);
    assert_eq!(LINK.settings().add("gain", &get_gain, &set_gain), Ok(0));
    assert_eq!(
        LINK.settings()
            .add("constant", &get_constant, &set_constant),
        Ok(1)
    );
    LINK.subscribe(Filter::message::<Block>(), &on_block)
        .unwrap();
    // Telemetry queued before the link runs goes out first.
    let attitude = Attitude {
        phi: 0.1,
        psi: 0.2,
        theta: 0.3,
    };
    LINK.send(&attitude).unwrap();

    let mut requests = service_requests();
    requests.extend([
        uplink_frame(
            &Block {
                block_id: 5,
                ac_id: AC_ID,
            },
            AC_ID,
        ), // for the user's subscriber
        uplink_frame(
            &Block {
                block_id: 6,
                ac_id: 9,
            },
            9,
        ), // addressed to aircraft 9
        uplink_frame(
            &MoveWp {
                wp_id: 1,
                ac_id: AC_ID,
                lat: 1,
                lon: 2,
                alt: 3,
            },
            AC_ID,
        ), // nobody subscribed
    ]);
    let log = RefCell::new(Vec::new());
    let mut tx = SimUart {
        byte_us: byte_time_us(57_600),
        log: &log,
    };
    let run = select(
        LINK.run(&mut tx, script(&requests)),
        Timer::after(Duration::from_millis(600)),
    );
    match run_with_mock_time(run, Duration::from_micros(50), 20_000) {
        Either::First(result) => panic!("the link stopped: {result:?}"),
        Either::Second(()) => {}
    }

    // Byte for byte: the ATTITUDE sent before, then the replies, in request order.
    assert_eq!(
        wire(log),
        [
            v2_frame(&attitude, AC_ID, 0),
            PONG_7.to_vec(),
            dl_value_frame(AC_ID, 0, 1.5),
            dl_value_frame(AC_ID, 1, 42.0),
        ]
    );
    assert_eq!(get_gain(), 1.5);
    assert_eq!(*BLOCKS.lock().unwrap(), [(5, 0)]);

    let stats = LINK.stats();
    let s = stats.services;
    assert_eq!((s.pings, s.settings, s.get_settings), (1, 1, 1));
    assert_eq!(
        (
            s.wrong_ac_id,
            s.unknown_index,
            s.malformed,
            s.replies_dropped
        ),
        (1, 1, 0, 0)
    );
    let up = stats.uplink;
    assert_eq!(
        (up.received, up.not_for_us, up.unhandled, up.read_errors),
        (7, 2, 1, 0)
    );
    assert!(up.last_received.is_some());
    let down = stats.downlink;
    assert_eq!((down.submitted, down.sent, down.queued), (4, 4, 0));
    assert_eq!(down.lost(), 0);
    assert!(down.is_balanced(), "{down:?}");
    assert_eq!(stats.arena.live, 0, "every frame's memory came back");
    assert_eq!(LINK.sender().stats(0), Some(down));

    // The first run was cancelled (its task ended): its port came back, so the link runs
    // again and writes what was queued meanwhile. While it runs, the device has one
    // writer: a second run is refused at once and changes nothing.
    LINK.send(&attitude).unwrap();
    let log2 = RefCell::new(Vec::new());
    let mut again = SimUart {
        byte_us: byte_time_us(57_600),
        log: &log2,
    };
    let mut other = SimUart {
        byte_us: 1,
        log: &RefCell::new(Vec::new()),
    };
    let restarted = select(LINK.run(&mut again, &[][..]), async {
        // Polled after the restarted run, which holds the port by now.
        let refused = LINK.run(&mut other, &[][..]).await;
        Timer::after(Duration::from_millis(100)).await;
        refused
    });
    match run_with_mock_time(restarted, Duration::from_micros(50), 10_000) {
        Either::First(result) => panic!("the restarted link stopped: {result:?}"),
        Either::Second(refused) => assert_eq!(refused.unwrap_err(), PortsTaken),
    }
    assert_eq!(wire(log2), [v2_frame(&attitude, AC_ID, 0)]);
    let down = LINK.stats().downlink;
    assert_eq!((down.submitted, down.sent, down.queued), (5, 5, 0));
    assert!(down.is_balanced(), "{down:?}");
}

#[test]
fn ports_are_handed_out_once() {
    let arena: FrameArena<M, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 2, 4> = Downlink::new(&arena, AC_ID, [v2(), v2()]);
    {
        let ports = downlink.ports().unwrap();
        assert_eq!(
            ports.each_ref().map(|p| p.device().index()),
            [0, 1],
            "in configuration order"
        );
        assert_eq!(downlink.ports().unwrap_err(), PortsTaken);
    } // the ports go out of scope
    assert_eq!(
        downlink.ports().err(),
        Some(PortsTaken),
        "dropping the ports does not hand them out again"
    );
    assert_eq!(
        PortsTaken.to_string(),
        "the downlink's ports were taken already (one writer per device)"
    );
    // Another downlink has its own ports.
    let other: Downlink<'_, M, 1, 4> = Downlink::new(&arena, AC_ID, [v2()]);
    assert!(other.ports().is_ok());
}

#[test]
fn device_handles_and_the_type_erased_sender() {
    let arena: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 2, 8> = Downlink::new(
        &arena,
        AC_ID,
        [v2(), DeviceConfig::new(PprzV1::new(1).into()).flush(true)],
    );
    let [mut p0, mut p1] = downlink.ports().unwrap();
    let (d0, d1) = (p0.device(), p1.device());
    assert_eq!((d0.index(), d1.index()), (0, 1));
    assert_eq!(d0, p0.device());
    assert_ne!(d0, d1);
    let other: Downlink<'_, M, 1, 8> = Downlink::new(&arena, AC_ID, [v2()]);
    let [other0] = other.ports().unwrap();
    assert_ne!(other0.device(), d0, "same index, another downlink");
    assert_eq!(Targets::from(d1), Targets::only(1));
    assert_eq!(d1.config(), *downlink.config(1).unwrap());
    assert!(d1.config().flush && !d0.config().flush);
    assert!(downlink.config(2).is_none());

    let sender = downlink.sender();
    assert_eq!((sender.ac_id(), sender.devices()), (AC_ID, 2));
    let value = |index: u8| DlValue { index, value: 0.5 };
    sender
        .send_with(
            &value(1),
            SendOptions::new()
                .on(Targets::from(d1))
                .priority(priority::LOW),
        )
        .unwrap();
    d0.send(&value(2)).unwrap(); // at DL_VALUE's own priority (high)
    d1.send_with(&value(3), SendOptions::new().priority(priority::NORMAL))
        .unwrap();
    sender.send(&value(4)).unwrap(); // every device, high
    // Nowhere: refused and counted, never accepted silently.
    for nowhere in [Targets::NONE, Targets::only(2), Targets::only(31).with(5)] {
        let err = d0
            .sender()
            .send_with(&value(5), SendOptions::new().on(nowhere).priority(0))
            .unwrap_err();
        assert_eq!((err.device, err.reason), (2, DropReason::NoDevice));
    }
    assert_eq!((sender.undeliverable(), downlink.undeliverable()), (3, 3));
    assert_eq!((d0.stats().queued, d1.stats().queued), (2, 3));
    assert_eq!(sender.stats(1), Some(d1.stats()));
    assert_eq!(sender.stats(2), None);
    assert_eq!(sender.arena_stats().live, 5);

    // Each device's frames in its transport, most important first.
    let mut v1_order = Vec::new();
    while let Some(frame) = p1.try_next() {
        assert_eq!(&frame[..4], &[0x99, 11, AC_ID, DlValue::ID], "PPRZ v1");
        v1_order.push(frame[4]);
        frame.finish(true);
    }
    assert_eq!(v1_order, [4, 3, 1]);
    let mut v2_order = Vec::new();
    while let Some(frame) = p0.try_next() {
        let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
        let mut input = &frame[..];
        let f = decoder.feed(&mut input).unwrap();
        v2_order.push(DlValue::decode(f.payload()).unwrap().index);
        frame.finish(true);
    }
    assert_eq!(v2_order, [2, 4], "FIFO among equal priorities");
    for d in [d0, d1] {
        let s = d.stats();
        assert_eq!(s.queued, 0);
        assert!(s.is_balanced(), "{s:?}");
    }
    assert_eq!(arena.stats().live, 0);
}

static PINGS_SEEN: AtomicU32 = AtomicU32::new(0);

#[test]
fn a_reply_goes_to_the_device_the_request_came_in_on() {
    let _clock = mock_time();
    let arena: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 2, 8> = Downlink::new(&arena, AC_ID, [v2(), v2()]);
    let [mut radio, mut usb] = downlink.ports().unwrap();
    let services: Services<'_, Set, M, 4> = Services::new(AC_ID);
    let get = || 3.0;
    let set = |_: f32| {};
    assert_eq!(services.settings().add("three", &get, &set), Ok(0));
    // A user subscriber answering a BLOCK with DL_VALUE(block id, device index).
    let echo = |rx: &Received<'_, '_>| {
        let block = rx.decode::<Block>().unwrap();
        rx.reply(&DlValue {
            index: block.block_id,
            value: rx.device.index() as f32,
        })
        .unwrap();
    };
    let count_pings = |_: &Received<'_, '_>| {
        PINGS_SEEN.fetch_add(1, Ordering::Relaxed);
    };
    let datalink: Datalink<'_, M, 8> = Datalink::new(AC_ID);
    services.subscribe(datalink.registry()).unwrap();
    datalink
        .subscribe(Filter::message::<Block>(), &echo)
        .unwrap();
    datalink
        .subscribe(Filter::message::<Ping>(), &count_pings)
        .unwrap();
    // One reader per device, each built with its own port's device.
    let mut radio_reader = Reader::<_, _>::new(&[][..], PprzV2::new(), radio.device());
    let mut usb_reader = Reader::<_, _>::new(&[][..], PprzV2::new(), usb.device());
    assert_eq!(radio_reader.device(), radio.device());
    assert_eq!(usb_reader.device(), usb.device());

    // A PING on the USB port: the PONG is queued on the USB port only.
    assert_eq!(usb_reader.feed(&PING_7, &datalink), 1);
    assert!(radio.try_next().is_none(), "nothing for the radio");
    let pong = usb.try_next().expect("the PONG, on the USB port");
    assert_eq!(&pong[..], PONG_7);
    pong.finish(true);
    // And the other way round.
    assert_eq!(radio_reader.feed(&PING_7, &datalink), 1);
    assert!(usb.try_next().is_none(), "nothing for the USB port");
    let pong = radio.try_next().expect("the PONG, on the radio");
    assert_eq!(&pong[..], PONG_7);
    pong.finish(true);
    assert_eq!(
        PINGS_SEEN.load(Ordering::Relaxed),
        2,
        "subscribers see PINGs too"
    );

    // SETTING on the radio, GET_SETTING on the USB port.
    radio_reader.feed(
        &uplink_frame(
            &Setting {
                index: 0,
                ac_id: AC_ID,
                value: 1.0,
            },
            AC_ID,
        ),
        &datalink,
    );
    usb_reader.feed(
        &uplink_frame(
            &GetSetting {
                index: 0,
                ac_id: AC_ID,
            },
            AC_ID,
        ),
        &datalink,
    );
    // A user's reply: BLOCK 4 on the USB port, BLOCK 8 on the radio.
    let block = |block_id| {
        uplink_frame(
            &Block {
                block_id,
                ac_id: AC_ID,
            },
            AC_ID,
        )
    };
    usb_reader.feed(&block(4), &datalink);
    radio_reader.feed(&block(8), &datalink);

    let drain = |port: &mut pprz_telemetry::Port<'_>| {
        let mut frames = Vec::new();
        while let Some(frame) = port.try_next() {
            frames.push(frame.to_vec());
            frame.finish(true);
        }
        frames
    };
    assert_eq!(
        drain(&mut radio),
        [dl_value_frame(AC_ID, 0, 3.0), dl_value_frame(AC_ID, 8, 0.0)]
    );
    assert_eq!(
        drain(&mut usb),
        [dl_value_frame(AC_ID, 0, 3.0), dl_value_frame(AC_ID, 4, 1.0)]
    );
    for port in [&radio, &usb] {
        let s = port.device().stats();
        assert_eq!((s.submitted, s.sent, s.queued), (3, 3, 0));
        assert!(s.is_balanced(), "{s:?}");
    }
    let s = services.stats();
    assert_eq!((s.pings, s.settings, s.get_settings), (2, 1, 1));
}

#[test]
fn an_outgoing_dropped_unfinished_counts_a_failed_write() {
    let arena: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&arena, AC_ID, [v2()]);
    let [mut port] = downlink.ports().unwrap();
    for index in 0..4 {
        downlink.send(&DlValue { index, value: 0.0 }).unwrap();
    }
    assert_eq!(arena.stats().live, 4);
    let high = priority::level(DlValue::PRIORITY);

    // Written.
    let frame = port.try_next().unwrap();
    assert_eq!(
        &frame[..],
        dl_value_frame(AC_ID, 0, 0.0),
        "the frame's bytes"
    );
    let len = frame.len() as u32;
    frame.finish(true);
    let s = downlink.stats(0).unwrap();
    assert_eq!(
        (s.sent, s.bytes_sent, s.dropped.write_error, s.queued),
        (1, len, 0, 3)
    );
    assert!(s.is_balanced(), "{s:?}");

    // Reported failed.
    port.try_next().unwrap().finish(false);
    let s = downlink.stats(0).unwrap();
    assert_eq!((s.sent, s.dropped.write_error, s.queued), (1, 1, 2));
    assert!(s.is_balanced(), "{s:?}");

    // Taken (in flight: still counted as queued), then dropped unfinished, as when a
    // writer is cancelled in the middle of a write.
    let frame = port.try_next().unwrap();
    let s = downlink.stats(0).unwrap();
    assert_eq!((s.queued, s.waiting), (2, 1), "one waiting, one in flight");
    assert!(s.is_balanced(), "{s:?}");
    drop(frame);
    let s = downlink.stats(0).unwrap();
    assert_eq!((s.sent, s.dropped.write_error, s.queued), (1, 2, 1));
    assert_eq!((s.levels[high].sent, s.levels[high].lost), (1, 2));
    assert!(s.is_balanced(), "{s:?}");
    assert_eq!(
        arena.stats().live,
        1,
        "the dropped frame's memory came back"
    );

    port.try_next().unwrap().finish(true);
    let s = downlink.stats(0).unwrap();
    assert_eq!(
        (s.submitted, s.sent, s.dropped.write_error, s.queued),
        (4, 2, 2, 0)
    );
    assert!(s.is_balanced(), "{s:?}");
    assert_eq!(arena.stats().live, 0);
    assert!(port.try_next().is_none());
}

fn send_attitude_on_mode_link() {
    let _ = MODE_LINK.send(&Attitude {
        phi: 0.0,
        psi: 0.0,
        theta: 0.0,
    });
}

static MODE_ARENA: FrameArena<LinkMutex, 4096> = FrameArena::new();
static MODE_LINK: Link<'static, Set> = Link::new(&MODE_ARENA, AC_ID);

#[test]
fn the_ground_switches_the_telemetry_mode_with_a_setting() {
    let _clock = mock_time();
    static MODES: Modes<'static, { periodic::PROCESSES }> = Modes::new(&periodic::SCHEDULE);
    static SCHEDULER: Scheduler<'static, M, { periodic::PROCESSES }, 4> = Scheduler::new(&MODES);
    assert!(
        SCHEDULER
            .register_message::<Attitude>(&send_attitude_on_mode_link)
            .unwrap()
            .is_scheduled()
    );
    assert_eq!(MODES.setting(5).unwrap_err(), ModeError::UnknownProcess);
    let index = MODE_LINK
        .settings()
        .add_mode("telemetry mode", MODES.setting(main::PROCESS).unwrap())
        .unwrap();
    assert_eq!(
        MODE_LINK.settings().get(index),
        Some(main::MODE_DEFAULT as f32)
    );

    // A second in the default mode: ATTITUDE every 0.25 s (ticks 3, 18, 33, 48).
    for _ in 0..60 {
        SCHEDULER.tick();
    }
    assert_eq!(MODE_LINK.stats().downlink.submitted, 4);

    let debug = main::MODE_DEBUG as f32;
    let setting = |value: f32| {
        uplink_frame(
            &Setting {
                index,
                ac_id: AC_ID,
                value,
            },
            AC_ID,
        )
    };
    let requests = [
        setting(debug),
        setting(99.0), // no such mode: refused
        setting(2.5),  // not a mode index (2 is minimal): refused
        setting(-1.0), // not a mode index: refused
        uplink_frame(
            &GetSetting {
                index,
                ac_id: AC_ID,
            },
            AC_ID,
        ),
    ];
    let log = RefCell::new(Vec::new());
    let mut tx = SimUart {
        byte_us: byte_time_us(57_600),
        log: &log,
    };
    let run = select(
        MODE_LINK.run(&mut tx, script(&requests)),
        Timer::after(Duration::from_millis(400)),
    );
    assert!(matches!(
        run_with_mock_time(run, Duration::from_micros(50), 20_000),
        Either::Second(())
    ));
    assert_eq!(MODES.mode(main::PROCESS), Some(main::MODE_DEBUG));

    // The four ATTITUDEs, then every acknowledgement reports the mode in force: debug.
    let wire = wire(log);
    assert_eq!(wire.len(), 4 + 5);
    for frame in &wire[..4] {
        assert_eq!(frame[5], Attitude::ID);
    }
    for frame in &wire[4..] {
        assert_eq!(frame, &dl_value_frame(AC_ID, index, debug));
    }
    let s = MODE_LINK.stats().services;
    assert_eq!((s.settings, s.get_settings, s.unknown_index), (4, 1, 0));

    // The next second runs the debug mode: ATTITUDE every 0.1 s.
    for _ in 0..60 {
        SCHEDULER.tick();
    }
    let down = MODE_LINK.stats().downlink;
    assert_eq!(down.submitted, 4 + 5 + 10);
    assert_eq!(down.queued, 10, "no writer runs any more");
    assert!(down.is_balanced(), "{down:?}");
}

/// `AnyTransport` in a `const` device configuration: a `static` downlink over two
/// transports, its handles `'static`.
#[test]
fn a_static_downlink_hands_out_static_handles() {
    static ARENA: FrameArena<M, 1024> = FrameArena::new();
    static DOWNLINK: Downlink<'static, M, 2, 4> = Downlink::new(
        &ARENA,
        AC_ID,
        [
            DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),
            DeviceConfig::new(AnyTransport::PprzV1(PprzV1::new(1))).depth(1),
        ],
    );
    let [_, mut log] = DOWNLINK.ports().unwrap();
    let device: pprz_telemetry::Device<'static> = log.device();
    let sender: pprz_telemetry::Sender<'static> = DOWNLINK.sender();
    std::thread::spawn(move || {
        device
            .send(&DlValue {
                index: 1,
                value: 0.0,
            })
            .unwrap();
        // Depth 1: an equal priority cannot get in.
        assert!(
            sender
                .send_with(
                    &DlValue {
                        index: 2,
                        value: 0.0
                    },
                    SendOptions::new()
                        .on(Targets::from(device))
                        .priority(DlValue::PRIORITY)
                )
                .is_err()
        );
    })
    .join()
    .unwrap();
    let s = log.device().stats();
    assert_eq!((s.submitted, s.queued, s.dropped.queue_full), (2, 1, 1));
    let frame = log.try_next().unwrap();
    assert_eq!(frame[4], 1);
    frame.finish(true);
}

/// On an XBee radio with a delivery window, the link's reader hands the module's transmit
/// statuses to its writer, and `LinkStats::delivery` counts what they said: a status for
/// the first frame, none for the second (timed out), one for no frame (unexpected).
#[test]
fn link_stats_count_the_radios_transmit_statuses() {
    use pprz_telemetry::DeliveryWindow;
    use pprz_telemetry::pprz_transports::XBee24;
    use pprz_telemetry::pprz_transports::xbee::{self, status};

    let _clock = mock_time();
    static ARENA: FrameArena<LinkMutex, 1024> = FrameArena::new();
    static LINK: Link<'static, Set> = Link::with_device(
        &ARENA,
        AC_ID,
        DeviceConfig::new(AnyTransport::XBee24(XBee24::new()))
            .delivery(Some(DeliveryWindow::new(1, 200))),
    );
    let attitude = Attitude {
        phi: 0.1,
        psi: 0.2,
        theta: 0.3,
    };
    LINK.send(&attitude).unwrap();
    LINK.send(&attitude).unwrap();
    let status_frame = |id| {
        let mut out = [0u8; xbee::TX_STATUS_FRAME_LEN];
        let n = xbee::encode_tx_status_24(id, status::SUCCESS, &mut out).unwrap();
        out[..n].to_vec()
    };
    let rx = ScriptedRx {
        chunks: VecDeque::from([
            (Duration::from_millis(50), status_frame(1)),
            (Duration::from_millis(50), status_frame(99)),
        ]),
    };
    let log = RefCell::new(Vec::new());
    let mut tx = SimUart {
        byte_us: byte_time_us(57_600),
        log: &log,
    };
    let run = select(
        LINK.run(&mut tx, rx),
        Timer::after(Duration::from_millis(600)),
    );
    match run_with_mock_time(run, Duration::from_micros(50), 20_000) {
        Either::First(result) => panic!("the link stopped: {result:?}"),
        Either::Second(()) => {}
    }
    let frames = wire(log);
    assert_eq!(frames.len(), 2);
    // Fresh frame ids 1 and 2, set by the writer.
    assert_eq!((frames[0][4], frames[1][4]), (1, 2));
    let d = LINK.stats().delivery;
    assert_eq!(
        (d.delivered, d.failed, d.timeouts, d.unexpected),
        (1, 0, 1, 1)
    );
}
