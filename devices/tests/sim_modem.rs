//! The simulated radio as a modem, under embassy-time's mock clock: serial rate versus
//! air rate, modem overfill (drop or CTS), UART and air busy time, and the XBee API
//! modem (RX frames, transmit statuses, retries, malformed frames).

mod common;

use common::{mock_time, run};
use embassy_futures::join::join;
use embassy_futures::select::{Either, select};
use embassy_sync::blocking_mutex::raw::NoopRawMutex;
use embassy_time::{Duration, Instant, MockDriver, Timer};
use embedded_io_async::{Read, Write};
use pprz_devices::sim::{
    Direction, Overflow, SimConfig, SimLink, SimStats, XBeeModem, XBeeVariant, xbee,
};
use pprz_transports::{MsgHeader, TxMeta, XBee24, XBee24Decoder, write_frame};

const US: Duration = Duration::from_micros(1);
const STEP: Duration = Duration::from_micros(100);

fn at_us(us: u64) -> Instant {
    Instant::from_micros(us)
}

/// Reads everything that arrives until `until`; returns each byte with its read time.
async fn read_until<R: Read>(rx: &mut R, until: Instant) -> Vec<(u8, Instant)> {
    let mut got = Vec::new();
    let mut buf = [0u8; 64];
    loop {
        match select(rx.read(&mut buf), Timer::at(until)).await {
            Either::First(n) => {
                let n = n.unwrap();
                let now = Instant::now();
                got.extend(buf[..n].iter().map(|&b| (b, now)));
            }
            Either::Second(()) => return got,
        }
    }
}

fn bytes(got: &[(u8, Instant)]) -> Vec<u8> {
    got.iter().map(|&(b, _)| b).collect()
}

/// Writes `data` and returns when the write completed.
async fn write_at<W: Write>(tx: &mut W, data: &[u8]) -> Instant {
    tx.write_all(data).await.unwrap();
    Instant::now()
}

#[test]
fn serial_rate_paces_the_write_and_air_rate_the_arrivals() {
    let _t = mock_time();
    // UART 1000 bytes/s (1 ms a byte), air 500 bytes/s (2 ms a byte), 5 ms latency.
    let config = SimConfig::new(500)
        .serial_rate(1000)
        .latency(Duration::from_millis(5))
        .buffer(64);
    let link = SimLink::<NoopRawMutex, 256>::new(config);
    let (mut a, mut b) = link.endpoints();
    let data: Vec<u8> = (1..=10).collect();
    let (done, got) = run(
        join(
            async {
                let done = write_at(&mut a, &data).await;
                // While the write was under way: 10 ms of UART, 9 ms of air (the first
                // byte entered the modem at 1 ms).
                let s = link.stats(Direction::AToB);
                assert_eq!((s.serial_busy_us, s.air_busy_us), (10_000, 9_000));
                done
            },
            read_until(&mut b, at_us(40_000)),
        ),
        STEP,
        1000,
    );
    assert_eq!(done, at_us(10_000), "the write lasts n / serial_rate");
    assert_eq!(bytes(&got), data);
    // Byte k enters the modem at (k + 1) ms; the air is busy from 1 ms on, 2 ms a byte,
    // so byte k is sent at 1 + 2 (k + 1) ms and read 5 ms later.
    for (k, &(_, t)) in got.iter().enumerate() {
        assert_eq!(t, at_us(1000 + 2000 * (k as u64 + 1) + 5000), "byte {k}");
    }
    let s = link.stats(Direction::AToB);
    assert_eq!((s.serial_busy_us, s.air_busy_us), (10_000, 20_000));
    assert_eq!(s.serial_busy(), Duration::from_millis(10));
    assert_eq!(s.air_busy(), Duration::from_millis(20));
    assert_eq!(
        (s.bytes_written, s.bytes_sent, s.dropped_bytes),
        (10, 10, 0)
    );
}

#[test]
fn rates_that_do_not_divide_the_tick_stay_exact() {
    let _t = mock_time();
    // 57600 baud (5760 bytes/s: 173.6 µs a byte), 4000 bytes/s on the air (250 µs).
    let link =
        SimLink::<NoopRawMutex, 1024>::new(SimConfig::new(4000).serial_rate(5760).buffer(1000));
    let (mut a, _b) = link.endpoints();
    let (done, flushed) = run(
        async {
            let done = write_at(&mut a, &[0x55; 576]).await;
            a.flush().await.unwrap();
            (done, Instant::now())
        },
        US,
        1_000_000,
    );
    // 576 bytes at 5760 bytes/s: 100 ms exactly, whatever the polling.
    assert_eq!(done, at_us(100_000));
    // The air starts when the first byte is in (1/5760 s) and never stops:
    // 1e6/5760 + 576 * 250 = 144 173.6 µs, rounded up to the tick.
    assert_eq!(flushed, at_us(144_174));
    let s = link.stats(Direction::AToB);
    assert_eq!(s.serial_busy_us, 100_000);
    assert_eq!(s.air_busy_us, 144_000);
    assert_eq!((s.bytes_sent, s.dropped_bytes), (576, 0));
}

