//! Wire primitives: packed little-endian scalars, arrays, and the cursors that generated
//! encoders and decoders are written with.
//!
//! Layout of a payload (also in `docs/wire-formats.md`): fields follow each other in XML
//! order, no padding, little-endian. A fixed array `T[N]` is `N` elements; a variable
//! array `T[]` is one `uint8` element count followed by the elements.
//!
//! ```text
//! ALIVE (md5sum: uint8[]) with [0, 1, 2]:   03 | 00 01 02
//! DL_VALUE (index: uint8, value: float):    idx | f32 LE (4 bytes)
//! ```
//!
//! # No-panic contract
//! Every function here is total: out-of-range reads and writes return errors, never panic.

use core::fmt;
use core::iter::FusedIterator;

use crate::descriptor::BaseType;
use crate::error::{DecodeError, EncodeError};

mod sealed {
    pub trait Sealed {}
}

/// A primitive that can be a message field: `u8`..`u64`, `i8`..`i64`, `f32`, `f64`.
///
/// Sealed: the wire format knows no other scalar.
pub trait Scalar: Copy + Default + PartialEq + fmt::Debug + sealed::Sealed {
    /// Size on the wire, in bytes.
    const SIZE: usize;
    /// The `messages.xml` type this Rust type carries (`char` is carried as [`u8`] and
    /// described separately).
    const BASE: BaseType;
    /// Reads one value from the first [`Self::SIZE`] bytes, `None` if there are fewer.
    fn read_le(bytes: &[u8]) -> Option<Self>;
    /// Writes the value into the first [`Self::SIZE`] bytes; `false` (and nothing
    /// written) if there are fewer.
    fn write_le(self, out: &mut [u8]) -> bool;
}

macro_rules! impl_scalar {
    ($($t:ty => $n:literal, $base:ident;)*) => {$(
        impl sealed::Sealed for $t {}
        impl Scalar for $t {
            const SIZE: usize = $n;
            const BASE: BaseType = BaseType::$base;
            #[inline(always)]
            fn read_le(bytes: &[u8]) -> Option<Self> {
                bytes.first_chunk::<$n>().map(|b| <$t>::from_le_bytes(*b))
            }
            #[inline(always)]
            fn write_le(self, out: &mut [u8]) -> bool {
                match out.first_chunk_mut::<$n>() {
                    Some(dst) => {
                        *dst = self.to_le_bytes();
                        true
                    }
                    None => false,
                }
            }
        }
    )*};
}

impl_scalar! {
    u8 => 1, U8;
    i8 => 1, I8;
    u16 => 2, U16;
    i16 => 2, I16;
    u32 => 4, U32;
    i32 => 4, I32;
    u64 => 8, U64;
    i64 => 8, I64;
    f32 => 4, F32;
    f64 => 8, F64;
}

/// A variable-length array field (`T[]`) without allocation.
///
/// Built from a native slice when encoding ([`VarArray::new`], `From<&[T]>`), and as a
/// zero-copy view of the little-endian wire bytes when decoding (the payload may be
/// unaligned, so it cannot be reinterpreted as `&[T]`). Both read the same way:
/// [`len`](Self::len), [`get`](Self::get), [`iter`](Self::iter); equality compares
/// elements.
#[derive(Clone, Copy)]
pub struct VarArray<'a, T: Scalar> {
    repr: Repr<'a, T>,
}

