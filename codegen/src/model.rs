//! The typed model of a `messages.xml`, and its parser and validator.
//!
//! Parsing collects every problem of a file (see [`crate::Error`]) rather than stopping
//! at the first, and never panics on any input.

use std::collections::HashMap;
use std::path::Path;

use pprz_messages::{BaseType, FieldDescriptor, FieldType, MessageDescriptor};
use roxmltree::Node;

use crate::error::{Diagnostic, Error, ErrorKind};
use crate::names;
use crate::xml::{self, Ctx, Seen};

/// Largest number of field bytes a PPRZ v2 frame carries (255 - STX, LEN, 2 checksum
/// bytes and the 4-byte v2 header).
pub const MAX_PAYLOAD: usize = 247;

/// Largest class id: a PPRZ v2 frame carries the class in the low 4 bits of the byte it
/// shares with the component id (`component << 4 | class`).
pub const MAX_CLASS_ID: u8 = 0x0F;

/// The `AnyMessage` enum every class module has, next to its message types.
const ANY_MESSAGE: &str = "AnyMessage";

/// What a coefficient must be (in diagnostics).
const FINITE: &str = "a finite number";

/// A parsed and validated message set.
#[derive(Debug, Clone, PartialEq)]
pub struct Protocol {
    /// Name of the file it was read from (for diagnostics).
    pub file: String,
    /// Message classes in file order.
    pub classes: Vec<Class>,
}

/// A `<msg_class>`.
#[derive(Debug, Clone, PartialEq)]
pub struct Class {
    /// Class name (`telemetry`).
    pub name: String,
    /// Class id (`telemetry` = 1).
    pub id: u8,
    /// Line of the element.
    pub line: u32,
    /// Messages in file order.
    pub messages: Vec<MessageDef>,
}

/// A `<message>`.
#[derive(Debug, Clone, PartialEq)]
pub struct MessageDef {
    /// Message name (`GPS`).
    pub name: String,
    /// Message id within its class.
    pub id: u8,
    /// Line of the element.
    pub line: u32,
    /// The `priority` attribute, if given.
    pub priority: Option<u8>,
    /// The `link` attribute (`forwarded`, `broadcasted`), if given.
    pub link: Option<String>,
    /// The `<description>` text.
    pub description: Option<String>,
    /// Fields in wire order.
    pub fields: Vec<FieldDef>,
}

/// A `<field>`.
#[derive(Debug, Clone, PartialEq)]
pub struct FieldDef {
    /// Field name as written.
    pub name: String,
    /// Line of the element.
    pub line: u32,
    /// The `type` attribute as written (trimmed).
    pub xml_type: String,
    /// Wire shape.
    pub ty: FieldType,
    /// `unit` attribute.
    pub unit: Option<String>,
    /// `alt_unit` attribute.
    pub alt_unit: Option<String>,
    /// `alt_unit_coef` attribute, or the `units.xml` default once applied.
    pub alt_unit_coef: Option<f64>,
    /// `format` attribute.
    pub format: Option<String>,
    /// `values` labels.
    pub values: Vec<String>,
    /// The element's text.
    pub description: Option<String>,
}

impl MessageDef {
    /// Smallest payload (variable arrays empty).
    pub fn min_len(&self) -> usize {
        self.fields.iter().map(|f| f.ty.min_size()).sum()
    }

    /// Largest payload (variable arrays at 255 elements).
    pub fn max_len(&self) -> usize {
        self.fields.iter().map(|f| f.ty.max_size()).sum()
    }

    /// Whether the payload length is the same for every value.
    pub fn is_fixed_size(&self) -> bool {
        self.fields.iter().all(|f| f.ty.fixed_size().is_some())
    }

