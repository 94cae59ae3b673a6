//! Long-term Ed25519 keys: the key file, its `const` parser, and the keys of each end.
//!
//! A key file is UTF-8 text, one key per line:
//!
//! ```text
//! # comments and blank lines are allowed
//! GCS_PUBLIC  = <64 hex digits>
//! GCS_PRIVATE = <64 hex digits>
//! UAV_PUBLIC  = <64 hex digits>
//! UAV_PRIVATE = <64 hex digits>
//! ```
//!
//! Private keys are 32-byte Ed25519 seeds (RFC 8032), public keys the 32-byte encoded
//! points. Names are those of Paparazzi's generated key headers; an unknown name, a
//! duplicate, a bad hex digit or a wrong length is an error with its line number (an
//! unknown name is an error rather than ignored, so a misspelt key cannot silently go
//! missing). Each end needs only its own private key and the other end's public key
//! ([`KeyFile::aircraft`], [`KeyFile::ground`]); when a file holds both halves of a pair
//! they must match.
//!
//! # Embedding keys in firmware
//! [`parse_raw`] is a `const fn`, so a firmware can embed a key file named by an
//! environment variable at build time, and a bad file fails the build:
//!
//! ```ignore
//! // PPRZ_SECURE_KEYS=/path/to/aircraft.keys cargo build --release
//! static KEYS: pprz_secure::KeyFile = pprz_secure::include_key_file!("PPRZ_SECURE_KEYS");
//! let keys = KEYS.aircraft()?; // at start-up: derives the public key from the seed
//! ```
//!
//! ([`const_key_file!`](crate::const_key_file) takes text already at hand; a `build.rs`
//! can call the same parser and write the keys out instead.) Never commit a
//! real key file; [`INSECURE_TEST_KEY_FILE`] is a published key set for tests and
//! simulation only.

use core::fmt;

use rand_core::CryptoRng;
use zeroize::Zeroize;

use crate::channel::ct_eq;
use crate::crypto::{SigningKey, VerifyingKey};

/// A published key set, **for tests and simulation only**: anyone can read it, so it
/// protects nothing. It is the key set of the known-answer vectors.
pub const INSECURE_TEST_KEY_FILE: &str = include_str!("../keys/INSECURE-TEST-ONLY.keys");

/// A [`KeyFile`] constant from key-file text known at build time (a literal, an
/// `include_str!`), parsed by the `const` [`parse_raw`]: a malformed line fails the
/// build.
///
/// ```
/// static KEYS: pprz_secure::KeyFile =
///     pprz_secure::const_key_file!(pprz_secure::keys::INSECURE_TEST_KEY_FILE);
/// assert!(KEYS.aircraft().is_ok());
/// ```
///
/// ```compile_fail
/// // A key of 2 hex digits: "a key value is not 64 hex digits", at build time.
/// static KEYS: pprz_secure::KeyFile = pprz_secure::const_key_file!("UAV_PUBLIC = 12");
/// ```
#[macro_export]
macro_rules! const_key_file {
    ($text:expr) => {{
        const KEYS: $crate::KeyFile =
            $crate::KeyFile::from_raw(match $crate::keys::parse_raw($text) {
                Ok(keys) => keys,
                Err(e) => panic!("{}", e.kind.message()),
            });
        KEYS
    }};
}

/// Embeds the key file named by the environment variable `$env` at build time (see
/// [`const_key_file!`]): a missing variable or file, or a malformed line, fails the
/// build. Keys an end needs but the file lacks are reported at run time by
/// [`KeyFile::aircraft`] or [`KeyFile::ground`].
#[macro_export]
macro_rules! include_key_file {
    ($env:literal) => {
        $crate::const_key_file!(include_str!(env!($env)))
    };
}

/// The names of the keys in a key file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum KeyName {
    /// `GCS_PUBLIC`: the ground's public key.
    GcsPublic,
    /// `GCS_PRIVATE`: the ground's seed.
    GcsPrivate,
    /// `UAV_PUBLIC`: the aircraft's public key.
    UavPublic,
    /// `UAV_PRIVATE`: the aircraft's seed.
    UavPrivate,
}