#[test]
fn coarse_polling_does_not_change_the_timeline() {
    let _t = mock_time();
    let config = SimConfig::new(4000).serial_rate(5760).buffer(1000);
    let link = SimLink::<NoopRawMutex, 1024>::new(config);
    let (mut a, _b) = link.endpoints();
    // Polled every 7 ms: the write is seen complete late, the model is not late.
    run(
        async {
            a.write_all(&[0x55; 576]).await.unwrap();
            a.flush().await.unwrap();
        },
        Duration::from_millis(7),
        1000,
    );
    let s = link.stats(Direction::AToB);
    assert_eq!((s.serial_busy_us, s.air_busy_us), (100_000, 144_000));
}

/// UART 2000 bytes/s (0.5 ms a byte), air 1000 bytes/s (1 ms), modem buffer 100.
const OVERFILL: SimConfig = SimConfig::new(1000).serial_rate(2000).buffer(100);

#[test]
fn drop_mode_overfills_the_modem_and_counts_every_byte() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 2048>::new(OVERFILL);
    let (mut a, mut b) = link.endpoints();
    let data: Vec<u8> = (0..1000u32).map(|i| i as u8).collect();
    let (done, got) = run(
        join(
            async {
                let done = write_at(&mut a, &data).await;
                let s = link.stats(Direction::AToB);
                // Backlogged from the first byte (0.5 ms) to the end of the write
                // (500 ms): the UART was always busy, the air 499.5 ms of 500.
                assert_eq!((s.serial_busy_us, s.air_busy_us), (500_000, 499_500));
                assert!(s.air_busy_us as f64 >= 0.95 * 500_000.0);
                assert_eq!(link.modem_occupancy(Direction::AToB), 100, "full");
                done
            },
            read_until(&mut b, at_us(700_000)),
        ),
        STEP,
        10_000,
    );
    assert_eq!(done, at_us(500_000), "a modem does not slow the UART down");
    // Byte k enters at 0.5 (k + 1) ms, when ceil(k / 2) bytes wait: from byte 199 on the
    // buffer is full every other byte, so the odd bytes from 199 are dropped.
    let expected: Vec<u8> = data
        .iter()
        .enumerate()
        .filter(|&(k, _)| k < 199 || k % 2 == 0)
        .map(|(_, &b)| b)
        .collect();
    assert_eq!(bytes(&got), expected);
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (
            s.bytes_written,
            s.bytes_sent,
            s.dropped_bytes,
            s.overrun_bytes
        ),
        (1000, 599, 401, 0)
    );
    assert_eq!(s.bytes_written, s.bytes_delivered + s.dropped_bytes);
    assert_eq!(s.air_busy_us, 599_000);
}

#[test]
fn wait_mode_stops_the_uart_and_never_drops() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 2048>::new(OVERFILL.overflow(Overflow::Wait));
    let (mut a, mut b) = link.endpoints();
    let data: Vec<u8> = (0..1000u32).map(|i| i as u8).collect();
    let ((done, flushed), got) = run(
        join(
            async {
                let done = write_at(&mut a, &data).await;
                assert_eq!(link.modem_occupancy(Direction::AToB), 100, "full");
                a.flush().await.unwrap();
                assert_eq!(link.modem_occupancy(Direction::AToB), 0);
                (done, Instant::now())
            },
            read_until(&mut b, at_us(1_100_000)),
        ),
        STEP,
        20_000,
    );
    // Byte k >= 199 waits until byte k - 100 has left (0.5 + k - 99 ms), then takes
    // 0.5 ms: the last one is in at 901 ms.
    assert_eq!(done, at_us(901_000));
    // The air never stopped from 0.5 ms: 1000 bytes later it is 1000.5 ms.
    assert_eq!(flushed, at_us(1_000_500));
    assert_eq!(bytes(&got), data, "nothing dropped, in order");
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (s.bytes_sent, s.dropped_bytes, s.overrun_bytes),
        (1000, 0, 0)
    );
    // The UART worked 500 ms of 901: CTS held it the rest of the time.
    assert_eq!((s.serial_busy_us, s.air_busy_us), (500_000, 1_000_000));
}

