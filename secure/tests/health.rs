//! Link health on the secure link (feature `embassy`): only frames the ground sealed keep
//! an aircraft's link Up.
//!
//! The aircraft (id 7) reads its secure radio with a `Reader` delivering through
//! `Layered::new(&secure_link, &datalink)`; the datalink drives a `LinkHealth` (Degraded
//! after 2 s, Lost after 3 s) and a subscriber that records the `Trust` of every message
//! it gets. The ground, with an established session, sends a sealed PING every 100 ms
//! until 10 s; from 10 s to 20 s it is silent while an attacker sends, every 100 ms,
//! plaintext PING and SETTING, replays, frames with forged tags, frames for another
//! aircraft, garbage and key-exchange messages; from 20 s the ground is back.
//!
//! Embassy-time's mock clock is global to this test binary: one test runs the scenarios
//! in sequence, advancing it 10 ms per step and polling the aircraft's tasks and a
//! `LinkHealth::changed` waiter at each step.

#![cfg(feature = "embassy")]

mod common;

use std::cell::RefCell;
use std::future::Future;
use std::pin::{Pin, pin};
use std::sync::Mutex;
use std::task::{Context, Poll, Waker};

use common::{
    AC_ID, Ground, TestRng, Wire, as_plaintext, frame, ping, plain, seal, setting, tamper,
};
use embassy_futures::select::select;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, Instant, MockDriver};
use pprz_secure::link::SecureLink;
use pprz_secure::rand_core::RngCore;
use pprz_secure::{ChannelStats, KEY_EXCHANGE_GCS, KEY_EXCHANGE_UAV, MsgId, Policy, Responder};
use pprz_telemetry::health::{Health, HealthConfig, LinkHealth};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::registry::{Filter, Received, Trust};
use pprz_telemetry::{Downlink, FrameArena, Layered, Targets, run_writer_with};
use pprz_transports::{Decoder, PprzV2};

/// Silence after which the aircraft's link is Lost.
const LOST_AFTER: Duration = Duration::from_secs(3);
/// The mock clock's step.
const STEP_MS: u64 = 10;
/// The ground's (and the attacker's) period.
const PERIOD_MS: u64 = 100;
/// The ground falls silent and the attacker starts.
const ATTACK_MS: u64 = 10_000;
/// The ground is back (the attacker stops).
const RESUME_MS: u64 = 20_000;
/// The end of a scenario.
const END_MS: u64 = 21_000;
/// Periods of attack.
const ATTACK_TICKS: u32 = ((RESUME_MS - ATTACK_MS) / PERIOD_MS) as u32;
/// Sealed frames the ground sends: before the attack, and from its end to the end.
const GENUINE: u32 = (ATTACK_MS / PERIOD_MS + (END_MS - RESUME_MS) / PERIOD_MS + 1) as u32;

/// Datalink PING and SETTING.
const PING: MsgId = MsgId::new(2, 8);
const SETTING: MsgId = MsgId::new(2, 4);
/// An aircraft that also accepts PING and SETTING in plaintext (whitelisted, so delivered
/// unauthenticated).
static PERMISSIVE_RX: [MsgId; 3] = [KEY_EXCHANGE_GCS, PING, SETTING];
static UAV_TX: [MsgId; 1] = [KEY_EXCHANGE_UAV];

/// One run of the timeline with the aircraft's plaintext policy.
struct Scenario {
    name: &'static str,
    policy: Policy,
    /// Whether plaintext PING and SETTING are on the aircraft's whitelist.
    plaintext_data: bool,
}

/// Polls a `LinkHealth::changed` waiter and records when it resolves.
struct Observer<'h> {
    health: &'h LinkHealth<M>,
    waiting: Pin<Box<dyn Future<Output = Health> + 'h>>,
    /// Mock time (ms) and the state it changed to.
    changes: Vec<(u64, Health)>,
}

impl<'h> Observer<'h> {
    fn new(health: &'h LinkHealth<M>) -> Self {
        Self {
            health,
            waiting: Box::pin(health.changed(health.state())),
            changes: Vec::new(),
        }
    }

