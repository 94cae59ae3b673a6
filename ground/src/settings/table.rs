//! Named settings: the table of the aircraft's settings files ([`SettingsTable`]).

use std::collections::HashMap;
use std::fmt;
use std::path::Path;

use pprz_codegen::{Diagnostic, SettingDef, SettingsSet, Units};

/// Text from a settings file for a line of the terminal: no control character, no line
/// break.
pub(crate) fn text(s: &str) -> String {
    crate::escape::lines(s).replace('\n', "\\n")
}

/// A number as the ground shows it: the shortest text of the `f32`.
fn number(v: f32) -> String {
    v.to_string()
}

/// Why a name names no setting.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum NameError {
    /// No setting has this variable, short name or unique name.
    Unknown {
        /// The name given.
        name: String,
        /// Settings in the table.
        count: usize,
    },
    /// An index beyond the table.
    NoSuchIndex {
        /// The index given.
        index: u8,
        /// Settings in the table.
        count: usize,
    },
    /// A short name of several variables.
    Ambiguous {
        /// The name given.
        name: String,
        /// The candidates' variables and first indices.
        candidates: Vec<(String, u8)>,
    },
}

impl fmt::Display for NameError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let last = |count: usize| count.saturating_sub(1);
        match self {
            Self::Unknown { name, count } => write!(
                f,
                "no setting is named `{}` (give a var, a short name, or an index 0 to {})",
                text(name),
                last(*count)
            ),
            Self::NoSuchIndex { index, count } => write!(
                f,
                "no setting has index {index}: the settings files have {count} (0 to {})",
                last(*count)
            ),
            Self::Ambiguous { name, candidates } => {
                let list: Vec<String> = candidates
                    .iter()
                    .map(|(var, i)| format!("{} (index {i})", text(var)))
                    .collect();
                write!(
                    f,
                    "the short name `{}` is ambiguous: {}; give the var",
                    text(name),
                    list.join(", ")
                )
            }
        }
    }
}

impl std::error::Error for NameError {}

/// Why a value is refused for a setting; each names the setting and its bounds.
#[derive(Debug, Clone, PartialEq)]
pub struct ValueError {
    /// The setting's index.
    pub index: u8,
    /// The setting and what is wrong, for the user.
    pub message: String,
}

impl fmt::Display for ValueError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

impl std::error::Error for ValueError {}

/// The settings of one or more settings files of an aircraft, read with `pprz-codegen`'s
/// parser and numbered as the generator numbers them: each index gets a name, bounds, a
/// unit and labels.
///
/// * Names: a setting is found by its variable (`var`), its short name, or its index.
///   A variable that appears several times names its first index (as the generator's
///   `index` module does). A short name shared by several variables is ambiguous and
///   refused, with the candidates; a variable always wins over a short name.
/// * Each setting also has a name unique in the table ([`SettingsTable::unique_name`]):
///   its variable, or `var@index` for the second and later occurrences of a variable.
/// * Values: a label of the setting's `values`, or a number in its display unit (the
///   `alt_unit` when the file gives one, with `alt_unit_coef`). The aircraft's value is
///   display / coefficient and the displayed value is value x coefficient, both computed
///   in `f64` and rounded to `f32` once, as the generator converts the bounds.
/// * Bounds: a value outside them (in the aircraft's units, where the aircraft checks
///   them), NaN, an infinity or an unknown label is refused, with the bounds in the
///   message (in the display unit, as the file writes them).
///
/// ```
/// use pprz_ground::settings::SettingsTable;
/// let table = SettingsTable::parse(&[("s.xml", r#"<settings><dl_settings>
///     <dl_setting var="gain" min="0" max="10"/>
///     <dl_setting var="ins.roll" shortname="roll" min="-90" max="90" unit="rad" alt_unit="deg"/>
///     <dl_setting var="ap_mode" min="0" max="2" values="KILL|NAV|HOME"/>
///     </dl_settings></settings>"#)]).unwrap();
/// assert_eq!(table.resolve("roll"), Ok(1));
/// assert_eq!(table.value(2, "HOME"), Ok(2.0));
/// assert_eq!(table.value(1, "90"), Ok(std::f32::consts::FRAC_PI_2));
/// let refused = table.value(0, "12").unwrap_err().to_string();
/// assert_eq!(refused, "setting gain (index 0): 12 is outside its bounds [0, 10]");
/// assert_eq!(table.show(2, 1.0), "NAV (1)");
/// ```
#[derive(Debug, Clone)]
pub struct SettingsTable {
    set: SettingsSet,
    /// The name of each index, unique in the table.
    unique: Vec<String>,
    /// Unique names and variables to indices (a variable to its first index).
    by_name: HashMap<String, u8>,
    /// Short names to their settings, the first one of each variable.
    by_short: HashMap<String, Vec<u8>>,
}

