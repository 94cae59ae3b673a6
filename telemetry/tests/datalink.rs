//! The uplink: readers, destination filtering, the subscriber registry, the PING /
//! SETTING / GET_SETTING services with their replies byte for byte over a simulated
//! link, and the DATALINK_REPORT.
//!
//! Every reader is built with the `Device` handle of a downlink device (from that
//! device's port): the device its messages came in on, where replies go.

mod common;

use std::cell::RefCell;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::join::join;
use embassy_futures::select::select;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Instant, Timer};
use pprz_default::messages::Set;
use pprz_default::messages::datalink::{Block, MoveWp, Ping, Setting};
use pprz_default::messages::telemetry::{DatalinkReport, DlValue, Pong};
use pprz_messages::Message;
use pprz_messages::roles::LinkReport;
use pprz_telemetry::pprz_transports::{AnyTransport, Encoder, MsgHeader, PprzV1, PprzV2, TxMeta};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::registry::{ChannelSubscriber, Filter, OwnedMessage, Received};
use pprz_telemetry::services::{LinkReporter, Services};
use pprz_telemetry::stats::DeviceStats;
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, run_writer};

use common::frames::{PING_7, PONG_7, dl_value_frame, service_requests, uplink_frame};
use common::sim::{ScriptedRx, SimUart, byte_time_us, mock_time, run_with_mock_time};

const AC_ID: u8 = 7;

/// One PPRZ v2 device, for the readers' `Device` handles and the replies.
fn v2() -> DeviceConfig {
    DeviceConfig::new(PprzV2::new().into())
}

static SETTING_0: AtomicU32 = AtomicU32::new(0);

#[test]
fn ping_and_settings_round_trip_byte_for_byte() {
    let _clock = mock_time();
    static ARENA: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 16> = Downlink::new(&ARENA, AC_ID, [v2()]);
    let [mut port] = downlink.ports().unwrap();
    let get = || f32::from_bits(SETTING_0.load(Ordering::Relaxed));
    let set = |v: f32| SETTING_0.store(v.to_bits(), Ordering::Relaxed);
    let get_k = || 42.0;
    let set_k = |_v: f32| {};
    let services: Services<'_, Set, M, 4> = Services::new(AC_ID);
    assert_eq!(services.settings().add("gain", &get, &set), Ok(0));
    assert_eq!(services.settings().add("constant", &get_k, &set_k), Ok(1));
    assert_eq!(services.settings().len(), 2);
    let datalink: Datalink<'_, M, 8> = Datalink::new(AC_ID);
    services.subscribe(datalink.registry()).unwrap();
    assert_eq!(
        datalink.registry().len(),
        Services::<Set, M, 4>::SUBSCRIPTIONS
    );

    // The ground's requests, as bytes on the radio, split across reads.
    let ping = PING_7;
    assert_eq!(uplink_frame(&Ping, AC_ID), ping, "hand-computed PING frame");
    let requests = service_requests();
    assert_eq!(requests[0], ping);
    let mut chunks = VecDeque::new();
    for frame in &requests {
        let (a, b) = frame.split_at(3);
        chunks.push_back((Duration::from_millis(50), a.to_vec()));
        chunks.push_back((Duration::from_millis(1), b.to_vec()));
    }
    let log = RefCell::new(Vec::new());
    let mut reader = Reader::<_, _>::new(ScriptedRx { chunks }, PprzV2::new(), port.device());
    let mut tx = SimUart {
        byte_us: byte_time_us(57_600),
        log: &log,
    };
    let run = select(
        join(reader.run(&datalink), run_writer(&mut port, &mut tx)),
        Timer::after(Duration::from_millis(500)),
    );
    run_with_mock_time(run, Duration::from_micros(50), 20_000);

    let replies: Vec<Vec<u8>> = log.into_inner().into_iter().map(|(_, _, b)| b).collect();
    assert_eq!(
        replies,
        [
            PONG_7.to_vec(),
            dl_value_frame(AC_ID, 0, 1.5),
            dl_value_frame(AC_ID, 1, 42.0)
        ]
    );
    assert_eq!(f32::from_bits(SETTING_0.load(Ordering::Relaxed)), 1.5);

    let s = services.stats();
    assert_eq!((s.pings, s.settings, s.get_settings), (1, 1, 1));
    assert_eq!((s.wrong_ac_id, s.unknown_index, s.malformed), (1, 1, 0));
    let up = datalink.stats();
    assert_eq!((up.received, up.not_for_us, up.unhandled), (5, 1, 0));
    assert!(up.last_received.is_some());
    assert_eq!(reader.decoder_stats().frames, 6);
    // DL_VALUE goes out at high priority, PONG too (replies go at the reply message's
    // priority, high for both in the default set).
    assert_eq!(DlValue::PRIORITY, pprz_messages::priority::HIGH);
    assert_eq!(Pong::PRIORITY, pprz_messages::priority::HIGH);
    let down = downlink.stats(0).unwrap();
    assert_eq!((down.submitted, down.sent, down.queued), (3, 3, 0));
    let high = down.levels[pprz_messages::priority::level(pprz_messages::priority::HIGH)];
    assert_eq!(
        (high.submitted, high.sent),
        (3, 3),
        "replies at high priority"
    );
    assert!(down.is_balanced(), "{down:?}");
}

