//! The ground's side of the handshake (initiator A): a state machine driven by the ground
//! tool's loop.
//!
//! * [`Initiator::poll`] says what to send now: message 1 (first, then again every
//!   [`retry_ms`](Initiator::with_retry_ms) until message 2 arrives, like Paparazzi's
//!   ground), message 3 again while the aircraft has not been heard under the new
//!   session (a lost message 3), and a new handshake when message 3 was sent
//!   [`MSG3_RESENDS`] times in vain or when the aircraft has been silent for
//!   [`silence_ms`](Initiator::with_silence_ms) (a rebooted aircraft lost its session).
//! * [`Initiator::handle`] takes message 2 and gives the session keys with message 3.
//!   A copy of that message 2 gets message 3 again, within the same [`MSG3_RESENDS`]
//!   and only while the aircraft is unconfirmed: a replayed message 2 cannot make the
//!   ground send message 3 again and again. Further copies are refused as
//!   [`HandshakeError::Duplicate`], and another message 2 once the session is up as
//!   [`HandshakeError::Unexpected`] (forged or stale); both counted.
//! * [`Initiator::confirm`] is called for every frame the channel decrypted: the
//!   aircraft uses the session.
//!
//! The ground considers the session up once it sends message 3 (as Paparazzi's does):
//! install the keys at once. When [`SecureChannel::needs_rekey`](crate::SecureChannel::needs_rekey)
//! is true, call [`Initiator::restart`].

use rand_core::CryptoRng;
use zeroize::Zeroizing;

use pprz_transports::{BROADCAST_ID, GROUND_ID};

use crate::channel::ct_eq;
use crate::crypto::{x25519, x25519_public};
use crate::frame::SessionKeys;
use crate::handshake::{
    HandshakeError, HandshakeStats, KeyExchange, KeyExchangeIds, MsgType, P_BE_DATA_LEN,
    PUBLIC_KEY_LEN, SIG_DATA_LEN, open_and_verify, session_keys, sign_and_seal,
};
use crate::keys::GroundKeys;

/// How many times message 3 is sent again (after a timeout, or for a copy of message 2)
/// before a new handshake starts.
pub const MSG3_RESENDS: u8 = 3;

/// What the caller does after a successful [`Initiator::handle`].
#[derive(Debug)]
pub enum InitiatorEvent {
    /// Message 2 verified: install `keys` in the channel and send `reply` (message 3).
    Established {
        /// This end's keys of the new session (tx Ka/Sa, rx Kb/Sb).
        keys: SessionKeys,
        /// `KEY_EXCHANGE_GCS` SIG, to send in plaintext.
        reply: KeyExchange,
    },
    /// A copy of the message 2 already accepted: send message 3 again (the aircraft
    /// answered a repeated message 1, so it may have missed message 3). Only while the
    /// aircraft has not been heard under the session, and at most [`MSG3_RESENDS`]
    /// times per handshake, counting the resends of [`Initiator::poll`]; further copies
    /// are refused as [`HandshakeError::Duplicate`].
    Resend(KeyExchange),
}

/// The initiator's state, for status reports.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum InitiatorState {
    /// Nothing sent yet ([`Initiator::poll`] starts a handshake).
    Idle,
    /// Message 1 sent, waiting for message 2.
    WaitMsg2,
    /// Message 3 sent and the session installed; the aircraft not heard under it yet.
    WaitConfirm,
    /// The aircraft sends under the session.
    Confirmed,
}

enum State {
    Idle,
    WaitMsg2 {
        secret: Zeroizing<[u8; 32]>,
        p_ae: [u8; PUBLIC_KEY_LEN],
        sent_ms: u64,
    },
    Up {
        msg2: [u8; P_BE_DATA_LEN],
        msg3: [u8; SIG_DATA_LEN],
        sent_ms: u64,
        resends: u8,
        confirmed: bool,
    },
}

/// The ground's handshake state machine for one aircraft.
pub struct Initiator {
    ac_id: u8,
    keys: GroundKeys,
    ids: KeyExchangeIds,
    retry_ms: u64,
    silence_ms: u64,
    state: State,
    stats: HandshakeStats,
}

impl core::fmt::Debug for Initiator {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.debug_struct("Initiator")
            .field("ac_id", &self.ac_id)
            .field("state", &self.state())
            .field("stats", &self.stats)
            .finish_non_exhaustive()
    }
}

