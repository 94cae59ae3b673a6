//! The downlink without time: priority order (the Figure 27 trace of Jornet's design), FIFO among
//! equal priorities, the overflow policy for queue and arena, per-device accounting under
//! random load (frames written, failed and abandoned through the devices' ports), and no
//! leaked arena memory.
//!
//! The queues are drained by hand through the devices' [`Port`]s (`try_next` and
//! `Outgoing::finish`), as a writer task would. A downlink hands out ports only with a
//! `Sync` mutex, hence `CriticalSectionRawMutex` throughout.

use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex;
use pprz_default::messages::telemetry::{Attitude, DlValue, Payload};
use pprz_messages::{Decode, Message, VarArray};
use pprz_telemetry::SendOptions;
use pprz_telemetry::pprz_transports::{AnyTransport, Decoder, PprzLog, PprzV1, PprzV2, XBee24};
use pprz_telemetry::{DeviceConfig, DeviceStats, Downlink, DropReason, FrameArena, Port, Targets};
use proptest::prelude::*;

type M = CriticalSectionRawMutex;

type Arena = FrameArena<CriticalSectionRawMutex, 8192>;

fn v2() -> DeviceConfig {
    DeviceConfig::new(PprzV2::new().into())
}

/// Takes every queued frame of the port's device in send order (reporting each as
/// written) and returns the DL_VALUE indices.
fn drain_indices(port: &mut Port<'_>) -> Vec<u8> {
    let mut order = Vec::new();
    while let Some(frame) = port.try_next() {
        let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
        let mut input = &frame[..];
        let f = decoder.feed(&mut input).expect("a complete PPRZ v2 frame");
        order.push(DlValue::decode(f.payload()).unwrap().index);
        frame.finish(true);
    }
    order
}

#[test]
fn jornet_figure_27_trace() {
    // Priorities 0, 1, 0, 1 arrive while the device is busy: sent 2nd, 4th, 1st, 3rd.
    let arena = Arena::new();
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&arena, 7, [v2()]);
    for (index, priority) in [(1, 0), (2, 1), (3, 0), (4, 1)] {
        downlink
            .send_with(
                &DlValue { index, value: 0.0 },
                SendOptions::new().on(Targets::ALL).priority(priority),
            )
            .unwrap();
    }
    let [mut port] = downlink.ports().unwrap();
    assert_eq!(drain_indices(&mut port), [2, 4, 1, 3]);
}

#[test]
fn many_levels_strictly_higher_first_fifo_among_equals() {
    let arena = Arena::new();
    let downlink: Downlink<'_, M, 1, 64> = Downlink::new(&arena, 7, [v2()]);
    let prios = [5u8, 255, 0, 5, 128, 255, 0, 128, 5, 1];
    for (i, p) in prios.iter().enumerate() {
        downlink
            .send_with(
                &DlValue {
                    index: i as u8,
                    value: 0.0,
                },
                SendOptions::new().on(Targets::ALL).priority(*p),
            )
            .unwrap();
    }
    let mut expected: Vec<(u8, u8)> = prios
        .iter()
        .enumerate()
        .map(|(i, p)| (*p, i as u8))
        .collect();
    expected.sort_by(|a, b| b.0.cmp(&a.0).then(a.1.cmp(&b.1)));
    let expected: Vec<u8> = expected.into_iter().map(|(_, i)| i).collect();
    let [mut port] = downlink.ports().unwrap();
    assert_eq!(drain_indices(&mut port), expected);
}