impl SettingsTable {
    /// Reads settings files, numbered in the order given, with the built-in unit
    /// conversions.
    ///
    /// # Errors
    /// Every problem of every file, each with file, line and column.
    pub fn load<P: AsRef<Path>>(paths: &[P]) -> Result<Self, pprz_codegen::Error> {
        SettingsSet::from_files(paths, &Units::builtin()).map(Self::from_set)
    }

    /// Parses settings texts (`(name, text)`), numbered in the order given.
    ///
    /// # Errors
    /// As [`load`](Self::load).
    pub fn parse(files: &[(&str, &str)]) -> Result<Self, pprz_codegen::Error> {
        SettingsSet::parse(files, &Units::builtin()).map(Self::from_set)
    }

    /// The table of a parsed set.
    pub fn from_set(set: SettingsSet) -> Self {
        let mut unique = Vec::with_capacity(set.settings.len());
        let mut by_name: HashMap<String, u8> = HashMap::new();
        let mut by_short: HashMap<String, Vec<u8>> = HashMap::new();
        for s in &set.settings {
            let name = if by_name.contains_key(&s.var) {
                format!("{}@{}", s.var, s.index)
            } else {
                s.var.clone()
            };
            by_name.entry(name.clone()).or_insert(s.index);
            unique.push(name);
        }
        for s in &set.settings {
            let Some(short) = &s.shortname else { continue };
            let list = by_short.entry(short.clone()).or_default();
            // One candidate per variable: its first setting with this short name.
            if !list
                .iter()
                .any(|&i| set.settings[usize::from(i)].var == s.var)
            {
                list.push(s.index);
            }
        }
        Self {
            set,
            unique,
            by_name,
            by_short,
        }
    }

    /// The settings as parsed.
    pub fn set(&self) -> &SettingsSet {
        &self.set
    }

    /// What the parser accepted with a warning.
    pub fn warnings(&self) -> &[Diagnostic] {
        &self.set.warnings
    }

    /// Number of settings.
    pub fn len(&self) -> usize {
        self.set.len()
    }

    /// Whether there are no settings.
    pub fn is_empty(&self) -> bool {
        self.set.is_empty()
    }

    /// The setting at `index`.
    pub fn get(&self, index: u8) -> Option<&SettingDef> {
        self.set.get(index)
    }

    /// The name of setting `index` unique in the table: its variable, or `var@index`
    /// for a later occurrence of a variable.
    pub fn unique_name(&self, index: u8) -> Option<&str> {
        self.unique.get(usize::from(index)).map(String::as_str)
    }

    /// The index a unique name (or a variable) names, and nothing else.
    pub fn by_unique_name(&self, name: &str) -> Option<u8> {
        self.by_name.get(name).copied()
    }

    /// The index `name` names: an index (digits), a variable (its first index), a
    /// unique name, or a short name of one variable (its first setting with that short
    /// name).
    ///
    /// # Errors
    /// [`NameError`]: unknown, beyond the table, or a short name of several variables
    /// (the candidates listed).
    pub fn resolve(&self, name: &str) -> Result<u8, NameError> {
        let count = self.len();
        if !name.is_empty() && name.bytes().all(|b| b.is_ascii_digit()) {
            return match name.parse::<u8>() {
                Ok(index) if usize::from(index) < count => Ok(index),
                Ok(index) => Err(NameError::NoSuchIndex { index, count }),
                Err(_) => Err(NameError::Unknown {
                    name: name.to_owned(),
                    count,
                }),
            };
        }
        if let Some(&index) = self.by_name.get(name) {
            return Ok(index);
        }
        match self.by_short.get(name).map(Vec::as_slice) {
            Some([index]) => Ok(*index),
            Some(several) => Err(NameError::Ambiguous {
                name: name.to_owned(),
                candidates: several
                    .iter()
                    .filter_map(|&i| Some((self.get(i)?.var.clone(), i)))
                    .collect(),
            }),
            None => Err(NameError::Unknown {
                name: name.to_owned(),
                count,
            }),
        }
    }

    /// `name (index N)` of setting `index`, for messages.
    pub fn describe(&self, index: u8) -> String {
        match self.get(index) {
            Some(s) => format!("{} (index {index})", text(s.name())),
            None => format!("index {index}"),
        }
    }

