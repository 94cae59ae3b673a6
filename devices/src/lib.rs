//! Devices of the Paparazzi telemetry stack.
//!
//! The generic device — one interface over every concrete driver (UART, USB, SD card,
//! sockets) — is [`embedded_io_async`]'s [`Read`] and [`Write`]: any driver that
//! implements them can carry telemetry and datalink frames, and they are re-exported here
//! so the stack names one device interface. Adapters for concrete drivers (embassy-stm32
//! UART, embassy-usb CDC-ACM, an SD card log, host sockets and files, a simulated radio
//! link) are added to this crate behind features, so a firmware compiles only what it
//! uses.
//!
//! ```
//! use pprz_devices::{Read, Write};
//!
//! /// Anything that is a device can be handed to the stack.
//! fn is_device<D: Read + Write>(_: &D) {}
//! ```
#![no_std]
#![deny(unsafe_code)]
#![warn(missing_docs)]

pub use embedded_io_async::{ErrorKind, ErrorType, Read, Write};
