//! Frames the ground sends to an aircraft (PING, SETTING, GET_SETTING), built from the
//! run-time message set so they follow whatever `messages.xml` the tool was given.

use std::fmt;

use pprz_messages::{FieldType, MessageDescriptor};
use pprz_transports::{AnyTransport, Encoder, GROUND_ID, MsgHeader, TxMeta};

use crate::json::parse::{Num, put_scalar};
use crate::set::RuntimeSet;

/// Why an uplink frame could not be built.
#[derive(Debug, Clone, PartialEq)]
pub enum UplinkError {
    /// The message set has no such datalink message.
    UnknownMessage(String),
    /// The message has a field that is not a number (arrays, text).
    UnsupportedField(String),
    /// A value does not fit its field's type (out of its range, a fractional part for an
    /// integer, a finite value beyond the range of `float`).
    OutOfRange {
        /// Field name.
        field: String,
        /// Value given.
        value: f64,
    },
    /// The transport refused the frame.
    Transport(String),
}

impl fmt::Display for UplinkError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::UnknownMessage(m) => write!(f, "the message set has no datalink message {m}"),
            Self::UnsupportedField(n) => write!(f, "field {n} is not a number"),
            Self::OutOfRange { field, value } => {
                write!(f, "value {value} does not fit field {field}")
            }
            Self::Transport(e) => write!(f, "transport: {e}"),
        }
    }
}

impl std::error::Error for UplinkError {}

/// Encodes a message made of numeric scalar fields from `(name, value)` pairs; fields
/// not given are 0.
///
/// # Errors
/// A field that is not a scalar number, or a value out of its type's range.
pub fn encode_scalars(
    desc: &MessageDescriptor<'_>,
    values: &[(&str, f64)],
) -> Result<Vec<u8>, UplinkError> {
    let mut out = Vec::new();
    for field in desc.fields {
        let FieldType::Scalar(base) = field.ty else {
            return Err(UplinkError::UnsupportedField(field.name.to_owned()));
        };
        let v = values
            .iter()
            .find(|(n, _)| *n == field.name)
            .map_or(0.0, |(_, v)| *v);
        put_scalar(base, Num::Float(v), &mut out).map_err(|_| UplinkError::OutOfRange {
            field: field.name.to_owned(),
            value: v,
        })?;
    }
    Ok(out)
}

/// A frame of datalink message `name` from the ground to aircraft `ac_id`: the frame's
/// destination (PPRZ v2 and the transports built on it) is `ac_id`, and so is the
/// message's `ac_id` field (SETTING, GET_SETTING... of Paparazzi, which an aircraft
/// checks against its own id; PPRZ v1 has no destination), unless `values` gives it.
/// Other fields not given are 0.
///
/// ```
/// use pprz_ground::{set::RuntimeSet, uplink};
/// use pprz_transports::PprzV2;
/// let set = RuntimeSet::parse("m.xml", r#"<protocol><msg_class name="datalink" id="2">
///     <message name="GET_SETTING" id="16"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/></message>
///     </msg_class></protocol>"#).unwrap();
/// let f = uplink::frame(&set, PprzV2::new().into(), 8, "GET_SETTING", &[("index", 3.0)]).unwrap();
/// // 0x99, length, source 0 (ground), destination 8, class 2, id 16, index 3, ac_id 8.
/// assert_eq!(&f[..8], &[0x99, 10, 0, 8, 2, 16, 3, 8]);
/// ```
///
/// # Errors
/// Unknown message, unsupported field or value, or the transport refused the frame.
pub fn frame(
    set: &RuntimeSet,
    transport: AnyTransport,
    ac_id: u8,
    name: &str,
    values: &[(&str, f64)],
) -> Result<Vec<u8>, UplinkError> {
    let desc = set
        .find_by_name("datalink", name)
        .ok_or_else(|| UplinkError::UnknownMessage(name.to_owned()))?;
    let mut values = values.to_vec();
    if !values.iter().any(|(n, _)| *n == "ac_id") {
        values.push(("ac_id", f64::from(ac_id)));
    }
    let payload = encode_scalars(desc, &values)?;
    encode(transport, ac_id, desc, &payload)
}

/// A frame of message `desc` with `payload` from the ground to aircraft `ac_id` (the
/// frame's destination, with PPRZ v2 and the transports built on it).
///
/// # Errors
/// The transport refused the frame (a payload too long for it).
pub fn encode(
    transport: AnyTransport,
    ac_id: u8,
    desc: &MessageDescriptor<'_>,
    payload: &[u8],
) -> Result<Vec<u8>, UplinkError> {
    let meta = TxMeta::new(MsgHeader::new(GROUND_ID, ac_id, desc.class_id, desc.id));
    let mut out = vec![0u8; transport.max_frame_len()];
    let n = transport
        .encode(&meta, payload, &mut out)
        .map_err(|e| UplinkError::Transport(e.to_string()))?;
    out.truncate(n);
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pprz_transports::PprzV2;

    const XML: &str = r#"<protocol><msg_class name="datalink" id="2">
        <message name="SETTING" id="4"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/></message>
        <message name="PING" id="8"/>
        <message name="TEXT" id="9"><field name="t" type="char[]"/></message>
        </msg_class></protocol>"#;

    #[test]
    fn builds_ping_and_setting_frames() {
        let set = RuntimeSet::parse("t.xml", XML).unwrap();
        let t = AnyTransport::from(PprzV2::new());
        assert_eq!(
            frame(&set, t, 7, "PING", &[]).unwrap(),
            [0x99, 0x08, 0x00, 0x07, 0x02, 0x08, 0x19, 0x49]
        );
        let f = frame(
            &set,
            t,
            7,
            "SETTING",
            &[("index", 2.0), ("ac_id", 7.0), ("value", 1.5)],
        )
        .unwrap();
        assert_eq!(&f[..9], &[0x99, 14, 0, 7, 2, 4, 2, 7, 0]);
        assert_eq!(&f[7..12], &[7, 0, 0, 0xC0, 0x3F]);
        // The destination and the `ac_id` field follow the aircraft addressed.
        let f = frame(&set, t, 8, "SETTING", &[("index", 2.0), ("value", 1.5)]).unwrap();
        assert_eq!(&f[..12], &[0x99, 14, 0, 8, 2, 4, 2, 8, 0, 0, 0xC0, 0x3F]);
        assert_eq!(frame(&set, t, 8, "PING", &[]).unwrap()[3], 8);
        assert_eq!(
            frame(&set, t, 7, "SETTING", &[("index", 300.0)]),
            Err(UplinkError::OutOfRange {
                field: "index".into(),
                value: 300.0
            })
        );
        assert!(matches!(
            frame(&set, t, 7, "TEXT", &[]),
            Err(UplinkError::UnsupportedField(_))
        ));
        assert!(matches!(
            frame(&set, t, 7, "NOPE", &[]),
            Err(UplinkError::UnknownMessage(_))
        ));
    }
}