impl KeyName {
    /// Every name, in file order.
    pub const ALL: [KeyName; 4] = [
        Self::GcsPublic,
        Self::GcsPrivate,
        Self::UavPublic,
        Self::UavPrivate,
    ];

    /// The name as written in a key file.
    pub const fn as_str(self) -> &'static str {
        match self {
            Self::GcsPublic => "GCS_PUBLIC",
            Self::GcsPrivate => "GCS_PRIVATE",
            Self::UavPublic => "UAV_PUBLIC",
            Self::UavPrivate => "UAV_PRIVATE",
        }
    }

    const fn index(self) -> usize {
        self as usize
    }
}

impl fmt::Display for KeyName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// What is wrong with a line of a key file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum KeyFileErrorKind {
    /// Not `NAME = value`.
    Syntax,
    /// A name other than the four key names.
    UnknownName,
    /// A key given twice.
    Duplicate(KeyName),
    /// A character that is not a hex digit in the value.
    BadHex,
    /// A value of another length than 64 hex digits.
    WrongLength,
}

impl KeyFileErrorKind {
    /// A short description (`const`, for build-time errors).
    pub const fn message(&self) -> &'static str {
        match self {
            Self::Syntax => "key file: a line is not `NAME = <64 hex digits>`",
            Self::UnknownName => {
                "key file: unknown key name (GCS_PUBLIC, GCS_PRIVATE, UAV_PUBLIC, UAV_PRIVATE)"
            }
            Self::Duplicate(_) => "key file: a key is given twice",
            Self::BadHex => "key file: a key value has a character that is not a hex digit",
            Self::WrongLength => "key file: a key value is not 64 hex digits (32 bytes)",
        }
    }
}

/// A key file parse error: what and on which line (1-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct KeyFileError {
    /// The line, counting from 1.
    pub line: u32,
    /// What is wrong.
    pub kind: KeyFileErrorKind,
}

impl fmt::Display for KeyFileError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}: {}", self.line, self.kind.message())?;
        if let KeyFileErrorKind::Duplicate(name) = self.kind {
            write!(f, " ({name})")?;
        }
        Ok(())
    }
}

impl core::error::Error for KeyFileError {}

/// Why a key file does not give the keys of an end.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
#[non_exhaustive]
pub enum KeyError {
    /// A key this end needs is not in the file.
    Missing(KeyName),
    /// The public key is not a valid Ed25519 point, or a weak (small-order) one.
    BadPublicKey(KeyName),
    /// The public key does not belong to the private key given with it.
    Mismatch(KeyName),
}

impl fmt::Display for KeyError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Missing(n) => write!(f, "key {n} missing"),
            Self::BadPublicKey(n) => write!(f, "key {n} is not a valid Ed25519 public key"),
            Self::Mismatch(n) => write!(f, "key {n} does not match its private key"),
        }
    }
}

impl core::error::Error for KeyError {}

/// A parsed key file. Private keys are zeroized on drop and never shown by `Debug`.
pub struct KeyFile {
    keys: [Option<[u8; 32]>; 4],
}

impl Drop for KeyFile {
    fn drop(&mut self) {
        for k in self.keys.iter_mut().flatten() {
            k.zeroize();
        }
    }
}

/// The keys of a key file in [`KeyName::ALL`] order (`GCS_PUBLIC`, `GCS_PRIVATE`,
/// `UAV_PUBLIC`, `UAV_PRIVATE`), as [`parse_raw`] gives them: plain arrays, so a `const`
/// can match on the result (a [`KeyFile`] zeroizes itself on drop, which `const`
/// evaluation cannot do). Make a [`KeyFile`] of it with [`KeyFile::from_raw`].
pub type RawKeys = [Option<[u8; 32]>; 4];

impl fmt::Debug for KeyFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let mut d = f.debug_struct("KeyFile");
        for name in KeyName::ALL {
            let shown = match (name, self.get(name)) {
                (_, None) => "-",
                (KeyName::GcsPrivate | KeyName::UavPrivate, Some(_)) => "(secret)",
                (_, Some(_)) => "(public)",
            };
            d.field(name.as_str(), &shown);
        }
        d.finish()
    }
}

const fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\r')
}

