//! Paparazzi settings files (`settings.xml`): parser, numbering and checks, and the
//! emitter of a settings table the aircraft registers in one call.
//!
//! ```text
//! <settings>
//!   <dl_settings>
//!     <dl_settings name="ins">
//!       <dl_setting var="ins_roll_neutral" min="-15" max="15" step="0.5"
//!                   unit="rad" alt_unit="deg" persistent="true"/>
//! ```
//!
//! # Numbering
//! Paparazzi's rule: every `<dl_setting>` in document order, the `<dl_settings>` groups
//! flattened, the files in the order given. The index is what SETTING, GET_SETTING and
//! DL_VALUE carry, so the aircraft and the ground must read the same files in the same
//! order. At most 256 settings (an index is one byte). Groups nest at most
//! [`MAX_GROUP_DEPTH`] deep; they are read iteratively.
//!
//! # Attributes
//! `<dl_setting>`: `var`, `min` and `max` are required. `step` (1 when absent),
//! `shortname`, `type` (float when absent), `values` (labels of `min`, `min + 1`, ...,
//! separated by `|`), `unit`, `alt_unit`, `alt_unit_coef`, `persistent`, `handler`,
//! `module`, `param` are read; `widget`, `header` and `auto` are known and not used.
//! Any other attribute is ignored with a warning. `<dl_settings>`: `name` (the group
//! path of a setting joins the names with `/`). `<settings>`: `target` (kept; every
//! file is read, whatever its target). `<strip_button>` and `<key_press>` inside a
//! `<dl_setting>` and `<rc_settings>` are ignored; other elements are ignored with a
//! warning.
//!
//! # Leniency
//! What Paparazzi's XML reader accepts and strict XML does not:
//!
//! - attribute and element names are matched without regard to case (`VAR`, `MIN`,
//!   `NAME`); the same attribute in two spellings (`var` and `VAR`) is an error;
//! - a missing space between two attributes (`handler="SetKiPhi"param="..."`) is
//!   accepted with a warning at the attribute's line and column in the file as written.
//!
//! # Types
//! `bool`, `int8`, `int16`, `int32`, `uint8`, `uint16`, `uint32` and `float` are the
//! types of [`SettingType`]. Any other type is read as the nearest, with a warning:
//! `int64` as `int32`, `uint64` as `uint32`, `double`, `fun` and the rest as `float`. A
//! persistent setting of another type is an error: it could not be stored as declared.
//!
//! # Bounds and units
//! `min`, `max` and `step` are written in the ground's display units: those of
//! `alt_unit` when it is given. The table holds them in the aircraft's units, where
//! they are checked: value = display / coefficient. The coefficient is `alt_unit_coef`;
//! without it, the conversion from `unit` to `alt_unit` (built in, such as `rad` to
//! `deg`, or from a `units.xml` given to the generator); without a known conversion, 1
//! with a warning. A negative coefficient swaps the bounds. The aircraft refuses a value
//! outside them (it does not clamp it) and answers with the value in force.
//!
//! # Refused
//! Each with file, line and column: malformed XML (other than the missing space), a
//! missing `var`, `min` or `max`; a bound, step or coefficient that is not a finite
//! number fitting an `f32` (also after conversion); `min` above `max`; a step of 0 or
//! less; a coefficient of 0; more than 256 settings; two different variables that make
//! the same Rust name (`a.b` and `a_b`); two different persistent variables with the
//! same storage key (FNV-1a of the variable); inputs beyond the [`limits`](crate::limits).
//!
//! # Warnings
//! A `values` list whose length is not `max - min + 1`; `persistent="false"` (any value
//! makes a setting persistent in Paparazzi, and here too); `alt_unit` without a known
//! coefficient; a type read as another; unknown attributes and elements; a group
//! holding both settings and groups (Paparazzi's generator refuses it); a second
//! top-level `<dl_settings>` (Paparazzi reads only the first).
//!
//! At most [`MAX_REPORTED`] problems and as many warnings are reported per file; the
//! others are counted. Past the 257th setting of a file, the rest of it is not read:
//! the set is refused for its size.
//!
//! The same `var` may appear several times (Paparazzi allows it): each occurrence has
//! its index, and the variable has one binding.

