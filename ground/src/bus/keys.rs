//! The key expressions of the fleet bus.
//!
//! | key | payload |
//! |---|---|
//! | `pprz/<ac_id>/<class>/<MESSAGE>` | a decoded message as JSON (attachment: the frame as its link received it) |
//! | `pprz/<ac_id>/frame` | every delivered message as a PPRZ v2 frame (messages the gateway cannot decode too) |
//! | `pprz/<ac_id>/link` | the aircraft's link figures, as JSON, once a second |
//! | `pprz/<ac_id>/alive` | a liveliness token, present while the aircraft is live |
//! | `pprz/<ac_id>/uplink/<MESSAGE>` | a command: the message's fields as a JSON object |
//! | `pprz/<ac_id>/settings/<name>` | a query: read a setting, or set it (payload `{"value": x}`) |
//! | `pprz/schema/<class>/<MESSAGE>` | a query: the JSON Schema of the message's JSON |
//! | `pprz/gateway/<name>` | a liveliness token, present while the gateway runs |
//! | `pprz/gateway/<name>/link/<link>` | one link's figures, as JSON, once a second |
//! | `pprz/gateway/<name>/refused` | a refused command: its key, the reason, the counts |
//! | `pprz/gateway/<name>/stats` | the gateway's counters, as JSON, once a second |
//!
//! Names from the `messages.xml` and link names are escaped with
//! [`topic_part`]: letters, digits, `_` and `-` as they are,
//! every other byte as `%XX`, so no name adds a level or a wildcard.
//!
//! ```
//! use pprz_ground::bus::keys;
//! assert_eq!(keys::message(7, "telemetry", "GPS_INT"), "pprz/7/telemetry/GPS_INT");
//! assert_eq!(keys::parse_uplink("pprz/7/uplink/SETTING"), Some((7, "SETTING".to_owned())));
//! assert_eq!(keys::parse_uplink("pprz/700/uplink/SETTING"), None);
//! ```

use crate::json::topic_part;

/// The root of every key.
pub const ROOT: &str = "pprz";

/// Every command: `pprz/*/uplink/*`.
pub const UPLINK_ALL: &str = "pprz/*/uplink/*";

/// Every settings query: `pprz/*/settings/*`.
pub const SETTINGS_ALL: &str = "pprz/*/settings/*";

/// Every schema: `pprz/schema/**`.
pub const SCHEMAS_ALL: &str = "pprz/schema/**";

/// Every delivered frame: `pprz/*/frame`.
pub const FRAMES_ALL: &str = "pprz/*/frame";

/// A decoded message of aircraft `ac`.
pub fn message(ac: u8, class: &str, name: &str) -> String {
    format!("{ROOT}/{ac}/{}/{}", topic_part(class), topic_part(name))
}

/// The JSON Schema of message `name` of class `class`.
pub fn schema(class: &str, name: &str) -> String {
    format!("{ROOT}/schema/{}/{}", topic_part(class), topic_part(name))
}

/// The PPRZ v2 frames of aircraft `ac`.
pub fn frame(ac: u8) -> String {
    format!("{ROOT}/{ac}/frame")
}

/// The link figures of aircraft `ac`.
pub fn link(ac: u8) -> String {
    format!("{ROOT}/{ac}/link")
}

/// The liveliness token of aircraft `ac`.
pub fn alive(ac: u8) -> String {
    format!("{ROOT}/{ac}/alive")
}

/// The liveliness token of gateway `gateway`.
pub fn gateway(gateway: &str) -> String {
    format!("{ROOT}/gateway/{}", topic_part(gateway))
}

/// A command `name` for aircraft `ac`.
pub fn uplink(ac: u8, name: &str) -> String {
    format!("{ROOT}/{ac}/uplink/{}", topic_part(name))
}

/// Setting `name` of aircraft `ac`.
pub fn setting(ac: u8, name: &str) -> String {
    format!("{ROOT}/{ac}/settings/{}", topic_part(name))
}

/// Link `link` of gateway `gateway`.
pub fn gateway_link(gateway: &str, link: &str) -> String {
    format!(
        "{ROOT}/gateway/{}/link/{}",
        topic_part(gateway),
        topic_part(link)
    )
}

/// The refused commands of gateway `gateway`.
pub fn refused(gateway: &str) -> String {
    format!("{ROOT}/gateway/{}/refused", topic_part(gateway))
}

/// The counters of gateway `gateway`.
pub fn stats(gateway: &str) -> String {
    format!("{ROOT}/gateway/{}/stats", topic_part(gateway))
}

/// The aircraft id and the last chunk of `pprz/<ac_id>/<kind>/<name>`, when `key` has
/// that form.
fn parse(key: &str, kind: &str) -> Option<(u8, String)> {
    let mut parts = key.split('/');
    let (root, ac, k, name) = (parts.next()?, parts.next()?, parts.next()?, parts.next()?);
    if root != ROOT || k != kind || parts.next().is_some() || name.is_empty() {
        return None;
    }
    if ac.len() > 3 || !ac.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    Some((ac.parse().ok()?, unescape(name)?))
}

/// The aircraft and message of a command key `pprz/<ac_id>/uplink/<MESSAGE>`.
pub fn parse_uplink(key: &str) -> Option<(u8, String)> {
    parse(key, "uplink")
}

/// The aircraft and setting name of `pprz/<ac_id>/settings/<name>`.
pub fn parse_setting(key: &str) -> Option<(u8, String)> {
    parse(key, "settings")
}

/// The inverse of [`topic_part`]: `%XX` back to the byte; `None` when that is not
/// UTF-8 or an escape is malformed.
fn unescape(part: &str) -> Option<String> {
    let b = part.as_bytes();
    let mut out = Vec::with_capacity(b.len());
    let mut i = 0;
    while i < b.len() {
        if b[i] == b'%' {
            let hex = std::str::from_utf8(b.get(i + 1..i + 3)?).ok()?;
            out.push(u8::from_str_radix(hex, 16).ok()?);
            i += 3;
        } else {
            out.push(b[i]);
            i += 1;
        }
    }
    String::from_utf8(out).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn keys_round_trip_and_nonsense_is_not_a_key() {
        for name in ["SETTING", "alt gain", "a/b", "x*y", "é"] {
            assert_eq!(parse_uplink(&uplink(9, name)), Some((9, name.to_owned())));
            assert_eq!(parse_setting(&setting(9, name)), Some((9, name.to_owned())));
        }
        for bad in [
            "pprz/7/uplink",
            "pprz/7/uplink/",
            "pprz/x/uplink/PING",
            "pprz/256/uplink/PING",
            "pprz/0007/uplink/PING",
            "pprz/7/uplink/PING/more",
            "other/7/uplink/PING",
            "pprz/7/uplink/%G1",
            "pprz/7/uplink/%FF",
        ] {
            assert_eq!(parse_uplink(bad), None, "{bad}");
        }
        assert_eq!(
            gateway_link("gw", "radio a"),
            "pprz/gateway/gw/link/radio%20a"
        );
    }
}