const fn hex_value(b: u8) -> Option<u8> {
    match b {
        b'0'..=b'9' => Some(b - b'0'),
        b'a'..=b'f' => Some(b - b'a' + 10),
        b'A'..=b'F' => Some(b - b'A' + 10),
        _ => None,
    }
}

// Indices bounded by the loops' conditions (`const fn` cannot use `get`).
#[allow(clippy::indexing_slicing)]
/// Whether `text[start..end]` is `name` (the range is within `text`).
const fn name_is(text: &[u8], start: usize, end: usize, name: &str) -> bool {
    let name = name.as_bytes();
    if end - start != name.len() {
        return false;
    }
    let mut i = 0;
    while i < name.len() {
        if text[start + i] != name[i] {
            return false;
        }
        i += 1;
    }
    true
}

// Indices bounded by the loops' conditions (`const fn` cannot use `get`).
#[allow(clippy::indexing_slicing)]
/// Parses the line `text[start..end]` (within `text`): `None` for a blank or comment
/// line, the key's index and value otherwise.
const fn parse_line(
    text: &[u8],
    mut start: usize,
    mut end: usize,
) -> Result<Option<(KeyName, [u8; 32])>, KeyFileErrorKind> {
    while start < end && is_space(text[start]) {
        start += 1;
    }
    while end > start && is_space(text[end - 1]) {
        end -= 1;
    }
    if start == end || text[start] == b'#' {
        return Ok(None);
    }
    let mut eq = start;
    while eq < end && text[eq] != b'=' {
        eq += 1;
    }
    if eq == end {
        return Err(KeyFileErrorKind::Syntax);
    }
    let mut name_end = eq;
    while name_end > start && is_space(text[name_end - 1]) {
        name_end -= 1;
    }
    let mut value = eq + 1;
    while value < end && is_space(text[value]) {
        value += 1;
    }
    let mut found = None;
    let mut n = 0;
    while n < KeyName::ALL.len() {
        if name_is(text, start, name_end, KeyName::ALL[n].as_str()) {
            found = Some(KeyName::ALL[n]);
        }
        n += 1;
    }
    let Some(name) = found else {
        return Err(KeyFileErrorKind::UnknownName);
    };
    let mut i = value;
    while i < end {
        if hex_value(text[i]).is_none() {
            return Err(KeyFileErrorKind::BadHex);
        }
        i += 1;
    }
    if end - value != 64 {
        return Err(KeyFileErrorKind::WrongLength);
    }
    let mut key = [0u8; 32];
    let mut k = 0;
    while k < 32 {
        let (Some(hi), Some(lo)) = (
            hex_value(text[value + 2 * k]),
            hex_value(text[value + 2 * k + 1]),
        ) else {
            return Err(KeyFileErrorKind::BadHex);
        };
        key[k] = (hi << 4) | lo;
        k += 1;
    }
    Ok(Some((name, key)))
}

// Indices bounded by the loops' conditions (`const fn` cannot use `get`).
#[allow(clippy::indexing_slicing)]
/// Parses a key file into its raw keys: the `const` parser behind [`KeyFile::parse`],
/// for build-time use (see [`include_key_file!`](crate::include_key_file)).
///
/// # Errors
/// The first bad line, see [`KeyFileErrorKind`].
pub const fn parse_raw(text: &str) -> Result<RawKeys, KeyFileError> {
    let text = text.as_bytes();
    let mut keys: [Option<[u8; 32]>; 4] = [None; 4];
    let mut i = 0;
    // A UTF-8 byte order mark is allowed.
    if text.len() >= 3 && text[0] == 0xEF && text[1] == 0xBB && text[2] == 0xBF {
        i = 3;
    }
    let mut line = 1u32;
    while i < text.len() {
        let start = i;
        while i < text.len() && text[i] != b'\n' {
            i += 1;
        }
        let end = i;
        if i < text.len() {
            i += 1;
        }
        match parse_line(text, start, end) {
            Ok(None) => {}
            Ok(Some((name, key))) => {
                if keys[name.index()].is_some() {
                    return Err(KeyFileError {
                        line,
                        kind: KeyFileErrorKind::Duplicate(name),
                    });
                }
                keys[name.index()] = Some(key);
            }
            Err(kind) => return Err(KeyFileError { line, kind }),
        }
        line = line.saturating_add(1);
    }
    Ok(keys)
}