#[test]
fn wait_mode_waits_for_the_reader_when_the_ring_is_full() {
    let _t = mock_time();
    let config = SimConfig::new(0).serial_rate(1000).overflow(Overflow::Wait);
    let link = SimLink::<NoopRawMutex, 8>::new(config);
    let (mut a, mut b) = link.endpoints();
    let (done, got) = run(
        join(write_at(&mut a, &[9u8; 20]), async {
            Timer::at(at_us(50_000)).await;
            read_until(&mut b, at_us(100_000)).await
        }),
        STEP,
        2000,
    );
    // 8 bytes fill the ring by 8 ms; the reader empties it at 50 ms, the UART resumes
    // then: 12 more bytes take until 62 ms.
    assert_eq!(done, at_us(62_000));
    assert_eq!(got.len(), 20);
    let s = link.stats(Direction::AToB);
    assert_eq!((s.overrun_bytes, s.serial_busy_us), (0, 20_000));
}

#[test]
fn a_cancelled_write_keeps_the_bytes_that_crossed() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 64>::new(SimConfig::new(0).serial_rate(1000));
    let (mut a, mut b) = link.endpoints();
    let (cut, got) = run(
        async {
            let write = a.write(&[1, 2, 3, 4, 5, 6, 7, 8, 9, 10]);
            let cut = matches!(
                select(write, Timer::at(at_us(5_500))).await,
                Either::Second(())
            );
            // The UART restarts with the next write.
            a.write_all(&[11]).await.unwrap();
            assert_eq!(Instant::now(), at_us(6_500));
            (cut, read_until(&mut b, at_us(10_000)).await)
        },
        STEP,
        1000,
    );
    assert!(cut);
    assert_eq!(bytes(&got), [1, 2, 3, 4, 5, 11]);
    let s = link.stats(Direction::AToB);
    assert_eq!((s.bytes_written, s.serial_busy_us), (6, 6_000));
}

// --- XBee API modem ---

/// A TX16 request (802.15.4).
fn tx16(frame_id: u8, dest: u16, options: u8, rf: &[u8]) -> Vec<u8> {
    let mut fd = vec![xbee::API_TX16, frame_id];
    fd.extend_from_slice(&dest.to_be_bytes());
    fd.push(options);
    fd.extend_from_slice(rf);
    frame(&fd)
}

/// `count` TX16 requests to the ground, frame ids 1 to `count`, request `i` carrying
/// `rf_len` bytes `i`.
fn tx16_run(count: u8, rf_len: usize) -> Vec<u8> {
    (0..count)
        .flat_map(|i| tx16(i + 1, 0x0100, 0, &vec![i; rf_len]))
        .collect()
}

/// An 868 transmit request.
fn tx868(frame_id: u8, dest: u64, options: u8, rf: &[u8]) -> Vec<u8> {
    let mut fd = vec![xbee::API_TX_868, frame_id];
    fd.extend_from_slice(&dest.to_be_bytes());
    fd.extend_from_slice(&[0xFF, 0xFE, 0, options]);
    fd.extend_from_slice(rf);
    frame(&fd)
}

fn frame(frame_data: &[u8]) -> Vec<u8> {
    let mut out = vec![0u8; frame_data.len() + xbee::FRAMING];
    let n = xbee::api_frame(frame_data, &mut out).unwrap();
    assert_eq!(n, out.len());
    out
}

/// Splits a byte stream into API frames' `FRAME_DATA`, checking every checksum; each
/// with the time its last byte was read.
fn api_frames(got: &[(u8, Instant)]) -> Vec<(Vec<u8>, Instant)> {
    let mut frames = Vec::new();
    let mut i = 0;
    while i < got.len() {
        assert_eq!(got[i].0, xbee::START, "frame start at byte {i}");
        let len = usize::from(u16::from_be_bytes([got[i + 1].0, got[i + 2].0]));
        let fd: Vec<u8> = got[i + 3..i + 3 + len].iter().map(|&(b, _)| b).collect();
        let (ck, t) = got[i + 3 + len];
        let sum = fd.iter().fold(ck, |s, &b| s.wrapping_add(b));
        assert_eq!(sum, 0xFF, "checksum of the frame at byte {i}");
        frames.push((fd, t));
        i += len + xbee::FRAMING;
    }
    frames
}

/// XBee 802.15.4 at round numbers: UART 5000 bytes/s (200 µs a byte), air 10 000
/// bytes/s (100 µs) + 10 bytes per transmission, 2 ms latency, 1 ms ACK delay.
fn xbee24() -> XBeeModem {
    XBeeModem::new(XBeeVariant::XBee24)
        .air_overhead(10)
        .ack_delay(Duration::from_millis(1))
}

fn xbee_config(modem: XBeeModem) -> SimConfig {
    SimConfig::new(10_000)
        .serial_rate(5000)
        .latency(Duration::from_millis(2))
        .buffer(202)
        .xbee(modem)
}

