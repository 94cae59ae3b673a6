//! Wire format of secure PPRZ v2 frames, and the per-direction keys that protect them.
//!
//! A secure frame is an ordinary PPRZ v2 frame (`99 | LEN | DATA | CK_A | CK_B`, `LEN`
//! counting the whole frame, the checksum over `LEN`..last `DATA` byte) whose `DATA`
//! starts with a crypto byte:
//!
//! ```text
//! encrypted (0x55):
//! +------+---------------+-----+-----+---------------------------------+---------+
//! | 0x55 | counter BE32  | src | dst | ChaCha20(comp<<4|class, id, ..) | tag(16) |
//! +------+---------------+-----+-----+---------------------------------+---------+
//!    0      1         4     5     6     7 ..                              len-16
//!          nonce = BE32(counter) || salt[4..12]      AAD = src, dst
//!
//! plaintext (0xAA), whitelisted messages only (the key exchange):
//! +------+-----+-----+--------------+----+--------+
//! | 0xAA | src | dst | comp<<4|class| id | fields |
//! +------+-----+-----+--------------+----+--------+
//! ```
//!
//! An encrypted frame is [`OVERHEAD`] (21) bytes longer than the plain v2 frame of the
//! same message: its `DATA` is at least [`MIN_ENCRYPTED_DATA_LEN`] (25) bytes, and it
//! carries at most [`MAX_FIELDS_LEN`] (226) bytes of message fields.
//!
//! # No-panic contract
//! Every function here takes lengths from the slices it is given and checks them with
//! `get`/`split_*_checked`-style accessors: any input gives a value or a typed error.

use chacha20poly1305::aead::inout::InOutBuf;
use chacha20poly1305::{AeadInOut, ChaCha20Poly1305, KeyInit};
use zeroize::{Zeroize, ZeroizeOnDrop};

pub use pprz_transports::pprz::STX;

/// Crypto byte of an encrypted frame.
pub const ENCRYPTED: u8 = 0x55;
/// Crypto byte of a plaintext frame (whitelisted messages only).
pub const PLAINTEXT: u8 = 0xAA;
/// Length of the frame counter (big-endian `u32`).
pub const COUNTER_LEN: usize = 4;
/// Length of the Poly1305 tag.
pub const TAG_LEN: usize = 16;
/// Length of a ChaCha20-Poly1305 key.
pub const KEY_LEN: usize = 32;
/// Length of a direction's salt (the 12-byte nonce base).
pub const SALT_LEN: usize = 12;
/// Length of a ChaCha20-Poly1305 nonce.
pub const NONCE_LEN: usize = 12;
/// Bytes an encrypted frame adds to the plain PPRZ v2 frame of the same message:
/// crypto byte, counter and tag. Reserve them when allocating a frame to be sealed.
pub const OVERHEAD: usize = 1 + COUNTER_LEN + TAG_LEN;
/// Bytes a plaintext (`0xAA`) frame adds to the plain v2 frame: the crypto byte.
pub const PLAINTEXT_OVERHEAD: usize = 1;
/// Longest PPRZ frame (`LEN` is one byte).
pub const MAX_FRAME_LEN: usize = pprz_transports::pprz::MAX_FRAME_LEN;
/// Length of a plain PPRZ v2 frame without fields (STX, LEN, 4-byte header, checksum).
pub const PLAIN_FRAME_MIN_LEN: usize = 8;
/// Shortest `DATA` of an encrypted frame (a message without fields).
pub const MIN_ENCRYPTED_DATA_LEN: usize = 1 + COUNTER_LEN + 2 + 2 + TAG_LEN;
/// Shortest encrypted frame.
pub const MIN_ENCRYPTED_FRAME_LEN: usize = MIN_ENCRYPTED_DATA_LEN + 4;
/// Most message-field bytes of an encrypted v2 frame.
pub const MAX_FIELDS_LEN: usize = MAX_FRAME_LEN - MIN_ENCRYPTED_FRAME_LEN;
/// Most message-field bytes of a plaintext (`0xAA`) v2 frame.
pub const MAX_PLAINTEXT_FIELDS_LEN: usize = MAX_FRAME_LEN - PLAIN_FRAME_MIN_LEN - 1;
/// Longest `DATA` of any PPRZ frame.
pub const MAX_DATA_LEN: usize = MAX_FRAME_LEN - 4;

