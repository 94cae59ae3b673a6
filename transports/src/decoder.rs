//! The incremental decoder: bytes in arbitrary chunks in, verified frames out.
//!
//! [`Decoder`] keeps the bytes of at most one frame candidate in a fixed buffer of
//! `N` bytes and never allocates. Its algorithm, the same for every transport:
//!
//! 1. Bytes before a start byte are dropped (counted in
//!    [`DecoderStats::dropped_bytes`]).
//! 2. At a start byte, the [`Framing`] reads the frame length from the first bytes.
//!    An impossible length, a frame longer than `N`, a bad checksum or (XBee) an
//!    API id the transport does not carry *rejects* the candidate.
//! 3. A rejected candidate loses **only its start byte**: the bytes after it, which
//!    are still in the buffer, are scanned again. A good frame that begins inside
//!    a bad one (for example after a false start byte in noise that announced a
//!    long frame) is therefore found as soon as its own bytes have arrived.
//! 4. A complete, verified frame is handed out as a borrowed [`Frame`] and its bytes
//!    are consumed; scanning goes on after it.
//! 5. A complete, verified *control* frame ([`Framing::control`]: an XBee transmit
//!    status) is not handed out: its bytes are consumed (counted in
//!    [`DecoderStats::control_frames`] and [`DecoderStats::control_bytes`]), the
//!    [`TxStatus`] it carries goes to a ring of [`TX_STATUS_CAPACITY`] entries, read
//!    with [`Decoder::take_tx_status`], and scanning goes on after it. An invalid one
//!    (bad checksum, a length its API id does not have) is rejected as in step 2,
//!    counted in [`DecoderStats::checksum_errors`] or [`DecoderStats::length_errors`].
//!    The PPRZ transports and PPRZLOG have no control frames.
//!
//! [`Decoder::feed`] copies every byte into the buffer and hands out views of it.
//! [`Decoder::feed_borrowed`] finds the same frames but reads a frame that arrives whole
//! in one input where it is, and hands out a view of the input (no copy).
//!
//! A false start byte that announces a long frame delays the frames after it until
//! that many bytes have arrived (or until [`Decoder::flush`]); it never loses them.
//! At the end of a stream (end of file, or a link that went silent), call
//! [`Decoder::flush`] to give up on an incomplete candidate and rescan what is
//! buffered.
//!
//! One corrupted frame may be counted several times (once per false start byte
//! rescanned inside it); the counters measure rejected candidates, not lost frames.
//!
//! # Example
//!
//! ```
//! use pprz_transports::{Decoder, PprzV2};
//! let mut decoder: Decoder<PprzV2, 255> = Decoder::new(PprzV2::new());
//! let stream = [0x12, 0x99, 0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x1C, 0xC4];
//! let mut found = 0;
//! for chunk in stream.chunks(5) {
//!     let mut input = chunk;
//!     while let Some(frame) = decoder.feed(&mut input) {
//!         assert_eq!((frame.source(), frame.msg_id()), (7, 2));
//!         found += 1;
//!     }
//!     assert!(input.is_empty()); // feed returns None only once the chunk is used up
//! }
//! assert_eq!(found, 1);
//! assert_eq!(decoder.stats().dropped_bytes, 1);
//! ```

use crate::transport::{Control, Frame, Framing, RxError, TxStatus};

/// Smallest decoder buffer accepted at compile time.
pub const MIN_BUFFER_LEN: usize = 16;

/// Transmit statuses a [`Decoder`] keeps until [`Decoder::take_tx_status`] takes them;
/// when the ring is full, a new status drops the oldest one
/// ([`DecoderStats::tx_status_overflows`]).
///
/// A module sends one status per transmit request with a frame id, so a writer that
/// keeps at most this many such requests in flight, and whose statuses are taken after
/// every [`feed`](Decoder::feed) call, never loses one.
pub const TX_STATUS_CAPACITY: usize = 8;

/// Counters of a [`Decoder`]. All wrap around on overflow.
///
/// Invariant (mod 2^32):
/// `bytes_in == frame_bytes + control_bytes + dropped_bytes + buffered()`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct DecoderStats {
    /// Verified frames handed out.
    pub frames: u32,
    /// Bytes taken from the input.
    pub bytes_in: u32,
    /// Bytes of the frames handed out.
    pub frame_bytes: u32,
    /// Bytes dropped: garbage between frames and the start bytes of rejected
    /// candidates.
    pub dropped_bytes: u32,
    /// Candidates rejected for a bad checksum.
    pub checksum_errors: u32,
    /// Candidates rejected for an impossible length field, or too short for the
    /// message header.
    pub length_errors: u32,
    /// Candidates longer than the decoder's buffer (overruns).
    pub too_long: u32,
    /// XBee: well-formed API frames of a type the transport does not carry.
    pub unknown_api: u32,
    /// Incomplete candidates abandoned by [`Decoder::flush`].
    pub truncated: u32,
    /// Verified control frames (XBee transmit statuses) consumed; they are not in
    /// `frames`.
    pub control_frames: u32,
    /// Bytes of the control frames.
    pub control_bytes: u32,
    /// Transmit statuses dropped, oldest first, because the ring of
    /// [`TX_STATUS_CAPACITY`] entries was full (not counted in
    /// [`errors`](DecoderStats::errors): nothing was rejected).
    pub tx_status_overflows: u32,
}

