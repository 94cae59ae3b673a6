//! Streams: every chunk boundary, noise and bit-flip injection, false starts.
//!
//! "Uncorrupted frame recovered" is checked against a reference model
//! ([`common::oracle`]): a whole-stream scan that, at each offset, accepts a valid
//! frame and skips it, or else moves one byte on. The incremental decoder must give
//! exactly the oracle's frames for any chunking. An injected frame that was not
//! corrupted must be among them, unless noise happened to form a *valid* frame (right
//! length, right checksum) that starts before it and overlaps its first byte: no
//! decoder can tell such a frame from a real one, so this is the only way a good
//! frame may be missed. The deterministic test below also bounds how often it
//! happens.

mod common;

use common::{Owned, Rng, all_transports, decode_chunked, encode, expected, oracle};
use pprz_transports::{AnyTransport, Encoder, Framing, MAX_FRAME_LEN, TxMeta};
use proptest::prelude::*;

/// A stream with frames at known offsets.
struct Built {
    stream: Vec<u8>,
    /// `(offset, raw bytes)` of every injected frame left intact.
    intact: Vec<(usize, Vec<u8>)>,
    /// Decoded form of every injected frame, in order (corrupted ones included).
    all: Vec<(bool, Owned)>,
}

struct Params {
    frames: usize,
    max_payload: usize,
    /// Most noise bytes between two frames.
    noise: usize,
    /// Chance (per 1000) that a noise byte is the start byte.
    start_bytes: usize,
    /// Chance (per 1000) that a frame gets bit flips.
    flips: usize,
    /// Chance (per 1000) that a frame is cut short.
    cuts: usize,
}

fn build(t: &AnyTransport, rng: &mut Rng, p: &Params) -> Built {
    let mut stream = Vec::new();
    let mut intact = Vec::new();
    let mut all = Vec::new();
    let start = t.start_byte();
    for _ in 0..p.frames {
        for _ in 0..rng.below(p.noise + 1) {
            let b = if rng.below(1000) < p.start_bytes {
                start
            } else {
                rng.byte()
            };
            stream.push(b);
        }
        let meta = TxMeta::new(rng.header()).at(rng.next_u64() as u32);
        let len = rng.below(p.max_payload.min(t.max_payload_len()) + 1);
        let payload: Vec<u8> = (0..len).map(|_| rng.byte()).collect();
        let mut raw = encode(t, &meta, &payload);
        let want = expected(t, &meta, &payload, &raw);
        let mut ok = true;
        if rng.below(1000) < p.flips {
            for _ in 0..=rng.below(3) {
                let i = rng.below(raw.len());
                raw[i] ^= 1 << rng.below(8);
            }
            ok = raw == want.raw;
        } else if rng.below(1000) < p.cuts {
            raw.truncate(rng.below(raw.len()));
            ok = false;
        }
        if ok {
            intact.push((stream.len(), raw.clone()));
        }
        all.push((ok, want));
        stream.extend_from_slice(&raw);
    }
    Built {
        stream,
        intact,
        all,
    }
}

/// Checks decoder == oracle and that every intact frame that fits the buffer was
/// recovered or hidden under a valid noise frame. Returns the number of intact frames so hidden.
fn check_recovery<const N: usize>(t: AnyTransport, b: &Built, chunks: &[usize]) -> usize {
    let (got, _) = decode_chunked::<N>(t, &b.stream, chunks);
    let model = oracle(&t, N, &b.stream);
    let model_frames: Vec<Owned> = model.iter().map(|(_, f)| f.clone()).collect();
    assert_eq!(
        got, model_frames,
        "decoder differs from the reference model"
    );
    let mut hidden = 0;
    for (offset, raw) in b.intact.iter().filter(|(_, raw)| raw.len() <= N) {
        let found = model.iter().any(|(q, f)| q == offset && &f.raw == raw);
        if !found {
            let covered = model
                .iter()
                .any(|(q, f)| q < offset && q + f.raw.len() > *offset);
            assert!(
                covered,
                "{t:?}: intact frame at {offset} lost without a valid frame over it"
            );
            hidden += 1;
        }
    }
    hidden
}

