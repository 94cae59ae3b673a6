//! XBee transmit statuses: decoded from whole and chunked streams mixed with messages,
//! kept aside (never handed out as frames), malformed ones counted and ignored; frame
//! ids rewritten at send time; the PPRZ transports have neither.

mod common;

use common::{
    Owned, Rng, all_transports, check_invariant, decode_with_statuses, encode, expected,
    oracle_with_statuses,
};
use pprz_transports::xbee::{self, status};
use pprz_transports::{
    AnyTransport, Decoder, Encoder, Framing, MAX_FRAME_LEN, MsgHeader, TX_STATUS_CAPACITY, TxMeta,
    TxStatus, XBee24, XBee868,
};
use proptest::prelude::*;

fn xbees() -> [AnyTransport; 2] {
    [XBee24::new().into(), XBee868::new().into()]
}

/// An 802.15.4 (0x89) status frame and what it decodes to.
fn status_24(frame_id: u8, code: u8) -> (Vec<u8>, TxStatus) {
    let mut buf = [0u8; 16];
    let n = xbee::encode_tx_status_24(frame_id, code, &mut buf).unwrap();
    let s = TxStatus {
        frame_id,
        delivered: code == status::SUCCESS,
        status: code,
        retries: 0,
    };
    (buf[..n].to_vec(), s)
}

/// An 868 (0x8B) status frame and what it decodes to.
fn status_868(frame_id: u8, retries: u8, delivery: u8) -> (Vec<u8>, TxStatus) {
    let mut buf = [0u8; 16];
    let n = xbee::encode_tx_status_868(
        frame_id,
        retries,
        delivery,
        status::DISCOVERY_ROUTE,
        &mut buf,
    )
    .unwrap();
    let s = TxStatus {
        frame_id,
        delivered: delivery == status::SUCCESS,
        status: delivery,
        retries,
    };
    (buf[..n].to_vec(), s)
}

/// A received RX16 (0x81) frame from `src` with `fields`.
fn rx16(src: u8, fields: &[u8]) -> Vec<u8> {
    let mut data = vec![xbee::API_RX16, 0x00, src, 0x30, 0x00, src, 0x00, 0x01, 0x02];
    data.extend_from_slice(fields);
    api_frame(&data)
}

/// A received 868 (0x90) frame from `src` with `fields`.
fn rx868(src: u8, fields: &[u8]) -> Vec<u8> {
    let mut data = vec![
        xbee::API_RX_868,
        0,
        0x13,
        0xA2,
        0,
        0x40,
        0,
        0,
        src,
        0xFF,
        0xFE,
        0,
    ];
    data.extend_from_slice(&[src, 0x00, 0x01, 0x02]);
    data.extend_from_slice(fields);
    api_frame(&data)
}

/// Frames `data` (FRAME_DATA) as an API frame, with a good checksum.
fn api_frame(data: &[u8]) -> Vec<u8> {
    let mut f = vec![xbee::START];
    f.extend_from_slice(&(data.len() as u16).to_be_bytes());
    f.extend_from_slice(data);
    let sum = data.iter().fold(0u8, |a, &b| a.wrapping_add(b));
    f.push(0xFF - sum);
    f
}

/// A received message frame of the radio of `t`, from `src`.
fn rx(t: &AnyTransport, src: u8, fields: &[u8]) -> Vec<u8> {
    match t {
        AnyTransport::XBee24(_) => rx16(src, fields),
        _ => rx868(src, fields),
    }
}

/// A stream of RX frames, loopback TX frames and statuses of both kinds, mixed; with
/// the frames and the statuses it must decode to.
fn mixed(t: &AnyTransport) -> (Vec<u8>, Vec<Vec<u8>>, Vec<TxStatus>) {
    let mut stream = Vec::new();
    let mut frames = Vec::new();
    let mut statuses = Vec::new();
    for i in 0..6u8 {
        let f = rx(t, 10 + i, &[i; 5]);
        stream.extend_from_slice(&f);
        frames.push(f);
        let (s, st) = status_24(2 * i + 1, i % 4);
        stream.extend_from_slice(&s);
        statuses.push(st);
        let (s, st) = status_868(2 * i + 2, i, [0, 0x21, 0x25, 0x74][usize::from(i % 4)]);
        stream.extend_from_slice(&s);
        statuses.push(st);
        let f = encode(t, &TxMeta::new(MsgHeader::new(1, i, 1, 2)), &[i, i]);
        stream.extend_from_slice(&f);
        frames.push(f);
        stream.extend_from_slice(&[0x00, 0x11]); // garbage
    }
    (stream, frames, statuses)
}

