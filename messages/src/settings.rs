//! Settings as a Paparazzi `settings.xml` declares them: what the code generator emits
//! for each `<dl_setting>`, and what the aircraft's settings table and the ground use to
//! name, bound and store them.
//!
//! ```
//! use pprz_messages::settings::{SettingDesc, SettingType};
//!
//! const GAIN: SettingDesc<'static> = SettingDesc::new(2, "gain", 0.0, 10.0)
//!     .shortname("Gain")
//!     .persistent(true);
//! assert_eq!(GAIN.name(), "Gain");
//! assert_eq!(GAIN.check(12.0), Err(GAIN.bounds_error(12.0)));
//! assert_eq!(GAIN.check(2.5), Ok(2.5));
//! assert_eq!(GAIN.ty, SettingType::Float);
//! ```

use core::fmt;

/// How a setting's variable is typed (Paparazzi's `type` attribute; float when absent).
/// Every value crosses the link as an `f32` (SETTING, DL_VALUE).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SettingType {
    /// `bool`.
    Bool,
    /// `int8`.
    I8,
    /// `int16`.
    I16,
    /// `int32`.
    I32,
    /// `uint8`.
    U8,
    /// `uint16`.
    U16,
    /// `uint32`.
    U32,
    /// `float` (the default).
    Float,
}

impl SettingType {
    /// The Paparazzi spelling (`"uint8"`, `"float"`, ...).
    pub const fn name(self) -> &'static str {
        match self {
            SettingType::Bool => "bool",
            SettingType::I8 => "int8",
            SettingType::I16 => "int16",
            SettingType::I32 => "int32",
            SettingType::U8 => "uint8",
            SettingType::U16 => "uint16",
            SettingType::U32 => "uint32",
            SettingType::Float => "float",
        }
    }
}

/// One setting of a `settings.xml`: its index (Paparazzi's numbering), names, bounds,
/// value labels, units and storage. `const`, built by named steps, so a generated table
/// is a `static`.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct SettingDesc<'a> {
    /// The index SETTING, GET_SETTING and DL_VALUE carry.
    pub index: u8,
    /// The variable (`var`), e.g. `stabilization_gains.p.x`.
    pub var: &'a str,
    /// The short name the ground shows (`shortname`), if any.
    pub shortname: Option<&'a str>,
    /// Smallest value accepted, in the aircraft's units.
    pub min: f32,
    /// Largest value accepted, in the aircraft's units.
    pub max: f32,
    /// The ground's step (a slider's resolution; the aircraft does not round).
    pub step: f32,
    /// The variable's type.
    pub ty: SettingType,
    /// Labels of the values `min`, `min + 1`, ... (`values="OFF|ON"`); empty if none.
    pub values: &'a [&'a str],
    /// Unit of the value (`unit`).
    pub unit: Option<&'a str>,
    /// Unit the ground shows (`alt_unit`), converted by `alt_unit_coef`.
    pub alt_unit: Option<&'a str>,
    /// Display value = value x this coefficient (1 when absent).
    pub alt_unit_coef: f32,
    /// Stored in flash and loaded at boot.
    pub persistent: bool,
    /// The function called with a new value (`handler`), if any, instead of assigning the
    /// variable.
    pub handler: Option<&'a str>,
    /// The module the handler belongs to (`module`), if any.
    pub module: Option<&'a str>,
}

impl<'a> SettingDesc<'a> {
    /// Setting `index` on `var`, accepting `min..=max`; a float, step 1, no labels, no
    /// units, not persistent, no handler.
    pub const fn new(index: u8, var: &'a str, min: f32, max: f32) -> Self {
        Self {
            index,
            var,
            shortname: None,
            min,
            max,
            step: 1.0,
            ty: SettingType::Float,
            values: &[],
            unit: None,
            alt_unit: None,
            alt_unit_coef: 1.0,
            persistent: false,
            handler: None,
            module: None,
        }
    }

    /// With a short name.
    pub const fn shortname(mut self, name: &'a str) -> Self {
        self.shortname = Some(name);
        self
    }

    /// With a step.
    pub const fn step(mut self, step: f32) -> Self {
        self.step = step;
        self
    }

    /// With a type.
    pub const fn ty(mut self, ty: SettingType) -> Self {
        self.ty = ty;
        self
    }

