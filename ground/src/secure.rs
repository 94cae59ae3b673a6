//! The ground's end of a secure PPRZ v2 link (`pprz-monitor --secure`), built on
//! [`pprz_secure`]: a [`SecureChannel`] that accepts only the chosen aircraft, the
//! [`Initiator`] of the station-to-station handshake, and a random number generator for
//! its ephemeral keys.
//!
//! A caller's loop:
//! * [`GroundSecure::poll`] regularly (every 100 ms, say): a frame to write when the
//!   handshake has something to send (message 1, sent again every second until the
//!   aircraft answers; message 3 again; a new handshake for a re-key or a silent
//!   aircraft);
//! * [`GroundSecure::open`] for the `DATA` of every PPRZ v2 frame decoded from the
//!   aircraft: a plain frame to decode as usual, a handshake step (maybe with a frame to
//!   write), or a rejection (counted, never decoded);
//! * [`GroundSecure::seal`] for every uplink frame (PING, SETTING): encrypted, or refused
//!   before the handshake has completed;
//! * [`GroundSecure::status`] for the display.
//!
//! ```
//! use pprz_ground::secure::{GroundSecure, Incoming};
//! use pprz_secure::{KeyFile, keys::INSECURE_TEST_KEY_FILE};
//!
//! let keys = KeyFile::parse(INSECURE_TEST_KEY_FILE).unwrap().ground().unwrap();
//! let mut ground = GroundSecure::new(7, keys);
//! let msg1 = ground.poll(0).expect("message 1 at once");
//! assert_eq!(msg1[0], 0x99); // a PPRZ v2 frame, to write to the aircraft
//! assert!(ground.poll(10).is_none()); // again after a second only
//! // Before the handshake, telemetry in the clear is refused, and nothing is sent.
//! let plain = [0x99, 0x08, 0x07, 0x00, 0x01, 0x03, 0x0C, 0x2C];
//! assert!(matches!(ground.open(&plain[2..6], 20), Incoming::Rejected(_)));
//! assert!(ground.seal(&plain).is_err());
//! ```

use std::fmt;
use std::path::{Path, PathBuf};

use pprz_secure::frame::MAX_FRAME_LEN;
use pprz_secure::rand_core::{CryptoRng, OsRng, UnwrapErr};
use pprz_secure::{
    GroundKeys, HandshakeError, Initiator, InitiatorEvent, InitiatorState, KeyError, KeyExchange,
    KeyFile, KeyFileError, OVERHEAD, Policy, Reject, SealError, SecureChannel, SecureStats,
};

/// Longest key file read, in bytes (a key file is a few hundred bytes).
pub const MAX_KEY_FILE_LEN: u64 = 64 * 1024;

/// Why a ground secure session could not be set up.
#[derive(Debug)]
pub enum SecureSetupError {
    /// The key file cannot be read (or is too long, or not UTF-8).
    Read {
        /// The key file.
        path: PathBuf,
        /// What failed.
        error: std::io::Error,
    },
    /// The key file does not parse (with the line of the problem).
    Parse {
        /// The key file.
        path: PathBuf,
        /// What is wrong and where.
        error: KeyFileError,
    },
    /// The key file lacks the ground's keys, or they are invalid or inconsistent.
    Keys {
        /// The key file.
        path: PathBuf,
        /// Which key and what is wrong.
        error: KeyError,
    },
    /// The link does not use PPRZ v2 framing: the secure link is PPRZ v2 only.
    NotPprzV2,
}

impl fmt::Display for SecureSetupError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Read { path, error } => {
                write!(f, "cannot read the key file {}: {error}", path.display())
            }
            Self::Parse { path, error } => {
                write!(f, "key file {}: {error}", path.display())
            }
            Self::Keys { path, error } => write!(
                f,
                "key file {}: no usable ground keys (GCS_PRIVATE, UAV_PUBLIC): {error}",
                path.display()
            ),
            Self::NotPprzV2 => f.write_str("the secure link needs the PPRZ v2 transport"),
        }
    }
}

impl std::error::Error for SecureSetupError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Read { error, .. } => Some(error),
            Self::Parse { error, .. } => Some(error),
            Self::Keys { error, .. } => Some(error),
            Self::NotPprzV2 => None,
        }
    }
}

