#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod arena;
pub mod delivery;
pub mod downlink;
pub mod health;
pub mod layer;
pub mod link;
#[cfg(feature = "basepri")]
pub mod mutex;
#[cfg(all(feature = "basepri", not(target_has_atomic = "32")))]
compile_error!("feature `basepri` needs a core with BASEPRI: Cortex-M3/M4/M7/M33, not M0/M0+");
mod atomic;
mod queue;
pub mod reader;
pub mod registry;
pub mod relay;
pub mod route;
pub mod scheduler;
pub mod services;
pub mod settings;
pub mod stats;
pub mod writer;

pub use pprz_messages;
pub use pprz_transports;

pub use arena::{AllocError, FrameArena, FrameBuf};
pub use delivery::{DeliveryStats, DeliveryWindow};
pub use downlink::{
    Device, DeviceConfig, Downlink, FrameAlloc, Pacing, ReplyLimit, SendError, SendOptions, Sender,
};
pub use health::{Health, HealthConfig, LinkHealth};
pub use layer::{LinkLayer, Plain};
pub use link::{Link, LinkMutex, LinkStats};
pub use reader::Layered;
pub use relay::{Relay, RelayStats};
pub use route::{Routes, Targets};
pub use stats::{DeviceStats, DropReason, RelayedStats};
pub use writer::{Outgoing, Port, PortsTaken, run_writer, run_writer_with};