    /// With value labels.
    pub const fn values(mut self, labels: &'a [&'a str]) -> Self {
        self.values = labels;
        self
    }

    /// With a unit.
    pub const fn unit(mut self, unit: &'a str) -> Self {
        self.unit = Some(unit);
        self
    }

    /// With the unit the ground shows and its coefficient.
    pub const fn alt_unit(mut self, unit: &'a str, coef: f32) -> Self {
        self.alt_unit = Some(unit);
        self.alt_unit_coef = coef;
        self
    }

    /// Persistent or not.
    pub const fn persistent(mut self, persistent: bool) -> Self {
        self.persistent = persistent;
        self
    }

    /// With a handler (and its module, if any).
    pub const fn handler(mut self, handler: &'a str, module: Option<&'a str>) -> Self {
        self.handler = Some(handler);
        self.module = module;
        self
    }

    /// The name to show: the short name, else the variable.
    pub const fn name(&self) -> &'a str {
        match self.shortname {
            Some(name) => name,
            None => self.var,
        }
    }

    /// The label of `value`, if the setting has labels and `value` is one of
    /// `min`, `min + 1`, ...
    pub fn label(&self, value: f32) -> Option<&'a str> {
        let offset = value - self.min;
        if offset < 0.0 || offset != (offset as u32) as f32 {
            return None;
        }
        self.values.get(offset as usize).copied()
    }

    /// `value` if the setting accepts it; NaN, infinities and values outside
    /// `min..=max` are refused.
    ///
    /// # Errors
    /// [`OutOfBounds`] with the bounds.
    pub fn check(&self, value: f32) -> Result<f32, OutOfBounds> {
        if value.is_finite() && value >= self.min && value <= self.max {
            Ok(value)
        } else {
            Err(self.bounds_error(value))
        }
    }

    /// The error [`check`](Self::check) returns for `value`.
    pub const fn bounds_error(&self, value: f32) -> OutOfBounds {
        OutOfBounds {
            index: self.index,
            value,
            min: self.min,
            max: self.max,
        }
    }

    /// The key its stored value is found under: FNV-1a (32 bits) of the variable's name,
    /// so values follow their variable when settings are added, removed or reordered.
    pub const fn key(&self) -> u32 {
        fnv1a(self.var.as_bytes())
    }
}

/// FNV-1a, 32 bits.
pub const fn fnv1a(bytes: &[u8]) -> u32 {
    let mut hash: u32 = 0x811c_9dc5;
    let mut i = 0;
    while i < bytes.len() {
        hash ^= bytes[i] as u32;
        hash = hash.wrapping_mul(0x0100_0193);
        i += 1;
    }
    hash
}

/// A value a setting refuses: not finite, or outside its bounds.
#[derive(Debug, Clone, Copy, PartialEq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct OutOfBounds {
    /// The setting.
    pub index: u8,
    /// The value refused.
    pub value: f32,
    /// Its smallest value.
    pub min: f32,
    /// Its largest value.
    pub max: f32,
}

impl fmt::Display for OutOfBounds {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "setting {}: {} is outside [{}, {}]",
            self.index, self.value, self.min, self.max
        )
    }
}

impl core::error::Error for OutOfBounds {}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bounds_refuse_nan_infinities_and_outside_values() {
        let d = SettingDesc::new(0, "x", -1.0, 1.0);
        assert_eq!(d.check(-1.0), Ok(-1.0));
        assert_eq!(d.check(1.0), Ok(1.0));
        for v in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY, 1.0001, -2.0] {
            assert!(d.check(v).is_err(), "{v}");
        }
        assert_eq!(
            d.check(2.0).unwrap_err().to_string(),
            "setting 0: 2 is outside [-1, 1]"
        );
    }

    #[test]
    fn labels_name_whole_offsets_from_min() {
        static LABELS: [&str; 2] = ["OFF", "ON"];
        let d = SettingDesc::new(1, "flag", 0.0, 1.0).values(&LABELS);
        assert_eq!(d.label(0.0), Some("OFF"));
        assert_eq!(d.label(1.0), Some("ON"));
        assert_eq!(d.label(0.5), None);
        assert_eq!(d.label(2.0), None);
        assert_eq!(d.label(-1.0), None);
        assert_eq!(d.label(f32::NAN), None);
    }

    #[test]
    fn keys_are_fnv1a_of_the_variable() {
        // Reference values of FNV-1a 32.
        assert_eq!(fnv1a(b""), 0x811c_9dc5);
        assert_eq!(fnv1a(b"a"), 0xe40c_292c);
        assert_eq!(SettingDesc::new(0, "a", 0.0, 1.0).key(), 0xe40c_292c);
    }
}
