//! JSON forms of decoded messages and their JSON Schemas, generated from the
//! `messages.xml` in use: what viewers (Foxglove, Lichtblick) plot and what MCAP
//! recordings hold ([`viewer`](crate::viewer)).
//!
//! A message is one JSON object with a key per field, in the file's order:
//!
//! * integers as JSON integers, `float` and `double` as JSON numbers written as the
//!   monitor's `--lines` output writes them (the shortest text that reads back as the
//!   same value; `null` for NaN and infinities);
//! * numeric arrays as JSON arrays;
//! * `char[N]`, `char[]` and `string` fields as JSON strings (without the NUL padding of a
//!   C string; bytes that are not UTF-8 become U+FFFD), a `char` as a one-character string;
//! * where the field has a display unit (`alt_unit`) and a coefficient, a second key,
//!   [`alt_key`] (`alt_alt` for `alt`), with the value converted (element by element for
//!   an array), as the monitor's text form shows it.
//!
//! The schema names every key with its JSON type, array bounds, and a description that
//! gives the unit, the `values` labels and the display unit.
//!
//! Names come from the file, which the loader accepts only as identifiers; topics and
//! schema names are escaped anyway ([`topic_part`]), and every text (units, labels) is
//! escaped as JSON, so a hostile file can neither break a topic nor a schema. Sizes are
//! bounded by the payload (at most 255 bytes), whatever the file declares.
//!
//! [`parse_message`] is the inverse of [`message`]: it reads such an object back into a
//! payload, refusing anything that does not fit the message with a [`ParseError`].

use std::fmt::Write as _;

use pprz_messages::DecodeError;
use pprz_messages::dynamic::{self, Value};
use pprz_messages::{BaseType, FieldDescriptor, FieldType, MessageDescriptor};
use serde_json::{Map, Value as Json, json};

use crate::format::is_unit;

pub(crate) mod parse;

pub use parse::{MAX_TEXT, ParseError, parse_message, parse_message_str};

/// The JSON Schema dialect of every schema.
pub const DIALECT: &str = "https://json-schema.org/draft/2020-12/schema";

/// Longest payload of a frame: bounds the items of a variable-length array.
const MAX_PAYLOAD: usize = 255;

/// A name as a part of a topic or schema name: ASCII letters, digits, `_` and `-` as
/// they are, every other byte as `%XX` (a `/` in a name cannot add a level).
pub fn topic_part(name: &str) -> String {
    let mut out = String::with_capacity(name.len());
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || b == b'_' || b == b'-' {
            out.push(char::from(b));
        } else {
            let _ = write!(out, "%{b:02X}");
        }
    }
    out
}

/// The topic of message `desc` from aircraft `ac_id`: `/ac/<id>/<class>/<MESSAGE>`.
pub fn topic(ac_id: u8, desc: &MessageDescriptor<'_>) -> String {
    format!(
        "/ac/{ac_id}/{}/{}",
        topic_part(desc.class_name),
        topic_part(desc.name)
    )
}

/// The schema name of message `desc`: `pprz.<class>.<MESSAGE>`.
pub fn schema_name(desc: &MessageDescriptor<'_>) -> String {
    format!(
        "pprz.{}.{}",
        topic_part(desc.class_name),
        topic_part(desc.name)
    )
}

/// Whether field `f` gets a converted value: a display unit and a coefficient, on a
/// numeric field.
fn has_alt(f: &FieldDescriptor<'_>) -> bool {
    f.alt_unit.is_some_and(is_unit)
        && f.alt_unit_coef.is_some_and(f64::is_finite)
        && !matches!(f.ty.base(), BaseType::Char)
}

/// The key of field `index`'s converted value: `<name>_alt`, with more `_` while that
/// names another field of the message. `None` if the field has no converted value.
pub fn alt_key(desc: &MessageDescriptor<'_>, index: usize) -> Option<String> {
    let f = desc.fields.get(index)?;
    if !has_alt(f) {
        return None;
    }
    let mut key = format!("{}_alt", f.name);
    let taken = |k: &str| {
        desc.fields.iter().any(|o| o.name == k)
            || desc.fields[..index]
                .iter()
                .any(|o| has_alt(o) && k.strip_suffix("_alt") == Some(o.name))
    };
    while taken(&key) {
        key.push('_');
    }
    Some(key)
}

