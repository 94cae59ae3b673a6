//! The inverse of [`message`](super::message): a JSON object to the payload of a message,
//! for whoever sends messages as JSON (see [`parse_message`]).

use std::fmt;

use pprz_messages::{BaseType, FieldDescriptor, FieldType, MessageDescriptor};
use serde_json::{Map, Number, Value as Json};

use super::{MAX_PAYLOAD, alt_key};
use crate::escape;

/// Longest JSON text [`parse_message_str`] reads, in bytes.
pub const MAX_TEXT: usize = 64 * 1024;

/// Why a JSON value is not a message.
///
/// `field` names the field of the message, with `[i]` for the element `i` of an array.
/// Every text shown is escaped ([`escape`]): the [`Display`](fmt::Display) form is one
/// line without control characters, whatever the input.
#[derive(Debug, Clone, PartialEq)]
pub enum ParseError {
    /// The JSON text is longer than [`MAX_TEXT`] (it is not read).
    TextTooLong {
        /// Length of the text, in bytes.
        len: usize,
        /// Longest text read.
        max: usize,
    },
    /// The text is not JSON (or nests deeper than `serde_json` reads).
    Syntax(String),
    /// The value is not a JSON object.
    NotAnObject {
        /// What was given instead (`an array of 2 items`...).
        found: String,
    },
    /// A key is neither a field nor a converted value ([`alt_key`]) of the message.
    UnknownKey(String),
    /// A field of the message has no key.
    MissingField(String),
    /// A value of the wrong JSON type (a string for a number, a number for an array...).
    WrongType {
        /// Field name.
        field: String,
        /// The field's type in `messages.xml` (`uint8`, `int16[3]`...).
        ty: String,
        /// What the field takes.
        expected: &'static str,
        /// What was given.
        found: String,
    },
    /// A number with a fractional part for an integer.
    NotAnInteger {
        /// Field name.
        field: String,
        /// The type of the value.
        ty: String,
        /// The number given.
        value: String,
    },
    /// A number out of the range of its type.
    OutOfRange {
        /// Field name.
        field: String,
        /// The type of the value.
        ty: String,
        /// The number given.
        value: String,
    },
    /// A string for a labelled integer that is none of the field's `values` labels.
    UnknownLabel {
        /// Field name.
        field: String,
        /// The string given.
        label: String,
    },
    /// A fixed-length array with another number of items.
    WrongLength {
        /// Field name.
        field: String,
        /// Items of the field.
        expected: usize,
        /// Items given.
        actual: usize,
    },
    /// A string longer than its `char[N]` field, in UTF-8 bytes.
    TextTooLongForField {
        /// Field name.
        field: String,
        /// Bytes of the field.
        max: usize,
        /// Bytes given.
        actual: usize,
    },
    /// The payload would be longer than a frame carries.
    PayloadTooLong {
        /// The field that makes it too long.
        field: String,
        /// Smallest payload with that field as given, in bytes.
        needed: usize,
        /// Longest payload.
        max: usize,
    },
}

/// A name from the message set, on one line.
fn one_line(s: &str) -> String {
    escape::lines(s).replace('\n', "\\n")
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TextTooLong { len, max } => {
                write!(f, "JSON text of {len} bytes, longer than {max}")
            }
            Self::Syntax(e) => write!(f, "not JSON: {}", one_line(e)),
            Self::NotAnObject { found } => write!(f, "a message is a JSON object, not {found}"),
            Self::UnknownKey(k) => write!(
                f,
                "unknown key {}: neither a field nor a converted value of the message",
                escape::quoted(k)
            ),
            Self::MissingField(n) => write!(f, "field {} is missing", one_line(n)),
            Self::WrongType {
                field,
                ty,
                expected,
                found,
            } => write!(
                f,
                "field {} ({}) takes {expected}, not {found}",
                one_line(field),
                one_line(ty)
            ),
            Self::NotAnInteger { field, ty, value } => write!(
                f,
                "field {} ({}) takes an integer, not {value}",
                one_line(field),
                one_line(ty)
            ),
            Self::OutOfRange { field, ty, value } => write!(
                f,
                "value {value} out of the range of field {} ({})",
                one_line(field),
                one_line(ty)
            ),
            Self::UnknownLabel { field, label } => write!(
                f,
                "field {} has no label {}",
                one_line(field),
                escape::quoted(label)
            ),
            Self::WrongLength {
                field,
                expected,
                actual,
            } => write!(
                f,
                "field {} takes {expected} items, not {actual}",
                one_line(field)
            ),
            Self::TextTooLongForField { field, max, actual } => write!(
                f,
                "field {} holds at most {max} bytes of text, not {actual}",
                one_line(field)
            ),
            Self::PayloadTooLong { field, needed, max } => write!(
                f,
                "payload too long: at least {needed} bytes with field {}, at most {max}",
                one_line(field)
            ),
        }
    }
}

impl std::error::Error for ParseError {}

