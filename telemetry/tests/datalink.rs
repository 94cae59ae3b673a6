//! The uplink: readers, destination filtering, the subscriber registry, the PING /
//! SETTING / GET_SETTING services with their replies byte for byte over a simulated
//! link, and the DATALINK_REPORT.

mod common;

use std::cell::RefCell;
use std::collections::VecDeque;
use std::sync::atomic::{AtomicU32, Ordering};

use embassy_futures::join::join;
use embassy_futures::select::select;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_sync::channel::Channel;
use embassy_time::{Duration, Instant, Timer};
use pprz_messages::Message;
use pprz_telemetry::messages::datalink::{Block, GetSetting, MoveWp, Ping, Setting};
use pprz_telemetry::messages::telemetry::{DlValue, Pong};
use pprz_telemetry::pprz_transports::{Encoder, MsgHeader, PprzV1, PprzV2, TxMeta};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::registry::{ChannelSubscriber, Filter, OwnedMessage, Received, Registry};
use pprz_telemetry::services::{LinkReporter, Services, Settings};
use pprz_telemetry::stats::DeviceStats;
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, run_writer};

use common::sim::{ScriptedRx, SimUart, byte_time_us, mock_time, run_with_mock_time};

const AC_ID: u8 = 7;

/// A PPRZ v2 frame from the ground (id 0) to `dest`.
fn uplink_frame<Msg: Message>(msg: &Msg, dest: u8) -> Vec<u8> {
    let mut fields = [0u8; 64];
    let n = msg.encode(&mut fields).unwrap();
    let mut out = [0u8; 80];
    let meta = TxMeta::new(MsgHeader::new(0, dest, Msg::CLASS_ID, Msg::ID));
    let len = PprzV2::new().encode(&meta, &fields[..n], &mut out).unwrap();
    out[..len].to_vec()
}

static SETTING_0: AtomicU32 = AtomicU32::new(0);

#[test]
fn ping_and_settings_round_trip_byte_for_byte() {
    let _clock = mock_time();
    static ARENA: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 16> =
        Downlink::new(&ARENA, AC_ID, [DeviceConfig::new(PprzV2::new().into())]);
    let get = || f32::from_bits(SETTING_0.load(Ordering::Relaxed));
    let set = |v: f32| SETTING_0.store(v.to_bits(), Ordering::Relaxed);
    let get_k = || 42.0;
    let set_k = |_v: f32| {};
    let mut settings: Settings<'_, 4> = Settings::new();
    assert_eq!(settings.add("gain", &get, &set), Ok(0));
    assert_eq!(settings.add("constant", &get_k, &set_k), Ok(1));
    let services: Services<'_, '_, M, 1, 16, 4> = Services::new(&downlink, settings);
    let mut registry: Registry<'_, 8> = Registry::new();
    services.subscribe(&mut registry).unwrap();
    let datalink: Datalink<'_, M, 8> = Datalink::new(AC_ID, registry);

    // The ground's requests, as bytes on the radio, split across reads.
    let ping = [0x99, 0x08, 0x00, 0x07, 0x02, 0x08, 0x19, 0x49];
    assert_eq!(uplink_frame(&Ping, AC_ID), ping, "hand-computed PING frame");
    let requests = [
        ping.to_vec(),
        uplink_frame(
            &Setting {
                index: 0,
                ac_id: AC_ID,
                value: 1.5,
            },
            AC_ID,
        ),
        uplink_frame(
            &GetSetting {
                index: 1,
                ac_id: AC_ID,
            },
            0xFF,
        ), // broadcast
        uplink_frame(
            &Setting {
                index: 0,
                ac_id: 9,
                value: 9.0,
            },
            AC_ID,
        ), // other aircraft id
        uplink_frame(
            &Setting {
                index: 5,
                ac_id: AC_ID,
                value: 9.0,
            },
            AC_ID,
        ), // no such setting
        uplink_frame(&Ping, 9), // addressed to aircraft 9
    ];
    let mut chunks = VecDeque::new();
    for frame in &requests {
        let (a, b) = frame.split_at(3);
        chunks.push_back((Duration::from_millis(50), a.to_vec()));
        chunks.push_back((Duration::from_millis(1), b.to_vec()));
    }
    let log = RefCell::new(Vec::new());
    let mut reader = Reader::<_, _>::new(ScriptedRx { chunks }, PprzV2::new(), 0);
    let mut tx = SimUart {
        byte_us: byte_time_us(57_600),
        log: &log,
    };
    let run = select(
        join(reader.run(&datalink), run_writer(&downlink, 0, &mut tx)),
        Timer::after(Duration::from_millis(500)),
    );
    run_with_mock_time(run, Duration::from_micros(50), 20_000);

    let replies: Vec<Vec<u8>> = log.into_inner().into_iter().map(|(_, _, b)| b).collect();
    let pong = vec![0x99, 0x08, 0x07, 0x00, 0x01, 0x03, 0x13, 0x49];
    let dl_value = |index: u8, value: f32| {
        let mut v = vec![0x99, 0x0D, AC_ID, 0x00, 0x01, 31, index];
        v.extend_from_slice(&value.to_le_bytes());
        let (mut a, mut b) = (0u8, 0u8);
        for byte in &v[1..] {
            a = a.wrapping_add(*byte);
            b = b.wrapping_add(a);
        }
        v.extend_from_slice(&[a, b]);
        v
    };
    assert_eq!(replies, [pong, dl_value(0, 1.5), dl_value(1, 42.0)]);
    assert_eq!(f32::from_bits(SETTING_0.load(Ordering::Relaxed)), 1.5);

    let s = services.stats();
    assert_eq!((s.pings, s.settings, s.get_settings), (1, 1, 1));
    assert_eq!((s.wrong_ac_id, s.unknown_index, s.malformed), (1, 1, 0));
    let up = datalink.stats();
    assert_eq!((up.received, up.not_for_us, up.unhandled), (5, 1, 0));
    assert!(up.last_received.is_some());
    assert_eq!(reader.decoder_stats().frames, 6);
    // DL_VALUE goes out at high priority, PONG too.
    assert_eq!(DlValue::PRIORITY, pprz_messages::priority::HIGH);
    assert_eq!(Pong::PRIORITY, pprz_messages::priority::HIGH);
}

