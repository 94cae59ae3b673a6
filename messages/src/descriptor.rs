//! Static descriptions of messages: names, ids, field names, types and units.
//!
//! The code generator emits one [`MessageSet`] per generated set (`MESSAGES`), so host
//! tools can decode and print any message generically with [`crate::dynamic`]. A tool
//! that reads a `messages.xml` at run time can build the same descriptors itself: every
//! descriptor borrows its strings (`'a`), nothing here allocates.

use core::fmt;

/// Element type of a field, as named in `messages.xml`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BaseType {
    /// `uint8`
    U8,
    /// `int8`
    I8,
    /// `uint16`
    U16,
    /// `int16`
    I16,
    /// `uint32`
    U32,
    /// `int32`
    I32,
    /// `uint64`
    U64,
    /// `int64`
    I64,
    /// `float` (IEEE 754 binary32)
    F32,
    /// `double` (IEEE 754 binary64)
    F64,
    /// `char`: one byte of text (arrays of it are strings, not NUL-terminated).
    Char,
}

impl BaseType {
    /// Every base type, in the order of this enum.
    pub const ALL: [BaseType; 11] = [
        Self::U8,
        Self::I8,
        Self::U16,
        Self::I16,
        Self::U32,
        Self::I32,
        Self::U64,
        Self::I64,
        Self::F32,
        Self::F64,
        Self::Char,
    ];

    /// Size of one element on the wire, in bytes.
    pub const fn size(self) -> usize {
        match self {
            Self::U8 | Self::I8 | Self::Char => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::I32 | Self::F32 => 4,
            Self::U64 | Self::I64 | Self::F64 => 8,
        }
    }

    /// Name of the type in `messages.xml` (`uint8`, `float`, ...).
    pub const fn xml_name(self) -> &'static str {
        match self {
            Self::U8 => "uint8",
            Self::I8 => "int8",
            Self::U16 => "uint16",
            Self::I16 => "int16",
            Self::U32 => "uint32",
            Self::I32 => "int32",
            Self::U64 => "uint64",
            Self::I64 => "int64",
            Self::F32 => "float",
            Self::F64 => "double",
            Self::Char => "char",
        }
    }

    /// Name of the Rust type that holds one element (`u8`, `f32`, ...; `char` is `u8`).
    pub const fn rust_name(self) -> &'static str {
        match self {
            Self::U8 | Self::Char => "u8",
            Self::I8 => "i8",
            Self::U16 => "u16",
            Self::I16 => "i16",
            Self::U32 => "u32",
            Self::I32 => "i32",
            Self::U64 => "u64",
            Self::I64 => "i64",
            Self::F32 => "f32",
            Self::F64 => "f64",
        }
    }

    /// Looks a type up by its `messages.xml` name.
    pub fn from_xml_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|t| t.xml_name() == name)
    }

    /// Whether the type is an integer (and so can index a `values` list).
    pub const fn is_integer(self) -> bool {
        !matches!(self, Self::F32 | Self::F64 | Self::Char)
    }
}

impl fmt::Display for BaseType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.xml_name())
    }
}

/// Shape of a field on the wire.
///
/// `string` fields (ground class only, never on the radio) have the wire layout of
/// `char[]` and are described as `Vector(Char)`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum FieldType {
    /// One element.
    Scalar(BaseType),
    /// `T[N]`: exactly `N` elements, no length on the wire.
    Array(BaseType, usize),
    /// `T[]`: a `uint8` element count, then that many elements.
    Vector(BaseType),
}

impl FieldType {
    /// Element type.
    pub const fn base(self) -> BaseType {
        match self {
            Self::Scalar(b) | Self::Array(b, _) | Self::Vector(b) => b,
        }
    }

    /// Size on the wire when it does not depend on the content.
    pub const fn fixed_size(self) -> Option<usize> {
        match self {
            Self::Vector(_) => None,
            _ => Some(self.min_size()),
        }
    }

    /// Smallest size on the wire (an empty vector is its one count byte).
    pub const fn min_size(self) -> usize {
        match self {
            Self::Scalar(b) => b.size(),
            Self::Array(b, n) => b.size() * n,
            Self::Vector(_) => 1,
        }
    }

    /// Largest size on the wire (a vector may hold 255 elements).
    pub const fn max_size(self) -> usize {
        match self {
            Self::Vector(b) => 1 + 255 * b.size(),
            _ => self.min_size(),
        }
    }
}

impl fmt::Display for FieldType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match *self {
            Self::Scalar(b) => write!(f, "{b}"),
            Self::Array(b, n) => write!(f, "{b}[{n}]"),
            Self::Vector(b) => write!(f, "{b}[]"),
        }
    }
}

