//! Workloads 1 and 2: encoding a fixed message sequence into a PPRZ v2 byte stream, and
//! parsing that stream back.
//!
//! The sequence alternates GPS (telemetry id 8, 27 field bytes, 35-byte frame) and
//! ATTITUDE (telemetry id 6, 12 field bytes, 20-byte frame); every field value is a
//! function of the message index, so the stream is fixed.
//!
//! * [`encode_stream`]: generated encoder straight into the frame's payload area, then
//!   the PPRZ v2 framing around it (`Encoder::payload_area` + `finish_frame`), frame
//!   after frame into one buffer. This is what the downlink does per message and
//!   transport, without the arena and queue.
//! * [`parse_stream`]: the whole stream through the incremental PPRZ v2 [`Decoder`](pprz_transports::Decoder)
//!   (`feed_borrowed`: frames verified in place, no copy), then the generated decoder of
//!   the message set (`AnyMessage::decode`, dispatching on class and id), reading two
//!   fields of every message into a digest. [`parse_stream_buffered`] does the same
//!   through `feed`, which copies every byte into the decoder's buffer.

use core::fmt;

use pprz_default::messages::AnyMessage;
use pprz_default::messages::telemetry::{self, Attitude, Gps};
use pprz_messages::Message;
use pprz_transports::{Encoder, Frame, GROUND_ID, MsgHeader, PprzV2, PprzV2Decoder, TxMeta};

/// Messages of the encode and parse workloads.
pub const MESSAGES: usize = 10_000;

/// Aircraft id of every frame (`source`).
pub const AC_ID: u8 = 7;

/// Frame length of a GPS message in PPRZ v2 (27 field bytes + 8 bytes of framing).
pub const GPS_FRAME_LEN: usize = 35;

/// Frame length of an ATTITUDE message in PPRZ v2 (12 field bytes + 8 bytes of framing).
pub const ATTITUDE_FRAME_LEN: usize = 20;

/// Length of the stream of `count` messages (GPS first, then alternating).
pub const fn stream_len(count: usize) -> usize {
    count.div_ceil(2) * GPS_FRAME_LEN + (count / 2) * ATTITUDE_FRAME_LEN
}

/// The GPS message of index `i` (every field varies with `i`).
pub fn gps(i: u32) -> Gps {
    Gps {
        mode: 3,
        utm_east: 36_000_000 + (i as i32).wrapping_mul(7),
        utm_north: 480_000_000 - (i as i32).wrapping_mul(3),
        course: (i % 3600) as i16,
        alt: 150_000 + i as i32,
        speed: (i % 2000) as u16,
        climb: (i % 200) as i16 - 100,
        week: 2300,
        itow: i.wrapping_mul(250),
        utm_zone: 31,
        gps_nb_err: (i % 7) as u8,
    }
}

/// The ATTITUDE message of index `i` (every field varies with `i`).
pub fn attitude(i: u32) -> Attitude {
    let x = i as f32;
    Attitude {
        phi: x * 1.0e-4,
        psi: 3.0 - x * 2.0e-4,
        theta: -x * 1.5e-4,
    }
}

/// Why a workload failed (the workloads check their own results).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum WorkloadError {
    /// A generated encoder failed (buffer too small).
    Encode(pprz_messages::EncodeError),
    /// The PPRZ v2 framing failed.
    Frame(pprz_transports::EncodeError),
    /// The output buffer is too small for the stream.
    BufferTooSmall,
}

impl fmt::Display for WorkloadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Encode(e) => write!(f, "message encoding failed: {e}"),
            Self::Frame(e) => write!(f, "PPRZ v2 framing failed: {e}"),
            Self::BufferTooSmall => f.write_str("output buffer too small for the stream"),
        }
    }
}

impl core::error::Error for WorkloadError {}

/// Encodes `msg` in place into a PPRZ v2 frame at the start of `frame`; returns the
/// frame length.
///
/// # Errors
/// The buffer is too small (see [`WorkloadError`]).
#[inline]
pub fn encode_frame<M: Message>(
    transport: &PprzV2,
    msg: &M,
    frame: &mut [u8],
) -> Result<usize, WorkloadError> {
    let n = msg
        .encode(transport.payload_area(frame))
        .map_err(WorkloadError::Encode)?;
    let meta = TxMeta::new(MsgHeader::new(AC_ID, GROUND_ID, M::CLASS_ID, M::ID));
    transport
        .finish_frame(&meta, frame, n)
        .map_err(WorkloadError::Frame)
}