impl DecoderStats {
    /// Rejected candidates of every kind (control frames included: an invalid transmit
    /// status is a checksum or length error).
    pub const fn errors(&self) -> u32 {
        self.checksum_errors
            .wrapping_add(self.length_errors)
            .wrapping_add(self.too_long)
            .wrapping_add(self.unknown_api)
            .wrapping_add(self.truncated)
    }
}

/// What [`Decoder::in_place`] found whole at the front of the input.
enum InPlace<'i> {
    /// A message frame, to hand out.
    Frame(Frame<'i>),
    /// A control frame, to consume.
    Control(Control),
}

/// Incremental decoder for the transport `F`, with an `N`-byte buffer.
///
/// `N` should be at least `framing.max_rx_frame_len()` ([`crate::MAX_FRAME_LEN`],
/// the default, fits every transport); a smaller buffer rejects longer frames as
/// [`DecoderStats::too_long`], which is fine on a link that only carries short
/// messages. `N` below [`MIN_BUFFER_LEN`] does not compile:
///
/// ```compile_fail
/// let d: pprz_transports::Decoder<pprz_transports::PprzV2, 4> =
///     pprz_transports::Decoder::new(pprz_transports::PprzV2::new());
/// ```
///
/// `new` is `const`, so a decoder can live in a `static` (behind a mutex).
///
/// # Time complexity
///
/// Each input byte is copied once into the buffer. A rejected candidate costs a
/// rescan of the buffered bytes after its start byte, so the worst case (noise full
/// of start bytes announcing long frames) is O(`N`) per input byte; normal traffic
/// is O(1) per byte plus one checksum pass per frame.
#[derive(Clone, Debug)]
pub struct Decoder<F, const N: usize = { crate::MAX_FRAME_LEN }> {
    framing: F,
    /// Invariant: `start <= end <= N`; `buf[start..end]` are the buffered bytes.
    buf: [u8; N],
    start: usize,
    end: usize,
    stats: DecoderStats,
    /// Ring of transmit statuses: `statuses_len` entries from `statuses_head` (the
    /// oldest), wrapping at [`TX_STATUS_CAPACITY`]. Invariant: both below the capacity
    /// (`statuses_len` at most equal).
    statuses: [TxStatus; TX_STATUS_CAPACITY],
    statuses_head: usize,
    statuses_len: usize,
}

const NO_STATUS: TxStatus = TxStatus {
    frame_id: 0,
    delivered: false,
    status: 0,
    retries: 0,
};

impl<F, const N: usize> Decoder<F, N> {
    const VALID: () = assert!(N >= MIN_BUFFER_LEN, "decoder buffer too small");

    /// A decoder with an empty buffer and zero counters.
    pub const fn new(framing: F) -> Self {
        #[allow(clippy::let_unit_value)]
        let () = Self::VALID;
        Self {
            framing,
            buf: [0; N],
            start: 0,
            end: 0,
            stats: DecoderStats {
                frames: 0,
                bytes_in: 0,
                frame_bytes: 0,
                dropped_bytes: 0,
                checksum_errors: 0,
                length_errors: 0,
                too_long: 0,
                unknown_api: 0,
                truncated: 0,
                control_frames: 0,
                control_bytes: 0,
                tx_status_overflows: 0,
            },
            statuses: [NO_STATUS; TX_STATUS_CAPACITY],
            statuses_head: 0,
            statuses_len: 0,
        }
    }

    /// The transport.
    pub const fn framing(&self) -> &F {
        &self.framing
    }

    /// Buffer size `N`.
    pub const fn capacity(&self) -> usize {
        N
    }

    /// Bytes held in the buffer.
    pub const fn buffered(&self) -> usize {
        self.end.saturating_sub(self.start)
    }

    /// The counters.
    pub const fn stats(&self) -> &DecoderStats {
        &self.stats
    }

    /// Transmit statuses waiting for [`take_tx_status`](Decoder::take_tx_status).
    pub const fn tx_statuses_pending(&self) -> usize {
        self.statuses_len
    }

    /// Keeps a transmit status, dropping the oldest one if the ring is full.
    fn push_tx_status(&mut self, status: TxStatus) {
        if self.statuses_len >= TX_STATUS_CAPACITY {
            self.statuses_head = (self.statuses_head + 1) % TX_STATUS_CAPACITY;
            self.statuses_len = TX_STATUS_CAPACITY - 1;
            self.stats.tx_status_overflows = self.stats.tx_status_overflows.wrapping_add(1);
        }
        let at = (self.statuses_head + self.statuses_len) % TX_STATUS_CAPACITY;
        if let Some(slot) = self.statuses.get_mut(at) {
            *slot = status;
            self.statuses_len += 1;
        }
    }

