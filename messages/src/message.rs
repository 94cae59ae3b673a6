//! The traits every generated message implements.

use crate::descriptor::MessageDescriptor;
use crate::error::{DecodeError, EncodeError};

/// A message of a Paparazzi message set: its identity, priority and encoder.
///
/// Implemented by the code generator for every message struct. Encoding writes the
/// fields only (little-endian, packed, XML order); the transport writes the headers
/// around them.
pub trait Message {
    /// Class id (`telemetry` = 1, `datalink` = 2, ...).
    const CLASS_ID: u8;
    /// Message id within the class.
    const ID: u8;
    /// Name as in `messages.xml`.
    const NAME: &'static str;
    /// Send priority, 0..=255, higher is more important (see [`crate::priority`]).
    const PRIORITY: u8;
    /// Smallest encoded length (every variable array empty).
    const MIN_LEN: usize;
    /// Largest encoded length (every variable array at 255 elements).
    const MAX_LEN: usize;
    /// Description of the message (names, types, units), for generic tools.
    const DESCRIPTOR: MessageDescriptor<'static>;

    /// Length of the encoded fields of this value.
    fn encoded_len(&self) -> usize;

    /// Encodes the fields into the start of `buf`, returning the number of bytes written.
    ///
    /// # Errors
    /// [`EncodeError::BufferTooSmall`] if `buf` is shorter than
    /// [`encoded_len`](Self::encoded_len) (nothing is written), or
    /// [`EncodeError::ArrayTooLong`] if a variable array has more than 255 elements.
    fn encode(&self, buf: &mut [u8]) -> Result<usize, EncodeError>;
}

/// Decoding of a message from its payload (the fields, without transport headers).
///
/// Messages with variable arrays borrow them from the payload (`'a`), without copying.
pub trait Decode<'a>: Message + Sized {
    /// Decodes a payload that must hold exactly one message.
    ///
    /// # Errors
    /// [`DecodeError::Truncated`] if the payload is too short (also when a variable
    /// array's count runs past its end), [`DecodeError::TrailingBytes`] if it is longer
    /// than the message. Never panics.
    fn decode(payload: &'a [u8]) -> Result<Self, DecodeError>;
}

/// The three fundamental priority levels of the original design, and the default.
///
/// Priorities are a byte: 0 is the least important, 255 the most. The `priority`
/// attribute of a `<message>` in `messages.xml` sets a message's priority; a message
/// without it gets the generator's default, [`DEFAULT`](self::priority::DEFAULT) unless configured otherwise.
pub mod priority {
    /// Payload and debug data: shed first when the link is saturated.
    pub const LOW: u8 = 64;
    /// Flight status telemetry.
    pub const NORMAL: u8 = 128;
    /// Acknowledgements (PONG, DL_VALUE): the ground must see that a command was applied.
    pub const HIGH: u8 = 192;
    /// Priority of a message whose definition has no `priority` attribute.
    pub const DEFAULT: u8 = NORMAL;

    /// Names of the three levels, indexed by [`level`].
    pub const LEVEL_NAMES: [&str; 3] = ["high", "normal", "low"];

    /// The fundamental level of a priority, for statistics: 0 high (`>= HIGH`), 1 normal
    /// (`>= NORMAL`), 2 low.
    pub const fn level(priority: u8) -> usize {
        if priority >= HIGH {
            0
        } else if priority >= NORMAL {
            1
        } else {
            2
        }
    }
}
