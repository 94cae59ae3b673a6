//! Several aircraft (issue 15): the ground reaches aircraft 8 only through aircraft 7,
//! which relays between its radio to the ground and a second radio to 8.
//!
//! ```text
//!  ground ◄── radio, 57600 baud ──► 7 ◄── radio 7-8 ──► 8
//! ```
//!
//! Two kinds of test, both deterministic:
//! * timed: every stack runs its writers and readers over simulated UARTs under the mock
//!   clock (services answering PING and SETTING, telemetry, a flood);
//! * pumped: frames are fed to readers and taken from the ports by hand, round after
//!   round until nothing moves (broadcast, loops, hostile frames), so what circulates is
//!   counted exactly.

mod common;

use pprz_telemetry::SendOptions;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::convert::Infallible;
use std::future::poll_fn;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU32, Ordering};
use std::task::Poll;

use embassy_futures::join::{join, join3};
use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
use embassy_time::{Duration, Instant, Timer};
use pprz_default::messages::datalink::{Block, Ping, Setting};
use pprz_default::messages::telemetry::{Attitude, DlValue, Payload, Pong};
use pprz_default::messages::{MESSAGES, Set};
use pprz_messages::{Message, VarArray};
use pprz_telemetry::pprz_transports::{
    BROADCAST_ID, Decoder, Encoder, GROUND_ID, MsgHeader, PprzV2, TxMeta,
};
use pprz_telemetry::reader::{Datalink, Reader};
use pprz_telemetry::registry::{Filter, Received};
use pprz_telemetry::services::Services;
use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, Port, Targets, run_writer};
use pprz_telemetry::{Relay, Routes};

use common::frames::v2_frame;
use common::sim::{byte_time_us, mock_time, run_with_mock_time};

/// Devices per aircraft (aircraft 8 uses only device 0).
const D: usize = 2;
type Dl = Downlink<'static, M, D, 32>;
type Dlk = Datalink<'static, M, 8>;
type Svc = Services<'static, Set, M, 2>;

/// Priority of forwarded frames whose message the relay does not know.
const RELAY_PRIORITY: u8 = 10;

/// One aircraft's stack, leaked so tasks can borrow it for the whole test.
struct Aircraft {
    id: u8,
    downlink: &'static Dl,
    datalink: &'static Dlk,
    relay: &'static Relay<'static, M, Dlk>,
    services: &'static Svc,
    /// Subscribers' view: (source, class, id) of every message delivered to us.
    delivered: &'static Mutex<Vec<(u8, u8, u8)>>,
}

fn leak<T>(value: T) -> &'static T {
    Box::leak(Box::new(value))
}

fn v2() -> DeviceConfig {
    DeviceConfig::new(PprzV2::new().into())
}

/// Aircraft `id` with `devices` devices (1 or 2), route table `table`, default route
/// `default`, broadcast on `broadcast`; relaying, answering PING and SETTING (one
/// setting, index 0), and recording every message delivered to it.
fn aircraft(
    id: u8,
    table: &'static [(u8, Targets)],
    default: Targets,
    broadcast: Targets,
    arena_bytes: usize,
) -> Aircraft {
    let arena: &'static FrameArena<M, 8192> = leak(FrameArena::new());
    assert!(arena_bytes <= 8192);
    let downlink: &'static Dl = leak(
        Downlink::new(arena, id, [v2(), v2()])
            .with_routes(Routes::new(table, default).broadcast(broadcast)),
    );
    let datalink: &'static Dlk = leak(Datalink::new(id));
    let relay = leak(Relay::new(datalink, RELAY_PRIORITY).with_messages(&MESSAGES));
    let services: &'static Svc = leak(Services::new(id));
    let value: &'static AtomicU32 = leak(AtomicU32::new(0));
    let get = leak(move || f32::from_bits(value.load(Ordering::Relaxed)));
    let set = leak(move |v: f32| value.store(v.to_bits(), Ordering::Relaxed));
    services.settings().add("gain", get, set).unwrap();
    services.subscribe(datalink.registry()).unwrap();
    let delivered: &'static Mutex<Vec<(u8, u8, u8)>> = leak(Mutex::new(Vec::new()));
    let record = leak(move |rx: &Received<'_, '_>| {
        delivered
            .lock()
            .unwrap()
            .push((rx.source(), rx.class_id(), rx.msg_id()));
    });
    datalink.subscribe(Filter::All, record).unwrap();
    Aircraft {
        id,
        downlink,
        datalink,
        relay,
        services,
        delivered,
    }
}