/// A short description of a JSON value for an error: numbers and short strings as
/// they are (strings quoted and escaped), arrays and objects by their size.
fn describe(v: &Json) -> String {
    const SHOWN: usize = 32;
    match v {
        Json::Null => "null".into(),
        Json::Bool(b) => b.to_string(),
        Json::Number(n) => n.to_string(),
        Json::String(s) if s.chars().count() <= SHOWN => escape::quoted(s),
        Json::String(s) => {
            let head: String = s.chars().take(SHOWN).collect();
            format!("{}... ({} bytes)", escape::quoted(&head), s.len())
        }
        Json::Array(a) => format!("an array of {} items", a.len()),
        Json::Object(o) => format!("an object of {} keys", o.len()),
    }
}

/// A number to write in a field of a numeric type.
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) enum Num {
    /// An integer (every `u64` and `i64`).
    Int(i128),
    /// Any other number.
    Float(f64),
}

/// Why a number does not fit a type.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum ScalarFault {
    /// A fractional part, for an integer type.
    Fraction,
    /// Out of the type's range (for an integer type, also NaN and infinities).
    OutOfRange,
}

/// The integer value of `num`: an integer or a finite float without fractional part.
fn integer(num: Num) -> Result<i128, ScalarFault> {
    match num {
        Num::Int(i) => Ok(i),
        Num::Float(x) if !x.is_finite() => Err(ScalarFault::OutOfRange),
        Num::Float(x) if x.fract() != 0.0 => Err(ScalarFault::Fraction),
        // Saturates: beyond the range of i128 is beyond every type's. `-0.0` is 0.
        Num::Float(x) => Ok(x as i128),
    }
}

/// `i` as a `T`, if in its range.
fn fit<T: TryFrom<i128>>(i: i128) -> Result<T, ScalarFault> {
    T::try_from(i).map_err(|_| ScalarFault::OutOfRange)
}

/// Appends `num` as one `base` element, little endian, as
/// [`dynamic::fields`](pprz_messages::dynamic::fields) reads it. A `char` is its byte
/// (0 to 255). Floats are rounded to the nearest `float`/`double`; a finite number beyond
/// the range of `float` is refused, NaN and infinities are written as they are.
///
/// # Errors
/// The number does not fit the type; nothing is appended then.
pub(crate) fn put_scalar(base: BaseType, num: Num, out: &mut Vec<u8>) -> Result<(), ScalarFault> {
    match base {
        BaseType::U8 | BaseType::Char => out.push(fit::<u8>(integer(num)?)?),
        BaseType::I8 => out.extend(fit::<i8>(integer(num)?)?.to_le_bytes()),
        BaseType::U16 => out.extend(fit::<u16>(integer(num)?)?.to_le_bytes()),
        BaseType::I16 => out.extend(fit::<i16>(integer(num)?)?.to_le_bytes()),
        BaseType::U32 => out.extend(fit::<u32>(integer(num)?)?.to_le_bytes()),
        BaseType::I32 => out.extend(fit::<i32>(integer(num)?)?.to_le_bytes()),
        BaseType::U64 => out.extend(fit::<u64>(integer(num)?)?.to_le_bytes()),
        BaseType::I64 => out.extend(fit::<i64>(integer(num)?)?.to_le_bytes()),
        BaseType::F32 => {
            // Straight to `f32` (no double rounding through `f64`); an `i128` always fits.
            let v = match num {
                Num::Int(i) => i as f32,
                Num::Float(x) => x as f32,
            };
            if v.is_infinite() && matches!(num, Num::Float(x) if x.is_finite()) {
                return Err(ScalarFault::OutOfRange);
            }
            out.extend(v.to_le_bytes());
        }
        BaseType::F64 => {
            let v = match num {
                Num::Int(i) => i as f64,
                Num::Float(x) => x,
            };
            out.extend(v.to_le_bytes());
        }
    }
    Ok(())
}

/// A JSON number as a [`Num`]: integers exactly.
fn json_num(n: &Number) -> Num {
    if let Some(u) = n.as_u64() {
        Num::Int(u.into())
    } else if let Some(i) = n.as_i64() {
        Num::Int(i.into())
    } else {
        Num::Float(n.as_f64().unwrap_or(f64::NAN))
    }
}