    /// Counts a verified control frame of `len` bytes (already consumed) and keeps what
    /// it carries.
    fn accept_control(&mut self, control: Control, len: usize) {
        self.stats.control_frames = self.stats.control_frames.wrapping_add(1);
        self.stats.control_bytes = self.stats.control_bytes.wrapping_add(len as u32);
        match control {
            Control::TxStatus(status) => self.push_tx_status(status),
        }
    }

    /// Drops the buffered bytes (counted as dropped), e.g. after a link reset. The
    /// transmit statuses not taken yet stay.
    pub fn clear(&mut self) {
        let n = self.buffered();
        self.drop_bytes(n);
        self.start = 0;
        self.end = 0;
    }

    fn drop_bytes(&mut self, n: usize) {
        let n = n.min(self.buffered());
        self.start += n;
        self.stats.dropped_bytes = self.stats.dropped_bytes.wrapping_add(n as u32);
    }

    fn reject(&mut self, error: RxError) {
        let counter = match error {
            RxError::Checksum => &mut self.stats.checksum_errors,
            RxError::TooLong => &mut self.stats.too_long,
            RxError::UnknownApiId(_) => &mut self.stats.unknown_api,
            RxError::BadLength | RxError::BadStart | RxError::Truncated => {
                &mut self.stats.length_errors
            }
        };
        *counter = counter.wrapping_add(1);
        self.drop_bytes(1);
    }
}

impl<F: Framing, const N: usize> Decoder<F, N> {
    /// The oldest transmit status not taken yet (statuses come out in the order they
    /// were received), or `None`.
    ///
    /// Statuses are decoded by [`feed`](Decoder::feed),
    /// [`feed_borrowed`](Decoder::feed_borrowed) and [`flush`](Decoder::flush), which
    /// never hand them out as frames; take them after each call (see
    /// [`TX_STATUS_CAPACITY`]).
    pub fn take_tx_status(&mut self) -> Option<TxStatus> {
        if !self.framing.has_control() || self.statuses_len == 0 {
            return None;
        }
        let status = self.statuses.get(self.statuses_head).copied();
        self.statuses_head = (self.statuses_head + 1) % TX_STATUS_CAPACITY;
        self.statuses_len -= 1;
        status
    }

