//! Rust source from a validated [`Protocol`].
//!
//! Layout of the output (to `include!` in a module):
//!
//! ```text
//! pub static MESSAGES: MessageSet       every message's descriptor, sorted by (class, id)
//! pub enum AnyMessage<'a>               one variant per class
//! pub struct Set;                       the set, for the runtime: the roles it fills
//! impl roles::Ping for datalink::Ping   each message that fits its role
//! impl roles::ServiceSet for Set        each set role whose messages all fit
//! pub mod telemetry {                   one module per class
//!     pub const CLASS_ID, CLASS_NAME
//!     pub struct Gps { .. }             one struct per message: Message + Decode
//!     pub enum AnyMessage<'a>           one variant per message of the class
//!     pub mod values { pub enum GpsMode { .. } }   enums from `values` attributes
//! }
//! ```
//!
//! Each item at the top level (and so each class module) carries `#[allow(dead_code)]`:
//! a binary crate that includes the code in a private module uses only some messages, and
//! must still compile without a warning (see [`ALLOW_DEAD_CODE`]).
//!
//! # Why text, not `quote` + `prettyplease`
//!
//! The code is written as text (`writeln!` into a `String`), already laid out, rather
//! than built as token trees with `quote` and formatted with `prettyplease`:
//!
//! - This crate is a build-dependency of every firmware that generates its own set:
//!   `syn` (with its `full` feature, which `prettyplease` needs), `quote` and
//!   `prettyplease` would be compiled for every clean firmware build, before its
//!   `build.rs` can even run, to produce the same output. Today the generator needs only
//!   `roxmltree` and `pprz-messages`.
//! - The output is reviewed as snapshots (`tests/snapshots/`) and read by users (it is
//!   their API): written text keeps the layout chosen for reading (a field descriptor per
//!   line, one-line table rows), and a change of the emitter shows as the same change of
//!   the snapshot. `prettyplease` would impose its own layout.
//! - The safety token trees would bring is obtained otherwise: identifiers come from
//!   validated names (`names`: keywords and names that would shadow a primitive type or
//!   a crate are escaped, names that make no usable Rust name are refused by the model),
//!   standard items are named by their full path (`::core::result::Result`, ...) so that
//!   no message type (`RESULT`, `OPTION`, `SOME`...) and nothing where the code is
//!   included shadows them, free text from `messages.xml` is emitted through `{:?}`
//!   string literals (`#[doc = "..."]`) or escaped, and the tests compile the output
//!   (the snapshot, and `tests/fixtures/hostile_names.xml` in a scratch crate).
//!
//! What is emitted more than once has one helper: both `AnyMessage` enums come from
//! [`emit_any_enum`], parameterised by their variants, their `decode` dispatch and their
//! methods.

use std::collections::HashSet;
use std::fmt::Write as _;

use pprz_messages::{BaseType, FieldType};

use crate::model::{Class, FieldDef, MessageDef, Protocol};
use crate::names;
use crate::roles::{self, RoleMessage, Roles, SetRole};

/// The attribute on each item at the top level of the generated code (a class module's
/// covers what the module holds). A binary crate that includes the code uses only some of
/// its messages, and rustc reports the public items of a private module that the crate
/// does not use as `dead_code`: the code compiles without a warning in any crate.
pub(crate) const ALLOW_DEAD_CODE: &str = "#[allow(dead_code)]";

/// Paths of the standard items the generated code uses, from `::core` so that no item
/// of the generated code (a message type named `Result`, `Option`, `Some`, `Default`...)
/// and no item where the code is included can shadow them.
const RESULT: &str = "::core::result::Result";
const OK: &str = "::core::result::Result::Ok";
const ERR: &str = "::core::result::Result::Err";
const OPTION: &str = "::core::option::Option";
const SOME: &str = "::core::option::Option::Some";
const NONE: &str = "::core::option::Option::None";
const DEFAULT: &str = "::core::default::Default";
const FROM: &str = "::core::convert::From";
const TRY_FROM: &str = "::core::convert::TryFrom";

/// What the emitter needs besides the model.
#[derive(Debug, Clone)]
pub(crate) struct Options {
    /// Path of the `pprz-messages` crate in the generated code (`::pprz_messages`).
    pub runtime: String,
    /// Priority of messages without a `priority` attribute.
    pub default_priority: u8,
}

/// Appends formatted text; writing to a `String` cannot fail.
macro_rules! out {
    ($dst:expr, $($arg:tt)*) => {
        let _ = writeln!($dst, $($arg)*);
    };
}

fn has_lifetime(m: &MessageDef) -> bool {
    m.fields
        .iter()
        .any(|f| matches!(f.ty, FieldType::Vector(_)))
}

fn class_has_lifetime(c: &Class) -> bool {
    c.messages.iter().any(has_lifetime)
}

fn lt(yes: bool) -> &'static str {
    if yes { "<'a>" } else { "" }
}

fn rust_type(ty: FieldType) -> String {
    match ty {
        FieldType::Scalar(b) => b.rust_name().to_owned(),
        FieldType::Array(b, n) => format!("[{}; {n}]", b.rust_name()),
        FieldType::Vector(BaseType::Char) => "__rt::Chars<'a>".to_owned(),
        FieldType::Vector(b) => format!("__rt::VarArray<'a, {}>", b.rust_name()),
    }
}

fn base_variant(b: BaseType) -> String {
    format!("__rt::BaseType::{b:?}")
}