/// Parses JSON text `text` and then the message, as [`parse_message`].
///
/// The text is refused unread when longer than [`MAX_TEXT`]; `serde_json` refuses
/// nesting deeper than 128 levels. When a key appears twice, the last one counts.
///
/// ```
/// use pprz_ground::{json, set::RuntimeSet};
/// let set = RuntimeSet::parse("m.xml", r#"<protocol><msg_class name="datalink" id="2">
///     <message name="SETTING" id="4"><field name="index" type="uint8"/>
///     <field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
///     </msg_class></protocol>"#).unwrap();
/// let setting = set.find_by_name("datalink", "SETTING").unwrap();
/// let p = json::parse_message_str(setting, r#"{"index": 2, "ac_id": 7, "value": 1.5}"#);
/// assert_eq!(p.unwrap(), [2, 7, 0, 0, 0xC0, 0x3F]);
/// let e = json::parse_message_str(setting, r#"{"index": 2, "ac_id": 7.5, "value": 1}"#);
/// assert_eq!(e.unwrap_err().to_string(), "field ac_id (uint8) takes an integer, not 7.5");
/// ```
///
/// # Errors
/// Text too long, not JSON, or as [`parse_message`].
pub fn parse_message_str(desc: &MessageDescriptor<'_>, text: &str) -> Result<Vec<u8>, ParseError> {
    if text.len() > MAX_TEXT {
        return Err(ParseError::TextTooLong {
            len: text.len(),
            max: MAX_TEXT,
        });
    }
    let json: Json = serde_json::from_str(text).map_err(|e| ParseError::Syntax(e.to_string()))?;
    parse_message(desc, &json)
}

/// The payload of message `desc` given as a JSON object: the inverse of
/// [`message`](super::message), whose output it reads back byte for byte (except text
/// that was not UTF-8, and the NUL bytes that end a `char[]`/`string`, which `message`
/// does not show).
///
/// * The value is a JSON object with a key per field of the message, all required, in
///   any order. The converted values [`message`](super::message) adds ([`alt_key`]) may
///   be there too, whatever their value: they are ignored, the field's own value is the
///   one written. Any other key is refused.
/// * Integer fields (`uint8` to `int64`) take a JSON integer in the type's range, or a
///   number without fractional part (`3.0`, `-0`, `1e3`). An integer field or array
///   with `values` labels also takes a label (exact, case included) for its index.
///   Booleans, strings, `null`, fractions and numbers out of range are refused.
/// * `float` and `double` take any JSON number (JSON has no NaN nor infinity), rounded to
///   the nearest value of the type; a number beyond the range of `float` is refused.
/// * A `char` takes a string of one character from U+0000 to U+00FF (the byte
///   [`message`](super::message) shows as that character), or an integer 0 to 255.
/// * `char[N]`, `char[]` and `string` take a JSON string, written as its UTF-8 bytes
///   (`\u0000` included): at most `N` bytes for `char[N]`, padded with NUL bytes; a
///   `char[]`/`string` is its length byte, then its bytes.
/// * Other arrays take a JSON array of numbers as above: exactly `N` items for `T[N]`,
///   and for `T[]` as many as fit in the payload (written as the count, then the items).
/// * The payload is at most 255 bytes, the most a length byte counts; a transport may
///   carry fewer (247 in PPRZ v2) and refuses a longer frame itself.
///
/// Payloads are little endian, as [`dynamic::fields`](pprz_messages::dynamic::fields)
/// decodes them. No input panics, and the work is bounded by the payload: an array too
/// long is refused before its items are read.
///
/// ```
/// use pprz_ground::{json, set::RuntimeSet};
/// use serde_json::json;
/// let set = RuntimeSet::parse("m.xml", r#"<protocol><msg_class name="datalink" id="2">
///     <message name="M" id="1"><field name="mode" type="uint8" values="OFF|ON"/>
///     <field name="alt" type="int32" unit="mm" alt_unit="m"/><field name="t" type="char[]"/>
///     </message></msg_class></protocol>"#).unwrap();
/// let m = set.find_by_name("datalink", "M").unwrap();
/// let p = json::parse_message(m, &json!({"mode": "ON", "alt": 1500, "alt_alt": 1.5, "t": "hi"}));
/// assert_eq!(p.unwrap(), [1, 0xDC, 0x05, 0, 0, 2, b'h', b'i']);
/// // What `message` writes is read back.
/// let text = json::message(m, &[1, 0xDC, 0x05, 0, 0, 2, b'h', b'i']).unwrap();
/// assert_eq!(json::parse_message_str(m, &text).unwrap(), [1, 0xDC, 0x05, 0, 0, 2, b'h', b'i']);
/// ```
///
/// # Errors
/// The first problem met, as a [`ParseError`] that names the key or field (and array
/// item) and the value given: not an object, then an unknown key, then the fields in
/// the message's order (missing, wrong JSON type, wrong length, payload too long,
/// then each number: fraction, out of range, unknown label).
pub fn parse_message(desc: &MessageDescriptor<'_>, json: &Json) -> Result<Vec<u8>, ParseError> {
    let Json::Object(obj) = json else {
        return Err(ParseError::NotAnObject {
            found: describe(json),
        });
    };
    check_keys(desc, obj)?;
    // The smallest size of the fields after each one, to refuse a payload too long at
    // the field that makes it so.
    let mut rest = vec![0usize; desc.fields.len() + 1];
    for (i, f) in desc.fields.iter().enumerate().rev() {
        rest[i] = rest[i + 1].saturating_add(min_size(f.ty));
    }
    let mut out = Vec::with_capacity(MAX_PAYLOAD);
    for (i, f) in desc.fields.iter().enumerate() {
        let v = obj
            .get(f.name)
            .ok_or_else(|| ParseError::MissingField(f.name.to_owned()))?;
        put_field(f, v, &mut out, rest[i + 1])?;
    }
    Ok(out)
}

