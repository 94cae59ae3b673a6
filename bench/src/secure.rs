//! Workload 8: the per-frame cost of the secure link (issue 14), sealing and opening a
//! frame with an installed session.
//!
//! The frame is a PAYLOAD (telemetry id 114) of 39 values, 40 bytes of message fields: a
//! 48-byte plain PPRZ v2 frame, 69 bytes once sealed (ChaCha20-Poly1305, [`OVERHEAD`]
//! bytes more). Every value is a function of the frame's index, so the inputs are fixed.
//!
//! * [`seal_frames`]: the aircraft's writer. Each plain frame, already in a buffer with
//!   [`OVERHEAD`] spare bytes ([`frame_buffers`]), is sealed in place
//!   ([`SecureChannel::seal_in_place`]); the sealed frames are kept for the check.
//! * [`open_frames`]: the ground's reader. The `DATA` of each sealed frame (what the PPRZ
//!   v2 decoder hands out; the decoder's own cost is workload 2) is verified and decrypted
//!   into a plain frame ([`SecureChannel::open`]).
//!
//! The session is installed with fixed keys ([`session`]), not through a handshake: the
//! per-frame cost does not depend on where the keys came from, and the handshake steps
//! are measured on the emulated Cortex-M4 (`bench/m4`).

use pprz_secure::{DirectionKey, OVERHEAD, Policy, SecureChannel, SessionKeys};
use pprz_transports::{Encoder, GROUND_ID, MsgHeader, PprzV2, TxMeta};

/// Frames of the seal and open workloads.
pub const FRAMES: usize = 10_000;

/// Aircraft id: source of every frame.
pub const AC_ID: u8 = 7;

/// Telemetry id of the frames (PAYLOAD: one `uint8[]` field).
pub const PAYLOAD_ID: u8 = 114;

/// Bytes of message fields per frame (the array's length byte and its 39 values).
pub const FIELDS_LEN: usize = 40;

/// Length of the plain PPRZ v2 frame (`STX LEN src dst class id fields CK_A CK_B`).
pub const PLAIN_FRAME_LEN: usize = FIELDS_LEN + 8;

/// Length of the sealed frame.
pub const SEALED_FRAME_LEN: usize = PLAIN_FRAME_LEN + OVERHEAD;

/// A plain frame.
pub type PlainFrame = [u8; PLAIN_FRAME_LEN];

/// A sealed frame.
pub type SealedFrame = [u8; SEALED_FRAME_LEN];

/// The two ends of a session with fixed keys (benchmark only): the aircraft's channel,
/// which seals, and the ground's, which opens.
pub fn session() -> (SecureChannel, SecureChannel) {
    let down = || DirectionKey::new([0xB1; 32], [0xB2; 12]);
    let up = || DirectionKey::new([0xA1; 32], [0xA2; 12]);
    let mut air = SecureChannel::new(Policy::aircraft(AC_ID));
    air.install(SessionKeys::new(down(), up()));
    let mut ground = SecureChannel::new(Policy::ground(AC_ID));
    ground.install(SessionKeys::new(up(), down()));
    (air, ground)
}

/// The plain frame of index `i`: PAYLOAD from the aircraft to the ground, 39 values
/// that vary with `i`.
pub fn plain_frame(i: u32) -> PlainFrame {
    let mut fields = [0u8; FIELDS_LEN];
    fields[0] = (FIELDS_LEN - 1) as u8;
    for (k, v) in fields[1..].iter_mut().enumerate() {
        *v = (i.wrapping_mul(31).wrapping_add(k as u32 * 7)) as u8;
    }
    let meta = TxMeta::new(MsgHeader::new(AC_ID, GROUND_ID, 1, PAYLOAD_ID));
    let mut frame = [0u8; PLAIN_FRAME_LEN];
    let len = PprzV2
        .encode(&meta, &fields, &mut frame)
        .expect("a 40-byte message fits a PPRZ v2 frame");
    assert_eq!(len, PLAIN_FRAME_LEN);
    frame
}

/// The plain frames of indices `0..count`.
pub fn plain_frames(count: usize) -> Vec<PlainFrame> {
    (0..count as u32).map(plain_frame).collect()
}

/// The plain frames of indices `0..count`, each at the start of a buffer with
/// [`OVERHEAD`] spare bytes, as the writer holds them: [`seal_frames`] seals them in place.
pub fn frame_buffers(count: usize) -> Vec<SealedFrame> {
    (0..count as u32)
        .map(|i| {
            let mut buf = [0u8; SEALED_FRAME_LEN];
            buf[..PLAIN_FRAME_LEN].copy_from_slice(&plain_frame(i));
            buf
        })
        .collect()
}

/// Seals, in place, the plain frame at the start of every buffer of `frames` (from
/// [`frame_buffers`]) on `channel`; returns how many were sealed.
///
/// # Panics
/// If a frame does not seal to [`SEALED_FRAME_LEN`] bytes (no session, say).
pub fn seal_frames(channel: &mut SecureChannel, frames: &mut [SealedFrame]) -> usize {
    let mut n = 0;
    for buf in frames.iter_mut() {
        let done = channel
            .seal_in_place(buf, PLAIN_FRAME_LEN)
            .expect("an installed session seals");
        assert_eq!(done.len, SEALED_FRAME_LEN);
        n += 1;
    }
    n
}

/// What [`open_frames`] saw: frames opened, and a digest of the plain frames they gave.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OpenSummary {
    /// Frames that opened (authentic, decrypted).
    pub opened: usize,
    /// Frames rejected.
    pub rejected: usize,
    /// A digest of every opened frame's bytes ([`digest`]).
    pub digest: u64,
}

/// FNV-1a over `bytes`, continuing from `h`.
pub fn digest(mut h: u64, bytes: &[u8]) -> u64 {
    for &b in bytes {
        h = (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01B3);
    }
    h
}

/// The FNV-1a offset basis, where [`digest`] starts.
pub const DIGEST_START: u64 = 0xCBF2_9CE4_8422_2325;

/// Opens the `DATA` of every frame of `sealed` on `channel`.
pub fn open_frames(channel: &mut SecureChannel, sealed: &[SealedFrame]) -> OpenSummary {
    let mut out = [0u8; 255];
    let mut summary = OpenSummary {
        opened: 0,
        rejected: 0,
        digest: DIGEST_START,
    };
    for frame in sealed {
        match channel.open(&frame[2..SEALED_FRAME_LEN - 2], &mut out) {
            Ok(opened) => {
                summary.opened += 1;
                summary.digest = digest(summary.digest, opened.frame());
            }
            Err(_) => summary.rejected += 1,
        }
    }
    summary
}

/// The summary [`open_frames`] must give for the frames of [`plain_frames`]`(count)`.
pub fn expected_open_summary(count: usize) -> OpenSummary {
    OpenSummary {
        opened: count,
        rejected: 0,
        digest: plain_frames(count)
            .iter()
            .fold(DIGEST_START, |h, f| digest(h, f)),
    }
}