/// What the endpoints of an XBee link read during [`exchange`].
struct Exchange {
    /// When A's write completed.
    done: Instant,
    /// What the ground (B) read.
    down: Vec<(u8, Instant)>,
    /// What the aircraft (A) read.
    up: Vec<(u8, Instant)>,
}

/// Writes `downlink` on A (the aircraft) and `uplink` on B (the ground) while both
/// read until `until_us`, polling every [`STEP`] at most `max_steps` times.
fn exchange<const N: usize>(
    link: &SimLink<NoopRawMutex, N>,
    downlink: &[u8],
    uplink: &[u8],
    until_us: u64,
    max_steps: u64,
) -> Exchange {
    let (air, ground) = link.endpoints();
    let (mut air_rx, mut air_tx) = air.split();
    let (mut ground_rx, mut ground_tx) = ground.split();
    let ((done, ()), (down, up)) = run(
        join(
            join(write_at(&mut air_tx, downlink), async {
                ground_tx.write_all(uplink).await.unwrap();
            }),
            join(
                read_until(&mut ground_rx, at_us(until_us)),
                read_until(&mut air_rx, at_us(until_us)),
            ),
        ),
        STEP,
        max_steps,
    );
    Exchange { done, down, up }
}

/// The `FRAME_DATA` of the API frames in `got` (see [`api_frames`]).
fn frame_data(got: &[(u8, Instant)]) -> Vec<Vec<u8>> {
    api_frames(got).into_iter().map(|(fd, _)| fd).collect()
}

#[test]
fn xbee24_rf_data_arrives_as_rx16_frames_and_statuses_come_back() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 1024>::new(xbee_config(xbee24()));
    let rf: Vec<u8> = (100..120).collect();
    let request = tx16(5, 0x0100, 0, &rf);
    assert_eq!(request.len(), 29);
    let Exchange { done, down, up } = exchange(&link, &request, &[], 30_000, 1000);
    // 29 bytes on the UART: 5.8 ms. Then 30 bytes on the air (20 + 10 overhead): 3 ms.
    assert_eq!(done, at_us(5_800));
    let down = api_frames(&down);
    let mut rx16 = vec![xbee::API_RX16, 0x00, 0x01, 40, 0];
    rx16.extend_from_slice(&rf);
    assert_eq!(down, [(rx16, at_us(5_800 + 3_000 + 2_000))]);
    // The status comes 1 ms (the ACK delay) after the transmission.
    let up = api_frames(&up);
    assert_eq!(
        up,
        [(
            vec![xbee::API_TX_STATUS, 5, xbee::STATUS_SUCCESS],
            at_us(9_800)
        )]
    );
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (s.frames_sent, s.bytes_written, s.bytes_sent, s.statuses),
        (1, 29, 29, 1)
    );
    assert_eq!((s.serial_busy_us, s.air_busy_us), (5_800, 3_000));
    assert_eq!(link.stats(Direction::BToA).bytes_delivered, 7);
}

#[test]
fn xbee24_frames_of_the_pprz_encoder_decode_at_the_ground() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 4096>::new(xbee_config(xbee24()));
    let (air, ground) = link.endpoints();
    let (mut air_rx, mut air_tx) = air.split();
    let (mut ground_rx, _ground_tx) = ground.split();
    const FRAMES: usize = 20;
    let (_, (down, up)) = run(
        join(
            async {
                for i in 0..FRAMES {
                    let encoder = XBee24 {
                        frame_id: i as u8 + 1,
                        options: 0,
                    };
                    let meta = TxMeta::new(MsgHeader::new(7, 0, 1, i as u8));
                    write_frame(&mut air_tx, &encoder, &meta, &[i as u8; 30])
                        .await
                        .unwrap();
                }
            },
            join(
                read_until(&mut ground_rx, at_us(500_000)),
                read_until(&mut air_rx, at_us(500_000)),
            ),
        ),
        STEP,
        10_000,
    );
    let mut decoder = XBee24Decoder::new(XBee24::new());
    let mut input = &bytes(&down)[..];
    let mut seen = Vec::new();
    while let Some(f) = decoder.feed(&mut input) {
        assert_eq!(f.payload(), [f.msg_id(); 30]);
        seen.push(f.msg_id());
    }
    assert_eq!(seen, (0..FRAMES as u8).collect::<Vec<_>>());
    let ids: Vec<u8> = api_frames(&up)
        .iter()
        .map(|(fd, _)| {
            assert_eq!((fd[0], fd[2]), (xbee::API_TX_STATUS, xbee::STATUS_SUCCESS));
            fd[1]
        })
        .collect();
    assert_eq!(ids, (1..=FRAMES as u8).collect::<Vec<_>>());
}

