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
fn name(s: &str) -> String {
    escape::lines(s).replace('\n', "\\n")
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::TextTooLong { len, max } => {
                write!(f, "JSON text of {len} bytes, longer than {max}")
            }
            Self::Syntax(e) => write!(f, "not JSON: {}", name(e)),
            Self::NotAnObject { found } => write!(f, "a message is a JSON object, not {found}"),
            Self::UnknownKey(k) => write!(
                f,
                "unknown key {}: neither a field nor a converted value of the message",
                escape::quoted(k)
            ),
            Self::MissingField(n) => write!(f, "field {} is missing", name(n)),
            Self::WrongType {
                field,
                ty,
                expected,
                found,
            } => write!(
                f,
                "field {} ({}) takes {expected}, not {found}",
                name(field),
                name(ty)
            ),
            Self::NotAnInteger { field, ty, value } => write!(
                f,
                "field {} ({}) takes an integer, not {value}",
                name(field),
                name(ty)
            ),
            Self::OutOfRange { field, ty, value } => write!(
                f,
                "value {value} out of the range of field {} ({})",
                name(field),
                name(ty)
            ),
            Self::UnknownLabel { field, label } => write!(
                f,
                "field {} has no label {}",
                name(field),
                escape::quoted(label)
            ),
            Self::WrongLength {
                field,
                expected,
                actual,
            } => write!(
                f,
                "field {} takes {expected} items, not {actual}",
                name(field)
            ),
            Self::TextTooLongForField { field, max, actual } => write!(
                f,
                "field {} holds at most {max} bytes of text, not {actual}",
                name(field)
            ),
            Self::PayloadTooLong { field, needed, max } => write!(
                f,
                "payload too long: at least {needed} bytes with field {}, at most {max}",
                name(field)
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
///   be there and are ignored: the field's own value is the one written. Any other key
///   is refused.
/// * Integer fields (`uint8` to `int64`) take a JSON integer in the type's range, or a
///   number without fractional part (`3.0`, `-0`, `1e3`). A field with `values` labels
///   also takes one of its labels, for the label's index.
/// * `float` and `double` take any JSON number (JSON has no NaN nor infinity), rounded to
///   the type; a number beyond the range of `float` is refused.
/// * A `char` takes a string of one character from U+0000 to U+00FF (the byte
///   [`message`](super::message) shows as that character), or an integer 0 to 255.
/// * `char[N]`, `char[]` and `string` take a JSON string, written as its UTF-8 bytes:
///   at most `N` bytes for `char[N]`, padded with NUL bytes; a `char[]`/`string` is its
///   length byte then its bytes.
/// * Other arrays take a JSON array of such numbers: exactly `N` items for `T[N]`, and
///   for `T[]` as many as fit in the payload (written as the count, then the items).
/// * The payload is at most 255 bytes, the most a frame carries.
///
/// Payloads are little endian, as [`dynamic::fields`](pprz_messages::dynamic::fields)
/// decodes them. No input panics; every refusal names the field (or key) and the value.
///
/// # Errors
/// The first field or key refused, in the order of the list above.
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
            fits(out, 1usize.saturating_add(items.len().saturating_mul(base.size())))?;
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
}
