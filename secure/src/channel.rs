//! The per-device secure state shared by a device's writer and reader: the session keys
//! and counters, the plaintext policy and the frame counters.
//!
//! * The writer calls [`SecureChannel::seal_in_place`] on each frame when it takes it for
//!   the wire (not when it is queued), so the counters on the wire increase strictly in
//!   the order the frames leave, whatever the priority queue did before.
//! * The reader calls [`SecureChannel::open`] on the `DATA` of each decoded PPRZ frame and
//!   gets back a plain PPRZ v2 frame (or a counted rejection).
//! * The end's handshake task installs the keys of each new session with
//!   [`SecureChannel::install`]; until then the previous session stays in force.
//!
//! Every method is synchronous, bounded and allocation-free; the longest, sealing or
//! opening a 255-byte frame, is one ChaCha20-Poly1305 pass over at most 228 bytes, so the
//! channel can live in a blocking mutex shared by the writer and the reader.

use core::fmt;

use pprz_transports::{BROADCAST_ID, GROUND_ID, MsgHeader};
use subtle::ConstantTimeEq;

use crate::frame::{
    COUNTER_LEN, DirectionKey, ENCRYPTED, MAX_DATA_LEN, MAX_FIELDS_LEN, MAX_FRAME_LEN,
    MIN_ENCRYPTED_DATA_LEN, OVERHEAD, PLAIN_FRAME_MIN_LEN, PLAINTEXT, PLAINTEXT_OVERHEAD, STX,
    SessionKeys, TAG_LEN, field, finish_pprz,
};

/// A message kind: class and id (the component is not part of it).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct MsgId {
    /// Message class, 0..=15 (telemetry 1, datalink 2 in PPRZLINK).
    pub class: u8,
    /// Message id within its class.
    pub id: u8,
}

impl MsgId {
    /// A message kind.
    pub const fn new(class: u8, id: u8) -> Self {
        Self { class, id }
    }

    /// Whether the `comp<<4|class` byte `component_class` and the id `id` name this
    /// message.
    pub const fn matches(&self, component_class: u8, id: u8) -> bool {
        self.class == component_class & 0x0F && self.id == id
    }
}

/// `KEY_EXCHANGE_GCS` (datalink class 2, id 159): the ground's handshake messages.
pub const KEY_EXCHANGE_GCS: MsgId = MsgId::new(2, 159);
/// `KEY_EXCHANGE_UAV` (telemetry class 1, id 239): the aircraft's handshake message.
pub const KEY_EXCHANGE_UAV: MsgId = MsgId::new(1, 239);
/// `SECURE_LINK_STATUS` (telemetry class 1, id 255) of the reference message set.
pub const SECURE_LINK_STATUS: MsgId = MsgId::new(1, 255);

/// What an end of the link sends and accepts in plaintext, and which addresses it
/// accepts. `const`, so a [`SecureChannel`] can be a `static`.
///
/// Plaintext is limited to the key exchange by default: the aircraft accepts only
/// `KEY_EXCHANGE_GCS` and sends only `KEY_EXCHANGE_UAV` in the clear, the ground the
/// reverse. Any other plaintext frame is rejected and counted.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Policy {
    /// Our id: received frames must be addressed to it or to broadcast (`0xFF`).
    pub own_id: u8,
    /// The only source accepted, if any (the ground accepts its aircraft only).
    pub peer_id: Option<u8>,
    /// Messages accepted in plaintext (`0xAA`).
    pub rx_plaintext: &'static [MsgId],
    /// Messages always sent in plaintext.
    pub tx_plaintext: &'static [MsgId],
    /// A message sent in plaintext while no session exists (a "still alive" beacon), and
    /// encrypted like any other once one does. `None` by default: see the crate docs for
    /// the trade-off.
    pub beacon: Option<MsgId>,
}

impl Policy {
    /// The aircraft `ac_id` (the responder): accepts frames for `ac_id` or broadcast from
    /// any source (they are authenticated), `KEY_EXCHANGE_GCS` in plaintext, and sends
    /// `KEY_EXCHANGE_UAV` in plaintext.
    pub const fn aircraft(ac_id: u8) -> Self {
        Self {
            own_id: ac_id,
            peer_id: None,
            rx_plaintext: &[KEY_EXCHANGE_GCS],
            tx_plaintext: &[KEY_EXCHANGE_UAV],
            beacon: None,
        }
    }

