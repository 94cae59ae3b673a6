//! What both ends of the station-to-station handshake share: the key-exchange messages,
//! the key derivation, errors and statistics.
//!
//! ```text
//!  ground (initiator A)                                   aircraft (responder B)
//!  a, P_ae = X25519(a, 9)
//!        --- KEY_EXCHANGE_GCS P_AE (plaintext): P_ae ------------------->
//!                                           b, P_be = X25519(b, 9); z = X25519(b, P_ae)
//!                                      Ka||Sa = SHA-512(z||00)[..44], Kb||Sb = (z||01)
//!        <-- KEY_EXCHANGE_UAV P_BE (plaintext): P_be ||
//!                   ChaCha20-Poly1305(Kb, Sb, sign(UAV, P_be||P_ae)) ----------
//!  z = X25519(a, P_be), same keys; decrypt, verify
//!        --- KEY_EXCHANGE_GCS SIG (plaintext):
//!                   ChaCha20-Poly1305(Kb->Ka, Sa, sign(GCS, P_ae||P_be)) ----->
//!  session up (tx Ka/Sa, rx Kb/Sb)                   decrypt, verify: session up
//!                                                    (tx Kb/Sb, rx Ka/Sa)
//! ```
//!
//! Fields: `KEY_EXCHANGE_GCS = ac_id u8, msg_type u8, msg_data u8[]` and
//! `KEY_EXCHANGE_UAV = msg_type u8, msg_data u8[]` (a `u8[]` is a count byte then the
//! bytes); `msg_type` P_AE = 0, P_BE = 1, SIG = 2.

use core::fmt;

use pprz_transports::MsgHeader;
use zeroize::Zeroizing;

use crate::channel::{KEY_EXCHANGE_GCS, KEY_EXCHANGE_UAV, MsgId};
use crate::crypto::{SigningKey, VerifyingKey};
use crate::frame::{DirectionKey, KEY_LEN, SALT_LEN, STX, TAG_LEN, finish_pprz};

/// Length of an X25519 public key.
pub const PUBLIC_KEY_LEN: usize = 32;
/// Length of an Ed25519 signature.
pub const SIGNATURE_LEN: usize = 64;
/// `msg_data` of P_AE: the ground's ephemeral public key.
pub const P_AE_DATA_LEN: usize = PUBLIC_KEY_LEN;
/// `msg_data` of P_BE: the aircraft's ephemeral public key and its encrypted signature.
pub const P_BE_DATA_LEN: usize = PUBLIC_KEY_LEN + SIGNATURE_LEN + TAG_LEN;
/// `msg_data` of SIG: the ground's encrypted signature.
pub const SIG_DATA_LEN: usize = SIGNATURE_LEN + TAG_LEN;
/// The longest `msg_data`.
pub const MAX_DATA_LEN: usize = P_BE_DATA_LEN;

/// The `msg_type` of a key-exchange message.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum MsgType {
    /// 0: the ground's ephemeral public key (message 1).
    PAe = 0,
    /// 1: the aircraft's ephemeral public key and signature (message 2).
    PBe = 1,
    /// 2: the ground's signature (message 3).
    Sig = 2,
}

impl MsgType {
    /// The type with wire value `v`.
    pub const fn from_u8(v: u8) -> Option<Self> {
        match v {
            0 => Some(Self::PAe),
            1 => Some(Self::PBe),
            2 => Some(Self::Sig),
            _ => None,
        }
    }
}

/// The ids of the two key-exchange messages in the message set (PPRZLINK's by default).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct KeyExchangeIds {
    /// `KEY_EXCHANGE_GCS`, ground to aircraft.
    pub gcs: MsgId,
    /// `KEY_EXCHANGE_UAV`, aircraft to ground.
    pub uav: MsgId,
}

impl KeyExchangeIds {
    /// PPRZLINK's ids: datalink 159 and telemetry 239.
    pub const PPRZLINK: Self = Self {
        gcs: KEY_EXCHANGE_GCS,
        uav: KEY_EXCHANGE_UAV,
    };
}

impl Default for KeyExchangeIds {
    fn default() -> Self {
        Self::PPRZLINK
    }
}

/// Why a handshake step refused a message. Every refusal is counted in
/// [`HandshakeStats`] and changes nothing else.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum HandshakeError {
    /// Not a key-exchange message of the right kind, or bad lengths or type.
    Malformed,
    /// Not for us (destination, `ac_id` field) or not from our peer.
    WrongAddress,
    /// Not expected now (a SIG without a pending handshake, a P_BE when not waiting).
    Unexpected,
    /// A copy of a message already handled.
    Duplicate,
    /// More work than the rate limit allows (responder): try again later.
    RateLimited,
    /// An all-zero or low-order ephemeral key (all-zero shared secret).
    BadKey,
    /// The encrypted signature does not decrypt (wrong keys or modified).
    BadTag,
    /// The signature does not verify under the peer's long-term key.
    BadSignature,
}

