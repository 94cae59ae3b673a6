//! Shared harness of the decoder fuzz targets.
//!
//! Input layout: the first byte seeds the chunk sizes, the rest is the byte stream.
//! The stream is decoded three ways (in the chunks the seed chooses, in one piece,
//! and with a 32-byte buffer); the harness checks:
//!
//! * no panic, and `feed` returns `None` only once its chunk is used up;
//! * the stats invariant
//!   `bytes_in == frame_bytes + control_bytes + dropped_bytes + buffered`;
//! * every control frame (XBee transmit status) is taken with `take_tx_status` or
//!   counted as a ring overflow; none on the PPRZ transports; each status taken is a
//!   valid status frame's (re-encodes to a frame that `parse_control` reads back);
//! * every frame re-parses to itself, fits the transport's receive limit, and its
//!   payload is a suffix of its data, which lies inside the raw frame;
//! * PPRZ v1/v2 and PPRZLOG frames re-encode to their exact bytes;
//! * chunking does not change the frames and statuses found (statuses are compared
//!   when the ring did not overflow; otherwise those taken are in the model's order);
//! * a 32-byte decoder finds exactly the frames of at most 32 bytes that the model
//!   (a whole-stream scan taking a valid status or frame at each offset, else
//!   skipping one byte) finds.

use pprz_test_support::chunked::{feed_in_chunks, ChunkFeed};
use pprz_transports::{
    xbee, AnyTransport, Control, Decoder, DecoderStats, Encoder, Extra, Frame, Framing, PprzLog,
    TxStatus, MAX_FRAME_LEN, TX_STATUS_CAPACITY,
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
            .wrapping_add(s.control_bytes)
            .wrapping_add(s.dropped_bytes)
            .wrapping_add(d.buffered() as u32)
    );
    assert!(d.buffered() <= N);
    assert!(d.tx_statuses_pending() <= TX_STATUS_CAPACITY);
    if !d.framing().has_tx_status() {
        assert_eq!((s.control_frames, s.control_bytes), (0, 0));
    }
}

/// A status taken from the decoder must be a valid status frame's: re-encoded in
/// either layout, it parses back to itself.
fn check_status(t: &AnyTransport, s: &TxStatus) {
    assert!(t.has_tx_status());
    assert_eq!(s.delivered, s.status == xbee::status::SUCCESS);
    let mut buf = [0u8; 16];
    let n = xbee::encode_tx_status_868(s.frame_id, s.retries, s.status, 0, &mut buf)
        .expect("a status frame fits 16 bytes");
    assert_eq!(t.parse_control(&buf), Some((Control::TxStatus(*s), n)));
    if s.retries == 0 {
        let n = xbee::encode_tx_status_24(s.frame_id, s.status, &mut buf)
            .expect("a status frame fits 16 bytes");
        assert_eq!(t.parse_control(&buf), Some((Control::TxStatus(*s), n)));
    }
}

/// What one decoding run found.
#[derive(Debug, PartialEq)]
struct Found {
    frames: Vec<Vec<u8>>,
    statuses: Vec<TxStatus>,
    overflows: u32,
}

impl Found {
    /// Chunking changes only where statuses are taken from the ring, so what is taken
    /// is the same unless the ring overflowed.
    fn same_as(&self, other: &Found) {
        assert_eq!(self.frames, other.frames);
        if self.overflows == 0 && other.overflows == 0 {
            assert_eq!(self.statuses, other.statuses);
        }
    }

    /// Against the model: the same frames; the same statuses, or, after an overflow,
    /// the model's statuses less as many as were dropped, in order.
    fn matches_model(&self, model: &Found) {
        assert_eq!(self.frames, model.frames);
        assert_eq!(
            self.statuses.len() + self.overflows as usize,
            model.statuses.len()
        );
        let mut it = model.statuses.iter();
        assert!(self.statuses.iter().all(|s| it.any(|m| m == s)));
    }
}

/// A decoding run of [`decode`] for the chunked-feed harness.
struct Run<const N: usize> {
    t: AnyTransport,
    d: Decoder<AnyTransport, N>,
    borrowed: bool,
    out: Vec<Vec<u8>>,
    statuses: Vec<TxStatus>,
}

impl<const N: usize> Run<N> {
    /// Takes the statuses waiting in the decoder, checking each.
    fn take(&mut self) {
        while let Some(s) = self.d.take_tx_status() {
            check_status(&self.t, &s);
            self.statuses.push(s);
        }
    }
}

impl<const N: usize> ChunkFeed for Run<N> {
    fn feed(&mut self, input: &mut &[u8]) -> bool {
        let frame = if self.borrowed {
            self.d.feed_borrowed(input)
        } else {
            self.d.feed(input)
        };
        let Some(f) = frame else { return false };
        check_frame(&self.t, &f);
        self.out.push(f.raw().to_vec());
        self.take();
        true
    }