#[test]
fn registry_calls_every_matching_subscriber_and_reports_full() {
    let _clock = mock_time();
    static PER_MESSAGE: AtomicU32 = AtomicU32::new(0);
    static ALSO: AtomicU32 = AtomicU32::new(0);
    static CLASS: AtomicU32 = AtomicU32::new(0);
    static ALL: AtomicU32 = AtomicU32::new(0);
    let on_block = |rx: &Received<'_>| {
        let block = rx.decode::<Block>().unwrap();
        PER_MESSAGE.fetch_add(u32::from(block.block_id), Ordering::Relaxed);
    };
    let also = |_: &Received<'_>| {
        ALSO.fetch_add(1, Ordering::Relaxed);
    };
    let class = |rx: &Received<'_>| {
        assert_eq!(rx.class_id(), 2);
        CLASS.fetch_add(1, Ordering::Relaxed);
    };
    let all = |rx: &Received<'_>| {
        assert_eq!(rx.link, 3);
        ALL.fetch_add(1, Ordering::Relaxed);
    };
    let mut registry: Registry<'_, 4> = Registry::new();
    registry
        .subscribe(Filter::message::<Block>(), &on_block)
        .unwrap();
    registry
        .subscribe(Filter::message::<Block>(), &also)
        .unwrap();
    registry.subscribe(Filter::Class(2), &class).unwrap();
    registry.subscribe(Filter::All, &all).unwrap();
    assert_eq!(
        registry.subscribe(Filter::All, &all).unwrap_err().capacity,
        4
    );
    let datalink: Datalink<'_, M, 4> = Datalink::new(AC_ID, registry);
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), 3);
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
    static INBOX: Channel<M, OwnedMessage, 2> = Channel::new();
    static NAV: ChannelSubscriber<'static, M, 2> = ChannelSubscriber::new(&INBOX);
    let mut registry: Registry<'static, 2> = Registry::new();
    registry
        .subscribe(Filter::message::<MoveWp>(), &NAV)
        .unwrap();
    let datalink: Datalink<'_, M, 2> = Datalink::new(AC_ID, registry);
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), 0);
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
    assert_eq!(first.link, 0);
    assert_eq!(first.source, 0);
    assert_eq!(first.destination, Some(AC_ID));
}

