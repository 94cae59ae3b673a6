//! Shared harness of the decoder fuzz targets.
//!
//! Input layout: the first byte seeds the chunk sizes, the rest is the byte stream.
//! The stream is decoded three ways (in the chunks the seed chooses, in one piece,
//! and with a 32-byte buffer); the harness checks:
//!
//! * no panic, and `feed` returns `None` only once its chunk is used up;
//! * the stats invariant `bytes_in == frame_bytes + dropped_bytes + buffered`;
//! * every frame re-parses to itself, fits the transport's receive limit, and its
//!   payload is a suffix of its data, which lies inside the raw frame;
//! * PPRZ v1/v2 and PPRZLOG frames re-encode to their exact bytes;
//! * chunking does not change the frames found;
//! * a 32-byte decoder finds exactly the frames of at most 32 bytes that the model
//!   (a whole-stream scan) finds.

use pprz_transports::{
    AnyTransport, Decoder, DecoderStats, Encoder, Extra, Frame, Framing, PprzLog, MAX_FRAME_LEN,
};

fn check_frame(t: &AnyTransport, f: &Frame<'_>) {
    let raw = f.raw();
    assert!(raw.len() <= t.max_rx_frame_len());
    assert!(f.payload().len() <= f.data().len());
    assert!(f.data().ends_with(f.payload()));
    assert!(raw.windows(f.data().len()).any(|w| w == f.data()) || f.data().is_empty());
    let (again, len) = t.parse(raw).expect("a decoded frame must re-parse");
    assert_eq!(len, raw.len());
    assert_eq!(again, *f);
    let reencoder = match (t, f.extra()) {
        (AnyTransport::PprzV1(_) | AnyTransport::PprzV2(_), _) => Some(*t),
        (AnyTransport::PprzLog(_), Extra::Log(l)) => {
            Some(AnyTransport::PprzLog(PprzLog::new(l.source)))
        }
        _ => None,
    };
    if let Some(e) = reencoder {
        let mut buf = [0u8; MAX_FRAME_LEN];
        let n = e
            .encode(&f.tx_meta(), f.payload(), &mut buf)
            .expect("a decoded frame must re-encode");
        assert_eq!(&buf[..n], raw);
    }
}

fn check_stats<const N: usize>(d: &Decoder<AnyTransport, N>) {
    let s: &DecoderStats = d.stats();
    assert_eq!(
        s.bytes_in,
        s.frame_bytes
            .wrapping_add(s.dropped_bytes)
            .wrapping_add(d.buffered() as u32)
    );
    assert!(d.buffered() <= N);
}

/// Decodes `stream` in chunks drawn from `seed` (0: one chunk), with `feed` or, when
/// `borrowed`, with the zero-copy `feed_borrowed`.
fn decode<const N: usize>(
    t: AnyTransport,
    stream: &[u8],
    seed: u8,
    borrowed: bool,
) -> Vec<Vec<u8>> {
    let mut d: Decoder<AnyTransport, N> = Decoder::new(t);
    let mut out = Vec::new();
    let mut state = u32::from(seed);
    let mut rest = stream;
    while !rest.is_empty() {
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        let size = if seed == 0 {
            rest.len()
        } else {
            1 + (state >> 16) as usize % 300
        };
        let (chunk, tail) = rest.split_at(size.min(rest.len()));
        rest = tail;
        let mut input = chunk;
        loop {
            let frame = if borrowed {
                d.feed_borrowed(&mut input)
            } else {
                d.feed(&mut input)
            };
            let Some(f) = frame else { break };
            check_frame(&t, &f);
            out.push(f.raw().to_vec());
        }
        assert!(input.is_empty());
        check_stats(&d);
    }
    while let Some(f) = d.flush() {
        check_frame(&t, &f);
        out.push(f.raw().to_vec());
    }
    assert_eq!(d.buffered(), 0);
    check_stats(&d);
    assert_eq!(d.stats().bytes_in as usize, stream.len());
    assert_eq!(d.stats().frames as usize, out.len());
    out
}

/// Whole-stream reference scan (see the module doc).
fn model(t: &AnyTransport, n: usize, stream: &[u8]) -> Vec<Vec<u8>> {
    let mut out = Vec::new();
    let mut pos = 0;
    while pos < stream.len() {
        if let Ok((f, len)) = t.parse(&stream[pos..]) {
            if len <= n {
                out.push(f.raw().to_vec());
                pos += len;
                continue;
            }
        }
        pos += 1;
    }
    out
}

/// Runs every check on `data` with transport `t`.
pub fn run(t: AnyTransport, data: &[u8]) {
    let Some((&seed, stream)) = data.split_first() else {
        return;
    };
    let chunked = decode::<MAX_FRAME_LEN>(t, stream, seed, false);
    let whole = decode::<MAX_FRAME_LEN>(t, stream, 0, false);
    assert_eq!(chunked, whole);
    assert_eq!(whole, model(&t, MAX_FRAME_LEN, stream));
    // The zero-copy path finds exactly the same frames.
    assert_eq!(decode::<MAX_FRAME_LEN>(t, stream, seed, true), whole);
    let small = decode::<32>(t, stream, seed, false);
    assert_eq!(small, model(&t, 32, stream));
    assert_eq!(decode::<32>(t, stream, seed, true), small);
}