impl fmt::Display for HandshakeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Malformed => "malformed key-exchange message",
            Self::WrongAddress => "key exchange not for us",
            Self::Unexpected => "unexpected key-exchange message",
            Self::Duplicate => "duplicate key-exchange message",
            Self::RateLimited => "key exchange rate-limited",
            Self::BadKey => "low-order ephemeral key",
            Self::BadTag => "encrypted signature does not decrypt",
            Self::BadSignature => "bad signature",
        })
    }
}

impl core::error::Error for HandshakeError {}

/// Handshake counters of one end (all wrapping).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct HandshakeStats {
    /// Handshakes started: message 1 sent (initiator) or answered with fresh keys
    /// (responder).
    pub started: u32,
    /// Handshakes completed: session keys handed out.
    pub completed: u32,
    /// Messages sent again (initiator: message 1 or 3 after a timeout; responder:
    /// message 2 again for a repeated message 1, from its cache, without new work).
    pub resent: u32,
    /// Refused: malformed.
    pub malformed: u32,
    /// Refused: wrong destination, `ac_id` or source.
    pub wrong_address: u32,
    /// Refused: unexpected in the current state.
    pub unexpected: u32,
    /// Refused: copies of handled messages (a replay, or a late copy) that get no
    /// answer.
    pub duplicate: u32,
    /// Refused: rate limit.
    pub rate_limited: u32,
    /// Refused: all-zero or low-order ephemeral key.
    pub bad_key: u32,
    /// Refused: encrypted signature does not decrypt.
    pub bad_tag: u32,
    /// Refused: signature does not verify.
    pub bad_signature: u32,
}

impl HandshakeStats {
    /// Every refusal, whatever the reason (duplicates included).
    pub fn refused(&self) -> u32 {
        [
            self.malformed,
            self.wrong_address,
            self.unexpected,
            self.duplicate,
            self.rate_limited,
            self.bad_key,
            self.bad_tag,
            self.bad_signature,
        ]
        .iter()
        .fold(0u32, |a, &b| a.wrapping_add(b))
    }

    pub(crate) fn count(&mut self, e: HandshakeError) {
        let c = match e {
            HandshakeError::Malformed => &mut self.malformed,
            HandshakeError::WrongAddress => &mut self.wrong_address,
            HandshakeError::Unexpected => &mut self.unexpected,
            HandshakeError::Duplicate => &mut self.duplicate,
            HandshakeError::RateLimited => &mut self.rate_limited,
            HandshakeError::BadKey => &mut self.bad_key,
            HandshakeError::BadTag => &mut self.bad_tag,
            HandshakeError::BadSignature => &mut self.bad_signature,
        };
        *c = c.wrapping_add(1);
    }
}

/// A key-exchange message (`KEY_EXCHANGE_GCS` or `KEY_EXCHANGE_UAV`) with its source and
/// destination: what the reader hands to the handshake, and what the handshake gives to
/// send. Owned and `Copy`-free but small (about 120 bytes), so it can cross a channel
/// between tasks.
#[derive(Clone, PartialEq, Eq)]
pub struct KeyExchange {
    /// Sender id.
    pub source: u8,
    /// Receiver id.
    pub destination: u8,
    /// The message kind (its class and id).
    pub msg: MsgId,
    /// The `ac_id` field of `KEY_EXCHANGE_GCS`; `None` for `KEY_EXCHANGE_UAV`.
    pub ac_id: Option<u8>,
    /// The message type.
    pub msg_type: MsgType,
    data: [u8; MAX_DATA_LEN],
    len: u8,
}

impl fmt::Debug for KeyExchange {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("KeyExchange")
            .field("source", &self.source)
            .field("destination", &self.destination)
            .field("msg", &self.msg)
            .field("ac_id", &self.ac_id)
            .field("msg_type", &self.msg_type)
            .field("data_len", &self.len)
            .finish()
    }
}

