#![doc = include_str!("../README.md")]
#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]

#[cfg(any(feature = "std", test))]
extern crate std;

pub mod counted;
#[cfg(feature = "std")]
pub mod host;
pub mod rng;
#[cfg(feature = "sdlog")]
pub mod sdlog;
#[cfg(feature = "sim")]
pub mod sim;
#[cfg(feature = "stm32")]
pub mod stm32;
#[cfg(feature = "usb")]
pub mod usb;

pub use counted::{Counted, IoCounters, IoStats};
pub use embedded_io_async::{ErrorKind, ErrorType, Read, Write};

/// Adds `n` to a counter that only one task updates (the owner of the device half it
/// counts); other tasks only read it. A load and a store, so it also works on cores
/// without atomic read-modify-write (Cortex-M0).
pub(crate) fn bump(counter: &core::sync::atomic::AtomicU32, n: u32) {
    use core::sync::atomic::Ordering::Relaxed;
    counter.store(counter.load(Relaxed).wrapping_add(n), Relaxed);
}

/// Saturating `usize` -> `u32` for counters of lengths.
pub(crate) fn len_u32(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}