#[test]
fn full_queue_evicts_oldest_of_least_important_never_equal() {
    let arena = Arena::new();
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&arena, 7, [v2().depth(3)]);
    let send = |index: u8, priority: u8| {
        downlink.send_with(
            &DlValue { index, value: 0.0 },
            SendOptions::new().on(Targets::ALL).priority(priority),
        )
    };
    send(1, 10).unwrap();
    send(2, 5).unwrap();
    send(3, 5).unwrap();
    // Full. Equal priority is never evicted: dropped.
    assert_eq!(
        send(4, 5),
        Err(pprz_telemetry::SendError {
            device: 0,
            reason: DropReason::QueueFull
        })
    );
    // Higher priority evicts the oldest of the lowest priority (2, not 3).
    send(5, 6).unwrap();
    let stats = downlink.stats(0).unwrap();
    assert_eq!(stats.dropped.queue_full, 1);
    assert_eq!(stats.evicted.queue_full, 1);
    assert_eq!(stats.queue_high_water, 3);
    assert!(stats.is_balanced(), "{stats:?}");
    let [mut port] = downlink.ports().unwrap();
    assert_eq!(drain_indices(&mut port), [1, 5, 3]);
    let stats = downlink.stats(0).unwrap();
    assert_eq!((stats.submitted, stats.sent, stats.queued), (5, 3, 0));
    assert!(stats.is_balanced());
    // All five are of the low level (priority < 128): three sent, two shed.
    let low = stats.levels[pprz_messages::priority::level(5)];
    assert_eq!((low.submitted, low.sent, low.lost), (5, 3, 2));
}

#[test]
fn full_arena_evicts_across_devices_least_important_first() {
    // A small arena shared by two devices.
    let arena: FrameArena<CriticalSectionRawMutex, 1024> = FrameArena::new();
    let downlink: Downlink<'_, M, 2, 64> = Downlink::new(&arena, 7, [v2(), v2()]);
    let bytes = [0xA5u8; 100];
    let payload = Payload {
        values: VarArray::new(&bytes),
    };
    // Fill the arena with low-priority frames alternating between the devices.
    let mut queued = 0;
    for i in 0..64 {
        if downlink
            .send_with(
                &payload,
                SendOptions::new().on(Targets::only(i % 2)).priority(1),
            )
            .is_err()
        {
            break;
        }
        queued += 1;
    }
    assert!(queued >= 4, "the arena held {queued} frames");
    // Equal priority cannot get in.
    assert_eq!(
        downlink
            .send_with(
                &payload,
                SendOptions::new().on(Targets::only(0)).priority(1)
            )
            .unwrap_err()
            .reason,
        DropReason::ArenaFull
    );
    // A more important frame evicts the oldest low-priority frame (device 0's first).
    downlink
        .send_with(
            &DlValue {
                index: 9,
                value: 1.0,
            },
            SendOptions::new().on(Targets::only(1)).priority(200),
        )
        .unwrap();
    let (s0, s1) = (downlink.stats(0).unwrap(), downlink.stats(1).unwrap());
    assert_eq!(s0.evicted.arena_full + s1.evicted.arena_full, 1);
    assert_eq!(s0.evicted.arena_full, 1, "the oldest frame was device 0's");
    assert_eq!(s0.dropped.arena_full, 1);
    assert!(s0.is_balanced() && s1.is_balanced());
    // The high-priority frame is next on device 1.
    let [_, mut port1] = downlink.ports().unwrap();
    assert_eq!(next_msg_id(&mut port1), DlValue::ID);
    assert_eq!(DlValue::ID, 31);
}

/// Message id of the next frame of the port's device (a PPRZ v2 frame), reported as
/// written.
fn next_msg_id(port: &mut Port<'_>) -> u8 {
    let frame = port.try_next().unwrap();
    let id = frame[5];
    frame.finish(true);
    id
}

