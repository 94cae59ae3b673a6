//! The aircraft's side of the handshake (responder B), as synchronous steps for the
//! aircraft's handshake task.
//!
//! Fixes over the reference responder, all invisible on the wire:
//! * a fresh `P_AE` is accepted at any time: while waiting for a signature it replaces
//!   the pending handshake, and while a session is established the session stays in
//!   force until the new handshake's signature verifies (the channel's keys change
//!   only on [`ResponderEvent::Established`]);
//! * the work a `P_AE` costs (two X25519, one Ed25519 signature) is rate-limited by the
//!   caller's monotonic clock: at most one per [`Responder::min_interval_ms`]
//!   (1000 ms by default), refusals counted; a repeated `P_AE` of the pending handshake
//!   is answered from a cache, without new work, at most twice per interval (so a
//!   replayed message 1 cannot make the aircraft flood the radio, and the ground's
//!   once-a-second repeat is answered despite clock jitter);
//! * at most one Ed25519 verification per pending handshake: a `SIG` whose signature
//!   fails ends that handshake (only the holder of the pending handshake's keys can get
//!   that far, and a genuine ground station signs correctly);
//! * the ephemeral key is fresh for every handshake, from the caller's RNG;
//! * an all-zero or low-order `P_AE` (all-zero shared secret) is refused;
//! * the destination byte must be our id or broadcast, and the `ac_id` field our id or 0
//!   (Paparazzi's ground leaves it at 0).
//!
//! What it cannot do: anyone can send `P_AE` (the key exchange is anonymous until the
//! signatures), so a sustained flood of fresh `P_AE` (more than one per interval) can
//! keep a ground from completing a *new* handshake (its `P_AE` refused by the rate limit,
//! or its pending handshake replaced by a newer one). It never disturbs an established
//! session, and costs the aircraft one handshake's work per interval; jamming the radio
//! would deny service as well.

use rand_core::CryptoRng;
use zeroize::Zeroizing;

use pprz_transports::{BROADCAST_ID, GROUND_ID};

use crate::channel::ct_eq;
use crate::crypto::{x25519, x25519_public};
use crate::frame::SessionKeys;
use crate::handshake::{
    HandshakeError, HandshakeStats, KeyExchange, KeyExchangeIds, MsgType, P_AE_DATA_LEN,
    P_BE_DATA_LEN, PUBLIC_KEY_LEN, SIG_DATA_LEN, open_and_verify, session_keys, sign_and_seal,
};
use crate::keys::AircraftKeys;

/// What the caller does after a successful [`Responder::handle`].
#[derive(Debug)]
pub enum ResponderEvent {
    /// Send this `KEY_EXCHANGE_UAV` (message 2) to the ground; it goes in plaintext.
    Reply(KeyExchange),
    /// The handshake is complete: install these keys in the device's
    /// [`SecureChannel`](crate::SecureChannel) (they replace the previous session).
    Established(SessionKeys),
}

/// The responder's state, for status reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum ResponderState {
    /// No session, no handshake under way: waiting for message 1.
    WaitMsg1,
    /// Message 2 sent, waiting for the signature (message 3); no session yet.
    WaitSig,
    /// A session is established.
    Established,
    /// A session is established and a new handshake waits for its signature.
    EstablishedWaitSig,
}

/// A handshake waiting for its signature.
struct Pending {
    p_ae: [u8; PUBLIC_KEY_LEN],
    /// Message 2's data: `P_be || encrypted signature`.
    msg2: [u8; P_BE_DATA_LEN],
    /// Our keys of the new session (tx Kb/Sb, rx Ka/Sa).
    keys: SessionKeys,
}

impl Pending {
    fn p_be(&self) -> [u8; PUBLIC_KEY_LEN] {
        let mut p = [0u8; PUBLIC_KEY_LEN];
        p.copy_from_slice(&self.msg2[..PUBLIC_KEY_LEN]);
        p
    }
}

