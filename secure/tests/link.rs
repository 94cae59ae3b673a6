//! The secure link inside the telemetry stack (feature `embassy`): an aircraft made of a
//! `pprz-telemetry` downlink whose radio has a [`SecureLink`] (writer sealing at wire
//! time, reader opening, handshake task, PING/SETTING services) and a ground made of this
//! crate's initiator and channel, talking over an in-memory radio that can lose frames.
//!
//! Deterministic: the futures are polled by hand while embassy-time's mock clock
//! advances 1 ms per step; the ground runs between two polls.

#![cfg(feature = "embassy")]

mod common;

use common::Wire;
use pprz_telemetry::SendOptions;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::future::{Future, poll_fn};
use std::pin::pin;
use std::task::{Context, Poll, Waker};

use embassy_futures::select::select3;
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, Instant, MockDriver};
use pprz_default::messages::Set;
use pprz_default::messages::telemetry::{Attitude, DlValue, Pong};
use pprz_messages::{Decode, Message};
use pprz_secure::link::SecureLink;
use pprz_secure::rand_core::{OsRng, TryRngCore, UnwrapErr};
use pprz_secure::{
    Initiator, InitiatorEvent, InitiatorState, KeyExchange, KeyExchangeIds, KeyFile, Policy,
    Protection, Responder, SecureChannel,
};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::services::Services;
use pprz_telemetry::{Downlink, FrameArena, Layered, Targets, run_writer_with};
use pprz_transports::{Decoder, Encoder, MsgHeader, PprzV2, TxMeta};

const AC_ID: u8 = 7;

/// The radio's uplink: bytes the ground sent, read by the aircraft's reader.
struct Uplink<'a>(&'a RefCell<VecDeque<u8>>);

impl embedded_io_async::ErrorType for Uplink<'_> {
    type Error = Infallible;
}

impl embedded_io_async::Read for Uplink<'_> {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        poll_fn(|_| {
            let mut q = self.0.borrow_mut();
            if q.is_empty() || buf.is_empty() {
                return Poll::Pending;
            }
            let n = buf.len().min(q.len());
            for (b, v) in buf.iter_mut().zip(q.drain(..n)) {
                *b = v;
            }
            Poll::Ready(Ok(n))
        })
        .await
    }
}

/// A frame the ground received: how it crossed the link and the plain frame.
#[derive(Debug, Clone)]
struct Got {
    protection: Protection,
    plain: Vec<u8>,
}

impl Got {
    fn is<T: Message>(&self) -> bool {
        self.plain.get(4) == Some(&T::CLASS_ID) && self.plain.get(5) == Some(&T::ID)
    }

    fn fields(&self) -> &[u8] {
        &self.plain[6..self.plain.len() - 2]
    }

    fn counter(&self) -> Option<u32> {
        match self.protection {
            Protection::Encrypted { counter } => Some(counter),
            Protection::Plaintext => None,
        }
    }
}

/// The ground: the initiator, its channel, a decoder of the downlink.
struct Ground {
    channel: SecureChannel,
    initiator: Initiator,
    rng: UnwrapErr<OsRng>,
    decoder: Decoder<PprzV2>,
    /// Messages 2 to lose on the radio before delivering one.
    lose_msg2: usize,
    got: Vec<Got>,
    /// Every frame's first DATA byte (crypto byte) as it was on the wire.
    crypto_bytes: Vec<u8>,
}

impl Ground {
    fn new() -> Self {
        let keys = KeyFile::parse(pprz_secure::keys::INSECURE_TEST_KEY_FILE).unwrap();
        Self {
            channel: SecureChannel::new(Policy::ground(AC_ID)),
            initiator: Initiator::new(AC_ID, keys.ground().unwrap()),
            rng: OsRng.unwrap_err(),
            decoder: Decoder::new(PprzV2::new()),
            lose_msg2: 0,
            got: Vec::new(),
            crypto_bytes: Vec::new(),
        }
    }

    /// Seals a plain frame for the uplink.
    fn send(&mut self, plain: &[u8], uplink: &RefCell<VecDeque<u8>>) {
        let mut buf = [0u8; 255];
        buf[..plain.len()].copy_from_slice(plain);
        let sealed = self.channel.seal_in_place(&mut buf, plain.len()).unwrap();
        uplink.borrow_mut().extend(&buf[..sealed.len]);
    }

    fn send_kx(&mut self, kx: &KeyExchange, uplink: &RefCell<VecDeque<u8>>) {
        let mut buf = [0u8; 255];
        let n = kx.write_frame(&mut buf).unwrap();
        self.send(&buf[..n], uplink);
    }