/// Aircraft 7: device 0 the radio to the ground, device 1 the radio to 8.
fn relay_7() -> Aircraft {
    static TABLE: [(u8, Targets); 1] = [(8, Targets::only(1))];
    aircraft(7, &TABLE, Targets::only(0), Targets::ALL, 8192)
}

/// Aircraft 8: device 0 the radio to 7, its only way anywhere.
fn leaf_8() -> Aircraft {
    aircraft(8, &[], Targets::only(0), Targets::only(0), 8192)
}

// ---------------------------------------------------------------------------------------
// Timed runs over simulated UARTs.

/// One direction of a UART: what one end writes (one byte time per byte, the whole
/// write arriving at its end) the other end reads. Every write is logged.
struct Wire {
    byte_us: u64,
    bytes: RefCell<VecDeque<u8>>,
    log: RefCell<Vec<(Instant, Instant, Vec<u8>)>>,
}

impl Wire {
    fn new(baud: u64) -> &'static Wire {
        leak(Wire {
            byte_us: byte_time_us(baud),
            bytes: RefCell::new(VecDeque::new()),
            log: RefCell::new(Vec::new()),
        })
    }

    /// Writes `bytes` (taking their time on the wire).
    async fn send(&self, bytes: &[u8]) {
        let start = Instant::now();
        Timer::after(Duration::from_micros(self.byte_us * bytes.len() as u64)).await;
        self.bytes.borrow_mut().extend(bytes);
        self.log
            .borrow_mut()
            .push((start, Instant::now(), bytes.to_vec()));
    }

    /// Every frame written, decoded: (start, end, source, destination, class, id, payload).
    fn frames(&self) -> Vec<WireFrame> {
        let mut out = Vec::new();
        for (start, end, bytes) in self.log.borrow().iter() {
            let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
            let mut input = &bytes[..];
            let frame = decoder.feed(&mut input).expect("every write is one frame");
            out.push(WireFrame {
                start: *start,
                end: *end,
                source: frame.source(),
                destination: frame.destination().unwrap(),
                class: frame.class(),
                msg_id: frame.msg_id(),
                payload: frame.payload().to_vec(),
                raw: bytes.clone(),
            });
        }
        out
    }
}

#[derive(Debug, Clone)]
struct WireFrame {
    start: Instant,
    end: Instant,
    source: u8,
    destination: u8,
    class: u8,
    msg_id: u8,
    payload: Vec<u8>,
    raw: Vec<u8>,
}

impl WireFrame {
    fn is<Msg: Message>(&self) -> bool {
        (self.class, self.msg_id) == (Msg::CLASS_ID, Msg::ID)
    }
}