    /// The aircraft's value of setting `index` for `text`: a label of the setting, or a
    /// number in its display unit; checked against its bounds.
    ///
    /// # Errors
    /// [`ValueError`] (with the bounds): no such setting, an unknown label, NaN, an
    /// infinity, or a value outside the bounds.
    pub fn value(&self, index: u8, text: &str) -> Result<f32, ValueError> {
        let s = self.def(index)?;
        let text = text.trim();
        if let Some(v) = label_value(s, text) {
            return self.check(index, v);
        }
        let Ok(display) = text.parse::<f64>() else {
            let what = if s.values.is_empty() {
                "is not a number".to_owned()
            } else {
                format!("is neither a number nor a label ({})", s.values.join("|"))
            };
            return Err(self.refusal(s, &format!("`{}` {what}", self::text(text))));
        };
        self.display_value(index, display)
    }

    /// The aircraft's value of setting `index` for a number in its display unit,
    /// checked against its bounds.
    ///
    /// # Errors
    /// [`ValueError`] (with the bounds): no such setting, NaN, an infinity, or a value
    /// outside the bounds.
    pub fn display_value(&self, index: u8, display: f64) -> Result<f32, ValueError> {
        let s = self.def(index)?;
        if !display.is_finite() {
            return Err(self.refusal(s, &format!("{display} is not a finite number")));
        }
        let v = from_display(s, display);
        if v.is_finite() && v >= s.min && v <= s.max {
            Ok(v)
        } else {
            let unit = display_unit(s).map_or_else(String::new, |u| format!(" {}", text(u)));
            Err(self.refusal(s, &format!("{display}{unit} is outside its bounds")))
        }
    }

    /// `value` (in the aircraft's units) if setting `index` accepts it.
    ///
    /// # Errors
    /// [`ValueError`] (with the bounds): no such setting, NaN, an infinity, or a value
    /// outside the bounds.
    pub fn check(&self, index: u8, value: f32) -> Result<f32, ValueError> {
        let s = self.def(index)?;
        if !value.is_finite() {
            return Err(self.refusal(s, &format!("{value} is not a finite number")));
        }
        if value >= s.min && value <= s.max {
            return Ok(value);
        }
        let shown = self.show(index, f64::from(value));
        Err(self.refusal(s, &format!("{shown} is outside its bounds")))
    }

    /// The setting at `index`, or the error naming the index.
    fn def(&self, index: u8) -> Result<&SettingDef, ValueError> {
        self.get(index).ok_or_else(|| ValueError {
            index,
            message: NameError::NoSuchIndex {
                index,
                count: self.len(),
            }
            .to_string(),
        })
    }

    /// A refusal of a value for `s`: `setting NAME (index N): WHY [min, max] unit`.
    fn refusal(&self, s: &SettingDef, why: &str) -> ValueError {
        let bounds = bounds_text(s);
        let message = if why.ends_with("its bounds") {
            format!("setting {}: {why} {bounds}", self.describe(s.index))
        } else {
            format!(
                "setting {}: {why} (bounds {bounds})",
                self.describe(s.index)
            )
        };
        ValueError {
            index: s.index,
            message,
        }
    }

    /// The value of setting `index` as shown: its label and number when it has one
    /// (`NAV (13)`), else the number in the display unit with the unit (`45 deg`).
    pub fn show(&self, index: u8, value: f64) -> String {
        let Some(s) = self.get(index) else {
            return number(value as f32);
        };
        if let Some(label) = label_of(s, value) {
            return format!("{} ({})", text(label), number(value as f32));
        }
        let shown = number(to_display(s, value));
        match display_unit(s) {
            Some(unit) => format!("{shown} {}", text(unit)),
            None => shown,
        }
    }

    /// The bounds of setting `index` in its display unit, as the file writes them:
    /// `[min, max] unit`.
    pub fn bounds(&self, index: u8) -> Option<String> {
        self.get(index).map(bounds_text)
    }

    /// The display value of setting `index` for the aircraft's `value` (value x
    /// coefficient, in `f64`, rounded to `f32` once); `value` itself for an unknown index.
    pub fn to_display(&self, index: u8, value: f64) -> f64 {
        match self.get(index) {
            Some(s) => f64::from(to_display(s, value)),
            None => value,
        }
    }
}

/// The unit values are shown in: `alt_unit`, else `unit`.
pub fn display_unit(s: &SettingDef) -> Option<&str> {
    s.alt_unit.as_deref().or(s.unit.as_deref())
}