/// What a handshake message from the aircraft did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum HandshakeEvent {
    /// Message 2 verified: the session keys are installed, message 3 is the reply.
    Established,
    /// A copy of the message 2 already accepted: message 3 is sent again (only while
    /// the aircraft is unconfirmed, at most
    /// [`MSG3_RESENDS`](pprz_secure::initiator::MSG3_RESENDS) times per handshake;
    /// further copies are refused).
    Resend,
    /// Refused (counted): a forged, malformed, duplicate or unexpected message.
    Refused(HandshakeError),
}

/// A frame from the aircraft, once through the secure channel.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Incoming {
    /// A plain PPRZ v2 frame (decrypted and authenticated), to decode as usual.
    Plain(Vec<u8>),
    /// A key-exchange message (`KEY_EXCHANGE_UAV`), handled here: not a message to show.
    Handshake {
        /// What it did.
        event: HandshakeEvent,
        /// A whole frame to write to the aircraft (message 3), if any.
        reply: Option<Vec<u8>>,
    },
    /// Rejected by the channel (counted in [`SecureStats`]): never decode it.
    Rejected(Reject),
}

/// The secure link's state and counters, for the display.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SecureStatus {
    /// The handshake's state.
    pub state: InitiatorState,
    /// Handshake and channel counters, counter space left, whether a session exists.
    pub stats: SecureStats,
    /// Handshakes restarted because the session's counters were running out.
    pub rekeys: u32,
}

/// A short description of a handshake state.
pub fn describe_state(state: InitiatorState) -> &'static str {
    match state {
        InitiatorState::Idle => "waiting for the handshake (not started)",
        InitiatorState::WaitMsg2 => {
            "waiting for the handshake (KEY_EXCHANGE_GCS sent, no answer from the aircraft yet)"
        }
        InitiatorState::WaitConfirm => {
            "session installed, waiting for the aircraft's first encrypted frame"
        }
        InitiatorState::Confirmed => "session up",
    }
}

impl SecureStatus {
    /// The status as display lines: the state and handshakes, then the frames.
    pub fn lines(&self) -> [String; 2] {
        let h = &self.stats.handshake;
        let c = &self.stats.channel;
        let state = describe_state(self.state);
        [
            format!(
                "secure link: {state}  handshakes started {}  completed {}  refused {} (bad signature {}, bad tag {}, bad key {}, wrong address {}, unexpected {}, duplicate {}, malformed {})  resent {}  re-keys {}",
                h.started,
                h.completed,
                h.refused(),
                h.bad_signature,
                h.bad_tag,
                h.bad_key,
                h.wrong_address,
                h.unexpected,
                h.duplicate,
                h.malformed,
                h.resent,
                self.rekeys,
            ),
            format!(
                "secure frames: decrypted {}  rejected {} (bad tag {}, replayed {}, plaintext {}, not secure {}, wrong address {}, no session {}, malformed {})  encrypted {}  not sent (no session) {}  counter space left {}",
                c.decrypted,
                c.rejected(),
                c.bad_tag,
                c.replayed,
                c.plaintext_not_allowed,
                c.not_secure,
                c.wrong_address,
                c.no_session_rx,
                c.malformed,
                c.encrypted,
                c.no_session_tx,
                self.stats.counter_space_left,
            ),
        ]
    }
}

/// The ground's secure session with one aircraft.
pub struct GroundSecure {
    channel: SecureChannel,
    initiator: Initiator,
    rng: Box<dyn CryptoRng + Send>,
    /// Key-exchange messages that did not even parse (the initiator never sees them).
    malformed_kx: u32,
    /// Plaintext frames that passed the channel but are not the aircraft's key
    /// exchange (the initiator never sees them).
    unexpected_kx: u32,
    rekeys: u32,
}

impl fmt::Debug for GroundSecure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("GroundSecure")
            .field("initiator", &self.initiator)
            .field("session", &self.channel.has_session())
            .finish_non_exhaustive()
    }
}

impl GroundSecure {
    /// The session with aircraft `ac_id` with the ground's long-term keys; ephemeral
    /// keys from the operating system's generator.
    pub fn new(ac_id: u8, keys: GroundKeys) -> Self {
        Self::with_rng(ac_id, keys, UnwrapErr(OsRng))
    }

    /// The same with another random number generator (a seeded one makes tests
    /// deterministic; never use a predictable one on a real link).
    pub fn with_rng(ac_id: u8, keys: GroundKeys, rng: impl CryptoRng + Send + 'static) -> Self {
        Self::with_initiator(ac_id, Initiator::new(ac_id, keys), rng)
    }

