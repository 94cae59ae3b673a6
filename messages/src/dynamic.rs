//! Decoding any message generically, driven by its [`MessageDescriptor`].
//!
//! For host tools (monitors, log converters) that print whatever arrives without
//! compiling a struct per message, including sets loaded from a `messages.xml` at run
//! time. Variable arrays may stand anywhere in a message: offsets are computed while
//! decoding.
//!
//! ```
//! use pprz_messages::descriptor::{BaseType, FieldDescriptor, FieldType, MessageDescriptor};
//! use pprz_messages::dynamic::{self, Value};
//!
//! const FIELDS: [FieldDescriptor<'static>; 2] = [
//!     FieldDescriptor::new("index", FieldType::Scalar(BaseType::U8)),
//!     FieldDescriptor::new("value", FieldType::Scalar(BaseType::F32)),
//! ];
//! let dl_value = MessageDescriptor {
//!     class_id: 1, class_name: "telemetry", id: 31, name: "DL_VALUE", priority: 192,
//!     fields: &FIELDS,
//! };
//! let payload = [3, 0, 0, 0x80, 0x3F];
//! let values: Vec<_> = dynamic::fields(&dl_value, &payload).collect::<Result<_, _>>().unwrap();
//! assert_eq!(values[0].1, Value::U8(3));
//! assert_eq!(values[1].1.to_string(), "1");
//! ```

use core::fmt;

use crate::descriptor::{BaseType, FieldDescriptor, FieldType, MessageDescriptor};
use crate::error::DecodeError;
use crate::wire::{Chars, Reader};

/// A decoded field value.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Value<'a> {
    /// `uint8`
    U8(u8),
    /// `int8`
    I8(i8),
    /// `uint16`
    U16(u16),
    /// `int16`
    I16(i16),
    /// `uint32`
    U32(u32),
    /// `int32`
    I32(i32),
    /// `uint64`
    U64(u64),
    /// `int64`
    I64(i64),
    /// `float`
    F32(f32),
    /// `double`
    F64(f64),
    /// `char`
    Char(u8),
    /// A fixed or variable array of numbers.
    Array(ArrayValue<'a>),
    /// A `char[N]`, `char[]` or `string` field.
    Text(Chars<'a>),
}

impl Value<'_> {
    fn read(base: BaseType, r: &mut Reader<'_>) -> Result<Self, DecodeError> {
        Ok(match base {
            BaseType::U8 => Value::U8(r.scalar()?),
            BaseType::I8 => Value::I8(r.scalar()?),
            BaseType::U16 => Value::U16(r.scalar()?),
            BaseType::I16 => Value::I16(r.scalar()?),
            BaseType::U32 => Value::U32(r.scalar()?),
            BaseType::I32 => Value::I32(r.scalar()?),
            BaseType::U64 => Value::U64(r.scalar()?),
            BaseType::I64 => Value::I64(r.scalar()?),
            BaseType::F32 => Value::F32(r.scalar()?),
            BaseType::F64 => Value::F64(r.scalar()?),
            BaseType::Char => Value::Char(r.scalar()?),
        })
    }

    /// The value as a number, for scalars (`None` for arrays and text).
    pub fn as_f64(&self) -> Option<f64> {
        Some(match *self {
            Value::U8(v) | Value::Char(v) => v.into(),
            Value::I8(v) => v.into(),
            Value::U16(v) => v.into(),
            Value::I16(v) => v.into(),
            Value::U32(v) => v.into(),
            Value::I32(v) => v.into(),
            Value::U64(v) => v as f64,
            Value::I64(v) => v as f64,
            Value::F32(v) => v.into(),
            Value::F64(v) => v,
            Value::Array(_) | Value::Text(_) => return None,
        })
    }

    /// The value as an integer, for integer scalars (enumeration indices).
    pub fn as_i64(&self) -> Option<i64> {
        Some(match *self {
            Value::U8(v) | Value::Char(v) => v.into(),
            Value::I8(v) => v.into(),
            Value::U16(v) => v.into(),
            Value::I16(v) => v.into(),
            Value::U32(v) => v.into(),
            Value::I32(v) => v.into(),
            Value::U64(v) => i64::try_from(v).ok()?,
            Value::I64(v) => v,
            _ => return None,
        })
    }
}