fn field_type_expr(ty: FieldType) -> String {
    match ty {
        FieldType::Scalar(b) => format!("__rt::FieldType::Scalar({})", base_variant(b)),
        FieldType::Array(b, n) => format!("__rt::FieldType::Array({}, {n})", base_variant(b)),
        FieldType::Vector(b) => format!("__rt::FieldType::Vector({})", base_variant(b)),
    }
}

fn opt_str(v: &Option<String>) -> String {
    match v {
        Some(s) => format!("{SOME}({s:?})"),
        None => NONE.to_owned(),
    }
}

/// A `#[doc = "..."]` line for each paragraph; the text is escaped as a string literal.
fn doc(out: &mut String, indent: &str, text: &str) {
    for line in text.lines() {
        out!(out, "{indent}#[doc = {:?}]", format!(" {line}"));
    }
}

/// Free text from `messages.xml` made inert in Markdown: rustdoc must not read its
/// brackets as links, its angle brackets as HTML or its stars as emphasis.
fn escape_markdown(text: &str) -> String {
    let mut out = String::with_capacity(text.len());
    for c in text.chars() {
        match c {
            '\\' | '[' | ']' | '*' | '`' | '_' | '#' | '|' => {
                out.push('\\');
                out.push(c);
            }
            '<' => out.push_str("&lt;"),
            '>' => out.push_str("&gt;"),
            '&' => out.push_str("&amp;"),
            _ => out.push(c),
        }
    }
    out
}

fn field_doc(f: &FieldDef) -> String {
    let mut d = f
        .description
        .as_deref()
        .map(escape_markdown)
        .unwrap_or_default();
    let mut meta = Vec::new();
    meta.push(format!("`{}`", f.xml_type));
    if let Some(u) = &f.unit {
        meta.push(format!("unit `{u}`"));
    }
    if let Some(u) = &f.alt_unit {
        match f.alt_unit_coef {
            Some(c) => meta.push(format!("displayed in `{u}` (x {c})")),
            None => meta.push(format!("displayed in `{u}`")),
        }
    }
    if !f.values.is_empty() {
        meta.push(format!("values `{}`", f.values.join("|")));
    }
    if !d.is_empty() {
        d.push_str("\n\n");
    }
    d.push_str(&meta.join(", "));
    d.push('.');
    d
}

/// Unique variant names for a list of labels.
fn variants(labels: &[String]) -> Vec<String> {
    let mut used = HashSet::new();
    labels
        .iter()
        .enumerate()
        .map(|(i, label)| {
            let mut v = names::variant_name(label).unwrap_or_else(|| format!("Value{i}"));
            if v == "Self" {
                v.push_str("Value");
            }
            if !used.insert(v.clone()) {
                v = format!("{v}Index{i}");
                used.insert(v.clone());
            }
            v
        })
        .collect()
}

pub(crate) fn emit(protocol: &Protocol, opts: &Options) -> String {
    let mut out = String::new();
    out!(
        out,
        "// Generated by pprz-codegen {} from `{}`. Do not edit.\n",
        env!("CARGO_PKG_VERSION"),
        protocol.file
    );
    emit_message_table(&mut out, protocol, opts);
    emit_any(&mut out, protocol, opts);
    emit_roles(&mut out, protocol, opts);
    for class in &protocol.classes {
        emit_class(&mut out, class, opts);
    }
    out
}

fn emit_message_table(out: &mut String, protocol: &Protocol, opts: &Options) {
    let rt = &opts.runtime;
    let mut all: Vec<(u8, u8, String)> = protocol
        .classes
        .iter()
        .flat_map(|c| {
            c.messages.iter().map(move |m| {
                (
                    c.id,
                    m.id,
                    format!(
                        "<{}::{} as {rt}::Message>::DESCRIPTOR",
                        names::module_name(&c.name),
                        names::camel_case(&m.name)
                    ),
                )
            })
        })
        .collect();
    all.sort_by_key(|(c, m, _)| (*c, *m));
    out!(
        out,
        "/// Every message of this set ({} messages), sorted by (class id, message id).",
        all.len()
    );
    out!(out, "{ALLOW_DEAD_CODE}");
    out!(
        out,
        "pub static MESSAGES: {rt}::MessageSet<'static> = {rt}::MessageSet::new(&["
    );
    for (_, _, expr) in &all {
        out!(out, "    {expr},");
    }
    out!(out, "]);\n");
}

