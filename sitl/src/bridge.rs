//! The ground ends of the radios, bridged to one UDP socket like Paparazzi's link agent:
//! telemetry from every radio goes on to the ground's port, uplink frames come from the
//! bridge's port and go up the radio of the aircraft they are for, PPRZ v2 on UDP
//! whatever the radios speak.
//!
//! Each radio to the ground has a downlink task of its own ([`downlink_bridge`]); they
//! share the UDP socket's sending half. One task reads the uplink ([`uplink_gateway`])
//! and holds every radio's ground-side writer. With one radio, the bytes go on as they
//! came (damaged frames too, for the ground to count); with several, whole frames only,
//! so that the frames of two radios never mix in the ground's byte stream.
//!
//! With `--radios 2` there are two links, each a UDP socket of its own: link 0 (radio
//! A of every aircraft: `--ground`, `--uplink`) and link 1 (radio B: `--ground-b`,
//! `--uplink-b`). `--frame-loss` drops whole frames here, each frame drawn apart on each
//! radio and direction ([`Loss`]). The record counts each message that reached a
//! radio's ground end once, however many radios brought it ([`Arrivals`]).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{LazyLock, Mutex as StdMutex, MutexGuard};

use embassy_executor::Spawner;
use embassy_sync::mutex::Mutex;
use embassy_time::{Duration, Instant, Timer};
use embedded_io_async::{Read, Write};
use pprz_devices::host::{HostDevice, HostRx, HostTx};
use pprz_devices::rng::SplitMix64;
use pprz_devices::sim::{SimRx, SimTx};
use pprz_example_app::{AC_ID, M};
use pprz_ground::gateway::dedup::{DEFAULT_CAPACITY, DEFAULT_WINDOW, Dedup};
use pprz_telemetry::pprz_transports::{AnyTransport, Decoder, Encoder, MAX_FRAME_LEN, PprzV2};

use crate::fleet::{self, MAX_FLEET};
use crate::options::TransportArg;
use crate::radio::{RADIO_RING, Radio};
use crate::record;

/// Uplink datagrams the bridge's UDP input dropped, full (the radio's uplink carried
/// less than the ground sent): read by [`uplink_datagrams_dropped`].
static UPLINK_DROPPED: AtomicU64 = AtomicU64::new(0);

/// Frames `--frame-loss` dropped, down (aircraft to ground) and up.
static LOST: [AtomicU64; 2] = [AtomicU64::new(0), AtomicU64::new(0)];

/// Uplink datagrams the radios' ground end dropped so far because its UDP input was
/// full: they never went up a radio.
pub fn uplink_datagrams_dropped() -> u64 {
    UPLINK_DROPPED.load(Ordering::Relaxed)
}

/// Frames `--frame-loss` dropped so far: (down, up), every radio together.
pub fn frames_lost() -> (u64, u64) {
    (
        LOST[0].load(Ordering::Relaxed),
        LOST[1].load(Ordering::Relaxed),
    )
}

/// One radio to the ground: the aircraft at its other end, the link it belongs to and
/// the radio. An aircraft with two radios has two of these, with its id in both.
#[derive(Clone, Copy)]
pub struct GroundRadio {
    /// The aircraft it carries the frames of (and those it relays).
    pub ac: u8,
    /// The ground's link it arrives on: 0 (radio A, `--ground`) or 1 (radio B).
    pub link: usize,
    /// Its index among the run's radios, from which its seeds derive.
    pub seed_index: u8,
    /// The radio (endpoint A the aircraft, B the ground).
    pub radio: &'static Radio,
}

/// `--frame-loss` on one radio in one direction: each frame lost with probability `p`,
/// drawn from a generator of its own.
struct Loss {
    p: f64,
    rng: SplitMix64,
    /// 0 down, 1 up: where the losses are counted.
    direction: usize,
}

impl Loss {
    /// The losses of radio `seed_index` going `up` (or down).
    fn new(mode: BridgeMode, seed_index: u8, up: bool) -> Self {
        Self {
            p: mode.frame_loss,
            rng: SplitMix64::new(fleet::loss_seed(mode.seed, seed_index, up)),
            direction: usize::from(up),
        }
    }