    fn poll(&mut self) {
        let mut cx = Context::from_waker(Waker::noop());
        while let Poll::Ready(state) = self.waiting.as_mut().poll(&mut cx) {
            self.changes.push((Instant::now().as_millis(), state));
            self.waiting = Box::pin(self.health.changed(state));
        }
    }
}

/// The aircraft as the test drives it: its reader (fed bytes), its writer and handshake
/// task (polled), and what its writer put on the radio.
struct Air<'a, T: Future> {
    reader: Reader<'a, &'static [u8], PprzV2>,
    inbox: Layered<'a, SecureLink<M>, Datalink<'a, M, 1>>,
    tasks: Pin<&'a mut T>,
    wire: &'a RefCell<Vec<u8>>,
    downlink: Decoder<PprzV2>,
}

impl<T: Future> Air<'_, T> {
    /// Bytes arrive on the radio, then the line goes idle (the reader's idle flush).
    fn receive(&mut self, bytes: &[u8]) {
        self.reader.feed(bytes, &self.inbox);
        self.reader.flush(&self.inbox);
        self.run();
    }

    fn run(&mut self) {
        let mut cx = Context::from_waker(Waker::noop());
        for _ in 0..4 {
            assert!(self.tasks.as_mut().poll(&mut cx).is_pending());
        }
    }

    /// The frames the writer sent since the last call.
    fn sent(&mut self) -> Vec<Vec<u8>> {
        let bytes = std::mem::take(&mut *self.wire.borrow_mut());
        let mut input = &bytes[..];
        let mut frames = Vec::new();
        while let Some(f) = self.downlink.feed(&mut input) {
            frames.push(f.raw().to_vec());
        }
        frames
    }
}

/// A `KEY_EXCHANGE_GCS` message 1 (`P_AE`) from the ground's address to `dst`, naming
/// aircraft `ac`, with a random key.
fn msg1(dst: u8, ac: u8, rng: &mut TestRng) -> Vec<u8> {
    let mut fields = vec![ac, 0, 32];
    let mut key = [0u8; 32];
    rng.fill_bytes(&mut key);
    fields.extend_from_slice(&key);
    plain(0, dst, KEY_EXCHANGE_GCS.class, KEY_EXCHANGE_GCS.id, &fields)
}

/// What the attacker sends in one period: `captured` are the ground's sealed frames.
fn attack(k: usize, captured: &[Vec<u8>], rng: &mut TestRng) -> Vec<u8> {
    let mut garbage = |n: usize| {
        let mut g = vec![0u8; n];
        rng.fill_bytes(&mut g);
        g
    };
    let (head, tail) = (garbage(40), garbage(40));
    let old = &captured[k % captured.len()];
    let tag_end = old.len() - 5; // last DATA byte: the tag's
    let mut forged = vec![0x55, 0xFF, 0xFF, 0xFF, 0xF0, 0, AC_ID];
    forged.extend(garbage(10 + 16));
    let to_8 = plain(0, 8, 2, 8, &[]);
    let frames = [
        // (e) garbage, then everything else.
        head,
        // (a) unsecured and forged plaintext (0xAA) PING and SETTING from the ground.
        ping(),
        setting(),
        as_plaintext(&ping()),
        as_plaintext(&setting()),
        // (b) a replay.
        old.clone(),
        // (c) forged tags: a fresh counter on a captured frame, also its tag changed, and
        // a made-up frame near the end of the counter space.
        tamper(old, 1, 0x40),
        tamper(&tamper(old, 1, 0x40), tag_end, 0x01),
        frame(&forged),
        // (d) for aircraft 8: unsecured, plaintext, key exchange, sealed.
        to_8.clone(),
        as_plaintext(&to_8),
        as_plaintext(&msg1(8, 8, rng)),
        tamper(old, 6, AC_ID ^ 8),
        // (f) whitelisted plaintext: a key exchange, and a malformed one.
        as_plaintext(&msg1(AC_ID, AC_ID, rng)),
        as_plaintext(&plain(0, AC_ID, 2, 159, &[AC_ID, 7, 1, 0])),
        // (e) garbage at the end, behind the frames (the idle flush drops it).
        tail,
    ];
    frames.concat()
}

