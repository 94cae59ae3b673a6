//! The snapshot record: every persistent setting's value, in one record stored under one
//! key, so a power cut leaves either the whole previous snapshot or the whole new one.
//!
//! Layout (little-endian):
//!
//! | bytes | field |
//! |---|---|
//! | 2 | magic, `"PS"` |
//! | 1 | version, [`VERSION`] |
//! | 1 | entry count *n* |
//! | 9 *n* | entries: `u32` key ([`SettingDesc::key`], FNV-1a of the variable), `u8` type tag ([`type_tag`]), `f32` value |
//!
//! Decoding is strict: the length must be exactly `4 + 9 n`, every type tag known and every
//! key distinct. Anything else is a [`RecordError`], never a panic.
//!
//! ```
//! use pprz_messages::settings::SettingType;
//! use pprz_settings::record::{Entry, Record, RecordWriter};
//!
//! let mut buf = [0u8; 32];
//! let mut w = RecordWriter::new(&mut buf).unwrap();
//! w.push(Entry { key: 7, ty: SettingType::Float, value: 2.5 }).unwrap();
//! let len = w.finish();
//! assert_eq!(len, 4 + 9);
//!
//! let record = Record::decode(&buf[..len]).unwrap();
//! assert_eq!(record.len(), 1);
//! assert_eq!(record.find(7).map(|e| e.value), Some(2.5));
//! ```
//!
//! [`SettingDesc::key`]: pprz_messages::settings::SettingDesc::key

use core::fmt;

use pprz_messages::settings::SettingType;
use sequential_storage::map::{SerializationError, Value};

/// The record's first two bytes, `"PS"`.
pub const MAGIC: [u8; 2] = *b"PS";
/// The record format's version.
pub const VERSION: u8 = 1;
/// Bytes before the entries: magic, version, count.
pub const HEADER_LEN: usize = 4;
/// Bytes of one entry: key, type tag, value.
pub const ENTRY_LEN: usize = 9;
/// Most entries one record holds (its count is one byte).
pub const MAX_ENTRIES: usize = u8::MAX as usize;

/// Bytes of a record of `entries` entries.
pub const fn record_len(entries: usize) -> usize {
    HEADER_LEN + ENTRY_LEN * entries
}

/// The stored tag of a setting type.
pub const fn type_tag(ty: SettingType) -> u8 {
    match ty {
        SettingType::Bool => 0,
        SettingType::I8 => 1,
        SettingType::I16 => 2,
        SettingType::I32 => 3,
        SettingType::U8 => 4,
        SettingType::U16 => 5,
        SettingType::U32 => 6,
        SettingType::Float => 7,
    }
}

/// The setting type a stored tag names, if any.
pub const fn type_from_tag(tag: u8) -> Option<SettingType> {
    Some(match tag {
        0 => SettingType::Bool,
        1 => SettingType::I8,
        2 => SettingType::I16,
        3 => SettingType::I32,
        4 => SettingType::U8,
        5 => SettingType::U16,
        6 => SettingType::U32,
        7 => SettingType::Float,
        _ => return None,
    })
}

/// One stored setting.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct Entry {
    /// The setting's key: FNV-1a of its variable's name.
    pub key: u32,
    /// The setting's type when it was stored.
    pub ty: SettingType,
    /// The value it read back (what DL_VALUE showed).
    pub value: f32,
}

impl Entry {
    fn encode(&self) -> [u8; ENTRY_LEN] {
        let mut out = [0; ENTRY_LEN];
        out[..4].copy_from_slice(&self.key.to_le_bytes());
        out[4] = type_tag(self.ty);
        out[5..].copy_from_slice(&self.value.to_le_bytes());
        out
    }