/// The set's `AnyMessage`: one variant per class.
fn emit_any(out: &mut String, protocol: &Protocol, opts: &Options) {
    let delegate = |doc: &'static str, sig: String, call: &'static str| AnyMethod {
        doc: vec![doc],
        sig,
        bind: true,
        arm: Box::new(move |_| format!("m.{call}")),
    };
    emit_any_enum(
        out,
        &AnyEnum {
            indent: "",
            doc: "A decoded message of any class of this set.",
            attrs: &[],
            rt: &opts.runtime,
            variants: protocol
                .classes
                .iter()
                .map(|c| {
                    let module = names::module_name(&c.name);
                    let lifetime = class_has_lifetime(c);
                    AnyVariant {
                        name: names::camel_case(&c.name),
                        ty: format!("{module}::AnyMessage{}", lt(lifetime)),
                        lifetime,
                        doc: format!("A message of class `{}` (id {}).", c.name, c.id),
                        id: c.id,
                        decode: set_decode_arm(c, &opts.runtime),
                    }
                })
                .collect(),
            dispatch: Dispatch {
                doc: "given its class and message id",
                errors: "Unknown class or message id, or a payload of the wrong length.",
                params: "class_id: u8, msg_id: u8",
                on: "class_id",
                unknown: "class_id, msg_id",
            },
            methods: vec![
                AnyMethod {
                    doc: vec!["Class id of the message."],
                    sig: "class_id(&self) -> u8".to_owned(),
                    bind: false,
                    arm: Box::new(|v| v.id.to_string()),
                },
                delegate(
                    "Message id within the class.",
                    "id(&self) -> u8".into(),
                    "id()",
                ),
                delegate(
                    "Message name.",
                    "name(&self) -> &'static str".into(),
                    "name()",
                ),
                delegate(
                    "Send priority.",
                    "priority(&self) -> u8".into(),
                    "priority()",
                ),
                delegate(
                    "Length of the encoded fields.",
                    "encoded_len(&self) -> usize".into(),
                    "encoded_len()",
                ),
                delegate(
                    "Encodes the fields into `buf`, returning the length written (errors as the message's encoder).",
                    format!(
                        "encode(&self, buf: &mut [u8]) -> {RESULT}<usize, {}::EncodeError>",
                        opts.runtime
                    ),
                    "encode(buf)",
                ),
            ],
            from_impls: false,
            allow_dead_code: true,
            helpers: Some(protocol),
        },
    );
}

/// The `Set` type, and the traits of `roles` for what the set fills (see [`crate::roles`]).
///
/// A message that fits its role implements the message's role trait even when its set
/// role is incomplete (a `PING` without a `DL_VALUE` still implements `roles::Ping`):
/// code that needs only that message can use it, while code that needs the set role
/// still does not compile, and the documentation of `Set` says why.
fn emit_roles(out: &mut String, protocol: &Protocol, opts: &Options) {
    let rt = &opts.runtime;
    let roles = Roles::of(protocol);
    let code = |s: &str| format!("`{s}`");
    let mut d = format!(
        "The message set of this file, for the runtime's set-generic code: the roles of\n\
         `{rt}::roles` the set fills are implemented on this type.\n"
    );
    let mut alone = Vec::new();
    for role in SetRole::ALL {
        match roles.set(role) {
            Ok(fits) => {
                let names: Vec<String> = fits.iter().map(|(m, _)| code(m.name())).collect();
                let _ = write!(d, "\n- `{}`: {}.", role.name(), roles::list(&names));
            }
            Err(why) => {
                let _ = write!(d, "\n- no `{}`: {}.", role.name(), why.join("; "));
                for &m in role.messages() {
                    if let Some(Ok(fit)) = roles.get(m) {
                        alone.push(format!("`{}` ({})", m.role(), code(&fit.path)));
                    }
                }
            }
        }
    }
    if !alone.is_empty() {
        let _ = write!(
            d,
            "\n\nMessages that fit their role implement it without the set role: {}.",
            roles::list(&alone)
        );
    }
    doc(out, "", &d);
    out!(out, "{ALLOW_DEAD_CODE}");
    out!(
        out,
        "#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]"
    );
    out!(out, "pub struct Set;\n");
    for (m, fit) in &roles.messages {
        if let Ok(fit) = fit {
            emit_message_role(out, rt, *m, &fit.path);
        }
    }
    for role in SetRole::ALL {
        if let Ok(fits) = roles.set(role) {
            out!(out, "impl {rt}::roles::{} for Set {{", role.name());
            for (m, fit) in fits {
                out!(out, "    type {} = {};", m.assoc(), fit.path);
            }
            out!(out, "}}\n");
        }
    }
}

/// The role trait of message `m` (of type `path`), whose fields are those of the role.
fn emit_message_role(out: &mut String, rt: &str, m: RoleMessage, path: &str) {
    let role = format!("{rt}::roles::{}", m.role());
    let fields = m.fields();
    match m {
        RoleMessage::Ping => {
            out!(out, "impl {role} for {path} {{}}\n");
        }
        RoleMessage::Pong => {
            out!(out, "impl {role} for {path} {{");
            out!(out, "    fn pong() -> Self {{");
            out!(out, "        Self");
            out!(out, "    }}");
            out!(out, "}}\n");
        }
        RoleMessage::Setting | RoleMessage::GetSetting => {
            out!(out, "impl {role} for {path} {{");
            for (name, ty) in fields {
                out!(out, "    fn {name}(&self) -> {} {{", ty.rust_name());
                out!(out, "        self.{name}");
                out!(out, "    }}");
            }
            out!(out, "}}\n");
        }
        RoleMessage::DlValue => {
            let params: Vec<String> = fields
                .iter()
                .map(|(name, ty)| format!("{name}: {}", ty.rust_name()))
                .collect();
            let names: Vec<&str> = fields.iter().map(|(name, _)| *name).collect();
            out!(out, "impl {role} for {path} {{");
            out!(out, "    fn new({}) -> Self {{", params.join(", "));
            out!(out, "        Self {{ {} }}", names.join(", "));
            out!(out, "    }}");
            out!(out, "}}\n");
        }
        RoleMessage::DatalinkReport => {
            out!(out, "impl {FROM}<{rt}::roles::LinkReport> for {path} {{");
            out!(out, "    fn from(r: {rt}::roles::LinkReport) -> Self {{");
            out!(out, "        Self {{");
            for (name, _) in fields {
                out!(out, "            {name}: r.{name},");
            }
            out!(out, "        }}");
            out!(out, "    }}");
            out!(out, "}}\n");
            out!(out, "impl {role} for {path} {{}}\n");
        }
    }
}

