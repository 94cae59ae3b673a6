//! A message set loaded from a `messages.xml` at run time, as descriptors that the
//! generic decoder of `pprz-messages` understands.

use std::path::Path;

use pprz_codegen::Protocol;
use pprz_messages::{FieldDescriptor, MessageDescriptor, MessageSet};

/// Descriptors of every message of a `messages.xml` file (all classes), sorted by
/// `(class, id)`.
///
/// The descriptors borrow their strings; the set is loaded once per run of a tool, so
/// its storage is leaked to give them a `'static` lifetime (bounded: one copy of the
/// file's metadata per load).
#[derive(Debug, Clone, Copy)]
pub struct RuntimeSet {
    set: MessageSet<'static>,
    /// The protocol the descriptors borrow from (kept reachable: a leak checker does
    /// not report the storage of a set loaded once).
    protocol: &'static Protocol,
}

impl RuntimeSet {
    /// Loads and validates `messages.xml`.
    ///
    /// # Errors
    /// Every problem of the file, with file, line, message and field.
    pub fn load(path: impl AsRef<Path>) -> Result<Self, pprz_codegen::Error> {
        Ok(Self::from_protocol(Protocol::from_file(path)?))
    }

    /// Parses `messages.xml` text; `name` names it in diagnostics.
    ///
    /// # Errors
    /// Every problem of the text.
    pub fn parse(name: &str, xml: &str) -> Result<Self, pprz_codegen::Error> {
        Ok(Self::from_protocol(Protocol::parse(name, xml)?))
    }

    /// Builds descriptors for a validated protocol, with the generator's default
    /// priority for messages without the attribute and its built-in unit conversions
    /// where a field has `unit` and `alt_unit` but no coefficient.
    pub fn from_protocol(mut protocol: Protocol) -> Self {
        protocol.apply_units(&pprz_codegen::Units::builtin());
        let protocol: &'static Protocol = Box::leak(Box::new(protocol));
        let mut messages: Vec<MessageDescriptor<'static>> = Vec::new();
        for class in &protocol.classes {
            for m in &class.messages {
                let fields: Vec<FieldDescriptor<'static>> = m
                    .fields
                    .iter()
                    .map(|f| {
                        let labels: &'static [&'static str] = f.value_labels().leak();
                        f.descriptor(labels)
                    })
                    .collect();
                messages.push(m.descriptor(class, pprz_messages::priority::DEFAULT, fields.leak()));
            }
        }
        messages.sort_by_key(|m| (m.class_id, m.id));
        messages.dedup_by_key(|m| (m.class_id, m.id));
        Self {
            set: MessageSet::new(messages.leak()),
            protocol,
        }
    }

    /// The validated protocol the set was built from.
    pub fn protocol(&self) -> &'static Protocol {
        self.protocol
    }

    /// The descriptor table.
    pub fn set(&self) -> &MessageSet<'static> {
        &self.set
    }

    /// Finds a message by class and id.
    pub fn find(&self, class_id: u8, msg_id: u8) -> Option<&'static MessageDescriptor<'static>> {
        self.set.find(class_id, msg_id)
    }

    /// Finds a message by class name and name.
    pub fn find_by_name(
        &self,
        class: &str,
        name: &str,
    ) -> Option<&'static MessageDescriptor<'static>> {
        self.set.find_by_name(class, name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builds_sorted_descriptors_with_labels() {
        let xml = r#"<protocol><msg_class name="datalink" id="2">
            <message name="PING" id="8"/></msg_class>
            <msg_class name="telemetry" id="1">
            <message name="B" id="9" priority="200"><field name="m" type="uint8" values="X|Y"/></message>
            <message name="A" id="3"><field name="v" type="float" unit="cm" alt_unit="m"/></message>
            </msg_class></protocol>"#;
        let set = RuntimeSet::parse("t.xml", xml).unwrap();
        let ids: Vec<_> = set
            .set()
            .messages()
            .iter()
            .map(|m| (m.class_id, m.id))
            .collect();
        assert_eq!(ids, [(1, 3), (1, 9), (2, 8)]);
        let b = set.find(1, 9).unwrap();
        assert_eq!((b.name, b.priority), ("B", 200));
        assert_eq!(b.fields[0].label(1), Some("Y"));
        let a = set.find_by_name("telemetry", "A").unwrap();
        assert_eq!(a.fields[0].alt_unit_coef, Some(0.01), "built-in cm -> m");
        assert_eq!(a.priority, pprz_messages::priority::DEFAULT);
    }
}