#[derive(Clone, Copy)]
enum Repr<'a, T> {
    /// Elements in native representation.
    Native(&'a [T]),
    /// Invariant: `len() % T::SIZE == 0`, checked by [`VarArray::from_wire`].
    Wire(&'a [u8]),
}

impl<'a, T: Scalar> VarArray<'a, T> {
    /// An array over native elements, for encoding.
    pub const fn new(elements: &'a [T]) -> Self {
        Self {
            repr: Repr::Native(elements),
        }
    }

    /// The empty array.
    pub const fn empty() -> Self {
        Self::new(&[])
    }

    /// A view of little-endian wire bytes; `None` unless the length is a whole number of
    /// elements.
    pub fn from_wire(bytes: &'a [u8]) -> Option<Self> {
        bytes.len().is_multiple_of(T::SIZE).then_some(Self {
            repr: Repr::Wire(bytes),
        })
    }

    /// Number of elements.
    pub fn len(&self) -> usize {
        match self.repr {
            Repr::Native(s) => s.len(),
            Repr::Wire(b) => b.len() / T::SIZE,
        }
    }

    /// Whether there is no element.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Size of the elements on the wire (without the count byte).
    pub fn wire_len(&self) -> usize {
        self.len() * T::SIZE
    }

    /// Element `index`, `None` past the end.
    pub fn get(&self, index: usize) -> Option<T> {
        match self.repr {
            Repr::Native(s) => s.get(index).copied(),
            Repr::Wire(b) => {
                let start = index.checked_mul(T::SIZE)?;
                T::read_le(b.get(start..)?)
            }
        }
    }

    /// Iterates over the elements.
    pub fn iter(&self) -> VarArrayIter<'a, T> {
        VarArrayIter {
            array: *self,
            index: 0,
        }
    }

    /// Copies the elements into `out`, returning how many were copied (at most
    /// `out.len()`).
    pub fn copy_to(&self, out: &mut [T]) -> usize {
        let mut n = 0;
        for (dst, v) in out.iter_mut().zip(self.iter()) {
            *dst = v;
            n += 1;
        }
        n
    }
}

impl<'a> VarArray<'a, u8> {
    /// The elements as bytes (for `uint8[]` the wire and native forms are the same).
    pub fn as_bytes(&self) -> &'a [u8] {
        match self.repr {
            Repr::Native(s) | Repr::Wire(s) => s,
        }
    }
}

impl<T: Scalar> Default for VarArray<'_, T> {
    fn default() -> Self {
        Self::empty()
    }
}

impl<'a, T: Scalar> From<&'a [T]> for VarArray<'a, T> {
    fn from(elements: &'a [T]) -> Self {
        Self::new(elements)
    }
}

impl<'a, T: Scalar, const N: usize> From<&'a [T; N]> for VarArray<'a, T> {
    fn from(elements: &'a [T; N]) -> Self {
        Self::new(elements)
    }
}

impl<T: Scalar> PartialEq for VarArray<'_, T> {
    fn eq(&self, other: &Self) -> bool {
        self.len() == other.len() && self.iter().eq(other.iter())
    }
}

impl<T: Scalar> fmt::Debug for VarArray<'_, T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.iter()).finish()
    }
}

#[cfg(feature = "defmt")]
impl<T: Scalar + defmt::Format> defmt::Format for VarArray<'_, T> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "[");
        for (i, v) in self.iter().enumerate() {
            if i > 0 {
                defmt::write!(f, ", ");
            }
            defmt::write!(f, "{}", v);
        }
        defmt::write!(f, "]");
    }
}

impl<'a, T: Scalar> IntoIterator for VarArray<'a, T> {
    type Item = T;
    type IntoIter = VarArrayIter<'a, T>;
    fn into_iter(self) -> Self::IntoIter {
        self.iter()
    }
}

/// Iterator over the elements of a [`VarArray`].
#[derive(Clone)]
pub struct VarArrayIter<'a, T: Scalar> {
    array: VarArray<'a, T>,
    index: usize,
}

impl<T: Scalar> Iterator for VarArrayIter<'_, T> {
    type Item = T;
    fn next(&mut self) -> Option<T> {
        let v = self.array.get(self.index)?;
        self.index += 1;
        Some(v)
    }

    fn size_hint(&self) -> (usize, Option<usize>) {
        let n = self.array.len().saturating_sub(self.index);
        (n, Some(n))
    }
}

impl<T: Scalar> ExactSizeIterator for VarArrayIter<'_, T> {}
impl<T: Scalar> FusedIterator for VarArrayIter<'_, T> {}

/// A `char[]` (or `string`) field: bytes of text, not NUL-terminated, not necessarily
/// UTF-8 when they come from the wire.
#[derive(Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Chars<'a>(&'a [u8]);

