//! Text forms of decoded messages: one line per message for scripts, and field values
//! with units for the live view.
//!
//! A field is written `name=value`, then, when the field has a unit, ` [unit]`, then,
//! when `messages.xml` gives a display unit (`alt_unit`) and a conversion coefficient
//! (`alt_unit_coef`, or a built-in one), the converted value and that unit:
//!
//! ```text
//! lat=434629172 [1e7deg] 43.4629172 deg
//! alt=152300 [mm] 152.300 m
//! mode=3(3D) [byte_mask]
//! values=1,2,165
//! msg="text sent by the aircraft\n"
//! ```
//!
//! Units that say there is no unit (`none`, `-`, empty) are not printed. Everything
//! that comes from the aircraft or from `messages.xml` goes through
//! [`escape`]: a line never contains a control character, and text
//! fields are quoted so that they cannot forge fields or lines.

use std::fmt::Write as _;

use pprz_messages::dynamic::{self, Value};
use pprz_messages::{BaseType, FieldDescriptor, MessageDescriptor};

use crate::escape;

/// Longest text kept for the fields of one message (the live view shows less); longer
/// text is cut at a character boundary and ends with `...`.
pub const MAX_FIELDS_LEN: usize = 2048;

/// Whether a `unit` attribute names a real unit (not `none`, `-` or empty).
pub fn is_unit(unit: &str) -> bool {
    let u = unit.trim();
    !(u.is_empty() || u == "-" || u.eq_ignore_ascii_case("none"))
}

/// A scalar value as text: numbers as Rust prints them, a `char` quoted and escaped.
fn scalar(value: &Value<'_>) -> String {
    match value {
        Value::Char(c) => escape::quoted(char::from(*c).encode_utf8(&mut [0; 4])),
        v => v.to_string(),
    }
}

/// A value as text: numbers as Rust prints them, arrays comma-separated, text quoted
/// and escaped (trailing NUL padding of a C string is not shown).
pub fn value(value: &Value<'_>) -> String {
    match value {
        Value::Text(t) => escape::quoted(t.to_string().trim_end_matches('\0')),
        Value::Array(a) => {
            let mut s = String::new();
            for (i, v) in a.iter().enumerate() {
                if i > 0 {
                    s.push(',');
                }
                s.push_str(&scalar(&v));
            }
            s
        }
        v => scalar(v),
    }
}

/// Decimal places for a value converted with `coef`: enough to keep the resolution of
/// the raw value (7 for `1e7deg` to `deg`), at least 3, at most 12.
fn alt_precision(coef: f64) -> usize {
    let c = coef.abs();
    if !(c.is_finite() && c > 0.0) {
        return 3;
    }
    let digits = (-c.log10() - 1e-9).ceil();
    if digits > 3.0 {
        (digits as usize).min(12)
    } else {
        3
    }
}

/// The value converted to `alt_unit`, when the field has one with a coefficient and
/// the value is numeric: `43.4629172 deg`, or `0.100,0.200 m` for an array.
fn converted(field: &FieldDescriptor<'_>, value: &Value<'_>) -> Option<String> {
    let alt = field.alt_unit.filter(|u| is_unit(u))?;
    let coef = field.alt_unit_coef?;
    let prec = alt_precision(coef);
    let number = |v: &Value<'_>| -> Option<String> {
        match v {
            Value::Char(_) => None,
            v => Some(format!("{:.prec$}", field.to_alt_unit(v.as_f64()?))),
        }
    };
    let mut s = match value {
        Value::Array(a) if a.base() != BaseType::Char => {
            let parts: Option<Vec<String>> = a.iter().map(|v| number(&v)).collect();
            parts?.join(",")
        }
        Value::Array(_) | Value::Text(_) => return None,
        v => number(v)?,
    };
    if s.is_empty() {
        return None;
    }
    s.push(' ');
    s.push_str(&escape::token(alt));
    Some(s)
}

