//! Roles a message set can fill for the runtime: which of its messages the datalink
//! services speak, and which one carries the link report.
//!
//! The runtime (`pprz-telemetry`) is generic over the message set: its services do not
//! name a generated type, they ask the set for it through these traits. The code
//! generator implements them on the generated `Set` type when the set holds the
//! messages with Paparazzi's field layout, so a firmware with its own `messages.xml`
//! gets the services as soon as its set contains them, and a set that lacks one does
//! not compile where the services are used (the error names the missing role):
//!
//! | role | messages (class), fields in order |
//! |---|---|
//! | [`ServiceSet`] | `PING` (datalink): none; `PONG` (telemetry): none; `SETTING` (datalink): `index: uint8, ac_id: uint8, value: float`; `GET_SETTING` (datalink): `index: uint8, ac_id: uint8`; `DL_VALUE` (telemetry): `index: uint8, value: float` |
//! | [`LinkReportSet`] | `DATALINK_REPORT` (telemetry): `uplink_lost_time: uint16, uplink_nb_msgs: uint16, downlink_nb_msgs: uint16, downlink_rate: uint16, uplink_rate: uint16, downlink_ovrn: uint8` |
//!
//! Ids and priorities are the set's own: the roles only fix names and fields.
//!
//! ```
//! use pprz_messages::roles::{Ping, ServiceSet, SettingRequest};
//! // Generic code: works with any set that has the services' messages.
//! fn is_ping<S: ServiceSet>(class_id: u8, msg_id: u8) -> bool {
//!     use pprz_messages::Message;
//!     (class_id, msg_id) == (S::Ping::CLASS_ID, S::Ping::ID)
//! }
//! ```

use crate::message::{Decode, Message};

/// `PING`: a request for a [`Pong`] (no fields).
pub trait Ping: for<'a> Decode<'a> {}

/// `PONG`: the answer to a [`Ping`] (no fields).
pub trait Pong: Message {
    /// The message (it has no fields).
    fn pong() -> Self;
}

/// `SETTING(index, ac_id, value)`: the ground sets a setting of aircraft `ac_id`.
pub trait SettingRequest: for<'a> Decode<'a> {
    /// Index of the setting in the aircraft's settings table.
    fn index(&self) -> u8;
    /// The aircraft the request is for.
    fn ac_id(&self) -> u8;
    /// The new value.
    fn value(&self) -> f32;
}

/// `GET_SETTING(index, ac_id)`: the ground asks for the value of a setting.
pub trait GetSettingRequest: for<'a> Decode<'a> {
    /// Index of the setting in the aircraft's settings table.
    fn index(&self) -> u8;
    /// The aircraft the request is for.
    fn ac_id(&self) -> u8;
}

/// `DL_VALUE(index, value)`: the value of a setting, the acknowledgement of a
/// [`SettingRequest`] and the answer to a [`GetSettingRequest`].
pub trait SettingValue: Message {
    /// The message for setting `index` holding `value`.
    fn new(index: u8, value: f32) -> Self;
}

/// The messages of the datalink services (PING -> PONG, SETTING and GET_SETTING ->
/// DL_VALUE), as a message set names them. Implemented by the generated `Set` of a
/// set that has all five with the fields listed in the [module docs](self).
#[diagnostic::on_unimplemented(
    message = "the message set `{Self}` lacks a message the datalink services need",
    note = "the services need PING, PONG, SETTING, GET_SETTING and DL_VALUE with Paparazzi's fields \
            (see `pprz_messages::roles`): add them to your messages.xml and to the generator's \
            class and message selection; the doc comment of the generated `Set` says which are missing"
)]
pub trait ServiceSet {
    /// `PING`.
    type Ping: Ping;
    /// `PONG`.
    type Pong: Pong;
    /// `SETTING`.
    type Setting: SettingRequest;
    /// `GET_SETTING`.
    type GetSetting: GetSettingRequest;
    /// `DL_VALUE`.
    type DlValue: SettingValue;
}

/// The fields of a `DATALINK_REPORT`: link health as the Paparazzi ground shows it.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct LinkReport {
    /// Seconds since the last uplink message (`u16::MAX`: never, or longer).
    pub uplink_lost_time: u16,
    /// Uplink messages received (wrapping).
    pub uplink_nb_msgs: u16,
    /// Downlink messages sent (wrapping).
    pub downlink_nb_msgs: u16,
    /// Downlink bytes per second since the previous report.
    pub downlink_rate: u16,
    /// Uplink messages per second since the previous report.
    pub uplink_rate: u16,
    /// Downlink messages lost (dropped or evicted; saturates at 255).
    pub downlink_ovrn: u8,
}

/// `DATALINK_REPORT`: a message built from a [`LinkReport`].
pub trait DatalinkReport: Message + From<LinkReport> {}

/// The link report message of a set. Implemented by the generated `Set` of a set that
/// has `DATALINK_REPORT` with the fields listed in the [module docs](self).
#[diagnostic::on_unimplemented(
    message = "the message set `{Self}` has no DATALINK_REPORT with Paparazzi's fields",
    note = "add DATALINK_REPORT (see `pprz_messages::roles`) to your messages.xml and to the \
            generator's selection"
)]
pub trait LinkReportSet {
    /// `DATALINK_REPORT`.
    type DatalinkReport: DatalinkReport;
}