#[test]
fn v1_frames_have_no_destination_and_are_accepted() {
    let _clock = mock_time();
    static SEEN: AtomicU32 = AtomicU32::new(0);
    let seen = |rx: &Received<'_>| {
        assert_eq!(rx.frame.destination(), None);
        SEEN.fetch_add(1, Ordering::Relaxed);
    };
    let mut registry: Registry<'_, 1> = Registry::new();
    registry.subscribe(Filter::All, &seen).unwrap();
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID, registry);
    let mut reader = Reader::<_, _>::new(&[][..], PprzV1::new(2), 0);
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
}

#[test]
fn datalink_report_from_uplink_and_downlink_counters() {
    let _clock = mock_time();
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID, Registry::new());
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), 0);
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
}

#[test]
fn an_idle_line_flushes_frames_held_behind_a_false_start() {
    let _clock = mock_time();
    static PINGS: AtomicU32 = AtomicU32::new(0);
    let on_ping = |_: &Received<'_>| {
        PINGS.fetch_add(1, Ordering::Relaxed);
    };
    let mut registry: Registry<'_, 1> = Registry::new();
    registry
        .subscribe(Filter::message::<Ping>(), &on_ping)
        .unwrap();
    let datalink: Datalink<'_, M, 1> = Datalink::new(AC_ID, registry);
    // A false start announcing a 240-byte frame, then a PING, then silence.
    let mut bytes = vec![0x99, 0xF0];
    bytes.extend(uplink_frame(&Ping, AC_ID));
    for idle in [None, Some(Duration::from_millis(20))] {
        PINGS.store(0, Ordering::Relaxed);
        let chunks = VecDeque::from([(Duration::from_millis(1), bytes.clone())]);
        let mut reader =
            Reader::<_, _>::new(ScriptedRx { chunks }, PprzV2::new(), 0).idle_flush(idle);
        run_with_mock_time(
            select(
                reader.run(&datalink),
                Timer::after(Duration::from_millis(100)),
            ),
            Duration::from_micros(100),
            10_000,
        );
        let expected = u32::from(idle.is_some());
        assert_eq!(
            PINGS.load(Ordering::Relaxed),
            expected,
            "idle flush {idle:?}"
        );
    }
}

#[test]
fn a_setting_switches_the_telemetry_mode() {
    use pprz_telemetry::periodic::{SCHEDULE, main};
    use pprz_telemetry::scheduler::Scheduler;
    let _clock = mock_time();
    static ARENA: FrameArena<M, 2048> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 16> =
        Downlink::new(&ARENA, AC_ID, [DeviceConfig::new(PprzV2::new().into())]);
    let scheduler: Scheduler<'_, M, 1, 8> = Scheduler::new(&SCHEDULE);
    let mode = scheduler.mode_setting(0).unwrap();
    let get_mode = || mode.get();
    let set_mode = |v: f32| {
        // An invalid mode is refused; the acknowledgement then reports the mode in force.
        let _ = mode.set(v);
    };
    let mut settings: Settings<'_, 4> = Settings::new();
    let index = settings
        .add("telemetry mode", &get_mode, &set_mode)
        .unwrap();
    let services: Services<'_, '_, M, 1, 16, 4> = Services::new(&downlink, settings);
    let mut registry: Registry<'_, 4> = Registry::new();
    services.subscribe(&mut registry).unwrap();
    let datalink: Datalink<'_, M, 4> = Datalink::new(AC_ID, registry);
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), 0);

    assert_eq!(scheduler.mode(0), Some(main::MODE_DEFAULT));
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
    assert_eq!(scheduler.mode(0), Some(main::MODE_DEBUG));
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
        scheduler.mode(0),
        Some(main::MODE_DEBUG),
        "no such mode: unchanged"
    );
    // Both SETTINGs were acknowledged with the mode in force.
    let q = downlink.queue(0).unwrap();
    for _ in 0..2 {
        let frame = q.try_receive().unwrap();
        assert_eq!(frame[5], DlValue::ID);
        let mut expected = vec![index];
        expected.extend_from_slice(&debug.to_le_bytes());
        assert_eq!(&frame[6..11], &expected[..]);
    }
}