fn raws(frames: &[Owned]) -> Vec<Vec<u8>> {
    frames.iter().map(|f| f.raw.clone()).collect()
}

#[test]
fn statuses_between_frames_every_chunking() {
    for t in xbees() {
        let (stream, frames, statuses) = mixed(&t);
        let control_bytes = (7 + 11) * 6;
        for borrowed in [false, true] {
            let check = |sizes: &[usize]| {
                let (got, st, s) =
                    decode_with_statuses::<MAX_FRAME_LEN>(t, &stream, sizes, borrowed);
                assert_eq!(raws(&got), frames, "{t:?} {sizes:?}");
                assert_eq!(st, statuses, "{t:?} {sizes:?}");
                assert_eq!(s.errors(), 0);
                assert_eq!(s.control_frames as usize, statuses.len());
                assert_eq!(s.control_bytes as usize, control_bytes);
                assert_eq!(s.dropped_bytes, 12);
                assert_eq!(
                    s.bytes_in,
                    s.frame_bytes + s.control_bytes + s.dropped_bytes
                );
                assert_eq!(s.tx_status_overflows, 0);
            };
            check(&[stream.len()]);
            for size in 1..=40 {
                check(&[size]);
            }
            for k in 0..=stream.len() {
                check(&[k, stream.len()]);
            }
        }
    }
}

#[test]
fn statuses_are_not_frames() {
    // A stream of statuses only: nothing handed out, everything consumed.
    for t in xbees() {
        let mut d: Decoder<AnyTransport> = Decoder::new(t);
        let (a, sa) = status_24(7, status::CCA_FAILURE);
        let (b, sb) = status_868(8, 3, status::ROUTE_NOT_FOUND);
        let mut stream = a.clone();
        stream.extend_from_slice(&b);
        for byte in stream.chunks(1) {
            let mut input = byte;
            assert!(d.feed(&mut input).is_none());
            check_invariant(&d);
        }
        assert!(d.flush().is_none());
        assert_eq!(d.tx_statuses_pending(), 2);
        assert_eq!(d.take_tx_status(), Some(sa));
        assert_eq!(d.take_tx_status(), Some(sb));
        assert_eq!(d.take_tx_status(), None);
        assert!(!sa.delivered && !sb.delivered);
        assert_eq!(sb.retries, 3);
        let s = d.stats();
        assert_eq!((s.frames, s.frame_bytes, s.dropped_bytes), (0, 0, 0));
        assert_eq!(d.buffered(), 0);
        assert_eq!(s.control_bytes as usize, stream.len());
        assert_eq!(s.bytes_in, s.control_bytes);
    }
}

#[test]
fn ring_overflow_is_counted() {
    // More statuses than the ring holds in one chunk: the oldest are dropped and
    // counted; the frames around them are unaffected.
    for t in xbees() {
        let mut stream = rx(&t, 1, &[1]);
        let mut all = Vec::new();
        for id in 1..=(TX_STATUS_CAPACITY as u8 + 3) {
            let (s, st) = status_868(id, 0, status::SUCCESS);
            stream.extend_from_slice(&s);
            all.push(st);
        }
        stream.extend_from_slice(&rx(&t, 2, &[2]));
        for borrowed in [false, true] {
            let mut d: Decoder<AnyTransport> = Decoder::new(t);
            let mut input = &stream[..];
            let mut sources = Vec::new();
            loop {
                let f = if borrowed {
                    d.feed_borrowed(&mut input)
                } else {
                    d.feed(&mut input)
                };
                let Some(f) = f else { break };
                sources.push(f.source());
            }
            assert_eq!(sources, [1, 2]);
            let s = *d.stats();
            assert_eq!(s.tx_status_overflows, 3);
            assert_eq!(s.control_frames as usize, all.len());
            assert_eq!(s.errors(), 0);
            let kept: Vec<TxStatus> = std::iter::from_fn(|| d.take_tx_status()).collect();
            assert_eq!(kept, all[3..]);
        }
    }
}