/// The channel's counters expected at the end of a scenario.
fn expected_channel(s: &Scenario) -> ChannelStats {
    let t = ATTACK_TICKS;
    let extra = u32::from(s.plaintext_data);
    ChannelStats {
        sessions: 1,
        // The ground's message 1 and 3; per period key exchanges (2), and the attacker's
        // PING and SETTING if whitelisted.
        received_plaintext: 2 + t * (2 + 2 * extra),
        decrypted: GENUINE,
        // Unsecured PING, SETTING (for us), PING for 8.
        not_secure: 3 * t,
        // Plaintext PING, SETTING (for us), PING for 8, unless whitelisted.
        plaintext_not_allowed: 3 * t * (1 - extra),
        // Key exchange and sealed frame for 8 (and the plaintext PING, if whitelisted).
        wrong_address: (2 + extra) * t,
        replayed: t,
        bad_tag: 3 * t,
        ..ChannelStats::default()
    }
}

/// The aircraft's expected state at `t` ms, after the frames of that step.
fn expected_state(t: u64) -> Health {
    match t {
        ..11_900 => Health::Up,
        11_900..12_900 => Health::Degraded,
        12_900..RESUME_MS => Health::Lost,
        _ => Health::Up,
    }
}

/// Runs the handshake at mock time 0: the ground's message 1 through the aircraft's
/// reader, its handshake task's message 2 back through its writer, message 3 in.
fn establish<T: Future>(air: &mut Air<'_, T>, ground: &mut Ground, rng: &mut TestRng) {
    ground.poll(0, rng);
    for _ in 0..3 {
        for f in std::mem::take(&mut ground.out) {
            air.receive(&f);
        }
        for f in air.sent() {
            ground.receive(&f, 0);
        }
    }
    assert!(ground.ch.has_session());
}

