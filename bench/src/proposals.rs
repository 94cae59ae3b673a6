//! Prototypes of the changes `BENCHMARKS.md` proposes to other crates, measured with the
//! same workloads so the proposals come with figures. Nothing here is used by the stack;
//! the tests check that every prototype produces exactly the bytes and values of the
//! code it would replace.
//!
//! * [`checksum`]: the PPRZ checksum unrolled by 8 (for `transports/src/checksum.rs`,
//!   `PprzChecksum::update`). The current byte loop costs 5 instructions per byte on
//!   x86_64 (load-add, add, increment, compare, branch); unrolled it is about 2.4.
//! * [`finish_v2`]: PPRZ v2 framing with one length check, the 6 header bytes stored as
//!   one array and the unrolled checksum (for `transports/src/pprz.rs`,
//!   `PprzV2::finish_frame`, which today checks the length four times and re-reads `LEN`
//!   from the buffer to find the checksum range).
//! * [`encode_gps`], [`encode_attitude`]: what `pprz-codegen` could emit for messages
//!   without variable arrays: one `first_chunk_mut::<LEN>()` check, then stores at
//!   constant offsets, which the compiler turns into plain moves (today every field goes
//!   through `wire::Writer::scalar`, a bounds check and a position update per field).
//! * [`parse_stream`]: a zero-copy fast path for the decoder: while nothing is buffered
//!   and the input holds a whole frame, verify it in place (unrolled checksum) and build
//!   its view once, instead of copying it into the decoder's buffer and building the view
//!   twice (`Decoder::scan` calls `Framing::view` to check the frame and
//!   `Decoder::view` builds it again). Anything else (a partial frame, a bad checksum,
//!   noise) goes to the existing decoder. The messages are decoded by the generated
//!   `AnyMessage::decode`, as in [`crate::stream::parse_stream`].

use pprz_messages::{EncodeError, Message};
use pprz_telemetry::messages::AnyMessage;
use pprz_telemetry::messages::telemetry::{self, Attitude, Gps};
use pprz_transports::pprz::{STX, V2_MAX_PAYLOAD_LEN};
use pprz_transports::{GROUND_ID, MsgHeader, PprzV2, PprzV2Decoder, TxMeta};

use crate::stream::{AC_ID, ParseSummary, WorkloadError, attitude, gps};

/// PPRZ checksum `(ck_a, ck_b)` of `bytes`, unrolled by 8 bytes (by hand: with
/// `opt-level = "s"` the compiler does not unroll loops).
#[inline]
pub fn checksum(bytes: &[u8]) -> (u8, u8) {
    #[inline(always)]
    fn step(a: &mut u8, b: &mut u8, x: u8) {
        *a = a.wrapping_add(x);
        *b = b.wrapping_add(*a);
    }
    let (mut a, mut b) = (0u8, 0u8);
    let (chunks, rest) = bytes.as_chunks::<8>();
    for &[x0, x1, x2, x3, x4, x5, x6, x7] in chunks {
        step(&mut a, &mut b, x0);
        step(&mut a, &mut b, x1);
        step(&mut a, &mut b, x2);
        step(&mut a, &mut b, x3);
        step(&mut a, &mut b, x4);
        step(&mut a, &mut b, x5);
        step(&mut a, &mut b, x6);
        step(&mut a, &mut b, x7);
    }
    for &x in rest {
        step(&mut a, &mut b, x);
    }
    (a, b)
}

/// PPRZ v2 framing around `payload_len` field bytes already at `frame[6..]`; returns
/// the frame length. Same result as `PprzV2::finish_frame`.
///
/// # Errors
/// The fields are too long, the header's class or component does not fit 4 bits, or the
/// buffer is too short.
#[inline]
pub fn finish_v2(
    meta: &TxMeta,
    frame: &mut [u8],
    payload_len: usize,
) -> Result<usize, pprz_transports::EncodeError> {
    if payload_len > V2_MAX_PAYLOAD_LEN {
        return Err(pprz_transports::EncodeError::PayloadTooLong {
            len: payload_len,
            max: V2_MAX_PAYLOAD_LEN,
        });
    }
    let h = &meta.header;
    h.check()?;
    let len = payload_len + 8;
    let available = frame.len();
    let frame = frame
        .get_mut(..len)
        .ok_or(pprz_transports::EncodeError::BufferTooSmall {
            needed: len,
            available,
        })?;
    // `len >= 8`: the header and the checksum are inside the frame.
    let (body, ck) = frame.split_at_mut(len - 2);
    if let Some(head) = body.first_chunk_mut::<6>() {
        *head = [
            STX,
            len as u8,
            h.source,
            h.destination,
            (h.component << 4) | h.class,
            h.msg_id,
        ];
    }
    let (a, b) = checksum(body.get(1..).unwrap_or_default());
    if let Some(ck) = ck.first_chunk_mut::<2>() {
        *ck = [a, b];
    }
    Ok(len)
}

