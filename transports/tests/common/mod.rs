//! Helpers shared by the integration tests (std is fine here).
#![allow(dead_code)]

use pprz_test_support::chunked::{ChunkFeed, cycled, feed_in_chunks};
use pprz_transports::{
    AnyTransport, Control, Decoder, DecoderStats, Encoder, Extra, Frame, Framing, MsgHeader,
    PprzLog, PprzV1, PprzV2, TxMeta, TxStatus, XBee24, XBee868, xbee,
};

/// Every transport, with the configuration the tests use.
pub fn all_transports() -> [AnyTransport; 5] {
    [
        AnyTransport::PprzV1(PprzV1::new(1)),
        AnyTransport::PprzV2(PprzV2::new()),
        AnyTransport::XBee24(XBee24::new()),
        AnyTransport::XBee868(XBee868::new()),
        AnyTransport::PprzLog(PprzLog::DATALINK),
    ]
}

/// A received frame, owned, for comparisons.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Owned {
    pub source: u8,
    pub destination: Option<u8>,
    pub class: u8,
    pub component: u8,
    pub msg_id: u8,
    pub payload: Vec<u8>,
    pub raw: Vec<u8>,
    pub extra: Extra,
}

impl From<Frame<'_>> for Owned {
    fn from(f: Frame<'_>) -> Self {
        Self {
            source: f.source(),
            destination: f.destination(),
            class: f.class(),
            component: f.component(),
            msg_id: f.msg_id(),
            payload: f.payload().to_vec(),
            raw: f.raw().to_vec(),
            extra: f.extra(),
        }
    }
}

/// Encodes one frame.
pub fn encode(t: &AnyTransport, meta: &TxMeta, payload: &[u8]) -> Vec<u8> {
    let mut buf = [0u8; pprz_transports::MAX_FRAME_LEN];
    let n = t.encode(meta, payload, &mut buf).expect("encode");
    buf[..n].to_vec()
}

/// What a decoder must report for a frame `t` encoded from `meta` and `payload`.
pub fn expected(t: &AnyTransport, meta: &TxMeta, payload: &[u8], raw: &[u8]) -> Owned {
    let h = meta.header;
    let mut o = Owned {
        source: h.source,
        destination: Some(h.destination),
        class: h.class,
        component: h.component,
        msg_id: h.msg_id,
        payload: payload.to_vec(),
        raw: raw.to_vec(),
        extra: Extra::None,
    };
    match t {
        AnyTransport::PprzV1(v1) => {
            o.destination = None;
            o.class = v1.rx_class;
            o.component = 0;
        }
        AnyTransport::XBee24(x) => {
            o.extra = Extra::XBee(pprz_transports::XBeeInfo {
                api_id: xbee::API_TX16,
                address: u64::from(xbee::address16(h.destination)),
                rssi: None,
                options: x.options,
            });
        }
        AnyTransport::XBee868(x) => {
            o.extra = Extra::XBee(pprz_transports::XBeeInfo {
                api_id: xbee::API_TX_868,
                address: xbee::address64(h.destination),
                rssi: None,
                options: x.options,
            });
        }
        AnyTransport::PprzLog(l) => {
            o.extra = Extra::Log(pprz_transports::LogInfo {
                source: l.source,
                timestamp: meta.timestamp,
            });
        }
        _ => {}
    }
    o
}

/// Feeds `stream` to a fresh decoder in chunks whose sizes come from `sizes`
/// (cycled; 0 means 1), then flushes. Checks the stats invariant at every step.
pub fn decode_chunked<const N: usize>(
    t: AnyTransport,
    stream: &[u8],
    sizes: &[usize],
) -> (Vec<Owned>, DecoderStats) {
    let (frames, _, stats) = decode_with_statuses::<N>(t, stream, sizes, false);
    (frames, stats)
}

/// A decoding run of [`decode_with_statuses`] for the chunked-feed harness.
struct Run<const N: usize> {
    d: Decoder<AnyTransport, N>,
    borrowed: bool,
    out: Vec<Owned>,
    statuses: Vec<TxStatus>,
}