impl<'a> Chars<'a> {
    /// Text from raw bytes.
    pub const fn new(bytes: &'a [u8]) -> Self {
        Self(bytes)
    }

    /// Text from a string slice.
    pub const fn from_str(text: &'a str) -> Self {
        Self(text.as_bytes())
    }

    /// The bytes.
    pub const fn as_bytes(&self) -> &'a [u8] {
        self.0
    }

    /// Number of bytes.
    pub const fn len(&self) -> usize {
        self.0.len()
    }

    /// Whether there is no byte.
    pub const fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// The text, if it is valid UTF-8.
    pub fn to_str(&self) -> Result<&'a str, core::str::Utf8Error> {
        core::str::from_utf8(self.0)
    }
}

impl<'a> From<&'a str> for Chars<'a> {
    fn from(text: &'a str) -> Self {
        Self::from_str(text)
    }
}

impl<'a> From<&'a [u8]> for Chars<'a> {
    fn from(bytes: &'a [u8]) -> Self {
        Self::new(bytes)
    }
}

/// Shows the text, invalid UTF-8 sequences replaced by U+FFFD.
impl fmt::Display for Chars<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for chunk in self.0.utf8_chunks() {
            f.write_str(chunk.valid())?;
            if !chunk.invalid().is_empty() {
                f.write_str("\u{FFFD}")?;
            }
        }
        Ok(())
    }
}

impl fmt::Debug for Chars<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "\"{}\"", self.0.escape_ascii())
    }
}

#[cfg(feature = "defmt")]
impl defmt::Format for Chars<'_> {
    fn format(&self, f: defmt::Formatter) {
        defmt::write!(f, "{=[u8]:a}", self.0)
    }
}

/// Decoding cursor over a payload. Every read is checked and returns
/// [`DecodeError::Truncated`] past the end.
#[derive(Debug, Clone)]
pub struct Reader<'a> {
    buf: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    /// A cursor at the start of `payload`.
    pub const fn new(payload: &'a [u8]) -> Self {
        Self {
            buf: payload,
            pos: 0,
        }
    }

    /// A cursor over a payload that must be exactly `len` bytes long (fixed-size
    /// messages check their length once, up front).
    ///
    /// # Errors
    /// [`DecodeError::Truncated`] or [`DecodeError::TrailingBytes`] for any other length.
    #[inline(always)]
    pub const fn exact(payload: &'a [u8], len: usize) -> Result<Self, DecodeError> {
        if payload.len() < len {
            Err(DecodeError::Truncated {
                needed: len,
                actual: payload.len(),
            })
        } else if payload.len() > len {
            Err(DecodeError::TrailingBytes {
                expected: len,
                actual: payload.len(),
            })
        } else {
            Ok(Self::new(payload))
        }
    }

    /// Bytes consumed so far.
    pub const fn position(&self) -> usize {
        self.pos
    }

    fn truncated(&self, needed: usize) -> DecodeError {
        DecodeError::Truncated {
            needed: self.pos.saturating_add(needed),
            actual: self.buf.len(),
        }
    }

    /// Takes the next `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let bytes = self
            .pos
            .checked_add(n)
            .and_then(|end| self.buf.get(self.pos..end))
            .ok_or_else(|| self.truncated(n))?;
        self.pos += n;
        Ok(bytes)
    }

    /// Reads one scalar.
    #[inline(always)]
    pub fn scalar<T: Scalar>(&mut self) -> Result<T, DecodeError> {
        let bytes = self.take(T::SIZE)?;
        T::read_le(bytes).ok_or_else(|| self.truncated(T::SIZE))
    }

    /// Reads a fixed array `T[N]`.
    #[inline]
    pub fn array<T: Scalar, const N: usize>(&mut self) -> Result<[T; N], DecodeError> {
        let bytes = self.take(N * T::SIZE)?;
        let mut out = [T::default(); N];
        for (dst, src) in out.iter_mut().zip(bytes.chunks_exact(T::SIZE)) {
            *dst = T::read_le(src).unwrap_or_default();
        }
        Ok(out)
    }

    /// Reads a variable array `T[]` (count byte, then elements) as a zero-copy view.
    #[inline]
    pub fn vector<T: Scalar>(&mut self) -> Result<VarArray<'a, T>, DecodeError> {
        let count = usize::from(self.scalar::<u8>()?);
        let bytes = self.take(count * T::SIZE)?;
        VarArray::from_wire(bytes).ok_or_else(|| self.truncated(0))
    }

    /// Reads a `char[]` / `string` field (count byte, then bytes).
    #[inline]
    pub fn chars(&mut self) -> Result<Chars<'a>, DecodeError> {
        let count = usize::from(self.scalar::<u8>()?);
        self.take(count).map(Chars::new)
    }

    /// Ends decoding: the payload must have been consumed exactly.
    pub fn finish(self) -> Result<(), DecodeError> {
        if self.pos == self.buf.len() {
            Ok(())
        } else {
            Err(DecodeError::TrailingBytes {
                expected: self.pos,
                actual: self.buf.len(),
            })
        }
    }
}