    /// The ground's end of the link with aircraft `ac_id` (the initiator): accepts frames
    /// from `ac_id` for the ground (0) or broadcast, `KEY_EXCHANGE_UAV` in plaintext, and
    /// sends `KEY_EXCHANGE_GCS` in plaintext.
    pub const fn ground(ac_id: u8) -> Self {
        Self {
            own_id: GROUND_ID,
            peer_id: Some(ac_id),
            rx_plaintext: &[KEY_EXCHANGE_UAV],
            tx_plaintext: &[KEY_EXCHANGE_GCS],
            beacon: None,
        }
    }

    /// The same policy with other plaintext lists (for a message set whose key-exchange
    /// messages have other ids).
    pub const fn with_plaintext(
        self,
        rx_plaintext: &'static [MsgId],
        tx_plaintext: &'static [MsgId],
    ) -> Self {
        Self {
            rx_plaintext,
            tx_plaintext,
            ..self
        }
    }

    /// The same policy with a plaintext beacon sent while no session exists.
    pub const fn with_beacon(self, beacon: Option<MsgId>) -> Self {
        Self { beacon, ..self }
    }

    fn listed(list: &[MsgId], component_class: u8, id: u8) -> bool {
        list.iter().any(|m| m.matches(component_class, id))
    }

    fn address_ok(&self, source: u8, destination: u8) -> bool {
        let dest_ok = destination == self.own_id || destination == BROADCAST_ID;
        let source_ok = self.peer_id.is_none_or(|p| p == source);
        dest_ok && source_ok
    }
}

/// Why [`SecureChannel::seal_in_place`] did not produce a frame. The frame is not sent;
/// every case is counted in [`ChannelStats`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum SealError {
    /// The bytes are not a plain PPRZ v2 frame of the given length (start byte, `LEN`).
    NotAFrame,
    /// More than [`MAX_FIELDS_LEN`] bytes of fields (plaintext: more than fit 255 bytes).
    TooLong,
    /// The buffer lacks the [`OVERHEAD`] bytes of room after the frame.
    BufferTooSmall,
    /// No session yet: only whitelisted plaintext (and the beacon) can be sent.
    NoSession,
    /// The frame counter is used up: the session must be replaced (a new handshake)
    /// before anything else is sent. Counters never wrap.
    CounterExhausted,
}

impl fmt::Display for SealError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::NotAFrame => "not a plain PPRZ v2 frame",
            Self::TooLong => "too many fields for a secure frame",
            Self::BufferTooSmall => "no room for the secure overhead",
            Self::NoSession => "no secure session",
            Self::CounterExhausted => "frame counter exhausted: a new session is needed",
        })
    }
}

impl core::error::Error for SealError {}

/// Why [`SecureChannel::open`] rejected a received frame. Nothing of the frame is
/// delivered and no state changes, except the counter of its reason in
/// [`ChannelStats`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum Reject {
    /// Too short for its crypto byte's layout, or longer than a PPRZ frame can be.
    Malformed,
    /// Neither `0x55` nor `0xAA` first: an unsecured frame (or garbage).
    NotSecure,
    /// A plaintext frame of a message not on the policy's whitelist.
    PlaintextNotAllowed,
    /// Addressed to another id, or (ground) from another aircraft.
    WrongAddress,
    /// An encrypted frame while no session exists.
    NoSession,
    /// A counter not above the last accepted one: a replay, or an old frame.
    Replayed,
    /// The tag does not verify: modified, forged, or from another session.
    BadTag,
    /// The output buffer cannot hold the plain frame (a caller error; a buffer of
    /// [`MAX_FRAME_LEN`] bytes never gives it).
    BufferTooSmall,
}

impl fmt::Display for Reject {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Malformed => "malformed secure frame",
            Self::NotSecure => "unsecured frame",
            Self::PlaintextNotAllowed => "plaintext not allowed for this message",
            Self::WrongAddress => "wrong source or destination",
            Self::NoSession => "encrypted frame without a session",
            Self::Replayed => "replayed or old counter",
            Self::BadTag => "authentication failed",
            Self::BufferTooSmall => "output buffer too small",
        })
    }
}

impl core::error::Error for Reject {}

/// How a frame crossed the link.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum Protection {
    /// Encrypted and authenticated, with this counter.
    Encrypted {
        /// The frame counter.
        counter: u32,
    },
    /// In plaintext (a whitelisted message): **not authenticated**.
    Plaintext,
}

/// A received frame that passed [`SecureChannel::open`]: a plain PPRZ v2 frame in the
/// caller's buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Opened<'a> {
    frame: &'a [u8],
    protection: Protection,
}