    /// Decodes one entry (`bytes` holds [`ENTRY_LEN`] bytes; checked by the caller).
    fn decode(bytes: &[u8]) -> Result<Self, u8> {
        let [k0, k1, k2, k3, tag, v0, v1, v2, v3] = *bytes else {
            // Callers pass exact chunks; an odd chunk reads as an unknown tag.
            return Err(u8::MAX);
        };
        Ok(Entry {
            key: u32::from_le_bytes([k0, k1, k2, k3]),
            ty: type_from_tag(tag).ok_or(tag)?,
            value: f32::from_le_bytes([v0, v1, v2, v3]),
        })
    }
}

/// Why stored bytes are not a record.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum RecordError {
    /// Fewer bytes than a header.
    TooShort {
        /// Bytes found.
        len: usize,
    },
    /// The first two bytes are not [`MAGIC`].
    BadMagic {
        /// The bytes found.
        found: [u8; 2],
    },
    /// A version this firmware does not read.
    UnsupportedVersion {
        /// The version found.
        version: u8,
    },
    /// The length does not match the entry count.
    LengthMismatch {
        /// The entry count of the header.
        count: u8,
        /// The length that count needs.
        expected: usize,
        /// The length found.
        len: usize,
    },
    /// An entry with a type tag this firmware does not know.
    UnknownType {
        /// The entry's position.
        entry: u8,
        /// Its tag.
        tag: u8,
    },
    /// Two entries with the same key.
    DuplicateKey {
        /// The key.
        key: u32,
    },
}

impl fmt::Display for RecordError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RecordError::TooShort { len } => {
                write!(f, "settings record too short ({len} bytes)")
            }
            RecordError::BadMagic { found } => {
                write!(f, "not a settings record (magic {found:02x?})")
            }
            RecordError::UnsupportedVersion { version } => {
                write!(f, "settings record version {version} is not {VERSION}")
            }
            RecordError::LengthMismatch {
                count,
                expected,
                len,
            } => write!(
                f,
                "settings record of {count} entries must be {expected} bytes, not {len}"
            ),
            RecordError::UnknownType { entry, tag } => {
                write!(f, "settings record entry {entry}: unknown type tag {tag}")
            }
            RecordError::DuplicateKey { key } => {
                write!(f, "settings record: key {key:#010x} stored twice")
            }
        }
    }
}

impl core::error::Error for RecordError {}

/// A record that decoded: a view of its bytes.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Record<'a> {
    bytes: &'a [u8],
}

impl<'a> Record<'a> {
    /// Checks `bytes` (a whole record, nothing after it) and views them.
    ///
    /// # Errors
    /// [`RecordError`]: short, wrong magic or version, a length that does not match the
    /// count, an unknown type tag or a key stored twice.
    pub fn decode(bytes: &'a [u8]) -> Result<Self, RecordError> {
        let [m0, m1, version, count, ..] = *bytes else {
            return Err(RecordError::TooShort { len: bytes.len() });
        };
        if [m0, m1] != MAGIC {
            return Err(RecordError::BadMagic { found: [m0, m1] });
        }
        if version != VERSION {
            return Err(RecordError::UnsupportedVersion { version });
        }
        let expected = record_len(usize::from(count));
        if bytes.len() != expected {
            return Err(RecordError::LengthMismatch {
                count,
                expected,
                len: bytes.len(),
            });
        }
        let record = Record { bytes };
        for (i, chunk) in record.chunks().enumerate() {
            let entry = Entry::decode(chunk).map_err(|tag| RecordError::UnknownType {
                // At most 255 chunks: the count is one byte.
                entry: u8::try_from(i).unwrap_or(u8::MAX),
                tag,
            })?;
            if record.chunks().take(i).any(|c| c[..4] == chunk[..4]) {
                return Err(RecordError::DuplicateKey { key: entry.key });
            }
        }
        Ok(record)
    }