#[test]
fn xbee_frame_id_zero_gets_no_status() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 1024>::new(xbee_config(xbee24()));
    let mut data = tx16(0, 0x0100, 0, b"silent");
    data.extend(tx16(9, 0x0100, 0, b"loud"));
    let Exchange { down, up, .. } = exchange(&link, &data, &[], 50_000, 1000);
    assert_eq!(api_frames(&down).len(), 2);
    let up = api_frames(&up);
    assert_eq!(up.len(), 1);
    assert_eq!(up[0].0, [xbee::API_TX_STATUS, 9, xbee::STATUS_SUCCESS]);
    assert_eq!(link.stats(Direction::AToB).statuses, 1);
}

/// Sends `frames` requests one at a time, each after the previous status; returns the
/// statuses with their delay after the end of the request's write, and the stats.
fn failing_link(seed: u64, frames: usize) -> (Vec<(u8, u8, Duration)>, SimStats) {
    let modem = XBeeModem::new(XBeeVariant::XBee868)
        .air_overhead(10)
        .ack_delay(Duration::from_millis(1))
        .failure_rate(0.3)
        .retries(2);
    let link = SimLink::<NoopRawMutex, 4096>::new(xbee_config(modem).seed(seed));
    let (air, ground) = link.endpoints();
    let (mut air_rx, mut air_tx) = air.split();
    let (mut ground_rx, _ground_tx) = ground.split();
    let aircraft = async {
        let mut statuses = Vec::new();
        for i in 0..frames {
            let id = (i % 255) as u8 + 1;
            let sent = write_at(&mut air_tx, &tx868(id, 0x0100, 0, &[i as u8; 40])).await;
            let mut fd = [0u8; 11];
            air_rx.read_exact(&mut fd).await.unwrap();
            let fd = &fd[3..10];
            assert_eq!(&fd[..4], &[xbee::API_TX_STATUS_868, id, 0xFF, 0xFE]);
            assert_eq!(fd[6], xbee::DISCOVERY_NONE);
            statuses.push((fd[4], fd[5], Instant::now() - sent));
        }
        statuses
    };
    // The ground reads everything (and checks nothing here).
    let ground = async {
        let mut buf = [0u8; 256];
        loop {
            ground_rx.read(&mut buf).await.unwrap();
        }
    };
    let statuses = match run(select(aircraft, ground), STEP, 200_000) {
        Either::First(statuses) => statuses,
        Either::Second(never) => never,
    };
    (statuses, link.stats(Direction::AToB))
}

#[test]
fn xbee_failures_are_seeded_retried_and_reported() {
    let _t = mock_time();
    const FRAMES: usize = 300;
    let (statuses, s) = failing_link(11, FRAMES);
    // Per attempt: 40 + 10 bytes on the air (5 ms) then 1 ms of ACK wait.
    for &(retries, delivery, delay) in &statuses {
        assert!(retries <= 2);
        assert_eq!(delay, Duration::from_millis(6 * (u64::from(retries) + 1)));
        if delivery == xbee::DELIVERY_NO_ACK {
            assert_eq!(retries, 2, "given up after every retry");
        } else {
            assert_eq!(delivery, xbee::STATUS_SUCCESS);
        }
    }
    let attempts: u32 = statuses.iter().map(|&(r, _, _)| u32::from(r) + 1).sum();
    let lost = statuses
        .iter()
        .filter(|&&(_, d, _)| d == xbee::DELIVERY_NO_ACK)
        .count() as u32;
    assert_eq!(s.frames_sent, FRAMES as u32);
    assert_eq!(s.frames_lost, lost);
    assert_eq!(s.failed_attempts, attempts - (FRAMES as u32 - lost));
    assert_eq!(
        s.air_busy_us,
        u64::from(attempts) * 5_000,
        "every attempt is on the air"
    );
    // A failure rate of 0.3 per attempt: about 0.3 * 1.3 * 1.09 attempts fail per
    // frame, 0.027 of the frames are lost.
    let failure = f64::from(s.failed_attempts) / f64::from(attempts);
    assert!((0.24..0.36).contains(&failure), "failure rate {failure}");
    assert!(lost <= 25, "{lost} lost");
    // Same seed, same run; another seed, another run.
    mock_time_reset();
    assert_eq!(failing_link(11, FRAMES), (statuses.clone(), s));
    mock_time_reset();
    assert_ne!(failing_link(12, FRAMES).0, statuses);
}

/// Restarts the mock clock at 0 (the caller holds the lock).
fn mock_time_reset() {
    MockDriver::get().reset();
}