#[test]
fn too_large_and_encode_errors_are_counted_per_device() {
    let arena = Arena::new();
    let downlink: Downlink<'_, M, 2, 8> = Downlink::new(
        &arena,
        7,
        [v2(), DeviceConfig::new(XBee24::default().into())],
    );
    let bytes = [1u8; 150];
    let big = Payload {
        values: VarArray::new(&bytes),
    };
    // 151 field bytes: fine for PPRZ v2, too large for XBee 802.15.4 (96).
    let err = downlink.send(&big).unwrap_err();
    assert_eq!((err.device, err.reason), (1, DropReason::TooLarge));
    assert_eq!(downlink.stats(0).unwrap().queued, 1);
    assert_eq!(downlink.stats(1).unwrap().dropped.too_large, 1);
    let too_many = [0u8; 256];
    let bad = Payload {
        values: VarArray::new(&too_many),
    };
    let err = downlink
        .send_with(&bad, SendOptions::new().on(Targets::only(0)).priority(1))
        .unwrap_err();
    assert_eq!(err.reason, DropReason::TooLarge);
    for d in 0..2 {
        assert!(downlink.stats(d).unwrap().is_balanced());
    }
}

#[test]
fn each_transport_frames_the_message_and_same_transports_share_the_encoding() {
    let arena = Arena::new();
    let transports: [AnyTransport; 4] = [
        PprzV2::new().into(),
        PprzV1::new(1).into(),
        PprzLog::TELEMETRY.into(),
        PprzV2::new().into(),
    ];
    let downlink: Downlink<'_, M, 4, 8> =
        Downlink::new(&arena, 7, transports.map(DeviceConfig::new));
    downlink
        .send(&DlValue {
            index: 3,
            value: 0.5,
        })
        .unwrap();
    let [mut p0, mut p1, mut p2, mut p3] = downlink.ports().unwrap();
    let (f0, f1, f2, f3) = (
        p0.try_next().unwrap(),
        p1.try_next().unwrap(),
        p2.try_next().unwrap(),
        p3.try_next().unwrap(),
    );
    assert_eq!(&f0[..], &f3[..]);
    assert_eq!(&f0[..6], &[0x99, 13, 7, 0, 1, 31]);
    assert_eq!(&f1[..4], &[0x99, 11, 7, 31]);
    assert_eq!(f2[0], 0x99);
    assert_eq!(
        f2[1],
        4 + 5,
        "PPRZLOG LEN counts the v2 header and the fields"
    );
    for f in [f0, f1, f2, f3] {
        f.finish(true);
    }
    for d in 0..4 {
        let s = downlink.stats(d).unwrap();
        assert_eq!((s.submitted, s.sent, s.queued), (1, 1, 0));
    }
    assert_eq!(downlink.arena_stats().live, 0);
}

