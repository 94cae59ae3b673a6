//! Text forms of decoded messages: one line per message for scripts, and field values
//! with units for the live view.

use std::fmt::Write as _;

use pprz_messages::dynamic::{self, Value};
use pprz_messages::{FieldDescriptor, MessageDescriptor};

/// `field=value` with the enumeration label (`mode=3(3D)`) and the display unit
/// (`alt=152300mm[152.300m]` when an `alt_unit` coefficient is known, else `alt=12.4V`).
pub fn field(field: &FieldDescriptor<'_>, value: &Value<'_>) -> String {
    let mut s = format!("{}={value}", field.name);
    if let Some(label) = value.as_i64().and_then(|i| field.label(i)) {
        let _ = write!(s, "({label})");
    }
    if let Some(unit) = field.unit {
        s.push_str(unit);
    }
    if let (Some(alt), Some(_), Some(raw)) = (field.alt_unit, field.alt_unit_coef, value.as_f64()) {
        let _ = write!(s, "[{:.3}{alt}]", field.to_alt_unit(raw));
    }
    s
}

/// The fields of a payload as `a=1 b=2.5V ...`; a payload that does not match the
/// description ends with `<error: ...>` after the fields that did decode.
pub fn fields(desc: &MessageDescriptor<'_>, payload: &[u8]) -> String {
    let mut out = Vec::new();
    for item in dynamic::fields(desc, payload) {
        match item {
            Ok((f, v)) => out.push(field(f, &v)),
            Err(e) => out.push(format!("<error: {e}>")),
        }
    }
    out.join(" ")
}

/// One line for a message: `source class NAME fields...`, or, for a message the set
/// does not know, `source class id=N unknown (len bytes)`.
pub fn line(
    source: u8,
    class_id: u8,
    msg_id: u8,
    desc: Option<&MessageDescriptor<'_>>,
    payload: &[u8],
) -> String {
    match desc {
        Some(d) => {
            let body = fields(d, payload);
            if body.is_empty() {
                format!("{source} {} {}", d.class_name, d.name)
            } else {
                format!("{source} {} {} {body}", d.class_name, d.name)
            }
        }
        None => format!(
            "{source} class{class_id} id={msg_id} unknown message ({} bytes)",
            payload.len()
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pprz_messages::{BaseType, FieldType};

    #[test]
    fn units_labels_and_errors() {
        let fields_desc = [
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
        let desc = MessageDescriptor {
            class_id: 1,
            class_name: "telemetry",
            id: 5,
            name: "X",
            priority: 1,
            fields: &fields_desc,
        };
        let payload = [0x10, 0x27, 0, 0, 1];
        assert_eq!(
            line(7, 1, 5, Some(&desc), &payload),
            "7 telemetry X east=10000cm[100.000m] state=1(ON)"
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
}