/// Numbers as Rust prints them, arrays comma-separated (as the Paparazzi ground bus
/// does), text as text.
impl fmt::Display for Value<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Value::U8(v) => write!(f, "{v}"),
            Value::I8(v) => write!(f, "{v}"),
            Value::U16(v) => write!(f, "{v}"),
            Value::I16(v) => write!(f, "{v}"),
            Value::U32(v) => write!(f, "{v}"),
            Value::I32(v) => write!(f, "{v}"),
            Value::U64(v) => write!(f, "{v}"),
            Value::I64(v) => write!(f, "{v}"),
            Value::F32(v) => write!(f, "{v}"),
            Value::F64(v) => write!(f, "{v}"),
            Value::Char(v) => write!(f, "{}", char::from(*v).escape_default()),
            Value::Array(a) => {
                for (i, v) in a.iter().enumerate() {
                    if i > 0 {
                        f.write_str(",")?;
                    }
                    write!(f, "{v}")?;
                }
                Ok(())
            }
            Value::Text(t) => write!(f, "{t}"),
        }
    }
}

/// An array of numbers, as a view of its little-endian wire bytes.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ArrayValue<'a> {
    base: BaseType,
    /// Invariant: a whole number of `base` elements.
    bytes: &'a [u8],
}

impl<'a> ArrayValue<'a> {
    /// Element type.
    pub const fn base(&self) -> BaseType {
        self.base
    }

    /// Number of elements.
    pub const fn len(&self) -> usize {
        self.bytes.len() / self.base.size()
    }

    /// Whether there is no element.
    pub const fn is_empty(&self) -> bool {
        self.bytes.is_empty()
    }

    /// The elements' wire bytes.
    pub const fn bytes(&self) -> &'a [u8] {
        self.bytes
    }

    /// Element `index`.
    pub fn get(&self, index: usize) -> Option<Value<'a>> {
        let size = self.base.size();
        let start = index.checked_mul(size)?;
        let bytes = self.bytes.get(start..start.checked_add(size)?)?;
        Value::read(self.base, &mut Reader::new(bytes)).ok()
    }

    /// Iterates over the elements.
    pub fn iter(&self) -> impl Iterator<Item = Value<'a>> + 'a {
        let this = *self;
        (0..this.len()).map_while(move |i| this.get(i))
    }
}

/// Iterator over the fields of a payload; see [`fields`].
#[derive(Debug, Clone)]
pub struct Fields<'d, 'p> {
    fields: core::slice::Iter<'d, FieldDescriptor<'d>>,
    reader: Reader<'p>,
    done: bool,
}

impl<'d, 'p> Iterator for Fields<'d, 'p> {
    type Item = Result<(&'d FieldDescriptor<'d>, Value<'p>), DecodeError>;

    fn next(&mut self) -> Option<Self::Item> {
        if self.done {
            return None;
        }
        let Some(field) = self.fields.next() else {
            self.done = true;
            return match self.reader.clone().finish() {
                Ok(()) => None,
                Err(e) => Some(Err(e)),
            };
        };
        let value = read_field(field.ty, &mut self.reader);
        if value.is_err() {
            self.done = true;
        }
        Some(value.map(|v| (field, v)))
    }
}

fn read_field<'p>(ty: FieldType, r: &mut Reader<'p>) -> Result<Value<'p>, DecodeError> {
    match ty {
        FieldType::Scalar(base) => Value::read(base, r),
        FieldType::Array(BaseType::Char, n) => r.take(n).map(|b| Value::Text(Chars::new(b))),
        FieldType::Vector(BaseType::Char) => r.chars().map(Value::Text),
        FieldType::Array(base, n) => r
            .take(n.saturating_mul(base.size()))
            .map(|bytes| Value::Array(ArrayValue { base, bytes })),
        FieldType::Vector(base) => {
            let count = usize::from(r.scalar::<u8>()?);
            r.take(count * base.size())
                .map(|bytes| Value::Array(ArrayValue { base, bytes }))
        }
    }
}

/// Decodes the fields of `payload` one by one, as described by `message`.
///
/// Yields `(field, value)` pairs in wire order. If the payload is too short, the field
/// that does not fit yields [`DecodeError::Truncated`]; if bytes remain after the last
/// field, a final [`DecodeError::TrailingBytes`] is yielded. Never panics.
pub fn fields<'d, 'p>(message: &'d MessageDescriptor<'d>, payload: &'p [u8]) -> Fields<'d, 'p> {
    Fields {
        fields: message.fields.iter(),
        reader: Reader::new(payload),
        done: false,
    }
}