    /// A descriptor for this message with the given fields (see
    /// [`FieldDef::descriptor`]).
    pub fn descriptor<'a>(
        &'a self,
        class: &'a Class,
        default_priority: u8,
        fields: &'a [FieldDescriptor<'a>],
    ) -> MessageDescriptor<'a> {
        MessageDescriptor {
            class_id: class.id,
            class_name: &class.name,
            id: self.id,
            name: &self.name,
            priority: self.priority.unwrap_or(default_priority),
            fields,
        }
    }
}

impl FieldDef {
    /// The descriptor of this field, borrowing its strings; `values` are its labels as
    /// string slices (see [`value_labels`](Self::value_labels)).
    pub fn descriptor<'a>(&'a self, values: &'a [&'a str]) -> FieldDescriptor<'a> {
        FieldDescriptor {
            name: &self.name,
            ty: self.ty,
            unit: self.unit.as_deref(),
            alt_unit: self.alt_unit.as_deref(),
            alt_unit_coef: self.alt_unit_coef,
            format: self.format.as_deref(),
            values,
        }
    }

    /// The `values` labels as string slices.
    pub fn value_labels(&self) -> Vec<&str> {
        self.values.iter().map(String::as_str).collect()
    }

    /// Name of the enum generated for this field's `values` in message `message`, if the
    /// field gets one: an integer scalar with labels.
    pub(crate) fn values_enum(&self, message: &str) -> Option<String> {
        match self.ty {
            FieldType::Scalar(b) if b.is_integer() && !self.values.is_empty() => {
                Some(names::values_enum(message, &self.name))
            }
            _ => None,
        }
    }
}

impl Protocol {
    /// Reads and validates a `messages.xml` file.
    ///
    /// # Errors
    /// Every problem found, each with file, line, message and field.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, Error> {
        xml::parse_file(path.as_ref(), Self::parse)
    }

    /// Parses and validates `messages.xml` text; `file` names it in diagnostics.
    ///
    /// # Errors
    /// Every problem found, each with file, line, message and field.
    pub fn parse(file: &str, text: &str) -> Result<Self, Error> {
        xml::parse(file, text, parse_protocol)
    }

    /// Finds a class by name.
    pub fn class(&self, name: &str) -> Option<&Class> {
        self.classes.iter().find(|c| c.name == name)
    }

    /// Finds a message by class name and message name.
    pub fn message(&self, class: &str, name: &str) -> Option<&MessageDef> {
        self.class(class)?.messages.iter().find(|m| m.name == name)
    }

    /// Number of messages in all classes.
    pub fn message_count(&self) -> usize {
        self.classes.iter().map(|c| c.messages.len()).sum()
    }

    /// Fills in `alt_unit_coef` from a units table where a field has `unit` and
    /// `alt_unit` but no explicit coefficient.
    pub fn apply_units(&mut self, units: &Units) {
        for field in self
            .classes
            .iter_mut()
            .flat_map(|c| c.messages.iter_mut())
            .flat_map(|m| m.fields.iter_mut())
        {
            if field.alt_unit_coef.is_none()
                && let (Some(from), Some(to)) = (&field.unit, &field.alt_unit)
            {
                field.alt_unit_coef = units.coef(from, to);
            }
        }
    }

    /// Keeps only the selected classes and messages.
    ///
    /// A message is kept if its class is in `classes` (by name or id) or it is in
    /// `messages` (`NAME` in any class, or `class.NAME`). With both lists empty,
    /// everything is kept.
    ///
    /// # Errors
    /// A selected class or message that does not exist.
    pub fn select(&self, classes: &[String], messages: &[String]) -> Result<Self, Error> {
        if classes.is_empty() && messages.is_empty() {
            return Ok(self.clone());
        }
        let class_matches = |c: &Class, sel: &str| c.name == sel || c.id.to_string() == sel;
        let message_matches = |c: &Class, m: &MessageDef, sel: &str| match sel.split_once('.') {
            Some((class, name)) => class_matches(c, class) && m.name == name,
            None => m.name == sel,
        };
        let mut unknown: Vec<String> = Vec::new();
        for sel in classes {
            if !self.classes.iter().any(|c| class_matches(c, sel)) {
                unknown.push(sel.clone());
            }
        }
        for sel in messages {
            if !self
                .classes
                .iter()
                .any(|c| c.messages.iter().any(|m| message_matches(c, m, sel)))
            {
                unknown.push(sel.clone());
            }
        }
        if !unknown.is_empty() {
            return Err(Error::new(
                unknown
                    .into_iter()
                    .map(|u| Diagnostic {
                        file: self.file.clone(),
                        line: 0,
                        column: 0,
                        message: None,
                        field: None,
                        kind: ErrorKind::UnknownSelection(u),
                    })
                    .collect(),
            ));
        }
        let classes = self
            .classes
            .iter()
            .filter_map(|c| {
                let whole = classes.iter().any(|s| class_matches(c, s));
                let messages: Vec<MessageDef> = c
                    .messages
                    .iter()
                    .filter(|m| whole || messages.iter().any(|s| message_matches(c, m, s)))
                    .cloned()
                    .collect();
                (!messages.is_empty()).then(|| Class {
                    messages,
                    ..c.clone()
                })
            })
            .collect();
        Ok(Self {
            file: self.file.clone(),
            classes,
        })
    }
}

