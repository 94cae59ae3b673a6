//! The one prototype of `BENCHMARKS.md` that was not applied, measured with the same
//! workload so the decision comes with a figure; nothing here is used by the stack, and
//! the tests check that it produces exactly the bytes of the code it would replace.
//!
//! * [`encode_gps`], [`encode_attitude`]: what `pprz-codegen` could emit for messages
//!   without variable arrays: one `first_chunk_mut::<LEN>()` check, then stores at
//!   constant offsets (the generated encoders go through `wire::Writer::scalar`, a bounds
//!   check and a position update per field). [`encode_stream`] frames them with the real
//!   `PprzV2::finish_frame`, so mode `encode-proposed` differs from `encode` only by the
//!   encoders. It gives the same count as the generated encoders: after `Writer::new`'s
//!   up-front length check the compiler already removes every per-field check, so the
//!   generator is left as it is.
//!
//! The other prototypes (unrolled checksum, one-pass PPRZ v2 framing, zero-copy parsing)
//! became the real code (`PprzChecksum::update`, `PprzV2::finish_frame`,
//! `Decoder::feed_borrowed`) and were removed from here.

use pprz_messages::{EncodeError, Message};
use pprz_telemetry::messages::telemetry::{Attitude, Gps};
use pprz_transports::{Encoder, GROUND_ID, MsgHeader, PprzV2, TxMeta};

use crate::stream::{AC_ID, WorkloadError, attitude, gps};

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
    let transport = PprzV2::new();
    let n = encode(transport.payload_area(frame)).map_err(WorkloadError::Encode)?;
    let meta = TxMeta::new(MsgHeader::new(AC_ID, GROUND_ID, M::CLASS_ID, M::ID));
    transport
        .finish_frame(&meta, frame, n)
        .map_err(WorkloadError::Frame)
}

/// Workload 1 with the fixed-offset encoders (and the real framing): the same stream as
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::stream;

    #[test]
    fn fixed_offset_encoders_give_the_same_bytes() {
        for i in 0..50u32 {
            let (mut a, mut b) = ([0u8; 64], [0u8; 64]);
            let n = encode_gps(&gps(i), &mut a).unwrap();
            let m = gps(i).encode(&mut b).unwrap();
            assert_eq!(a[..n], b[..m]);
            let n = encode_attitude(&attitude(i), &mut a).unwrap();
            let m = attitude(i).encode(&mut b).unwrap();
            assert_eq!(a[..n], b[..m]);
        }
        assert!(encode_gps(&gps(0), &mut [0u8; 26]).is_err());
        assert!(encode_attitude(&attitude(0), &mut [0u8; 11]).is_err());
    }

    #[test]
    fn fixed_offset_stream_is_identical() {
        let count = 101;
        let current = stream::make_stream(count);
        let mut proposed = vec![0u8; stream::stream_len(count)];
        let len = encode_stream(count, &mut proposed).unwrap();
        assert_eq!(proposed[..len], current[..]);
    }
}
