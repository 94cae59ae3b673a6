//! Generator errors: every problem names the file, line and column, and the message and
//! field it is about.
//!
//! Their `Display` escapes the text they quote from the inputs (see [`crate::escape`]):
//! a diagnostic is printed as it is, never with a raw control character.

use std::fmt::{self, Write as _};

use crate::escape::Escaping;

/// Where a problem is and what it is about.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Diagnostic {
    /// The input file (as given to the generator).
    pub file: String,
    /// 1-based line, 0 when the problem is about the file as a whole.
    pub line: u32,
    /// 1-based column, 0 when unknown.
    pub column: u32,
    /// The message the problem is in, if any.
    pub message: Option<String>,
    /// The field the problem is in, if any.
    pub field: Option<String>,
    /// What is wrong.
    pub kind: ErrorKind,
}

/// What is wrong with an input.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum ErrorKind {
    /// The file could not be read.
    Io(String),
    /// The output file could not be written (the diagnostic's file is the output path).
    Write(String),
    /// The input is larger than the generator reads (see [`crate::limits`]).
    InputTooLarge {
        /// Size of the input, in bytes.
        size: u64,
        /// Largest input accepted, in bytes.
        max: u64,
    },
    /// The document has more XML nodes than the generator builds (see [`crate::limits`]).
    TooManyNodes {
        /// Largest number of nodes accepted.
        max: u32,
    },
    /// An element has more attributes than accepted (see [`crate::limits`]).
    TooManyAttributes {
        /// Largest number of attributes of an element.
        max: usize,
    },
    /// An entity of the document type definition refers to another entity: nested
    /// entities are refused (they are how a small file expands exponentially).
    NestedEntity {
        /// The entity declared.
        name: String,
        /// The entity its value refers to.
        referenced: String,
    },
    /// The document type definition declares more entities than accepted (see
    /// [`crate::limits`]).
    TooManyEntities {
        /// Largest number of entity declarations accepted.
        max: usize,
    },
    /// The document refers to entities more often than accepted (see [`crate::limits`]).
    TooManyEntityReferences {
        /// Largest number of entity references accepted.
        max: usize,
    },
    /// The entity references of the document expand to more text than accepted (see
    /// [`crate::limits`]).
    EntityExpansionTooLarge {
        /// Largest total size of the expanded entities, in bytes.
        max: usize,
    },
    /// The file is not well-formed XML.
    Xml(String),
    /// The root element or a child element is not what the format allows.
    UnexpectedElement {
        /// Element found.
        found: String,
        /// Element(s) allowed there.
        expected: &'static str,
    },
    /// A required attribute is absent.
    MissingAttribute {
        /// Element the attribute belongs to.
        element: &'static str,
        /// Attribute name.
        attribute: &'static str,
    },
    /// An attribute that must be a number is not one in range.
    InvalidNumber {
        /// Attribute name.
        attribute: &'static str,
        /// Value found.
        value: String,
        /// Range allowed.
        expected: &'static str,
    },
    /// The `priority` attribute is not an integer in 0..=255.
    PriorityOutOfRange(String),
    /// A name is not usable as an identifier (`[A-Za-z_][A-Za-z0-9_]*`).
    InvalidName(String),
    /// Two classes, two messages of one class, or two fields of one message share an id
    /// or a name (after conversion to a Rust identifier where that applies).
    Duplicate {
        /// What is duplicated: `class id`, `message name`, `field name`...
        what: &'static str,
        /// The duplicated value.
        value: String,
        /// Line of the first occurrence.
        first_line: u32,
    },
    /// A field type that is not one of the Paparazzi types.
    UnknownType(String),
    /// A field type with a malformed array suffix (`uint8[`, `float[0]`, `int16[x]`...).
    MalformedArray(String),
    /// The payload cannot fit a PPRZ v2 frame even with every variable array empty.
    PayloadTooLarge {
        /// Smallest payload of the message, in bytes.
        min_len: usize,
        /// Largest payload a PPRZ v2 frame carries.
        max: usize,
    },
    /// A `values` list has more labels than the field's type can index.
    TooManyValues {
        /// Number of labels.
        count: usize,
        /// The field's type.
        ty: String,
    },
    /// A name that is a valid identifier, but whose Rust form cannot be used in the
    /// generated code (a keyword such as `Self`, no letter or digit left, a leading
    /// digit, or the name of an item the generator emits next to it).
    UnusableName {
        /// What is named: `class`, `message`, `field`, `process`.
        what: &'static str,
        /// The name as written.
        name: String,
        /// Why it cannot be used.
        reason: String,
    },
    /// A class id that does not fit the 4 bits a PPRZ v2 frame has for it.
    ClassIdOutOfRange {
        /// The id found.
        id: u8,
        /// Largest class id a PPRZ v2 frame carries.
        max: u8,
    },
    /// An element appears more than once where only one is allowed.
    DuplicateElement {
        /// The element (`description`).
        element: &'static str,
        /// Line of the first occurrence.
        first_line: u32,
    },
    /// A class or message named in the selection does not exist.
    UnknownSelection(String),
    /// Something else in a telemetry configuration.
    Telemetry(String),
    /// An input the generation needs was not given (what is missing, and how to give
    /// it).
    NoInput(&'static str),
    /// A problem of a settings file (`settings.xml`), or what was accepted from one with
    /// a warning (see [`crate::settings`]).
    Setting {
        /// The variable of the setting it is about, if it is about one.
        var: Option<String>,
        /// What it is.
        problem: SettingProblem,
    },
}