impl KeyExchange {
    pub(crate) fn new(
        header: (u8, u8),
        msg: MsgId,
        ac_id: Option<u8>,
        msg_type: MsgType,
        data: &[u8],
    ) -> Self {
        let mut buf = [0u8; MAX_DATA_LEN];
        let mut n = 0;
        for (b, d) in buf.iter_mut().zip(data) {
            *b = *d;
            n += 1;
        }
        Self {
            source: header.0,
            destination: header.1,
            msg,
            ac_id,
            msg_type,
            data: buf,
            len: n as u8,
        }
    }

    /// The `msg_data` bytes.
    pub fn data(&self) -> &[u8] {
        self.data.get(..usize::from(self.len)).unwrap_or_default()
    }

    /// Parses the `DATA` of a plain PPRZ v2 frame (`src dst comp<<4|class id fields`, as
    /// [`Opened::data`](crate::Opened::data) gives it). `Ok(None)` when it is not one of
    /// the two key-exchange messages of `ids`.
    ///
    /// # Errors
    /// [`HandshakeError::Malformed`]: a key-exchange message with an unknown type, a
    /// `msg_data` longer than [`MAX_DATA_LEN`], or fields that disagree with their count.
    pub fn parse(data: &[u8], ids: &KeyExchangeIds) -> Result<Option<Self>, HandshakeError> {
        let Some((h, fields)) = MsgHeader::parse_v2(data) else {
            return Ok(None);
        };
        let is_gcs = h.class == ids.gcs.class && h.msg_id == ids.gcs.id;
        let is_uav = h.class == ids.uav.class && h.msg_id == ids.uav.id;
        let (msg, ac_id, rest) = match fields {
            [ac_id, rest @ ..] if is_gcs => (ids.gcs, Some(*ac_id), rest),
            rest if is_uav => (ids.uav, None, rest),
            _ if is_gcs => return Err(HandshakeError::Malformed),
            _ => return Ok(None),
        };
        match rest {
            [t, n, bytes @ ..] if usize::from(*n) == bytes.len() && bytes.len() <= MAX_DATA_LEN => {
                let msg_type = MsgType::from_u8(*t).ok_or(HandshakeError::Malformed)?;
                Ok(Some(Self::new(
                    (h.source, h.destination),
                    msg,
                    ac_id,
                    msg_type,
                    bytes,
                )))
            }
            _ => Err(HandshakeError::Malformed),
        }
    }

    /// The message's fields (`[ac_id,] msg_type, count, msg_data`): returns their length.
    /// `buf` must hold [`fields_len`](Self::fields_len) bytes; `None` otherwise.
    pub fn write_fields(&self, buf: &mut [u8]) -> Option<usize> {
        let n = self.fields_len();
        let out = buf.get_mut(..n)?;
        let (head, data) = match (self.ac_id, out) {
            (Some(ac), [a, t, c, data @ ..]) => {
                *a = ac;
                ((t, c), data)
            }
            (None, [t, c, data @ ..]) => ((t, c), data),
            _ => return None,
        };
        *head.0 = self.msg_type as u8;
        *head.1 = self.len;
        data.copy_from_slice(self.data());
        Some(n)
    }

    /// Length of the message's fields.
    pub fn fields_len(&self) -> usize {
        usize::from(self.ac_id.is_some()) + 2 + usize::from(self.len)
    }

    /// Writes the message as a plain PPRZ v2 frame (component 0) into `buf`, returns its
    /// length: what a sender queues, and the channel's
    /// [`seal_in_place`](crate::SecureChannel::seal_in_place) sends in plaintext.
    /// `None` if `buf` is shorter than the frame (at most 125 bytes).
    pub fn write_frame(&self, buf: &mut [u8]) -> Option<usize> {
        let len = 8 + self.fields_len();
        let frame = buf.get_mut(..len)?;
        let (head, rest) = frame.split_at_mut_checked(6)?;
        head.copy_from_slice(&[
            STX,
            0,
            self.source,
            self.destination,
            self.msg.class & 0x0F,
            self.msg.id,
        ]);
        self.write_fields(rest)?;
        finish_pprz(frame);
        Some(len)
    }
}

/// `Ka||Sa` (`label` 0) or `Kb||Sb` (`label` 1) from the shared secret `z`:
/// `SHA-512(z || label)`, key = bytes 0..32, salt = bytes 32..44.
pub(crate) fn derive(z: &[u8; 32], label: u8) -> DirectionKey {
    let out = crate::crypto::sha512(&[z, &[label]]);
    let mut key = Zeroizing::new([0u8; KEY_LEN]);
    let mut salt = Zeroizing::new([0u8; SALT_LEN]);
    let (k, rest) = out.split_at(KEY_LEN);
    key.copy_from_slice(k);
    for (s, b) in salt.iter_mut().zip(rest) {
        *s = *b;
    }
    DirectionKey::new(*key, *salt)
}