/// The aircraft's handshake state machine. Owned by the aircraft's handshake task: each
/// call is a bounded synchronous step (the most expensive, a fresh `P_AE`, is two X25519
/// and one Ed25519 signature), and none waits for anything.
pub struct Responder {
    ac_id: u8,
    keys: AircraftKeys,
    ids: KeyExchangeIds,
    min_interval_ms: u64,
    last_work_ms: Option<u64>,
    last_resend_ms: Option<u64>,
    pending: Option<Pending>,
    /// `P_AE` of the established session, to recognise late copies of its message 1.
    session_p_ae: Option<[u8; PUBLIC_KEY_LEN]>,
    last_error: Option<HandshakeError>,
    stats: HandshakeStats,
}

impl core::fmt::Debug for Responder {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Responder")
            .field("ac_id", &self.ac_id)
            .field("state", &self.state())
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl Responder {
    /// The responder of aircraft `ac_id` with its long-term keys, PPRZLINK's message ids
    /// and a rate limit of one handshake per second.
    pub fn new(ac_id: u8, keys: AircraftKeys) -> Self {
        Self {
            ac_id,
            keys,
            ids: KeyExchangeIds::PPRZLINK,
            min_interval_ms: 1000,
            last_work_ms: None,
            last_resend_ms: None,
            pending: None,
            session_p_ae: None,
            last_error: None,
            stats: HandshakeStats::default(),
        }
    }

    /// The same responder with other key-exchange message ids.
    pub fn with_ids(mut self, ids: KeyExchangeIds) -> Self {
        self.ids = ids;
        self
    }

    /// The same responder with another rate limit: at most one handshake's work per
    /// `ms` milliseconds.
    pub fn with_min_interval_ms(mut self, ms: u64) -> Self {
        self.min_interval_ms = ms;
        self
    }

    /// The rate limit: milliseconds between two handshakes' work.
    pub fn min_interval_ms(&self) -> u64 {
        self.min_interval_ms
    }

    /// The key-exchange message ids.
    pub fn ids(&self) -> &KeyExchangeIds {
        &self.ids
    }

    /// The handshake counters.
    pub fn stats(&self) -> HandshakeStats {
        self.stats
    }

    /// The last refusal, if any (for status reports).
    pub fn last_error(&self) -> Option<HandshakeError> {
        self.last_error
    }

    /// The state.
    pub fn state(&self) -> ResponderState {
        match (self.session_p_ae.is_some(), self.pending.is_some()) {
            (false, false) => ResponderState::WaitMsg1,
            (false, true) => ResponderState::WaitSig,
            (true, false) => ResponderState::Established,
            (true, true) => ResponderState::EstablishedWaitSig,
        }
    }

    /// Handles a key-exchange message received at `now_ms` (any monotonic millisecond
    /// clock); `rng` gives the ephemeral key of a new handshake. Every refusal is
    /// counted and changes nothing.
    ///
    /// # Errors
    /// See [`HandshakeError`].
    pub fn handle<R: CryptoRng + ?Sized>(
        &mut self,
        msg: &KeyExchange,
        now_ms: u64,
        rng: &mut R,
    ) -> Result<ResponderEvent, HandshakeError> {
        let result = self.step(msg, now_ms, rng);
        match &result {
            Ok(ResponderEvent::Established(_)) => {
                self.stats.completed = self.stats.completed.wrapping_add(1);
            }
            Ok(ResponderEvent::Reply(_)) => {}
            Err(e) => {
                self.stats.count(*e);
                self.last_error = Some(*e);
            }
        }
        result
    }

    fn step<R: CryptoRng + ?Sized>(
        &mut self,
        msg: &KeyExchange,
        now_ms: u64,
        rng: &mut R,
    ) -> Result<ResponderEvent, HandshakeError> {
        if msg.msg != self.ids.gcs {
            return Err(HandshakeError::Unexpected);
        }
        let dest_ok = msg.destination == self.ac_id || msg.destination == BROADCAST_ID;
        let ac_ok = matches!(msg.ac_id, Some(id) if id == self.ac_id || id == 0);
        if !dest_ok || !ac_ok {
            return Err(HandshakeError::WrongAddress);
        }
        match msg.msg_type {
            MsgType::PAe => self.on_p_ae(msg.data(), now_ms, rng),
            MsgType::Sig => self.on_sig(msg.data()),
            MsgType::PBe => Err(HandshakeError::Unexpected),
        }
    }

    fn elapsed(last: Option<u64>, now_ms: u64, interval: u64) -> bool {
        last.is_none_or(|t| now_ms.saturating_sub(t) >= interval)
    }

    fn reply(&self, data: &[u8]) -> ResponderEvent {
        ResponderEvent::Reply(KeyExchange::new(
            (self.ac_id, GROUND_ID),
            self.ids.uav,
            None,
            MsgType::PBe,
            data,
        ))
    }

    fn on_p_ae<R: CryptoRng + ?Sized>(
        &mut self,
        data: &[u8],
        now_ms: u64,
        rng: &mut R,
    ) -> Result<ResponderEvent, HandshakeError> {
        let p_ae: [u8; P_AE_DATA_LEN] = data.try_into().map_err(|_| HandshakeError::Malformed)?;
        if let Some(p) = &self.pending
            && ct_eq(&p.p_ae, &p_ae)
        {
            // Message 2 was lost (the ground repeats message 1): the same answer again,
            // without new work, rate-limited like the work.
            if !Self::elapsed(self.last_resend_ms, now_ms, self.min_interval_ms / 2) {
                return Err(HandshakeError::RateLimited);
            }
            self.last_resend_ms = Some(now_ms);
            self.stats.resent = self.stats.resent.wrapping_add(1);
            let msg2 = p.msg2;
            return Ok(self.reply(&msg2));
        }
        if self.session_p_ae.is_some_and(|s| ct_eq(&s, &p_ae)) {
            return Err(HandshakeError::Duplicate);
        }
        if ct_eq(&p_ae, &[0u8; PUBLIC_KEY_LEN]) {
            return Err(HandshakeError::BadKey);
        }
        if !Self::elapsed(self.last_work_ms, now_ms, self.min_interval_ms) {
            return Err(HandshakeError::RateLimited);
        }
        // The slot is used whatever the outcome of the work.
        self.last_work_ms = Some(now_ms);
        let mut b = Zeroizing::new([0u8; 32]);
        rng.fill_bytes(b.as_mut_slice());
        let p_be = x25519_public(&b);
        let z = x25519(&b, &p_ae);
        drop(b);
        let (a_to_b, b_to_a) = session_keys(&z).ok_or(HandshakeError::BadKey)?;
        drop(z);
        let sealed =
            sign_and_seal(&self.keys.0.own, &p_be, &p_ae, &b_to_a).ok_or(HandshakeError::BadKey)?;
        let mut msg2 = [0u8; P_BE_DATA_LEN];
        msg2[..PUBLIC_KEY_LEN].copy_from_slice(&p_be);
        msg2[PUBLIC_KEY_LEN..].copy_from_slice(&sealed);
        // A newer handshake replaces the pending one; the session, if any, stays.
        self.pending = Some(Pending {
            p_ae,
            msg2,
            keys: SessionKeys::new(b_to_a, a_to_b),
        });
        self.last_resend_ms = Some(now_ms);
        self.stats.started = self.stats.started.wrapping_add(1);
        Ok(self.reply(&msg2))
    }

    fn on_sig(&mut self, data: &[u8]) -> Result<ResponderEvent, HandshakeError> {
        if data.len() != SIG_DATA_LEN {
            return Err(HandshakeError::Malformed);
        }
        let pending = self.pending.as_ref().ok_or(HandshakeError::Unexpected)?;
        let p_be = pending.p_be();
        match open_and_verify(
            &self.keys.0.peer,
            &pending.p_ae,
            &p_be,
            pending.keys.rx(),
            data,
        ) {
            Ok(()) => {}
            Err(HandshakeError::BadSignature) => {
                // Only the holder of this handshake's keys gets here: end it, so a
                // signature is verified at most once per (rate-limited) handshake.
                self.pending = None;
                return Err(HandshakeError::BadSignature);
            }
            // A corrupt or forged message 3 leaves the pending handshake as it was.
            Err(e) => return Err(e),
        }
        let pending = self.pending.take().ok_or(HandshakeError::Unexpected)?;
        self.session_p_ae = Some(pending.p_ae);
        Ok(ResponderEvent::Established(pending.keys))
    }
}