    /// The same with an initiator configured by the caller (other retry or silence
    /// delays, other message ids); `ac_id` must be the initiator's.
    pub fn with_initiator(
        ac_id: u8,
        initiator: Initiator,
        rng: impl CryptoRng + Send + 'static,
    ) -> Self {
        Self {
            channel: SecureChannel::new(Policy::ground(ac_id)),
            initiator,
            rng: Box::new(rng),
            malformed_kx: 0,
            unexpected_kx: 0,
            rekeys: 0,
        }
    }

    /// The session with aircraft `ac_id` with the ground keys of a key file
    /// (`GCS_PRIVATE`, `UAV_PUBLIC`; `GCS_PUBLIC` checked if present).
    ///
    /// # Errors
    /// The file cannot be read, does not parse, or lacks valid ground keys.
    pub fn from_key_file(path: &Path, ac_id: u8) -> Result<Self, SecureSetupError> {
        Ok(Self::new(ac_id, ground_keys_from_file(path)?))
    }

    /// The aircraft id.
    pub fn ac_id(&self) -> u8 {
        self.initiator.ac_id()
    }

    /// Whether uplink frames can be sealed (the session keys are installed).
    pub fn has_session(&self) -> bool {
        self.channel.has_session()
    }

    /// A whole PPRZ v2 frame to write to the aircraft at `now_ms` (any monotonic
    /// millisecond clock), if the handshake has one: message 1 at first and every second
    /// until the aircraft answers, message 3 again while the aircraft is not heard under
    /// the new session, a new handshake when the aircraft has been silent or the counters
    /// run out. Call it regularly.
    pub fn poll(&mut self, now_ms: u64) -> Option<Vec<u8>> {
        if self.channel.needs_rekey()
            && matches!(
                self.initiator.state(),
                InitiatorState::Confirmed | InitiatorState::WaitConfirm
            )
        {
            self.initiator.restart();
            self.rekeys = self.rekeys.wrapping_add(1);
        }
        let kx = self.initiator.poll(now_ms, &mut *self.rng)?;
        self.kx_frame(&kx)
    }

    /// Seals a key-exchange message for the wire (in plaintext, as the policy says).
    fn kx_frame(&mut self, kx: &KeyExchange) -> Option<Vec<u8>> {
        let mut buf = [0u8; MAX_FRAME_LEN + OVERHEAD];
        let n = kx.write_frame(&mut buf)?;
        let sealed = self.channel.seal_in_place(&mut buf, n).ok()?;
        buf.get(..sealed.len).map(<[u8]>::to_vec)
    }

    /// Opens the `DATA` of a PPRZ v2 frame received at `now_ms` (`data()` of the
    /// decoder's frame). Whatever the bytes, nothing panics: a frame that fails is
    /// [`Incoming::Rejected`] and counted.
    pub fn open(&mut self, data: &[u8], now_ms: u64) -> Incoming {
        let mut out = [0u8; MAX_FRAME_LEN];
        let opened = match self.channel.open(data, &mut out) {
            Ok(opened) => opened,
            Err(reject) => return Incoming::Rejected(reject),
        };
        if opened.is_encrypted() {
            self.initiator.confirm(now_ms);
            return Incoming::Plain(opened.frame().to_vec());
        }
        // Plaintext passed the whitelist: a key exchange.
        let kx = match KeyExchange::parse(opened.data(), self.initiator.ids()) {
            Ok(Some(kx)) => kx,
            Ok(None) => {
                self.unexpected_kx = self.unexpected_kx.wrapping_add(1);
                return Incoming::Handshake {
                    event: HandshakeEvent::Refused(HandshakeError::Unexpected),
                    reply: None,
                };
            }
            Err(e) => {
                self.malformed_kx = self.malformed_kx.wrapping_add(1);
                return Incoming::Handshake {
                    event: HandshakeEvent::Refused(e),
                    reply: None,
                };
            }
        };
        match self.initiator.handle(&kx, now_ms) {
            Ok(InitiatorEvent::Established { keys, reply }) => {
                self.channel.install(keys);
                Incoming::Handshake {
                    event: HandshakeEvent::Established,
                    reply: self.kx_frame(&reply),
                }
            }
            Ok(InitiatorEvent::Resend(reply)) => Incoming::Handshake {
                event: HandshakeEvent::Resend,
                reply: self.kx_frame(&reply),
            },
            Err(e) => Incoming::Handshake {
                event: HandshakeEvent::Refused(e),
                reply: None,
            },
        }
    }