impl<'a> Opened<'a> {
    /// The plain PPRZ v2 frame (`99 LEN src dst comp<<4|class id fields CK_A CK_B`),
    /// ready for `PprzV2::view`.
    pub fn frame(&self) -> &'a [u8] {
        self.frame
    }

    /// Its `DATA`: the v2 header and the fields.
    pub fn data(&self) -> &'a [u8] {
        let end = self.frame.len().saturating_sub(2);
        self.frame.get(2..end).unwrap_or_default()
    }

    /// Its v2 header.
    pub fn header(&self) -> MsgHeader {
        MsgHeader::parse_v2(self.data())
            .map(|(h, _)| h)
            .unwrap_or_default()
    }

    /// Its message fields.
    pub fn fields(&self) -> &'a [u8] {
        self.data().get(4..).unwrap_or_default()
    }

    /// Whether it is the message `msg`.
    pub fn is(&self, msg: MsgId) -> bool {
        let h = self.header();
        h.class == msg.class && h.msg_id == msg.id
    }

    /// How it crossed the link.
    pub fn protection(&self) -> Protection {
        self.protection
    }

    /// Whether it was encrypted (hence authenticated).
    pub fn is_encrypted(&self) -> bool {
        matches!(self.protection, Protection::Encrypted { .. })
    }
}

/// What [`SecureChannel::seal_in_place`] made of a frame.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Sealed {
    /// Length of the frame to write, from the start of the buffer.
    pub len: usize,
    /// How it goes.
    pub protection: Protection,
}

/// Frame counters of a [`SecureChannel`] (all wrapping).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct ChannelStats {
    /// Sessions installed.
    pub sessions: u32,
    /// Frames encrypted for sending.
    pub encrypted: u32,
    /// Frames sent in plaintext (key exchange, beacon).
    pub sent_plaintext: u32,
    /// Frames refused for want of a session (telemetry before the handshake).
    pub no_session_tx: u32,
    /// Frames refused because the counter was used up.
    pub counter_exhausted: u32,
    /// Frames refused as not a frame, too long or without room.
    pub seal_errors: u32,
    /// Frames decrypted and accepted.
    pub decrypted: u32,
    /// Whitelisted plaintext frames accepted.
    pub received_plaintext: u32,
    /// Rejected: tag did not verify.
    pub bad_tag: u32,
    /// Rejected: counter not above the last accepted.
    pub replayed: u32,
    /// Rejected: plaintext of a message not on the whitelist.
    pub plaintext_not_allowed: u32,
    /// Rejected: malformed secure frame.
    pub malformed: u32,
    /// Rejected: unsecured frame (first byte neither `0x55` nor `0xAA`).
    pub not_secure: u32,
    /// Rejected: wrong destination (or, on the ground, wrong source aircraft).
    pub wrong_address: u32,
    /// Rejected: encrypted frame while no session exists.
    pub no_session_rx: u32,
}

impl ChannelStats {
    /// Every received frame rejected, whatever the reason.
    pub fn rejected(&self) -> u32 {
        [
            self.bad_tag,
            self.replayed,
            self.plaintext_not_allowed,
            self.malformed,
            self.not_secure,
            self.wrong_address,
            self.no_session_rx,
        ]
        .iter()
        .fold(0u32, |a, &b| a.wrapping_add(b))
    }

    fn count_reject(&mut self, reason: Reject) {
        let c = match reason {
            // A caller error, not a property of the frame: not counted.
            Reject::BufferTooSmall => return,
            Reject::Malformed => &mut self.malformed,
            Reject::NotSecure => &mut self.not_secure,
            Reject::PlaintextNotAllowed => &mut self.plaintext_not_allowed,
            Reject::WrongAddress => &mut self.wrong_address,
            Reject::NoSession => &mut self.no_session_rx,
            Reject::Replayed => &mut self.replayed,
            Reject::BadTag => &mut self.bad_tag,
        };
        *c = c.wrapping_add(1);
    }

    fn count_seal_error(&mut self, e: SealError) {
        let c = match e {
            SealError::NoSession => &mut self.no_session_tx,
            SealError::CounterExhausted => &mut self.counter_exhausted,
            SealError::NotAFrame | SealError::TooLong | SealError::BufferTooSmall => {
                &mut self.seal_errors
            }
        };
        *c = c.wrapping_add(1);
    }
}

