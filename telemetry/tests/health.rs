//! Link health on mock time: the ground's uplink cut for a window, Lost signalled once at
//! the timeout, Up again when it returns; frames that must not count (for another
//! aircraft, from another aircraft, garbage) during the cut; two ground links, one cut;
//! the one-link facade driving its own health.

mod common;

use std::pin::pin;
use std::task::{Context, Poll, Waker};

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, Instant, MockDriver};
use pprz_default::messages::Set;
use pprz_default::messages::datalink::{Ping, Setting};
use pprz_telemetry::health::{Health, HealthConfig, Heard, LinkHealth};
use pprz_telemetry::pprz_transports::{AnyTransport, PprzV2};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Link, LinkMutex, Targets};

use common::frames::{PING_7, uplink_frame, v2_frame};
use common::sim::mock_time;

const AC_ID: u8 = 7;
const STEP: Duration = Duration::from_millis(10);

fn v2() -> DeviceConfig {
    DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new()))
}

/// Milliseconds of mock time since the clock was reset.
fn now_ms() -> u64 {
    Instant::now().as_millis()
}

/// A failsafe's view: every change `changed` reports, with the mock time it resolved at.
/// The future is polled once per step, as an executor would after its timer fired.
struct Watch<'h, const D: usize> {
    health: &'h LinkHealth<M, D>,
    seen: Health,
    changes: Vec<(u64, Health)>,
}

impl<'h, const D: usize> Watch<'h, D> {
    fn new(health: &'h LinkHealth<M, D>) -> Self {
        Self {
            health,
            seen: health.state(),
            changes: Vec::new(),
        }
    }

    /// Polls `changed` until it is pending (several changes may be due at one instant).
    fn poll(&mut self) {
        loop {
            let mut fut = pin!(self.health.changed(self.seen));
            match fut.as_mut().poll(&mut Context::from_waker(Waker::noop())) {
                Poll::Ready(state) => {
                    self.seen = state;
                    self.changes.push((now_ms(), state));
                }
                Poll::Pending => return,
            }
        }
    }

    fn times_of(&self, state: Health) -> Vec<u64> {
        self.changes
            .iter()
            .filter(|(_, s)| *s == state)
            .map(|(t, _)| *t)
            .collect()
    }
}

/// Lost after 3 s, uplink cut from 10 s to 20 s, the ground sending a PING every 100 ms
/// otherwise. During the cut, the aircraft's reader still gets frames that must not count.
#[test]
fn uplink_cut_is_lost_once_at_the_timeout_and_up_when_it_returns() {
    let _clock = mock_time();
    static ARENA: FrameArena<M, 1024> = FrameArena::new();
    static HEALTH: LinkHealth<M> =
        LinkHealth::new(HealthConfig::new().lost_after(Duration::from_secs(3)));
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&ARENA, AC_ID, [v2()]);
    let [port] = downlink.ports().unwrap();
    let datalink: Datalink<'_, M, 4> = Datalink::with_health(AC_ID, &HEALTH);
    let mut reader = Reader::<_, _>::new(&[][..], PprzV2::new(), port.device());

    let ping = uplink_frame(&Ping {}, AC_ID);
    let for_8 = uplink_frame(&Ping {}, 8);
    let from_aircraft_9 = v2_frame(&Ping {}, 9, AC_ID);
    let mut corrupt = ping.clone();
    *corrupt.last_mut().unwrap() ^= 0x55;
    let mut watch = Watch::new(&HEALTH);
    assert_eq!(watch.seen, Health::Lost, "never heard: Lost");

    for step in 0..3_000u64 {
        let ms = step * 10;
        let cut = (10_000..20_000).contains(&ms);
        if ms % 100 == 0 {
            if cut {
                // 100 frames every 100 ms that must not hold the link Up.
                for _ in 0..25 {
                    reader.feed(&for_8, &datalink);
                    reader.feed(&from_aircraft_9, &datalink);
                    reader.feed(&corrupt, &datalink);
                    reader.feed(&[0x99, 0x00, 0x42, 0x13, 0x99, 0x03], &datalink);
                }
            } else {
                reader.feed(&ping, &datalink);
            }
        }
        watch.poll();
        MockDriver::get().advance(STEP);
    }

    assert_eq!(
        watch.times_of(Health::Up),
        [0, 20_000],
        "{:?}",
        watch.changes
    );
    // Last PING at 9.9 s: Degraded 2 s later, Lost 3 s later, exactly once.
    assert_eq!(
        watch.times_of(Health::Degraded),
        [11_900],
        "{:?}",
        watch.changes
    );
    assert_eq!(
        watch.times_of(Health::Lost),
        [12_900],
        "{:?}",
        watch.changes
    );
    let lost_at = watch.times_of(Health::Lost)[0];
    assert!(
        (12_900..=13_000).contains(&lost_at),
        "within one ground period of 13 s"
    );

    let device = HEALTH.device(0).unwrap();
    assert_eq!(device.losses, 1);
    assert_eq!(
        device.heard,
        100 + 100,
        "PINGs before and after the cut only"
    );
    assert_eq!(device.state, Health::Up);
    let stats = datalink.stats();
    assert_eq!(stats.not_for_us, 100 * 25, "frames for aircraft 8 counted");
    assert_eq!(
        reader.decoder_stats().checksum_errors,
        100 * 25,
        "corrupt frames counted"
    );
}