    fn chunks(&self) -> core::slice::ChunksExact<'a, u8> {
        self.bytes
            .get(HEADER_LEN..)
            .unwrap_or_default()
            .chunks_exact(ENTRY_LEN)
    }

    /// Number of entries.
    pub fn len(&self) -> usize {
        self.chunks().len()
    }

    /// Whether the record has no entries.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The entries, in stored order.
    pub fn entries(&self) -> impl Iterator<Item = Entry> + 'a {
        // Every chunk decoded when the record was checked.
        self.chunks().filter_map(|c| Entry::decode(c).ok())
    }

    /// The entry stored under `key`, if any.
    pub fn find(&self, key: u32) -> Option<Entry> {
        self.position(key, 0).map(|(_, e)| e)
    }

    /// The entry at position `i` (stored order).
    pub fn entry(&self, i: usize) -> Option<Entry> {
        let start = HEADER_LEN + i.checked_mul(ENTRY_LEN)?;
        let chunk = self.bytes.get(start..start.checked_add(ENTRY_LEN)?)?;
        Entry::decode(chunk).ok()
    }

    /// The position and entry stored under `key`, looking at position `hint` first (a
    /// record saved by the same table has its entries in the table's order, so a reader
    /// walking the table finds each entry at once).
    pub fn position(&self, key: u32, hint: usize) -> Option<(usize, Entry)> {
        if let Some(e) = self.entry(hint)
            && e.key == key
        {
            return Some((hint, e));
        }
        self.entries().enumerate().find(|(_, e)| e.key == key)
    }

    /// The record's bytes.
    pub fn as_bytes(&self) -> &'a [u8] {
        self.bytes
    }
}

/// The record as a sequential-storage map value: stored as its bytes, read back through
/// [`Record::decode`] (a record that does not decode is
/// [`SerializationError::InvalidFormat`]).
impl<'a> Value<'a> for Record<'a> {
    fn serialize_into(&self, buffer: &mut [u8]) -> Result<usize, SerializationError> {
        let out = buffer
            .get_mut(..self.bytes.len())
            .ok_or(SerializationError::BufferTooSmall)?;
        out.copy_from_slice(self.bytes);
        Ok(self.bytes.len())
    }

    fn deserialize_from(buffer: &'a [u8]) -> Result<(Self, usize), SerializationError> {
        let record = Record::decode(buffer).map_err(|_| SerializationError::InvalidFormat)?;
        Ok((record, buffer.len()))
    }
}

/// Why an entry was not written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum EncodeError {
    /// The buffer holds no more entries (or the record has [`MAX_ENTRIES`]).
    Full {
        /// Entries the buffer holds.
        capacity: usize,
    },
    /// An entry with this key is in the record already.
    DuplicateKey {
        /// The key.
        key: u32,
    },
}

impl fmt::Display for EncodeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EncodeError::Full { capacity } => {
                write!(f, "settings record full ({capacity} entries)")
            }
            EncodeError::DuplicateKey { key } => {
                write!(f, "settings record: key {key:#010x} written twice")
            }
        }
    }
}

impl core::error::Error for EncodeError {}

/// Writes a record into a buffer, entry by entry.
#[derive(Debug)]
pub struct RecordWriter<'b> {
    buf: &'b mut [u8],
    count: u8,
}

impl<'b> RecordWriter<'b> {
    /// Starts an empty record in `buf`.
    ///
    /// # Errors
    /// [`EncodeError::Full`] if `buf` is shorter than a header.
    pub fn new(buf: &'b mut [u8]) -> Result<Self, EncodeError> {
        let header = buf
            .get_mut(..HEADER_LEN)
            .ok_or(EncodeError::Full { capacity: 0 })?;
        header.copy_from_slice(&[MAGIC[0], MAGIC[1], VERSION, 0]);
        Ok(Self { buf, count: 0 })
    }

    /// Entries this writer's buffer holds.
    pub fn capacity(&self) -> usize {
        (self.buf.len().saturating_sub(HEADER_LEN) / ENTRY_LEN).min(MAX_ENTRIES)
    }

    /// Entries written so far.
    pub fn len(&self) -> usize {
        usize::from(self.count)
    }

