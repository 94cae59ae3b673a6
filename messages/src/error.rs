//! Errors of message encoding and decoding.

use core::fmt;

/// Why a payload could not be decoded into a message.
///
/// Decoders never panic: every malformed input ends up as one of these.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum DecodeError {
    /// The payload ended before the message did: at least `needed` bytes were required,
    /// only `actual` were there.
    Truncated {
        /// Minimum payload length that would have let decoding go on.
        needed: usize,
        /// Length of the payload given.
        actual: usize,
    },
    /// The message was complete after `expected` bytes but the payload had `actual`.
    TrailingBytes {
        /// Length of the message as decoded.
        expected: usize,
        /// Length of the payload given.
        actual: usize,
    },
    /// No message with this class and id is known to the decoder.
    UnknownMessage {
        /// Class id (`telemetry` = 1, `datalink` = 2, ...).
        class_id: u8,
        /// Message id within the class.
        msg_id: u8,
    },
}

impl fmt::Display for DecodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Truncated { needed, actual } => {
                write!(
                    f,
                    "payload truncated: needs at least {needed} bytes, got {actual}"
                )
            }
            Self::TrailingBytes { expected, actual } => {
                write!(
                    f,
                    "payload too long: message ends after {expected} bytes, got {actual}"
                )
            }
            Self::UnknownMessage { class_id, msg_id } => {
                write!(f, "unknown message id {msg_id} in class {class_id}")
            }
        }
    }
}

impl core::error::Error for DecodeError {}

/// Why a message could not be encoded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum EncodeError {
    /// The output buffer is shorter than the encoded message. Nothing was written.
    BufferTooSmall {
        /// Bytes the message needs.
        needed: usize,
        /// Bytes the buffer has.
        available: usize,
    },
    /// A variable-length array holds more than 255 elements, which its one-byte length
    /// prefix cannot express.
    ArrayTooLong {
        /// Number of elements in the array.
        len: usize,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::BufferTooSmall { needed, available } => {
                write!(
                    f,
                    "buffer too small: message needs {needed} bytes, buffer has {available}"
                )
            }
            Self::ArrayTooLong { len } => {
                write!(
                    f,
                    "variable array of {len} elements exceeds the 255-element wire limit"
                )
            }
        }
    }
}

impl core::error::Error for EncodeError {}