/// Stores `bytes` at `at` of a fixed-size block (the offsets are constants, so the
/// checks fold away).
#[inline(always)]
fn put<const L: usize, const K: usize>(out: &mut [u8; L], at: usize, bytes: [u8; K]) {
    if let Some(dst) = out.get_mut(at..at + K) {
        dst.copy_from_slice(&bytes);
    }
}

/// GPS encoded the way a fixed-size encoder could be generated; same bytes as
/// `Gps::encode`.
///
/// # Errors
/// `buf` is shorter than 27 bytes.
#[inline]
pub fn encode_gps(m: &Gps, buf: &mut [u8]) -> Result<usize, EncodeError> {
    const LEN: usize = 27;
    let available = buf.len();
    let out = buf
        .first_chunk_mut::<LEN>()
        .ok_or(EncodeError::BufferTooSmall {
            needed: LEN,
            available,
        })?;
    put(out, 0, m.mode.to_le_bytes());
    put(out, 1, m.utm_east.to_le_bytes());
    put(out, 5, m.utm_north.to_le_bytes());
    put(out, 9, m.course.to_le_bytes());
    put(out, 11, m.alt.to_le_bytes());
    put(out, 15, m.speed.to_le_bytes());
    put(out, 17, m.climb.to_le_bytes());
    put(out, 19, m.week.to_le_bytes());
    put(out, 21, m.itow.to_le_bytes());
    put(out, 25, m.utm_zone.to_le_bytes());
    put(out, 26, m.gps_nb_err.to_le_bytes());
    Ok(LEN)
}

/// ATTITUDE encoded the way a fixed-size encoder could be generated; same bytes as
/// `Attitude::encode`.
///
/// # Errors
/// `buf` is shorter than 12 bytes.
#[inline]
pub fn encode_attitude(m: &Attitude, buf: &mut [u8]) -> Result<usize, EncodeError> {
    const LEN: usize = 12;
    let available = buf.len();
    let out = buf
        .first_chunk_mut::<LEN>()
        .ok_or(EncodeError::BufferTooSmall {
            needed: LEN,
            available,
        })?;
    put(out, 0, m.phi.to_le_bytes());
    put(out, 4, m.psi.to_le_bytes());
    put(out, 8, m.theta.to_le_bytes());
    Ok(LEN)
}

#[inline]
fn frame_with<M: Message>(
    frame: &mut [u8],
    encode: impl FnOnce(&mut [u8]) -> Result<usize, EncodeError>,
) -> Result<usize, WorkloadError> {
    let n = encode(frame.get_mut(6..).unwrap_or_default()).map_err(WorkloadError::Encode)?;
    let meta = TxMeta::new(MsgHeader::new(AC_ID, GROUND_ID, M::CLASS_ID, M::ID));
    finish_v2(&meta, frame, n).map_err(WorkloadError::Frame)
}

/// Workload 1 with the proposed encoders and framing: the same stream as
/// [`crate::stream::encode_stream`].
///
/// # Errors
/// `out` is too short.
pub fn encode_stream(count: usize, out: &mut [u8]) -> Result<usize, WorkloadError> {
    let mut pos = 0;
    for i in 0..count {
        let frame = out.get_mut(pos..).ok_or(WorkloadError::BufferTooSmall)?;
        let index = i as u32;
        pos += if i % 2 == 0 {
            frame_with::<Gps>(frame, |b| encode_gps(&gps(index), b))?
        } else {
            frame_with::<Attitude>(frame, |b| encode_attitude(&attitude(index), b))?
        };
    }
    Ok(pos)
}

/// Workload 1 with the current generated encoders and only the proposed framing
/// ([`finish_v2`]), to tell the two proposals apart; the same stream again.
///
/// # Errors
/// `out` is too short.
pub fn encode_stream_framing_only(count: usize, out: &mut [u8]) -> Result<usize, WorkloadError> {
    let mut pos = 0;
    for i in 0..count {
        let frame = out.get_mut(pos..).ok_or(WorkloadError::BufferTooSmall)?;
        let index = i as u32;
        pos += if i % 2 == 0 {
            frame_with::<Gps>(frame, |b| gps(index).encode(b))?
        } else {
            frame_with::<Attitude>(frame, |b| attitude(index).encode(b))?
        };
    }
    Ok(pos)
}