/// Default unit conversions (`units.xml`): `<unit from="cm" to="m" coef="0.01"/>`.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Units {
    coefs: HashMap<(String, String), f64>,
}

impl Units {
    /// Reads a `units.xml` file.
    ///
    /// # Errors
    /// Unreadable file, malformed XML, or a `<unit>` without a numeric `coef`.
    pub fn from_file(path: impl AsRef<Path>) -> Result<Self, Error> {
        xml::parse_file(path.as_ref(), Self::parse)
    }

    /// Parses `units.xml` text.
    ///
    /// # Errors
    /// Malformed XML, or a `<unit>` without `from`, `to` or a numeric `coef`.
    pub fn parse(file: &str, text: &str) -> Result<Self, Error> {
        xml::parse(file, text, |p| {
            let mut units = Units::default();
            let root = p.document().root_element();
            for node in root.children().filter(|n| n.has_tag_name("unit")) {
                let ctx = Ctx::default();
                let from = p.required(node, "unit", "from", &ctx);
                let to = p.required(node, "unit", "to", &ctx);
                let coef = p
                    .required(node, "unit", "coef", &ctx)
                    .and_then(|v| p.number(node, &ctx, "coef", v, |_| true, FINITE));
                if let (Some(from), Some(to), Some(coef)) = (from, to, coef) {
                    units.coefs.insert((from.to_owned(), to.to_owned()), coef);
                }
            }
            units
        })
    }

    /// Conversions between the units Paparazzi messages use, built in so generated
    /// descriptors carry display coefficients without a `units.xml`:
    /// length (m, cm, mm), speed (m/s, cm/s, mm/s), angles (rad, deg, decideg,
    /// centideg) and angular rates and accelerations (rad/s, deg/s, rad/s2, deg/s2).
    pub fn builtin() -> Self {
        const RAD_TO_DEG: f64 = 180.0 / core::f64::consts::PI;
        let pairs: [(&str, &str, f64); 10] = [
            ("m", "cm", 100.0),
            ("m", "mm", 1000.0),
            ("m/s", "cm/s", 100.0),
            ("m/s", "mm/s", 1000.0),
            ("deg", "decideg", 10.0),
            ("deg", "centideg", 100.0),
            ("rad", "deg", RAD_TO_DEG),
            ("rad/s", "deg/s", RAD_TO_DEG),
            ("rad/s2", "deg/s2", RAD_TO_DEG),
            ("m", "ft", 1.0 / 0.3048),
        ];
        let mut coefs = HashMap::new();
        for (from, to, coef) in pairs {
            coefs.insert((from.to_owned(), to.to_owned()), coef);
            coefs.insert((to.to_owned(), from.to_owned()), 1.0 / coef);
        }
        Self { coefs }
    }