/// Two ground links (a radio and a USB cable); the radio's uplink is cut: the radio is
/// Lost, the aircraft is not.
#[test]
fn two_ground_links_one_cut_stays_up() {
    let _clock = mock_time();
    static ARENA: FrameArena<M, 1024> = FrameArena::new();
    static HEALTH: LinkHealth<M, 2> =
        LinkHealth::new(HealthConfig::new().lost_after(Duration::from_secs(3)));
    let downlink: Downlink<'_, M, 2, 8> = Downlink::new(&ARENA, AC_ID, [v2(), v2()]);
    let [radio, usb] = downlink.ports().unwrap();
    let datalink: Datalink<'_, M, 4> = Datalink::with_health(AC_ID, &HEALTH);
    let mut radio_rx = Reader::<_, _>::new(&[][..], PprzV2::new(), radio.device());
    let mut usb_rx = Reader::<_, _>::new(&[][..], PprzV2::new(), usb.device());
    let mut watch = Watch::new(&HEALTH);

    for step in 0..3_000u64 {
        let ms = step * 10;
        if ms % 100 == 0 {
            if !(10_000..20_000).contains(&ms) {
                radio_rx.feed(&PING_7, &datalink);
            }
            usb_rx.feed(&PING_7, &datalink);
        }
        watch.poll();
        if ms == 15_000 {
            assert_eq!(HEALTH.device_state(0), Some(Health::Lost));
            assert_eq!(HEALTH.device_state(1), Some(Health::Up));
        }
        MockDriver::get().advance(STEP);
    }
    assert_eq!(
        watch.changes,
        [(0, Health::Up)],
        "the aircraft never left Up"
    );
    assert_eq!(HEALTH.device(0).unwrap().losses, 1);
    assert_eq!(HEALTH.device(1).unwrap().losses, 0);
}

/// Only the devices marked as ground links count: a link to another aircraft that keeps
/// talking does not hold the aircraft Up.
#[test]
fn a_device_that_is_not_a_ground_link_does_not_count() {
    let _clock = mock_time();
    static HEALTH: LinkHealth<M, 2> =
        LinkHealth::new(HealthConfig::new().heard(Heard::AnySource)).ground_links(Targets::only(0));
    HEALTH.heard(0, Instant::now());
    HEALTH.heard(1, Instant::now());
    assert_eq!(HEALTH.state(), Health::Up);
    MockDriver::get().advance(Duration::from_secs(6));
    HEALTH.heard(1, Instant::now());
    assert_eq!(HEALTH.device_state(1), Some(Health::Up));
    assert_eq!(HEALTH.state(), Health::Lost);
    assert_eq!(HEALTH.device_state(2), None, "no such device");
}

/// "Never": timeouts too long to add to the clock give no deadline, and the watcher
/// waits for frames instead of panicking.
#[test]
fn timeouts_past_the_clock_s_end_never_expire() {
    let _clock = mock_time();
    static HEALTH: LinkHealth<M, 1> = LinkHealth::new(
        HealthConfig::new()
            .heard(Heard::Manual)
            .degraded_after(Duration::MAX)
            .lost_after(Duration::MAX),
    );
    HEALTH.heard(0, Instant::now());
    let mut watch = Watch::new(&HEALTH);
    watch.poll();
    MockDriver::get().advance(Duration::from_secs(3600));
    watch.poll();
    assert_eq!(HEALTH.state(), Health::Up);
    assert!(watch.changes.is_empty(), "{:?}", watch.changes);
    // Heard at the clock's end: no deadline either.
    HEALTH.heard(0, Instant::MAX);
    watch.poll();
    assert_eq!(HEALTH.state(), Health::Up);
}