    /// One step of the ground at `now_ms`: handshake timers, then the downlink's bytes.
    fn step(&mut self, now_ms: u64, wire: &RefCell<Vec<u8>>, uplink: &RefCell<VecDeque<u8>>) {
        // Once per session running out (not again while the new handshake is under way).
        if self.channel.needs_rekey() && self.initiator.state() == InitiatorState::Confirmed {
            self.initiator.restart();
        }
        if let Some(kx) = self.initiator.poll(now_ms, &mut self.rng) {
            self.send_kx(&kx, uplink);
        }
        let bytes = std::mem::take(&mut *wire.borrow_mut());
        let mut input = &bytes[..];
        let mut frames = Vec::new();
        while let Some(frame) = self.decoder.feed(&mut input) {
            frames.push(frame.data().to_vec());
        }
        for data in frames {
            self.crypto_bytes.push(data[0]);
            let mut out = [0u8; 255];
            let Ok(opened) = self.channel.open(&data, &mut out) else {
                continue;
            };
            let got = Got {
                protection: opened.protection(),
                plain: opened.frame().to_vec(),
            };
            if let Ok(Some(kx)) = KeyExchange::parse(opened.data(), &KeyExchangeIds::PPRZLINK) {
                if self.lose_msg2 > 0 {
                    self.lose_msg2 -= 1;
                    continue;
                }
                if let Ok(InitiatorEvent::Established { keys, reply }) =
                    self.initiator.handle(&kx, now_ms)
                {
                    self.channel.install(keys);
                    self.send_kx(&reply, uplink);
                }
                continue;
            }
            if opened.is_encrypted() {
                self.initiator.confirm(now_ms);
            }
            self.got.push(got);
        }
    }
}

/// A plain uplink frame from the ground to the aircraft.
fn uplink_frame<T: Message>(msg: &T) -> Vec<u8> {
    let mut fields = [0u8; 255];
    let n = msg.encode(&mut fields).unwrap();
    let mut buf = [0u8; 255];
    let meta = TxMeta::new(MsgHeader::new(0, AC_ID, T::CLASS_ID, T::ID));
    let len = PprzV2::new().encode(&meta, &fields[..n], &mut buf).unwrap();
    buf[..len].to_vec()
}

/// Polls the aircraft and runs the ground for `ms` milliseconds of mock time.
fn run_for(
    aircraft: &mut std::pin::Pin<&mut impl Future>,
    ground: &mut Ground,
    ms: u64,
    wire: &RefCell<Vec<u8>>,
    uplink: &RefCell<VecDeque<u8>>,
) {
    let mut cx = Context::from_waker(Waker::noop());
    for _ in 0..ms {
        for _ in 0..4 {
            assert!(aircraft.as_mut().poll(&mut cx).is_pending());
        }
        ground.step(Instant::now().as_millis(), wire, uplink);
        MockDriver::get().advance(Duration::from_millis(1));
    }
}

static ARENA: FrameArena<M, 4096> = FrameArena::new();
static DOWNLINK: Downlink<'static, M, 1, 16> =
    Downlink::new(&ARENA, AC_ID, [SecureLink::<M>::DEVICE]);
static SECURE: SecureLink<M> = SecureLink::aircraft(AC_ID);

static GAIN: std::sync::Mutex<f32> = std::sync::Mutex::new(1.0);