/// The two direction keys of the shared secret `z`: `(A->B, B->A)`; `None` if `z` is
/// all zero (a low-order public key).
pub(crate) fn session_keys(z: &Zeroizing<[u8; 32]>) -> Option<(DirectionKey, DirectionKey)> {
    if crate::crypto::is_zero(z) {
        return None;
    }
    Some((derive(z, 0), derive(z, 1)))
}

/// `first || second`.
fn concat(first: &[u8; 32], second: &[u8; 32]) -> [u8; 64] {
    let mut m = [0u8; 64];
    m[..32].copy_from_slice(first);
    m[32..].copy_from_slice(second);
    m
}

/// Signs `first || second` and encrypts the signature under `key` with its raw salt as
/// the nonce and no AAD: `ciphertext (64) || tag (16)`.
pub(crate) fn sign_and_seal(
    own: &SigningKey,
    first: &[u8; 32],
    second: &[u8; 32],
    key: &DirectionKey,
) -> Option<[u8; SIG_DATA_LEN]> {
    let sig = own.sign(&concat(first, second));
    let mut out = [0u8; SIG_DATA_LEN];
    let (ct, tag_out) = out.split_at_mut(SIGNATURE_LEN);
    ct.copy_from_slice(&sig);
    let tag = key.encrypt(key.salt(), &[], ct)?;
    tag_out.copy_from_slice(&tag);
    Some(out)
}

/// Decrypts `sealed` (`ciphertext (64) || tag (16)`) under `key` with its raw salt, and
/// verifies the signature over `first || second` under `peer`.
pub(crate) fn open_and_verify(
    peer: &VerifyingKey,
    first: &[u8; 32],
    second: &[u8; 32],
    key: &DirectionKey,
    sealed: &[u8],
) -> Result<(), HandshakeError> {
    let (ct, tag) = sealed
        .split_last_chunk::<TAG_LEN>()
        .filter(|(ct, _)| ct.len() == SIGNATURE_LEN)
        .ok_or(HandshakeError::Malformed)?;
    let mut sig = [0u8; SIGNATURE_LEN];
    if !key.decrypt(key.salt(), &[], ct, &mut sig, tag) {
        return Err(HandshakeError::BadTag);
    }
    if peer.verify(&concat(first, second), &sig) {
        Ok(())
    } else {
        Err(HandshakeError::BadSignature)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn key_exchange_fields_and_frames() {
        let ids = KeyExchangeIds::PPRZLINK;
        let m = KeyExchange::new((0, 7), ids.gcs, Some(0), MsgType::PAe, &[9; 32]);
        let mut frame = [0u8; 128];
        let n = m.write_frame(&mut frame).unwrap();
        assert_eq!(n, 8 + 35);
        assert_eq!(&frame[..9], &[STX, 43, 0, 7, 2, 159, 0, 0, 32]);
        let back = KeyExchange::parse(&frame[2..n - 2], &ids).unwrap().unwrap();
        assert_eq!(back, m);
        assert!(m.write_frame(&mut frame[..42]).is_none());
        // Other messages are not key exchanges; bad ones are malformed.
        assert_eq!(KeyExchange::parse(&[0, 7, 2, 8], &ids), Ok(None));
        assert_eq!(KeyExchange::parse(&[0, 7], &ids), Ok(None));
        assert_eq!(
            KeyExchange::parse(&[0, 7, 2, 159], &ids),
            Err(HandshakeError::Malformed)
        );
        assert_eq!(
            KeyExchange::parse(&[0, 7, 2, 159, 0, 3, 1], &ids),
            Err(HandshakeError::Malformed)
        );
        assert_eq!(
            KeyExchange::parse(&[7, 0, 1, 239, 1, 2, 1], &ids),
            Err(HandshakeError::Malformed)
        );
        let uav = KeyExchange::parse(&[7, 0, 0x31, 239, 1, 2, 1, 2], &ids)
            .unwrap()
            .unwrap();
        assert_eq!(
            (uav.ac_id, uav.msg_type, uav.data()),
            (None, MsgType::PBe, &[1, 2][..])
        );
        let mut f = [0u8; 4];
        assert_eq!(uav.write_fields(&mut f), Some(4));
        assert_eq!(f, [1, 2, 1, 2]);
    }

    #[test]
    fn zero_shared_secret_is_refused() {
        assert!(session_keys(&Zeroizing::new([0; 32])).is_none());
        assert!(session_keys(&Zeroizing::new([1; 32])).is_some());
    }
}