/// What is wrong with a Paparazzi settings file (`settings.xml`), or what was accepted
/// from one with a warning (see [`crate::settings`] for which is which).
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub enum SettingProblem {
    /// An attribute is given twice, in two spellings (names are matched without regard
    /// to case).
    DuplicateAttribute {
        /// The attribute (lower case).
        attribute: &'static str,
        /// Its first spelling.
        first: String,
        /// Its second spelling.
        second: String,
    },
    /// `min` is above `max`.
    MinAboveMax {
        /// `min` as written.
        min: String,
        /// `max` as written.
        max: String,
    },
    /// A bound or step, converted to the aircraft's units, is not a finite `f32` (or a
    /// step rounds to 0).
    ConvertedOutOfRange {
        /// The attribute.
        attribute: &'static str,
        /// Its value as written.
        value: String,
        /// The display coefficient it was divided by.
        coef: String,
    },
    /// More settings than an index byte numbers.
    TooManySettings {
        /// Largest number of settings.
        max: usize,
    },
    /// Groups (`<dl_settings>`) nested deeper than accepted.
    TooDeep {
        /// Largest nesting of groups.
        max: usize,
    },
    /// Two different variables make the same Rust name.
    NameClash {
        /// The Rust name.
        rust: String,
        /// The other variable.
        other: String,
        /// Where the other variable is (`file:line:column`).
        other_at: String,
    },
    /// Two different persistent variables have the same storage key (FNV-1a of the
    /// variable).
    KeyCollision {
        /// The key.
        key: u32,
        /// The other variable.
        other: String,
        /// Where the other variable is (`file:line:column`).
        other_at: String,
    },
    /// A persistent setting whose `type` is not one a setting is stored as.
    PersistentType {
        /// The type as written.
        ty: String,
    },
    /// Warning: no space between an attribute and the one before it; accepted.
    MissingSpace {
        /// The attribute after the missing space.
        attribute: String,
    },
    /// Warning: an attribute the generator does not know; ignored.
    UnknownAttribute {
        /// The element.
        element: &'static str,
        /// The attribute as written.
        attribute: String,
    },
    /// Warning: an element that is not read.
    IgnoredElement {
        /// The element.
        element: String,
        /// Where it is, and why it is not read.
        reason: &'static str,
    },
    /// Warning: a group holds both settings and groups.
    MixedGroup,
    /// Warning: a second `<dl_settings>` under `<settings>`.
    SecondTopLevelGroup,
    /// Warning: the number of `values` labels is not `max - min + 1`.
    LabelCount {
        /// Number of labels.
        labels: usize,
        /// `max - min + 1`.
        values: String,
    },
    /// Warning: `persistent` with a value that reads as false; the setting is persistent.
    PersistentFalse {
        /// The value as written.
        value: String,
    },
    /// Warning: a `type` read as another one.
    TypeMapped {
        /// The type as written.
        ty: String,
        /// The type it is read as.
        mapped: &'static str,
    },
    /// More problems (or warnings) than are reported for one file: how many more.
    Untold {
        /// How many were not reported.
        count: usize,
        /// `errors` or `warnings`.
        what: &'static str,
    },
    /// Warning: `alt_unit` without `alt_unit_coef`, and no known conversion from `unit`;
    /// the coefficient is 1.
    UnknownConversion {
        /// `unit`, if given.
        unit: Option<String>,
        /// `alt_unit`.
        alt_unit: String,
    },
}

impl fmt::Display for SettingProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write(&mut Escaping(f))
    }
}