/// Counters below this many frames left make [`SecureChannel::needs_rekey`] true.
pub const REKEY_THRESHOLD: u32 = 1 << 20;

/// The sending half of a session: key and next counter.
#[derive(Debug)]
struct Tx {
    key: DirectionKey,
    /// The next counter to use, 1..=2^32 (2^32: exhausted). Never decreases.
    next: u64,
    /// The counter that would reuse the handshake's nonce.
    reserved: u32,
}

impl Tx {
    const END: u64 = 1 << 32;

    fn new(key: DirectionKey) -> Self {
        let reserved = key.reserved_counter();
        Self {
            key,
            next: 1,
            reserved,
        }
    }

    /// Takes the next counter, skipping the reserved one; `None` when used up.
    fn take(&mut self) -> Option<u32> {
        loop {
            let c = u32::try_from(self.next).ok()?;
            self.next += 1;
            if c != self.reserved {
                return Some(c);
            }
        }
    }

    /// How many frames can still be sent.
    fn left(&self) -> u32 {
        let left = Self::END.saturating_sub(self.next);
        let reserved_ahead = u64::from(u64::from(self.reserved) >= self.next);
        u32::try_from(left.saturating_sub(reserved_ahead)).unwrap_or(u32::MAX)
    }
}

/// The receiving half of a session: key and last accepted counter.
#[derive(Debug)]
struct Rx {
    key: DirectionKey,
    /// The last accepted counter (0: none yet; counters start at 1).
    last: u32,
}

/// The secure state of one end of a link on one device: session keys, counters, policy
/// and statistics. See the [module documentation](self).
#[derive(Debug)]
pub struct SecureChannel {
    policy: Policy,
    tx: Option<Tx>,
    rx: Option<Rx>,
    stats: ChannelStats,
}

impl SecureChannel {
    /// A channel without a session yet.
    pub const fn new(policy: Policy) -> Self {
        Self {
            policy,
            tx: None,
            rx: None,
            stats: ChannelStats {
                sessions: 0,
                encrypted: 0,
                sent_plaintext: 0,
                no_session_tx: 0,
                counter_exhausted: 0,
                seal_errors: 0,
                decrypted: 0,
                received_plaintext: 0,
                bad_tag: 0,
                replayed: 0,
                plaintext_not_allowed: 0,
                malformed: 0,
                not_secure: 0,
                wrong_address: 0,
                no_session_rx: 0,
            },
        }
    }

    /// The policy.
    pub fn policy(&self) -> &Policy {
        &self.policy
    }

    /// Installs a new session (the keys a completed handshake gives): counters restart
    /// at 1 in both directions; the previous session's keys are zeroized.
    pub fn install(&mut self, keys: SessionKeys) {
        let (tx, rx) = keys.into_parts();
        self.tx = Some(Tx::new(tx));
        self.rx = Some(Rx { key: rx, last: 0 });
        self.stats.sessions = self.stats.sessions.wrapping_add(1);
    }

    /// Forgets the session (keys zeroized): only plaintext is possible until the next
    /// [`install`](Self::install).
    pub fn clear(&mut self) {
        self.tx = None;
        self.rx = None;
    }

    /// Whether a session is installed.
    pub fn has_session(&self) -> bool {
        self.tx.is_some()
    }

    /// How many more frames the current session can send (0 without a session).
    pub fn counter_space_left(&self) -> u32 {
        self.tx.as_ref().map_or(0, Tx::left)
    }

    /// How many more frames the peer can send before its counter is used up, as far as
    /// we know (0 without a session).
    pub fn peer_counter_space_left(&self) -> u32 {
        self.rx.as_ref().map_or(0, |rx| u32::MAX - rx.last)
    }

    /// The last counter accepted from the peer (0: none yet in this session).
    pub fn last_rx_counter(&self) -> u32 {
        self.rx.as_ref().map_or(0, |rx| rx.last)
    }

    /// Whether the session should be replaced soon: either direction has fewer than
    /// [`REKEY_THRESHOLD`] frames left. The initiator (ground) restarts the handshake
    /// when this is true.
    pub fn needs_rekey(&self) -> bool {
        self.has_session()
            && (self.counter_space_left() < REKEY_THRESHOLD
                || self.peer_counter_space_left() < REKEY_THRESHOLD)
    }

    /// Moves the send counter forward so the next frame uses `next` (or the one after,
    /// if `next` is reserved). It never moves backwards, so it cannot cause a counter to
    /// be reused; meant for tests of counter exhaustion. Without a session it does
    /// nothing.
    pub fn advance_tx_counter(&mut self, next: u32) {
        if let Some(tx) = &mut self.tx {
            tx.next = tx.next.max(u64::from(next));
        }
    }

