//! The secure link on an Embassy aircraft (feature `embassy`): a [`SecureLink`] is the
//! [`LinkLayer`] of one secure device of a `pprz-telemetry` downlink, and
//! [`SecureLink::run_responder`] is the aircraft's handshake task.
//!
//! ```text
//!  queue ─► writer: seal (counter, encryption at wire time) ─► radio
//!  radio ─► reader: open ─┬─► plain frame ─► destination filter, services, subscribers
//!                         └─► KEY_EXCHANGE_GCS ─► handshake queue ─► run_responder
//!                                               (X25519, Ed25519: own task, rate-limited)
//!                             KEY_EXCHANGE_UAV ◄── at the highest priority ◄─┘
//! ```
//!
//! The channel state (keys, counters) sits behind a short lock shared by the writer and
//! the reader; the slow steps of the handshake run in their own task and hold no lock,
//! so neither sending nor the control loop ever waits for them. Key-exchange messages
//! wait in a small queue ([`HANDSHAKE_QUEUE`]); when it is full, further ones are dropped
//! and counted ([`SecureLinkStats::handshake_queue_full`]), so a flood of message 1 costs
//! the reader a copy per message and the handshake task at most its rate limit.
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_secure::{KeyFile, Responder};
//! use pprz_secure::link::SecureLink;
//! use pprz_telemetry::{Downlink, FrameArena, Targets};
//!
//! static ARENA: FrameArena<M, 4096> = FrameArena::new();
//! // The radio reserves the secure overhead after every frame.
//! static DOWNLINK: Downlink<'static, M, 1, 32> =
//!     Downlink::new(&ARENA, 7, [SecureLink::<M>::DEVICE]);
//! static SECURE: SecureLink<M> = SecureLink::aircraft(7);
//!
//! async fn tasks(
//!     uart_tx: impl embedded_io_async::Write,
//!     uart_rx: impl embedded_io_async::Read,
//!     rng: &mut impl pprz_secure::rand_core::CryptoRng,
//! ) {
//!     let [mut radio] = DOWNLINK.ports().unwrap();
//!     let device = radio.device();
//!     // Never the published test keys on a real aircraft: embed your own key file.
//!     let keys = KeyFile::parse(pprz_secure::keys::INSECURE_TEST_KEY_FILE).unwrap();
//!     let mut responder = Responder::new(7, keys.aircraft().unwrap());
//!     // Each in a task of its own (or joined): writer, reader, handshake.
//!     let writer = pprz_telemetry::run_writer_with(&mut radio, uart_tx, &SECURE);
//!     let datalink: pprz_telemetry::reader::Datalink<'_, M, 4> =
//!         pprz_telemetry::reader::Datalink::new(7);
//!     let inbox = pprz_telemetry::Layered::new(&SECURE, &datalink);
//!     let mut reader = pprz_telemetry::reader::Reader::<_, _>::new(
//!         uart_rx,
//!         pprz_telemetry::pprz_transports::PprzV2::new(),
//!         device,
//!     );
//!     let handshake = SECURE.run_responder(&mut responder, rng, device.sender(), Targets::from(device));
//!     # let _ = (writer, reader.run(&inbox), handshake);
//! }
//! ```

use core::cell::{Cell, RefCell};
use pprz_telemetry::SendOptions;

use embassy_sync::blocking_mutex::Mutex;
use embassy_sync::blocking_mutex::raw::RawMutex;
use embassy_sync::channel::Channel;
use embassy_time::Instant;
use pprz_messages::{
    BaseType, EncodeError, FieldDescriptor, FieldType, Message, MessageDescriptor,
};
use pprz_telemetry::layer::{LinkLayer, Opened, Refused};
use pprz_telemetry::{DeviceConfig, Sender, Targets};
use pprz_transports::{AnyTransport, Frame, MAX_FRAME_LEN, PprzV2};
use rand_core::CryptoRng;

use crate::channel::{ChannelStats, Policy, SecureChannel};
use crate::frame::OVERHEAD;
use crate::handshake::{HandshakeError, HandshakeStats, KeyExchange, KeyExchangeIds};
use crate::responder::{Responder, ResponderEvent, ResponderState};
use crate::stats::{LinkStatus, SecureStats};

/// Key-exchange messages waiting for the handshake task at most.
pub const HANDSHAKE_QUEUE: usize = 2;

/// Priority of the aircraft's `KEY_EXCHANGE_UAV` replies: the highest, as without them
/// no session, and so no telemetry, exists.
pub const KEY_EXCHANGE_PRIORITY: u8 = 255;