#[test]
fn malformed_statuses_are_counted_and_ignored() {
    for t in xbees() {
        let good = rx(&t, 4, &[9, 9]);
        let (ok, st) = status_24(0x42, status::SUCCESS);
        // Bad checksum.
        let (mut bad_ck, _) = status_868(5, 0, 0);
        *bad_ck.last_mut().unwrap() ^= 0x80;
        // Good checksum, but a length the API id does not have.
        let long_89 = api_frame(&[xbee::API_TX_STATUS, 6, 0, 0]);
        let short_8b = api_frame(&[xbee::API_TX_STATUS_868, 7, 0xFF, 0xFE, 0, 0]);
        let mut stream = Vec::new();
        for part in [&bad_ck, &good, &long_89, &short_8b, &ok, &good] {
            stream.extend_from_slice(part);
        }
        for borrowed in [false, true] {
            for size in [1, 3, stream.len()] {
                let (got, statuses, s) =
                    decode_with_statuses::<MAX_FRAME_LEN>(t, &stream, &[size], borrowed);
                assert_eq!(raws(&got), [good.clone(), good.clone()], "{t:?}");
                assert_eq!(statuses, [st]);
                assert_eq!(s.checksum_errors, 1);
                assert_eq!(s.length_errors, 2);
                assert_eq!(s.control_frames, 1);
                // Each rejected candidate loses only its start byte; the rest is
                // rescanned and dropped as garbage.
                assert_eq!(
                    s.dropped_bytes as usize,
                    bad_ck.len() + long_89.len() + short_8b.len()
                );
            }
        }
    }
}

#[test]
fn a_frame_inside_a_malformed_status_is_found() {
    // A status frame whose LEN was corrupted to announce more bytes: the good frame
    // after it is inside the candidate, found after the rejection.
    for t in xbees() {
        let (mut s, _) = status_24(1, 0);
        s[2] = 0x20; // LEN 32: the candidate covers the next frame
        let good = rx(&t, 8, &[1, 2, 3]);
        let mut stream = s.clone();
        stream.extend_from_slice(&good);
        stream.extend_from_slice(&[0u8; 40]);
        let (got, statuses, stats) = decode_with_statuses::<MAX_FRAME_LEN>(t, &stream, &[1], false);
        assert_eq!(raws(&got), [good]);
        assert!(statuses.is_empty());
        // Rejected for its checksum, or (if the 32 bytes happen to sum right) for a
        // length 0x89 does not have.
        assert_eq!(stats.checksum_errors + stats.length_errors, 1);
    }
}

#[test]
fn pprz_transports_have_no_tx_status() {
    let (s24, _) = status_24(1, 0);
    let (s868, _) = status_868(2, 0, 0);
    for t in all_transports() {
        let xbee = matches!(t, AnyTransport::XBee24(_) | AnyTransport::XBee868(_));
        assert_eq!(t.has_tx_status(), xbee, "{t:?}");
        let mut frame = encode(&t, &TxMeta::new(MsgHeader::new(1, 2, 3, 4)), &[5, 6]);
        if xbee {
            assert_eq!(t.frame_id(&frame), Some(xbee::NO_FRAME_ID));
            continue;
        }
        let before = frame.clone();
        assert_eq!(t.frame_id(&frame), None);
        assert!(!t.set_frame_id(&mut frame, 1));
        assert_eq!(frame, before);
        // Status frames on a PPRZ link are garbage: never a status, never a frame.
        let mut stream = s24.clone();
        stream.extend_from_slice(&before);
        stream.extend_from_slice(&s868);
        let (got, statuses, s) = decode_with_statuses::<MAX_FRAME_LEN>(t, &stream, &[1], false);
        assert_eq!(raws(&got), [before]);
        assert!(statuses.is_empty());
        assert_eq!((s.control_frames, s.control_bytes), (0, 0));
        assert_eq!(t.parse_control(&s24), None);
        assert_eq!(t.control(&s24), None);
    }
}

#[test]
fn set_frame_id_round_trip() {
    let mut rng = Rng::new(11);
    for t in xbees() {
        let other = match t {
            AnyTransport::XBee24(_) => AnyTransport::XBee868(XBee868::new()),
            _ => AnyTransport::XBee24(XBee24::new()),
        };
        for id in 0..=255u8 {
            let meta = TxMeta::new(rng.header());
            let payload: Vec<u8> = (0..rng.below(t.max_payload_len() + 1))
                .map(|_| rng.byte())
                .collect();
            let mut frame = encode(&t, &meta, &payload);
            let want = expected(&t, &meta, &payload, &frame);
            assert!(t.set_frame_id(&mut frame, id));
            assert_eq!(t.frame_id(&frame), Some(id));
            // Checksum valid: the frame decodes (loopback) to the same message.
            let sum = frame[3..].iter().fold(0u8, |a, &b| a.wrapping_add(b));
            assert_eq!(sum, 0xFF);
            let mut d: Decoder<AnyTransport> = Decoder::new(t);
            let mut input = &frame[..];
            let f = common::Owned::from(d.feed(&mut input).expect("decodes"));
            assert_eq!(f.payload, want.payload);
            assert_eq!(
                (f.source, f.msg_id, f.extra),
                (want.source, want.msg_id, want.extra)
            );
            assert_eq!(f.raw[4], id);
            // The other radio's transport does not touch it.
            let before = frame.clone();
            assert_eq!(other.frame_id(&frame), None);
            assert!(!other.set_frame_id(&mut frame, id.wrapping_add(1)));
            assert_eq!(frame, before);
            // Too short: false, untouched.
            let mut cut = frame[..frame.len() - 1].to_vec();
            assert_eq!(t.frame_id(&cut), None);
            assert!(!t.set_frame_id(&mut cut, 3));
            assert_eq!(cut, frame[..frame.len() - 1]);
        }
    }
}