    /// Adds (or replaces) the conversions of `other`.
    pub fn extend(&mut self, other: &Units) {
        self.coefs
            .extend(other.coefs.iter().map(|(k, v)| (k.clone(), *v)));
    }

    /// The coefficient from `from` to `to`, if known.
    pub fn coef(&self, from: &str, to: &str) -> Option<f64> {
        self.coefs.get(&(from.to_owned(), to.to_owned())).copied()
    }
}

/// An `id` attribute value: a class or message id.
fn parse_id(p: &mut xml::Parser<'_, '_>, node: Node<'_, '_>, v: &str, ctx: &Ctx) -> Option<u8> {
    match v.parse::<u8>() {
        Ok(id) => Some(id),
        Err(_) => {
            p.report(
                node,
                ctx,
                ErrorKind::InvalidNumber {
                    attribute: "id",
                    value: v.to_owned(),
                    expected: "an integer in 0..=255",
                },
            );
            None
        }
    }
}

/// The `<protocol>` root of a `messages.xml`: its classes.
fn parse_protocol(p: &mut xml::Parser<'_, '_>) -> Protocol {
    let ctx = Ctx::default();
    let mut seen = Seen::default();
    let classes = match p.root("protocol", "<protocol> as the root element") {
        None => Vec::new(),
        Some(root) => p.children(root, "msg_class", &ctx, "<msg_class>", |p, node| {
            let class = parse_class(p, node)?;
            let line = class.line;
            seen.check(p, node, &ctx, "class name", class.name.clone(), line);
            seen.check(p, node, &ctx, "class id", class.id.to_string(), line);
            let module = names::module_name(&class.name);
            seen.check(p, node, &ctx, "module name of class", module, line);
            let variant = names::camel_case(&class.name);
            seen.check(p, node, &ctx, "Rust variant name of class", variant, line);
            Some(class)
        }),
    };
    Protocol {
        file: p.file().to_owned(),
        classes,
    }
}

/// A `<msg_class>` and its messages; `None` if its name or id is unusable.
fn parse_class(p: &mut xml::Parser<'_, '_>, node: Node<'_, '_>) -> Option<Class> {
    let ctx = Ctx::default();
    // The name makes a module (snake case) and a variant of the set's `AnyMessage`
    // (camel case).
    let name = p.name(node, "msg_class", &ctx).filter(|name| {
        let problem = names::snake_name_problem(name).or_else(|| names::type_name_problem(name));
        !p.unusable(node, &ctx, "class", name, problem)
    });
    let id = p
        .required(node, "msg_class", "id", &ctx)
        .and_then(|v| parse_id(p, node, v, &ctx));
    if let Some(id) = id
        && id > MAX_CLASS_ID
    {
        p.report(
            node,
            &ctx,
            ErrorKind::ClassIdOutOfRange {
                id,
                max: MAX_CLASS_ID,
            },
        );
    }
    let mut seen = Seen::default();
    let messages = p.children(node, "message", &ctx, "<message>", |p, child| {
        let m = parse_message(p, child)?;
        let (ctx, line) = (Ctx::message(&m.name), m.line);
        seen.check(p, child, &ctx, "message name", m.name.clone(), line);
        seen.check(p, child, &ctx, "message id", m.id.to_string(), line);
        let type_name = names::camel_case(&m.name);
        seen.check(p, child, &ctx, "Rust type name of message", type_name, line);
        for f in &m.fields {
            if let Some(e) = f.values_enum(&m.name) {
                let fctx = Ctx {
                    message: Some(m.name.clone()),
                    field: Some(f.name.clone()),
                };
                seen.check(p, child, &fctx, "enum name of `values`", e, f.line);
            }
        }
        Some(m)
    });
    let (line, _) = p.line_col(node);
    Some(Class {
        name: name?,
        id: id?,
        line,
        messages,
    })
}