#[test]
fn registry_calls_every_matching_subscriber_and_reports_full() {
    let _clock = mock_time();
    static PER_MESSAGE: AtomicU32 = AtomicU32::new(0);
    static ALSO: AtomicU32 = AtomicU32::new(0);
    static CLASS: AtomicU32 = AtomicU32::new(0);
    static ALL: AtomicU32 = AtomicU32::new(0);
    let arena: FrameArena<M, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 4, 4> = Downlink::new(&arena, AC_ID, [v2(), v2(), v2(), v2()]);
    let [_, _, _, port3] = downlink.ports().unwrap();
    let link3 = port3.device();
    let on_block = |rx: &Received<'_, '_>| {
        let block = rx.decode::<Block>().unwrap();
        PER_MESSAGE.fetch_add(u32::from(block.block_id), Ordering::Relaxed);
    };
    let also = |_: &Received<'_, '_>| {
        ALSO.fetch_add(1, Ordering::Relaxed);
    };
    let class = |rx: &Received<'_, '_>| {
        assert_eq!(rx.class_id(), 2);
        CLASS.fetch_add(1, Ordering::Relaxed);
    };
    let all = |rx: &Received<'_, '_>| {
        assert_eq!(rx.device.index(), 3);
        assert_eq!(rx.device, link3, "the reader's device");
        ALL.fetch_add(1, Ordering::Relaxed);
    };
    let datalink: Datalink<'_, M, 4> = Datalink::new(AC_ID);
    datalink
        .subscribe(Filter::message::<Block>(), &on_block)
        .unwrap();
    datalink
        .subscribe(Filter::message::<Block>(), &also)
        .unwrap();
    datalink
        .registry()
        .subscribe(Filter::Class(2), &class)
        .unwrap();
    datalink.subscribe(Filter::All, &all).unwrap();
    assert_eq!(
        datalink.subscribe(Filter::All, &all).unwrap_err().capacity,
        4
    );
    assert_eq!(datalink.registry().len(), 4);
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), link3);
    let mut bytes = uplink_frame(
        &Block {
            block_id: 5,
            ac_id: AC_ID,
        },
        AC_ID,
    );
    bytes.extend(uplink_frame(
        &MoveWp {
            wp_id: 1,
            ac_id: AC_ID,
            lat: 1,
            lon: 2,
            alt: 3,
        },
        AC_ID,
    ));
    assert_eq!(reader.feed(&bytes, &datalink), 2);
    assert_eq!(PER_MESSAGE.load(Ordering::Relaxed), 5);
    assert_eq!(ALSO.load(Ordering::Relaxed), 1);
    assert_eq!(CLASS.load(Ordering::Relaxed), 2);
    assert_eq!(ALL.load(Ordering::Relaxed), 2);
}

#[test]
fn slow_async_subscriber_drops_are_counted() {
    let _clock = mock_time();
    static ARENA: FrameArena<M, 1024> = FrameArena::new();
    static DOWNLINK: Downlink<'static, M, 1, 4> = Downlink::new(
        &ARENA,
        AC_ID,
        [DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))],
    );
    static INBOX: Channel<M, OwnedMessage<'static>, 2> = Channel::new();
    static NAV: ChannelSubscriber<'static, M, 2> = ChannelSubscriber::new(&INBOX);
    let [mut port] = DOWNLINK.ports().unwrap();
    let datalink: Datalink<'static, M, 2> = Datalink::new(AC_ID);
    datalink
        .subscribe(Filter::message::<MoveWp>(), &NAV)
        .unwrap();
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), port.device());
    for wp_id in 0..5 {
        let frame = uplink_frame(
            &MoveWp {
                wp_id,
                ac_id: AC_ID,
                lat: 10,
                lon: 20,
                alt: 30,
            },
            AC_ID,
        );
        reader.feed(&frame, &datalink);
    }
    assert_eq!(NAV.dropped(), 3, "the channel holds 2, the task never ran");
    let first = INBOX.try_receive().unwrap();
    assert_eq!(first.decode::<MoveWp>().unwrap().wp_id, 0);
    assert_eq!(first.device.index(), 0);
    assert_eq!(first.device, port.device());
    assert_eq!(first.source, 0);
    assert_eq!(first.destination, Some(AC_ID));
    // The task answers later, on the device the message came in on.
    first.reply(&Pong).unwrap();
    let frame = port.try_next().expect("the reply is queued on device 0");
    assert_eq!(&frame[..], PONG_7);
    frame.finish(true);
}