const _: () = {
    assert!(OVERHEAD == 21);
    assert!(MIN_ENCRYPTED_DATA_LEN == 25);
    assert!(MAX_FIELDS_LEN == 226);
};

/// Offsets inside the `DATA` of secure frames (`DATA` starts at byte 2 of the frame).
pub mod field {
    /// A byte range.
    pub type Field = core::ops::Range<usize>;

    /// The crypto byte ([`ENCRYPTED`](super::ENCRYPTED) or
    /// [`PLAINTEXT`](super::PLAINTEXT)), in both kinds of frame.
    pub const CRYPTO: usize = 0;

    /// Offsets in the `DATA` of an encrypted frame.
    pub mod encrypted {
        use super::Field;
        /// Frame counter, big-endian.
        pub const COUNTER: Field = 1..5;
        /// Source id (clear, authenticated).
        pub const SOURCE: usize = 5;
        /// Destination id (clear, authenticated).
        pub const DESTINATION: usize = 6;
        /// The additional authenticated data: source and destination.
        pub const AAD: Field = SOURCE..DESTINATION + 1;
        /// First ciphertext byte (the encrypted `comp<<4|class`).
        pub const CIPHERTEXT: usize = 7;
    }

    /// Offsets in the `DATA` of a plaintext frame.
    pub mod plaintext {
        /// Source id.
        pub const SOURCE: usize = 1;
        /// Destination id.
        pub const DESTINATION: usize = 2;
        /// `comp<<4|class`.
        pub const COMPONENT_CLASS: usize = 3;
        /// Message id.
        pub const MSG_ID: usize = 4;
        /// First byte of the message fields.
        pub const FIELDS: usize = 5;
    }
}

/// Writes `LEN` and the PPRZ checksum of the frame `frame` (whole frame, `STX` first).
/// Lengths below the framing overhead or above 255 leave the frame unchanged.
pub(crate) fn finish_pprz(frame: &mut [u8]) {
    let len = frame.len();
    let Ok(len_byte) = u8::try_from(len) else {
        return;
    };
    if len < 4 {
        return;
    }
    if let Some(l) = frame.get_mut(1) {
        *l = len_byte;
    }
    if let Some((body, ck)) = frame.split_last_chunk_mut::<2>() {
        let (a, b) = pprz_transports::checksum::pprz(body.get(1..).unwrap_or_default());
        *ck = [a, b];
    }
}

/// The symmetric key and salt of one direction of a session (`Ka, Sa` ground to
/// aircraft, `Kb, Sb` aircraft to ground). Zeroized on drop; its `Debug` shows nothing
/// secret.
#[derive(Zeroize, ZeroizeOnDrop)]
pub struct DirectionKey {
    key: [u8; KEY_LEN],
    salt: [u8; SALT_LEN],
}

impl core::fmt::Debug for DirectionKey {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str("DirectionKey(..)")
    }
}

impl DirectionKey {
    /// A direction key from its key and salt (the handshake derives them; tests and
    /// known-answer vectors give them directly).
    pub const fn new(key: [u8; KEY_LEN], salt: [u8; SALT_LEN]) -> Self {
        Self { key, salt }
    }

    /// The ChaCha20-Poly1305 key.
    pub fn key(&self) -> &[u8; KEY_LEN] {
        &self.key
    }

    /// The 12-byte salt.
    pub fn salt(&self) -> &[u8; SALT_LEN] {
        &self.salt
    }

