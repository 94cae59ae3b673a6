//! The ground end of the radio, bridged to UDP like Paparazzi's link agent: telemetry
//! goes on to the ground's port, uplink frames come from the bridge's port, PPRZ v2 on
//! UDP whatever the radio speaks.

use std::sync::atomic::{AtomicU64, Ordering};

use embassy_time::{Duration, Instant, Timer};
use embedded_io_async::{Read, Write};
use pprz_devices::host::HostDevice;
use pprz_devices::sim::SimEnd;
use pprz_example_app::{AC_ID, M};
use pprz_telemetry::pprz_transports::{AnyTransport, Decoder, Encoder, MAX_FRAME_LEN, PprzV2};

use crate::options::TransportArg;
use crate::radio::RADIO_RING;
use crate::record;

/// Uplink datagrams the bridge's UDP input dropped, full (the radio's uplink carried
/// less than the ground sent): read by [`uplink_datagrams_dropped`].
static UPLINK_DROPPED: AtomicU64 = AtomicU64::new(0);

/// Uplink datagrams the radio's ground end dropped so far because its UDP input was
/// full: they never went up the radio.
pub fn uplink_datagrams_dropped() -> u64 {
    UPLINK_DROPPED.load(Ordering::Relaxed)
}

/// The ground end of the radio, bridged to UDP both ways: decodes what comes down (for
/// the record, and to re-frame XBee as PPRZ v2 for UDP) and what goes up (PINGs, and
/// XBee framing of the uplink).
#[embassy_executor::task]
pub async fn ground_bridge(
    ground: SimEnd<'static, M, RADIO_RING>,
    udp: HostDevice,
    xbee: bool,
    secure: bool,
) {
    let (mut radio_rx, mut radio_tx) = ground.split();
    let (mut udp_rx, mut udp_tx) = udp.split();
    let radio_transport = if xbee {
        TransportArg::Xbee
    } else {
        TransportArg::Pprz2
    }
    .any();
    let down = async {
        let mut decoder: Decoder<AnyTransport> = Decoder::new(radio_transport);
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
                if !secure {
                    record::received(f.source(), f.class(), f.msg_id(), f.payload(), now);
                }
                if xbee && let Ok(len) = v2.encode(&f.tx_meta(), f.payload(), &mut frame) {
                    out.extend_from_slice(&frame[..len]);
                }
            }
            // PPRZ v2 goes on as it came (damaged frames too, for the ground to count).
            let bytes = if xbee { &out[..] } else { &buf[..n] };
            if !bytes.is_empty() {
                let _ = udp_tx.write_all(bytes).await;
            }
        }
    };
    let up = async {
        let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
        let mut buf = [0u8; 256];
        let mut frame = [0u8; MAX_FRAME_LEN];
        let mut out = Vec::new();
        loop {
            let read = udp_rx.read(&mut buf).await;
            UPLINK_DROPPED.store(udp_rx.stats().rx_dropped_datagrams, Ordering::Relaxed);
            match read {
                Ok(n) if n > 0 => {
                    let now = Instant::now();
                    let mut input = &buf[..n];
                    out.clear();
                    while let Some(f) = decoder.feed(&mut input) {
                        if !secure {
                            let to = f.destination().unwrap_or(AC_ID);
                            record::uplink(to, f.class(), f.msg_id(), f.payload(), now);
                        }
                        if xbee
                            && let Ok(len) =
                                radio_transport.encode(&f.tx_meta(), f.payload(), &mut frame)
                        {
                            out.extend_from_slice(&frame[..len]);
                        }
                    }
                    let bytes = if xbee { &out[..] } else { &buf[..n] };
                    let _ = radio_tx.write_all(bytes).await;
                }
                _ => Timer::after(Duration::from_millis(10)).await,
            }
        }
    };
    embassy_futures::join::join(down, up).await;
}