/// One field of a message.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct FieldDescriptor<'a> {
    /// Name as written in `messages.xml`.
    pub name: &'a str,
    /// Wire shape.
    pub ty: FieldType,
    /// Unit of the raw value (`unit` attribute), e.g. `cm`.
    pub unit: Option<&'a str>,
    /// Unit to display the value in (`alt_unit` attribute), e.g. `m`.
    pub alt_unit: Option<&'a str>,
    /// Factor from `unit` to `alt_unit`: the `alt_unit_coef` attribute, or the default
    /// coefficient from `units.xml` when the generator was given one.
    pub alt_unit_coef: Option<f64>,
    /// printf-style display format (`format` attribute).
    pub format: Option<&'a str>,
    /// Enumeration labels by index (`values` attribute, `A|B|C`); empty if none.
    pub values: &'a [&'a str],
}

impl<'a> FieldDescriptor<'a> {
    /// A field with a name and a type and no metadata.
    pub const fn new(name: &'a str, ty: FieldType) -> Self {
        Self {
            name,
            ty,
            unit: None,
            alt_unit: None,
            alt_unit_coef: None,
            format: None,
            values: &[],
        }
    }

    /// The `values` label for an enumeration index, if the field has one.
    pub fn label(&self, index: i64) -> Option<&'a str> {
        usize::try_from(index)
            .ok()
            .and_then(|i| self.values.get(i).copied())
    }

    /// Converts a raw value to `alt_unit` (identity when there is no coefficient).
    pub fn to_alt_unit(&self, raw: f64) -> f64 {
        match self.alt_unit_coef {
            Some(coef) => raw * coef,
            None => raw,
        }
    }
}

/// One message: where it lives (class, id), its name, priority and fields.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MessageDescriptor<'a> {
    /// Class id (`telemetry` = 1, `datalink` = 2, `ground` = 3, `alert` = 4, `intermcu` = 5).
    pub class_id: u8,
    /// Class name.
    pub class_name: &'a str,
    /// Message id within its class.
    pub id: u8,
    /// Message name (`GPS`).
    pub name: &'a str,
    /// Send priority, 0..=255, higher is more important (see [`crate::priority`]).
    pub priority: u8,
    /// Fields in wire order.
    pub fields: &'a [FieldDescriptor<'a>],
}

impl MessageDescriptor<'_> {
    /// Smallest payload (every vector empty).
    pub fn min_len(&self) -> usize {
        self.fields.iter().map(|f| f.ty.min_size()).sum()
    }

    /// Largest payload (every vector with 255 elements).
    pub fn max_len(&self) -> usize {
        self.fields.iter().map(|f| f.ty.max_size()).sum()
    }

    /// Looks a field up by name.
    pub fn field(&self, name: &str) -> Option<&FieldDescriptor<'_>> {
        self.fields.iter().find(|f| f.name == name)
    }
}

/// A table of message descriptors sorted by `(class_id, id)`.
#[derive(Debug, Clone, Copy)]
pub struct MessageSet<'a> {
    messages: &'a [MessageDescriptor<'a>],
}

impl<'a> MessageSet<'a> {
    /// Wraps a table. Lookups by id need it sorted by `(class_id, id)` without
    /// duplicates, as the code generator emits it; use [`MessageSet::is_sorted`] to check
    /// a table built by hand.
    pub const fn new(messages: &'a [MessageDescriptor<'a>]) -> Self {
        Self { messages }
    }

    /// Whether the table is strictly sorted by `(class_id, id)`.
    pub fn is_sorted(&self) -> bool {
        self.messages
            .windows(2)
            .all(|w| (w[0].class_id, w[0].id) < (w[1].class_id, w[1].id))
    }

    /// Every message, sorted by `(class_id, id)`.
    pub const fn messages(&self) -> &'a [MessageDescriptor<'a>] {
        self.messages
    }

    /// Number of messages.
    pub const fn len(&self) -> usize {
        self.messages.len()
    }

    /// Whether the set is empty.
    pub const fn is_empty(&self) -> bool {
        self.messages.is_empty()
    }

    /// Finds a message by class and id (binary search).
    ///
    /// # Time Complexity
    /// O(log n) in the number of messages.
    pub fn find(&self, class_id: u8, id: u8) -> Option<&'a MessageDescriptor<'a>> {
        self.messages
            .binary_search_by_key(&(class_id, id), |m| (m.class_id, m.id))
            .ok()
            .and_then(|i| self.messages.get(i))
    }

    /// Finds a message by class name and message name (linear search).
    pub fn find_by_name(&self, class_name: &str, name: &str) -> Option<&'a MessageDescriptor<'a>> {
        self.messages
            .iter()
            .find(|m| m.class_name == class_name && m.name == name)
    }
}
