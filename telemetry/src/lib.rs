#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub mod arena;
pub mod downlink;
pub mod queue;
pub mod reader;
pub mod registry;
pub mod scheduler;
pub mod services;
pub mod stats;
pub mod writer;

pub use pprz_messages;
pub use pprz_transports;

pub use arena::{AllocError, FrameArena, FrameBuf};
pub use downlink::{DeviceConfig, Downlink, SendError, Targets};
pub use queue::FrameQueue;
pub use stats::{DeviceStats, DropReason};
pub use writer::run_writer;

/// The project's default message set, generated at build time from `messages.xml` at the
/// root of the repository (telemetry and datalink classes).
///
/// A firmware with its own `messages.xml` generates its own set the same way; see
/// `pprz-codegen`.
pub mod messages {
    include!(concat!(env!("OUT_DIR"), "/messages.rs"));
}

/// The project's periodic telemetry schedule, generated at build time from `telemetry.xml`
/// at the root of the repository, resolved against [`messages`]: [`SCHEDULE`](periodic::SCHEDULE)
/// for a [`Scheduler`](scheduler::Scheduler), and per process a module with its index and
/// mode indices (`periodic::main::PROCESS`, `periodic::main::MODE_DEFAULT`, ...).
///
/// A firmware with its own `telemetry.xml` generates its own schedule the same way; see
/// `pprz-codegen`.
pub mod periodic {
    include!(concat!(env!("OUT_DIR"), "/periodic.rs"));
}