/// With a recovery rule of 3 frames at most 500 ms apart, single frames on a dying link
/// do not make a Lost link Up.
#[test]
fn lost_link_recovers_after_the_configured_run_of_frames() {
    let _clock = mock_time();
    static HEALTH: LinkHealth<M> = LinkHealth::new(
        HealthConfig::new()
            .lost_after(Duration::from_secs(3))
            .recover_frames(3, Duration::from_millis(500)),
    );
    let t0 = Instant::now();
    let at = |ms: u64| t0 + Duration::from_millis(ms);
    // Never heard is Lost: the first run of three frames makes it Up.
    for ms in [0, 100] {
        HEALTH.heard(0, at(ms));
        assert_eq!(HEALTH.state_at(at(ms)), Health::Lost);
    }
    HEALTH.heard(0, at(200));
    assert_eq!(HEALTH.state_at(at(200)), Health::Up);
    assert_eq!(
        HEALTH.device_at(0, at(200)).unwrap().losses,
        0,
        "nothing lost yet"
    );
    assert_eq!(HEALTH.state_at(at(2_500)), Health::Degraded);
    assert_eq!(HEALTH.state_at(at(3_200)), Health::Lost);
    // Frames 1 s apart: each run is one frame long.
    for ms in [4_000, 5_000, 6_000] {
        HEALTH.heard(0, at(ms));
        assert_eq!(HEALTH.state_at(at(ms)), Health::Lost, "at {ms} ms");
    }
    // Three frames 400 ms apart: Up on the third.
    HEALTH.heard(0, at(7_000));
    HEALTH.heard(0, at(7_400));
    assert_eq!(HEALTH.state_at(at(7_400)), Health::Lost);
    HEALTH.heard(0, at(7_800));
    assert_eq!(HEALTH.state_at(at(7_800)), Health::Up);
    assert_eq!(HEALTH.device_at(0, at(7_800)).unwrap().losses, 1);
    // Degraded -> Up needs one frame.
    HEALTH.heard(0, at(10_000));
    assert_eq!(HEALTH.state_at(at(10_000)), Health::Up);
}

/// A silence that loses the link ends a run even when it is within the recovery gap:
/// the frames before the loss do not count towards recovering from it.
#[test]
fn frames_before_a_loss_do_not_count_towards_recovering_from_it() {
    let _clock = mock_time();
    static HEALTH: LinkHealth<M> = LinkHealth::new(
        HealthConfig::new()
            .degraded_after(Duration::from_millis(200))
            .lost_after(Duration::from_millis(500))
            .recover_frames(3, Duration::from_secs(1)),
    );
    let t0 = Instant::now();
    let at = |ms: u64| t0 + Duration::from_millis(ms);
    for ms in [0, 100, 200] {
        HEALTH.heard(0, at(ms));
    }
    assert_eq!(HEALTH.state_at(at(200)), Health::Up);
    assert_eq!(HEALTH.state_at(at(900)), Health::Lost);
    // 700 ms after the last frame: within the recovery gap, but after a loss.
    HEALTH.heard(0, at(900));
    assert_eq!(HEALTH.state_at(at(900)), Health::Lost);
    HEALTH.heard(0, at(1_000));
    assert_eq!(HEALTH.state_at(at(1_000)), Health::Lost);
    HEALTH.heard(0, at(1_100));
    assert_eq!(HEALTH.state_at(at(1_100)), Health::Up);
    assert_eq!(HEALTH.device_at(0, at(1_100)).unwrap().losses, 1);
}