impl KeyFile {
    /// Parses a key file (see the [module documentation](self)); [`parse_raw`] is its
    /// `const` form, usable at build time. Keys absent from the file are `None`; which ones an end needs is
    /// checked by [`aircraft`](Self::aircraft) and [`ground`](Self::ground).
    ///
    /// # Errors
    /// The first bad line, see [`KeyFileErrorKind`].
    pub fn parse(text: &str) -> Result<KeyFile, KeyFileError> {
        parse_raw(text).map(Self::from_raw)
    }

    /// A key file of the keys [`parse_raw`] gave.
    pub const fn from_raw(keys: RawKeys) -> Self {
        Self { keys }
    }
    /// A key file with the given keys (for tests and key generation).
    pub const fn from_keys(
        gcs_public: Option<[u8; 32]>,
        gcs_private: Option<[u8; 32]>,
        uav_public: Option<[u8; 32]>,
        uav_private: Option<[u8; 32]>,
    ) -> Self {
        Self {
            keys: [gcs_public, gcs_private, uav_public, uav_private],
        }
    }

    /// A new key set: fresh seeds for the ground and the aircraft from `rng`, and their
    /// public keys.
    pub fn generate<R: CryptoRng + ?Sized>(rng: &mut R) -> Self {
        let mut gcs = [0u8; 32];
        let mut uav = [0u8; 32];
        rng.fill_bytes(&mut gcs);
        rng.fill_bytes(&mut uav);
        let gcs_public = SigningKey::from_seed(&gcs).public();
        let uav_public = SigningKey::from_seed(&uav).public();
        let file = Self::from_keys(Some(gcs_public), Some(gcs), Some(uav_public), Some(uav));
        gcs.zeroize();
        uav.zeroize();
        file
    }

    /// The key `name`, if the file has it.
    pub const fn get(&self, name: KeyName) -> Option<&[u8; 32]> {
        let [gcs_public, gcs_private, uav_public, uav_private] = &self.keys;
        match name {
            KeyName::GcsPublic => gcs_public.as_ref(),
            KeyName::GcsPrivate => gcs_private.as_ref(),
            KeyName::UavPublic => uav_public.as_ref(),
            KeyName::UavPrivate => uav_private.as_ref(),
        }
    }

    /// The same file without the key `name` (to write the part of a key set one end
    /// needs).
    pub fn without(mut self, name: KeyName) -> Self {
        if let Some(slot) = self.keys.get_mut(name.index()) {
            if let Some(k) = slot {
                k.zeroize();
            }
            *slot = None;
        }
        self
    }

    /// Writes the file in the key file format (with a warning comment when it holds a
    /// private key).
    ///
    /// # Errors
    /// Those of `out`.
    pub fn write_to(&self, out: &mut dyn fmt::Write) -> fmt::Result {
        writeln!(
            out,
            "# pprz-secure key file: Ed25519 keys (private keys are RFC 8032 seeds)."
        )?;
        if self.get(KeyName::GcsPrivate).is_some() || self.get(KeyName::UavPrivate).is_some() {
            writeln!(
                out,
                "# SECRET: holds private keys. Keep it safe; never commit it."
            )?;
        }
        for name in KeyName::ALL {
            if let Some(key) = self.get(name) {
                write!(out, "{name} = ")?;
                for b in key {
                    write!(out, "{b:02x}")?;
                }
                writeln!(out)?;
            }
        }
        Ok(())
    }

    fn identity(
        &self,
        own: KeyName,
        own_public: KeyName,
        peer: KeyName,
    ) -> Result<Identity, KeyError> {
        let seed = self.get(own).ok_or(KeyError::Missing(own))?;
        let peer_bytes = self.get(peer).ok_or(KeyError::Missing(peer))?;
        let signing = SigningKey::from_seed(seed);
        if let Some(public) = self.get(own_public)
            && !ct_eq(public, &signing.public())
        {
            return Err(KeyError::Mismatch(own_public));
        }
        let peer_key = VerifyingKey::from_bytes(peer_bytes).ok_or(KeyError::BadPublicKey(peer))?;
        Ok(Identity {
            own: signing,
            peer: peer_key,
        })
    }