#[test]
fn every_chunk_boundary() {
    for t in all_transports() {
        let mut rng = Rng::new(7);
        // Garbage without start bytes, so the expected output is exactly the frames.
        let b = build(
            &t,
            &mut rng,
            &Params {
                frames: 12,
                max_payload: 40,
                noise: 5,
                start_bytes: 0,
                flips: 0,
                cuts: 0,
            },
        );
        let mut clean = b.stream.clone();
        let mut pos = 0;
        for (offset, raw) in &b.intact {
            for byte in &mut clean[pos..*offset] {
                if *byte == t.start_byte() {
                    *byte ^= 0x01;
                }
            }
            pos = offset + raw.len();
        }
        let want: Vec<Owned> = b.all.iter().map(|(_, f)| f.clone()).collect();
        let whole = decode_chunked::<MAX_FRAME_LEN>(t, &clean, &[clean.len()]).0;
        assert_eq!(whole, want, "{t:?}");
        // Two chunks, split at every offset.
        for k in 0..=clean.len() {
            let (got, stats) = decode_chunked::<MAX_FRAME_LEN>(t, &clean, &[k, clean.len()]);
            assert_eq!(got, want, "{t:?} split at {k}");
            assert_eq!(stats.errors(), 0);
        }
        // One byte at a time, and every chunk size up to 64.
        for size in 1..=64 {
            let got = decode_chunked::<MAX_FRAME_LEN>(t, &clean, &[size]).0;
            assert_eq!(got, want, "{t:?} chunk size {size}");
        }
    }
}

#[test]
fn noise_and_bit_flips_deterministic() {
    let mut total = 0;
    let mut hidden = 0;
    for t in all_transports() {
        let before = hidden;
        for seed in 0..40 {
            let mut rng = Rng::new(2000 + seed);
            let b = build(
                &t,
                &mut rng,
                &Params {
                    frames: 40,
                    max_payload: 251,
                    noise: 30,
                    start_bytes: 150,
                    flips: 250,
                    cuts: 100,
                },
            );
            let sizes: Vec<usize> = (0..5).map(|_| 1 + rng.below(97)).collect();
            hidden += check_recovery::<MAX_FRAME_LEN>(t, &b, &sizes);
            total += b.intact.len();
        }
        eprintln!("{t:?}: {} hidden", hidden - before);
    }
    eprintln!("{hidden} of {total} intact frames hidden under valid noise frames");
    // Noise forming a valid frame over a good one is rare (8-bit checksums are the
    // weak point); most runs see none. Over seed bases 1000..6000 step 1000 the count
    // was 10 to 28 of about 5400 (mean 16): the bound is about twice the mean.
    assert!(
        hidden * 200 <= total,
        "{hidden} of {total} intact frames hidden"
    );
}

#[test]
fn small_buffer_matches_model() {
    for t in all_transports() {
        let mut rng = Rng::new(99);
        let b = build(
            &t,
            &mut rng,
            &Params {
                frames: 60,
                max_payload: 80,
                noise: 10,
                start_bytes: 200,
                flips: 200,
                cuts: 100,
            },
        );
        check_recovery::<48>(t, &b, &[1, 7, 13]);
    }
}

#[test]
fn frame_after_false_start_is_found() {
    for t in all_transports() {
        let start = t.start_byte();
        let raw = encode(&t, &TxMeta::default(), &[1, 2, 3]);
        // False starts announcing the longest, the shortest and impossible lengths.
        for prefix in [
            vec![start, 0xFF, 0xFF],
            vec![start, 0x00, 0xF0],
            vec![start, 0x00, 0x01],
            vec![start, 0x00],
            vec![start; 300],
        ] {
            let mut stream = prefix.clone();
            stream.extend_from_slice(&raw);
            let model = oracle(&t, MAX_FRAME_LEN, &stream);
            if matches!(t, AnyTransport::PprzLog(_)) && prefix.len() == 300 {
                // 99 99 .. 99 07 happens to be a valid PPRZLOG record (LEN = SOURCE =
                // 0x99, DATA all 0x99, CK = 159 * 0x99 mod 256 = 0x07 = the real
                // frame's LEN byte): the 8-bit sum cannot tell. It ends on the real
                // frame's second byte.
                assert_eq!(model.len(), 1);
                assert_eq!(model[0].0 + model[0].1.raw.len(), 302);
            } else {
                assert_eq!(model.len(), 1, "{t:?} prefix {:02X?}", &prefix[..3]);
                assert_eq!(model[0].1.raw, raw);
            }
            for size in [1, 2, 5, stream.len()] {
                let (got, _) = decode_chunked::<MAX_FRAME_LEN>(t, &stream, &[size]);
                assert_eq!(got, vec![model[0].1.clone()]);
            }
        }
    }
}