/// What the handshake task publishes for the link report.
#[derive(Clone, Copy, Debug)]
struct Published {
    handshake: HandshakeStats,
    state: ResponderState,
    last_error: Option<HandshakeError>,
    queue_full: u32,
    not_key_exchange: u32,
}

/// Counters of one secure device of the aircraft.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SecureLinkStats {
    /// Handshakes and frames: started, completed, refused by reason; sealed, opened,
    /// rejected by reason; counter space left.
    pub secure: SecureStats,
    /// Key-exchange messages dropped because the handshake task had
    /// [`HANDSHAKE_QUEUE`] waiting already (a flood).
    pub handshake_queue_full: u32,
    /// Plaintext messages on the whitelist that are not a well-formed key exchange
    /// (dropped).
    pub malformed_key_exchange: u32,
}

/// The secure link of one device of the aircraft: the [`SecureChannel`] its writer seals
/// with and its reader opens with, and the queue of key-exchange messages for its
/// handshake task. `const`, so it is a `static`; see the [module documentation](self).
pub struct SecureLink<M: RawMutex> {
    channel: Mutex<M, RefCell<SecureChannel>>,
    handshake: Channel<M, KeyExchange, HANDSHAKE_QUEUE>,
    published: Mutex<M, Cell<Published>>,
    ids: KeyExchangeIds,
}

impl<M: RawMutex> SecureLink<M> {
    /// The configuration of a secure PPRZ v2 device: [`OVERHEAD`] spare bytes reserved
    /// after each frame, so the writer seals it in place (messages with more than
    /// [`MAX_FIELDS_LEN`](crate::MAX_FIELDS_LEN) bytes of fields are refused at `send`).
    pub const DEVICE: DeviceConfig =
        DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())).reserve(OVERHEAD as u8);

    /// The secure link of aircraft `ac_id` ([`Policy::aircraft`]).
    pub const fn aircraft(ac_id: u8) -> Self {
        Self::new(Policy::aircraft(ac_id))
    }

    /// A secure link with `policy` (e.g. [`Policy::with_beacon`]).
    pub const fn new(policy: Policy) -> Self {
        Self {
            channel: Mutex::new(RefCell::new(SecureChannel::new(policy))),
            handshake: Channel::new(),
            published: Mutex::new(Cell::new(Published {
                handshake: HandshakeStats {
                    started: 0,
                    completed: 0,
                    resent: 0,
                    malformed: 0,
                    wrong_address: 0,
                    unexpected: 0,
                    duplicate: 0,
                    rate_limited: 0,
                    bad_key: 0,
                    bad_tag: 0,
                    bad_signature: 0,
                },
                state: ResponderState::WaitMsg1,
                last_error: None,
                queue_full: 0,
                not_key_exchange: 0,
            })),
            ids: KeyExchangeIds::PPRZLINK,
        }
    }

    /// Whether a session is established (telemetry flows).
    pub fn has_session(&self) -> bool {
        self.channel.lock(|c| c.borrow().has_session())
    }

    /// Runs `f` on the channel (its lock held: keep it short). For tests and tools, e.g.
    /// [`SecureChannel::advance_tx_counter`].
    pub fn with_channel<T>(&self, f: impl FnOnce(&mut SecureChannel) -> T) -> T {
        self.channel.lock(|c| f(&mut c.borrow_mut()))
    }

    /// The counters, for the link report.
    pub fn stats(&self) -> SecureLinkStats {
        let p = self.published.lock(Cell::get);
        let secure = self
            .channel
            .lock(|c| SecureStats::new(p.handshake, &c.borrow()));
        SecureLinkStats {
            secure,
            handshake_queue_full: p.queue_full,
            malformed_key_exchange: p.not_key_exchange,
        }
    }

    /// The fields of Paparazzi's `SECURE_LINK_STATUS` for this link.
    pub fn status(&self) -> LinkStatus {
        let p = self.published.lock(Cell::get);
        let channel: ChannelStats = self.channel.lock(|c| c.borrow().stats());
        LinkStatus::aircraft(p.state, p.last_error, &channel)
    }

    fn publish(&self, f: impl FnOnce(&mut Published)) {
        self.published.lock(|p| {
            let mut v = p.get();
            f(&mut v);
            p.set(v);
        });
    }

    /// The aircraft's handshake task: takes the key-exchange messages the reader queued,
    /// answers message 1 with message 2 through `out` to `targets` (the secure device;
    /// at [`KEY_EXCHANGE_PRIORITY`], sent in plaintext by the writer), and installs the
    /// session once message 3 verifies (the previous session stays in force until
    /// then). `rng` makes each handshake's ephemeral key: a hardware RNG (any
    /// `rand_core` 0.9 [`CryptoRng`]). The responder's rate limit bounds its work
    /// (one X25519 + one Ed25519 signature per second by default). Never returns.
    pub async fn run_responder<R: CryptoRng + ?Sized>(
        &self,
        responder: &mut Responder,
        rng: &mut R,
        out: Sender<'_>,
        targets: Targets,
    ) -> ! {
        loop {
            let kx = self.handshake.receive().await;
            let now_ms = Instant::now().as_millis();
            match responder.handle(&kx, now_ms, rng) {
                Ok(ResponderEvent::Reply(reply)) => {
                    // A drop (queue full of replies, ...) is counted by the downlink;
                    // the ground repeats message 1.
                    let _ = out.send_with(
                        &KeyExchangeUav(&reply),
                        SendOptions::new()
                            .on(targets)
                            .priority(KEY_EXCHANGE_PRIORITY),
                    );
                }
                Ok(ResponderEvent::Established(keys)) => {
                    self.channel.lock(|c| c.borrow_mut().install(keys));
                }
                // Counted by the responder.
                Err(_) => {}
            }
            let (handshake, state, last_error) =
                (responder.stats(), responder.state(), responder.last_error());
            self.publish(|p| {
                p.handshake = handshake;
                p.state = state;
                p.last_error = last_error;
            });
        }
    }
}