    fn chunk_done(&mut self) {
        check_stats(&self.d);
        self.take();
    }

    fn flush(&mut self) -> bool {
        let Some(f) = self.d.flush() else {
            return false;
        };
        check_frame(&self.t, &f);
        self.out.push(f.raw().to_vec());
        self.take();
        true
    }
}

/// Decodes `stream` in chunks drawn from `seed` (0: one chunk), with `feed` or, when
/// `borrowed`, with the zero-copy `feed_borrowed`.
fn decode<const N: usize>(t: AnyTransport, stream: &[u8], seed: u8, borrowed: bool) -> Found {
    let mut run = Run::<N> {
        t,
        d: Decoder::new(t),
        borrowed,
        out: Vec::new(),
        statuses: Vec::new(),
    };
    let mut state = u32::from(seed);
    let sizes = std::iter::repeat_with(move || {
        state = state.wrapping_mul(1_103_515_245).wrapping_add(12_345);
        if seed == 0 {
            usize::MAX
        } else {
            1 + (state >> 16) as usize % 300
        }
    });
    feed_in_chunks(&mut run, stream, sizes);
    run.take();
    let Run {
        d, out, statuses, ..
    } = run;
    assert_eq!(d.buffered(), 0);
    check_stats(&d);
    let s = *d.stats();
    assert_eq!(s.bytes_in as usize, stream.len());
    assert_eq!(s.frames as usize, out.len());
    assert_eq!(
        s.control_frames as usize,
        statuses.len() + s.tx_status_overflows as usize
    );
    Found {
        frames: out,
        statuses,
        overflows: s.tx_status_overflows,
    }
}

/// Whole-stream reference scan (see the module doc).
fn model(t: &AnyTransport, n: usize, stream: &[u8]) -> Found {
    let mut out = Vec::new();
    let mut statuses = Vec::new();
    let mut pos = 0;
    while pos < stream.len() {
        if let Some((control, len)) = t.parse_control(&stream[pos..]) {
            if len <= n {
                match control {
                    Control::TxStatus(s) => statuses.push(s),
                    other => panic!("unexpected control frame {other:?}"),
                }
                pos += len;
                continue;
            }
        }
        if let Ok((f, len)) = t.parse(&stream[pos..]) {
            if len <= n {
                out.push(f.raw().to_vec());
                pos += len;
                continue;
            }
        }
        pos += 1;
    }
    Found {
        frames: out,
        statuses,
        overflows: 0,
    }
}

/// Runs every check on `data` with transport `t`.
pub fn run(t: AnyTransport, data: &[u8]) {
    let Some((&seed, stream)) = data.split_first() else {
        return;
    };
    let chunked = decode::<MAX_FRAME_LEN>(t, stream, seed, false);
    let whole = decode::<MAX_FRAME_LEN>(t, stream, 0, false);
    chunked.same_as(&whole);
    let reference = model(&t, MAX_FRAME_LEN, stream);
    chunked.matches_model(&reference);
    whole.matches_model(&reference);
    // The zero-copy path finds exactly the same frames and statuses, taken at the same
    // points (it returns at the same frames).
    assert_eq!(decode::<MAX_FRAME_LEN>(t, stream, seed, true), chunked);
    let small = decode::<32>(t, stream, seed, false);
    small.matches_model(&model(&t, 32, stream));
    assert_eq!(decode::<32>(t, stream, seed, true), small);
}

/// The transport a selector byte names (modulo 5): PPRZ v2, PPRZ v1, XBee 2.4 GHz, XBee
/// 868 MHz, PPRZLOG.
pub fn transport(selector: u8) -> AnyTransport {
    use pprz_transports::{PprzV1, PprzV2, XBee24, XBee868};
    match selector % 5 {
        0 => PprzV2::new().into(),
        1 => PprzV1::new(1).into(),
        2 => XBee24::default().into(),
        3 => XBee868::default().into(),
        _ => PprzLog::TELEMETRY.into(),
    }
}

/// The PPRZLINK reference message set, loaded once from the reference directory
/// (`pprz_test_support::reference::dir`); panics at start-up, naming the fuzz `target`,
/// the path and the variable that sets it, when it is missing.
pub fn reference_set(target: &str) -> pprz_ground::set::RuntimeSet {
    use pprz_ground::set::RuntimeSet;
    static SET: std::sync::OnceLock<RuntimeSet> = std::sync::OnceLock::new();
    *SET.get_or_init(|| {
        let path = pprz_test_support::reference::dir().join("messages.xml");
        RuntimeSet::load(&path).unwrap_or_else(|e| {
            panic!(
                "the {target} fuzz target needs the PPRZLINK reference messages.xml: cannot load {} ({e}); set {} to the directory that holds it",
                path.display(),
                pprz_test_support::reference::DIR_VAR
            )
        })
    })
}