mod check;
mod emit;
mod read;
mod repair;

use std::path::Path;

use pprz_messages::settings::{SettingType, fnv1a};

use crate::error::{Diagnostic, Error};
use crate::model::Units;
use crate::xml;

pub(crate) use emit::{Paths, emit};

/// Largest nesting of `<dl_settings>` groups.
pub const MAX_GROUP_DEPTH: usize = 64;

/// Largest number of settings (an index is one byte).
pub const MAX_SETTINGS: usize = 256;

/// The most problems, and the most warnings, reported for one file; the others are
/// counted in one last diagnostic (a hostile file could make millions).
pub const MAX_REPORTED: usize = 1000;

/// One `<dl_setting>`, numbered and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct SettingDef {
    /// Its index (Paparazzi's numbering).
    pub index: u8,
    /// The file it comes from.
    pub file: String,
    /// Line of the element.
    pub line: u32,
    /// Column of the element.
    pub column: u32,
    /// The names of its groups, outermost first, joined with `/` (empty if none).
    pub group: String,
    /// The variable (`var`), e.g. `stabilization_gains.p.x`.
    pub var: String,
    /// The Rust name of its binding (`stabilization_gains_p_x`).
    pub rust_name: String,
    /// The short name (`shortname`).
    pub shortname: Option<String>,
    /// Smallest value, in the aircraft's units.
    pub min: f32,
    /// Largest value, in the aircraft's units.
    pub max: f32,
    /// Step, in the aircraft's units.
    pub step: f32,
    /// `min` as written (display units).
    pub written_min: f64,
    /// `max` as written (display units).
    pub written_max: f64,
    /// `step` as written, 1 when absent (display units).
    pub written_step: f64,
    /// Its type.
    pub ty: SettingType,
    /// `type` as written.
    pub type_name: Option<String>,
    /// Labels of `min`, `min + 1`, ...
    pub values: Vec<String>,
    /// `unit`.
    pub unit: Option<String>,
    /// `alt_unit`.
    pub alt_unit: Option<String>,
    /// Display value = value x this (1 when there is no conversion).
    pub alt_unit_coef: f64,
    /// Stored and loaded at boot (`persistent`, whatever its value).
    pub persistent: bool,
    /// `handler`.
    pub handler: Option<String>,
    /// `module`.
    pub module: Option<String>,
    /// `param`.
    pub param: Option<String>,
}

impl SettingDef {
    /// The name of its index constant (`STABILIZATION_GAINS_P_X`).
    pub fn index_const(&self) -> String {
        self.rust_name.to_ascii_uppercase()
    }

    /// The key its stored value is found under: FNV-1a of the variable.
    pub fn key(&self) -> u32 {
        fnv1a(self.var.as_bytes())
    }

    /// The name to show: the short name, else the variable.
    pub fn name(&self) -> &str {
        self.shortname.as_deref().unwrap_or(&self.var)
    }

    /// `file:line:column`.
    pub fn location(&self) -> String {
        format!("{}:{}:{}", self.file, self.line, self.column)
    }
}

/// A settings file of a [`SettingsSet`].
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SettingsFile {
    /// Its name, as given.
    pub name: String,
    /// The `target` attribute of its `<settings>`.
    pub target: Option<String>,
    /// Index of its first setting (the number of settings before it).
    pub first: usize,
    /// Number of its settings.
    pub count: usize,
}

/// A variable of a [`SettingsSet`]: one binding, one or more settings.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Variable<'s> {
    /// The variable.
    pub var: &'s str,
    /// The Rust name of its binding.
    pub rust_name: &'s str,
    /// Its settings' indices, in order.
    pub indices: Vec<u8>,
}

/// The settings of one or more files, numbered in order and checked.
#[derive(Debug, Clone, PartialEq)]
pub struct SettingsSet {
    /// The files, in the order read.
    pub files: Vec<SettingsFile>,
    /// The settings in index order.
    pub settings: Vec<SettingDef>,
    /// What was accepted with a warning; print them as `warning: {diagnostic}`.
    pub warnings: Vec<Diagnostic>,
}