    /// Whether no entry was written.
    pub fn is_empty(&self) -> bool {
        self.count == 0
    }

    /// Appends `entry`.
    ///
    /// # Errors
    /// [`EncodeError::Full`], or [`EncodeError::DuplicateKey`] if an entry with the same key
    /// was written (the record is unchanged).
    pub fn push(&mut self, entry: Entry) -> Result<(), EncodeError> {
        let written = self
            .buf
            .get(HEADER_LEN..record_len(self.len()))
            .unwrap_or_default();
        let key = entry.key.to_le_bytes();
        if written.chunks_exact(ENTRY_LEN).any(|c| c[..4] == key) {
            return Err(EncodeError::DuplicateKey { key: entry.key });
        }
        let full = EncodeError::Full {
            capacity: self.capacity(),
        };
        if self.len() >= self.capacity() {
            return Err(full);
        }
        let at = record_len(self.len());
        let slot = self.buf.get_mut(at..at + ENTRY_LEN).ok_or(full)?;
        slot.copy_from_slice(&entry.encode());
        self.count += 1;
        self.buf[3] = self.count;
        Ok(())
    }

    /// The record's length (its bytes are `buf[..len]`).
    pub fn finish(self) -> usize {
        record_len(self.len())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn entry(key: u32, value: f32) -> Entry {
        Entry {
            key,
            ty: SettingType::Float,
            value,
        }
    }

    fn encode(entries: &[Entry], buf: &mut [u8]) -> usize {
        let mut w = RecordWriter::new(buf).unwrap();
        for e in entries {
            w.push(*e).unwrap();
        }
        w.finish()
    }

    #[test]
    fn round_trip_keeps_keys_types_and_bits() {
        let entries = [
            entry(1, 2.5),
            Entry {
                key: 0xdead_beef,
                ty: SettingType::U8,
                value: 3.0,
            },
            entry(3, f32::NAN),
            entry(4, -0.0),
        ];
        let mut buf = [0u8; 64];
        let len = encode(&entries, &mut buf);
        assert_eq!(len, record_len(4));
        let record = Record::decode(&buf[..len]).unwrap();
        assert_eq!(record.len(), 4);
        for (a, b) in record.entries().zip(entries) {
            assert_eq!((a.key, a.ty), (b.key, b.ty));
            assert_eq!(a.value.to_bits(), b.value.to_bits());
        }
        assert_eq!(
            record.find(0xdead_beef).map(|e| e.ty),
            Some(SettingType::U8)
        );
        assert_eq!(record.find(99), None);
    }

    #[test]
    fn every_type_has_a_distinct_tag() {
        let all = [
            SettingType::Bool,
            SettingType::I8,
            SettingType::I16,
            SettingType::I32,
            SettingType::U8,
            SettingType::U16,
            SettingType::U32,
            SettingType::Float,
        ];
        for ty in all {
            assert_eq!(type_from_tag(type_tag(ty)), Some(ty));
        }
        for tag in 8..=u8::MAX {
            assert_eq!(type_from_tag(tag), None);
        }
    }

    #[test]
    fn decode_is_strict() {
        let mut buf = [0u8; 64];
        let len = encode(&[entry(1, 1.0), entry(2, 2.0)], &mut buf);
        let good = &buf[..len];
        assert_eq!(
            Record::decode(&good[..3]),
            Err(RecordError::TooShort { len: 3 })
        );
        assert!(matches!(
            Record::decode(&good[..len - 1]),
            Err(RecordError::LengthMismatch {
                count: 2,
                expected: 22,
                len: 21
            })
        ));
        let mut longer = [0u8; 23];
        longer[..len].copy_from_slice(good);
        assert!(matches!(
            Record::decode(&longer),
            Err(RecordError::LengthMismatch { len: 23, .. })
        ));
        let mut bad = [0u8; 22];
        bad.copy_from_slice(good);
        bad[0] = b'X';
        assert!(matches!(
            Record::decode(&bad),
            Err(RecordError::BadMagic { .. })
        ));
        bad.copy_from_slice(good);
        bad[2] = 2;
        assert_eq!(
            Record::decode(&bad),
            Err(RecordError::UnsupportedVersion { version: 2 })
        );
        bad.copy_from_slice(good);
        bad[HEADER_LEN + ENTRY_LEN + 4] = 8;
        assert_eq!(
            Record::decode(&bad),
            Err(RecordError::UnknownType { entry: 1, tag: 8 })
        );
        bad.copy_from_slice(good);
        bad[HEADER_LEN + ENTRY_LEN] = 1; // second key = first key
        assert_eq!(
            Record::decode(&bad),
            Err(RecordError::DuplicateKey { key: 1 })
        );
    }

    #[test]
    fn empty_record_is_valid() {
        let mut buf = [0u8; 4];
        let len = encode(&[], &mut buf);
        let record = Record::decode(&buf[..len]).unwrap();
        assert!(record.is_empty());
        assert_eq!(record.entries().count(), 0);
    }

    #[test]
    fn writer_refuses_duplicates_and_overflow() {
        let mut buf = [0u8; record_len(2) + 8];
        let mut w = RecordWriter::new(&mut buf).unwrap();
        assert_eq!(w.capacity(), 2);
        w.push(entry(1, 1.0)).unwrap();
        assert_eq!(
            w.push(entry(1, 5.0)),
            Err(EncodeError::DuplicateKey { key: 1 })
        );
        w.push(entry(2, 2.0)).unwrap();
        assert_eq!(
            w.push(entry(3, 3.0)),
            Err(EncodeError::Full { capacity: 2 })
        );
        assert_eq!(w.finish(), record_len(2));
        assert!(RecordWriter::new(&mut [0u8; 3]).is_err());
    }

    #[test]
    fn writer_stops_at_255_entries() {
        let mut buf = [0u8; record_len(300)];
        let mut w = RecordWriter::new(&mut buf).unwrap();
        assert_eq!(w.capacity(), MAX_ENTRIES);
        for key in 0..255 {
            w.push(entry(key, 0.0)).unwrap();
        }
        assert!(matches!(
            w.push(entry(999, 0.0)),
            Err(EncodeError::Full { .. })
        ));
        let len = w.finish();
        assert_eq!(Record::decode(&buf[..len]).unwrap().len(), 255);
    }

    #[test]
    fn value_impl_round_trips_and_rejects_garbage() {
        let mut buf = [0u8; 32];
        let len = encode(&[entry(5, 1.5)], &mut buf);
        let record = Record::decode(&buf[..len]).unwrap();
        let mut out = [0u8; 32];
        let n = record.serialize_into(&mut out).unwrap();
        assert_eq!(&out[..n], record.as_bytes());
        assert_eq!(
            record.serialize_into(&mut [0u8; 4]),
            Err(SerializationError::BufferTooSmall)
        );
        let (back, used) = <Record as Value>::deserialize_from(&out[..n]).unwrap();
        assert_eq!((back, used), (record, n));
        assert!(<Record as Value>::deserialize_from(&out[..n - 1]).is_err());
    }

    #[test]
    fn decode_never_panics_on_any_short_input() {
        // Every byte pattern of lengths 0..=13 that a single byte flip of a valid record
        // gives, and a sweep of counts.
        let mut buf = [0u8; 13];
        let len = encode(&[entry(9, 9.0)], &mut buf);
        for i in 0..len {
            for bit in 0..8 {
                let mut b = buf;
                b[i] ^= 1 << bit;
                let _ = Record::decode(&b[..len]);
            }
        }
        for count in 0..=u8::MAX {
            let mut b = buf;
            b[3] = count;
            for l in 0..=len {
                let _ = Record::decode(&b[..l]);
            }
        }
    }
}