#[test]
fn v1_frames_have_no_destination_and_are_accepted() {
    let _clock = mock_time();
    static SEEN: AtomicU32 = AtomicU32::new(0);
    let arena: FrameArena<M, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 4> =
        Downlink::new(&arena, AC_ID, [DeviceConfig::new(PprzV1::new(1).into())]);
    let [port] = downlink.ports().unwrap();
    let seen = |rx: &Received<'_, '_>| {
        assert_eq!(rx.frame.destination(), None);
        SEEN.fetch_add(1, Ordering::Relaxed);
    };
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID);
    datalink.subscribe(Filter::All, &seen).unwrap();
    let mut reader = Reader::<_, _>::new(&[][..], PprzV1::new(2), port.device());
    let mut out = [0u8; 16];
    let len = PprzV1::new(2)
        .encode(
            &TxMeta::new(MsgHeader::new(0, 0, 2, Ping::ID)),
            &[],
            &mut out,
        )
        .unwrap();
    reader.feed(&out[..len], &datalink);
    assert_eq!(SEEN.load(Ordering::Relaxed), 1);
    assert_eq!(datalink.stats().received, 1);
}

#[test]
fn datalink_report_from_uplink_and_downlink_counters() {
    let _clock = mock_time();
    let arena: FrameArena<M, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 4> = Downlink::new(&arena, AC_ID, [v2()]);
    let [port] = downlink.ports().unwrap();
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID);
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), port.device());
    let mut reporter = LinkReporter::new();
    let t0 = Instant::now();
    let first = reporter.report(t0, &datalink.stats(), &DeviceStats::default());
    assert_eq!(first.uplink_lost_time, u16::MAX, "nothing received yet");
    assert_eq!((first.uplink_rate, first.downlink_rate), (0, 0));

    for _ in 0..10 {
        reader.feed(&uplink_frame(&Ping, AC_ID), &datalink);
    }
    embassy_time::MockDriver::get().advance(Duration::from_secs(5));
    let down = DeviceStats {
        submitted: 100,
        sent: 100,
        bytes_sent: 2_500,
        ..Default::default()
    };
    let report = reporter.report(Instant::now(), &datalink.stats(), &down);
    assert_eq!(report.uplink_lost_time, 5);
    assert_eq!(report.uplink_nb_msgs, 10);
    assert_eq!(report.uplink_rate, 2, "10 messages in 5 s");
    assert_eq!(report.downlink_nb_msgs, 100);
    assert_eq!(report.downlink_rate, 500, "2500 bytes in 5 s");
    assert_eq!(report.downlink_ovrn, 0);
    assert_eq!(
        report,
        LinkReport {
            uplink_lost_time: 5,
            uplink_nb_msgs: 10,
            downlink_nb_msgs: 100,
            downlink_rate: 500,
            uplink_rate: 2,
            downlink_ovrn: 0,
        }
    );
    // The set's DATALINK_REPORT, field for field.
    let msg: DatalinkReport = report.into();
    assert_eq!(
        (
            msg.uplink_lost_time,
            msg.uplink_nb_msgs,
            msg.downlink_nb_msgs,
            msg.downlink_rate,
            msg.uplink_rate,
            msg.downlink_ovrn
        ),
        (5, 10, 100, 500, 2, 0)
    );
    // Unanswered PINGs (no services here) are counted as unhandled.
    assert_eq!(datalink.stats().unhandled, 10);
}