/// A `<message>` of a class and its fields; `None` if its name or id is unusable.
fn parse_message(p: &mut xml::Parser<'_, '_>, node: Node<'_, '_>) -> Option<MessageDef> {
    let mut ctx = Ctx::default();
    let name = p.name(node, "message", &ctx);
    ctx.message = name.clone();
    // An unusable name is reported, and the message left out of the checks of its class.
    let name = name.filter(|name| {
        let problem = names::type_name_problem(name).or_else(|| {
            (names::camel_case(name) == ANY_MESSAGE).then(|| {
                format!("its Rust type name `{ANY_MESSAGE}` is that of the enum of the messages of its class")
            })
        });
        !p.unusable(node, &ctx, "message", name, problem)
    });
    let id = p
        .required(node, "message", "id", &ctx)
        .and_then(|v| parse_id(p, node, v, &ctx));
    let priority = match node.attribute("priority").map(str::trim) {
        None => None,
        Some(v) => match v.parse::<u8>() {
            Ok(priority) => Some(priority),
            Err(_) => {
                p.report(node, &ctx, ErrorKind::PriorityOutOfRange(v.to_owned()));
                None
            }
        },
    };
    let mut description = None;
    let mut description_line = None;
    let mut fields = Vec::new();
    let mut seen = Seen::default();
    for child in node.children().filter(Node::is_element) {
        match child.tag_name().name() {
            "description" => match description_line {
                Some(first_line) => p.report(
                    child,
                    &ctx,
                    ErrorKind::DuplicateElement {
                        element: "description",
                        first_line,
                    },
                ),
                None => {
                    description_line = Some(p.line_col(child).0);
                    description = text(child);
                }
            },
            "field" => {
                if let Some(f) = parse_field(p, child, &ctx) {
                    let fctx = Ctx {
                        message: ctx.message.clone(),
                        field: Some(f.name.clone()),
                    };
                    seen.check(p, child, &fctx, "field name", f.name.clone(), f.line);
                    seen.check(
                        p,
                        child,
                        &fctx,
                        "Rust name of field",
                        names::snake_case(&f.name),
                        f.line,
                    );
                    fields.push(f);
                }
            }
            _ => p.unexpected(child, &ctx, "<description> or <field>"),
        }
    }
    let (line, _) = p.line_col(node);
    let message = MessageDef {
        name: name?,
        id: id?,
        line,
        priority,
        link: node.attribute("link").map(str::to_owned),
        description,
        fields,
    };
    let min_len = message.min_len();
    if min_len > MAX_PAYLOAD {
        p.report(
            node,
            &ctx,
            ErrorKind::PayloadTooLarge {
                min_len,
                max: MAX_PAYLOAD,
            },
        );
    }
    Some(message)
}

/// A `<field>` of the message `message`; `None` if its name or type is unusable.
fn parse_field(p: &mut xml::Parser<'_, '_>, node: Node<'_, '_>, message: &Ctx) -> Option<FieldDef> {
    let mut ctx = Ctx {
        message: message.message.clone(),
        field: None,
    };
    let name = p.name(node, "field", &ctx);
    ctx.field = name.clone();
    let name =
        name.filter(|name| !p.unusable(node, &ctx, "field", name, names::snake_name_problem(name)));
    for child in node.children().filter(Node::is_element) {
        p.unexpected(child, &ctx, "only text inside <field>");
    }
    let xml_type = p.required(node, "field", "type", &ctx);
    let ty = xml_type.and_then(|t| match parse_type(t) {
        Ok(ty) => Some(ty),
        Err(kind) => {
            p.report(node, &ctx, kind);
            None
        }
    });
    let alt_unit_coef = node
        .attribute("alt_unit_coef")
        .and_then(|v| p.number(node, &ctx, "alt_unit_coef", v.trim(), |_| true, FINITE));
    let values: Vec<String> = node
        .attribute("values")
        .map(|v| v.split('|').map(|s| s.trim().to_owned()).collect())
        .unwrap_or_default();
    if let Some(ty) = ty
        && !values.is_empty()
        && let FieldType::Scalar(base) = ty
        && base.is_integer()
    {
        let capacity = 1u128 << (8 * base.size() - usize::from(is_signed(base)));
        if values.len() as u128 > capacity {
            p.report(
                node,
                &ctx,
                ErrorKind::TooManyValues {
                    count: values.len(),
                    ty: base.xml_name().to_owned(),
                },
            );
        }
    }
    let attr = |a: &str| node.attribute(a).map(|v| v.trim().to_owned());
    let (line, _) = p.line_col(node);
    Some(FieldDef {
        name: name?,
        line,
        xml_type: xml_type?.to_owned(),
        ty: ty?,
        unit: attr("unit"),
        alt_unit: attr("alt_unit"),
        alt_unit_coef,
        format: attr("format"),
        values,
        description: text(node),
    })
}