#[derive(Debug, Clone)]
enum Op {
    Send {
        size: u8,
        priority: u8,
        targets: u8,
    },
    Write {
        device: u8,
        ok: bool,
    },
    /// A frame taken and dropped unfinished (a writer cancelled mid-write).
    Abandon {
        device: u8,
    },
    /// A state message (ATTITUDE, or DL_VALUE) sent with `SendOptions::latest`.
    Latest {
        attitude: bool,
    },
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        3 => (any::<u8>(), 0u8..4, 1u8..8).prop_map(|(size, priority, targets)| Op::Send {
            size,
            priority: priority * 60,
            targets
        }),
        1 => (0u8..3, prop::bool::weighted(0.9)).prop_map(|(device, ok)| Op::Write { device, ok }),
        1 => (0u8..3).prop_map(|device| Op::Abandon { device }),
        2 => any::<bool>().prop_map(|attitude| Op::Latest { attitude }),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn accounting_balances_under_random_load(ops in prop::collection::vec(op(), 1..400)) {
        let arena: FrameArena<CriticalSectionRawMutex, 2048> = FrameArena::new();
        let downlink: Downlink<'_, M, 3, 16> = Downlink::new(
            &arena,
            7,
            [v2(), DeviceConfig::new(XBee24::default().into()).depth(4), DeviceConfig::new(PprzLog::TELEMETRY.into())],
        );
        let mut ports = downlink.ports().unwrap();
        let bytes = [0x5Au8; 255];
        for op in ops {
            match op {
                Op::Send { size, priority, targets } => {
                    let msg = Payload { values: VarArray::new(&bytes[..usize::from(size)]) };
                    let _ = downlink.send_with(&msg, SendOptions::new().on(Targets::from_bits(u32::from(targets))).priority(priority));
                }
                Op::Write { device, ok } => {
                    if let Some(frame) = ports[usize::from(device)].try_next() {
                        frame.finish(ok);
                    }
                }
                Op::Latest { attitude } => {
                    let _ = if attitude {
                        downlink.send_with(&Attitude { phi: 0.1, psi: 0.2, theta: 0.3 }, SendOptions::new().latest())
                    } else {
                        downlink.send_with(&DlValue { index: 1, value: 2.0 }, SendOptions::new().latest())
                    };
                }
                Op::Abandon { device } => {
                    let before = downlink.stats(usize::from(device)).unwrap().dropped.write_error;
                    if let Some(frame) = ports[usize::from(device)].try_next() {
                        drop(frame);
                        let after = downlink.stats(usize::from(device)).unwrap().dropped.write_error;
                        prop_assert_eq!(after, before + 1, "an abandoned frame is a failed write");
                    }
                }
            }
            let stats: Vec<DeviceStats> = (0..3).map(|d| downlink.stats(d).unwrap()).collect();
            for s in &stats {
                prop_assert!(s.is_balanced(), "{:?}", s);
            }
            for s in &stats {
                prop_assert_eq!(
                    s.submitted,
                    s.sent + s.dropped.total() + s.evicted.total() + s.superseded + u32::from(s.queued)
                );
                let per_level: u32 =
                    s.levels.iter().map(|l| l.submitted - l.sent - l.lost - l.superseded).sum();
                prop_assert_eq!(per_level, u32::from(s.queued), "levels balance too: {:?}", s);
                prop_assert_eq!(s.levels.iter().map(|l| l.submitted).sum::<u32>(), s.submitted);
            }
            let queued: u32 = stats.iter().map(|s| u32::from(s.queued)).sum();
            prop_assert_eq!(downlink.arena_stats().live as u32, queued, "arena frames = queued frames");
        }
        // Drain: everything ends sent or counted, and the arena is empty again.
        for (d, port) in ports.iter_mut().enumerate() {
            while let Some(frame) = port.try_next() {
                frame.finish(true);
            }
            let s = downlink.stats(d).unwrap();
            prop_assert!(s.is_balanced());
            prop_assert_eq!(s.queued, 0);
        }
        prop_assert_eq!(downlink.arena_stats().live, 0);
    }
}

/// A hand-written `Message` whose `encode` writes `writes` bytes while `encoded_len`
/// claims `claims`: a user's impl may be wrong, the send path must not panic on it.
struct Lying {
    claims: usize,
    writes: usize,
}

impl Message for Lying {
    const CLASS_ID: u8 = 1;
    const ID: u8 = 200;
    const NAME: &'static str = "LYING";
    const PRIORITY: u8 = 100;
    const MIN_LEN: usize = 0;
    const MAX_LEN: usize = 255;
    const DESCRIPTOR: pprz_messages::MessageDescriptor<'static> =
        pprz_messages::MessageDescriptor {
            class_id: 1,
            class_name: "telemetry",
            id: 200,
            name: "LYING",
            priority: 100,
            fields: &[],
        };

    fn encoded_len(&self) -> usize {
        self.claims
    }

    fn encode(&self, buf: &mut [u8]) -> Result<usize, pprz_messages::EncodeError> {
        let n = self.writes.min(buf.len());
        buf[..n].fill(0xA5);
        Ok(self.writes)
    }
}