#[test]
fn good_frame_starting_inside_a_bad_one() {
    for t in all_transports() {
        let meta = TxMeta::new(pprz_transports::MsgHeader::new(3, 0, 1, 42)).at(7777);
        let a = encode(&t, &meta, &[9; 30]);
        let b = encode(&t, &meta, &[4, 5, 6]);
        // Cut `a` short: `b` starts inside the bytes `a` announced.
        let mut stream = a[..a.len() / 2].to_vec();
        stream.extend_from_slice(&b);
        stream.extend_from_slice(&a);
        let (got, _) = decode_chunked::<MAX_FRAME_LEN>(t, &stream, &[1]);
        let raws: Vec<&[u8]> = got.iter().map(|f| f.raw.as_slice()).collect();
        assert_eq!(raws, [&b[..], &a[..]], "{t:?}");
    }
}

#[test]
fn pure_noise_never_panics_and_keeps_invariants() {
    for t in all_transports() {
        let mut rng = Rng::new(5);
        for _ in 0..50 {
            let len = rng.below(3000);
            let noise: Vec<u8> = (0..len)
                .map(|_| {
                    if rng.below(4) == 0 {
                        t.start_byte()
                    } else {
                        rng.byte()
                    }
                })
                .collect();
            let (got, stats) = decode_chunked::<MAX_FRAME_LEN>(t, &noise, &[1 + rng.below(64)]);
            assert_eq!(got.len() as u32, stats.frames);
            let model = oracle(&t, MAX_FRAME_LEN, &noise);
            assert_eq!(got.len(), model.len());
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn noise_and_bit_flips(
        ti in 0usize..5,
        seed in any::<u64>(),
        frames in 1usize..30,
        noise in 0usize..40,
        start_bytes in 0usize..500,
        flips in 0usize..500,
        chunks in proptest::collection::vec(1usize..120, 1..6),
    ) {
        let t = all_transports()[ti];
        let mut rng = Rng::new(seed);
        let b = build(&t, &mut rng, &Params {
            frames, max_payload: 251, noise, start_bytes, flips, cuts: 100,
        });
        check_recovery::<MAX_FRAME_LEN>(t, &b, &chunks);
    }

    #[test]
    fn arbitrary_bytes_match_model(
        ti in 0usize..5,
        bytes in proptest::collection::vec(any::<u8>(), 0..1500),
        chunks in proptest::collection::vec(1usize..300, 1..6),
    ) {
        let t = all_transports()[ti];
        let (got, stats) = decode_chunked::<MAX_FRAME_LEN>(t, &bytes, &chunks);
        let model: Vec<Owned> = oracle(&t, MAX_FRAME_LEN, &bytes).into_iter().map(|(_, f)| f).collect();
        prop_assert_eq!(got, model);
        prop_assert_eq!(stats.bytes_in as usize, bytes.len());
    }
}

#[test]
fn max_payload_is_respected_by_decoded_frames() {
    // Received frames may carry more than we send (XBee 868: 252 field bytes) but
    // never more than the transport's receive limit.
    for t in all_transports() {
        let mut rng = Rng::new(3);
        let b = build(
            &t,
            &mut rng,
            &Params {
                frames: 30,
                max_payload: 251,
                noise: 3,
                start_bytes: 100,
                flips: 100,
                cuts: 0,
            },
        );
        let (got, _) = decode_chunked::<MAX_FRAME_LEN>(t, &b.stream, &[64]);
        for f in got {
            assert!(f.raw.len() <= t.max_rx_frame_len());
            assert!(f.payload.len() < f.raw.len());
        }
        assert!(t.max_frame_len() <= t.max_rx_frame_len());
    }
}