#[test]
fn an_aircraft_with_a_secure_radio_talks_only_encrypted_to_its_ground() {
    MockDriver::get().reset();
    let wire = RefCell::new(Vec::new());
    let uplink = RefCell::new(VecDeque::new());
    let keys = KeyFile::parse(pprz_secure::keys::INSECURE_TEST_KEY_FILE).unwrap();
    let mut responder = Responder::new(AC_ID, keys.aircraft().unwrap());
    let mut rng = OsRng.unwrap_err();

    let [mut radio] = DOWNLINK.ports().unwrap();
    let device = radio.device();
    let services: Services<'_, Set, M, 2> = Services::new(AC_ID);
    let datalink: Datalink<'_, M, { Services::<Set, M, 2>::SUBSCRIPTIONS }> = Datalink::new(AC_ID);
    let get_gain = || *GAIN.lock().unwrap();
    let set_gain = |v: f32| *GAIN.lock().unwrap() = v;
    services
        .settings()
        .add("gain", &get_gain, &set_gain)
        .unwrap();
    services.subscribe(datalink.registry()).unwrap();
    let inbox = Layered::new(&SECURE, &datalink);
    let mut reader = Reader::<_, PprzV2>::new(Uplink(&uplink), PprzV2::new(), device);
    let aircraft = select3(
        run_writer_with(&mut radio, Wire(&wire), &SECURE),
        reader.run(&inbox),
        SECURE.run_responder(
            &mut responder,
            &mut rng,
            device.sender(),
            Targets::from(device),
        ),
    );
    let mut aircraft = pin!(aircraft);
    let mut ground = Ground::new();

    // Telemetry before the session: refused at the wire, counted, nothing in the clear.
    let attitude = Attitude {
        phi: 0.5,
        psi: 0.25,
        theta: -0.125,
    };
    device.send(&attitude).unwrap();
    // The first message 2 is lost: the ground repeats message 1 a second later, and the
    // aircraft answers again (from its cache, within its rate limit).
    ground.lose_msg2 = 1;
    run_for(&mut aircraft, &mut ground, 2500, &wire, &uplink);
    assert!(SECURE.has_session(), "{:?}", SECURE.stats());
    assert_eq!(device.stats().dropped.refused, 1, "{:?}", device.stats());
    let stats = SECURE.stats();
    assert_eq!(stats.secure.handshake.completed, 1, "{stats:?}");
    assert!(stats.secure.handshake.started >= 1);
    // Only key exchanges crossed, in plaintext.
    assert!(ground.got.is_empty(), "{:?}", ground.got);
    assert!(ground.crypto_bytes.iter().all(|&b| b == 0xAA));
    assert!(ground.crypto_bytes.len() >= 2, "message 2 twice");

    // PING up, PONG down; SETTING up, DL_VALUE down: encrypted both ways.
    let ping = uplink_frame(&pprz_default::messages::datalink::Ping {});
    ground.send(&ping, &uplink);
    let setting = uplink_frame(&pprz_default::messages::datalink::Setting {
        index: 0,
        ac_id: AC_ID,
        value: 2.5,
    });
    ground.send(&setting, &uplink);
    run_for(&mut aircraft, &mut ground, 50, &wire, &uplink);
    assert_eq!(*GAIN.lock().unwrap(), 2.5);
    let pongs = ground.got.iter().filter(|g| g.is::<Pong>()).count();
    assert_eq!(pongs, 1, "{:?}", ground.got);
    let dl_value = ground.got.iter().find(|g| g.is::<DlValue>()).unwrap();
    assert_eq!(
        DlValue::decode(dl_value.fields()).unwrap(),
        DlValue {
            index: 0,
            value: 2.5
        }
    );
    assert!(ground.got.iter().all(|g| g.counter().is_some()));

    // Priority reordering: three frames queued at once leave most important first, and
    // the counters follow the order on the wire.
    ground.got.clear();
    for priority in [10, 200, 100] {
        device
            .send_with(&attitude, SendOptions::new().priority(priority))
            .unwrap();
    }
    run_for(&mut aircraft, &mut ground, 20, &wire, &uplink);
    let counters: Vec<u32> = ground.got.iter().filter_map(Got::counter).collect();
    assert_eq!(counters.len(), 3, "{:?}", ground.got);
    assert!(counters.windows(2).all(|w| w[0] < w[1]), "{counters:?}");
    assert_eq!(
        Attitude::decode(ground.got[0].fields()).unwrap(),
        attitude,
        "a frame decrypts to what was sent"
    );

    // Attacks, each rejected and counted, nothing applied: a PING in plaintext (no
    // secure byte), a replayed encrypted SETTING, a modified ciphertext.
    let before = SECURE.stats().secure.channel;
    let pings = services.stats().pings;
    uplink.borrow_mut().extend(&ping);
    let mut buf = [0u8; 255];
    let replay_setting = uplink_frame(&pprz_default::messages::datalink::Setting {
        index: 0,
        ac_id: AC_ID,
        value: 9.0,
    });
    buf[..replay_setting.len()].copy_from_slice(&replay_setting);
    let sealed = ground
        .channel
        .seal_in_place(&mut buf, replay_setting.len())
        .unwrap();
    let frame = buf[..sealed.len].to_vec();
    uplink.borrow_mut().extend(&frame);
    run_for(&mut aircraft, &mut ground, 20, &wire, &uplink);
    assert_eq!(*GAIN.lock().unwrap(), 9.0, "the real one applies");
    *GAIN.lock().unwrap() = 1.0;
    uplink.borrow_mut().extend(&frame);
    // A fresh frame (a counter never seen), one ciphertext bit flipped.
    buf[..replay_setting.len()].copy_from_slice(&replay_setting);
    let sealed = ground
        .channel
        .seal_in_place(&mut buf, replay_setting.len())
        .unwrap();
    let mut tampered = buf[..sealed.len].to_vec();
    tampered[12] ^= 1;
    // Fix the PPRZ checksum so only the tag can tell.
    let (a, b) = pprz_transports::checksum::pprz(&tampered[1..tampered.len() - 2]);
    let n = tampered.len();
    tampered[n - 2] = a;
    tampered[n - 1] = b;
    uplink.borrow_mut().extend(&tampered);
    run_for(&mut aircraft, &mut ground, 20, &wire, &uplink);
    assert_eq!(*GAIN.lock().unwrap(), 1.0, "nothing applied");
    assert_eq!(
        services.stats().pings,
        pings,
        "the plaintext PING is not answered"
    );
    let after = SECURE.stats().secure.channel;
    assert_eq!(after.not_secure, before.not_secure + 1);
    assert_eq!(after.replayed, before.replayed + 1);
    assert_eq!(after.bad_tag, before.bad_tag + 1);

    // A flood of fresh message 1: the session stays, telemetry keeps flowing, the
    // handshake task's queue overflows (counted) and its rate limit holds.
    let mut attacker = Initiator::new(AC_ID, keys.ground().unwrap());
    let mut attacker_rng = OsRng.unwrap_err();
    let started = SECURE.stats().secure.handshake.started;
    ground.got.clear();
    for i in 0..40u64 {
        attacker.restart();
        let kx = attacker.poll(i, &mut attacker_rng).unwrap();
        let mut buf = [0u8; 255];
        let n = kx.write_frame(&mut buf).unwrap();
        let mut attacker_channel = SecureChannel::new(Policy::ground(AC_ID));
        let sealed = attacker_channel.seal_in_place(&mut buf, n).unwrap();
        // Each fresh key five times in one burst.
        for _ in 0..5 {
            uplink.borrow_mut().extend(&buf[..sealed.len]);
        }
        device.send(&attitude).unwrap();
        run_for(&mut aircraft, &mut ground, 25, &wire, &uplink);
    }
    let stats = SECURE.stats();
    assert!(SECURE.has_session());
    assert!(stats.handshake_queue_full > 0, "{stats:?}");
    // 1 s of flood: at most 2 handshakes' work (the rate limit is 1 per second).
    assert!(stats.secure.handshake.started - started <= 2, "{stats:?}");
    assert!(stats.secure.handshake.rate_limited > 0, "{stats:?}");
    let flowing = ground.got.iter().filter(|g| g.is::<Attitude>()).count();
    assert_eq!(flowing, 40, "telemetry kept flowing under the old session");

    // The counter close to 2^32: the aircraft stops sending (counted), never wraps; the
    // ground re-keys and telemetry resumes under a new session.
    let refused = device.stats().dropped.refused;
    SECURE.with_channel(|c| c.advance_tx_counter(u32::MAX - 1));
    ground.got.clear();
    device.send(&attitude).unwrap();
    device.send(&attitude).unwrap(); // the last counter value, 2^32 - 1
    device.send(&attitude).unwrap(); // refused
    run_for(&mut aircraft, &mut ground, 20, &wire, &uplink);
    let last: Vec<u32> = ground.got.iter().filter_map(Got::counter).collect();
    assert_eq!(last, [u32::MAX - 1, u32::MAX], "{:?}", ground.got);
    assert_eq!(device.stats().dropped.refused, refused + 1);
    assert_eq!(SECURE.stats().secure.channel.counter_exhausted, 1);
    // The ground re-keys (`needs_rekey`: it would have long before, had the counter not
    // jumped), after the flood's rate limit has passed.
    run_for(&mut aircraft, &mut ground, 2500, &wire, &uplink);
    ground.got.clear();
    device.send(&attitude).unwrap();
    run_for(&mut aircraft, &mut ground, 20, &wire, &uplink);
    assert_eq!(
        ground
            .got
            .iter()
            .filter_map(Got::counter)
            .collect::<Vec<_>>(),
        [1],
        "a new session counts from 1: {:?}",
        SECURE.stats()
    );
    // Every message accepted for sending is sent or counted.
    assert!(device.stats().is_balanced(), "{:?}", device.stats());
}