fn emit_class(out: &mut String, class: &Class, opts: &Options) {
    let module = names::module_name(&class.name);
    out!(
        out,
        "/// Messages of class `{}` (id {}).",
        class.name,
        class.id
    );
    out!(out, "{ALLOW_DEAD_CODE}");
    out!(out, "pub mod {module} {{");
    out!(out, "    use {} as __rt;\n", opts.runtime);
    out!(out, "    /// Id of this class.");
    out!(out, "    pub const CLASS_ID: u8 = {};", class.id);
    out!(out, "    /// Name of this class.");
    out!(out, "    pub const CLASS_NAME: &str = {:?};\n", class.name);
    for m in &class.messages {
        emit_message(out, class, m, opts);
    }
    emit_class_any(out, class);
    emit_values(out, class);
    out!(out, "}}\n");
}

/// One message of a class: its struct, `Default` where it cannot be derived, `Message`
/// (descriptor and encoder), `Decode`, and the accessors of its enumerated fields.
fn emit_message(out: &mut String, class: &Class, m: &MessageDef, opts: &Options) {
    let item = MessageItem {
        class,
        m,
        ty: names::camel_case(&m.name),
        l: lt(has_lifetime(m)),
        priority: m.priority.unwrap_or(opts.default_priority),
    };
    emit_struct(out, &item);
    emit_default(out, &item);
    emit_message_impl(out, &item);
    emit_decode(out, &item);
    emit_value_accessors(out, &item);
}

/// What the items of one message are written from.
struct MessageItem<'a> {
    class: &'a Class,
    m: &'a MessageDef,
    /// The Rust type name.
    ty: String,
    /// `<'a>` if the type borrows from the payload, else empty.
    l: &'static str,
    /// The message's own priority, or the set's default.
    priority: u8,
}

/// Whether `Default` can be derived: no array longer than 32 elements.
fn derivable_default(m: &MessageDef) -> bool {
    m.fields
        .iter()
        .all(|f| !matches!(f.ty, FieldType::Array(_, n) if n > 32))
}

/// The message's doc comment and its struct, one public field per `<field>`.
fn emit_struct(out: &mut String, item: &MessageItem) {
    let MessageItem {
        class,
        m,
        ty,
        l,
        priority,
    } = item;
    let mut d = m
        .description
        .clone()
        .unwrap_or_else(|| format!("`{}`", m.name));
    let _ = write!(
        d,
        "\n\n`{}`: class `{}` ({}), id {}, priority {priority}, {} payload bytes.",
        m.name,
        class.name,
        class.id,
        m.id,
        if m.is_fixed_size() {
            m.min_len().to_string()
        } else {
            format!("{}..={}", m.min_len(), m.max_len())
        }
    );
    doc(out, "    ", &d);
    if derivable_default(m) {
        out!(out, "    #[derive(Debug, Clone, Copy, PartialEq, Default)]");
    } else {
        out!(out, "    #[derive(Debug, Clone, Copy, PartialEq)]");
    }
    if m.fields.is_empty() {
        out!(out, "    pub struct {ty};\n");
    } else {
        out!(out, "    pub struct {ty}{l} {{");
        for f in &m.fields {
            doc(out, "        ", &field_doc(f));
            out!(
                out,
                "        pub {}: {},",
                names::snake_case(&f.name),
                rust_type(f.ty)
            );
        }
        out!(out, "    }}\n");
    }
}

/// `Default` written out, for a message whose arrays are too long to derive it.
fn emit_default(out: &mut String, item: &MessageItem) {
    let MessageItem { m, ty, l, .. } = item;
    if derivable_default(m) {
        return;
    }
    out!(out, "    impl{l} {DEFAULT} for {ty}{l} {{");
    out!(out, "        fn default() -> Self {{");
    out!(out, "            Self {{");
    for f in &m.fields {
        let v = match f.ty {
            FieldType::Array(_, n) => format!("[{DEFAULT}::default(); {n}]"),
            FieldType::Scalar(_) | FieldType::Vector(_) => format!("{DEFAULT}::default()"),
        };
        out!(out, "                {}: {v},", names::snake_case(&f.name));
    }
    out!(out, "            }}");
    out!(out, "        }}");
    out!(out, "    }}\n");
}

/// `impl Message`: the constants, the descriptor, the encoder.
fn emit_message_impl(out: &mut String, item: &MessageItem) {
    let MessageItem {
        class,
        m,
        ty,
        l,
        priority,
    } = item;
    let min = m.min_len();
    let max = m.max_len();
    out!(out, "    impl{l} __rt::Message for {ty}{l} {{");
    out!(out, "        const CLASS_ID: u8 = {};", class.id);
    out!(out, "        const ID: u8 = {};", m.id);
    out!(out, "        const NAME: &'static str = {:?};", m.name);
    out!(out, "        const PRIORITY: u8 = {priority};");
    out!(out, "        const MIN_LEN: usize = {min};");
    out!(out, "        const MAX_LEN: usize = {max};");
    emit_descriptor(out, class, m, *priority);
    emit_encode(out, m);
}