/// A random XBee stream: RX and loopback frames, statuses of both kinds, noise, start
/// bytes, bit flips, cuts.
fn random_stream(t: &AnyTransport, rng: &mut Rng, parts: usize, flips: usize) -> Vec<u8> {
    let mut stream = Vec::new();
    for _ in 0..parts {
        let mut part = match rng.below(6) {
            0 => rx(t, rng.byte(), &vec![rng.byte(); rng.below(60)]),
            1 => encode(
                t,
                &TxMeta::new(rng.header()),
                &vec![rng.byte(); rng.below(60)],
            ),
            2 | 3 => status_24(rng.byte(), rng.byte()).0,
            4 => status_868(rng.byte(), rng.byte(), rng.byte()).0,
            _ => (0..rng.below(12))
                .map(|_| {
                    if rng.below(4) == 0 {
                        xbee::START
                    } else {
                        rng.byte()
                    }
                })
                .collect(),
        };
        if rng.below(1000) < flips {
            let i = rng.below(part.len().max(1));
            if let Some(b) = part.get_mut(i) {
                *b ^= 1 << rng.below(8);
            }
        } else if rng.below(10) == 0 {
            part.truncate(rng.below(part.len() + 1));
        }
        stream.extend_from_slice(&part);
    }
    stream
}

/// Whether `sub` is a subsequence of `all`.
fn subsequence(sub: &[TxStatus], all: &[TxStatus]) -> bool {
    let mut it = all.iter();
    sub.iter().all(|s| it.any(|a| a == s))
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    /// The decoder's frames and statuses are those of the whole-stream model (a valid
    /// status or frame at the current offset is taken, else one byte is skipped), for
    /// any chunking, through both entry points and with a small buffer.
    #[test]
    fn statuses_match_model(
        ti in 0usize..2,
        seed in any::<u64>(),
        parts in 0usize..60,
        flips in 0usize..400,
        chunks in proptest::collection::vec(1usize..120, 1..6),
    ) {
        let t = xbees()[ti];
        let mut rng = Rng::new(seed);
        let stream = random_stream(&t, &mut rng, parts, flips);
        for n in [MAX_FRAME_LEN, 48] {
            let (frames, statuses) = oracle_with_statuses(&t, n, &stream);
            let frames: Vec<Owned> = frames.into_iter().map(|(_, f)| f).collect();
            for borrowed in [false, true] {
                let (got, st, s) = if n == MAX_FRAME_LEN {
                    decode_with_statuses::<MAX_FRAME_LEN>(t, &stream, &chunks, borrowed)
                } else {
                    decode_with_statuses::<48>(t, &stream, &chunks, borrowed)
                };
                prop_assert_eq!(&got, &frames);
                prop_assert_eq!(s.control_frames as usize, statuses.len());
                prop_assert_eq!(s.bytes_in as usize, stream.len());
                if s.tx_status_overflows == 0 {
                    prop_assert_eq!(&st, &statuses);
                } else {
                    prop_assert!(subsequence(&st, &statuses));
                }
            }
        }
    }
}

#[test]
fn only_the_xbee_transports_have_control_frames() {
    for t in all_transports() {
        assert_eq!(t.has_control(), t.has_tx_status(), "{t:?}");
    }
    assert!(XBee24::new().has_control() && XBee868::new().has_control());
    // A decoder of a concrete XBee transport hands its statuses out as AnyTransport's does.
    let (a, sa) = status_24(5, status::SUCCESS);
    let mut d: Decoder<XBee24> = Decoder::new(XBee24::new());
    let mut input = &a[..];
    assert!(d.feed(&mut input).is_none());
    assert_eq!(d.take_tx_status(), Some(sa));
    assert_eq!(d.take_tx_status(), None);
}
