//! Property tests: encode -> decode is the identity for every transport, for random
//! headers, time stamps and payload sizes from 0 to the transport's maximum, one
//! frame or many in a stream, fed in random chunks.

mod common;

use common::{all_transports, decode_chunked, encode, expected};
use pprz_transports::{
    AnyTransport, Encoder, Framing, MAX_FRAME_LEN, MsgHeader, PprzLogDecoder, PprzV1Decoder,
    PprzV2Decoder, TxMeta, XBee24Decoder, XBee868Decoder,
};
use proptest::collection::vec;
use proptest::prelude::*;

fn meta_strategy() -> impl Strategy<Value = TxMeta> {
    (
        any::<u8>(),
        any::<u8>(),
        0u8..16,
        0u8..16,
        any::<u8>(),
        any::<u32>(),
    )
        .prop_map(|(src, dst, class, comp, id, ts)| {
            TxMeta::new(MsgHeader::new(src, dst, class, id).with_component(comp)).at(ts)
        })
}

/// A message: metadata, a size selector and bytes (the payload is the first
/// `sel % (max + 1)` bytes, so every size 0..=max is reachable for every transport).
fn msg_strategy() -> impl Strategy<Value = (TxMeta, usize, Vec<u8>)> {
    (meta_strategy(), any::<usize>(), vec(any::<u8>(), 251))
}

fn payload(t: &AnyTransport, sel: usize, bytes: &[u8]) -> Vec<u8> {
    bytes[..sel % (t.max_payload_len() + 1)].to_vec()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(512))]

    #[test]
    fn single_frame_identity(ti in 0usize..5, (meta, sel, bytes) in msg_strategy()) {
        let t = all_transports()[ti];
        let p = payload(&t, sel, &bytes);
        let raw = encode(&t, &meta, &p);
        prop_assert_eq!(raw.len(), t.frame_len(p.len()).unwrap());
        let (frame, len) = t.parse(&raw).unwrap();
        prop_assert_eq!(len, raw.len());
        prop_assert_eq!(common::Owned::from(frame), expected(&t, &meta, &p, &raw));
        // The frame's own metadata re-encodes to the same bytes (XBee: as loopback).
        let again = encode(&t, &frame.tx_meta(), frame.payload());
        prop_assert_eq!(again, raw);
    }

    #[test]
    fn stream_identity(
        ti in 0usize..5,
        msgs in vec(msg_strategy(), 1..16),
        chunks in vec(1usize..80, 1..8),
    ) {
        let t = all_transports()[ti];
        let mut stream = Vec::new();
        let mut want = Vec::new();
        for (meta, sel, bytes) in &msgs {
            let p = payload(&t, *sel, bytes);
            let raw = encode(&t, meta, &p);
            want.push(expected(&t, meta, &p, &raw));
            stream.extend_from_slice(&raw);
        }
        let (got, stats) = decode_chunked::<MAX_FRAME_LEN>(t, &stream, &chunks);
        prop_assert_eq!(&got, &want);
        prop_assert_eq!(stats.frames as usize, msgs.len());
        prop_assert_eq!(stats.errors(), 0);
        prop_assert_eq!(stats.dropped_bytes, 0);
    }
}

/// The per-transport decoder aliases (exact buffer sizes) accept their largest
/// frames.
#[test]
fn typed_decoders_accept_largest_frames() {
    let meta = TxMeta::new(MsgHeader::new(1, 2, 3, 4).with_component(5)).at(6);
    let big = [0xA5u8; 251];
    macro_rules! go {
        ($($dec:ty => $t:expr),*) => {$({
            type D = $dec;
            let t = $t;
            let mut buf = [0u8; MAX_FRAME_LEN];
            let n = t.encode(&meta, &big[..t.max_payload_len()], &mut buf).unwrap();
            let mut d = D::new(t);
            assert!(d.capacity() >= n);
            let mut input = &buf[..n];
            let f = d.feed(&mut input).expect("largest frame");
            assert_eq!(f.payload().len(), t.max_payload_len());
            assert_eq!(f.raw().len(), n);
        })*};
    }
    go!(
        PprzV1Decoder => pprz_transports::PprzV1::new(2),
        PprzV2Decoder => pprz_transports::PprzV2::new(),
        XBee24Decoder => pprz_transports::XBee24::new(),
        XBee868Decoder => pprz_transports::XBee868::new(),
        PprzLogDecoder => pprz_transports::PprzLog::TELEMETRY
    );
}