/// The displayed value of the aircraft's `value`: value x coefficient, in `f64`, rounded
/// to `f32` once.
pub fn to_display(s: &SettingDef, value: f64) -> f32 {
    (value * s.alt_unit_coef) as f32
}

/// The aircraft's value of a `display` value: display / coefficient, in `f64`, rounded
/// to `f32` once (as the generator converts the bounds).
pub fn from_display(s: &SettingDef, display: f64) -> f32 {
    (display / s.alt_unit_coef) as f32
}

/// `[min, max] unit` as the file writes them.
fn bounds_text(s: &SettingDef) -> String {
    let (lo, hi) = (s.written_min, s.written_max);
    match display_unit(s) {
        Some(unit) => format!("[{lo}, {hi}] {}", text(unit)),
        None => format!("[{lo}, {hi}]"),
    }
}

/// The label of `value`: labels name `min`, `min + 1`, ... in the aircraft's units (as
/// [`SettingDesc::label`](pprz_messages::settings::SettingDesc::label) does).
fn label_of(s: &SettingDef, value: f64) -> Option<&str> {
    let offset = value - f64::from(s.min);
    if !(0.0..=f64::from(u16::MAX)).contains(&offset) || offset.fract() != 0.0 {
        return None;
    }
    s.values.get(offset as usize).map(String::as_str)
}

