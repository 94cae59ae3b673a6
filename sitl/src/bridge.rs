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

use std::sync::atomic::{AtomicU64, Ordering};

use embassy_executor::Spawner;
use embassy_sync::mutex::Mutex;
use embassy_time::{Duration, Instant, Timer};
use embedded_io_async::{Read, Write};
use pprz_devices::host::{HostDevice, HostRx, HostTx};
use pprz_devices::sim::{SimRx, SimTx};
use pprz_example_app::{AC_ID, M};
use pprz_telemetry::pprz_transports::{AnyTransport, Decoder, Encoder, MAX_FRAME_LEN, PprzV2};

use crate::fleet::MAX_FLEET;
use crate::options::TransportArg;
use crate::radio::{RADIO_RING, Radio};
use crate::record;

/// Uplink datagrams the bridge's UDP input dropped, full (the radio's uplink carried
/// less than the ground sent): read by [`uplink_datagrams_dropped`].
static UPLINK_DROPPED: AtomicU64 = AtomicU64::new(0);

/// Uplink datagrams the radios' ground end dropped so far because its UDP input was
/// full: they never went up a radio.
pub fn uplink_datagrams_dropped() -> u64 {
    UPLINK_DROPPED.load(Ordering::Relaxed)
}

/// One radio to the ground: the aircraft at its other end and the radio. An aircraft
/// with two radios would have two of these, with its id in both.
#[derive(Clone, Copy)]
pub struct GroundRadio {
    /// The aircraft it carries the frames of (and those it relays).
    pub ac: u8,
    /// The radio (endpoint A the aircraft, B the ground).
    pub radio: &'static Radio,
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

/// Spawns the bridge of `radios` to `udp`: a downlink task per radio and the uplink
/// gateway.
pub fn spawn(spawner: Spawner, radios: &[GroundRadio], udp: HostDevice, mode: BridgeMode) {
    let (udp_rx, udp_tx) = udp.split();
    let out: &'static UdpOut = Box::leak(Box::new(Mutex::new(udp_tx)));
    let whole_frames = radios.len() > 1;
    let mut uplinks = Vec::with_capacity(radios.len());
    for r in radios {
        let (_, ground) = r.radio.endpoints();
        let (rx, tx) = ground.split();
        spawner.spawn(downlink_bridge(rx, out, mode, whole_frames).unwrap());
        uplinks.push((r.ac, tx));
    }
    spawner.spawn(uplink_gateway(udp_rx, uplinks, mode).unwrap());
}

/// The ground end of one radio, down: decodes what comes down (for the record, and to
/// re-frame XBee as PPRZ v2 for UDP) and sends it on to the ground's UDP port, as it
/// came or (`whole_frames`) frame by frame.
#[embassy_executor::task(pool_size = MAX_FLEET as usize)]
async fn downlink_bridge(
    mut radio_rx: SimRx<'static, M, RADIO_RING>,
    udp: &'static UdpOut,
    mode: BridgeMode,
    whole_frames: bool,
) {
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
            // Secure frames are opened by the ground, which records them.
            if !mode.secure {
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
#[embassy_executor::task]
async fn uplink_gateway(
    mut udp_rx: HostRx,
    mut radios: Vec<(u8, SimTx<'static, M, RADIO_RING>)>,
    mode: BridgeMode,
) {
    let radio_transport = mode.transport();
    let raw = !mode.xbee && radios.len() == 1;
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
            let carried = radios.iter().any(|(ac, _)| Some(*ac) == to);
            for (ac, tx) in &mut radios {
                if !carried || Some(*ac) == to {
                    let _ = tx.write_all(bytes).await;
                }
            }
        }
        if raw && let Some((_, tx)) = radios.first_mut() {
            let _ = tx.write_all(&buf[..n]).await;
        }
    }
}