impl SettingProblem {
    /// The text, unescaped (`Display::fmt` escapes it).
    fn write(&self, f: &mut dyn fmt::Write) -> fmt::Result {
        match self {
            Self::DuplicateAttribute {
                attribute,
                first,
                second,
            } => write!(
                f,
                "attribute `{attribute}` is given twice, as `{first}` and `{second}` (names are matched without regard to case)"
            ),
            Self::MinAboveMax { min, max } => write!(f, "min {min} is above max {max}"),
            Self::ConvertedOutOfRange {
                attribute,
                value,
                coef,
            } => write!(
                f,
                "`{attribute}` = {value} divided by the display coefficient {coef} does not fit an f32"
            ),
            Self::TooManySettings { max } => {
                write!(f, "more than {max} settings: a setting's index is one byte")
            }
            Self::TooDeep { max } => {
                write!(f, "<dl_settings> nested more than {max} deep: refused")
            }
            Self::NameClash {
                rust,
                other,
                other_at,
            } => write!(
                f,
                "makes the Rust name `{rust}`, as `{other}` does ({other_at})"
            ),
            Self::KeyCollision {
                key,
                other,
                other_at,
            } => write!(
                f,
                "storage key {key:#010x} (FNV-1a of the variable) is also that of the persistent `{other}` ({other_at}): rename one"
            ),
            Self::Untold { count, what } => {
                write!(f, "{count} more {what} in this file are not shown")
            }
            Self::PersistentType { ty } => write!(
                f,
                "type `{ty}` cannot be stored: a persistent setting is bool, int8, int16, int32, uint8, uint16, uint32 or float"
            ),
            _ => self.write_warning(f),
        }
    }

    /// The text of the kinds that are warnings; the others are written by
    /// [`write`](Self::write).
    fn write_warning(&self, f: &mut dyn fmt::Write) -> fmt::Result {
        match self {
            Self::MissingSpace { attribute } => write!(
                f,
                "no space before attribute `{attribute}`: accepted, as Paparazzi accepts it"
            ),
            Self::UnknownAttribute { element, attribute } => {
                write!(f, "<{element}> attribute `{attribute}` is not known: ignored")
            }
            Self::IgnoredElement { element, reason } => {
                write!(f, "<{element}> {reason}: ignored")
            }
            Self::MixedGroup => f.write_str(
                "this group holds both <dl_setting> and <dl_settings>: Paparazzi's generator refuses that; numbered here in document order",
            ),
            Self::SecondTopLevelGroup => f.write_str(
                "a second <dl_settings> under <settings>: Paparazzi reads only the first; read here too, in document order",
            ),
            Self::LabelCount { labels, values } => write!(
                f,
                "{labels} `values` labels for {values} values (max - min + 1): the labels name min, min + 1, ... in order"
            ),
            Self::PersistentFalse { value } => write!(
                f,
                "persistent=\"{value}\" makes the setting persistent, as in Paparazzi (any value does): remove the attribute for a setting that is not stored"
            ),
            Self::TypeMapped { ty, mapped } => write!(
                f,
                "type `{ty}` is not a setting type here: read as `{mapped}`"
            ),
            Self::UnknownConversion { unit, alt_unit } => match unit {
                Some(unit) => write!(
                    f,
                    "alt_unit `{alt_unit}` without alt_unit_coef, and no known conversion from `{unit}`: coefficient 1 (bounds taken as written)"
                ),
                None => write!(
                    f,
                    "alt_unit `{alt_unit}` without alt_unit_coef nor unit: coefficient 1 (bounds taken as written)"
                ),
            },
            _ => Ok(()),
        }
    }
}

impl fmt::Display for ErrorKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.write(&mut Escaping(f))
    }
}