/// Smallest size of a field on the wire, without overflow whatever the descriptor says.
fn min_size(ty: FieldType) -> usize {
    match ty {
        FieldType::Scalar(b) => b.size(),
        FieldType::Array(b, n) => b.size().saturating_mul(n),
        FieldType::Vector(_) => 1,
    }
}

/// Refuses a key that is neither a field nor a converted value.
fn check_keys(desc: &MessageDescriptor<'_>, obj: &Map<String, Json>) -> Result<(), ParseError> {
    let alt: Vec<String> = (0..desc.fields.len())
        .filter_map(|i| alt_key(desc, i))
        .collect();
    for key in obj.keys() {
        if !desc.fields.iter().any(|f| f.name == key) && !alt.contains(key) {
            return Err(ParseError::UnknownKey(key.clone()));
        }
    }
    Ok(())
}

/// Appends field `f` given as `v`; `after` is the smallest size of the fields after it.
fn put_field(
    f: &FieldDescriptor<'_>,
    v: &Json,
    out: &mut Vec<u8>,
    after: usize,
) -> Result<(), ParseError> {
    let wrong = |expected| ParseError::WrongType {
        field: f.name.to_owned(),
        ty: f.ty.to_string(),
        expected,
        found: describe(v),
    };
    // The size of the field as given, once its shape is known.
    let fits = |out: &Vec<u8>, size: usize| {
        let needed = out.len().saturating_add(size).saturating_add(after);
        if needed > MAX_PAYLOAD {
            Err(ParseError::PayloadTooLong {
                field: f.name.to_owned(),
                needed,
                max: MAX_PAYLOAD,
            })
        } else {
            Ok(())
        }
    };
    match f.ty {
        FieldType::Array(BaseType::Char, n) => {
            let s = v.as_str().ok_or_else(|| wrong("a string"))?;
            if s.len() > n {
                return Err(ParseError::TextTooLongForField {
                    field: f.name.to_owned(),
                    max: n,
                    actual: s.len(),
                });
            }
            fits(out, n)?;
            out.extend(s.as_bytes());
            out.resize(out.len() + n - s.len(), 0);
        }
        FieldType::Vector(BaseType::Char) => {
            let s = v.as_str().ok_or_else(|| wrong("a string"))?;
            fits(out, 1 + s.len())?;
            // At most 254 bytes once it fits.
            out.push(u8::try_from(s.len()).unwrap_or(u8::MAX));
            out.extend(s.as_bytes());
        }
        FieldType::Scalar(base) => {
            fits(out, base.size())?;
            put_element(f, base, None, v, out)?;
        }
        FieldType::Array(base, n) => {
            let items = v.as_array().ok_or_else(|| wrong("an array"))?;
            if items.len() != n {
                return Err(ParseError::WrongLength {
                    field: f.name.to_owned(),
                    expected: n,
                    actual: items.len(),
                });
            }
            fits(out, min_size(f.ty))?;
            for (i, item) in items.iter().enumerate() {
                put_element(f, base, Some(i), item, out)?;
            }
        }
        FieldType::Vector(base) => {
            let items = v.as_array().ok_or_else(|| wrong("an array"))?;
            fits(
                out,
                1usize.saturating_add(items.len().saturating_mul(base.size())),
            )?;
            out.push(u8::try_from(items.len()).unwrap_or(u8::MAX));
            for (i, item) in items.iter().enumerate() {
                put_element(f, base, Some(i), item, out)?;
            }
        }
    }
    Ok(())
}