impl SettingsSet {
    /// Reads and checks settings files, numbered in the order given.
    ///
    /// # Errors
    /// Every problem of every file (see the [module docs](self)), each with file, line
    /// and column.
    pub fn from_files<P: AsRef<Path>>(paths: &[P], units: &Units) -> Result<Self, Error> {
        let inputs: Vec<Input<'_>> = paths.iter().map(|p| Input::File(p.as_ref())).collect();
        read(&inputs, units)
    }

    /// Parses and checks settings texts (`(name, text)`: `name` names the text in
    /// diagnostics), numbered in the order given; `units` supplies the conversions from
    /// `unit` to `alt_unit` (e.g. [`Units::builtin`]).
    ///
    /// # Errors
    /// As [`from_files`](Self::from_files).
    pub fn parse(files: &[(&str, &str)], units: &Units) -> Result<Self, Error> {
        let inputs: Vec<Input<'_>> = files.iter().map(|&(n, t)| Input::Text(n, t)).collect();
        read(&inputs, units)
    }

    /// Number of settings.
    pub fn len(&self) -> usize {
        self.settings.len()
    }

    /// Whether there are no settings.
    pub fn is_empty(&self) -> bool {
        self.settings.is_empty()
    }

    /// The setting at `index`.
    pub fn get(&self, index: u8) -> Option<&SettingDef> {
        self.settings.get(usize::from(index))
    }

    /// The variables, in the order of their first setting.
    pub fn variables(&self) -> Vec<Variable<'_>> {
        let mut vars: Vec<Variable<'_>> = Vec::new();
        let mut position = std::collections::HashMap::new();
        for s in &self.settings {
            match position.get(s.var.as_str()) {
                Some(&i) => {
                    let v: &mut Variable<'_> = &mut vars[i];
                    v.indices.push(s.index);
                }
                None => {
                    position.insert(s.var.as_str(), vars.len());
                    vars.push(Variable {
                        var: &s.var,
                        rust_name: &s.rust_name,
                        indices: vec![s.index],
                    });
                }
            }
        }
        vars
    }

    /// Number of persistent settings.
    pub fn persistent_count(&self) -> usize {
        self.settings.iter().filter(|s| s.persistent).count()
    }
}

/// A settings file to read.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Input<'s> {
    /// A file.
    File(&'s Path),
    /// A text, and the name that names it in diagnostics.
    Text(&'s str, &'s str),
}

/// Reads and checks `inputs`, numbered in order.
pub(crate) fn read(inputs: &[Input<'_>], units: &Units) -> Result<SettingsSet, Error> {
    let one = |name: &str, text: &str| {
        xml::parse_repaired(name, text, repair::missing_spaces, |p| read::file(p, units))
            .map(|r| (name.to_owned(), r))
    };
    let read = inputs
        .iter()
        .map(|input| match *input {
            Input::File(path) => xml::parse_file(path, one),
            Input::Text(name, text) => one(name, text),
        })
        .collect();
    combine(read)
}

/// The files read (each, or its problems), numbered in order and checked together.
fn combine(read: Vec<Result<(String, read::FileRead), Error>>) -> Result<SettingsSet, Error> {
    let mut errors = Vec::new();
    let mut set = SettingsSet {
        files: Vec::new(),
        settings: Vec::new(),
        warnings: Vec::new(),
    };
    for file in read {
        match file {
            Ok((name, r)) => {
                set.files.push(SettingsFile {
                    name,
                    target: r.target,
                    first: set.settings.len(),
                    count: r.settings.len(),
                });
                set.settings.extend(r.settings);
                set.warnings.extend(r.warnings);
            }
            Err(e) => errors.extend_from_slice(e.diagnostics()),
        }
    }
    for (i, s) in set.settings.iter_mut().enumerate() {
        // Beyond 255 the count is refused below.
        s.index = u8::try_from(i).unwrap_or(u8::MAX);
    }
    check::all(&set.settings, &mut errors);
    if errors.is_empty() {
        Ok(set)
    } else {
        Err(Error::new(errors))
    }
}