/// The value of label `text`: an exact label, else the one label equal to it without
/// regard to case.
fn label_value(s: &SettingDef, text: &str) -> Option<f32> {
    let at = s.values.iter().position(|l| l == text).or_else(|| {
        let mut same = s
            .values
            .iter()
            .enumerate()
            .filter(|(_, l)| l.eq_ignore_ascii_case(text));
        match (same.next(), same.next()) {
            (Some((i, _)), None) => Some(i),
            _ => None,
        }
    })?;
    Some((f64::from(s.min) + at as f64) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    const FILE: &str = r#"<settings><dl_settings>
      <dl_settings name="vert">
        <dl_setting var="guidance_v_kp" shortname="kp" min="0" max="600"/>
        <dl_setting var="flight_altitude" shortname="alt" min="0" max="1000" unit="m"/>
      </dl_settings>
      <dl_settings name="horiz">
        <dl_setting var="guidance_h_kp" shortname="kp" min="0" max="400"/>
        <dl_setting var="ins.roll" shortname="roll" min="-90" max="90" unit="rad" alt_unit="deg"/>
        <dl_setting var="pos_z" min="-10" max="10" unit="1/2^8m" alt_unit="m" alt_unit_coef="0.00390625"/>
        <dl_setting var="ap_mode" min="0" max="19" values="KILL|FAILSAFE|HOME|RATE_DIRECT|ATTITUDE_DIRECT|RATE_RC_CLIMB|ATTITUDE_RC_CLIMB|ATTITUDE_CLIMB|RATE_Z_HOLD|ATTITUDE_Z_HOLD|HOVER_DIRECT|HOVER_CLIMB|HOVER_Z_HOLD|NAV|RC_DIRECT|CARE_FREE|FORWARD|MODULE|FLIP|GUIDED"/>
        <dl_setting var="flight_altitude" shortname="alt2" min="0" max="500" unit="m"/>
        <dl_setting var="alt" shortname="kp" min="0" max="1"/>
      </dl_settings>
    </dl_settings></settings>"#;

    fn table() -> SettingsTable {
        SettingsTable::parse(&[("t.xml", FILE)]).unwrap()
    }

    #[test]
    fn names_resolve_by_var_short_name_and_index() {
        let t = table();
        assert_eq!(t.resolve("guidance_v_kp"), Ok(0));
        assert_eq!(t.resolve("roll"), Ok(3));
        assert_eq!(t.resolve("ins.roll"), Ok(3));
        assert_eq!(t.resolve("5"), Ok(5));
        // A repeated variable names its first index; its later one has a unique name.
        assert_eq!(t.resolve("flight_altitude"), Ok(1));
        assert_eq!(t.unique_name(6), Some("flight_altitude@6"));
        assert_eq!(t.resolve("flight_altitude@6"), Ok(6));
        assert_eq!(
            t.resolve("alt2"),
            Ok(6),
            "a short name names its own setting"
        );
        // A var wins over a short name: `alt` is a var and the short name of another.
        assert_eq!(t.resolve("alt"), Ok(7));
        let e = t.resolve("kp").unwrap_err();
        assert_eq!(
            e.to_string(),
            "the short name `kp` is ambiguous: guidance_v_kp (index 0), guidance_h_kp (index 2), alt (index 7); give the var"
        );
        assert!(matches!(
            t.resolve("8"),
            Err(NameError::NoSuchIndex { index: 8, count: 8 })
        ));
        assert!(matches!(t.resolve("300"), Err(NameError::Unknown { .. })));
        let e = t.resolve("nope").unwrap_err().to_string();
        assert!(e.contains("no setting is named `nope`"), "{e}");
        assert!(e.contains("0 to 7"), "{e}");
    }

    #[test]
    fn labels_both_ways() {
        let t = table();
        assert_eq!(t.value(5, "NAV"), Ok(13.0));
        assert_eq!(
            t.value(5, "home"),
            Ok(2.0),
            "one label without regard to case"
        );
        assert_eq!(t.value(5, "13"), Ok(13.0), "a number still works");
        assert_eq!(t.show(5, 13.0), "NAV (13)");
        assert_eq!(t.show(5, 2.0), "HOME (2)");
        assert_eq!(t.show(5, 2.5), "2.5", "no label between two");
        let e = t.value(5, "WARP").unwrap_err().to_string();
        assert!(e.starts_with("setting ap_mode (index 5): `WARP` is neither a number nor a label (KILL|FAILSAFE|HOME|"), "{e}");
        assert!(e.ends_with("(bounds [0, 19])"), "{e}");
    }

    #[test]
    fn alt_units_both_ways_with_one_rounding() {
        let t = table();
        // Degrees on the ground, radians aboard.
        let v = t.value(3, "45").unwrap();
        assert_eq!(v, (45.0f64 / (180.0 / std::f64::consts::PI)) as f32);
        assert_eq!(t.value(3, "90"), Ok(std::f32::consts::FRAC_PI_2));
        assert_eq!(t.show(3, f64::from(std::f32::consts::FRAC_PI_2)), "90 deg");
        assert_eq!(t.bounds(3).unwrap(), "[-90, 90] deg");
        // The bound as written converts to the bound aboard: accepted.
        assert_eq!(t.value(3, "-90"), Ok(-std::f32::consts::FRAC_PI_2));
        let e = t.value(3, "90.001").unwrap_err().to_string();
        assert_eq!(
            e,
            "setting roll (index 3): 90.001 deg is outside its bounds [-90, 90] deg"
        );
        // A fixed-point value: 1/2^8 m aboard.
        assert_eq!(t.value(4, "1.5"), Ok(384.0));
        assert_eq!(t.show(4, 384.0), "1.5 m");
        assert_eq!(t.to_display(4, 384.0), 1.5);
        // f64 then one rounding: 0.1 m is 25.6 aboard, not 25.600000381...
        assert_eq!(t.value(4, "0.1"), Ok(25.6f32));
        assert_eq!(t.show(4, f64::from(25.6f32)), "0.1 m");
    }

    #[test]
    fn nan_infinities_and_out_of_bounds_are_refused_with_the_bounds() {
        let t = table();
        for bad in ["NaN", "inf", "-inf", "1e300", "601", "-1"] {
            let e = t.value(0, bad).unwrap_err();
            assert!(e.message.contains("[0, 600]"), "{bad}: {e}");
            assert_eq!(e.index, 0);
        }
        assert_eq!(t.value(0, "600"), Ok(600.0));
        assert_eq!(t.value(0, " 2.5 "), Ok(2.5));
        assert!(
            t.value(0, "x")
                .unwrap_err()
                .message
                .contains("`x` is not a number")
        );
        assert!(t.check(1, f32::NAN).is_err());
        let e = t.check(1, 1200.0).unwrap_err().to_string();
        assert_eq!(
            e,
            "setting alt (index 1): 1200 m is outside its bounds [0, 1000] m"
        );
        let e = t.value(9, "1").unwrap_err().to_string();
        assert!(e.contains("no setting has index 9"), "{e}");
    }

    #[test]
    fn control_characters_in_names_are_escaped() {
        let t = SettingsTable::parse(&[(
            "e.xml",
            r#"<settings><dl_settings><dl_setting var="a" shortname="x&#10;&#x202E;y" min="0" max="1"/></dl_settings></settings>"#,
        )])
        .unwrap();
        let d = t.describe(0);
        assert!(!d.chars().any(crate::escape::is_unsafe), "{d:?}");
        assert!(!d.contains('\n'));
    }
}