/// Appends one number of field `f` (element `index` of an array), of type `base`.
fn put_element(
    f: &FieldDescriptor<'_>,
    base: BaseType,
    index: Option<usize>,
    v: &Json,
    out: &mut Vec<u8>,
) -> Result<(), ParseError> {
    let field = || match index {
        Some(i) => format!("{}[{i}]", f.name),
        None => f.name.to_owned(),
    };
    let labelled = base.is_integer() && !f.values.is_empty();
    let expected = match base {
        BaseType::F32 | BaseType::F64 => "a number",
        BaseType::Char => "one character U+0000 to U+00FF or an integer 0 to 255",
        _ if labelled => "an integer or one of its labels",
        _ => "an integer",
    };
    let num = match v {
        Json::Number(n) => Some(json_num(n)),
        Json::String(s) if base == BaseType::Char => {
            let mut chars = s.chars();
            match (chars.next().map(u32::from), chars.next()) {
                (Some(c), None) if c <= 0xFF => Some(Num::Int(c.into())),
                _ => None,
            }
        }
        Json::String(s) if labelled => match f.values.iter().position(|l| l == s) {
            Some(i) => Some(Num::Int(i as i128)),
            None => {
                return Err(ParseError::UnknownLabel {
                    field: field(),
                    label: s.clone(),
                });
            }
        },
        _ => None,
    };
    let Some(num) = num else {
        return Err(ParseError::WrongType {
            field: field(),
            ty: base.to_string(),
            expected,
            found: describe(v),
        });
    };
    let refused = match num {
        // JSON has no NaN nor infinity: a number that is not finite is out of range.
        Num::Float(x) if !x.is_finite() => ScalarFault::OutOfRange,
        num => match put_scalar(base, num, out) {
            Ok(()) => return Ok(()),
            Err(e) => e,
        },
    };
    let (field, ty, value) = (field(), base.to_string(), describe(v));
    Err(match refused {
        ScalarFault::Fraction => ParseError::NotAnInteger { field, ty, value },
        ScalarFault::OutOfRange => ParseError::OutOfRange { field, ty, value },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::json::message;
    use crate::set::RuntimeSet;
    use pprz_test_support::rng::Rng;
    use serde_json::json;

    /// Every type and shape: labels, converted values, fixed and variable arrays, text.
    const XML: &str = r#"<protocol>
        <msg_class name="datalink" id="2">
        <message name="ALL" id="1">
          <field name="mode" type="uint8" values="OFF|ON|AUTO"/>
          <field name="i8" type="int8"/>
          <field name="u16" type="uint16"/>
          <field name="i16" type="int16" unit="cm" alt_unit="m"/>
          <field name="u32" type="uint32"/>
          <field name="i32" type="int32" unit="mm" alt_unit="m"/>
          <field name="u64" type="uint64"/>
          <field name="i64" type="int64"/>
          <field name="phi" type="float" unit="rad" alt_unit="deg"/>
          <field name="d" type="double"/>
          <field name="c" type="char"/>
          <field name="acc" type="int16[3]" unit="cm" alt_unit="m"/>
          <field name="modes" type="uint8[2]" values="A|B"/>
          <field name="bytes" type="uint8[]"/>
          <field name="name" type="char[6]"/>
          <field name="text" type="char[]"/>
          <field name="fs" type="float[]" unit="rad" alt_unit="deg"/>
          <field name="ds" type="double[2]"/>
          <field name="last" type="int64[]"/>
        </message>
        <message name="SETTING" id="4"><field name="index" type="uint8"/>
          <field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
        <message name="PING" id="8"/>
        <message name="BIG" id="9"><field name="a" type="double[15]"/><field name="b" type="double[]"/></message>
        </msg_class>
        <msg_class name="ground" id="3">
        <message name="NAMED" id="1"><field name="s" type="string"/><field name="x" type="uint8"/></message>
        </msg_class></protocol>"#;

    fn set() -> RuntimeSet {
        RuntimeSet::parse("all.xml", XML).unwrap()
    }

    fn desc<'a>(set: &'a RuntimeSet, class: &str, name: &str) -> &'a MessageDescriptor<'static> {
        set.find_by_name(class, name).unwrap()
    }

    /// A random number of `base`: any bit pattern but NaN and infinities (which have no
    /// JSON form), often a value at an edge.
    fn random_number(rng: &mut Rng, base: BaseType, out: &mut Vec<u8>) {
        const F64_EDGES: [f64; 8] = [
            -0.0,
            f64::MAX,
            f64::MIN,
            f64::MIN_POSITIVE,
            5e-324,
            1e300,
            -1.5e19,
            0.1,
        ];
        match base {
            BaseType::F32 => loop {
                let v = if rng.chance(10) {
                    F64_EDGES[rng.below(8)] as f32
                } else {
                    f32::from_bits(rng.next_u64() as u32)
                };
                if v.is_finite() {
                    break out.extend(v.to_le_bytes());
                }
            },
            BaseType::F64 => loop {
                let v = if rng.chance(10) {
                    F64_EDGES[rng.below(8)]
                } else {
                    f64::from_bits(rng.next_u64())
                };
                if v.is_finite() {
                    break out.extend(v.to_le_bytes());
                }
            },
            b => {
                let bits = match rng.below(4) {
                    0 => 0,
                    1 => u64::MAX,
                    2 => u64::MAX >> 1,
                    _ => rng.next_u64(),
                };
                out.extend(&bits.to_le_bytes()[..b.size()]);
            }
        }
    }

    /// Random UTF-8 text of at most `max` bytes, with controls, NUL, quotes, escapes,
    /// bidi overrides and characters of 2, 3 and 4 bytes.
    fn random_text(rng: &mut Rng, max: usize) -> Vec<u8> {
        const CHARS: [char; 13] = [
            'a', 'Z', ' ', '\0', '\n', '\x1b', '"', '\\', '\x7f', 'é', '€', '\u{202e}', '😀',
        ];
        let target = rng.below(max + 1);
        let mut s = String::new();
        for _ in 0..target {
            let c = CHARS[rng.below(CHARS.len())];
            if s.len() + c.len_utf8() <= target {
                s.push(c);
            }
        }
        s.into_bytes()
    }

    /// A random well-formed payload of `desc` that has a JSON form read back exactly:
    /// text is UTF-8 and a `char[]` does not end with NUL. `None` if no payload fits.
    fn random_payload(rng: &mut Rng, desc: &MessageDescriptor<'_>) -> Option<Vec<u8>> {
        let mut budget = MAX_PAYLOAD.checked_sub(desc.min_len())?;
        let mut p = Vec::new();
        for f in desc.fields {
            match f.ty {
                FieldType::Scalar(b) => random_number(rng, b, &mut p),
                FieldType::Array(BaseType::Char, n) => {
                    let t = random_text(rng, n);
                    p.extend(&t);
                    p.resize(p.len() + n - t.len(), 0);
                }
                FieldType::Vector(BaseType::Char) => {
                    let mut t = random_text(rng, budget.min(60));
                    while t.last() == Some(&0) {
                        t.pop();
                    }
                    budget -= t.len();
                    p.push(t.len() as u8);
                    p.extend(t);
                }
                FieldType::Array(b, n) => (0..n).for_each(|_| random_number(rng, b, &mut p)),
                FieldType::Vector(b) => {
                    let count = rng.below((budget / b.size()).min(20) + 1);
                    budget -= count * b.size();
                    p.push(count as u8);
                    (0..count).for_each(|_| random_number(rng, b, &mut p));
                }
            }
        }
        Some(p)
    }

    /// `message` then `parse_message_str` gives `payload` back.
    fn assert_round_trip(desc: &MessageDescriptor<'_>, payload: &[u8]) {
        let text = message(desc, payload).unwrap();
        let back = parse_message_str(desc, &text);
        assert_eq!(back.as_deref(), Ok(payload), "{} {text}", desc.name);
    }

    #[test]
    fn every_type_round_trips() {
        let set = set();
        let mut rng = Rng::new(28);
        for desc in set.set().messages() {
            for _ in 0..500 {
                if let Some(p) = random_payload(&mut rng, desc) {
                    assert_round_trip(desc, &p);
                }
            }
        }
    }

    #[test]
    fn reference_messages_round_trip() {
        let Some(dir) =
            pprz_test_support::reference::locate_for_test("pprz-ground json reference round trip")
        else {
            return;
        };
        let set = RuntimeSet::load(dir.join("messages.xml")).expect("the reference loads");
        let messages = set.set().messages();
        assert!(messages.len() > 100, "{} messages", messages.len());
        let mut rng = Rng::new(7);
        let mut tried = 0;
        for desc in messages {
            for _ in 0..20 {
                if let Some(p) = random_payload(&mut rng, desc) {
                    assert_round_trip(desc, &p);
                    tried += 1;
                }
            }
        }
        assert!(tried > 100 * 20, "{tried}");
    }

    /// A valid ALL message, with every form accepted besides the plain one.
    fn all() -> Json {
        json!({
            "mode": "AUTO", "i8": -128, "u16": 65535.0, "i16": -3, "i16_alt": 999,
            "u32": 4_294_967_295u32, "i32": 1e3, "u64": u64::MAX, "i64": i64::MIN,
            "phi": 0.5, "d": -0.0, "c": "é", "acc": [1, 2.0, -3], "acc_alt": "ignored",
            "modes": ["B", 0], "bytes": [], "name": "ab", "text": "hi\u{0}",
            "fs": [1.5], "ds": [1, -0], "last": [-1]
        })
    }

    fn all_payload() -> Vec<u8> {
        let mut p = vec![2, 0x80, 0xFF, 0xFF, 0xFD, 0xFF, 0xFF, 0xFF, 0xFF, 0xFF];
        p.extend(1000i32.to_le_bytes());
        p.extend(u64::MAX.to_le_bytes());
        p.extend(i64::MIN.to_le_bytes());
        p.extend(0.5f32.to_le_bytes());
        p.extend((-0.0f64).to_le_bytes());
        p.push(0xE9);
        p.extend([1, 0, 2, 0, 0xFD, 0xFF]);
        p.extend([1, 0]);
        p.push(0);
        p.extend(*b"ab\0\0\0\0");
        p.extend([3, b'h', b'i', 0]);
        p.push(1);
        p.extend(1.5f32.to_le_bytes());
        p.extend(1f64.to_le_bytes());
        // `-0` in `json!` is the Rust integer 0.
        p.extend(0f64.to_le_bytes());
        p.push(1);
        p.extend((-1i64).to_le_bytes());
        p
    }

    #[test]
    fn accepted_forms() {
        let set = set();
        let d = desc(&set, "datalink", "ALL");
        assert_eq!(parse_message(d, &all()), Ok(all_payload()));
        // A char as its byte, an integer with its label's index.
        let mut j = all();
        j["c"] = json!(0xE9);
        j["mode"] = json!(2);
        j["modes"] = json!([1, "A"]);
        assert_eq!(parse_message(d, &j), Ok(all_payload()));
        // In JSON text, `-0` keeps its sign for a float.
        let setting = desc(&set, "datalink", "SETTING");
        let p = parse_message_str(setting, r#"{"value": -0, "ac_id": -0, "index": 1e2}"#);
        assert_eq!(p, Ok(vec![100, 0, 0, 0, 0, 0x80]));
        // A key twice: the last one counts.
        let p = parse_message_str(
            setting,
            r#"{"value": 0, "ac_id": 1, "ac_id": 2, "index": 3}"#,
        );
        assert_eq!(p, Ok(vec![3, 2, 0, 0, 0, 0]));
        assert_eq!(
            parse_message_str(desc(&set, "datalink", "PING"), " {} "),
            Ok(vec![])
        );
        let named = desc(&set, "ground", "NAMED");
        assert_eq!(
            parse_message(named, &json!({"s": "€", "x": 1})),
            Ok(vec![3, 0xE2, 0x82, 0xAC, 1])
        );
        // A field named like another field's converted value is that field; the
        // converted value has another key, ignored.
        let s = RuntimeSet::parse(
            "a.xml",
            r#"<protocol><msg_class name="datalink" id="2"><message name="M" id="1">
            <field name="a" type="int32" unit="mm" alt_unit="m"/>
            <field name="a_alt" type="uint8"/></message></msg_class></protocol>"#,
        )
        .unwrap();
        let m = desc(&s, "datalink", "M");
        let j = json!({"a": 5, "a_alt": 6, "a_alt_": 0.005});
        assert_eq!(parse_message(m, &j), Ok(vec![5, 0, 0, 0, 6]));
    }

    #[test]
    fn shared_scalar_encoder() {
        let mut out = Vec::new();
        assert_eq!(
            put_scalar(BaseType::F32, Num::Int(16_777_217), &mut out),
            Ok(())
        );
        assert_eq!(out, 16_777_216f32.to_le_bytes());
        assert_eq!(
            put_scalar(BaseType::F32, Num::Float(1e39), &mut out),
            Err(ScalarFault::OutOfRange)
        );
        // NaN and infinities are written (a command line may give them; JSON cannot).
        assert_eq!(
            put_scalar(BaseType::F32, Num::Float(f64::NAN), &mut out),
            Ok(())
        );
        assert_eq!(
            put_scalar(
                BaseType::U64,
                Num::Float(18_446_744_073_709_551_616.0),
                &mut out
            ),
            Err(ScalarFault::OutOfRange)
        );
        assert_eq!(
            put_scalar(BaseType::I8, Num::Float(f64::INFINITY), &mut out),
            Err(ScalarFault::OutOfRange)
        );
        assert_eq!(
            put_scalar(BaseType::I8, Num::Float(0.5), &mut out),
            Err(ScalarFault::Fraction)
        );
        assert_eq!(out.len(), 8);
    }

    /// The error of ALL with `key` set to `value` (removed when `None`).
    fn refuse(key: &str, value: Option<Json>) -> ParseError {
        let set = set();
        let mut j = all();
        match value {
            Some(v) => j[key] = v,
            None => drop(j.as_object_mut().unwrap().remove(key)),
        }
        parse_message(desc(&set, "datalink", "ALL"), &j).unwrap_err()
    }

    #[test]
    fn every_refusal() {
        let set = set();
        let all_desc = desc(&set, "datalink", "ALL");
        let str_err = |t: &str| parse_message_str(all_desc, t).unwrap_err();
        let cases: Vec<(ParseError, &str)> = vec![
            (
                str_err(&" ".repeat(MAX_TEXT + 1)),
                "JSON text of 65537 bytes, longer than 65536",
            ),
            (str_err("{\"mode\": 1,"), "not JSON: EOF while parsing"),
            (
                parse_message(all_desc, &json!([1, 2])).unwrap_err(),
                "a message is a JSON object, not an array of 2 items",
            ),
            (
                refuse("x\u{1b}[2J\n\u{202e}", Some(json!(1))),
                r#"unknown key "x\x1b[2J\n\u{202e}": neither a field nor a converted value of the message"#,
            ),
            (refuse("d", None), "field d is missing"),
            (
                refuse("u16", Some(json!("3"))),
                r#"field u16 (uint16) takes an integer, not "3""#,
            ),
            (
                refuse("i8", Some(json!(1.5))),
                "field i8 (int8) takes an integer, not 1.5",
            ),
            (
                refuse("u64", Some(json!(18_446_744_073_709_551_616.0))),
                "value 1.8446744073709552e+19 out of the range of field u64 (uint64)",
            ),
            (
                refuse("modes", Some(json!([0, "C"]))),
                r#"field modes[1] has no label "C""#,
            ),
            (
                refuse("acc", Some(json!([1, 2]))),
                "field acc takes 3 items, not 2",
            ),
            (
                refuse("name", Some(json!("abcdeé"))),
                "field name holds at most 6 bytes of text, not 7",
            ),
            (
                refuse("bytes", Some(json!(vec![0; 200]))),
                "payload too long: at least 277 bytes with field bytes, at most 255",
            ),
        ];
        for (e, text) in cases {
            let shown = e.to_string();
            assert!(shown.starts_with(text), "{shown:?} vs {text:?}");
            assert!(!shown.chars().any(escape::is_unsafe), "{shown:?}");
        }
    }

    #[test]
    fn wrong_types_and_ranges() {
        let wrong = |key: &str, v: Json| match refuse(key, Some(v)) {
            ParseError::WrongType { field, .. } => field,
            e => panic!("{key}: {e}"),
        };
        assert_eq!(wrong("mode", json!(true)), "mode");
        assert_eq!(wrong("i8", Json::Null), "i8");
        assert_eq!(wrong("c", json!("ab")), "c");
        assert_eq!(wrong("c", json!("Ā")), "c");
        assert_eq!(wrong("c", json!("")), "c");
        assert_eq!(wrong("acc", json!(5)), "acc");
        assert_eq!(wrong("acc", json!([1, {"a": 1}, 3])), "acc[1]");
        assert_eq!(wrong("name", json!(["a"])), "name");
        assert_eq!(wrong("text", json!(null)), "text");
        assert_eq!(wrong("phi", json!("0.5")), "phi");
        let range = |key: &str, v: Json| match refuse(key, Some(v)) {
            ParseError::OutOfRange { field, ty, .. } => format!("{field} {ty}"),
            e => panic!("{key}: {e}"),
        };
        assert_eq!(range("i8", json!(128)), "i8 int8");
        assert_eq!(range("u16", json!(-1)), "u16 uint16");
        assert_eq!(range("i64", json!(9.3e18)), "i64 int64");
        assert_eq!(range("c", json!(256)), "c char");
        assert_eq!(range("phi", json!(1e39)), "phi float");
        assert_eq!(range("last", json!([0, 1e300])), "last[1] int64");
        assert!(matches!(
            refuse("mode", Some(json!("MANUAL"))),
            ParseError::UnknownLabel { .. }
        ));
    }

    #[test]
    fn hostile_inputs() {
        let set = set();
        let d = desc(&set, "datalink", "ALL");
        // Nesting beyond serde_json's limit, numbers beyond f64.
        let deep = format!("{}{}", "[".repeat(10_000), "]".repeat(10_000));
        assert!(
            matches!(parse_message_str(d, &deep), Err(ParseError::Syntax(e)) if e.contains("recursion"))
        );
        let huge = r#"{"mode": 1e400}"#;
        assert!(matches!(
            parse_message_str(d, huge),
            Err(ParseError::Syntax(_))
        ));
        let setting = desc(&set, "datalink", "SETTING");
        for (text, field) in [
            (
                r#"{"index": 18446744073709551616, "ac_id": 1, "value": 0}"#,
                "index",
            ),
            (r#"{"index": -1e-400, "ac_id": 1e300, "value": 0}"#, "ac_id"),
            (r#"{"index": 0, "ac_id": 1, "value": -3.5e38}"#, "value"),
        ] {
            let e = parse_message_str(setting, text);
            assert!(
                matches!(&e, Err(ParseError::OutOfRange { field: f, .. }) if f == field),
                "{e:?}"
            );
        }
        // Nested values where numbers belong are refused without looking inside.
        let mut nested = json!(1);
        for _ in 0..100 {
            nested = json!([nested]);
        }
        assert!(matches!(
            refuse("acc", Some(json!([nested, 1, 2]))),
            ParseError::WrongType { .. }
        ));
        // Long strings and arrays: refused by size, shown shortened.
        let long = "\u{1b}".repeat(100_000);
        let e = refuse("name", Some(json!(long))).to_string();
        assert!(e.ends_with("not 100000"), "{e}");
        let e = refuse("text", Some(json!(long)));
        assert!(matches!(e, ParseError::PayloadTooLong { needed, .. } if needed > 100_000));
        let e = refuse("i8", Some(json!(long))).to_string();
        assert!(e.len() < 200 && e.contains("(100000 bytes)"), "{e}");
        assert!(!e.chars().any(escape::is_unsafe));
        let e = refuse("bytes", Some(json!(vec![1; 1_000_000])));
        assert!(matches!(e, ParseError::PayloadTooLong { .. }));
        // The payload is checked with the fields that follow: a vector that fits alone
        // but not with them.
        let big = desc(&set, "datalink", "BIG");
        let j = json!({"a": vec![0; 15], "b": vec![0.5; 16]});
        assert_eq!(parse_message(big, &j).map(|p| p.len()), Ok(249));
        let j = json!({"a": vec![0; 15], "b": vec![0.5; 17]});
        assert_eq!(
            parse_message(big, &j),
            Err(ParseError::PayloadTooLong {
                field: "b".into(),
                needed: 257,
                max: 255
            })
        );
        // Control characters in keys and values are escaped in every message.
        let e = refuse("\u{0}\r\u{85}\u{2028}", Some(json!(1))).to_string();
        assert!(!e.chars().any(escape::is_unsafe), "{e}");
        let e = refuse("mode", Some(json!("\u{7}\u{9b}"))).to_string();
        assert!(!e.chars().any(escape::is_unsafe), "{e}");
    }
}