/// The `DESCRIPTOR` constant of `impl Message`.
fn emit_descriptor(out: &mut String, class: &Class, m: &MessageDef, priority: u8) {
    out!(
        out,
        "        const DESCRIPTOR: __rt::MessageDescriptor<'static> = __rt::MessageDescriptor {{"
    );
    out!(
        out,
        "            class_id: {}, class_name: {:?}, id: {}, name: {:?}, priority: {priority},",
        class.id,
        class.name,
        m.id,
        m.name
    );
    out!(out, "            fields: &[");
    for f in &m.fields {
        let values = if f.values.is_empty() {
            "&[]".to_owned()
        } else {
            format!(
                "&[{}]",
                f.values
                    .iter()
                    .map(|v| format!("{v:?}"))
                    .collect::<Vec<_>>()
                    .join(", ")
            )
        };
        out!(out, "                __rt::FieldDescriptor {{");
        out!(
            out,
            "                    name: {:?}, ty: {},",
            f.name,
            field_type_expr(f.ty)
        );
        out!(
            out,
            "                    unit: {}, alt_unit: {}, alt_unit_coef: {}, format: {}, values: {values},",
            opt_str(&f.unit),
            opt_str(&f.alt_unit),
            match f.alt_unit_coef {
                Some(c) => format!("{SOME}({c:?})"),
                None => NONE.to_owned(),
            },
            opt_str(&f.format)
        );
        out!(out, "                }},");
    }
    out!(out, "            ],");
    out!(out, "        }};\n");
}

/// `encoded_len` and `encode` of `impl Message`, and the end of the impl.
fn emit_encode(out: &mut String, m: &MessageDef) {
    let var_terms: Vec<String> = m
        .fields
        .iter()
        .filter_map(|f| match f.ty {
            FieldType::Vector(BaseType::Char) => {
                Some(format!("self.{}.len()", names::snake_case(&f.name)))
            }
            FieldType::Vector(_) => Some(format!("self.{}.wire_len()", names::snake_case(&f.name))),
            _ => None,
        })
        .collect();
    out!(out, "        #[inline]");
    out!(out, "        fn encoded_len(&self) -> usize {{");
    if var_terms.is_empty() {
        out!(out, "            Self::MIN_LEN");
    } else {
        out!(out, "            Self::MIN_LEN + {}", var_terms.join(" + "));
    }
    out!(out, "        }}\n");
    out!(out, "        #[inline]");
    out!(
        out,
        "        fn encode(&self, buf: &mut [u8]) -> {RESULT}<usize, __rt::EncodeError> {{"
    );
    let mutw = if m.fields.is_empty() { "" } else { "mut " };
    out!(
        out,
        "            let {mutw}w = __rt::wire::Writer::new(buf, __rt::Message::encoded_len(self))?;"
    );
    for f in &m.fields {
        let name = names::snake_case(&f.name);
        let call = match f.ty {
            FieldType::Scalar(_) => format!("scalar(self.{name})"),
            FieldType::Array(..) => format!("array(&self.{name})"),
            FieldType::Vector(BaseType::Char) => format!("chars(&self.{name})"),
            FieldType::Vector(_) => format!("vector(&self.{name})"),
        };
        out!(out, "            w.{call}?;");
    }
    out!(out, "            {OK}(w.finish())");
    out!(out, "        }}");
    out!(out, "    }}\n");
}

/// `impl Decode`: a reader over the payload, one read per field.
fn emit_decode(out: &mut String, item: &MessageItem) {
    let MessageItem { m, ty, l, .. } = item;
    out!(out, "    impl<'a> __rt::Decode<'a> for {ty}{l} {{");
    out!(out, "        #[inline]");
    out!(
        out,
        "        fn decode(payload: &'a [u8]) -> {RESULT}<Self, __rt::DecodeError> {{"
    );
    decode_body(out, m, "            ", "__rt", "Self", "msg");
    out!(out, "        }}");
    out!(out, "    }}\n");
}

/// The statements of a decoder of `m` from `payload`: a reader over it, one read per
/// field into the struct `ty`, then `Ok(ok)` (an expression of `msg`, the message).
fn decode_body(out: &mut String, m: &MessageDef, i: &str, rt: &str, ty: &str, ok: &str) {
    let min = m.min_len();
    let mutr = if m.fields.is_empty() { "" } else { "mut " };
    if m.is_fixed_size() {
        out!(
            out,
            "{i}let {mutr}r = {rt}::wire::Reader::exact(payload, {min})?;"
        );
    } else {
        out!(out, "{i}let {mutr}r = {rt}::wire::Reader::new(payload);");
    }
    if m.fields.is_empty() {
        out!(out, "{i}let msg = {ty};");
    } else {
        out!(out, "{i}let msg = {ty} {{");
        for f in &m.fields {
            let call = match f.ty {
                FieldType::Scalar(_) => "scalar",
                FieldType::Array(..) => "array",
                FieldType::Vector(BaseType::Char) => "chars",
                FieldType::Vector(_) => "vector",
            };
            out!(out, "{i}    {}: r.{call}()?,", names::snake_case(&f.name));
        }
        out!(out, "{i}}};");
    }
    out!(out, "{i}r.finish()?;");
    out!(out, "{i}{OK}({ok})");
}

