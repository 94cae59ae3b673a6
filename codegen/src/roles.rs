//! The roles of `pprz_messages::roles` a message set can fill, and which ones a
//! [`Protocol`] fills.
//!
//! A role message is found by class name and message name, and fits when its fields have
//! exactly the role's names and types, in order, with no extra field (ids and priorities
//! are the set's own). A set role (`ServiceSet`, `LinkReportSet`) is filled when all its
//! messages fit; otherwise each reason is kept for the documentation of the generated
//! `Set`.

use pprz_messages::{BaseType, FieldType};

use crate::model::{MessageDef, Protocol};
use crate::names;

/// A message a role needs (the table of `pprz_messages::roles`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum RoleMessage {
    /// `PING` (datalink), no fields.
    Ping,
    /// `PONG` (telemetry), no fields.
    Pong,
    /// `SETTING` (datalink): `index: uint8, ac_id: uint8, value: float`.
    Setting,
    /// `GET_SETTING` (datalink): `index: uint8, ac_id: uint8`.
    GetSetting,
    /// `DL_VALUE` (telemetry): `index: uint8, value: float`.
    DlValue,
    /// `DATALINK_REPORT` (telemetry): the six fields of `roles::LinkReport`.
    DatalinkReport,
}

impl RoleMessage {
    /// Message name in `messages.xml`.
    pub(crate) const fn name(self) -> &'static str {
        match self {
            Self::Ping => "PING",
            Self::Pong => "PONG",
            Self::Setting => "SETTING",
            Self::GetSetting => "GET_SETTING",
            Self::DlValue => "DL_VALUE",
            Self::DatalinkReport => "DATALINK_REPORT",
        }
    }

    /// Name of the class the message must be in.
    pub(crate) const fn class(self) -> &'static str {
        match self {
            Self::Ping | Self::Setting | Self::GetSetting => "datalink",
            Self::Pong | Self::DlValue | Self::DatalinkReport => "telemetry",
        }
    }

    /// The fields the message must have, in order.
    pub(crate) const fn fields(self) -> &'static [(&'static str, BaseType)] {
        match self {
            Self::Ping | Self::Pong => &[],
            Self::Setting => &[
                ("index", BaseType::U8),
                ("ac_id", BaseType::U8),
                ("value", BaseType::F32),
            ],
            Self::GetSetting => &[("index", BaseType::U8), ("ac_id", BaseType::U8)],
            Self::DlValue => &[("index", BaseType::U8), ("value", BaseType::F32)],
            Self::DatalinkReport => &[
                ("uplink_lost_time", BaseType::U16),
                ("uplink_nb_msgs", BaseType::U16),
                ("downlink_nb_msgs", BaseType::U16),
                ("downlink_rate", BaseType::U16),
                ("uplink_rate", BaseType::U16),
                ("downlink_ovrn", BaseType::U8),
            ],
        }
    }

    /// The trait of `roles` the message implements.
    pub(crate) const fn role(self) -> &'static str {
        match self {
            Self::Ping => "Ping",
            Self::Pong => "Pong",
            Self::Setting => "SettingRequest",
            Self::GetSetting => "GetSettingRequest",
            Self::DlValue => "SettingValue",
            Self::DatalinkReport => "DatalinkReport",
        }
    }

    /// The associated type of its set role that names it.
    pub(crate) const fn assoc(self) -> &'static str {
        match self {
            Self::Ping => "Ping",
            Self::Pong => "Pong",
            Self::Setting => "Setting",
            Self::GetSetting => "GetSetting",
            Self::DlValue => "DlValue",
            Self::DatalinkReport => "DatalinkReport",
        }
    }
}

/// A role of the whole set: a trait of `roles` implemented on the generated `Set`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum SetRole {
    /// `ServiceSet`: the messages of the datalink services.
    ServiceSet,
    /// `LinkReportSet`: the link report message.
    LinkReportSet,
}

impl SetRole {
    /// Every set role, in the order of the documentation.
    pub(crate) const ALL: [Self; 2] = [Self::ServiceSet, Self::LinkReportSet];

    /// The trait of `roles`.
    pub(crate) const fn name(self) -> &'static str {
        match self {
            Self::ServiceSet => "ServiceSet",
            Self::LinkReportSet => "LinkReportSet",
        }
    }

    /// The messages it needs.
    pub(crate) const fn messages(self) -> &'static [RoleMessage] {
        match self {
            Self::ServiceSet => &[
                RoleMessage::Ping,
                RoleMessage::Pong,
                RoleMessage::Setting,
                RoleMessage::GetSetting,
                RoleMessage::DlValue,
            ],
            Self::LinkReportSet => &[RoleMessage::DatalinkReport],
        }
    }
}