/// Workload 1: encodes `count` messages (GPS and ATTITUDE alternating, GPS first) into
/// consecutive PPRZ v2 frames in `out`; returns the stream length.
///
/// # Errors
/// `out` is shorter than [`stream_len`]`(count)`.
pub fn encode_stream(count: usize, out: &mut [u8]) -> Result<usize, WorkloadError> {
    let transport = PprzV2::new();
    let mut pos = 0;
    for i in 0..count {
        let frame = out.get_mut(pos..).ok_or(WorkloadError::BufferTooSmall)?;
        let index = i as u32;
        pos += if i % 2 == 0 {
            encode_frame(&transport, &gps(index), frame)?
        } else {
            encode_frame(&transport, &attitude(index), frame)?
        };
    }
    Ok(pos)
}

/// What [`parse_stream`] found.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct ParseSummary {
    /// Verified frames out of the decoder.
    pub frames: u32,
    /// GPS messages decoded.
    pub gps: u32,
    /// ATTITUDE messages decoded.
    pub attitude: u32,
    /// Frames whose payload did not decode, or of another message.
    pub other: u32,
    /// A digest of two fields of every message (`utm_east` and `itow` of GPS, the bits of
    /// `phi` and `theta` of ATTITUDE), so the reads cannot be optimised away and the
    /// result can be checked against the encoded values.
    pub digest: u64,
}

fn mix(digest: u64, value: u32) -> u64 {
    digest.rotate_left(5) ^ u64::from(value)
}

fn digest_gps(digest: u64, g: &Gps) -> u64 {
    mix(mix(digest, g.utm_east as u32), g.itow)
}

fn digest_attitude(digest: u64, a: &Attitude) -> u64 {
    mix(mix(digest, a.phi.to_bits()), a.theta.to_bits())
}

/// Counts `frame` and folds two fields of its message into the digest.
#[inline]
fn account(summary: &mut ParseSummary, frame: &Frame<'_>) {
    summary.frames += 1;
    match AnyMessage::decode(frame.class(), frame.msg_id(), frame.payload()) {
        Ok(AnyMessage::Telemetry(telemetry::AnyMessage::Gps(g))) => {
            summary.gps += 1;
            summary.digest = digest_gps(summary.digest, &g);
        }
        Ok(AnyMessage::Telemetry(telemetry::AnyMessage::Attitude(a))) => {
            summary.attitude += 1;
            summary.digest = digest_attitude(summary.digest, &a);
        }
        _ => summary.other += 1,
    }
}

/// Workload 2: feeds `stream` to a PPRZ v2 decoder with `Decoder::feed_borrowed` (whole
/// frames are verified in the input and not copied) and decodes every frame with the
/// generated decoder of the default message set, reading two fields of each message.
pub fn parse_stream(stream: &[u8]) -> ParseSummary {
    let mut decoder = PprzV2Decoder::new(PprzV2::new());
    let mut summary = ParseSummary::default();
    let mut input = stream;
    while let Some(frame) = decoder.feed_borrowed(&mut input) {
        account(&mut summary, &frame);
    }
    summary
}

/// Workload 2 through `Decoder::feed` (every byte copied into the decoder's buffer, as
/// the ground tools do); the same summary as [`parse_stream`].
pub fn parse_stream_buffered(stream: &[u8]) -> ParseSummary {
    let mut decoder = PprzV2Decoder::new(PprzV2::new());
    let mut summary = ParseSummary::default();
    let mut input = stream;
    while let Some(frame) = decoder.feed(&mut input) {
        account(&mut summary, &frame);
    }
    summary
}

/// The [`ParseSummary`] that parsing the stream of `count` messages must give, computed
/// from the messages themselves (no encoding or decoding involved).
pub fn expected_summary(count: usize) -> ParseSummary {
    let mut s = ParseSummary::default();
    for i in 0..count {
        s.frames += 1;
        if i % 2 == 0 {
            s.gps += 1;
            s.digest = digest_gps(s.digest, &gps(i as u32));
        } else {
            s.attitude += 1;
            s.digest = digest_attitude(s.digest, &attitude(i as u32));
        }
    }
    s
}