    /// The frame counters.
    pub fn stats(&self) -> ChannelStats {
        self.stats
    }

    /// Seals the plain PPRZ v2 frame `buf[..frame_len]` in place for the wire and returns
    /// the length of the frame to write.
    ///
    /// `buf` is the frame's whole buffer: at least `frame_len +` [`OVERHEAD`] bytes. The
    /// message's fields move right by 5 bytes, `LEN` and the checksum are recomputed.
    ///
    /// * A message on the policy's plaintext list (and the beacon while there is no
    ///   session) goes in plaintext: `0xAA` inserted, one byte longer.
    /// * Otherwise it is encrypted under the session with the next counter
    ///   (strictly increasing, skipping the reserved value): 21 bytes longer.
    ///
    /// Call it when the frame is taken for the wire, so counters follow the order on
    /// the wire. On error the frame must not be sent (its bytes are unspecified); every
    /// outcome is counted.
    ///
    /// # Errors
    /// See [`SealError`].
    pub fn seal_in_place(&mut self, buf: &mut [u8], frame_len: usize) -> Result<Sealed, SealError> {
        let result = self.seal(buf, frame_len);
        match &result {
            Ok(Sealed {
                protection: Protection::Plaintext,
                ..
            }) => self.stats.sent_plaintext = self.stats.sent_plaintext.wrapping_add(1),
            Ok(_) => self.stats.encrypted = self.stats.encrypted.wrapping_add(1),
            Err(e) => self.stats.count_seal_error(*e),
        }
        result
    }

    fn seal(&mut self, buf: &mut [u8], frame_len: usize) -> Result<Sealed, SealError> {
        let frame = buf.get(..frame_len).ok_or(SealError::NotAFrame)?;
        let (cc, id) = match frame {
            [STX, len, _src, _dst, cc, id, ..]
                if usize::from(*len) == frame_len && frame_len >= PLAIN_FRAME_MIN_LEN =>
            {
                (*cc, *id)
            }
            _ => return Err(SealError::NotAFrame),
        };
        // DATA of the plain frame: src, dst, comp<<4|class, id, fields.
        let data_end = frame_len - 2;
        let plaintext = Policy::listed(self.policy.tx_plaintext, cc, id)
            || (self.tx.is_none() && self.policy.beacon.is_some_and(|b| b.matches(cc, id)));
        if plaintext {
            let len = frame_len + PLAINTEXT_OVERHEAD;
            if len > MAX_FRAME_LEN {
                return Err(SealError::TooLong);
            }
            let out = buf.get_mut(..len).ok_or(SealError::BufferTooSmall)?;
            // In range: data_end + 1 == len - 2.
            out.copy_within(2..data_end, 3);
            if let Some(b) = out.get_mut(2) {
                *b = PLAINTEXT;
            }
            finish_pprz(out);
            return Ok(Sealed {
                len,
                protection: Protection::Plaintext,
            });
        }
        let tx = self.tx.as_mut().ok_or(SealError::NoSession)?;
        let fields_len = frame_len - PLAIN_FRAME_MIN_LEN;
        if fields_len > MAX_FIELDS_LEN {
            return Err(SealError::TooLong);
        }
        let len = frame_len + OVERHEAD;
        let out = buf.get_mut(..len).ok_or(SealError::BufferTooSmall)?;
        let counter = tx.take().ok_or(SealError::CounterExhausted)?;
        // 99 LEN | 55 ctr(4) | src dst | cc id fields | tag(16) | CK
        //        ^2           ^7        ^9             ^9+2+fields_len
        const SRC_AT: usize = 2 + field::encrypted::SOURCE;
        const CT_AT: usize = 2 + field::encrypted::CIPHERTEXT;
        // In range: SRC_AT + (data_end - 2) == len - 18.
        out.copy_within(2..data_end, SRC_AT);
        let ct_end = CT_AT + 2 + fields_len;
        let nonce = tx.key.nonce(counter);
        let (head, rest) = out
            .split_at_mut_checked(CT_AT)
            .ok_or(SealError::BufferTooSmall)?;
        let (ct, rest) = rest
            .split_at_mut_checked(ct_end - CT_AT)
            .ok_or(SealError::BufferTooSmall)?;
        let tag_out = rest.get_mut(..TAG_LEN).ok_or(SealError::BufferTooSmall)?;
        let aad = head.get(SRC_AT..CT_AT).unwrap_or_default();
        let tag = tx
            .key
            .encrypt(&nonce, aad, ct)
            .ok_or(SealError::BufferTooSmall)?;
        tag_out.copy_from_slice(&tag);
        if let Some([c, n0, n1, n2, n3]) = head.get_mut(2..3 + COUNTER_LEN) {
            *c = ENCRYPTED;
            [*n0, *n1, *n2, *n3] = counter.to_be_bytes();
        }
        finish_pprz(out);
        Ok(Sealed {
            len,
            protection: Protection::Encrypted { counter },
        })
    }