    /// The aircraft's keys: its seed (`UAV_PRIVATE`) and the ground's public key
    /// (`GCS_PUBLIC`); `UAV_PUBLIC`, if present, must match the seed.
    ///
    /// # Errors
    /// See [`KeyError`].
    pub fn aircraft(&self) -> Result<AircraftKeys, KeyError> {
        self.identity(KeyName::UavPrivate, KeyName::UavPublic, KeyName::GcsPublic)
            .map(AircraftKeys)
    }

    /// The ground's keys: its seed (`GCS_PRIVATE`) and the aircraft's public key
    /// (`UAV_PUBLIC`); `GCS_PUBLIC`, if present, must match the seed.
    ///
    /// # Errors
    /// See [`KeyError`].
    pub fn ground(&self) -> Result<GroundKeys, KeyError> {
        self.identity(KeyName::GcsPrivate, KeyName::GcsPublic, KeyName::UavPublic)
            .map(GroundKeys)
    }
}

/// Our signing key and the peer's verifying key.
pub(crate) struct Identity {
    pub(crate) own: SigningKey,
    pub(crate) peer: VerifyingKey,
}

/// The aircraft's long-term keys: its Ed25519 signing key and the ground's verifying key
/// (what the [`Responder`](crate::Responder) needs). The secret is zeroized on drop.
pub struct AircraftKeys(pub(crate) Identity);

/// The ground's long-term keys: its Ed25519 signing key and the aircraft's verifying key
/// (what the [`Initiator`](crate::Initiator) needs). The secret is zeroized on drop.
pub struct GroundKeys(pub(crate) Identity);

impl AircraftKeys {
    /// The aircraft's keys from its seed and the ground's public key.
    ///
    /// # Errors
    /// [`KeyError::BadPublicKey`] if `gcs_public` is not a valid, strong public key.
    pub fn new(uav_private: &[u8; 32], gcs_public: &[u8; 32]) -> Result<Self, KeyError> {
        KeyFile::from_keys(Some(*gcs_public), None, None, Some(*uav_private)).aircraft()
    }

    /// The aircraft's public key.
    pub fn public(&self) -> [u8; 32] {
        self.0.own.public()
    }
}

impl GroundKeys {
    /// The ground's keys from its seed and the aircraft's public key.
    ///
    /// # Errors
    /// [`KeyError::BadPublicKey`] if `uav_public` is not a valid, strong public key.
    pub fn new(gcs_private: &[u8; 32], uav_public: &[u8; 32]) -> Result<Self, KeyError> {
        KeyFile::from_keys(None, Some(*gcs_private), Some(*uav_public), None).ground()
    }

    /// The ground's public key.
    pub fn public(&self) -> [u8; 32] {
        self.0.own.public()
    }
}

impl fmt::Debug for AircraftKeys {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("AircraftKeys(..)")
    }
}

impl fmt::Debug for GroundKeys {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("GroundKeys(..)")
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use std::string::String;

    use super::*;

    const HEX_A: &str = "0101010101010101010101010101010101010101010101010101010101010101";

    fn err(text: &str) -> KeyFileError {
        KeyFile::parse(text).unwrap_err()
    }

    #[test]
    fn parses_names_comments_and_spaces() {
        let text = std::format!(
            "\u{feff}# keys\r\n\n  GCS_PRIVATE={HEX_A}\r\n\tUAV_PUBLIC =  {} \n",
            HEX_A.to_uppercase()
        );
        let f = KeyFile::parse(&text).unwrap();
        assert_eq!(f.get(KeyName::GcsPrivate), Some(&[1; 32]));
        assert_eq!(f.get(KeyName::UavPublic), Some(&[1; 32]));
        assert_eq!(f.get(KeyName::GcsPublic), None);
        assert_eq!(
            std::format!("{f:?}"),
            "KeyFile { GCS_PUBLIC: \"-\", GCS_PRIVATE: \"(secret)\", UAV_PUBLIC: \"(public)\", UAV_PRIVATE: \"-\" }"
        );
        assert!(KeyFile::parse("").is_ok());
    }