/// `name=value`, with the enumeration label (`mode=3(3D)`), the unit in brackets
/// (`alt=152300 [mm]`) and the converted value (`alt=152300 [mm] 152.300 m`).
pub fn field(field: &FieldDescriptor<'_>, v: &Value<'_>) -> String {
    let mut s = format!("{}={}", escape::token(field.name), value(v));
    if let Some(label) = v.as_i64().and_then(|i| field.label(i)) {
        let _ = write!(s, "({})", escape::token(label));
    }
    if let Some(unit) = field.unit.filter(|u| is_unit(u)) {
        let _ = write!(s, " [{}]", escape::token(unit));
    }
    if let Some(alt) = converted(field, v) {
        s.push(' ');
        s.push_str(&alt);
    }
    s
}

/// Cuts `s` to at most `max` bytes at a character boundary, ending with `...` when cut.
pub fn truncate(s: &mut String, max: usize) {
    if s.len() <= max {
        return;
    }
    let mut end = max.saturating_sub(3);
    while !s.is_char_boundary(end) {
        end -= 1;
    }
    s.truncate(end);
    s.push_str("...");
}

/// The fields of a payload as `a=1 b=2.5 [V] ...` (at most [`MAX_FIELDS_LEN`] bytes);
/// a payload that does not match the description ends with `<error: ...>` after the
/// fields that did decode.
pub fn fields(desc: &MessageDescriptor<'_>, payload: &[u8]) -> String {
    let mut out = String::new();
    for item in dynamic::fields(desc, payload) {
        if !out.is_empty() {
            out.push(' ');
        }
        match item {
            Ok((f, v)) => out.push_str(&field(f, &v)),
            Err(e) => {
                let _ = write!(out, "<error: {}>", escape::lines(&e.to_string()));
            }
        }
        if out.len() > MAX_FIELDS_LEN {
            break;
        }
    }
    truncate(&mut out, MAX_FIELDS_LEN);
    out
}

/// The line of a known message whose [`fields`] are `body`: `source class NAME body`.
pub fn known_line(source: u8, desc: &MessageDescriptor<'_>, body: &str) -> String {
    let (class, name) = (escape::token(desc.class_name), escape::token(desc.name));
    if body.is_empty() {
        format!("{source} {class} {name}")
    } else {
        format!("{source} {class} {name} {body}")
    }
}