/// Typed accessors for enumerated fields (`mode_value()` -> `Option<values::GpsMode>`).
fn emit_value_accessors(out: &mut String, item: &MessageItem) {
    let MessageItem { m, ty, l, .. } = item;
    let enums: Vec<(&FieldDef, String)> = m
        .fields
        .iter()
        .filter_map(|f| f.values_enum(&m.name).map(|e| (f, e)))
        .collect();
    if !enums.is_empty() {
        out!(out, "    impl{l} {ty}{l} {{");
        for (f, e) in enums {
            let name = names::snake_case(&f.name);
            let getter = format!("{}_value", name.trim_end_matches('_'));
            out!(
                out,
                "        /// `{}` as [`values::{e}`], `None` if the raw value has no label.",
                f.name
            );
            out!(
                out,
                "        pub fn {getter}(&self) -> {OPTION}<values::{e}> {{"
            );
            out!(out, "            values::{e}::from_raw(self.{name})");
            out!(out, "        }}");
        }
        out!(out, "    }}\n");
    }
}

/// The arm of the set's `AnyMessage::decode` for `class`: a `match msg_id` that calls
/// the message's helper of [`set_decode_helpers`].
fn set_decode_arm(class: &Class, rt: &str) -> String {
    let mut arm = String::from("match msg_id {\n");
    for m in &class.messages {
        out!(
            arm,
            "                {} => Self::{}(payload),",
            m.id,
            set_decode_helper_name(class, m),
        );
    }
    out!(
        arm,
        "                _ => {ERR}({rt}::DecodeError::UnknownMessage {{ class_id, msg_id }}),"
    );
    arm.push_str("            }");
    arm
}

/// Name of the set-level helper that decodes message `m` of `class`: made of the ids,
/// which are unique in the set (names joined by `_` could collide).
fn set_decode_helper_name(class: &Class, m: &MessageDef) -> String {
    format!("decode_{}_{}", class.id, m.id)
}

/// The set's `AnyMessage::decode` helpers, one per message: each reads the fields
/// itself (the statements of the message's `Decode` impl) and builds the set's variant
/// from them, so the message is written straight where the caller wants the result.
///
/// Calling the message's `Decode::decode` and wrapping its result instead costs, where
/// the compiler keeps that call out of line (x86_64 at `opt-level = "s"`), a temporary
/// `Result` and two copies of the message. A helper is its own function: where `decode`
/// stays out of line, its dispatch jumps to the helper (a tail call); where `decode` is
/// inlined into its caller (Cortex-M), so are the helpers, as the `Decode` impls were.
fn set_decode_helpers(out: &mut String, protocol: &Protocol, rt: &str, input: &str) {
    for class in &protocol.classes {
        let module = names::module_name(&class.name);
        let variant = names::camel_case(&class.name);
        for m in &class.messages {
            let name = names::camel_case(&m.name);
            out!(
                out,
                "    /// Decodes `{}` of class `{}`.",
                m.name,
                class.name
            );
            out!(out, "    #[inline]");
            out!(
                out,
                "    fn {}(payload: {input}) -> {RESULT}<Self, {rt}::DecodeError> {{",
                set_decode_helper_name(class, m)
            );
            decode_body(
                out,
                m,
                "        ",
                rt,
                &format!("{module}::{name}"),
                &format!("Self::{variant}({module}::AnyMessage::{name}(msg))"),
            );
            out!(out, "    }}\n");
        }
    }
}

/// A class's `AnyMessage`: one variant per message.
fn emit_class_any(out: &mut String, class: &Class) {
    // The variants are named after the message types, so `v.name` is the type.
    // `const_ref`: "" for the constant's value, "&" for a reference to it.
    let constant =
        |doc: &'static str, sig: &str, const_ref: &'static str, name: &'static str| AnyMethod {
            doc: vec![doc],
            sig: sig.to_owned(),
            bind: false,
            arm: Box::new(move |v| format!("{const_ref}<{} as __rt::Message>::{name}", v.name)),
        };
    let call = |doc: Vec<&'static str>, sig: &str, expr: &'static str| AnyMethod {
        doc,
        sig: sig.to_owned(),
        bind: true,
        arm: Box::new(move |_| expr.to_owned()),
    };
    emit_any_enum(
        out,
        &AnyEnum {
            indent: "    ",
            doc: "A decoded message of this class.",
            attrs: &["#[allow(clippy::large_enum_variant)]"],
            rt: "__rt",
            variants: class
                .messages
                .iter()
                .map(|m| {
                    let name = names::camel_case(&m.name);
                    let lifetime = has_lifetime(m);
                    let ty = format!("{name}{}", lt(lifetime));
                    AnyVariant {
                        decode: format!(
                            "<{ty} as __rt::Decode>::decode(payload).map(Self::{name})"
                        ),
                        doc: format!("`{}` (id {}).", m.name, m.id),
                        id: m.id,
                        name,
                        ty,
                        lifetime,
                    }
                })
                .collect(),
            dispatch: Dispatch {
                doc: "given its message id",
                errors: "Unknown message id, or a payload of the wrong length.",
                params: "msg_id: u8",
                on: "msg_id",
                unknown: "class_id: CLASS_ID, msg_id",
            },
            methods: vec![
                constant("Message id.", "id(&self) -> u8", "", "ID"),
                constant("Message name.", "name(&self) -> &'static str", "", "NAME"),
                constant("Send priority.", "priority(&self) -> u8", "", "PRIORITY"),
                constant(
                    "Description of the message.",
                    "descriptor(&self) -> &'static __rt::MessageDescriptor<'static>",
                    "&",
                    "DESCRIPTOR",
                ),
                call(
                    vec!["Length of the encoded fields."],
                    "encoded_len(&self) -> usize",
                    "__rt::Message::encoded_len(m)",
                ),
                call(
                    vec![
                        "Encodes the fields into `buf`, returning the length written.",
                        "",
                        "# Errors",
                        "See [`Message::encode`](__rt::Message::encode).",
                    ],
                    &format!("encode(&self, buf: &mut [u8]) -> {RESULT}<usize, __rt::EncodeError>"),
                    "__rt::Message::encode(m, buf)",
                ),
            ],
            from_impls: true,
            allow_dead_code: false,
            helpers: None,
        },
    );
}

