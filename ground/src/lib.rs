//! Ground tools of the Paparazzi telemetry stack: decode any `messages.xml` at run time
//! and watch one or several aircraft live.
//!
//! * [`set`]: a message set loaded from a `messages.xml` at run time (the full PPRZLINK
//!   reference included), as descriptors for generic decoding.
//! * [`format`](mod@format): text forms of decoded messages (values with units and labels).
//! * [`escape`]: escaping of everything printed that comes from the aircraft or the XML.
//! * [`monitor`]: the state of the `pprz-monitor` tool: per-message rates and latest
//!   values (for all aircraft and per aircraft), link statistics, link quality per
//!   aircraft (live or stale, RSSI, downlink loss, autopilot mode), PING round trips and
//!   SETTING acknowledgements per aircraft.
//! * [`ping`], [`settings`]: matching PONGs to PINGs and DL_VALUEs to SETTINGs; the
//!   aircraft's settings files, which name, bound and label the settings; the reading
//!   of every setting.
//! * [`input`]: the bounded queue between the reading threads and the decoder.
//! * [`cli`]: the command line, with every value checked.
//! * [`device`]: the links to aircraft (UDP, TCP, serial ports, files): reading and
//!   writing.
//! * [`uplink`]: PING / SETTING / GET_SETTING frames for the aircraft.
//! * [`bus`]: the fleet bus (Zenoh): the gateway's session, ground stations'
//!   sessions, the key layout.
//! * [`gateway`]: the fleet gateway's logic (`pprz-gateway`): several links at once,
//!   redundant links merged, commands routed to the link each aircraft is heard on.
//! * [`secure`]: the ground's end of a secure PPRZ v2 link (`pprz-monitor --secure`).
//! * [`viewer`]: decoded telemetry for Foxglove and Lichtblick: a WebSocket server
//!   (`--foxglove`), MCAP recordings (`--mcap`), settings as parameters; [`json`](mod@json)
//!   gives the messages' JSON forms and JSON Schemas.
//!
//! ```
//! use pprz_ground::{monitor::Monitor, set::RuntimeSet};
//! use pprz_transports::PprzV2;
//!
//! let set = RuntimeSet::parse("m.xml", r#"<protocol><msg_class name="telemetry" id="1">
//!     <message name="ALIVE" id="2"><field name="md5sum" type="uint8[]"/></message>
//!     </msg_class></protocol>"#).unwrap();
//! let mut monitor = Monitor::new(set, PprzV2::new().into());
//! let mut lines = Vec::new();
//! monitor.feed(0.0, &[0x99, 0x0C, 0x07, 0x00, 0x01, 0x02, 0x03, 0x00, 0x01, 0x02, 0x1C, 0xC4],
//!     |m| lines.push(m.line.to_owned()));
//! assert_eq!(lines, ["7 telemetry ALIVE md5sum=0,1,2"]);
//! ```

#![warn(missing_docs)]
#![deny(unsafe_code)]

#[cfg(feature = "bus")]
pub mod bus;
pub mod cli;
pub mod device;
pub mod escape;
pub mod format;
pub mod gateway;
pub mod input;
pub mod json;
pub mod monitor;
pub mod ping;
pub mod secure;
pub mod set;
pub mod settings;
pub mod uplink;
pub mod viewer;