/// Zero timeouts are one tick: a frame makes the link Up for the tick it is heard in
/// (with 0 the link was never Up, and a failsafe waiting for Up never armed).
#[test]
fn zero_timeouts_are_one_tick() {
    let _clock = mock_time();
    static HEALTH: LinkHealth<M> = LinkHealth::new(
        HealthConfig::new()
            .degraded_after(Duration::from_ticks(0))
            .lost_after(Duration::from_ticks(0)),
    );
    assert_eq!(HEALTH.config().lost_timeout(), Duration::from_ticks(1));
    assert_eq!(HEALTH.config().degraded_timeout(), Duration::from_ticks(1));
    let t0 = Instant::now();
    HEALTH.heard(0, t0);
    assert_eq!(HEALTH.state_at(t0), Health::Up);
    assert_eq!(HEALTH.device_at(0, t0).unwrap().losses, 0);
    assert_eq!(HEALTH.state_at(t0 + Duration::from_ticks(1)), Health::Lost);
}

/// The one-link facade: its reader drives `Link::health`; frames for another aircraft do
/// not.
#[test]
fn the_link_facade_drives_its_health() {
    let _clock = mock_time();
    static ARENA: FrameArena<LinkMutex, 2048> = FrameArena::new();
    static LINK: Link<'static, Set> = Link::new(&ARENA, AC_ID)
        .health_config(HealthConfig::new().lost_after(Duration::from_secs(3)));
    assert_eq!(
        LINK.health().config().lost_timeout(),
        Duration::from_secs(3)
    );
    let ping = uplink_frame(&Ping {}, AC_ID);
    let setting_for_8 = uplink_frame(
        &Setting {
            index: 0,
            ac_id: 8,
            value: 1.0,
        },
        8,
    );
    let mut ground = ping.clone();
    ground.extend_from_slice(&setting_for_8);
    let log = std::cell::RefCell::new(Vec::new());
    let tx = common::sim::SimUart {
        byte_us: 100,
        log: &log,
    };
    let second = Duration::from_secs(1);
    let rx = common::sim::ScriptedRx {
        chunks: [
            (Duration::from_ticks(0), ground),
            (second, setting_for_8.clone()),
            (second, setting_for_8.clone()),
            (second, setting_for_8),
        ]
        .into(),
    };
    let mut run = pin!(LINK.run(tx, rx));
    let mut watch = Watch::new(LINK.health());
    for _ in 0..600 {
        let _ = run.as_mut().poll(&mut Context::from_waker(Waker::noop()));
        watch.poll();
        MockDriver::get().advance(STEP);
    }
    assert_eq!(
        watch.changes,
        [
            (10, Health::Up),
            (2_010, Health::Degraded),
            (3_010, Health::Lost)
        ],
        "the PING read at the first step after start, nothing for us after it"
    );
    assert_eq!(LINK.stats().uplink.not_for_us, 4);
}

/// An XBee 802.15.4 receive frame carries the RSSI the modem measured: the health keeps
/// the last one heard.
#[test]
fn xbee_frames_report_their_rssi() {
    use pprz_telemetry::pprz_transports::XBee24;
    let _clock = mock_time();
    static ARENA: FrameArena<M, 1024> = FrameArena::new();
    static HEALTH: LinkHealth<M> = LinkHealth::new(HealthConfig::new());
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(
        &ARENA,
        AC_ID,
        [DeviceConfig::new(AnyTransport::XBee24(XBee24::new()))],
    );
    let [port] = downlink.ports().unwrap();
    let datalink: Datalink<'_, M, 4> = Datalink::with_health(AC_ID, &HEALTH);
    let mut reader = Reader::<_, _>::new(&[][..], XBee24::new(), port.device());
    assert_eq!(HEALTH.rssi(), None);
    // RX16 from the ground modem (address 0x0000), RSSI 0x28 (-40 dBm), options 0, then
    // PING from the ground (0) to aircraft 7; checksum 0xFF minus the byte sum.
    let rx16 = |rssi: u8| {
        let data = [0x81, 0x00, 0x00, rssi, 0x00, 0x00, AC_ID, 0x02, 0x08];
        let sum = data.iter().fold(0u8, |a, b| a.wrapping_add(*b));
        let mut frame = vec![0x7E, 0x00, data.len() as u8];
        frame.extend_from_slice(&data);
        frame.push(0xFF - sum);
        frame
    };
    assert_eq!(reader.feed(&rx16(0x28), &datalink), 1);
    assert_eq!(HEALTH.rssi(), Some(0x28));
    assert_eq!(HEALTH.state(), Health::Up);
    reader.feed(&rx16(0x50), &datalink);
    assert_eq!(HEALTH.device(0).unwrap().rssi, Some(0x50), "the latest");
    assert_eq!(HEALTH.device(0).unwrap().heard, 2);
}