/// A variant of an `AnyMessage` enum.
struct AnyVariant {
    /// Variant name (`Telemetry`, `Gps`).
    name: String,
    /// The type it holds, with its lifetime if it has one (`telemetry::AnyMessage<'a>`).
    ty: String,
    /// Whether `ty` has the lifetime `'a`.
    lifetime: bool,
    /// Doc comment.
    doc: String,
    /// The id it is decoded from (class id, or message id).
    id: u8,
    /// Expression decoding `payload` into a `Result<Self, DecodeError>` (the enum's
    /// `Self`, this variant or an error).
    decode: String,
}

/// How `decode` picks the variant.
struct Dispatch {
    /// What the payload is decoded by, in the doc comment (`given its message id`).
    doc: &'static str,
    /// The `# Errors` section of the doc comment.
    errors: &'static str,
    /// The id parameters (`msg_id: u8`); a `payload` parameter follows.
    params: &'static str,
    /// The parameter matched against the variants' ids.
    on: &'static str,
    /// Fields of `DecodeError::UnknownMessage` for an unknown id.
    unknown: &'static str,
}

/// A method of an `AnyMessage` enum: one `match self` arm per variant.
struct AnyMethod<'f> {
    /// Doc comment lines.
    doc: Vec<&'static str>,
    /// Signature after `pub fn`.
    sig: String,
    /// Whether the arms bind the message as `m` (else `_`).
    bind: bool,
    /// Expression of a variant's arm.
    arm: Box<dyn Fn(&AnyVariant) -> String + 'f>,
}

/// What differs between the set's `AnyMessage` and a class's.
struct AnyEnum<'f> {
    /// Indentation of the items (inside a class module or not).
    indent: &'static str,
    /// Doc comment of the enum.
    doc: &'static str,
    /// Attributes after the derives.
    attrs: &'static [&'static str],
    /// Path of the runtime crate as seen from the enum.
    rt: &'f str,
    variants: Vec<AnyVariant>,
    dispatch: Dispatch,
    /// Methods after `decode`.
    methods: Vec<AnyMethod<'f>>,
    /// Whether to emit `From<message>` for each variant.
    from_impls: bool,
    /// Whether the enum and its inherent impl carry [`ALLOW_DEAD_CODE`] (at the top
    /// level; inside a class module, the module's attribute covers them).
    allow_dead_code: bool,
    /// The set whose per-message decode helpers ([`set_decode_helpers`]) the inherent
    /// impl holds (the set's `AnyMessage` only).
    helpers: Option<&'f Protocol>,
}

/// An `AnyMessage` enum, its `decode`, its methods and, if asked, its `From` impls.
fn emit_any_enum(out: &mut String, e: &AnyEnum) {
    let i = e.indent;
    let rt = e.rt;
    let life = e.variants.iter().any(|v| v.lifetime);
    let l = lt(life);
    let docs = |out: &mut String, lines: &[&str]| {
        for line in lines {
            if line.is_empty() {
                out!(out, "{i}    ///");
            } else {
                out!(out, "{i}    /// {line}");
            }
        }
    };
    let allow = if e.allow_dead_code {
        format!("{i}{ALLOW_DEAD_CODE}\n")
    } else {
        String::new()
    };
    out!(out, "{i}/// {}", e.doc);
    out.push_str(&allow);
    out!(out, "{i}#[derive(Debug, Clone, Copy, PartialEq)]");
    for attr in e.attrs {
        out!(out, "{i}{attr}");
    }
    out!(out, "{i}pub enum AnyMessage{l} {{");
    for v in &e.variants {
        out!(out, "{i}    /// {}", v.doc);
        out!(out, "{i}    {}({}),", v.name, v.ty);
    }
    out!(out, "{i}}}\n");

    let d = &e.dispatch;
    let input = if life { "&'a [u8]" } else { "&[u8]" };
    // A class without messages (legal in messages.xml) decodes nothing: its enum is
    // uninhabited, its matches dereference `self` to be exhaustive without arms, and its
    // methods' arguments go unused.
    let empty = e.variants.is_empty();
    out.push_str(&allow);
    if empty {
        out!(out, "{i}#[allow(unused_variables)]");
    }
    out!(out, "{i}impl{l} AnyMessage{l} {{");
    docs(
        out,
        &[
            &format!("Decodes a payload (fields only) {}.", d.doc),
            "",
            "# Errors",
            d.errors,
        ],
    );
    out!(
        out,
        "{i}    pub fn decode({}, payload: {input}) -> {RESULT}<Self, {rt}::DecodeError> {{",
        d.params
    );
    out!(out, "{i}        match {} {{", d.on);
    for v in &e.variants {
        out!(out, "{i}            {} => {},", v.id, v.decode,);
    }
    out!(
        out,
        "{i}            _ => {ERR}({rt}::DecodeError::UnknownMessage {{ {} }}),",
        d.unknown
    );
    out!(out, "{i}        }}");
    out!(out, "{i}    }}\n");
    if let Some(protocol) = e.helpers {
        set_decode_helpers(out, protocol, rt, input);
    }
    for method in &e.methods {
        docs(out, &method.doc);
        out!(out, "{i}    pub fn {} {{", method.sig);
        out!(
            out,
            "{i}        match {}self {{",
            if empty { "*" } else { "" }
        );
        let pat = if method.bind { "m" } else { "_" };
        for v in &e.variants {
            out!(
                out,
                "{i}            Self::{}({pat}) => {},",
                v.name,
                (method.arm)(v)
            );
        }
        out!(out, "{i}        }}");
        out!(out, "{i}    }}\n");
    }
    out!(out, "{i}}}\n");

    if e.from_impls {
        emit_any_from_impls(out, e, l);
    }
}