fn run(s: &Scenario) {
    MockDriver::get().reset();
    let arena: FrameArena<M, 4096> = FrameArena::new();
    let downlink: Downlink<'_, M, 1, 16> = Downlink::new(&arena, AC_ID, [SecureLink::<M>::DEVICE]);
    let secure = SecureLink::<M>::new(s.policy);
    let health: LinkHealth<M> = LinkHealth::new(HealthConfig::new().lost_after(LOST_AFTER));
    let trusts: Mutex<Vec<(u8, u8, Trust)>> = Mutex::new(Vec::new());
    let record = |rx: &Received<'_, '_>| {
        let entry = (rx.frame.source(), rx.msg_id(), rx.trust);
        trusts.lock().unwrap().push(entry);
    };
    let datalink: Datalink<'_, M, 1> = Datalink::with_health(AC_ID, &health);
    datalink.subscribe(Filter::All, &record).unwrap();

    let mut rng = TestRng::new(7);
    let mut air_rng = TestRng::new(8);
    let keys = common::test_keys();
    let mut responder = Responder::new(AC_ID, keys.aircraft().unwrap());
    let [mut radio] = downlink.ports().unwrap();
    let device = radio.device();
    let wire = RefCell::new(Vec::new());
    let tasks = pin!(select(
        run_writer_with(&mut radio, Wire(&wire), &secure),
        secure.run_responder(
            &mut responder,
            &mut air_rng,
            device.sender(),
            Targets::from(device),
        ),
    ));
    let mut air = Air {
        reader: Reader::new(&[][..], PprzV2::new(), device),
        inbox: Layered::new(&secure, &datalink),
        tasks,
        wire: &wire,
        downlink: Decoder::new(PprzV2::new()),
    };
    let mut ground = Ground::new();
    establish(&mut air, &mut ground, &mut rng);
    assert!(secure.has_session(), "{}: {:?}", s.name, secure.stats());
    assert_eq!(health.state(), Health::Lost, "never heard: Lost");

    let mut observer = Observer::new(&health);
    let mut captured = Vec::new();
    for t in (0..=END_MS).step_by(STEP_MS as usize) {
        assert_eq!(Instant::now().as_millis(), t);
        if t % PERIOD_MS == 0 {
            if (ATTACK_MS..RESUME_MS).contains(&t) {
                let k = ((t - ATTACK_MS) / PERIOD_MS) as usize;
                air.receive(&attack(k, &captured, &mut rng));
            } else {
                let sealed = seal(&mut ground.ch, &ping()).unwrap();
                air.receive(&sealed);
                if t < ATTACK_MS {
                    captured.push(sealed);
                }
            }
        }
        air.run();
        // The aircraft's handshake answers (message 2 to the attacker's message 1).
        air.sent();
        observer.poll();
        assert_eq!(health.state(), expected_state(t), "{} at {t} ms", s.name);
        MockDriver::get().advance(Duration::from_millis(STEP_MS));
    }

    // Lost once, 3 s after the last genuine frame (9.9 s), through the attack; Up again
    // on the first genuine frame.
    assert_eq!(
        observer.changes,
        [
            (0, Health::Up),
            (11_900, Health::Degraded),
            (12_900, Health::Lost),
            (RESUME_MS, Health::Up),
        ],
        "{}",
        s.name
    );
    let lost: Vec<u64> = observer
        .changes
        .iter()
        .filter(|c| c.1 == Health::Lost)
        .map(|c| c.0)
        .collect();
    assert!(
        lost.len() == 1 && (12_900..=13_000).contains(&lost[0]),
        "{lost:?}"
    );
    // Only the genuine frames were heard.
    let d = health.device(0).unwrap();
    assert_eq!((d.heard, d.losses), (GENUINE, 1), "{}: {d:?}", s.name);
    assert_eq!(d.last_heard, Some(Instant::from_millis(END_MS)));

    // Every frame is accounted for: rejected by the channel under its reason, consumed as
    // a key exchange, or delivered.
    let stats = secure.stats();
    let ch = stats.secure.channel;
    let expected = expected_channel(s);
    let received = ChannelStats {
        encrypted: 0,
        sent_plaintext: 0,
        ..ch
    };
    assert_eq!(received, expected, "{}", s.name);
    let decoded = air.reader.decoder_stats().frames;
    assert_eq!(
        decoded,
        ch.rejected() + ch.decrypted + ch.received_plaintext,
        "{}",
        s.name
    );
    assert_eq!(stats.malformed_key_exchange, ATTACK_TICKS);
    assert_eq!(stats.secure.handshake.completed, 1, "{:?}", stats.secure);
    assert!(
        stats.secure.handshake.started >= 2,
        "the attacker's message 1 too"
    );

    // Nothing for another aircraft gets past the channel (counted there, wrong_address):
    // the datalink never sees one.
    let unauthenticated = if s.plaintext_data {
        2 * ATTACK_TICKS
    } else {
        0
    };
    let dl = datalink.stats();
    assert_eq!(dl.not_for_us, 0, "{dl:?}");
    assert_eq!(dl.received, GENUINE + unauthenticated, "{dl:?}");
    assert_eq!(dl.unhandled, 0);

    // What the subscriber saw: the sealed PINGs, authenticated; whitelisted plaintext
    // (if any), from the ground's address but unauthenticated.
    let trusts = trusts.lock().unwrap();
    let count = |trust: Trust| trusts.iter().filter(|e| e.2 == trust).count() as u32;
    assert_eq!(count(Trust::Authenticated), GENUINE);
    assert_eq!(count(Trust::Unauthenticated), unauthenticated);
    assert_eq!(count(Trust::Plain), 0);
    assert!(
        trusts.iter().all(|e| e.0 == 0),
        "all from the ground's address"
    );
    let sealed_ids: Vec<u8> = trusts
        .iter()
        .filter(|e| e.2 == Trust::Authenticated)
        .map(|e| e.1)
        .collect();
    assert!(sealed_ids.iter().all(|&id| id == PING.id));
}

#[test]
fn only_sealed_frames_from_the_ground_keep_the_link_up() {
    let scenarios = [
        Scenario {
            name: "key exchange only in plaintext",
            policy: Policy::aircraft(AC_ID),
            plaintext_data: false,
        },
        Scenario {
            name: "PING and SETTING also in plaintext",
            policy: Policy::aircraft(AC_ID).with_plaintext(&PERMISSIVE_RX, &UAV_TX),
            plaintext_data: true,
        },
    ];
    for s in &scenarios {
        run(s);
    }
}