    /// Seals a plain PPRZ v2 frame for the aircraft (PING, SETTING...): encrypted under
    /// the session.
    ///
    /// # Errors
    /// [`SealError::NoSession`] before the handshake has completed, and the other
    /// [`SealError`]s (not a PPRZ v2 frame, too long for a secure frame, counter used
    /// up); every refusal is counted and nothing is to be sent.
    pub fn seal(&mut self, plain_frame: &[u8]) -> Result<Vec<u8>, SealError> {
        let mut buf = [0u8; MAX_FRAME_LEN + OVERHEAD];
        let Some(head) = buf.get_mut(..plain_frame.len()) else {
            return Err(SealError::NotAFrame);
        };
        head.copy_from_slice(plain_frame);
        let sealed = self.channel.seal_in_place(&mut buf, plain_frame.len())?;
        buf.get(..sealed.len)
            .map(<[u8]>::to_vec)
            .ok_or(SealError::BufferTooSmall)
    }

    /// The state and counters.
    pub fn status(&self) -> SecureStatus {
        let mut stats = SecureStats::new(self.initiator.stats(), &self.channel);
        stats.handshake.malformed = stats.handshake.malformed.wrapping_add(self.malformed_kx);
        stats.handshake.unexpected = stats.handshake.unexpected.wrapping_add(self.unexpected_kx);
        SecureStatus {
            state: self.initiator.state(),
            stats,
            rekeys: self.rekeys,
        }
    }

    /// The channel (for its counters and policy).
    pub fn channel(&self) -> &SecureChannel {
        &self.channel
    }

    /// The handshake state machine.
    pub fn initiator(&self) -> &Initiator {
        &self.initiator
    }
}

/// Reads and parses a key file: at most [`MAX_KEY_FILE_LEN`] bytes of UTF-8 text, read
/// at once into a buffer that is cleared afterwards (no copies of private keys left
/// behind); a directory, an unreadable, too long or non-UTF-8 file is a
/// [`SecureSetupError::Read`], a malformed line a [`SecureSetupError::Parse`].
///
/// # Errors
/// As described.
pub fn key_file_from_path(path: &Path) -> Result<KeyFile, SecureSetupError> {
    use std::io::Read as _;
    let read_error = |error| SecureSetupError::Read {
        path: path.to_owned(),
        error,
    };
    let file = std::fs::File::open(path).map_err(read_error)?;
    if file.metadata().map_err(read_error)?.is_dir() {
        return Err(read_error(std::io::Error::other("it is a directory")));
    }
    // Room for the whole file at once: no copies of the private key left behind by a
    // reallocation; the bytes are cleared once parsed.
    let mut bytes = Vec::with_capacity(MAX_KEY_FILE_LEN as usize + 1);
    let read = file
        .take(MAX_KEY_FILE_LEN + 1)
        .read_to_end(&mut bytes)
        .map_err(read_error);
    let result = read.and_then(|_| parse_key_file(path, &bytes));
    bytes.fill(0);
    result
}

fn parse_key_file(path: &Path, bytes: &[u8]) -> Result<KeyFile, SecureSetupError> {
    let read_error = |error| SecureSetupError::Read {
        path: path.to_owned(),
        error,
    };
    if bytes.len() as u64 > MAX_KEY_FILE_LEN {
        return Err(read_error(std::io::Error::other(format!(
            "longer than {MAX_KEY_FILE_LEN} bytes: not a key file"
        ))));
    }
    let text = std::str::from_utf8(bytes).map_err(|_| {
        read_error(std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            "not UTF-8 text",
        ))
    })?;
    KeyFile::parse(text).map_err(|error| SecureSetupError::Parse {
        path: path.to_owned(),
        error,
    })
}

/// Reads the ground's keys from a key file.
///
/// # Errors
/// The file cannot be read, does not parse, or lacks valid ground keys.
pub fn ground_keys_from_file(path: &Path) -> Result<GroundKeys, SecureSetupError> {
    key_file_from_path(path)?
        .ground()
        .map_err(|error| SecureSetupError::Keys {
            path: path.to_owned(),
            error,
        })
}