/// `From<Message>` for each variant of an `AnyMessage` enum (`l`: its lifetime, if any).
fn emit_any_from_impls(out: &mut String, e: &AnyEnum, l: &str) {
    let i = e.indent;
    for v in &e.variants {
        out!(out, "{i}impl{l} {FROM}<{}> for AnyMessage{l} {{", v.ty);
        out!(out, "{i}    fn from(m: {}) -> Self {{", v.ty);
        out!(out, "{i}        Self::{}(m)", v.name);
        out!(out, "{i}    }}");
        out!(out, "{i}}}\n");
    }
}

/// A class's `values` module: an enum per enumerated field.
fn emit_values(out: &mut String, class: &Class) {
    let enums: Vec<(&MessageDef, &FieldDef, String)> = class
        .messages
        .iter()
        .flat_map(|m| {
            m.fields
                .iter()
                .filter_map(move |f| f.values_enum(&m.name).map(|e| (m, f, e)))
        })
        .collect();
    if enums.is_empty() {
        return;
    }
    out!(
        out,
        "    /// Enumerations from the `values` attributes of this class' fields."
    );
    out!(out, "    pub mod values {{");
    // Enum names are unique within a class (checked by the model).
    for (m, f, e) in enums {
        emit_value_enum(out, m, f, &e);
    }
    out!(out, "    }}");
}

/// The enum `e` of field `f`'s `values` and its conversions from and to the raw value.
fn emit_value_enum(out: &mut String, m: &MessageDef, f: &FieldDef, e: &str) {
    let FieldType::Scalar(base) = f.ty else {
        return;
    };
    let repr = base.rust_name();
    let vs = variants(&f.values);
    out!(
        out,
        "        /// Values of field `{}` of `{}`.",
        f.name,
        m.name
    );
    out!(
        out,
        "        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]"
    );
    out!(out, "        #[repr({repr})]");
    out!(out, "        pub enum {e} {{");
    for (i, (v, label)) in vs.iter().zip(&f.values).enumerate() {
        out!(out, "            /// `{label}`");
        out!(out, "            {v} = {i},");
    }
    out!(out, "        }}\n");
    emit_value_enum_impls(out, f, e, repr, &vs);
}

/// `LABELS`, `from_raw`, `raw`, `label`, `TryFrom` and `From` of value enum `e`.
fn emit_value_enum_impls(out: &mut String, f: &FieldDef, e: &str, repr: &str, vs: &[String]) {
    out!(out, "        impl {e} {{");
    out!(
        out,
        "            /// Labels by raw value, as in `messages.xml`."
    );
    out!(
        out,
        "            pub const LABELS: &'static [&'static str] = &[{}];",
        f.values
            .iter()
            .map(|v| format!("{v:?}"))
            .collect::<Vec<_>>()
            .join(", ")
    );
    out!(out, "            /// The value for a raw field value.");
    out!(
        out,
        "            pub const fn from_raw(raw: {repr}) -> {OPTION}<Self> {{"
    );
    out!(out, "                match raw {{");
    for (i, v) in vs.iter().enumerate() {
        out!(out, "                    {i} => {SOME}(Self::{v}),");
    }
    out!(out, "                    _ => {NONE},");
    out!(out, "                }}");
    out!(out, "            }}");
    out!(out, "            /// The raw field value.");
    out!(out, "            pub const fn raw(self) -> {repr} {{");
    out!(out, "                self as {repr}");
    out!(out, "            }}");
    out!(out, "            /// The label, as in `messages.xml`.");
    out!(
        out,
        "            pub const fn label(self) -> &'static str {{"
    );
    out!(out, "                match self {{");
    for (v, label) in vs.iter().zip(&f.values) {
        out!(out, "                    Self::{v} => {label:?},");
    }
    out!(out, "                }}");
    out!(out, "            }}");
    out!(out, "        }}\n");
    out!(out, "        impl {TRY_FROM}<{repr}> for {e} {{");
    out!(out, "            type Error = {repr};");
    out!(
        out,
        "            fn try_from(raw: {repr}) -> {RESULT}<Self, {repr}> {{"
    );
    out!(out, "                Self::from_raw(raw).ok_or(raw)");
    out!(out, "            }}");
    out!(out, "        }}\n");
    out!(out, "        impl {FROM}<{e}> for {repr} {{");
    out!(out, "            fn from(v: {e}) -> {repr} {{");
    out!(out, "                v.raw()");
    out!(out, "            }}");
    out!(out, "        }}\n");
}
