#![doc = include_str!("../README.md")]
#![no_std]
#![forbid(unsafe_code)]
// No panic on any input: no indexing that can fail, no unwrap, no panic (the `const`
// key-file parser and `const` tables, evaluated at build time, are the exceptions,
// allowed where they are).
#![cfg_attr(
    not(test),
    deny(
        clippy::indexing_slicing,
        clippy::unwrap_used,
        clippy::expect_used,
        clippy::panic
    )
)]

pub mod channel;
pub mod crypto;
pub mod frame;
pub mod handshake;
pub mod initiator;
pub mod keys;
#[cfg(feature = "embassy")]
pub mod link;
pub mod responder;
pub mod stats;

pub use channel::{
    ChannelStats, KEY_EXCHANGE_GCS, KEY_EXCHANGE_UAV, MsgId, Opened, Policy, Protection, Reject,
    SECURE_LINK_STATUS, SealError, Sealed, SecureChannel,
};
pub use frame::{
    DirectionKey, MAX_FIELDS_LEN, MIN_ENCRYPTED_DATA_LEN, MIN_ENCRYPTED_FRAME_LEN, OVERHEAD,
    PLAINTEXT_OVERHEAD, SessionKeys,
};
pub use handshake::{HandshakeError, HandshakeStats, KeyExchange, KeyExchangeIds, MsgType};
pub use initiator::{Initiator, InitiatorEvent, InitiatorState};
pub use keys::{AircraftKeys, GroundKeys, KeyError, KeyFile, KeyFileError, KeyName};
pub use rand_core;
pub use responder::{Responder, ResponderEvent, ResponderState};
pub use stats::{LinkStatus, SecureStats};