/// Why a role message does not fit.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum Unfit {
    /// No message of that name in the (selected) set.
    Missing,
    /// The message is in another class (its names).
    WrongClass(Vec<String>),
    /// The fields differ; the text says how.
    Fields(String),
}

/// A role message the set has with the right fields: the Rust path of its type.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Fit {
    /// `datalink::Ping`, relative to the generated file.
    pub(crate) path: String,
}

/// What a message set fills.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) struct Roles {
    /// Each role message, in the order of [`SetRole::ALL`].
    pub(crate) messages: Vec<(RoleMessage, Result<Fit, Unfit>)>,
}

impl Roles {
    /// Checks every role message against `protocol`.
    pub(crate) fn of(protocol: &Protocol) -> Self {
        let messages = SetRole::ALL
            .iter()
            .flat_map(|r| r.messages())
            .map(|&m| (m, check(protocol, m)))
            .collect();
        Self { messages }
    }

    /// How `m` fits.
    pub(crate) fn get(&self, m: RoleMessage) -> Option<&Result<Fit, Unfit>> {
        self.messages.iter().find(|(r, _)| *r == m).map(|(_, f)| f)
    }

    /// The messages of `role` if all fit, else every reason why not (as documentation
    /// text: `` `DL_VALUE` missing ``).
    pub(crate) fn set(&self, role: SetRole) -> Result<Vec<(RoleMessage, &Fit)>, Vec<String>> {
        let mut fits = Vec::new();
        let mut missing = Vec::new();
        let mut reasons = Vec::new();
        for &m in role.messages() {
            match self.get(m) {
                Some(Ok(fit)) => fits.push((m, fit)),
                Some(Err(Unfit::Missing)) | None => missing.push(format!("`{}`", m.name())),
                Some(Err(Unfit::WrongClass(classes))) => reasons.push(format!(
                    "`{}` is in class {}, the role needs class `{}`",
                    m.name(),
                    classes
                        .iter()
                        .map(|c| format!("`{c}`"))
                        .collect::<Vec<_>>()
                        .join(" and "),
                    m.class()
                )),
                Some(Err(Unfit::Fields(why))) => reasons.push(why.clone()),
            }
        }
        if missing.is_empty() && reasons.is_empty() {
            return Ok(fits);
        }
        if !missing.is_empty() {
            reasons.insert(0, format!("{} missing", list(&missing)));
        }
        Err(reasons)
    }
}

/// `a`, `a and b`, `a, b and c`.
pub(crate) fn list(items: &[String]) -> String {
    match items {
        [] => String::new(),
        [one] => one.clone(),
        [init @ .., last] => format!("{} and {last}", init.join(", ")),
    }
}

fn plural(n: usize, what: &str) -> String {
    match n {
        0 => format!("no {what}s"),
        1 => format!("1 {what}"),
        _ => format!("{n} {what}s"),
    }
}

/// Whether `protocol` has `m` in the right class with the right fields.
fn check(protocol: &Protocol, m: RoleMessage) -> Result<Fit, Unfit> {
    let class = protocol.classes.iter().find(|c| c.name == m.class());
    let Some((class, def)) = class.and_then(|c| {
        c.messages
            .iter()
            .find(|d| d.name == m.name())
            .map(|d| (c, d))
    }) else {
        let elsewhere: Vec<String> = protocol
            .classes
            .iter()
            .filter(|c| c.messages.iter().any(|d| d.name == m.name()))
            .map(|c| c.name.clone())
            .collect();
        return Err(if elsewhere.is_empty() {
            Unfit::Missing
        } else {
            Unfit::WrongClass(elsewhere)
        });
    };
    check_fields(m, def).map_err(Unfit::Fields)?;
    Ok(Fit {
        path: format!(
            "{}::{}",
            names::module_name(&class.name),
            names::camel_case(&def.name)
        ),
    })
}