impl Initiator {
    /// The initiator for aircraft `ac_id` with the ground's long-term keys: PPRZLINK's
    /// message ids, message 1 repeated every second, a new handshake after 5 s without
    /// an authenticated frame from the aircraft.
    pub fn new(ac_id: u8, keys: GroundKeys) -> Self {
        Self {
            ac_id,
            keys,
            ids: KeyExchangeIds::PPRZLINK,
            retry_ms: 1000,
            silence_ms: 5000,
            state: State::Idle,
            stats: HandshakeStats::default(),
        }
    }

    /// The same initiator with other key-exchange message ids.
    pub fn with_ids(mut self, ids: KeyExchangeIds) -> Self {
        self.ids = ids;
        self
    }

    /// The same initiator repeating messages 1 and 3 every `ms` milliseconds.
    pub fn with_retry_ms(mut self, ms: u64) -> Self {
        self.retry_ms = ms;
        self
    }

    /// The same initiator starting a new handshake after `ms` milliseconds without an
    /// authenticated frame from the aircraft.
    pub fn with_silence_ms(mut self, ms: u64) -> Self {
        self.silence_ms = ms;
        self
    }

    /// The aircraft id.
    pub fn ac_id(&self) -> u8 {
        self.ac_id
    }

    /// The key-exchange message ids.
    pub fn ids(&self) -> &KeyExchangeIds {
        &self.ids
    }

    /// The handshake counters.
    pub fn stats(&self) -> HandshakeStats {
        self.stats
    }

    /// The state.
    pub fn state(&self) -> InitiatorState {
        match &self.state {
            State::Idle => InitiatorState::Idle,
            State::WaitMsg2 { .. } => InitiatorState::WaitMsg2,
            State::Up {
                confirmed: false, ..
            } => InitiatorState::WaitConfirm,
            State::Up {
                confirmed: true, ..
            } => InitiatorState::Confirmed,
        }
    }

    /// Forgets the handshake: the next [`poll`](Self::poll) starts a new one (with a new
    /// ephemeral key). Keep the channel's session until the new one is installed.
    pub fn restart(&mut self) {
        self.state = State::Idle;
    }

    /// The aircraft sent a frame that the current session decrypted, at `now_ms`.
    pub fn confirm(&mut self, now_ms: u64) {
        if let State::Up {
            confirmed, sent_ms, ..
        } = &mut self.state
        {
            *confirmed = true;
            *sent_ms = now_ms;
        }
    }

    fn gcs(&self, msg_type: MsgType, data: &[u8]) -> KeyExchange {
        KeyExchange::new(
            (GROUND_ID, self.ac_id),
            self.ids.gcs,
            Some(self.ac_id),
            msg_type,
            data,
        )
    }

    fn start<R: CryptoRng + ?Sized>(&mut self, now_ms: u64, rng: &mut R) -> KeyExchange {
        let mut secret = Zeroizing::new([0u8; 32]);
        rng.fill_bytes(secret.as_mut_slice());
        let p_ae = x25519_public(&secret);
        self.state = State::WaitMsg2 {
            secret,
            p_ae,
            sent_ms: now_ms,
        };
        self.stats.started = self.stats.started.wrapping_add(1);
        self.gcs(MsgType::PAe, &p_ae)
    }

    /// What to send at `now_ms` (any monotonic millisecond clock), if anything: call it
    /// periodically (every 100 ms, say). `rng` gives the ephemeral key of a new
    /// handshake.
    pub fn poll<R: CryptoRng + ?Sized>(&mut self, now_ms: u64, rng: &mut R) -> Option<KeyExchange> {
        let due = |sent: u64, every: u64| now_ms.saturating_sub(sent) >= every;
        match &mut self.state {
            State::Idle => Some(self.start(now_ms, rng)),
            State::WaitMsg2 { p_ae, sent_ms, .. } => {
                if !due(*sent_ms, self.retry_ms) {
                    return None;
                }
                *sent_ms = now_ms;
                let p_ae = *p_ae;
                self.stats.resent = self.stats.resent.wrapping_add(1);
                Some(self.gcs(MsgType::PAe, &p_ae))
            }
            State::Up {
                confirmed: true,
                sent_ms,
                ..
            } => due(*sent_ms, self.silence_ms).then(|| self.start(now_ms, rng)),
            State::Up {
                confirmed: false,
                msg3,
                sent_ms,
                resends,
                ..
            } => {
                if !due(*sent_ms, self.retry_ms) {
                    return None;
                }
                if *resends >= MSG3_RESENDS {
                    return Some(self.start(now_ms, rng));
                }
                *resends += 1;
                *sent_ms = now_ms;
                let msg3 = *msg3;
                self.stats.resent = self.stats.resent.wrapping_add(1);
                Some(self.gcs(MsgType::Sig, &msg3))
            }
        }
    }