    /// The nonce of the frame with counter `counter`: `BE32(counter) || salt[4..12]`.
    pub fn nonce(&self, counter: u32) -> [u8; NONCE_LEN] {
        let mut nonce = self.salt;
        let [a, b, c, d, ..] = &mut nonce;
        [*a, *b, *c, *d] = counter.to_be_bytes();
        nonce
    }

    /// The counter whose nonce equals the raw salt, which the handshake message of this
    /// direction was encrypted with: `BE32(salt[0..4])`. A sender never uses it.
    pub fn reserved_counter(&self) -> u32 {
        let [a, b, c, d, ..] = self.salt;
        u32::from_be_bytes([a, b, c, d])
    }

    fn cipher(&self) -> ChaCha20Poly1305 {
        ChaCha20Poly1305::new(&self.key.into())
    }

    /// Encrypts `buf` in place under `nonce` with `aad`; returns the tag.
    pub(crate) fn encrypt(
        &self,
        nonce: &[u8; NONCE_LEN],
        aad: &[u8],
        buf: &mut [u8],
    ) -> Option<[u8; TAG_LEN]> {
        self.cipher()
            .encrypt_inout_detached(&(*nonce).into(), aad, buf.into())
            .ok()
            .map(Into::into)
    }

    /// Verifies `tag` over `input` and `aad`, then decrypts `input` into `out` (of the
    /// same length). `false`, with `out` unspecified, when the tag does not verify.
    pub(crate) fn decrypt(
        &self,
        nonce: &[u8; NONCE_LEN],
        aad: &[u8],
        input: &[u8],
        out: &mut [u8],
        tag: &[u8; TAG_LEN],
    ) -> bool {
        let Ok(buf) = InOutBuf::new(input, out) else {
            return false;
        };
        self.cipher()
            .decrypt_inout_detached(&(*nonce).into(), aad, buf, &(*tag).into())
            .is_ok()
    }
}

/// The two direction keys of a session, as the handshake hands them to the
/// [`SecureChannel`](crate::SecureChannel) of its end: `tx` protects the frames this end
/// sends, `rx` those it receives. Zeroized on drop.
#[derive(Debug)]
pub struct SessionKeys {
    tx: DirectionKey,
    rx: DirectionKey,
}

impl SessionKeys {
    /// Session keys from the direction keys of this end.
    pub const fn new(tx: DirectionKey, rx: DirectionKey) -> Self {
        Self { tx, rx }
    }

    /// The key of the frames this end sends.
    pub fn tx(&self) -> &DirectionKey {
        &self.tx
    }

    /// The key of the frames this end receives.
    pub fn rx(&self) -> &DirectionKey {
        &self.rx
    }

    pub(crate) fn into_parts(self) -> (DirectionKey, DirectionKey) {
        (self.tx, self.rx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nonce_and_reserved_counter() {
        let k = DirectionKey::new([7; 32], [1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12]);
        assert_eq!(k.nonce(1), [0, 0, 0, 1, 5, 6, 7, 8, 9, 10, 11, 12]);
        assert_eq!(k.reserved_counter(), 0x0102_0304);
        assert_eq!(k.nonce(k.reserved_counter()), *k.salt());
        assert_eq!(format!("{k:?}"), "DirectionKey(..)");
    }

    #[test]
    fn finish_pprz_matches_the_transport() {
        // ALIVE from aircraft 7 (see pprz-transports): 99 0C 07 00 01 02 03 00 01 02 1C C4
        let mut f = [0x99, 0, 7, 0, 1, 2, 3, 0, 1, 2, 0, 0];
        finish_pprz(&mut f);
        assert_eq!(f, [0x99, 0x0C, 7, 0, 1, 2, 3, 0, 1, 2, 0x1C, 0xC4]);
        // Too short or too long: unchanged, no panic.
        let mut short = [0x99, 0, 0];
        finish_pprz(&mut short);
        assert_eq!(short, [0x99, 0, 0]);
        let mut long = [0u8; 256];
        finish_pprz(&mut long);
        assert!(long.iter().all(|&b| b == 0));
    }

    extern crate std;
    use std::format;
}