/// Checks that `payload` is exactly one well-formed `message`.
///
/// # Errors
/// As [`fields`].
pub fn check(message: &MessageDescriptor<'_>, payload: &[u8]) -> Result<(), DecodeError> {
    fields(message, payload).try_for_each(|f| f.map(drop))
}

/// Writes a well-formed payload for `message` into `out`: every field byte comes from
/// `next_byte`, and so does every variable array's element count (bounded by
/// `max_elements`). Returns the payload length.
///
/// For property tests, fuzzing and benchmarks: the result always decodes, both
/// generically ([`check`]) and with the generated types.
///
/// # Errors
/// [`EncodeError::BufferTooSmall`](crate::EncodeError::BufferTooSmall) if `out` is too
/// short for the payload drawn.
pub fn synthesize(
    message: &MessageDescriptor<'_>,
    out: &mut [u8],
    max_elements: u8,
    mut next_byte: impl FnMut() -> u8,
) -> Result<usize, crate::EncodeError> {
    let mut w = crate::wire::Writer::new(out, 0)?;
    for field in message.fields {
        let elements = match field.ty {
            FieldType::Scalar(_) => 1,
            FieldType::Array(_, n) => n,
            FieldType::Vector(_) => {
                let count = next_byte() % max_elements.saturating_add(1).max(1);
                w.scalar(count)?;
                usize::from(count)
            }
        };
        for _ in 0..elements * field.ty.base().size() {
            w.scalar(next_byte())?;
        }
    }
    Ok(w.finish())
}

#[cfg(test)]
mod tests {
    use super::*;

    const FIELDS: [FieldDescriptor<'static>; 4] = [
        FieldDescriptor::new("a", FieldType::Vector(BaseType::I16)),
        FieldDescriptor::new("b", FieldType::Scalar(BaseType::U8)),
        FieldDescriptor::new("name", FieldType::Vector(BaseType::Char)),
        FieldDescriptor::new("c", FieldType::Array(BaseType::F32, 2)),
    ];
    const MSG: MessageDescriptor<'static> = MessageDescriptor {
        class_id: 1,
        class_name: "telemetry",
        id: 200,
        name: "TEST",
        priority: 1,
        fields: &FIELDS,
    };

    #[test]
    fn decodes_fields_after_a_variable_array() {
        let payload = [
            2, 1, 0, 0xFE, 0xFF, 9, 2, b'h', b'i', 0, 0, 0x80, 0x3F, 0, 0, 0, 0x40,
        ];
        let v: Vec<_> = fields(&MSG, &payload).map(|r| r.unwrap()).collect();
        assert_eq!(v.len(), 4);
        assert_eq!(v[0].1.to_string(), "1,-2");
        assert_eq!(v[1].1, Value::U8(9));
        assert_eq!(v[2].1.to_string(), "hi");
        assert_eq!(v[3].1.to_string(), "1,2");
        assert_eq!(check(&MSG, &payload), Ok(()));
        assert_eq!(MSG.min_len(), 1 + 1 + 1 + 8);
    }

    #[test]
    fn synthesized_payloads_are_well_formed() {
        let mut seed = 7u32;
        let mut next = || {
            seed = seed.wrapping_mul(1_103_515_245).wrapping_add(12_345);
            (seed >> 16) as u8
        };
        let mut buf = [0u8; 1024];
        for _ in 0..100 {
            let n = synthesize(&MSG, &mut buf, 20, &mut next).unwrap();
            assert!(n >= MSG.min_len());
            assert_eq!(check(&MSG, &buf[..n]), Ok(()));
        }
        assert!(synthesize(&MSG, &mut buf[..5], 0, || 0).is_err());
    }

    #[test]
    fn reports_truncation_and_trailing_bytes() {
        let payload = [3, 1, 0];
        assert_eq!(
            check(&MSG, &payload),
            Err(DecodeError::Truncated {
                needed: 7,
                actual: 3
            })
        );
        let mut long = [0u8; 12];
        long[2] = 0; // empty vectors, then 8 bytes of floats, one byte too many
        assert_eq!(
            check(&MSG, &long),
            Err(DecodeError::TrailingBytes {
                expected: 11,
                actual: 12
            })
        );
    }
}