#[test]
fn xbee_lost_frames_do_not_arrive() {
    let _t = mock_time();
    let modem = xbee24().failure_rate(1.0).retries(1);
    let link = SimLink::<NoopRawMutex, 1024>::new(xbee_config(modem));
    let mut data = tx16(1, 0x0100, 0, &[1; 10]);
    // A broadcast is sent once, lost too, and reported delivered.
    data.extend(tx16(2, xbee::BROADCAST_16, 0, &[2; 10]));
    // So is a frame with the ACK disabled.
    data.extend(tx16(3, 0x0100, xbee::OPTION_DISABLE_ACK, &[3; 10]));
    let Exchange { down, up, .. } = exchange(&link, &data, &[], 100_000, 2000);
    assert!(down.is_empty());
    assert_eq!(
        frame_data(&up),
        [
            vec![xbee::API_TX_STATUS, 1, xbee::STATUS_NO_ACK],
            vec![xbee::API_TX_STATUS, 2, xbee::STATUS_SUCCESS],
            vec![xbee::API_TX_STATUS, 3, xbee::STATUS_SUCCESS],
        ]
    );
    let s = link.stats(Direction::AToB);
    assert_eq!((s.frames_sent, s.frames_lost, s.failed_attempts), (3, 3, 4));
    // 2 attempts + 1 + 1, 20 air bytes each: 4 x 2 ms.
    assert_eq!(s.air_busy_us, 8_000);
}

/// XBee transmissions that end in an outage fail like unacknowledged ones: the modem
/// retries, and a frame whose every attempt falls in the window is lost ("no ACK").
#[test]
fn xbee_transmissions_in_an_outage_fail_and_are_retried() {
    let request = tx16(5, 0x0100, 0, &[9; 20]);
    // 29 bytes on the UART: 5.8 ms; each attempt 3 ms on the air, then 1 ms of ACK wait:
    // attempts end at 8.8, 12.8, 16.8 and 20.8 ms.
    for (until_us, status, arrives, outage_attempts) in [
        (10_000, xbee::STATUS_SUCCESS, Some(12_800 + 2_000), 1),
        (100_000, xbee::STATUS_NO_ACK, None, 4),
    ] {
        let _t = mock_time();
        let link = SimLink::<NoopRawMutex, 1024>::new(xbee_config(xbee24()));
        link.add_outage(Direction::AToB, at_us(0), at_us(until_us))
            .unwrap();
        let Exchange { down, up, .. } = exchange(&link, &request, &[], 50_000, 1000);
        let down = api_frames(&down);
        assert_eq!(
            down.first().map(|(_, t)| *t),
            arrives.map(at_us),
            "{until_us}"
        );
        assert_eq!(
            frame_data(&up),
            [vec![xbee::API_TX_STATUS, 5, status]],
            "{until_us}"
        );
        let s = link.stats(Direction::AToB);
        assert_eq!(s.outage_attempts, outage_attempts, "{until_us}");
        assert_eq!(s.failed_attempts, outage_attempts, "{until_us}");
        assert_eq!(s.frames_lost, u32::from(arrives.is_none()), "{until_us}");
    }
}

#[test]
fn xbee_bit_errors_fail_transmissions_instead_of_corrupting_frames() {
    let _t = mock_time();
    // BER 1e-3 on 70 bytes on the air: 43 % of the transmissions fail. CTS keeps the
    // modem from dropping frames while it retries.
    let modem = xbee24().retries(10);
    let config = xbee_config(modem)
        .bit_error_rate(1e-3)
        .overflow(Overflow::Wait);
    let link = SimLink::<NoopRawMutex, 8192>::new(config);
    let data = tx16_run(50, 60);
    let Exchange { down, .. } = exchange(&link, &data, &[], 2_000_000, 30_000);
    let s = link.stats(Direction::AToB);
    assert!(s.bit_errors > 0 && s.failed_attempts > 10, "{s:?}");
    assert_eq!((s.frames_sent, s.frames_dropped, s.frames_lost), (50, 0, 0));
    let down = api_frames(&down);
    assert_eq!(down.len(), 50);
    for (fd, _) in &down {
        assert!(fd[5..].iter().all(|&b| b == fd[5]), "RF data intact");
    }
}