/// The JSON type of a scalar of `base`.
fn scalar_schema(base: BaseType) -> Json {
    match base {
        BaseType::F32 | BaseType::F64 => json!({ "type": ["number", "null"] }),
        BaseType::Char => json!({ "type": "string", "maxLength": 1 }),
        _ => json!({ "type": "integer" }),
    }
}

/// The schema of a field's raw value.
fn field_schema(f: &FieldDescriptor<'_>) -> Json {
    let base = f.ty.base();
    let size = base.size().max(1);
    let mut s = match f.ty {
        FieldType::Scalar(b) => scalar_schema(b),
        FieldType::Array(BaseType::Char, _) | FieldType::Vector(BaseType::Char) => {
            json!({ "type": "string" })
        }
        FieldType::Array(b, n) => {
            let n = n.min(MAX_PAYLOAD / size);
            json!({ "type": "array", "items": scalar_schema(b), "minItems": n, "maxItems": n })
        }
        FieldType::Vector(b) => {
            json!({ "type": "array", "items": scalar_schema(b), "maxItems": MAX_PAYLOAD / size })
        }
    };
    s["description"] = Json::String(field_description(f));
    s
}

/// A field's description: its type, unit, labels and display unit.
fn field_description(f: &FieldDescriptor<'_>) -> String {
    let mut d = f.ty.to_string();
    if let Some(unit) = f.unit.filter(|u| is_unit(u)) {
        let _ = write!(d, ", unit: {unit}");
    }
    if !f.values.is_empty() {
        d.push_str(", values: ");
        for (i, label) in f.values.iter().enumerate() {
            if i > 0 {
                d.push_str(", ");
            }
            let _ = write!(d, "{i}={label}");
        }
    }
    if has_alt(f)
        && let (Some(alt), Some(coef)) = (f.alt_unit, f.alt_unit_coef)
    {
        let _ = write!(d, ", display unit: {alt} (x{coef})");
    }
    d
}

/// The JSON Schema of message `desc` (a JSON text).
pub fn schema(desc: &MessageDescriptor<'_>) -> String {
    let mut properties = Map::new();
    let mut required = Vec::new();
    for (i, f) in desc.fields.iter().enumerate() {
        properties.insert(f.name.to_owned(), field_schema(f));
        required.push(Json::String(f.name.to_owned()));
        if let Some(key) = alt_key(desc, i) {
            let items = json!({ "type": ["number", "null"] });
            let mut s = match f.ty {
                FieldType::Scalar(_) => items,
                _ => json!({ "type": "array", "items": items }),
            };
            let unit = f.alt_unit.unwrap_or_default();
            let coef = f.alt_unit_coef.unwrap_or_default();
            s["description"] = Json::String(format!("{} in {unit} ({} x{coef})", f.name, f.name));
            properties.insert(key, s);
        }
    }
    json!({
        "$schema": DIALECT,
        "title": schema_name(desc),
        "description": format!(
            "Paparazzi message {} (class {}, id {}, priority {})",
            desc.name, desc.class_name, desc.id, desc.priority
        ),
        "type": "object",
        "properties": properties,
        "required": required,
        "additionalProperties": false,
    })
    .to_string()
}

/// Writes a number as the monitor's text form does (`Display`: shortest text that
/// reads back as the same value, no exponent), `null` when not finite.
fn write_float(out: &mut String, v: f64, single: bool) {
    if !v.is_finite() {
        out.push_str("null");
    } else if single {
        let _ = write!(out, "{}", v as f32);
    } else {
        let _ = write!(out, "{v}");
    }
}

/// Writes a JSON string.
fn write_str(out: &mut String, s: &str) {
    // Serializing a `str` cannot fail.
    out.push_str(&serde_json::to_string(s).unwrap_or_default());
}