fn account(summary: &mut ParseSummary, class: u8, id: u8, payload: &[u8]) {
    summary.frames += 1;
    match AnyMessage::decode(class, id, payload) {
        Ok(AnyMessage::Telemetry(telemetry::AnyMessage::Gps(g))) => {
            summary.gps += 1;
            summary.digest = summary.digest.rotate_left(5) ^ u64::from(g.utm_east as u32);
            summary.digest = summary.digest.rotate_left(5) ^ u64::from(g.itow);
        }
        Ok(AnyMessage::Telemetry(telemetry::AnyMessage::Attitude(a))) => {
            summary.attitude += 1;
            summary.digest = summary.digest.rotate_left(5) ^ u64::from(a.phi.to_bits());
            summary.digest = summary.digest.rotate_left(5) ^ u64::from(a.theta.to_bits());
        }
        _ => summary.other += 1,
    }
}

/// Workload 2 with the proposed zero-copy fast path (see the module documentation);
/// the same summary as [`crate::stream::parse_stream`].
pub fn parse_stream(stream: &[u8]) -> ParseSummary {
    let mut summary = ParseSummary::default();
    let mut input = stream;
    // Fast path: whole, valid frames at the front of the input.
    while let [STX, len, ..] = input {
        let len = usize::from(*len);
        let Some(frame) = input.get(..len).filter(|_| len >= 8) else {
            break;
        };
        let (body, ck) = frame.split_at(len - 2);
        if checksum(body.get(1..).unwrap_or_default()) != (ck[0], ck[1]) {
            break;
        }
        if let [_, _, _source, _destination, cc, id, payload @ ..] = body {
            account(&mut summary, cc & 0x0F, *id, payload);
        }
        input = input.get(len..).unwrap_or_default();
    }
    // Everything else: the existing decoder.
    if !input.is_empty() {
        let mut decoder = PprzV2Decoder::new(PprzV2::new());
        while let Some(frame) = decoder.feed(&mut input) {
            account(&mut summary, frame.class(), frame.msg_id(), frame.payload());
        }
    }
    summary
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream;
    use pprz_transports::Encoder;

    #[test]
    fn checksum_matches_the_transport() {
        let bytes: Vec<u8> = (0..300u32).map(|i| (i * 37 + 11) as u8).collect();
        for n in 0..bytes.len() {
            assert_eq!(
                checksum(&bytes[..n]),
                pprz_transports::checksum::pprz(&bytes[..n])
            );
        }
    }

    #[test]
    fn proposed_framing_and_encoders_give_the_same_bytes() {
        for i in 0..50u32 {
            let (mut a, mut b) = ([0u8; 64], [0u8; 64]);
            let n = encode_gps(&gps(i), &mut a).unwrap();
            let m = gps(i).encode(&mut b).unwrap();
            assert_eq!(a[..n], b[..m]);
            let n = encode_attitude(&attitude(i), &mut a).unwrap();
            let m = attitude(i).encode(&mut b).unwrap();
            assert_eq!(a[..n], b[..m]);
        }
        let meta = TxMeta::new(MsgHeader::new(7, 0, 1, 8).with_component(3));
        let (mut a, mut b) = ([9u8; 64], [9u8; 64]);
        let n = finish_v2(&meta, &mut a, 20).unwrap();
        let m = PprzV2::new().finish_frame(&meta, &mut b, 20).unwrap();
        assert_eq!(a[..n], b[..m]);
        assert!(finish_v2(&meta, &mut a, 60).is_err());
        assert!(finish_v2(&meta, &mut a, 248).is_err());
    }

    #[test]
    fn proposed_stream_is_identical_and_parses_the_same() {
        let count = 101;
        let current = stream::make_stream(count);
        let mut proposed = vec![0u8; stream::stream_len(count)];
        let len = encode_stream(count, &mut proposed).unwrap();
        assert_eq!(proposed[..len], current[..]);
        let len = encode_stream_framing_only(count, &mut proposed).unwrap();
        assert_eq!(proposed[..len], current[..]);
        assert_eq!(parse_stream(&current), stream::expected_summary(count));
        // Noise and a cut frame go through the existing decoder.
        let mut noisy = vec![0x99, 0x03, 0x42];
        noisy.extend_from_slice(&current);
        assert_eq!(parse_stream(&noisy), stream::expected_summary(count));
        let cut = &current[..current.len() - 1];
        assert_eq!(parse_stream(cut).frames as usize, count - 1);
    }
}