    /// Opens the `DATA` of a received PPRZ frame (checksum already verified by the
    /// decoder): verifies and decrypts an encrypted frame, or checks a plaintext one
    /// against the whitelist, and writes the plain PPRZ v2 frame into `out` (at most
    /// [`MAX_FRAME_LEN`] bytes).
    ///
    /// Checks, in order, each failure counted and nothing else changed: layout,
    /// whitelist (plaintext), addresses, session, counter above the last accepted one,
    /// tag. The counter is updated only once the tag has verified.
    ///
    /// # Errors
    /// See [`Reject`].
    pub fn open<'o>(&mut self, data: &[u8], out: &'o mut [u8]) -> Result<Opened<'o>, Reject> {
        match self.open_inner(data, out) {
            Ok((len, protection)) => {
                match protection {
                    Protection::Encrypted { .. } => {
                        self.stats.decrypted = self.stats.decrypted.wrapping_add(1);
                    }
                    Protection::Plaintext => {
                        self.stats.received_plaintext =
                            self.stats.received_plaintext.wrapping_add(1);
                    }
                }
                let frame = out.get(..len).unwrap_or_default();
                Ok(Opened { frame, protection })
            }
            Err(reason) => {
                self.stats.count_reject(reason);
                Err(reason)
            }
        }
    }

    fn open_inner(&mut self, data: &[u8], out: &mut [u8]) -> Result<(usize, Protection), Reject> {
        if data.len() > MAX_DATA_LEN {
            return Err(Reject::Malformed);
        }
        match data.first() {
            Some(&ENCRYPTED) => self.open_encrypted(data, out),
            Some(&PLAINTEXT) => self.open_plaintext(data, out),
            Some(_) => Err(Reject::NotSecure),
            None => Err(Reject::Malformed),
        }
    }

    fn open_plaintext(&self, data: &[u8], out: &mut [u8]) -> Result<(usize, Protection), Reject> {
        use field::plaintext as f;
        let (src, dst, cc, id) = match data {
            [_, src, dst, cc, id, ..] => (*src, *dst, *cc, *id),
            _ => return Err(Reject::Malformed),
        };
        if !Policy::listed(self.policy.rx_plaintext, cc, id) {
            return Err(Reject::PlaintextNotAllowed);
        }
        if !self.policy.address_ok(src, dst) {
            return Err(Reject::WrongAddress);
        }
        let inner = data.get(f::SOURCE..).unwrap_or_default();
        let len = inner.len() + 4;
        let frame = out.get_mut(..len).ok_or(Reject::BufferTooSmall)?;
        frame
            .get_mut(2..2 + inner.len())
            .ok_or(Reject::BufferTooSmall)?
            .copy_from_slice(inner);
        if let Some(s) = frame.first_mut() {
            *s = STX;
        }
        finish_pprz(frame);
        Ok((len, Protection::Plaintext))
    }

    fn open_encrypted(
        &mut self,
        data: &[u8],
        out: &mut [u8],
    ) -> Result<(usize, Protection), Reject> {
        use field::encrypted as f;
        if data.len() < MIN_ENCRYPTED_DATA_LEN {
            return Err(Reject::Malformed);
        }
        let (body, tag) = data
            .split_last_chunk::<TAG_LEN>()
            .ok_or(Reject::Malformed)?;
        let (counter, src, dst) = match body {
            [_, c0, c1, c2, c3, src, dst, ..] => {
                (u32::from_be_bytes([*c0, *c1, *c2, *c3]), *src, *dst)
            }
            _ => return Err(Reject::Malformed),
        };
        let ct = body.get(f::CIPHERTEXT..).ok_or(Reject::Malformed)?;
        let aad = body.get(f::AAD).ok_or(Reject::Malformed)?;
        if !self.policy.address_ok(src, dst) {
            return Err(Reject::WrongAddress);
        }
        let rx = self.rx.as_mut().ok_or(Reject::NoSession)?;
        if counter <= rx.last {
            return Err(Reject::Replayed);
        }
        // 99 LEN src dst | cc id fields | CK
        let len = ct.len() + 6;
        let frame = out.get_mut(..len).ok_or(Reject::BufferTooSmall)?;
        let (head, rest) = frame
            .split_at_mut_checked(4)
            .ok_or(Reject::BufferTooSmall)?;
        let plain = rest.get_mut(..ct.len()).ok_or(Reject::BufferTooSmall)?;
        if !rx.key.decrypt(&rx.key.nonce(counter), aad, ct, plain, tag) {
            return Err(Reject::BadTag);
        }
        rx.last = counter;
        head.copy_from_slice(&[STX, 0, src, dst]);
        finish_pprz(frame);
        Ok((len, Protection::Encrypted { counter }))
    }
}