impl<const N: usize> Run<N> {
    fn take_statuses(&mut self) {
        self.statuses
            .extend(std::iter::from_fn(|| self.d.take_tx_status()));
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
        self.out.push(Owned::from(f));
        self.take_statuses();
        true
    }

    fn chunk_done(&mut self) {
        self.take_statuses();
        check_invariant(&self.d);
    }

    fn flush(&mut self) -> bool {
        let Some(f) = self.d.flush() else {
            return false;
        };
        self.out.push(Owned::from(f));
        self.take_statuses();
        true
    }
}

/// [`decode_chunked`], through `feed_borrowed` when `borrowed`, also returning the
/// transmit statuses, taken after every call. Checks that every control frame's status
/// was taken or counted as an overflow.
pub fn decode_with_statuses<const N: usize>(
    t: AnyTransport,
    stream: &[u8],
    sizes: &[usize],
    borrowed: bool,
) -> (Vec<Owned>, Vec<TxStatus>, DecoderStats) {
    let mut run = Run::<N> {
        d: Decoder::new(t),
        borrowed,
        out: Vec::new(),
        statuses: Vec::new(),
    };
    feed_in_chunks(&mut run, stream, cycled(sizes));
    run.take_statuses();
    let Run {
        d, out, statuses, ..
    } = run;
    assert_eq!(d.buffered(), 0);
    check_invariant(&d);
    let s = *d.stats();
    assert_eq!(s.frames as usize, out.len());
    assert_eq!(
        s.control_frames as usize,
        statuses.len() + s.tx_status_overflows as usize
    );
    (out, statuses, s)
}

pub fn check_invariant<const N: usize>(d: &Decoder<AnyTransport, N>) {
    let s = d.stats();
    assert_eq!(
        s.bytes_in,
        s.frame_bytes
            .wrapping_add(s.control_bytes)
            .wrapping_add(s.dropped_bytes)
            .wrapping_add(d.buffered() as u32),
        "stats invariant: {s:?}, buffered {}",
        d.buffered()
    );
}

/// Reference model: a whole-stream, non-incremental scan with the same acceptance
/// rule (a valid control frame or frame no longer than `n` bytes at the current
/// position is taken whole; anything else advances one byte). Returns `(offset, frame)`.
pub fn oracle(t: &AnyTransport, n: usize, stream: &[u8]) -> Vec<(usize, Owned)> {
    oracle_with_statuses(t, n, stream).0
}

/// [`oracle`], also returning the transmit statuses of the control frames taken.
pub fn oracle_with_statuses(
    t: &AnyTransport,
    n: usize,
    stream: &[u8],
) -> (Vec<(usize, Owned)>, Vec<TxStatus>) {
    let mut out = Vec::new();
    let mut statuses = Vec::new();
    let mut pos = 0;
    while pos < stream.len() {
        let here = &stream[pos..];
        if let Some((control, len)) = t.parse_control(here)
            && len <= n
        {
            match control {
                Control::TxStatus(s) => statuses.push(s),
                other => panic!("unexpected control frame {other:?}"),
            }
            pos += len;
            continue;
        }
        if let Ok((frame, len)) = t.parse(here)
            && len <= n
        {
            out.push((pos, Owned::from(frame)));
            pos += len;
            continue;
        }
        pos += 1;
    }
    (out, statuses)
}

/// The seeded generator of the tests (the workspace's one SplitMix64), with the helpers
/// these tests draw frames with.
pub struct Rng(pprz_test_support::rng::Rng);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(pprz_test_support::rng::Rng::new(seed))
    }
    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }
    pub fn below(&mut self, n: usize) -> usize {
        (self.next_u64() % n.max(1) as u64) as usize
    }
    pub fn byte(&mut self) -> u8 {
        self.next_u64() as u8
    }
    pub fn header(&mut self) -> MsgHeader {
        MsgHeader::new(self.byte(), self.byte(), self.below(16) as u8, self.byte())
            .with_component(self.below(16) as u8)
    }
}