    /// Handles a key-exchange message from the aircraft received at `now_ms`.
    ///
    /// # Errors
    /// See [`HandshakeError`]; every refusal is counted and changes nothing (a forged
    /// message 2 does not end the wait for the real one).
    pub fn handle(
        &mut self,
        msg: &KeyExchange,
        now_ms: u64,
    ) -> Result<InitiatorEvent, HandshakeError> {
        let result = self.step(msg, now_ms);
        match &result {
            Ok(InitiatorEvent::Established { .. }) => {
                self.stats.completed = self.stats.completed.wrapping_add(1);
            }
            Ok(InitiatorEvent::Resend(_)) => {
                self.stats.resent = self.stats.resent.wrapping_add(1);
            }
            Err(e) => self.stats.count(*e),
        }
        result
    }

    /// Message 2 after the handshake (state `Up`). A copy of the accepted one gets
    /// message 3 again from the same budget as the clock's resends, and only while the
    /// aircraft is not heard under the session; beyond that it is a replay. Any other
    /// message 2 is forged or stale.
    fn step_up(
        &mut self,
        data: &[u8; P_BE_DATA_LEN],
        now_ms: u64,
    ) -> Result<InitiatorEvent, HandshakeError> {
        let State::Up {
            msg2,
            msg3,
            sent_ms,
            resends,
            confirmed,
        } = &mut self.state
        else {
            return Err(HandshakeError::Unexpected);
        };
        if !ct_eq(msg2, data) {
            return Err(HandshakeError::Unexpected);
        }
        if *confirmed || *resends >= MSG3_RESENDS {
            return Err(HandshakeError::Duplicate);
        }
        *resends += 1;
        *sent_ms = now_ms;
        let msg3 = *msg3;
        Ok(InitiatorEvent::Resend(self.gcs(MsgType::Sig, &msg3)))
    }

    fn step(&mut self, msg: &KeyExchange, now_ms: u64) -> Result<InitiatorEvent, HandshakeError> {
        if msg.msg != self.ids.uav {
            return Err(HandshakeError::Unexpected);
        }
        if msg.source != self.ac_id
            || (msg.destination != GROUND_ID && msg.destination != BROADCAST_ID)
        {
            return Err(HandshakeError::WrongAddress);
        }
        if msg.msg_type != MsgType::PBe {
            return Err(HandshakeError::Unexpected);
        }
        let data: &[u8; P_BE_DATA_LEN] = msg
            .data()
            .try_into()
            .map_err(|_| HandshakeError::Malformed)?;
        if matches!(self.state, State::Up { .. }) {
            return self.step_up(data, now_ms);
        }
        let State::WaitMsg2 { secret, p_ae, .. } = &self.state else {
            return Err(HandshakeError::Unexpected);
        };
        let p_ae = *p_ae;
        let (p_be_bytes, sealed) = data.split_at(PUBLIC_KEY_LEN);
        let mut p_be = [0u8; PUBLIC_KEY_LEN];
        p_be.copy_from_slice(p_be_bytes);
        let z = x25519(secret, &p_be);
        let (a_to_b, b_to_a) = session_keys(&z).ok_or(HandshakeError::BadKey)?;
        drop(z);
        open_and_verify(&self.keys.0.peer, &p_be, &p_ae, &b_to_a, sealed)?;
        let msg3 =
            sign_and_seal(&self.keys.0.own, &p_ae, &p_be, &a_to_b).ok_or(HandshakeError::BadKey)?;
        self.state = State::Up {
            msg2: *data,
            msg3,
            sent_ms: now_ms,
            resends: 0,
            confirmed: false,
        };
        Ok(InitiatorEvent::Established {
            keys: SessionKeys::new(a_to_b, b_to_a),
            reply: self.gcs(MsgType::Sig, &msg3),
        })
    }
}