#[test]
fn xbee_malformed_frames_are_counted_and_dropped() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 1024>::new(xbee_config(xbee24()));
    let mut data = b"noise".to_vec(); // 5 bytes outside frames
    let mut bad_checksum = tx16(1, 0x0100, 0, b"abc"); // 12 bytes
    *bad_checksum.last_mut().unwrap() ^= 0x20;
    data.extend(&bad_checksum);
    data.extend(frame(&[0x08, 2, b'N', b'I'])); // an AT command: 8 bytes
    data.extend(tx16(3, 0x0100, 0, &[0; 101])); // RF data too long: 110 bytes
    data.extend([xbee::START, 0x02, 0x00]); // length above any frame: 3 bytes
    data.extend(tx16(4, 0x0100, 0, b"good")); // 13 bytes
    let Exchange { down, up, .. } = exchange(&link, &data, &[], 100_000, 2000);
    let down = api_frames(&down);
    assert_eq!(down.len(), 1);
    assert_eq!(&down[0].0[5..], b"good");
    assert_eq!(api_frames(&up)[0].0, [xbee::API_TX_STATUS, 4, 0]);
    let s = link.stats(Direction::AToB);
    assert_eq!(s.malformed_frames, 4);
    assert_eq!(s.discarded_bytes, 5 + 12 + 8 + 110 + 3);
    assert_eq!((s.frames_sent, s.bytes_sent), (1, 13));
    assert_eq!(s.bytes_written, s.bytes_sent + s.discarded_bytes);
}

#[test]
fn xbee_full_modem_drops_whole_frames() {
    let _t = mock_time();
    // An instant UART: 10 frames of 29 bytes arrive at once in a 202-byte modem.
    let modem = xbee24().purge_status(true);
    let link = SimLink::<NoopRawMutex, 2048>::new(xbee_config(modem).serial_rate(0));
    let data = tx16_run(10, 20);
    let Exchange { down, up, .. } = exchange(&link, &data, &[], 100_000, 2000);
    // 6 frames (174 bytes) fit, the 7th would make 203.
    let down = api_frames(&down);
    assert_eq!(down.len(), 6);
    assert!(down.iter().enumerate().all(|(i, (fd, _))| fd[5] == i as u8));
    let up: Vec<(u8, u8)> = api_frames(&up)
        .iter()
        .map(|(fd, _)| (fd[1], fd[2]))
        .collect();
    // Purged statuses come at once, the others after their transmission.
    let mut expected: Vec<(u8, u8)> = (7..=10).map(|id| (id, xbee::STATUS_PURGED)).collect();
    expected.extend((1..=6).map(|id| (id, xbee::STATUS_SUCCESS)));
    assert_eq!(up, expected);
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (
            s.frames_sent,
            s.frames_dropped,
            s.bytes_sent,
            s.dropped_bytes
        ),
        (6, 4, 174, 116)
    );
    assert_eq!(s.bytes_written, s.bytes_sent + s.dropped_bytes);
}

#[test]
fn xbee_wait_mode_holds_the_uart_instead_of_dropping() {
    let _t = mock_time();
    // A fast UART (50 000 bytes/s, 20 µs a byte) and the largest frames (109 bytes,
    // 2.18 ms of UART): the modem (11 ms on the air + 1 ms ACK wait a frame) is the
    // bottleneck.
    let config = xbee_config(xbee24())
        .serial_rate(50_000)
        .overflow(Overflow::Wait);
    let link = SimLink::<NoopRawMutex, 4096>::new(config);
    let (air, ground) = link.endpoints();
    let (mut air_rx, mut air_tx) = air.split();
    let (mut ground_rx, _ground_tx) = ground.split();
    let data = tx16_run(30, 100);
    let ((done, flushed), (down, up)) = run(
        join(
            async {
                let done = write_at(&mut air_tx, &data).await;
                // Frame 28 was done 0.32 ms ago; frame 29 is the only one in.
                assert_eq!(link.modem_occupancy(Direction::AToB), 109);
                air_tx.flush().await.unwrap();
                (done, Instant::now())
            },
            join(
                read_until(&mut ground_rx, at_us(400_000)),
                read_until(&mut air_rx, at_us(400_000)),
            ),
        ),
        US,
        500_000,
    );
    // Frame 0 is in at 2.18 ms and done at 14.18 ms. The next one's first 93 bytes fit
    // beside it in the 202-byte buffer; CTS holds the other 16 until 14.18 ms, so frame
    // 1 is in at 14.5 ms, and every later frame 12.32 ms after the previous one.
    assert_eq!(done, at_us(14_500 + 28 * 12_320));
    assert_eq!(flushed, at_us(14_500 + 28 * 12_320 + 12_000));
    assert_eq!(api_frames(&down).len(), 30);
    assert_eq!(api_frames(&up).len(), 30);
    let s = link.stats(Direction::AToB);
    assert_eq!(
        (s.frames_sent, s.frames_dropped, s.dropped_bytes),
        (30, 0, 0)
    );
    assert_eq!(s.serial_busy_us, 30 * 109 * 20);
    assert_eq!(s.air_busy_us, 30 * 11_000);
}