    /// Takes bytes from the front of `input` and returns the next verified frame,
    /// or `None` once `input` is empty and no complete frame is buffered. Control
    /// frames met on the way are consumed, not returned (their statuses wait for
    /// [`take_tx_status`](Decoder::take_tx_status)).
    ///
    /// `feed` returns `None` only with `input` empty, so
    /// `while let Some(f) = d.feed(&mut input) { .. }` uses up a whole chunk. The
    /// frame borrows the decoder until the next call.
    pub fn feed<'d>(&'d mut self, input: &mut &[u8]) -> Option<Frame<'d>> {
        loop {
            if let Some((start, len)) = self.scan() {
                return self.view(start, len);
            }
            if input.is_empty() {
                return None;
            }
            self.refill(input, N);
        }
    }

    /// [`feed`](Decoder::feed) without a copy when it can: while nothing is buffered, a
    /// frame that lies whole at the front of `input` is verified where it is and handed
    /// out as a view of `input`. Everything else (garbage, a frame split across reads, a
    /// rejected candidate, a frame longer than `N`) goes through the buffer as with
    /// `feed`, except that the buffer takes only the bytes its candidate still needs, so
    /// that the frames after a split one are again read in place.
    ///
    /// The frames found, their order and the counters are exactly those of `feed` on the
    /// same bytes (the resynchronisation rules of the [module documentation](self)
    /// hold unchanged); only the input is consumed in other steps, so
    /// [`buffered`](Decoder::buffered) can differ between two calls. Like `feed`, it
    /// returns `None` only once `input` is empty.
    ///
    /// The price is the lifetime: the frame may borrow `input`'s bytes, so they must
    /// outlive it (`'i: 'd`), whereas `feed`'s frame borrows only the decoder. Reading
    /// into a local buffer and feeding it, the usual loop, satisfies this:
    ///
    /// ```
    /// use pprz_transports::{PprzV2, PprzV2Decoder};
    /// let mut decoder = PprzV2Decoder::new(PprzV2::new());
    /// let received = [0x99, 0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x1C, 0xC4];
    /// let mut input = &received[..];
    /// while let Some(frame) = decoder.feed_borrowed(&mut input) {
    ///     assert_eq!(frame.raw().as_ptr(), received.as_ptr()); // not copied
    ///     assert_eq!((frame.source(), frame.msg_id()), (7, 2));
    /// }
    /// assert_eq!(decoder.stats().frames, 1);
    /// ```
    pub fn feed_borrowed<'d, 'i: 'd>(&'d mut self, input: &mut &'i [u8]) -> Option<Frame<'d>> {
        loop {
            if self.buffered() == 0 {
                let mut bytes: &'i [u8] = input;
                let start_byte = self.framing.start_byte();
                if bytes.first() != Some(&start_byte) {
                    // Garbage before a start byte: dropped without copying, as `feed` does.
                    let skip = bytes
                        .iter()
                        .position(|&b| b == start_byte)
                        .unwrap_or(bytes.len());
                    self.stats.bytes_in = self.stats.bytes_in.wrapping_add(skip as u32);
                    self.stats.dropped_bytes = self.stats.dropped_bytes.wrapping_add(skip as u32);
                    bytes = bytes.get(skip..).unwrap_or_default();
                    *input = bytes;
                }
                match self.in_place(bytes) {
                    Some((InPlace::Frame(frame), len, rest)) => {
                        *input = rest;
                        self.stats.bytes_in = self.stats.bytes_in.wrapping_add(len as u32);
                        self.count_frame(len);
                        return Some(frame);
                    }
                    Some((InPlace::Control(control), len, rest)) => {
                        *input = rest;
                        self.stats.bytes_in = self.stats.bytes_in.wrapping_add(len as u32);
                        self.accept_control(control, len);
                        continue;
                    }
                    None => {}
                }
            }
            if let Some((start, len)) = self.scan() {
                return self.view(start, len);
            }
            if input.is_empty() {
                return None;
            }
            let needed = self.needed();
            self.refill(input, needed);
        }
    }

    /// Bytes the buffered candidate still needs to be complete (one at a time while its
    /// length is not known yet); `N`, as many as fit, when nothing is buffered.
    fn needed(&self) -> usize {
        let avail = self.buf.get(self.start..self.end).unwrap_or_default();
        if avail.is_empty() {
            return N;
        }
        match self.framing.rx_frame_len(avail) {
            Ok(Some(total)) => total.saturating_sub(avail.len()).max(1),
            _ => 1,
        }
    }

    /// The frame or control frame at the front of `bytes` (which is empty or starts with
    /// the start byte), if it is there whole and `feed` would accept it from the buffer;
    /// with its length and the bytes after it.
    #[inline]
    fn in_place<'i>(&self, bytes: &'i [u8]) -> Option<(InPlace<'i>, usize, &'i [u8])> {
        let len = match self.framing.rx_frame_len(bytes) {
            Ok(Some(len)) if len > 0 && len <= N => len,
            _ => return None,
        };
        let (frame, rest) = bytes.split_at_checked(len)?;
        match self.framing.control(frame) {
            Some(Ok(control)) => return Some((InPlace::Control(control), len, rest)),
            Some(Err(_)) => return None,
            None => {}
        }
        self.framing.check(frame).ok()?;
        let frame = self.framing.view(frame).ok()?;
        Some((InPlace::Frame(frame), len, rest))
    }

    fn count_frame(&mut self, len: usize) {
        self.stats.frames = self.stats.frames.wrapping_add(1);
        self.stats.frame_bytes = self.stats.frame_bytes.wrapping_add(len as u32);
    }

    /// End of stream: abandons an incomplete candidate (counted in
    /// [`DecoderStats::truncated`]) and rescans the buffered bytes after its start
    /// byte. Call until it returns `None`; the buffer is then empty.
    pub fn flush(&mut self) -> Option<Frame<'_>> {
        loop {
            if let Some((start, len)) = self.scan() {
                return self.view(start, len);
            }
            if self.buffered() == 0 {
                return None;
            }
            self.stats.truncated = self.stats.truncated.wrapping_add(1);
            self.drop_bytes(1);
        }
    }

    #[inline]
    fn view(&self, start: usize, len: usize) -> Option<Frame<'_>> {
        let frame = self.buf.get(start..start.checked_add(len)?)?;
        self.framing.view(frame).ok()
    }

    /// Copies bytes from `input` into the buffer, at most `max` (at least 1).
    fn refill(&mut self, input: &mut &[u8], max: usize) {
        let taken = if self.buffered() == 0 {
            // Nothing buffered: skip garbage without copying it.
            self.start = 0;
            self.end = 0;
            let start_byte = self.framing.start_byte();
            let skip = input
                .iter()
                .position(|&b| b == start_byte)
                .unwrap_or(input.len());
            self.stats.dropped_bytes = self.stats.dropped_bytes.wrapping_add(skip as u32);
            skip
        } else {
            if self.end >= N {
                self.buf.copy_within(self.start..self.end, 0);
                self.end -= self.start;
                self.start = 0;
            }
            0
        };
        let rest = input.get(taken..).unwrap_or_default();
        let n = N.saturating_sub(self.end).min(rest.len()).min(max);
        if let (Some(dst), Some(src)) = (self.buf.get_mut(self.end..self.end + n), rest.get(..n)) {
            dst.copy_from_slice(src);
            self.end += n;
        }
        let consumed = taken + n;
        self.stats.bytes_in = self.stats.bytes_in.wrapping_add(consumed as u32);
        *input = input.get(consumed..).unwrap_or_default();
        if consumed == 0 && !input.is_empty() {
            // Unreachable by construction (scan never waits on a full buffer);
            // guarantees progress anyway.
            self.reject(RxError::TooLong);
        }
    }

    /// Finds the next frame in the buffer: `Some((start, len))` (consumed already),
    /// or `None` if more bytes are needed.
    fn scan(&mut self) -> Option<(usize, usize)> {
        let start_byte = self.framing.start_byte();
        loop {
            let avail = self.buf.get(self.start..self.end).unwrap_or_default();
            let Some(&first) = avail.first() else {
                self.start = 0;
                self.end = 0;
                return None;
            };
            if first != start_byte {
                let skip = avail
                    .iter()
                    .position(|&b| b == start_byte)
                    .unwrap_or(avail.len());
                self.drop_bytes(skip);
                continue;
            }
            let total = match self.framing.rx_frame_len(avail) {
                Err(e) => {
                    self.reject(e);
                    continue;
                }
                Ok(None) if avail.len() >= N => {
                    self.reject(RxError::TooLong);
                    continue;
                }
                Ok(None) => return None,
                Ok(Some(0)) => {
                    self.reject(RxError::BadLength);
                    continue;
                }
                Ok(Some(total)) if total > N => {
                    self.reject(RxError::TooLong);
                    continue;
                }
                Ok(Some(total)) => total,
            };
            // Not all of the candidate is here yet.
            let frame = avail.get(..total)?;
            match self.framing.control(frame) {
                Some(Ok(control)) => {
                    self.start += total;
                    self.accept_control(control, total);
                    continue;
                }
                Some(Err(e)) => {
                    self.reject(e);
                    continue;
                }
                None => {}
            }
            // Verified without building the view: `view` builds it once, for the caller.
            match self.framing.check(frame) {
                Ok(()) => {
                    let start = self.start;
                    self.start += total;
                    self.count_frame(total);
                    return Some((start, total));
                }
                Err(e) => self.reject(e),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Encoder, MsgHeader, PprzV2, TxMeta};

    fn frame(src: u8, fields: &[u8]) -> ([u8; 255], usize) {
        let mut out = [0u8; 255];
        let n = PprzV2
            .encode(&TxMeta::new(MsgHeader::new(src, 0, 1, 9)), fields, &mut out)
            .unwrap();
        (out, n)
    }

    /// The next frame through `feed`, or through `feed_borrowed` when `borrowed`.
    fn next<'d, 'i: 'd, F: Framing, const N: usize>(
        d: &'d mut Decoder<F, N>,
        input: &mut &'i [u8],
        borrowed: bool,
    ) -> Option<Frame<'d>> {
        if borrowed {
            d.feed_borrowed(input)
        } else {
            d.feed(input)
        }
    }

    #[test]
    fn frame_inside_false_start_is_found() {
        // A false start announcing 200 bytes, then a good frame, then enough filler
        // for the false candidate to fail its checksum; through both entry points.
        let (good, n) = frame(3, &[1, 2, 3]);
        let mut stream = [0u8; 260];
        stream[0] = 0x99;
        stream[1] = 200;
        stream[2..2 + n].copy_from_slice(&good[..n]);
        for borrowed in [false, true] {
            let mut d: Decoder<PprzV2, 255> = Decoder::new(PprzV2);
            let mut input = &stream[..];
            let f = next(&mut d, &mut input, borrowed).expect("frame");
            assert_eq!(f.source(), 3);
            assert_eq!(d.stats().checksum_errors, 1);
            while next(&mut d, &mut input, borrowed).is_some() {}
            assert!(d.flush().is_none());
            let s = *d.stats();
            assert_eq!(s.bytes_in, s.frame_bytes + s.dropped_bytes);
        }
    }

    #[test]
    fn flush_recovers_frame_behind_truncated_candidate() {
        let (good, n) = frame(4, &[]);
        let mut stream = [0u8; 64];
        stream[0] = 0x99;
        stream[1] = 250; // never completes
        stream[2..2 + n].copy_from_slice(&good[..n]);
        let mut d: Decoder<PprzV2> = Decoder::new(PprzV2);
        let mut input = &stream[..2 + n];
        assert!(d.feed(&mut input).is_none());
        assert_eq!(d.flush().map(|f| f.source()), Some(4));
        assert!(d.flush().is_none());
        assert_eq!(d.stats().truncated, 1);
        assert_eq!(d.buffered(), 0);
    }

    extern crate std;
    use crate::{AnyTransport, Frame, PprzLog, PprzV1, TxStatus, XBee24, XBee868};
    use pprz_test_support::chunked::{ChunkFeed, cycled, feed_in_chunks};
    use proptest::prelude::*;
    use std::vec::Vec;

    /// A frame, owned, for comparisons.
    type Owned = (Vec<u8>, crate::MsgHeader, Vec<u8>, crate::Extra);

    fn owned(f: &Frame<'_>) -> Owned {
        (
            f.raw().to_vec(),
            f.header(),
            f.payload().to_vec(),
            f.extra(),
        )
    }

    fn invariant<F, const N: usize>(d: &Decoder<F, N>) {
        let s = d.stats();
        assert_eq!(
            s.bytes_in,
            s.frame_bytes
                .wrapping_add(s.control_bytes)
                .wrapping_add(s.dropped_bytes)
                .wrapping_add(d.buffered() as u32)
        );
        assert!(d.tx_statuses_pending() <= TX_STATUS_CAPACITY);
    }

    /// Decodes `stream` in chunks of `sizes` (cycled) with `feed` or `feed_borrowed`,
    /// then flushes; checks the stats invariant after every call, and that the frames
    /// `feed_borrowed` hands out from the input are views of the input. The transmit
    /// statuses left in the decoder are taken at the end.
    fn decode<const N: usize>(
        t: AnyTransport,
        stream: &[u8],
        sizes: &[usize],
        borrowed: bool,
    ) -> (Vec<Owned>, DecoderStats, usize) {
        let (frames, stats, in_place, _) = decode_statuses::<N>(t, stream, sizes, borrowed);
        (frames, stats, in_place)
    }

    /// A decoding run of [`decode_statuses`] for the chunked-feed harness.
    struct Run<const N: usize> {
        d: Decoder<AnyTransport, N>,
        borrowed: bool,
        out: Vec<Owned>,
        /// Frames `feed_borrowed` handed out as views of the input.
        in_place: usize,
        statuses: Vec<TxStatus>,
    }

    impl<const N: usize> ChunkFeed for Run<N> {
        fn feed(&mut self, input: &mut &[u8]) -> bool {
            let chunk = *input;
            let Some(f) = next(&mut self.d, input, self.borrowed) else {
                return false;
            };
            if chunk.as_ptr_range().contains(&f.raw().as_ptr()) {
                assert!(self.borrowed, "feed hands out views of its buffer only");
                self.in_place += 1;
            }
            self.out.push(owned(&f));
            invariant(&self.d);
            true
        }

        fn chunk_done(&mut self) {
            invariant(&self.d);
            self.statuses
                .extend(core::iter::from_fn(|| self.d.take_tx_status()));
        }

        fn flush(&mut self) -> bool {
            let Some(f) = self.d.flush() else {
                return false;
            };
            self.out.push(owned(&f));
            true
        }
    }

    /// [`decode`], also returning the transmit statuses, taken at the end of every chunk
    /// (so that a chunk full of statuses overflows the ring).
    fn decode_statuses<const N: usize>(
        t: AnyTransport,
        stream: &[u8],
        sizes: &[usize],
        borrowed: bool,
    ) -> (Vec<Owned>, DecoderStats, usize, Vec<TxStatus>) {
        let mut run = Run::<N> {
            d: Decoder::new(t),
            borrowed,
            out: Vec::new(),
            in_place: 0,
            statuses: Vec::new(),
        };
        feed_in_chunks(&mut run, stream, cycled(sizes));
        let Run {
            mut d,
            out,
            in_place,
            mut statuses,
            ..
        } = run;
        statuses.extend(core::iter::from_fn(|| d.take_tx_status()));
        assert_eq!(d.buffered(), 0);
        assert_eq!(d.tx_statuses_pending(), 0);
        invariant(&d);
        let s = *d.stats();
        assert_eq!(
            s.control_frames as usize,
            statuses.len() + s.tx_status_overflows as usize
        );
        (out, s, in_place, statuses)
    }

    fn transports() -> [AnyTransport; 5] {
        [
            PprzV2.into(),
            PprzV1::new(2).into(),
            PprzLog::TELEMETRY.into(),
            XBee24::new().into(),
            XBee868::new().into(),
        ]
    }

    /// A stream of `parts`: `(kind, payload length, seed)` with kind 0..=3 a valid frame,
    /// 4 noise, 5 a false start announcing a long frame, 6 a frame with a flipped bit,
    /// 7 a frame cut short, 8 an XBee 802.15.4 transmit status, 9 an 868 one, 10 one of
    /// them with a flipped bit (the status frames are noise to the PPRZ transports).
    fn stream_of(t: &AnyTransport, parts: &[(u8, u8, u8)]) -> Vec<u8> {
        let mut stream = Vec::new();
        for &(kind, len, seed) in parts {
            let payload: Vec<u8> = (0..len).map(|i| i.wrapping_mul(seed) ^ seed).collect();
            let mut buf = [0u8; crate::MAX_FRAME_LEN];
            let meta = TxMeta::new(MsgHeader::new(seed, 0, seed & 0x0F, len)).at(1234);
            let Ok(n) = t.encode(
                &meta,
                &payload[..usize::from(len).min(t.max_payload_len())],
                &mut buf,
            ) else {
                continue;
            };
            match kind {
                0..=3 => stream.extend_from_slice(&buf[..n]),
                4 => stream.extend(payload.iter().take(usize::from(seed % 9))),
                5 => stream.extend_from_slice(&[t.start_byte(), seed | 0x80, 0x00, 0x10]),
                6 => {
                    buf[usize::from(seed) % n] ^= 1 << (len % 8);
                    stream.extend_from_slice(&buf[..n]);
                }
                7 => stream.extend_from_slice(&buf[..n / 2]),
                8..=10 => {
                    let n = if seed % 2 == 0 {
                        crate::xbee::encode_tx_status_24(len, seed, &mut buf)
                    } else {
                        crate::xbee::encode_tx_status_868(len, seed, seed >> 4, seed & 3, &mut buf)
                    }
                    .unwrap();
                    if kind == 10 {
                        buf[usize::from(seed) % n] ^= 1 << (len % 8);
                    }
                    stream.extend_from_slice(&buf[..n]);
                }
                _ => {}
            }
        }
        stream
    }

    proptest! {
        /// `feed_borrowed` finds exactly the frames of `feed`, in the same order, with the
        /// same counters, for any chunking and any decoder size; the stats invariant
        /// holds after every call.
        #[test]
        fn feed_borrowed_finds_what_feed_finds(
            parts in proptest::collection::vec((0u8..11, 0u8..80, any::<u8>()), 0..40),
            sizes in proptest::collection::vec(1usize..300, 1..8),
        ) {
            for t in transports() {
                let stream = stream_of(&t, &parts);
                let fed = decode_statuses::<{ crate::MAX_FRAME_LEN }>(t, &stream, &sizes, false);
                let borrowed =
                    decode_statuses::<{ crate::MAX_FRAME_LEN }>(t, &stream, &sizes, true);
                prop_assert_eq!(&fed.0, &borrowed.0);
                prop_assert_eq!(fed.1, borrowed.1);
                prop_assert_eq!(&fed.3, &borrowed.3);
                prop_assert_eq!(fed.1.bytes_in as usize, stream.len());
                if !matches!(t, AnyTransport::XBee24(_) | AnyTransport::XBee868(_)) {
                    prop_assert_eq!(fed.1.control_frames, 0);
                }
                let fed = decode_statuses::<32>(t, &stream, &sizes, false);
                let borrowed = decode_statuses::<32>(t, &stream, &sizes, true);
                prop_assert_eq!(&fed.0, &borrowed.0);
                prop_assert_eq!(fed.1, borrowed.1);
                prop_assert_eq!(&fed.3, &borrowed.3);
            }
        }
    }

    #[test]
    fn feed_borrowed_copies_nothing_on_a_clean_stream() {
        let t: AnyTransport = PprzV2.into();
        let parts: Vec<(u8, u8, u8)> = (0..50u8).map(|i| (0, i % 30, i)).collect();
        let stream = stream_of(&t, &parts);
        let (frames, stats, in_place) = decode::<255>(t, &stream, &[stream.len()], true);
        assert_eq!((frames.len(), in_place), (50, 50));
        assert_eq!(
            (stats.frames, stats.errors(), stats.dropped_bytes),
            (50, 0, 0)
        );
        // Noise first, then the same frames: still in place after the noise.
        let mut noisy = std::vec![0x12, 0x34];
        noisy.extend_from_slice(&stream);
        let (_, stats, in_place) = decode::<255>(t, &noisy, &[noisy.len()], true);
        assert_eq!((stats.frames, stats.dropped_bytes, in_place), (50, 2, 50));
    }

    #[test]
    fn feed_borrowed_copies_only_split_frames() {
        // A continuous stream read in 64-byte chunks: the buffer takes only the rest of a
        // frame split across two reads, so every frame that lies inside one read is read
        // in place.
        for t in transports() {
            let parts: Vec<(u8, u8, u8)> =
                (0..60u8).map(|i| (0, i.wrapping_mul(7) % 40, i)).collect();
            let stream = stream_of(&t, &parts);
            let mut whole = 0;
            let mut pos = 0;
            let mut d: Decoder<AnyTransport> = Decoder::new(t);
            let mut offsets = Vec::new();
            let mut rest = &stream[..];
            while let Some(f) = d.feed(&mut rest) {
                offsets.push((pos, f.raw().len()));
                pos += f.raw().len();
            }
            for &(at, len) in &offsets {
                if at / 64 == (at + len - 1) / 64 {
                    whole += 1;
                }
            }
            let (frames, stats, in_place) = decode::<255>(t, &stream, &[64], true);
            assert_eq!((frames.len(), stats.errors()), (60, 0), "{t:?}");
            assert_eq!(in_place, whole, "{t:?}");
        }
    }

    #[test]
    fn feed_borrowed_counts_too_long_like_feed() {
        let (big, n) = frame(5, &[0xAA; 100]);
        let (small, m) = frame(6, &[1]);
        let mut d: Decoder<PprzV2, 32> = Decoder::new(PprzV2);
        let mut input = &big[..n];
        assert!(d.feed_borrowed(&mut input).is_none());
        let mut input = &small[..m];
        assert_eq!(d.feed_borrowed(&mut input).map(|f| f.source()), Some(6));
        assert_eq!(d.stats().too_long, 1);
    }

    #[test]
    fn check_is_verify_and_view() {
        for t in transports() {
            let mut buf = [0u8; crate::MAX_FRAME_LEN];
            let meta = TxMeta::new(MsgHeader::new(1, 2, 3, 4));
            let n = t.encode(&meta, &[9, 8, 7], &mut buf).unwrap();
            // Every prefix, every single-bit corruption, and LEN values too small for
            // the headers (with the checksum fixed up by the encoder where possible).
            let mut cases: Vec<Vec<u8>> = (0..=n).map(|k| buf[..k].to_vec()).collect();
            for i in 0..n {
                let mut c = buf[..n].to_vec();
                c[i] ^= 0x04;
                cases.push(c);
            }
            for short in 0..12u8 {
                let mut c = buf[..n].to_vec();
                c[1] = short;
                cases.push(c);
            }
            for c in &cases {
                let both = t.verify(c).and_then(|()| t.view(c).map(|_| ()));
                assert_eq!(t.check(c), both, "{t:?} {c:02x?}");
            }
        }
        // A PPRZ v2 frame too short for the message header, with a good checksum.
        let (a, b) = crate::checksum::pprz(&[0x06, 0x07, 0x00]);
        let short = [0x99, 0x06, 0x07, 0x00, a, b];
        assert_eq!(PprzV2.verify(&short), Ok(()));
        assert!(PprzV2.view(&short).is_err());
        assert_eq!(PprzV2.check(&short), Err(RxError::BadLength));
        assert_eq!(PprzV1::new(1).check(&short), Ok(()));
    }

    #[test]
    fn tx_status_ring_keeps_the_newest() {
        // Ten statuses in one chunk, no frame: `feed` does not return in between, so the
        // ring of 8 drops the two oldest.
        let mut stream = Vec::new();
        let mut buf = [0u8; 16];
        for id in 1..=10u8 {
            let n = if id % 2 == 0 {
                crate::xbee::encode_tx_status_24(id, id % 3, &mut buf)
            } else {
                crate::xbee::encode_tx_status_868(id, id, 0, 0, &mut buf)
            }
            .unwrap();
            stream.extend_from_slice(&buf[..n]);
        }
        for borrowed in [false, true] {
            let mut d: Decoder<XBee868> = Decoder::new(XBee868::new());
            let mut input = &stream[..];
            assert!(next(&mut d, &mut input, borrowed).is_none());
            assert_eq!(d.tx_statuses_pending(), TX_STATUS_CAPACITY);
            let s = *d.stats();
            assert_eq!((s.control_frames, s.tx_status_overflows), (10, 2));
            assert_eq!((s.frames, s.errors(), s.dropped_bytes), (0, 0, 0));
            assert_eq!(s.control_bytes as usize, stream.len());
            let ids: Vec<u8> = core::iter::from_fn(|| d.take_tx_status())
                .map(|s| s.frame_id)
                .collect();
            assert_eq!(ids, (3..=10).collect::<Vec<u8>>());
            assert_eq!(d.take_tx_status(), None);
            // Emptied, the ring takes new statuses again, without overflow.
            let mut input = &stream[..2 * 11 + 7];
            assert!(next(&mut d, &mut input, borrowed).is_none());
            let ids: Vec<u8> = core::iter::from_fn(|| d.take_tx_status())
                .map(|s| s.frame_id)
                .collect();
            assert_eq!(ids, [1, 2, 3]);
            assert_eq!(d.stats().tx_status_overflows, 2);
            // `clear` drops bytes, not statuses.
            let mut input = &stream[..11 + 3];
            assert!(next(&mut d, &mut input, borrowed).is_none());
            d.clear();
            assert_eq!(d.take_tx_status().map(|s| s.frame_id), Some(1));
        }
    }

    #[test]
    fn tx_status_between_frames_through_flush() {
        // A status behind a false start that announces a long frame: found by `flush`
        // (it is not handed out, but the frame after it is).
        let mut stream = std::vec![0x7E, 0x00, 0x60, 0x01];
        let mut buf = [0u8; crate::MAX_FRAME_LEN];
        let n = crate::xbee::encode_tx_status_24(0x33, 0, &mut buf).unwrap();
        stream.extend_from_slice(&buf[..n]);
        let m = XBee24::new()
            .encode(
                &TxMeta::new(MsgHeader::new(5, 0, 1, 2)),
                &[1, 2, 3],
                &mut buf,
            )
            .unwrap();
        stream.extend_from_slice(&buf[..m]);
        let mut d: Decoder<XBee24> = Decoder::new(XBee24::new());
        let mut input = &stream[..];
        assert!(d.feed(&mut input).is_none());
        assert_eq!(d.take_tx_status(), None);
        assert_eq!(d.flush().map(|f| f.source()), Some(5));
        let status = d.take_tx_status().unwrap();
        assert_eq!((status.frame_id, status.delivered), (0x33, true));
        assert!(d.flush().is_none());
        let s = *d.stats();
        assert_eq!((s.truncated, s.control_frames, s.frames), (1, 1, 1));
        invariant(&d);
    }

    #[test]
    fn small_buffer_counts_too_long() {
        let (big, n) = frame(5, &[0xAA; 100]);
        let (small, m) = frame(6, &[1]);
        let mut d: Decoder<PprzV2, 32> = Decoder::new(PprzV2);
        let mut input = &big[..n];
        assert!(d.feed(&mut input).is_none());
        let mut input = &small[..m];
        assert_eq!(d.feed(&mut input).map(|f| f.source()), Some(6));
        assert_eq!(d.stats().too_long, 1);
    }
}