#[test]
fn an_idle_line_flushes_frames_held_behind_a_false_start() {
    let _clock = mock_time();
    static PINGS: AtomicU32 = AtomicU32::new(0);
    let arena: FrameArena<M, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 4> = Downlink::new(&arena, AC_ID, [v2()]);
    let [port] = downlink.ports().unwrap();
    let on_ping = |_: &Received<'_, '_>| {
        PINGS.fetch_add(1, Ordering::Relaxed);
    };
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID);
    datalink
        .subscribe(Filter::message::<Ping>(), &on_ping)
        .unwrap();
    // A false start announcing a 240-byte frame, then a PING, then silence.
    let mut bytes = vec![0x99, 0xF0];
    bytes.extend(uplink_frame(&Ping, AC_ID));
    // An idle time too long to add to the clock never ends (and does not panic).
    for idle in [None, Some(Duration::from_millis(20)), Some(Duration::MAX)] {
        PINGS.store(0, Ordering::Relaxed);
        let chunks = VecDeque::from([(Duration::from_millis(1), bytes.clone())]);
        let mut reader = Reader::<_, _>::new(ScriptedRx { chunks }, PprzV2::new(), port.device())
            .idle_flush(idle);
        run_with_mock_time(
            select(
                reader.run(&datalink),
                Timer::after(Duration::from_millis(100)),
            ),
            Duration::from_micros(100),
            10_000,
        );
        let expected = u32::from(idle.is_some_and(|i| i < Duration::MAX));
        assert_eq!(
            PINGS.load(Ordering::Relaxed),
            expected,
            "idle flush {idle:?}"
        );
    }
}

/// A device whose every read claims one byte more than the buffer holds.
struct Boaster;

impl embedded_io_async::ErrorType for Boaster {
    type Error = core::convert::Infallible;
}

impl embedded_io_async::Read for Boaster {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Self::Error> {
        Timer::after(Duration::from_millis(1)).await;
        Ok(buf.len() + 1)
    }
}

#[test]
fn a_read_of_more_bytes_than_the_buffer_is_a_counted_read_error() {
    let _clock = mock_time();
    let arena: FrameArena<M, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 4> = Downlink::new(&arena, AC_ID, [v2()]);
    let [port] = downlink.ports().unwrap();
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID);
    let mut reader = Reader::<_, _>::new(Boaster, PprzV2::new(), port.device());
    run_with_mock_time(
        select(
            reader.run(&datalink),
            Timer::after(Duration::from_millis(100)),
        ),
        Duration::from_micros(100),
        10_000,
    );
    // One read, then a 10 ms pause after each error: about 9 in 100 ms.
    let errors = datalink.stats().read_errors;
    assert!((5..=10).contains(&errors), "{errors} read errors");
    assert_eq!(reader.decoder_stats().frames, 0);
}

#[test]
fn a_setting_switches_the_telemetry_mode() {
    use pprz_default::periodic::{PROCESSES, SCHEDULE, main};
    use pprz_telemetry::scheduler::{Modes, Scheduler};
    let _clock = mock_time();
    static ARENA: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 16> = Downlink::new(&ARENA, AC_ID, [v2()]);
    let [mut port] = downlink.ports().unwrap();
    let modes: Modes<'_, PROCESSES> = Modes::new(&SCHEDULE);
    let scheduler: Scheduler<'_, M, PROCESSES, 8> = Scheduler::new(&modes);
    let services: Services<'_, Set, M, 4> = Services::new(AC_ID);
    // An invalid mode is refused; the acknowledgement then reports the mode in force.
    let index = services
        .settings()
        .add_mode("telemetry mode", modes.setting(main::PROCESS).unwrap())
        .unwrap();
    let datalink: Datalink<'_, M, 4> = Datalink::new(AC_ID);
    services.subscribe(datalink.registry()).unwrap();
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), port.device());

    assert_eq!(scheduler.modes().mode(0), Some(main::MODE_DEFAULT));
    let debug = main::MODE_DEBUG as f32;
    reader.feed(
        &uplink_frame(
            &Setting {
                index,
                ac_id: AC_ID,
                value: debug,
            },
            AC_ID,
        ),
        &datalink,
    );
    assert_eq!(scheduler.modes().mode(0), Some(main::MODE_DEBUG));
    reader.feed(
        &uplink_frame(
            &Setting {
                index,
                ac_id: AC_ID,
                value: 99.0,
            },
            AC_ID,
        ),
        &datalink,
    );
    assert_eq!(
        scheduler.modes().mode(0),
        Some(main::MODE_DEBUG),
        "no such mode: unchanged"
    );
    // Both SETTINGs were acknowledged with the mode in force.
    for _ in 0..2 {
        let frame = port.try_next().unwrap();
        assert_eq!(frame[5], DlValue::ID);
        let mut expected = vec![index];
        expected.extend_from_slice(&debug.to_le_bytes());
        assert_eq!(&frame[6..11], &expected[..]);
        frame.finish(true);
    }
    assert!(port.try_next().is_none(), "one acknowledgement per SETTING");
    let s = services.stats();
    assert_eq!((s.settings, s.unknown_index), (2, 0));
}