#[test]
fn xbee_receiver_overrun_loses_the_frame_not_the_status() {
    let _t = mock_time();
    // A 64-byte ring: a 31-byte RX frame and a second one fit, not a third.
    let link = SimLink::<NoopRawMutex, 64>::new(xbee_config(xbee24()));
    let (air, ground) = link.endpoints();
    let (mut air_rx, mut air_tx) = air.split();
    let data = tx16_run(3, 22);
    let (_, up) = run(
        join(
            air_tx.write_all(&data),
            read_until(&mut air_rx, at_us(100_000)),
        ),
        STEP,
        2000,
    );
    assert_eq!(
        frame_data(&up).len(),
        3,
        "every frame was sent and acknowledged"
    );
    let s = link.stats(Direction::AToB);
    assert_eq!((s.frames_sent, s.frames_overrun), (3, 1));
    assert_eq!((s.bytes_sent, s.overrun_bytes), (62, 31));
    let _ = ground;
}

#[test]
fn xbee868_layouts() {
    let _t = mock_time();
    let modem = XBeeModem::new(XBeeVariant::XBee868)
        .addresses(0x0013_A200_4000_0007, 0x0013_A200_4000_0100)
        .api_uplink(true);
    let link = SimLink::<NoopRawMutex, 1024>::new(xbee_config(modem));
    let mut data = tx868(1, 0x0100, 0, b"unicast");
    data.extend(tx868(2, xbee::BROADCAST_64, 0, b"broadcast"));
    let uplink = tx868(3, 7, 0, b"uplink");
    let Exchange { down, up, .. } = exchange(&link, &data, &uplink, 100_000, 2000);
    let rx90 = |source: u64, options: u8, rf: &[u8]| {
        let mut fd = vec![xbee::API_RX_868];
        fd.extend_from_slice(&source.to_be_bytes());
        fd.extend_from_slice(&[0xFF, 0xFE, options]);
        fd.extend_from_slice(rf);
        fd
    };
    let status = |id: u8| vec![xbee::API_TX_STATUS_868, id, 0xFF, 0xFE, 0, 0, 0];
    let (down, up) = (frame_data(&down), frame_data(&up));
    let a = 0x0013_A200_4000_0007;
    let b = 0x0013_A200_4000_0100;
    // Ground: its status at 6.4 ms (24 bytes of UART, 0.6 ms of air, 1 ms of ACK
    // wait), the RX frames at 7.7 ms (25 bytes, 0.7 ms, 2 ms of latency) and 13.3 ms.
    assert_eq!(
        down,
        [
            status(3),
            rx90(a, xbee::RX_OPTION_ACKED, b"unicast"),
            rx90(a, xbee::RX_OPTION_BROADCAST, b"broadcast"),
        ]
    );
    // Aircraft: status 1 at 6.7 ms, the uplink at 7.4 ms, status 2 (a broadcast: no
    // ACK wait) at 11.3 ms.
    assert_eq!(
        up,
        [
            status(1),
            rx90(b, xbee::RX_OPTION_ACKED, b"uplink"),
            status(2)
        ]
    );
}

#[test]
fn xbee_plain_uplink_passes_bytes_unchanged() {
    let _t = mock_time();
    let link = SimLink::<NoopRawMutex, 1024>::new(xbee_config(xbee24()));
    let (air, ground) = link.endpoints();
    let (mut air_rx, _air_tx) = air.split();
    let (_ground_rx, mut ground_tx) = ground.split();
    let (_, up) = run(
        join(
            ground_tx.write_all(b"\x99 plain bytes"),
            read_until(&mut air_rx, at_us(100_000)),
        ),
        STEP,
        2000,
    );
    assert_eq!(bytes(&up), b"\x99 plain bytes");
    let s = link.stats(Direction::BToA);
    assert_eq!((s.bytes_sent, s.frames_sent, s.discarded_bytes), (13, 0, 0));
}

#[test]
fn an_ack_delay_of_forever_at_the_highest_rates_does_not_overflow() {
    let _t = mock_time();
    // The ACK wait alone is near 2^128 time units: the modem's schedule saturates.
    let modem = XBeeModem::new(XBeeVariant::XBee24)
        .ack_delay(Duration::MAX)
        .retries(0);
    let config = SimConfig::new(u32::MAX).serial_rate(u32::MAX).xbee(modem);
    let link = SimLink::<NoopRawMutex, 1024>::new(config);
    let (mut a, _b) = link.endpoints();
    let mut frame = [0u8; 32];
    let tx16 = [0x01, 0x00, 0x01, 0x00, 0x00, 7, 0, 1, 2];
    let n = xbee::api_frame(&tx16, &mut frame).unwrap();
    for _ in 0..2 {
        run(a.write_all(&frame[..n]), Duration::from_micros(1), 1000).unwrap();
    }
    assert_eq!(link.stats(Direction::AToB).frames_sent, 2);
}