/// Encoding cursor into an output buffer.
///
/// [`Writer::new`] checks the whole length up front, so a message is written entirely or
/// not at all; the individual writes are still checked (and cannot fail once the
/// up-front check passed with the right length).
#[derive(Debug)]
pub struct Writer<'a> {
    buf: &'a mut [u8],
    pos: usize,
}

impl<'a> Writer<'a> {
    /// A cursor at the start of `buf`, which must hold at least `len` bytes.
    #[inline(always)]
    pub fn new(buf: &'a mut [u8], len: usize) -> Result<Self, EncodeError> {
        if buf.len() < len {
            return Err(EncodeError::BufferTooSmall {
                needed: len,
                available: buf.len(),
            });
        }
        Ok(Self { buf, pos: 0 })
    }

    /// Bytes written so far.
    pub const fn position(&self) -> usize {
        self.pos
    }

    fn overflow(&self, n: usize) -> EncodeError {
        EncodeError::BufferTooSmall {
            needed: self.pos.saturating_add(n),
            available: self.buf.len(),
        }
    }

    /// Writes one scalar.
    #[inline(always)]
    pub fn scalar<T: Scalar>(&mut self, value: T) -> Result<(), EncodeError> {
        let ok = match self.buf.get_mut(self.pos..) {
            Some(rest) => value.write_le(rest),
            None => false,
        };
        if !ok {
            return Err(self.overflow(T::SIZE));
        }
        self.pos += T::SIZE;
        Ok(())
    }

    /// Writes a fixed array `T[N]`.
    #[inline]
    pub fn array<T: Scalar, const N: usize>(&mut self, values: &[T; N]) -> Result<(), EncodeError> {
        for v in values {
            self.scalar(*v)?;
        }
        Ok(())
    }

    /// Writes raw bytes.
    #[inline]
    pub fn bytes(&mut self, bytes: &[u8]) -> Result<(), EncodeError> {
        let n = bytes.len();
        let err = self.overflow(n);
        let pos = self.pos;
        let dst = pos
            .checked_add(n)
            .and_then(|end| self.buf.get_mut(pos..end))
            .ok_or(err)?;
        dst.copy_from_slice(bytes);
        self.pos += n;
        Ok(())
    }

    fn count(&mut self, len: usize) -> Result<(), EncodeError> {
        let count = u8::try_from(len).map_err(|_| EncodeError::ArrayTooLong { len })?;
        self.scalar(count)
    }

    /// Writes a variable array `T[]` (count byte, then elements).
    #[inline]
    pub fn vector<T: Scalar>(&mut self, values: &VarArray<'_, T>) -> Result<(), EncodeError> {
        self.count(values.len())?;
        match values.repr {
            Repr::Wire(bytes) => self.bytes(bytes),
            Repr::Native(elements) => {
                for v in elements {
                    self.scalar(*v)?;
                }
                Ok(())
            }
        }
    }