/// Whether the two byte strings are equal, in time that depends only on their lengths.
pub(crate) fn ct_eq(a: &[u8], b: &[u8]) -> bool {
    bool::from(a.ct_eq(b))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn keys(seed: u8) -> SessionKeys {
        SessionKeys::new(
            DirectionKey::new([seed; 32], [seed.wrapping_add(1); 12]),
            DirectionKey::new([seed.wrapping_add(2); 32], [seed.wrapping_add(3); 12]),
        )
    }

    fn pair() -> (SecureChannel, SecureChannel) {
        let mut air = SecureChannel::new(Policy::aircraft(7));
        let mut ground = SecureChannel::new(Policy::ground(7));
        air.install(keys(1));
        ground.install(SessionKeys::new(
            DirectionKey::new([3; 32], [4; 12]),
            DirectionKey::new([1; 32], [2; 12]),
        ));
        (air, ground)
    }

    /// PONG from 7 to the ground, no fields, in a buffer with room for the overhead.
    fn pong() -> ([u8; 64], usize) {
        let mut buf = [0u8; 64];
        buf[..8].copy_from_slice(&[STX, 8, 7, 0, 1, 3, 0, 0]);
        finish_pprz(&mut buf[..8]);
        (buf, 8)
    }

    #[test]
    fn seal_open_round_trip() {
        let (mut air, mut ground) = pair();
        let (mut buf, n) = pong();
        let plain = buf[..n].to_vec();
        let sealed = air.seal_in_place(&mut buf, n).unwrap();
        assert_eq!(sealed.len, n + OVERHEAD);
        assert_eq!(sealed.protection, Protection::Encrypted { counter: 1 });
        let wire = &buf[..sealed.len];
        assert_eq!(wire[2], ENCRYPTED);
        let mut out = [0u8; MAX_FRAME_LEN];
        let opened = ground.open(&wire[2..wire.len() - 2], &mut out).unwrap();
        assert_eq!(opened.frame(), &plain[..]);
        assert!(opened.is(MsgId::new(1, 3)));
        assert_eq!(ground.stats().decrypted, 1);
        assert_eq!(ground.last_rx_counter(), 1);
    }

    #[test]
    fn counters_skip_the_reserved_value_and_stop() {
        let (mut air, _) = pair();
        // Salt of the aircraft's tx direction: [2; 12] -> reserved 0x02020202.
        let reserved = 0x0202_0202;
        air.advance_tx_counter(reserved - 1);
        let left = air.counter_space_left();
        assert_eq!(left, u32::MAX - (reserved - 1) + 1 - 1);
        let mut got = vec![];
        for _ in 0..2 {
            let (mut buf, n) = pong();
            match air.seal_in_place(&mut buf, n).unwrap().protection {
                Protection::Encrypted { counter } => got.push(counter),
                Protection::Plaintext => unreachable!(),
            }
        }
        assert_eq!(got, [reserved - 1, reserved + 1]);
        assert_eq!(air.counter_space_left(), left - 2);
        air.advance_tx_counter(u32::MAX);
        assert_eq!(air.counter_space_left(), 1);
        let (mut buf, n) = pong();
        assert!(air.seal_in_place(&mut buf, n).is_ok());
        assert_eq!(air.counter_space_left(), 0);
        let (mut buf, n) = pong();
        assert_eq!(
            air.seal_in_place(&mut buf, n),
            Err(SealError::CounterExhausted)
        );
        assert_eq!(air.stats().counter_exhausted, 1);
        // Never backwards.
        air.advance_tx_counter(5);
        assert_eq!(air.counter_space_left(), 0);
        assert!(air.needs_rekey());
    }

    #[test]
    fn no_session_sends_only_plaintext() {
        let mut air = SecureChannel::new(Policy::aircraft(7));
        let (mut buf, n) = pong();
        assert_eq!(air.seal_in_place(&mut buf, n), Err(SealError::NoSession));
        // KEY_EXCHANGE_UAV goes in plaintext.
        let mut buf = [0u8; 16];
        buf[..9].copy_from_slice(&[STX, 9, 7, 0, 1, 239, 1, 0, 0]);
        finish_pprz(&mut buf[..9]);
        let s = air.seal_in_place(&mut buf, 9).unwrap();
        assert_eq!(s.len, 10);
        assert_eq!(&buf[..8], &[STX, 10, PLAINTEXT, 7, 0, 1, 239, 1]);
        // With a beacon: ALIVE in plaintext until a session exists.
        let mut air = SecureChannel::new(Policy::aircraft(7).with_beacon(Some(MsgId::new(1, 2))));
        let mut buf = [0u8; 40];
        buf[..8].copy_from_slice(&[STX, 8, 7, 0, 1, 2, 0, 0]);
        finish_pprz(&mut buf[..8]);
        let frame = buf;
        assert_eq!(
            air.seal_in_place(&mut buf, 8).unwrap().protection,
            Protection::Plaintext
        );
        air.install(keys(1));
        let mut buf = frame;
        assert!(matches!(
            air.seal_in_place(&mut buf, 8).unwrap().protection,
            Protection::Encrypted { .. }
        ));
        let st = air.stats();
        assert_eq!(
            (st.no_session_tx, st.sent_plaintext, st.encrypted),
            (0, 1, 1)
        );
    }

    #[test]
    fn seal_errors() {
        let (mut air, _) = pair();
        let (mut buf, n) = pong();
        assert_eq!(
            air.seal_in_place(&mut buf[..n + 20], n),
            Err(SealError::BufferTooSmall)
        );
        assert_eq!(air.seal_in_place(&mut buf, 9), Err(SealError::NotAFrame));
        assert_eq!(air.seal_in_place(&mut buf, 100), Err(SealError::NotAFrame));
        assert_eq!(air.seal_in_place(&mut [], 0), Err(SealError::NotAFrame));
        let mut big = [0u8; 300];
        big[..2].copy_from_slice(&[STX, 235]);
        assert_eq!(air.seal_in_place(&mut big, 235), Err(SealError::TooLong));
        big[1] = 234;
        assert!(air.seal_in_place(&mut big, 234).is_ok());
        assert_eq!(air.stats().seal_errors, 5);
    }

    #[test]
    fn open_rejections_are_counted() {
        let (mut air, mut ground) = pair();
        let mut out = [0u8; MAX_FRAME_LEN];
        assert_eq!(ground.open(&[], &mut out), Err(Reject::Malformed));
        assert_eq!(ground.open(&[0x55; 24], &mut out), Err(Reject::Malformed));
        assert_eq!(
            ground.open(&[0xAA, 7, 0, 1], &mut out),
            Err(Reject::Malformed)
        );
        assert_eq!(ground.open(&[7, 0, 1, 3], &mut out), Err(Reject::NotSecure));
        assert_eq!(
            ground.open(&[0xAA, 7, 0, 1, 3], &mut out),
            Err(Reject::PlaintextNotAllowed)
        );
        assert_eq!(
            ground.open(&[0xAA, 8, 0, 1, 239, 1, 0], &mut out),
            Err(Reject::WrongAddress)
        );
        let (mut buf, n) = pong();
        let s = air.seal_in_place(&mut buf, n).unwrap();
        let data = &buf[2..s.len - 2];
        assert_eq!(
            ground.open(data, &mut out[..7]),
            Err(Reject::BufferTooSmall)
        );
        assert!(ground.open(data, &mut out).is_ok());
        assert_eq!(ground.open(data, &mut out), Err(Reject::Replayed));
        let mut fresh = SecureChannel::new(Policy::ground(7));
        assert_eq!(fresh.open(data, &mut out), Err(Reject::NoSession));
        let st = ground.stats();
        assert_eq!(st.rejected(), 7);
        assert_eq!(
            (
                st.malformed,
                st.not_secure,
                st.plaintext_not_allowed,
                st.wrong_address,
                st.replayed
            ),
            (3, 1, 1, 1, 1)
        );
    }

    extern crate std;
    use std::vec;
}