/// A 10 kHz PING flood (an attacker, or a ground tool gone wrong) on a radio that writes
/// one frame every 2 ms: the device's reply rate limit keeps the PONGs to its budget and
/// counts the rest, so the aircraft's telemetry (ATTITUDE at 4 Hz, normal priority) all
/// goes out. Without the limit the high-priority PONGs fill the queue and ATTITUDE is shed.
#[test]
fn ping_flood_is_rate_limited_and_telemetry_keeps_flowing() {
    use embassy_time::MockDriver;
    use pprz_default::messages::telemetry::Attitude;
    use pprz_telemetry::ReplyLimit;
    let _clock = mock_time();
    static ARENA: FrameArena<M, 2048> = FrameArena::new();
    let limit = ReplyLimit::new(10, 5);
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&ARENA, AC_ID, [v2().replies(Some(limit))]);
    let [mut port] = downlink.ports().unwrap();
    let services: Services<'_, Set, M, 1> = Services::new(AC_ID);
    let datalink: Datalink<'_, M, 4> = Datalink::new(AC_ID);
    services.subscribe(datalink.registry()).unwrap();
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), port.device());

    let (mut pongs, mut attitudes, mut pings) = (0u32, 0u32, 0u32);
    for ms in 0..3_000u32 {
        for _ in 0..10 {
            reader.feed(&PING_7, &datalink);
            pings += 1;
        }
        if ms % 250 == 0 {
            downlink
                .send(&Attitude {
                    phi: 0.0,
                    psi: 0.0,
                    theta: 0.0,
                })
                .unwrap();
        }
        if ms % 2 == 0
            && let Some(frame) = port.try_next()
        {
            match frame[5] {
                id if id == Pong::ID => pongs += 1,
                id if id == Attitude::ID => attitudes += 1,
                id => panic!("unexpected message {id}"),
            }
            frame.finish(true);
        }
        MockDriver::get().advance(Duration::from_millis(1));
    }
    while let Some(frame) = port.try_next() {
        if frame[5] == Pong::ID {
            pongs += 1;
        } else {
            attitudes += 1;
        }
        frame.finish(true);
    }
    let stats = downlink.stats(0).unwrap();
    assert_eq!(attitudes, 12, "every ATTITUDE sent: {stats:?}");
    assert_eq!(stats.lost(), stats.dropped.rate_limited, "{stats:?}");
    // The burst, then 10 per second for 3 s (the first of each interval conforms).
    assert!((30..=5 + 31).contains(&pongs), "{pongs} PONGs");
    assert_eq!(stats.dropped.rate_limited, pings - pongs);
    assert_eq!(services.stats().replies_dropped, pings - pongs);
    assert_eq!(services.stats().pings, pings);
    assert!(stats.is_balanced());
}

/// SETTING with NaN or an infinity (which `clamp` in a setter would let through, or
/// store): refused by the services before the setter runs, acknowledged with the value
/// in force, counted.
#[test]
fn non_finite_setting_values_are_not_applied() {
    let _clock = mock_time();
    static STORED: AtomicU32 = AtomicU32::new(0);
    let arena: FrameArena<M, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&arena, AC_ID, [v2()]);
    let [mut port] = downlink.ports().unwrap();
    let get = || f32::from_bits(STORED.load(Ordering::Relaxed));
    let set = |v: f32| STORED.store(v.clamp(0.0, 10.0).to_bits(), Ordering::Relaxed);
    let services: Services<'_, Set, M, 1> = Services::new(AC_ID);
    services.settings().add("gain", &get, &set).unwrap();
    let datalink: Datalink<'_, M, 4> = Datalink::new(AC_ID);
    services.subscribe(datalink.registry()).unwrap();
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), port.device());
    let setting = |value: f32| {
        uplink_frame(
            &Setting {
                index: 0,
                ac_id: AC_ID,
                value,
            },
            AC_ID,
        )
    };
    reader.feed(&setting(2.5), &datalink);
    for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
        reader.feed(&setting(bad), &datalink);
    }
    for _ in 0..4 {
        let frame = port.try_next().expect("one acknowledgement per SETTING");
        assert_eq!(&frame[..], dl_value_frame(AC_ID, 0, 2.5));
        frame.finish(true);
    }
    assert_eq!(get(), 2.5);
    let stats = services.stats();
    assert_eq!((stats.settings, stats.non_finite), (1, 3));
}