    /// Writes a `char[]` / `string` field (count byte, then bytes).
    #[inline]
    pub fn chars(&mut self, text: &Chars<'_>) -> Result<(), EncodeError> {
        self.count(text.len())?;
        self.bytes(text.as_bytes())
    }

    /// Ends encoding, returning the number of bytes written.
    pub const fn finish(self) -> usize {
        self.pos
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scalars_are_little_endian() {
        let mut buf = [0u8; 15];
        let mut w = Writer::new(&mut buf, 15).unwrap();
        w.scalar(0x0102u16).unwrap();
        w.scalar(-2i32).unwrap();
        w.scalar(1.0f32).unwrap();
        w.array(&[7u8, 8]).unwrap();
        w.vector(&VarArray::new(&[0x0304u16])).unwrap();
        assert_eq!(w.finish(), 15);
        assert_eq!(
            buf,
            [
                2, 1, 0xFE, 0xFF, 0xFF, 0xFF, 0, 0, 0x80, 0x3F, 7, 8, 1, 4, 3
            ]
        );
        let mut r = Reader::new(&buf);
        assert_eq!(r.scalar::<u16>(), Ok(0x0102));
        assert_eq!(r.scalar::<i32>(), Ok(-2));
        assert_eq!(r.scalar::<f32>(), Ok(1.0));
        assert_eq!(r.array::<u8, 2>(), Ok([7, 8]));
        let v = r.vector::<u16>().unwrap();
        assert_eq!(v, VarArray::new(&[0x0304u16]));
        assert_eq!(r.finish(), Ok(()));
    }

    #[test]
    fn reader_reports_truncation_and_trailing_bytes() {
        let mut r = Reader::new(&[1, 2, 3]);
        assert_eq!(
            r.scalar::<u32>(),
            Err(DecodeError::Truncated {
                needed: 4,
                actual: 3
            })
        );
        let mut r = Reader::new(&[5, 1, 2]);
        assert_eq!(
            r.vector::<u8>(),
            Err(DecodeError::Truncated {
                needed: 6,
                actual: 3
            })
        );
        let mut r = Reader::new(&[1, 2, 3]);
        r.scalar::<u16>().unwrap();
        assert_eq!(
            r.finish(),
            Err(DecodeError::TrailingBytes {
                expected: 2,
                actual: 3
            })
        );
    }

    #[test]
    fn writer_checks_length_up_front_and_array_limit() {
        let mut buf = [0u8; 3];
        assert_eq!(
            Writer::new(&mut buf, 4).unwrap_err(),
            EncodeError::BufferTooSmall {
                needed: 4,
                available: 3
            }
        );
        let mut big = [0u8; 600];
        let long = [0u16; 256];
        let mut w = Writer::new(&mut big, 600).unwrap();
        assert_eq!(
            w.vector(&VarArray::new(&long)),
            Err(EncodeError::ArrayTooLong { len: 256 })
        );
        // A writer given too short a length still cannot write out of bounds.
        let mut small = [0u8; 2];
        let mut w = Writer::new(&mut small, 0).unwrap();
        assert!(w.scalar(1u32).is_err());
        assert_eq!(small, [0, 0]);
    }

    #[test]
    fn wire_views_need_whole_elements() {
        assert!(VarArray::<u32>::from_wire(&[1, 2, 3]).is_none());
        let v = VarArray::<i16>::from_wire(&[0xFF, 0xFF, 2, 0]).unwrap();
        assert_eq!(v.len(), 2);
        assert_eq!(v.iter().collect::<Vec<_>>(), [-1, 2]);
        assert_eq!(v.get(2), None);
        assert_eq!(format!("{v:?}"), "[-1, 2]");
    }

    #[test]
    fn chars_display_replaces_invalid_utf8() {
        assert_eq!(Chars::new(b"ab\xFFc").to_string(), "ab\u{FFFD}c");
        assert_eq!(format!("{:?}", Chars::new(b"a\"\x01")), "\"a\\\"\\x01\"");
        assert_eq!(Chars::from_str("ok").to_str(), Ok("ok"));
    }
}