fn is_signed(base: BaseType) -> bool {
    matches!(
        base,
        BaseType::I8 | BaseType::I16 | BaseType::I32 | BaseType::I64
    )
}

/// The trimmed text of an element, `None` if empty.
fn text(node: Node<'_, '_>) -> Option<String> {
    let t: String = node
        .descendants()
        .filter(Node::is_text)
        .filter_map(|n| n.text())
        .collect();
    let t = t.split_whitespace().collect::<Vec<_>>().join(" ");
    (!t.is_empty()).then_some(t)
}

/// Parses a field type: `uint8`, `float[3]`, `int16[]`, `char[]`, `string`.
pub fn parse_type(t: &str) -> Result<FieldType, ErrorKind> {
    let t = t.trim();
    let (base_name, array) = match t.find('[') {
        None => {
            if t.contains(']') {
                return Err(ErrorKind::MalformedArray(t.to_owned()));
            }
            (t, None)
        }
        Some(open) => {
            let inner = t[open + 1..]
                .strip_suffix(']')
                .ok_or_else(|| ErrorKind::MalformedArray(t.to_owned()))?;
            (&t[..open], Some(inner))
        }
    };
    if base_name == "string" {
        return match array {
            None => Ok(FieldType::Vector(BaseType::Char)),
            Some(_) => Err(ErrorKind::MalformedArray(t.to_owned())),
        };
    }
    let base = BaseType::from_xml_name(base_name.trim())
        .ok_or_else(|| ErrorKind::UnknownType(t.to_owned()))?;
    match array {
        None => Ok(FieldType::Scalar(base)),
        Some("") => Ok(FieldType::Vector(base)),
        Some(n) => match n.trim().parse::<u8>() {
            Ok(n) if n > 0 => Ok(FieldType::Array(base, usize::from(n))),
            _ => Err(ErrorKind::MalformedArray(t.to_owned())),
        },
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_types() {
        assert_eq!(parse_type("uint8"), Ok(FieldType::Scalar(BaseType::U8)));
        assert_eq!(
            parse_type("float[3]"),
            Ok(FieldType::Array(BaseType::F32, 3))
        );
        assert_eq!(parse_type("int16[]"), Ok(FieldType::Vector(BaseType::I16)));
        assert_eq!(parse_type("string"), Ok(FieldType::Vector(BaseType::Char)));
        assert_eq!(
            parse_type(" char[5] "),
            Ok(FieldType::Array(BaseType::Char, 5))
        );
        for bad in [
            "uint8[",
            "uint8]",
            "float[0]",
            "float[256]",
            "int16[x]",
            "string[]",
            "u[]x",
        ] {
            assert!(
                matches!(parse_type(bad), Err(ErrorKind::MalformedArray(_))),
                "{bad}"
            );
        }
        assert_eq!(
            parse_type("uint9"),
            Err(ErrorKind::UnknownType("uint9".into()))
        );
    }
}