/// The first difference between the fields of `def` and those `m` needs.
fn check_fields(m: RoleMessage, def: &MessageDef) -> Result<(), String> {
    let want = m.fields();
    if def.fields.len() != want.len() {
        let needs = if want.is_empty() {
            "none".to_owned()
        } else {
            format!(
                "{} (`{}`)",
                want.len(),
                want.iter()
                    .map(|(name, ty)| format!("{name}: {}", ty.xml_name()))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        return Err(format!(
            "`{}` has {}, the role needs {needs}",
            m.name(),
            plural(def.fields.len(), "field"),
        ));
    }
    for (i, (f, (name, ty))) in def.fields.iter().zip(want).enumerate() {
        if f.name != *name {
            return Err(format!(
                "`{}` field {} is `{}`, the role needs `{name}`",
                m.name(),
                i + 1,
                f.name
            ));
        }
        if f.ty != FieldType::Scalar(*ty) {
            return Err(format!(
                "`{}` field {} (`{name}`) is `{}`, the role needs `{}`",
                m.name(),
                i + 1,
                f.xml_type,
                ty.xml_name()
            ));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn roles(xml: &str) -> Roles {
        Roles::of(&Protocol::parse("t.xml", xml).unwrap())
    }

    const FULL: &str = r#"<protocol>
      <msg_class name="telemetry" id="1">
        <message name="PONG" id="3"/>
        <message name="DATALINK_REPORT" id="30">
          <field name="uplink_lost_time" type="uint16"/><field name="uplink_nb_msgs" type="uint16"/>
          <field name="downlink_nb_msgs" type="uint16"/><field name="downlink_rate" type="uint16"/>
          <field name="uplink_rate" type="uint16"/><field name="downlink_ovrn" type="uint8"/>
        </message>
        <message name="DL_VALUE" id="31"><field name="index" type="uint8"/><field name="value" type="float"/></message>
      </msg_class>
      <msg_class name="datalink" id="2">
        <message name="SETTING" id="4">
          <field name="index" type="uint8"/><field name="ac_id" type="uint8"/><field name="value" type="float"/>
        </message>
        <message name="PING" id="8"/>
        <message name="GET_SETTING" id="16"><field name="index" type="uint8"/><field name="ac_id" type="uint8"/></message>
      </msg_class></protocol>"#;

    #[test]
    fn full_set_fills_both_roles() {
        let r = roles(FULL);
        let services = r.set(SetRole::ServiceSet).unwrap();
        let paths: Vec<&str> = services.iter().map(|(_, f)| f.path.as_str()).collect();
        assert_eq!(
            paths,
            [
                "datalink::Ping",
                "telemetry::Pong",
                "datalink::Setting",
                "datalink::GetSetting",
                "telemetry::DlValue"
            ]
        );
        assert_eq!(
            r.set(SetRole::LinkReportSet).unwrap()[0].1.path,
            "telemetry::DatalinkReport"
        );
    }

    #[test]
    fn every_kind_of_misfit_is_explained() {
        let xml = FULL
            .replace(r#"<message name="PING" id="8"/>"#, "")
            .replace(r#"<message name="PONG" id="3"/>"#, "")
            .replace(
                r#"<field name="value" type="float"/></message>"#,
                r#"<field name="value" type="double"/></message>"#,
            )
            .replace(
                r#"<field name="index" type="uint8"/><field name="ac_id" type="uint8"/></message>"#,
                r#"<field name="index" type="uint8"/><field name="aircraft" type="uint8"/></message>"#,
            )
            .replace(
                r#"<field name="downlink_ovrn" type="uint8"/>"#,
                r#"<field name="downlink_ovrn" type="uint8"/><field name="extra" type="uint8"/>"#,
            )
            .replace(
                r#"<msg_class name="datalink" id="2">"#,
                r#"<msg_class name="datalink" id="2"><message name="PONG" id="3"/>"#,
            );
        let r = roles(&xml);
        assert_eq!(
            r.set(SetRole::ServiceSet).unwrap_err(),
            [
                "`PING` missing",
                "`PONG` is in class `datalink`, the role needs class `telemetry`",
                "`GET_SETTING` field 2 is `aircraft`, the role needs `ac_id`",
                "`DL_VALUE` field 2 (`value`) is `double`, the role needs `float`",
            ]
        );
        assert_eq!(
            r.set(SetRole::LinkReportSet).unwrap_err(),
            [
                "`DATALINK_REPORT` has 7 fields, the role needs 6 (`uplink_lost_time: uint16, \
              uplink_nb_msgs: uint16, downlink_nb_msgs: uint16, downlink_rate: uint16, \
              uplink_rate: uint16, downlink_ovrn: uint8`)"
            ]
        );
        // SETTING still fits on its own.
        assert!(matches!(r.get(RoleMessage::Setting), Some(Ok(_))));
    }

    #[test]
    fn field_less_role_with_a_field() {
        let xml = FULL.replace(
            r#"<message name="PING" id="8"/>"#,
            r#"<message name="PING" id="8"><field name="x" type="uint8"/></message>"#,
        );
        assert_eq!(
            roles(&xml).set(SetRole::ServiceSet).unwrap_err(),
            ["`PING` has 1 field, the role needs none"]
        );
    }

    #[test]
    fn lists() {
        let s = |v: &[&str]| list(&v.iter().map(|s| s.to_string()).collect::<Vec<_>>());
        assert_eq!(s(&[]), "");
        assert_eq!(s(&["a"]), "a");
        assert_eq!(s(&["a", "b"]), "a and b");
        assert_eq!(s(&["a", "b", "c"]), "a, b and c");
    }
}
