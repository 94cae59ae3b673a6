#![doc = include_str!("../README.md")]
#![cfg_attr(not(test), no_std)]
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub use pprz_messages;

/// The project's default message set, generated at build time from `messages.xml` at the
/// root of the repository (telemetry and datalink classes).
///
/// A firmware with its own `messages.xml` generates its own set the same way; see
/// `pprz-codegen`.
pub mod messages {
    include!(concat!(env!("OUT_DIR"), "/messages.rs"));
}