    #[test]
    fn typed_errors_with_lines() {
        use KeyFileErrorKind::*;
        let e = err(&std::format!("# c\nGCS_PUBLIC {HEX_A}"));
        assert_eq!((e.line, e.kind), (2, Syntax));
        assert_eq!(err(&std::format!("GCS_KEY = {HEX_A}")).kind, UnknownName);
        assert_eq!(err(&std::format!("gcs_public = {HEX_A}")).kind, UnknownName);
        assert_eq!(err("UAV_PUBLIC = 0g").kind, BadHex);
        assert_eq!(err("UAV_PUBLIC = 0x01").kind, BadHex);
        assert_eq!(err("UAV_PUBLIC = 0102").kind, WrongLength);
        assert_eq!(err("UAV_PUBLIC =").kind, WrongLength);
        assert_eq!(
            err(&std::format!("UAV_PUBLIC = {HEX_A}00")).kind,
            WrongLength
        );
        let e = err(&std::format!(
            "UAV_PUBLIC = {HEX_A}\nUAV_PUBLIC = {HEX_A}\n"
        ));
        assert_eq!((e.line, e.kind), (2, Duplicate(KeyName::UavPublic)));
        assert_eq!(
            std::format!("{e}"),
            "line 2: key file: a key is given twice (UAV_PUBLIC)"
        );
    }

    #[test]
    fn const_parse() {
        static F: KeyFile = crate::const_key_file!(INSECURE_TEST_KEY_FILE);
        assert!(F.aircraft().is_ok());
        assert!(F.ground().is_ok());
    }

    #[test]
    fn role_keys_missing_mismatch_bad() {
        let f = KeyFile::parse(INSECURE_TEST_KEY_FILE).unwrap();
        let gcs_pub = *f.get(KeyName::GcsPublic).unwrap();
        let uav_pub = *f.get(KeyName::UavPublic).unwrap();
        assert_eq!(
            f.aircraft().unwrap().public(),
            uav_pub,
            "the test key file is consistent"
        );
        assert_eq!(f.ground().unwrap().public(), gcs_pub);
        let f = f.without(KeyName::GcsPublic);
        assert!(matches!(
            f.aircraft(),
            Err(KeyError::Missing(KeyName::GcsPublic))
        ));
        let f = KeyFile::from_keys(Some(gcs_pub), None, Some(gcs_pub), Some([1; 32]));
        assert!(matches!(
            f.aircraft(),
            Err(KeyError::Mismatch(KeyName::UavPublic))
        ));
        // The identity point is a weak key; [2, 0, ..] does not decode.
        let mut identity = [0u8; 32];
        identity[0] = 1;
        assert!(matches!(
            AircraftKeys::new(&[1; 32], &identity),
            Err(KeyError::BadPublicKey(KeyName::GcsPublic))
        ));
        let mut bad = [0xFFu8; 32];
        bad[31] = 0x7F;
        bad[0] = 0xEE;
        assert!(GroundKeys::new(&[1; 32], &bad).is_err());
    }

    #[test]
    fn generate_and_write_round_trip() {
        struct Counter(u8);
        impl rand_core::RngCore for Counter {
            fn next_u32(&mut self) -> u32 {
                rand_core::impls::next_u32_via_fill(self)
            }
            fn next_u64(&mut self) -> u64 {
                rand_core::impls::next_u64_via_fill(self)
            }
            fn fill_bytes(&mut self, dst: &mut [u8]) {
                for b in dst {
                    self.0 = self.0.wrapping_add(1);
                    *b = self.0;
                }
            }
        }
        impl CryptoRng for Counter {}
        let f = KeyFile::generate(&mut Counter(0));
        let mut text = String::new();
        f.write_to(&mut text).unwrap();
        assert!(text.contains("SECRET"));
        let g = KeyFile::parse(&text).unwrap();
        for name in KeyName::ALL {
            assert_eq!(f.get(name), g.get(name));
        }
        assert!(g.aircraft().is_ok() && g.ground().is_ok());
        // The aircraft's part: no ground seed, no "SECRET" line missing.
        let air = g.without(KeyName::GcsPrivate);
        let mut text = String::new();
        air.write_to(&mut text).unwrap();
        assert!(!text.contains("GCS_PRIVATE"));
        assert!(KeyFile::parse(&text).unwrap().aircraft().is_ok());
    }
}
