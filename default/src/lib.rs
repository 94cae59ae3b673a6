#![doc = include_str!("../README.md")]
#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub use pprz_messages;

/// The default message set, generated at build time from the repository's top-level
/// `messages.xml` (classes `telemetry` = 1 and `datalink` = 2).
///
/// [`Set`](messages::Set) names the set for the runtime: it fills the roles of
/// `pprz_messages::roles` (the datalink services' PING/PONG/SETTING/GET_SETTING/DL_VALUE and
/// DATALINK_REPORT).
pub mod messages {
    include!(concat!(env!("OUT_DIR"), "/messages.rs"));
}

/// The default periodic telemetry schedule, generated at build time from the repository's
/// top-level `telemetry.xml`, resolved against [`messages`]: [`SCHEDULE`](periodic::SCHEDULE)
/// for a scheduler, and per process a module with its index and mode indices
/// (`periodic::main::PROCESS`, `periodic::main::MODE_DEFAULT`, ...).
pub mod periodic {
    include!(concat!(env!("OUT_DIR"), "/periodic.rs"));
}