/// One line for a message: `source class NAME fields...`, or, for a message the set
/// does not know, `source class<N> id=<M> unknown message (<len> bytes)`.
pub fn line(
    source: u8,
    class_id: u8,
    msg_id: u8,
    desc: Option<&MessageDescriptor<'_>>,
    payload: &[u8],
) -> String {
    match desc {
        Some(d) => known_line(source, d, &fields(d, payload)),
        None => format!(
            "{source} class{class_id} id={msg_id} unknown message ({} bytes)",
            payload.len()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pprz_messages::FieldType;

    fn desc(fields: &'static [FieldDescriptor<'static>]) -> MessageDescriptor<'static> {
        MessageDescriptor {
            class_id: 1,
            class_name: "telemetry",
            id: 5,
            name: "X",
            priority: 1,
            fields,
        }
    }

    #[test]
    fn units_labels_and_errors() {
        static FIELDS: [FieldDescriptor<'static>; 2] = [
            FieldDescriptor {
                unit: Some("cm"),
                alt_unit: Some("m"),
                alt_unit_coef: Some(0.01),
                ..FieldDescriptor::new("east", FieldType::Scalar(BaseType::I32))
            },
            FieldDescriptor {
                values: &["OFF", "ON"],
                ..FieldDescriptor::new("state", FieldType::Scalar(BaseType::U8))
            },
        ];
        let desc = desc(&FIELDS);
        let payload = [0x10, 0x27, 0, 0, 1];
        assert_eq!(
            line(7, 1, 5, Some(&desc), &payload),
            "7 telemetry X east=10000 [cm] 100.000 m state=1(ON)"
        );
        assert_eq!(
            line(7, 1, 5, Some(&desc), &payload[..3]),
            "7 telemetry X <error: payload truncated: needs at least 4 bytes, got 3>"
        );
        assert_eq!(
            line(7, 1, 99, None, &payload),
            "7 class1 id=99 unknown message (5 bytes)"
        );
    }

    /// Issue: `lat=4346291721e7deg`, `values=...,165none`: the unit glued to the
    /// number, and a `none` unit printed.
    #[test]
    fn value_and_unit_are_separate_and_none_is_not_a_unit() {
        static FIELDS: [FieldDescriptor<'static>; 4] = [
            FieldDescriptor {
                unit: Some("1e7deg"),
                alt_unit: Some("deg"),
                alt_unit_coef: Some(0.000_000_1),
                ..FieldDescriptor::new("lat", FieldType::Scalar(BaseType::I32))
            },
            FieldDescriptor {
                unit: Some("none"),
                ..FieldDescriptor::new("values", FieldType::Vector(BaseType::U8))
            },
            FieldDescriptor {
                unit: Some("rad"),
                alt_unit: Some("deg"),
                alt_unit_coef: Some(57.29578),
                ..FieldDescriptor::new("att", FieldType::Array(BaseType::F32, 2))
            },
            FieldDescriptor {
                unit: Some("-"),
                alt_unit: Some("none"),
                alt_unit_coef: Some(2.0),
                ..FieldDescriptor::new("n", FieldType::Scalar(BaseType::I8))
            },
        ];
        let desc = desc(&FIELDS);
        let mut payload = Vec::new();
        payload.extend(434_629_172i32.to_le_bytes());
        payload.extend([3, 1, 2, 165]);
        payload.extend(0.5f32.to_le_bytes());
        payload.extend((-1.0f32).to_le_bytes());
        payload.push(0xFF);
        assert_eq!(
            fields(&desc, &payload),
            "lat=434629172 [1e7deg] 43.4629172 deg values=1,2,165 \
             att=0.5,-1 [rad] 28.648,-57.296 deg n=-1"
        );
        let f = fields(&desc, &payload);
        assert!(!f.contains("none") && !f.contains("1e7deg43"), "{f}");
    }

    #[test]
    fn text_is_quoted_and_escaped() {
        static FIELDS: [FieldDescriptor<'static>; 3] = [
            FieldDescriptor::new("msg", FieldType::Vector(BaseType::Char)),
            FieldDescriptor::new("name", FieldType::Array(BaseType::Char, 4)),
            FieldDescriptor::new("c", FieldType::Scalar(BaseType::Char)),
        ];
        let desc = desc(&FIELDS);
        let text = b"hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;t\x07";
        let mut payload = vec![text.len() as u8];
        payload.extend_from_slice(text);
        payload.extend_from_slice(b"ab\0\0");
        payload.push(0x1b);
        let l = line(7, 1, 5, Some(&desc), &payload);
        assert_eq!(
            l,
            r#"7 telemetry X msg="hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;t\x07" name="ab" c="\x1b""#
        );
        assert!(!l.chars().any(escape::is_unsafe));
    }

    #[test]
    fn names_units_and_labels_from_the_xml_are_escaped() {
        static FIELDS: [FieldDescriptor<'static>; 1] = [FieldDescriptor {
            unit: Some("m\n7 telemetry FORGED"),
            alt_unit: Some("\x1b[2J"),
            alt_unit_coef: Some(1.0),
            values: &["A B\x07"],
            ..FieldDescriptor::new("f\x1b=", FieldType::Scalar(BaseType::U8))
        }];
        let desc = MessageDescriptor {
            class_name: "tele\u{202e}metry",
            name: "X\r",
            ..desc(&FIELDS)
        };
        let l = line(7, 1, 5, Some(&desc), &[0]);
        assert_eq!(
            l,
            r"7 tele\u{202e}metry X\r f\x1b\x3d=0(A\x20B\x07) [m\n7\x20telemetry\x20FORGED] 0.000 \x1b\x5b2J"
        );
        assert!(!l.chars().any(escape::is_unsafe));
    }

    #[test]
    fn long_fields_are_cut() {
        static FIELDS: [FieldDescriptor<'static>; 1] = [FieldDescriptor::new(
            "v",
            FieldType::Array(BaseType::F64, 30),
        )];
        let desc = desc(&FIELDS);
        let payload: Vec<u8> = (0..30).flat_map(|_| f64::MAX.to_le_bytes()).collect();
        let f = fields(&desc, &payload);
        assert_eq!(f.len(), MAX_FIELDS_LEN);
        assert!(f.ends_with("..."));
        let mut s = "ééé".to_owned();
        truncate(&mut s, 5);
        assert_eq!(s, "é...");
        let mut s = "éééé".to_owned();
        truncate(&mut s, 7);
        assert_eq!(s, "éé...");
    }
}