impl ErrorKind {
    /// The text, unescaped (`Display::fmt` escapes it).
    fn write(&self, f: &mut dyn fmt::Write) -> fmt::Result {
        match self {
            Self::Io(e) => write!(f, "cannot read file: {e}"),
            Self::Write(e) => write!(f, "cannot write output file: {e}"),
            Self::InputTooLarge { .. }
            | Self::TooManyNodes { .. }
            | Self::TooManyAttributes { .. }
            | Self::NestedEntity { .. }
            | Self::TooManyEntities { .. }
            | Self::TooManyEntityReferences { .. }
            | Self::EntityExpansionTooLarge { .. } => self.write_limit(f),
            Self::Xml(e) => write!(f, "malformed XML: {e}"),
            Self::UnexpectedElement { found, expected } => {
                write!(f, "unexpected element <{found}>, expected {expected}")
            }
            Self::MissingAttribute { element, attribute } => {
                write!(
                    f,
                    "<{element}> is missing the required attribute `{attribute}`"
                )
            }
            Self::InvalidNumber {
                attribute,
                value,
                expected,
            } => write!(f, "attribute `{attribute}` = `{value}` is not {expected}"),
            Self::PriorityOutOfRange(v) => {
                write!(
                    f,
                    "priority `{v}` is out of range: expected an integer 0..=255"
                )
            }
            Self::InvalidName(n) => write!(
                f,
                "name `{n}` is not a valid identifier (letters, digits and `_`, not starting with a digit)"
            ),
            Self::Duplicate {
                what,
                value,
                first_line,
            } => write!(
                f,
                "duplicate {what} `{value}` (first defined on line {first_line})"
            ),
            Self::UnknownType(t) => write!(
                f,
                "unknown type `{t}`: expected one of int8 uint8 int16 uint16 int32 uint32 int64 uint64 float double char string, optionally as T[N] or T[]"
            ),
            Self::MalformedArray(t) => write!(
                f,
                "malformed array type `{t}`: expected T[N] with N in 1..=255, or T[]"
            ),
            Self::PayloadTooLarge { min_len, max } => write!(
                f,
                "payload of at least {min_len} bytes cannot fit a PPRZ v2 frame ({max} bytes of fields at most)"
            ),
            Self::TooManyValues { count, ty } => {
                write!(f, "{count} `values` labels cannot all be indexed by a {ty}")
            }
            Self::UnusableName { what, name, reason } => {
                write!(f, "{what} name `{name}` cannot be used: {reason}")
            }
            Self::ClassIdOutOfRange { id, max } => write!(
                f,
                "class id {id} does not fit a PPRZ v2 frame: class ids are 4 bits (0..={max})"
            ),
            Self::DuplicateElement {
                element,
                first_line,
            } => write!(
                f,
                "duplicate <{element}> (first defined on line {first_line}): only one is allowed"
            ),
            Self::UnknownSelection(n) => write!(f, "selected `{n}` does not exist in the input"),
            Self::Telemetry(e) => f.write_str(e),
            Self::NoInput(what) => f.write_str(what),
            Self::Setting { var, problem } => {
                if let Some(var) = var {
                    write!(f, "setting `{var}`: ")?;
                }
                problem.write(f)
            }
        }
    }

    /// The text of a kind that reports an input beyond one of the [`crate::limits`];
    /// the other kinds are written by [`write`](Self::write).
    fn write_limit(&self, f: &mut dyn fmt::Write) -> fmt::Result {
        match self {
            Self::InputTooLarge { size, max } => write!(
                f,
                "input of {size} bytes is too large: at most {max} bytes are read"
            ),
            Self::TooManyNodes { max } => write!(
                f,
                "too many XML nodes: at most {max} elements, text runs and comments are read"
            ),
            Self::TooManyAttributes { max } => {
                write!(
                    f,
                    "too many attributes: at most {max} per element are accepted"
                )
            }
            Self::NestedEntity { name, referenced } => write!(
                f,
                "entity `{name}` refers to entity `{referenced}`: nested entities are refused"
            ),
            Self::TooManyEntities { max } => {
                write!(
                    f,
                    "too many entity declarations: at most {max} are accepted"
                )
            }
            Self::TooManyEntityReferences { max } => {
                write!(f, "too many entity references: at most {max} are accepted")
            }
            Self::EntityExpansionTooLarge { max } => write!(
                f,
                "entity references expand to more than {max} bytes: refused"
            ),
            _ => Ok(()),
        }
    }
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let f = &mut Escaping(f);
        f.write_str(&self.file)?;
        if self.line > 0 {
            write!(f, ":{}", self.line)?;
            if self.column > 0 {
                write!(f, ":{}", self.column)?;
            }
        }
        f.write_str(": ")?;
        if let Some(m) = &self.message {
            write!(f, "message {m}")?;
            if let Some(field) = &self.field {
                write!(f, ", field {field}")?;
            }
            f.write_str(": ")?;
        }
        self.kind.write(f)
    }
}

/// One or more problems found in the inputs. All problems are collected before
/// reporting, so one run shows every mistake of a file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Error {
    diagnostics: Vec<Diagnostic>,
}

impl Error {
    pub(crate) fn new(diagnostics: Vec<Diagnostic>) -> Self {
        Self { diagnostics }
    }

    pub(crate) fn single(file: &str, kind: ErrorKind) -> Self {
        Self::new(vec![Diagnostic {
            file: file.to_owned(),
            line: 0,
            column: 0,
            message: None,
            field: None,
            kind,
        }])
    }

    /// Every problem found, in file order.
    pub fn diagnostics(&self) -> &[Diagnostic] {
        &self.diagnostics
    }
}

impl fmt::Display for Error {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.diagnostics.iter().enumerate() {
            if i > 0 {
                f.write_str("\n")?;
            }
            write!(f, "error: {d}")?;
        }
        Ok(())
    }
}

impl std::error::Error for Error {}
