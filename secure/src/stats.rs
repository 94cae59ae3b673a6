//! The statistics of a secure endpoint, and Paparazzi's `SECURE_LINK_STATUS` report.

use crate::channel::{ChannelStats, SecureChannel};
use crate::handshake::{HandshakeError, HandshakeStats};
use crate::responder::ResponderState;

/// Everything counted about one secure endpoint (a device's channel and the handshake of
/// its end): what the link report of the aircraft, or the ground's display, shows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SecureStats {
    /// Handshakes started, completed, refused by reason.
    pub handshake: HandshakeStats,
    /// Frames sealed and opened, rejected by reason.
    pub channel: ChannelStats,
    /// Frames the current session can still send (0 without a session).
    pub counter_space_left: u32,
    /// Whether a session is installed.
    pub session: bool,
}

impl SecureStats {
    /// The statistics of `channel` and of the handshake whose counters are `handshake`
    /// (from [`Responder::stats`](crate::Responder::stats) or
    /// [`Initiator::stats`](crate::Initiator::stats)).
    pub fn new(handshake: HandshakeStats, channel: &SecureChannel) -> Self {
        Self {
            handshake,
            channel: channel.stats(),
            counter_space_left: channel.counter_space_left(),
            session: channel.has_session(),
        }
    }
}

/// The fields of Paparazzi's `SECURE_LINK_STATUS` (telemetry id 255 in the reference
/// set): `sts_stage u8, sts_error u8, counter_err u32, decrypt_err u32, encrypt_err u32`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkStatus {
    /// `INIT` 0, `WAIT_MSG1` 1, `WAIT_MSG2` 2, `WAIT_MSG3` 3, `CRYPTO_OK` 4.
    pub stage: u8,
    /// The reference's error codes: `NONE` 0, `MSG1_ENCRYPT` 2 (a bad `P_AE`),
    /// `MSG3_DECRYPT` 4, `MSG3_SIGNVERIFY` 5, `UNEXPECTED_STAGE` 11, `UNEXPECTED_MSG` 12.
    /// Rate-limited and duplicate messages are not errors of the protocol: 0.
    pub error: u8,
    /// Frames rejected for their counter (replays).
    pub counter_err: u32,
    /// Frames whose tag did not verify.
    pub decrypt_err: u32,
    /// Frames not sent: counter exhausted or not sealable.
    pub encrypt_err: u32,
}

impl LinkStatus {
    /// Length of the message's fields.
    pub const FIELDS_LEN: usize = 14;

    /// The aircraft's status from its responder's state and last refusal and its
    /// channel's counters.
    pub fn aircraft(
        state: ResponderState,
        last_error: Option<HandshakeError>,
        channel: &ChannelStats,
    ) -> Self {
        let stage = match state {
            ResponderState::WaitMsg1 => 1,
            ResponderState::WaitSig => 3,
            ResponderState::Established | ResponderState::EstablishedWaitSig => 4,
        };
        let error = match last_error {
            None | Some(HandshakeError::RateLimited | HandshakeError::Duplicate) => 0,
            Some(HandshakeError::BadKey) => 2,
            Some(HandshakeError::BadTag) => 4,
            Some(HandshakeError::BadSignature) => 5,
            Some(HandshakeError::Unexpected) => 11,
            Some(HandshakeError::Malformed | HandshakeError::WrongAddress) => 12,
        };
        Self {
            stage,
            error,
            counter_err: channel.replayed,
            decrypt_err: channel.bad_tag,
            encrypt_err: channel.counter_exhausted.wrapping_add(channel.seal_errors),
        }
    }

    /// The message's fields, little-endian as on the wire.
    pub fn fields(&self) -> [u8; Self::FIELDS_LEN] {
        let mut f = [0u8; Self::FIELDS_LEN];
        f[0] = self.stage;
        f[1] = self.error;
        f[2..6].copy_from_slice(&self.counter_err.to_le_bytes());
        f[6..10].copy_from_slice(&self.decrypt_err.to_le_bytes());
        f[10..14].copy_from_slice(&self.encrypt_err.to_le_bytes());
        f
    }
}