struct Tx(&'static Wire);
struct Rx(&'static Wire);

impl embedded_io_async::ErrorType for Tx {
    type Error = Infallible;
}
impl embedded_io_async::ErrorType for Rx {
    type Error = Infallible;
}

impl embedded_io_async::Write for Tx {
    async fn write(&mut self, buf: &[u8]) -> Result<usize, Infallible> {
        self.0.send(buf).await;
        Ok(buf.len())
    }

    async fn flush(&mut self) -> Result<(), Infallible> {
        Ok(())
    }
}

impl embedded_io_async::Read for Rx {
    async fn read(&mut self, buf: &mut [u8]) -> Result<usize, Infallible> {
        // The simulation polls every future at each step: no waker needed.
        poll_fn(|_| {
            let mut bytes = self.0.bytes.borrow_mut();
            if bytes.is_empty() {
                return Poll::Pending;
            }
            let n = bytes.len().min(buf.len());
            for (slot, byte) in buf.iter_mut().zip(bytes.drain(..n)) {
                *slot = byte;
            }
            Poll::Ready(Ok(n))
        })
        .await
    }
}

/// Runs one device of `ac`: its writer onto `out`, its reader from `input`.
async fn device(ac: &Aircraft, mut port: Port<'static>, out: &'static Wire, input: &'static Wire) {
    let mut reader = Reader::<_, _>::new(Rx(input), PprzV2::new(), port.device());
    let relay = ac.relay;
    let _: (Infallible, Infallible) =
        match select(run_writer(&mut port, Tx(out)), reader.run(relay)).await {
            Either::First(never) | Either::Second(never) => never,
        };
}

/// The fleet's links: ground <-> 7 at `ground_baud`, 7 <-> 8 at `link_baud`.
struct Fleet {
    up: &'static Wire,     // ground -> 7
    down: &'static Wire,   // 7 -> ground
    to_8: &'static Wire,   // 7 -> 8
    from_8: &'static Wire, // 8 -> 7
    a7: Aircraft,
    a8: Aircraft,
}

impl Fleet {
    fn new(ground_baud: u64, link_baud: u64) -> Self {
        Fleet {
            up: Wire::new(ground_baud),
            down: Wire::new(ground_baud),
            to_8: Wire::new(link_baud),
            from_8: Wire::new(link_baud),
            a7: relay_7(),
            a8: leaf_8(),
        }
    }

    /// Runs both aircraft and `script` (the ground and the applications) until `script`
    /// ends, then `drain` more of simulated time.
    fn run(&self, script: impl Future<Output = ()>, seconds: u64) {
        let [radio, to_8] = self.a7.downlink.ports().unwrap();
        let [to_7, _unused] = self.a8.downlink.ports().unwrap();
        let fleet = join3(
            device(&self.a7, radio, self.down, self.up),
            device(&self.a7, to_8, self.to_8, self.from_8),
            device(&self.a8, to_7, self.from_8, self.to_8),
        );
        let script = async {
            script.await;
            // Let every queue drain.
            Timer::after(Duration::from_secs(2)).await;
        };
        let done = run_with_mock_time(
            select(script, fleet),
            Duration::from_micros(20),
            (seconds + 3) * 50_000,
        );
        assert!(matches!(done, Either::First(())));
    }
}

fn setting(ac_id: u8, index: u8, value: f32) -> Vec<u8> {
    v2_frame(
        &Setting {
            index,
            ac_id,
            value,
        },
        GROUND_ID,
        ac_id,
    )
}

#[test]
fn ground_reaches_8_through_7() {
    let _clock = mock_time();
    let fleet = Fleet::new(57_600, 57_600);
    let (a7, a8) = (&fleet.a7, &fleet.a8);
    let script = async {
        Timer::after(Duration::from_millis(10)).await;
        fleet.up.send(&v2_frame(&Ping, GROUND_ID, 8)).await;
        Timer::after(Duration::from_millis(100)).await;
        fleet.up.send(&setting(8, 0, 2.5)).await;
        Timer::after(Duration::from_millis(100)).await;
        fleet.up.send(&v2_frame(&Ping, GROUND_ID, 7)).await;
        // 8's own telemetry, to the ground (its default route).
        let attitude = Attitude {
            phi: 0.5,
            psi: 0.25,
            theta: -0.5,
        };
        a8.downlink.send(&attitude).unwrap();
        // And 8 to 7 directly (sent to a destination).
        a8.downlink
            .send_with(
                &Block {
                    block_id: 3,
                    ac_id: 7,
                },
                SendOptions::new().to(7).priority(100),
            )
            .unwrap();
        Timer::after(Duration::from_millis(300)).await;
    };
    fleet.run(script, 1);

    let down = fleet.down.frames();
    // PONG from 8 (to the ground), relayed by 7.
    let pong_8: Vec<_> = down
        .iter()
        .filter(|f| f.is::<Pong>() && f.source == 8)
        .collect();
    assert_eq!(pong_8.len(), 1, "{down:?}");
    assert_eq!(pong_8[0].destination, GROUND_ID);
    // DL_VALUE of 8's setting 0, acknowledging the value set.
    let acks_8: Vec<_> = down
        .iter()
        .filter(|f| f.is::<DlValue>() && f.source == 8)
        .collect();
    assert_eq!(acks_8.len(), 1);
    let mut expected = vec![0u8];
    expected.extend_from_slice(&2.5f32.to_le_bytes());
    assert_eq!(acks_8[0].payload, expected);
    // 7 answered its own PING.
    assert_eq!(
        down.iter()
            .filter(|f| f.is::<Pong>() && f.source == 7)
            .count(),
        1
    );
    // 8's telemetry reaches the ground with source 8, byte for byte as 8 sent it.
    let att_8: Vec<_> = down
        .iter()
        .filter(|f| f.is::<Attitude>() && f.source == 8)
        .collect();
    assert_eq!(att_8.len(), 1);
    let sent_by_8: Vec<_> = fleet
        .from_8
        .frames()
        .into_iter()
        .filter(|f| f.is::<Attitude>())
        .collect();
    assert_eq!(sent_by_8.len(), 1);
    assert_eq!(att_8[0].raw, sent_by_8[0].raw, "forwarded unchanged");
    // The block for 7 went to 7 only (not on to the ground), and 7's subscribers saw
    // it coming from 8.
    assert!(!down.iter().any(|f| f.is::<Block>()));
    assert!(
        a7.delivered
            .lock()
            .unwrap()
            .contains(&(8, Block::CLASS_ID, Block::ID))
    );
    // 8 saw the ground's requests with the ground as their source.
    assert!(
        a8.delivered
            .lock()
            .unwrap()
            .contains(&(GROUND_ID, Ping::CLASS_ID, Ping::ID))
    );
    assert_eq!(a8.services.settings().get(0), Some(2.5));
    assert_eq!(
        a7.services.settings().get(0),
        Some(0.0),
        "7's setting untouched"
    );

    // Accounting at each hop.
    let r7 = a7.relay.stats();
    assert_eq!(
        r7.forwarded, 5,
        "PING, SETTING down; PONG, DL_VALUE, ATTITUDE up: {r7:?}"
    );
    assert_eq!(r7.refused(), 0, "{r7:?}");
    let radio = a7.downlink.stats(0).unwrap();
    let link = a7.downlink.stats(1).unwrap();
    assert!(radio.is_balanced() && link.is_balanced());
    assert_eq!((radio.relayed.submitted, radio.relayed.sent), (3, 3));
    assert_eq!((link.relayed.submitted, link.relayed.sent), (2, 2));
    assert_eq!(link.sent, 2, "7 sends nothing of its own to 8");
    assert_eq!(a8.relay.stats().forwarded, 0);
}

#[test]
fn a_saturated_relay_keeps_acknowledgements_first() {
    const SECONDS: u64 = 5;
    const GROUND_BAUD: u64 = 57_600;
    let _clock = mock_time();
    // The 7-8 radio is ten times faster than the ground's: 8's flood reaches 7 whole.
    let fleet = Fleet::new(GROUND_BAUD, 10 * GROUND_BAUD);
    let (a7, a8) = (&fleet.a7, &fleet.a8);
    let payload_bytes = [0x5A; 120];
    let produced = RefCell::new(0u32);
    // 8: PAYLOAD (priority 64) at 10x the ground link (a 129-byte frame every 2.24 ms
    // = 57.6 kB/s); 7: ATTITUDE at 10 Hz.
    let applications = async {
        let frame_us = 129 * byte_time_us(GROUND_BAUD) / 10;
        let mut next_payload = Instant::now();
        let mut next_attitude = Instant::now();
        let end = Instant::now() + Duration::from_secs(SECONDS);
        while Instant::now() < end {
            let now = Instant::now();
            if now >= next_payload {
                let _ = a8.downlink.send(&Payload {
                    values: VarArray::new(&payload_bytes),
                });
                *produced.borrow_mut() += 1;
                next_payload += Duration::from_micros(frame_us);
            }
            if now >= next_attitude {
                let _ = a7.downlink.send(&Attitude {
                    phi: 0.1,
                    psi: 0.2,
                    theta: 0.3,
                });
                next_attitude += Duration::from_millis(100);
            }
            Timer::after(Duration::from_micros(100)).await;
        }
    };
    // The ground: a SETTING to 7 and one to 8 every 250 ms.
    let ground = async {
        for i in 0..SECONDS * 4 {
            Timer::after(Duration::from_millis(125)).await;
            fleet.up.send(&setting(7, 0, i as f32)).await;
            Timer::after(Duration::from_millis(125)).await;
            fleet.up.send(&setting(8, 0, i as f32)).await;
        }
    };
    fleet.run(
        async {
            join(applications, ground).await;
        },
        SECONDS,
    );

    let up = fleet.up.frames();
    let down = fleet.down.frames();
    let byte_us = byte_time_us(GROUND_BAUD);
    let max_frame = Duration::from_micros(255 * byte_us);
    // 7's acknowledgements: each left within two maximum-size frame times of its
    // request's arrival.
    let requests_7: Vec<_> = up.iter().filter(|f| f.destination == 7).collect();
    let acks_7: Vec<_> = down
        .iter()
        .filter(|f| f.is::<DlValue>() && f.source == 7)
        .collect();
    assert_eq!(
        acks_7.len(),
        requests_7.len(),
        "no acknowledgement of 7 lost"
    );
    let mut waits: Vec<Duration> = requests_7
        .iter()
        .zip(&acks_7)
        .map(|(req, ack)| ack.start - req.end)
        .collect();
    waits.sort();
    let p99 = waits[(waits.len() * 99).div_ceil(100) - 1];
    println!(
        "7's acks: p99 wait {} µs, max {} µs (two max-size frames: {} µs)",
        p99.as_micros(),
        waits.last().unwrap().as_micros(),
        2 * max_frame.as_micros()
    );
    assert!(p99 <= 2 * max_frame, "ack p99 {} µs", p99.as_micros());
    // 8's acknowledgements all got through 7.
    let requests_8 = up.iter().filter(|f| f.destination == 8).count();
    let acks_8 = down
        .iter()
        .filter(|f| f.is::<DlValue>() && f.source == 8)
        .count();
    assert_eq!(acks_8, requests_8, "no acknowledgement of 8 lost");
    // 7's status kept flowing: every ATTITUDE sent.
    let attitudes = down.iter().filter(|f| f.is::<Attitude>()).count() as u64;
    assert_eq!(attitudes, SECONDS * 10);

    // Every frame accounted for at each hop.
    let produced = *produced.borrow();
    let s8 = a8.downlink.stats(0).unwrap();
    assert!(s8.is_balanced(), "{s8:?}");
    assert_eq!(
        s8.submitted,
        produced + requests_8 as u32,
        "payload and acks"
    );
    let sent_by_8 = fleet.from_8.frames().len() as u32;
    assert_eq!(s8.sent, sent_by_8);
    // 7 forwarded every frame 8 sent (all for the ground) and every request for 8.
    let r7 = a7.relay.stats();
    assert_eq!(r7.forwarded, sent_by_8 + requests_8 as u32, "{r7:?}");
    assert_eq!(r7.refused(), 0);
    let radio = a7.downlink.stats(0).unwrap();
    assert!(radio.is_balanced(), "{radio:?}");
    let relayed = radio.relayed;
    assert_eq!(relayed.submitted, sent_by_8);
    assert_eq!(relayed.queued(), 0, "drained");
    let from_8_on_ground = down.iter().filter(|f| f.source == 8).count() as u32;
    assert_eq!(relayed.sent, from_8_on_ground);
    assert_eq!(relayed.submitted, relayed.sent + relayed.lost());
    // The payload was shed, at the low level only; nothing of 7's own was.
    assert!(relayed.levels[2].lost > 0, "{relayed:?}");
    assert_eq!(relayed.levels[0].lost, 0);
    assert_eq!(
        radio.lost(),
        relayed.lost(),
        "7's own frames were never shed"
    );
    println!(
        "relay 7 -> ground: {} of 8's frames submitted, {} sent, {} shed ({} low-priority)",
        relayed.submitted,
        relayed.sent,
        relayed.lost(),
        relayed.levels[2].lost
    );
}

// ---------------------------------------------------------------------------------------
// Pumped runs: frames moved by hand until nothing moves.

/// Takes every frame queued on `port`, as sent.
fn drain(port: &mut Port<'_>) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    while let Some(frame) = port.try_next() {
        out.push(frame.to_vec());
        frame.finish(true);
    }
    out
}

/// A point-to-point radio between device `.0.1` of aircraft `.0.0` and device `.1.1` of
/// aircraft `.1.0` (indices into the fleet).
type Radio = ((usize, usize), (usize, usize));

/// A fleet whose frames are moved by hand.
struct Pumped<'f> {
    fleet: Vec<&'f Aircraft>,
    ports: Vec<[Port<'static>; D]>,
}

impl<'f> Pumped<'f> {
    fn new(fleet: &[&'f Aircraft]) -> Self {
        Self {
            fleet: fleet.to_vec(),
            ports: fleet
                .iter()
                .map(|ac| ac.downlink.ports().unwrap())
                .collect(),
        }
    }

    /// Aircraft `ac` receives `frame` on its device `device`.
    fn receive(&self, ac: usize, device: usize, frame: &[u8]) {
        let mut reader =
            Reader::<_, _>::new(&[][..], PprzV2::new(), self.ports[ac][device].device());
        reader.feed(frame, self.fleet[ac].relay);
    }

    /// Takes what aircraft `ac` queued on its device `device`.
    fn take(&mut self, ac: usize, device: usize) -> Vec<Vec<u8>> {
        drain(&mut self.ports[ac][device])
    }

    /// Moves frames along `radios` until none is queued on them; returns how many frames
    /// crossed each radio (both directions). Panics if frames still move after
    /// `max_rounds` rounds (something circulates).
    fn pump(&mut self, radios: &[Radio], max_rounds: usize) -> Vec<usize> {
        let mut crossed = vec![0; radios.len()];
        for _ in 0..max_rounds {
            let mut moved = false;
            for (r, &((a, da), (b, db))) in radios.iter().enumerate() {
                for ((from, df), (to, dt)) in [((a, da), (b, db)), ((b, db), (a, da))] {
                    for frame in self.take(from, df) {
                        crossed[r] += 1;
                        moved = true;
                        self.receive(to, dt, &frame);
                    }
                }
            }
            if !moved {
                for ac in &self.fleet {
                    for d in 0..D {
                        let stats = ac.downlink.stats(d).unwrap();
                        assert!(stats.is_balanced(), "{stats:?}");
                    }
                }
                return crossed;
            }
        }
        panic!("frames still moving after {max_rounds} rounds");
    }
}

fn count(ac: &Aircraft, source: u8, msg: (u8, u8)) -> usize {
    ac.delivered
        .lock()
        .unwrap()
        .iter()
        .filter(|&&(s, c, i)| (s, (c, i)) == (source, msg))
        .count()
}

const BLOCK: (u8, u8) = (Block::CLASS_ID, Block::ID);

#[test]
fn broadcast_is_delivered_once_and_a_loop_does_not_circulate() {
    // 7 and 8 each have the other as their default route; 7 reaches the ground by an
    // explicit route.
    static TABLE_7: [(u8, Targets); 1] = [(GROUND_ID, Targets::only(0))];
    let a7 = aircraft(7, &TABLE_7, Targets::only(1), Targets::ALL, 8192);
    let a8 = aircraft(8, &[], Targets::only(0), Targets::ALL, 8192);
    let mut fleet = Pumped::new(&[&a7, &a8]);
    let link_78: Radio = ((0, 1), (1, 0));
    let block = |dest| {
        v2_frame(
            &Block {
                block_id: 1,
                ac_id: dest,
            },
            GROUND_ID,
            dest,
        )
    };

    // A broadcast from the ground: delivered to 7 and to 8, once each.
    fleet.receive(0, 0, &block(BROADCAST_ID));
    let crossed = fleet.pump(&[link_78], 10);
    assert_eq!(crossed, [1], "7 -> 8 once, never back");
    assert_eq!(count(&a7, GROUND_ID, BLOCK), 1);
    assert_eq!(count(&a8, GROUND_ID, BLOCK), 1);
    assert!(fleet.take(0, 0).is_empty(), "not back to the ground");

    // A frame for an aircraft nobody knows: 7 sends it on its default route (8), 8's
    // default route leads back where it came from: it stops there.
    fleet.receive(0, 0, &block(9));
    assert_eq!(fleet.pump(&[link_78], 10), [1]);
    assert_eq!(a8.relay.stats().no_route, 1);
    // 8 sending to 9 itself: 7's route for 9 is the link it came from.
    a8.downlink
        .send_with(
            &Block {
                block_id: 2,
                ac_id: 9,
            },
            SendOptions::new().to(9).priority(100),
        )
        .unwrap();
    assert_eq!(fleet.pump(&[link_78], 10), [1]);
    assert_eq!(a7.relay.stats().no_route, 1);
    // A broadcast from 8 reaches 7 and the ground, and not 8 again.
    a8.downlink
        .send_with(
            &Block {
                block_id: 3,
                ac_id: 0,
            },
            SendOptions::new().to(BROADCAST_ID).priority(100),
        )
        .unwrap();
    assert_eq!(fleet.pump(&[link_78], 10), [1]);
    assert_eq!(count(&a7, 8, BLOCK), 1);
    assert_eq!(fleet.take(0, 0).len(), 1, "on to the ground");
    assert_eq!(count(&a8, 8, BLOCK), 0);
    assert_eq!(a8.relay.stats().own_source, 0, "it never came back");
    for ac in [&a7, &a8] {
        assert_eq!(ac.relay.stats().reverse_path, 0);
        assert_eq!(ac.relay.stats().malformed, 0);
    }
}

#[test]
fn a_broadcast_source_is_refused_so_nothing_circulates_on_a_ring() {
    // Three aircraft in a triangle of links, each with its two neighbours routed
    // directly: 7 (0: to 8, 1: to 9), 8 (0: to 7, 1: to 9), 9 (0: to 7, 1: to 8).
    static TABLE_7: [(u8, Targets); 2] = [(8, Targets::only(0)), (9, Targets::only(1))];
    static TABLE_8: [(u8, Targets); 2] = [(7, Targets::only(0)), (9, Targets::only(1))];
    static TABLE_9: [(u8, Targets); 2] = [(7, Targets::only(0)), (8, Targets::only(1))];
    let a7 = aircraft(7, &TABLE_7, Targets::only(0), Targets::ALL, 8192);
    let a8 = aircraft(8, &TABLE_8, Targets::only(0), Targets::ALL, 8192);
    let a9 = aircraft(9, &TABLE_9, Targets::only(0), Targets::ALL, 8192);
    let mut fleet = Pumped::new(&[&a7, &a8, &a9]);
    let ring: [Radio; 3] = [((0, 0), (1, 0)), ((1, 1), (2, 1)), ((2, 0), (0, 1))];

    // A broadcast PING from 8, arriving at 7 from 8: delivered to 7, and the copy 7
    // forwards to 9 stops there at the reverse-path rule (9 hears 8 directly).
    fleet.receive(0, 0, &v2_frame(&Ping, 8, BROADCAST_ID));
    let crossed = fleet.pump(&ring, 20);
    assert_eq!(count(&a7, 8, (Ping::CLASS_ID, Ping::ID)), 1);
    assert_eq!(count(&a9, 8, (Ping::CLASS_ID, Ping::ID)), 0);
    assert_eq!(a9.relay.stats().reverse_path, 1);
    assert_eq!(crossed[2], 1, "7 -> 9 once");

    // The same frame claiming the broadcast id as its source: every route leads back to
    // 0xFF, so without the rule it would go round forever (and be answered on each lap).
    for ac in [&a7, &a8, &a9] {
        ac.delivered.lock().unwrap().clear();
    }
    fleet.receive(0, 0, &v2_frame(&Ping, BROADCAST_ID, BROADCAST_ID));
    fleet.receive(0, 0, &v2_frame(&Ping, BROADCAST_ID, 7));
    let crossed = fleet.pump(&ring, 20);
    assert_eq!(crossed, [0, 0, 0], "nothing forwarded, nothing answered");
    assert_eq!(a7.relay.stats().broadcast_source, 2);
    assert_eq!(a7.relay.stats().refused(), 2);
    assert!(
        a7.delivered.lock().unwrap().is_empty(),
        "not delivered to 7"
    );
}

#[test]
fn a_ring_of_misconfigured_defaults_stops_every_frame() {
    // Three relays in a ring, each with the next as its default route for everything
    // (the ground included): 7 -> 8 -> 9 -> 7. Device 0 of each leads to the next, device
    // 1 to the previous.
    let a7 = aircraft(7, &[], Targets::only(0), Targets::ALL, 8192);
    let a8 = aircraft(8, &[], Targets::only(0), Targets::ALL, 8192);
    let a9 = aircraft(9, &[], Targets::only(0), Targets::ALL, 8192);
    let mut fleet = Pumped::new(&[&a7, &a8, &a9]);
    let ring: [Radio; 3] = [((0, 0), (1, 1)), ((1, 0), (2, 1)), ((2, 0), (0, 1))];

    // Each sends a message to an unknown aircraft and a broadcast.
    for ac in [&a7, &a8, &a9] {
        ac.downlink
            .send_with(
                &Block {
                    block_id: 1,
                    ac_id: 5,
                },
                SendOptions::new().to(5).priority(100),
            )
            .unwrap();
        ac.downlink
            .send_with(
                &Block {
                    block_id: 2,
                    ac_id: 0,
                },
                SendOptions::new().to(BROADCAST_ID).priority(100),
            )
            .unwrap();
    }
    let crossed = fleet.pump(&ring, 20);
    // Every frame made at most one hop past its sender before a rule stopped it.
    assert!(crossed.iter().sum::<usize>() <= 3 * 2 * 3, "{crossed:?}");
    for (i, ac) in [&a7, &a8, &a9].iter().enumerate() {
        let r = ac.relay.stats();
        println!("aircraft {}: {r:?}", ac.id);
        // Each other aircraft's broadcast is delivered exactly once (the copy that
        // came the other way round was refused by the reverse-path rule).
        for other in [7u8, 8, 9].into_iter().filter(|&o| o != ac.id) {
            assert_eq!(count(ac, other, BLOCK), 1, "aircraft {i} from {other}");
        }
        assert_eq!(count(ac, ac.id, BLOCK), 0, "nobody hears itself");
    }
    let refused: u32 = [&a7, &a8, &a9]
        .iter()
        .map(|ac| ac.relay.stats().refused())
        .sum();
    assert!(refused > 0);
}

#[test]
fn hostile_frames_are_counted_and_never_forwarded() {
    let a7 = relay_7();
    let a8 = leaf_8();
    let mut fleet = Pumped::new(&[&a7, &a8]);

    // A frame claiming to come from 7 itself, for 8 and for 7.
    fleet.receive(0, 0, &v2_frame(&Ping, 7, 8));
    fleet.receive(0, 0, &v2_frame(&Ping, 7, 7));
    // A destination with no route but back: 7's default route is the radio it came in on.
    fleet.receive(0, 0, &v2_frame(&Ping, GROUND_ID, 42));
    // A frame from 8 arriving on the ground radio: not our way back to 8.
    fleet.receive(0, 0, &v2_frame(&Ping, 8, GROUND_ID));
    // A SETTING for 8 one byte too long, and a PAYLOAD whose array claims more bytes
    // than the frame has.
    let long = setting(8, 0, 1.0);
    let fields = &mut long[6..long.len() - 2].to_vec();
    fields.push(0xEE);
    let long = raw_v2(GROUND_ID, 8, Setting::CLASS_ID, Setting::ID, fields);
    fleet.receive(0, 0, &long);
    let short_array = raw_v2(
        8,
        GROUND_ID,
        Payload::CLASS_ID,
        Payload::ID,
        &[200, 1, 2, 3],
    );
    fleet.receive(0, 1, &short_array);
    // An unknown message for 8 is forwarded at the relay priority.
    fleet.receive(0, 0, &raw_v2(GROUND_ID, 8, 2, 250, &[1, 2, 3]));

    let r = a7.relay.stats();
    assert_eq!(r.own_source, 2, "{r:?}");
    assert_eq!(r.no_route, 1, "{r:?}");
    assert_eq!(r.reverse_path, 1, "{r:?}");
    assert_eq!(r.malformed, 2, "{r:?}");
    assert_eq!(r.forwarded, 1, "{r:?}");
    assert!(fleet.take(0, 0).is_empty(), "nothing back to the ground");
    let to_8 = fleet.take(0, 1);
    assert_eq!(to_8, [raw_v2(GROUND_ID, 8, 2, 250, &[1, 2, 3])]);
    let link = a7.downlink.stats(1).unwrap();
    assert_eq!(
        link.relayed.levels[pprz_messages::priority::level(RELAY_PRIORITY)].sent,
        1
    );
    assert!(
        a7.delivered.lock().unwrap().is_empty(),
        "nothing delivered to 7"
    );
}

#[test]
fn random_frames_never_panic_and_are_all_accounted_for() {
    let a7 = relay_7();
    let a8 = leaf_8();
    let mut fleet = Pumped::new(&[&a7, &a8]);
    let mut rng = pprz_test_support::rng::Rng::new(15);
    let mut for_others = 0u32; // for others, or from "us" or from "everyone"
    for _ in 0..5_000 {
        let source = [0, 7, 8, 9, 255][rng.below(5)];
        let dest = [0, 7, 8, 9, 255][rng.below(5)];
        let class = rng.below(16) as u8;
        let id = [
            Setting::ID,
            Block::ID,
            Ping::ID,
            Payload::ID,
            rng.below(256) as u8,
        ][rng.below(5)];
        let len = rng.below(40);
        let fields: Vec<u8> = (0..len).map(|_| rng.below(256) as u8).collect();
        if dest != 7 || source == 7 || source == 255 {
            for_others += 1;
        }
        fleet.receive(0, rng.below(2), &raw_v2(source, dest, class, id, &fields));
        if rng.chance(10) {
            fleet.take(0, 0);
            fleet.take(0, 1);
        }
    }
    let s = a7.datalink.stats();
    let r = a7.relay.stats();
    println!("{s:?}");
    // Every frame for another aircraft or broadcast (or claiming to be ours or 0xFF's) was
    // forwarded or refused, by reason, exactly once (a broadcast always has another
    // device to go to here).
    assert_eq!(r.forwarded + r.refused(), for_others, "{r:?}");
    assert!(r.forwarded > 0 && r.no_route > 0 && r.reverse_path > 0 && r.malformed > 0);
    assert!(r.own_source > 0 && r.broadcast_source > 0);
    for d in 0..D {
        assert!(a7.downlink.stats(d).unwrap().is_balanced());
    }
    let _ = a8;
}

/// A PPRZ v2 frame with any header and fields (the transport's encoder: any class below
/// 16, any fields).
fn raw_v2(source: u8, dest: u8, class: u8, msg_id: u8, fields: &[u8]) -> Vec<u8> {
    let mut out = [0u8; 300];
    let meta = TxMeta::new(MsgHeader::new(source, dest, class, msg_id));
    let len = PprzV2::new().encode(&meta, fields, &mut out).unwrap();
    out[..len].to_vec()
}
