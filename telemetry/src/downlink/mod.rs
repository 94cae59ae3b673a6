//! The downlink: send a message to one or more devices, each with its own transport and
//! priority queue, all frames in one shared [`FrameArena`](crate::FrameArena). Sending
//! never blocks: a message is encoded straight into arena memory and queued, or dropped
//! and counted with a reason.
//!
//! ```text
//!  send(&msg) ──encode per transport──► FrameArena (shared bytes)
//!        │                                   ▲ released when written or evicted
//!        ├──► FrameQueue[0] ──► writer task 0 ──► radio  (PPRZ v2)
//!        └──► FrameQueue[1] ──► writer task 1 ──► SD log (PPRZLOG)
//! ```
//!
//! # Overflow policy
//! When a device's queue or the arena has no room, the new message evicts queued
//! messages of strictly lower priority (least important first, and among those the
//! oldest) until it fits; if it still does not fit it is dropped. Equal or higher
//! priorities are never evicted. Every eviction and drop is counted per device and
//! reason ([`DeviceStats`](crate::DeviceStats)).
//!
//! # Set-up
//! Everything is `const`, so the arena and the downlink are plain `static`s:
//!
//! ```
//! use embassy_sync::blocking_mutex::raw::CriticalSectionRawMutex as M;
//! use pprz_telemetry::{DeviceConfig, Downlink, FrameArena, SendOptions, Targets};
//! use pprz_telemetry::pprz_transports::{AnyTransport, PprzLog, PprzV2};
//! use pprz_default::messages::telemetry::Attitude; // any generated message set
//!
//! // One arena for the pending frames of every device (size it for the backlog you accept:
//! // e.g. 4 KiB holds ~50 typical 60-byte frames plus allocator overhead).
//! static ARENA: FrameArena<M, 4096> = FrameArena::new();
//! // Two devices, queues of up to 32 frames each.
//! static DOWNLINK: Downlink<'static, M, 2, 32> = Downlink::new(&ARENA, 7, [
//!     DeviceConfig::new(AnyTransport::PprzV2(PprzV2::new())),              // radio
//!     DeviceConfig::new(AnyTransport::PprzLog(PprzLog::TELEMETRY)).depth(16), // SD card log
//! ]);
//!
//! // At start-up: one port per device, each for the device's writer task.
//! let [radio, log] = DOWNLINK.ports().unwrap();
//! // spawner.spawn(radio_writer(radio, uart_tx)) with `run_writer(&mut port, uart_tx).await`
//!
//! // From any task: returns at once. `sender()` is a copyable handle without the
//! // downlink's generic parameters.
//! let tx = DOWNLINK.sender();
//! let attitude = Attitude { phi: 0.1, psi: 0.0, theta: 0.0 };
//! tx.send(&attitude).unwrap(); // every device
//! // Only the radio, ahead of the usual traffic.
//! radio.device().send_with(&attitude, SendOptions::new().priority(200)).unwrap();
//! // Only the log, behind it.
//! let to_log = SendOptions::new().on(Targets::from(log.device())).priority(10);
//! tx.send_with(&attitude, to_log).unwrap();
//! assert_eq!(radio.device().stats().queued, 2);
//! assert_eq!(log.device().stats().queued, 2);
//! ```

//!
//! # Files
//! `send.rs` holds the downlink and its send path, `config.rs` the per-device settings,
//! `options.rs` what a send names, `handles.rs` the type-erased [`Sender`] and
//! [`Device`]. The consumer side of each queue, [`Port`](crate::Port), lives with its
//! consumer, the [writer](crate::writer).

mod config;
mod handles;
mod options;
mod send;

pub use config::{DeviceConfig, Pacing, ReplyLimit};
pub use handles::{Device, Sender};
pub use options::{SendError, SendOptions};
pub use send::{Downlink, FrameAlloc};