/// Writes a scalar value.
fn write_scalar(out: &mut String, v: &Value<'_>) {
    match *v {
        Value::F32(x) => write_float(out, f64::from(x), true),
        Value::F64(x) => write_float(out, x, false),
        Value::Char(c) => write_str(out, char::from(c).encode_utf8(&mut [0; 4])),
        ref v => {
            let _ = write!(out, "{v}");
        }
    }
}

/// Writes a value converted to the field's display unit.
fn write_alt(out: &mut String, f: &FieldDescriptor<'_>, v: &Value<'_>) {
    let one = |out: &mut String, v: &Value<'_>| match v.as_f64() {
        Some(x) => write_float(out, f.to_alt_unit(x), false),
        None => out.push_str("null"),
    };
    match v {
        Value::Array(a) => {
            out.push('[');
            for (i, e) in a.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                one(out, &e);
            }
            out.push(']');
        }
        v => one(out, v),
    }
}

/// The JSON object of a payload of message `desc`.
///
/// # Errors
/// The payload does not match the description (a malformed message has no JSON form).
pub fn message(desc: &MessageDescriptor<'_>, payload: &[u8]) -> Result<String, DecodeError> {
    dynamic::check(desc, payload)?;
    let mut out = String::with_capacity(16 + payload.len() * 8);
    out.push('{');
    for (i, item) in dynamic::fields(desc, payload).enumerate() {
        let (f, v) = item?;
        if i > 0 {
            out.push(',');
        }
        write_str(&mut out, f.name);
        out.push(':');
        match &v {
            Value::Text(t) => write_str(&mut out, t.to_string().trim_end_matches('\0')),
            Value::Array(a) => {
                out.push('[');
                for (j, e) in a.iter().enumerate() {
                    if j > 0 {
                        out.push(',');
                    }
                    write_scalar(&mut out, &e);
                }
                out.push(']');
            }
            v => write_scalar(&mut out, v),
        }
        if let Some(key) = alt_key(desc, i) {
            out.push(',');
            write_str(&mut out, &key);
            out.push(':');
            write_alt(&mut out, f, &v);
        }
    }
    out.push('}');
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::set::RuntimeSet;

    fn set(xml_fields: &str) -> RuntimeSet {
        RuntimeSet::parse(
            "m.xml",
            &format!(
                r#"<protocol><msg_class name="telemetry" id="1">
                <message name="M" id="5">{xml_fields}</message></msg_class></protocol>"#
            ),
        )
        .unwrap()
    }

    fn parse(s: &str) -> Json {
        serde_json::from_str(s).unwrap_or_else(|e| panic!("{e}: {s}"))
    }

    #[test]
    fn values_units_labels_and_converted_values() {
        let s = set(
            r#"<field name="phi" type="float" unit="rad" alt_unit="deg"/>
            <field name="alt" type="int32" unit="mm" alt_unit="m"/>
            <field name="mode" type="uint8" values="OFF|ON"/>
            <field name="acc" type="int16[3]" unit="cm" alt_unit="m"/>
            <field name="md5" type="uint8[]"/>
            <field name="name" type="char[4]"/>"#,
        );
        let d = s.find(1, 5).unwrap();
        let mut p = Vec::new();
        p.extend(0.1f32.to_le_bytes());
        p.extend(152_300i32.to_le_bytes());
        p.push(1);
        for v in [1i16, -2, 300] {
            p.extend(v.to_le_bytes());
        }
        p.extend([2, 7, 9]);
        p.extend(*b"ab\0\0");
        let text = message(d, &p).unwrap();
        assert!(
            text.starts_with(r#"{"phi":0.1,"phi_alt":5.72957"#),
            "{text}"
        );
        let j = parse(&text);
        assert_eq!(j["alt"], 152300);
        assert_eq!(j["alt_alt"], 152.3);
        assert_eq!(j["mode"], 1);
        assert_eq!(j["acc"], json!([1, -2, 300]));
        assert_eq!(j["acc_alt"], json!([0.01, -0.02, 3]));
        assert_eq!(j["md5"], json!([7, 9]));
        assert_eq!(j["name"], "ab");
        let sc = parse(&schema(d));
        assert_eq!(sc["title"], "pprz.telemetry.M");
        let props = &sc["properties"];
        assert_eq!(props["mode"]["description"], "uint8, values: 0=OFF, 1=ON");
        assert!(
            props["alt"]["description"]
                .as_str()
                .unwrap()
                .contains("unit: mm")
        );
        assert_eq!(props["acc"]["maxItems"], 3);
        assert_eq!(props["md5"]["maxItems"], 255);
        assert_eq!(props["alt_alt"]["type"], json!(["number", "null"]));
        // The raw fields are required (the converted ones are always there too).
        assert_eq!(sc["required"].as_array().unwrap().len(), 6);
        // Every key of the message is in the schema, and every required key in the message.
        for k in j.as_object().unwrap().keys() {
            assert!(props.get(k).is_some(), "{k}");
        }
    }

    #[test]
    fn non_finite_floats_are_null_and_text_is_escaped() {
        let s = set(r#"<field name="x" type="double"/><field name="t" type="string"/>"#);
        let d = s.find(1, 5).unwrap();
        let mut p = f64::NAN.to_le_bytes().to_vec();
        p.push(5);
        p.extend(b"a\"\x1b\n\xff");
        let j = parse(&message(d, &p).unwrap());
        assert_eq!(j["x"], Json::Null);
        assert_eq!(j["t"], "a\"\u{1b}\n\u{fffd}");
    }

    #[test]
    fn the_largest_arrays_stay_small() {
        let s = set(r#"<field name="a" type="double[30]" unit="rad" alt_unit="deg"/>"#);
        let d = s.find(1, 5).unwrap();
        let p: Vec<u8> = (0..30)
            .flat_map(|i| (-1e300 / f64::from(i + 1)).to_le_bytes())
            .collect();
        let text = message(d, &p).unwrap();
        // 30 values and 30 converted ones, each written in full (no exponent: at most
        // about 330 characters for a double): bounded by the payload, whatever the file.
        assert!(text.len() < 30 * 2 * 330 + 32, "{}", text.len());
        assert!(parse(&text)["a"].as_array().unwrap().len() == 30);
        let s = set(r#"<field name="v" type="int8[]"/>"#);
        let d = s.find(1, 5).unwrap();
        let mut p = vec![246u8];
        p.extend([0x80; 246]);
        let j = parse(&message(d, &p).unwrap());
        assert_eq!(j["v"].as_array().unwrap().len(), 246);
        assert_eq!(parse(&schema(d))["properties"]["v"]["maxItems"], 255);
    }

    #[test]
    fn malformed_payloads_have_no_json() {
        let s = set(r#"<field name="x" type="int32"/>"#);
        assert!(message(s.find(1, 5).unwrap(), &[1, 2]).is_err());
    }

    #[test]
    fn alt_keys_do_not_collide_with_fields() {
        let s = set(r#"<field name="a" type="int32" unit="mm" alt_unit="m"/>
            <field name="a_alt" type="int32"/>"#);
        let d = s.find(1, 5).unwrap();
        assert_eq!(alt_key(d, 0).as_deref(), Some("a_alt_"));
        assert_eq!(alt_key(d, 1), None);
        let j = parse(&message(d, &[0; 8]).unwrap());
        assert_eq!(j.as_object().unwrap().len(), 3);
    }

    #[test]
    fn hostile_names_cannot_break_topics() {
        assert_eq!(topic_part("GPS_INT"), "GPS_INT");
        assert_eq!(topic_part("a/../b c"), "a%2F%2E%2E%2Fb%20c");
        assert_eq!(topic_part("é"), "%C3%A9");
    }

    #[test]
    fn hostile_units_and_labels_stay_inside_the_schema() {
        let s = set(
            r#"<field name="x" type="uint8" unit="&quot;},{&quot;a" values="&quot;|\|&#10;"/>"#,
        );
        let d = s.find(1, 5).unwrap();
        let sc = parse(&schema(d));
        assert_eq!(sc["properties"].as_object().unwrap().len(), 1);
        let desc = sc["properties"]["x"]["description"].as_str().unwrap();
        assert!(desc.contains("unit: \"},{\"a"), "{desc}");
    }
}