    /// Whether the next frame is lost (counted).
    fn lose(&mut self) -> bool {
        if self.p <= 0.0 {
            return false;
        }
        // 53 random bits: a uniform draw in [0, 1).
        let u = (self.rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
        let lost = u < self.p;
        if lost {
            LOST[self.direction].fetch_add(1, Ordering::Relaxed);
        }
        lost
    }
}

/// The messages that reached the radios' ground ends, each counted once however many
/// radios brought it (the gateway's merging: [`Dedup`]): before the frame loss
/// (`aired`, what the aircraft got through the air) and after it (recorded as
/// received).
pub struct Arrivals {
    aired: Dedup,
    kept: Dedup,
    /// Per aircraft: messages that reached a radio's ground end before the frame loss,
    /// counted once.
    pub aired_by: [u64; 256],
    /// Per aircraft: messages kept after the frame loss, counted once.
    pub kept_by: [u64; 256],
}

static ARRIVALS: LazyLock<StdMutex<Arrivals>> = LazyLock::new(|| {
    StdMutex::new(Arrivals {
        aired: Dedup::new(2, DEFAULT_WINDOW, DEFAULT_CAPACITY),
        kept: Dedup::new(2, DEFAULT_WINDOW, DEFAULT_CAPACITY),
        aired_by: [0; 256],
        kept_by: [0; 256],
    })
});

/// The arrivals so far (a panic elsewhere does not make them unreadable).
pub fn arrivals() -> MutexGuard<'static, Arrivals> {
    ARRIVALS
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

impl Arrivals {
    /// A message of `source` with `key` fields reached link `link`'s ground end at
    /// `now` (seconds): counted once in `aired`; then, unless `lost`, once in `kept`.
    /// Whether it is a first arrival after the loss (to record).
    fn arrived(
        &mut self,
        now: f64,
        link: usize,
        source: u8,
        key: (u8, u8, &[u8]),
        lost: bool,
    ) -> bool {
        let k = self.aired.key(source, key.0, key.1, key.2);
        if self.aired.check(now, link, source, k).delivered() {
            self.aired_by[usize::from(source)] += 1;
        }
        if lost {
            self.kept.expire(now);
            return false;
        }
        let first = self.kept.check(now, link, source, k).delivered();
        if first {
            self.kept_by[usize::from(source)] += 1;
        }
        first
    }
}

/// The UDP socket's sending half, shared by the radios' downlink tasks.
type UdpOut = Mutex<M, HostTx>;

/// What the radios speak and whether the link is secure, for every bridge task.
#[derive(Clone, Copy)]
pub struct BridgeMode {
    /// XBee API frames on the radios (PPRZ v2 otherwise).
    pub xbee: bool,
    /// `--secure`: the frames are sealed (the ground records them once opened).
    pub secure: bool,
    /// `--frame-loss`: the probability that a frame is lost, each radio and direction.
    pub frame_loss: f64,
    /// `--seed`: the losses' seeds derive from it.
    pub seed: u64,
}

impl BridgeMode {
    /// The radios' transport.
    fn transport(self) -> AnyTransport {
        if self.xbee {
            TransportArg::Xbee
        } else {
            TransportArg::Pprz2
        }
        .any()
    }
}

/// Spawns the bridge of `radios` to the UDP sockets of their links (`udp[link]`): a
/// downlink task per radio and an uplink gateway per link.
pub fn spawn(spawner: Spawner, radios: &[GroundRadio], udp: Vec<HostDevice>, mode: BridgeMode) {
    for (link, udp) in udp.into_iter().enumerate() {
        let on_link: Vec<&GroundRadio> = radios.iter().filter(|r| r.link == link).collect();
        let (udp_rx, udp_tx) = udp.split();
        let out: &'static UdpOut = Box::leak(Box::new(Mutex::new(udp_tx)));
        let whole_frames = on_link.len() > 1 || mode.frame_loss > 0.0;
        let mut uplinks = Vec::with_capacity(on_link.len());
        for r in on_link {
            let (_, ground) = r.radio.endpoints();
            let (rx, tx) = ground.split();
            let end = GroundEnd {
                link,
                whole_frames,
                loss: Loss::new(mode, r.seed_index, false),
            };
            spawner.spawn(downlink_bridge(rx, out, mode, end).unwrap());
            uplinks.push((r.ac, tx, Loss::new(mode, r.seed_index, true)));
        }
        spawner.spawn(uplink_gateway(udp_rx, uplinks, mode).unwrap());
    }
}

/// One radio's ground end, down: its link, whether it sends whole frames only, and its
/// frame loss.
struct GroundEnd {
    link: usize,
    whole_frames: bool,
    loss: Loss,
}

/// The ground end of one radio, down: decodes what comes down (for the record, and to
/// re-frame XBee as PPRZ v2 for UDP), drops the frames `--frame-loss` loses, and sends
/// the rest on to its link's UDP port, as it came or (`whole_frames`) frame by frame.
#[embassy_executor::task(pool_size = 2 * MAX_FLEET as usize)]
async fn downlink_bridge(
    mut radio_rx: SimRx<'static, M, RADIO_RING>,
    udp: &'static UdpOut,
    mode: BridgeMode,
    mut end: GroundEnd,
) {
    let whole_frames = end.whole_frames;
    let mut decoder: Decoder<AnyTransport> = Decoder::new(mode.transport());
    let v2 = PprzV2::new();
    let mut buf = [0u8; 256];
    let mut frame = [0u8; MAX_FRAME_LEN];
    let mut out = Vec::new();
    loop {
        let Ok(n) = radio_rx.read(&mut buf).await;
        let now = Instant::now();
        let mut input = &buf[..n];
        out.clear();
        while let Some(f) = decoder.feed(&mut input) {
            let lost = end.loss.lose();
            let key = (f.class(), f.msg_id(), f.payload());
            let first = arrivals().arrived(seconds(now), end.link, f.source(), key, lost);
            if lost {
                continue;
            }
            // Secure frames are opened by the ground, which records them.
            if !mode.secure && first {
                record::received(f.source(), f.class(), f.msg_id(), f.payload(), now);
            }
            if mode.xbee {
                if let Ok(len) = v2.encode(&f.tx_meta(), f.payload(), &mut frame) {
                    out.extend_from_slice(&frame[..len]);
                }
            } else if whole_frames {
                out.extend_from_slice(f.raw());
            }
        }
        // PPRZ v2 from one radio goes on as it came (damaged frames too, for the
        // ground to count).
        let bytes = if mode.xbee || whole_frames {
            &out[..]
        } else {
            &buf[..n]
        };
        if !bytes.is_empty() {
            let _ = udp.lock().await.write_all(bytes).await;
        }
    }
}

/// The uplink: each frame from the ground's UDP goes up the radio(s) of the aircraft it
/// is for, and up every radio when no radio carries its destination (broadcast, or an
/// aircraft behind a relay). With one radio, the bytes go up as they came.
#[embassy_executor::task(pool_size = 2)]
async fn uplink_gateway(
    mut udp_rx: HostRx,
    mut radios: Vec<(u8, SimTx<'static, M, RADIO_RING>, Loss)>,
    mode: BridgeMode,
) {
    let radio_transport = mode.transport();
    let raw = !mode.xbee && radios.len() == 1 && mode.frame_loss <= 0.0;
    let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
    let mut buf = [0u8; 256];
    let mut encoded = [0u8; MAX_FRAME_LEN];
    loop {
        let read = udp_rx.read(&mut buf).await;
        UPLINK_DROPPED.store(udp_rx.stats().rx_dropped_datagrams, Ordering::Relaxed);
        let n = match read {
            Ok(n) if n > 0 => n,
            _ => {
                Timer::after(Duration::from_millis(10)).await;
                continue;
            }
        };
        let now = Instant::now();
        let mut input = &buf[..n];
        while let Some(f) = decoder.feed(&mut input) {
            if !mode.secure {
                let to = f.destination().unwrap_or(AC_ID);
                record::uplink(to, f.class(), f.msg_id(), f.payload(), now);
            }
            if raw {
                continue;
            }
            let bytes = if mode.xbee {
                match radio_transport.encode(&f.tx_meta(), f.payload(), &mut encoded) {
                    Ok(len) => &encoded[..len],
                    Err(_) => continue,
                }
            } else {
                f.raw()
            };
            let to = f.destination();
            let carried = radios.iter().any(|(ac, _, _)| Some(*ac) == to);
            for (ac, tx, loss) in &mut radios {
                if (!carried || Some(*ac) == to) && !loss.lose() {
                    let _ = tx.write_all(bytes).await;
                }
            }
        }
        if raw && let Some((_, tx, _)) = radios.first_mut() {
            let _ = tx.write_all(&buf[..n]).await;
        }
    }
}

/// Seconds of an instant of the simulation's clock.
fn seconds(t: Instant) -> f64 {
    t.as_micros() as f64 / 1e6
}