#[test]
fn a_message_whose_encode_disagrees_with_its_length_is_dropped_not_panicking() {
    let arena = Arena::new();
    // Two devices with the same transport (the copy path) and one with another.
    let downlink: Downlink<'_, M, 3, 8> = Downlink::new(
        &arena,
        7,
        [v2(), v2(), DeviceConfig::new(PprzV1::new(1).into())],
    );
    for (claims, writes) in [(10, 4), (4, 10), (0, 1), (1, 0), (300, 2)] {
        let err = downlink.send(&Lying { claims, writes }).unwrap_err();
        assert!(
            matches!(err.reason, DropReason::Encode | DropReason::TooLarge),
            "{claims}/{writes}: {err:?}"
        );
    }
    // An honest one of the same shape goes out to all three.
    downlink
        .send(&Lying {
            claims: 6,
            writes: 6,
        })
        .unwrap();
    for d in 0..3 {
        let s = downlink.stats(d).unwrap();
        assert!(s.is_balanced(), "{s:?}");
        assert_eq!((s.submitted, s.queued), (6, 1), "device {d}");
        assert_eq!(s.dropped.encode + s.dropped.too_large, 5, "device {d}");
    }
    assert_eq!(downlink.arena_stats().live, 3);
}

/// State messages: a newer ATTITUDE takes the place of a waiting older one (counted as
/// superseded), keeping its place in line; the one being written, events sent with
/// `send`, and other priorities are never superseded.
#[test]
fn latest_value_wins_for_state_messages() {
    let arena = Arena::new();
    let downlink: Downlink<'_, M, 1, 8> = Downlink::new(&arena, 7, [v2()]);
    let [mut port] = downlink.ports().unwrap();
    let attitude = |phi: f32| Attitude {
        phi,
        psi: 0.0,
        theta: 0.0,
    };
    let value = |index: u8| DlValue { index, value: 0.0 };
    downlink
        .send_with(&attitude(1.0), SendOptions::new().latest())
        .unwrap();
    downlink.send(&value(1)).unwrap(); // an event of another message
    downlink
        .send_with(&attitude(2.0), SendOptions::new().latest())
        .unwrap();
    downlink
        .send_with(&attitude(3.0), SendOptions::new().latest())
        .unwrap();
    // The same message at another priority is another stream.
    downlink
        .sender()
        .send_with(
            &attitude(9.0),
            SendOptions::new()
                .on(Targets::ALL)
                .priority(Attitude::PRIORITY + 1),
        )
        .unwrap();
    let s = downlink.stats(0).unwrap();
    assert_eq!((s.submitted, s.superseded, s.queued), (5, 2, 3));
    assert!(s.is_balanced(), "{s:?}");
    let level = &s.levels[pprz_messages::priority::level(Attitude::PRIORITY)];
    assert_eq!(level.superseded, 2);
    assert_eq!(
        downlink.arena_stats().live,
        3,
        "superseded frames are released"
    );

    let decode_phi = |frame: &[u8]| {
        let mut decoder: Decoder<PprzV2> = Decoder::new(PprzV2::new());
        let mut input = frame;
        let f = decoder.feed(&mut input).unwrap();
        (
            f.msg_id(),
            Attitude::decode(f.payload()).map(|a| a.phi).ok(),
        )
    };
    // Most important first (DL_VALUE, then the ATTITUDE at priority + 1), then the
    // latest ATTITUDE.
    let mut order = Vec::new();
    while let Some(frame) = port.try_next() {
        order.push(decode_phi(&frame));
        frame.finish(true);
    }
    assert_eq!(
        order,
        [
            (DlValue::ID, None),
            (Attitude::ID, Some(9.0)),
            (Attitude::ID, Some(3.0))
        ]
    );

    // A frame being written is on the wire already: a newer one queues behind it.
    downlink
        .send_with(&attitude(4.0), SendOptions::new().latest())
        .unwrap();
    let writing = port.try_next().unwrap();
    downlink
        .send_with(&attitude(5.0), SendOptions::new().latest())
        .unwrap();
    let s = downlink.stats(0).unwrap();
    assert_eq!((s.superseded, s.queued, s.waiting), (2, 2, 1));
    writing.finish(true);
    // `send` never supersedes.
    downlink.send(&attitude(6.0)).unwrap();
    let s = downlink.stats(0).unwrap();
    assert_eq!((s.superseded, s.queued), (2, 2));
    assert!(s.is_balanced(), "{s:?}");
}