impl<M: RawMutex + Sync> LinkLayer for SecureLink<M> {
    fn seal(&self, buf: &mut [u8], len: usize) -> Result<usize, Refused> {
        self.channel
            .lock(|c| c.borrow_mut().seal_in_place(buf, len))
            .map(|sealed| sealed.len)
            .map_err(|_| Refused)
    }

    fn open(&self, frame: &Frame<'_>, out: &mut [u8; MAX_FRAME_LEN]) -> Opened {
        let opened = self.channel.lock(|c| {
            c.borrow_mut()
                .open(frame.data(), out)
                .map(|o| (o.frame().len(), o.is_encrypted()))
        });
        // Rejections are counted by the channel.
        let Ok((len, encrypted)) = opened else {
            return Opened::Withheld;
        };
        if encrypted {
            // Checked by its tag and counter: sealed by the peer, not a replay.
            return Opened::Authenticated(len);
        }
        // Plaintext passed the whitelist: the key exchange (or a beacon, on a ground).
        let data = out.get(2..len.saturating_sub(2)).unwrap_or_default();
        match KeyExchange::parse(data, &self.ids) {
            Ok(Some(kx)) => {
                if self.handshake.try_send(kx).is_err() {
                    self.publish(|p| p.queue_full = p.queue_full.wrapping_add(1));
                }
                Opened::Withheld
            }
            Ok(None) => Opened::Rewritten(len),
            Err(_) => {
                self.publish(|p| p.not_key_exchange = p.not_key_exchange.wrapping_add(1));
                Opened::Withheld
            }
        }
    }

    fn authenticates(&self) -> bool {
        true
    }
}

/// `KEY_EXCHANGE_UAV` (telemetry 239 in PPRZLINK's set) as a message the downlink
/// sends: `msg_type u8, msg_data u8[]`.
struct KeyExchangeUav<'a>(&'a KeyExchange);

/// The fields of `KEY_EXCHANGE_UAV`.
const KX_UAV_FIELDS: [FieldDescriptor<'static>; 2] = [
    FieldDescriptor::new("msg_type", FieldType::Scalar(BaseType::U8)),
    FieldDescriptor::new("msg_data", FieldType::Vector(BaseType::U8)),
];

impl Message for KeyExchangeUav<'_> {
    const CLASS_ID: u8 = KeyExchangeIds::PPRZLINK.uav.class;
    const ID: u8 = KeyExchangeIds::PPRZLINK.uav.id;
    const NAME: &'static str = "KEY_EXCHANGE_UAV";
    const PRIORITY: u8 = KEY_EXCHANGE_PRIORITY;
    const MIN_LEN: usize = 2;
    const MAX_LEN: usize = 2 + 255;
    const DESCRIPTOR: MessageDescriptor<'static> = MessageDescriptor {
        class_id: Self::CLASS_ID,
        class_name: "telemetry",
        id: Self::ID,
        name: Self::NAME,
        priority: Self::PRIORITY,
        fields: &KX_UAV_FIELDS,
    };

    fn encoded_len(&self) -> usize {
        self.0.fields_len()
    }

    fn encode(&self, buf: &mut [u8]) -> Result<usize, EncodeError> {
        let needed = self.0.fields_len();
        let available = buf.len();
        self.0
            .write_fields(buf)
            .ok_or(EncodeError::BufferTooSmall { needed, available })
    }
}
