//! Reading one settings file: its groups, flattened in document order, and each
//! `<dl_setting>` checked on its own (the checks across settings and files are in
//! [`super::check`]).

use roxmltree::{Children, Node};

use pprz_messages::settings::SettingType;

use super::{MAX_GROUP_DEPTH, MAX_REPORTED, MAX_SETTINGS, SettingDef};
use crate::error::{Diagnostic, ErrorKind, SettingProblem};
use crate::model::Units;
use crate::names;
use crate::xml::{Ctx, Parser};

/// Attributes of `<settings>`.
const SETTINGS_ATTRS: &[&str] = &["target"];
/// Attributes of `<dl_settings>`.
const GROUP_ATTRS: &[&str] = &["name"];
/// Attributes of `<dl_setting>`: those read, then those known and not used (`widget`
/// and `header` of the DTD and newer Paparazzi, `auto` of the GCS).
const SETTING_ATTRS: &[&str] = &[
    "var",
    "min",
    "max",
    "step",
    "shortname",
    "type",
    "values",
    "unit",
    "alt_unit",
    "alt_unit_coef",
    "persistent",
    "handler",
    "module",
    "param",
    "widget",
    "header",
    "auto",
];

/// What one file holds.
#[derive(Debug, Default)]
pub(super) struct FileRead {
    /// The `target` attribute of `<settings>`.
    pub(super) target: Option<String>,
    /// Its settings in document order (not numbered yet).
    pub(super) settings: Vec<SettingDef>,
    /// What was accepted with a warning.
    pub(super) warnings: Vec<Diagnostic>,
}

/// Whether `node` is an element with tag `tag`, without regard to case (as Paparazzi
/// compares tags).
fn tag_is(node: Node<'_, '_>, tag: &str) -> bool {
    node.is_element() && node.tag_name().name().eq_ignore_ascii_case(tag)
}

/// The attributes of an element, looked up without regard to case.
#[derive(Default)]
struct Attrs<'n> {
    /// (name in lower case, value, offset of the attribute).
    found: Vec<(&'static str, &'n str, usize)>,
}

impl<'n> Attrs<'n> {
    /// The trimmed value of attribute `name` (lower case) and its offset.
    fn get(&self, name: &str) -> Option<(&'n str, usize)> {
        self.found
            .iter()
            .find(|(n, _, _)| *n == name)
            .map(|&(_, v, at)| (v.trim(), at))
    }

    /// The trimmed value of attribute `name`, if given and not empty.
    fn text(&self, name: &str) -> Option<String> {
        self.get(name)
            .map(|(v, _)| v)
            .filter(|v| !v.is_empty())
            .map(str::to_owned)
    }
}

/// Reads one settings file, recording its problems in `p`.
pub(super) fn file(p: &mut Parser<'_, '_>, units: &Units) -> FileRead {
    let mut r = Reader {
        p,
        units,
        read: FileRead::default(),
        too_deep: false,
        errors: 0,
        untold: [0, 0],
    };
    r.missing_spaces();
    r.root();
    r.finish()
}

impl Reader<'_, '_, '_> {
    /// Reads the root element and its groups.
    fn root(&mut self) {
        let root = self.p.document().root_element();
        if !tag_is(root, "settings") {
            self.p
                .unexpected(root, &Ctx::default(), "<settings> as the root element");
            return;
        }
        let attrs = self.attributes(root, "settings", SETTINGS_ATTRS);
        self.read.target = attrs.and_then(|a| a.text("target"));
        let mut groups = 0;
        for child in root.children().filter(Node::is_element) {
            if tag_is(child, "dl_settings") {
                groups += 1;
                if groups == 2 {
                    self.warn(child, None, SettingProblem::SecondTopLevelGroup);
                }
                self.groups(child);
            } else if tag_is(child, "dl_setting") {
                let reason = "directly under <settings> (Paparazzi reads settings inside <dl_settings> only)";
                self.ignore(child, reason);
            } else if !tag_is(child, "rc_settings") {
                self.ignore(child, "is not a settings element");
            }
        }
    }

    /// What was read, with a count of the problems and warnings not reported.
    fn finish(mut self) -> FileRead {
        let [errors, warnings] = self.untold;
        for (count, what) in [(errors, "errors"), (warnings, "warnings")] {
            if count == 0 {
                continue;
            }
            let d = Diagnostic {
                file: self.p.file().to_owned(),
                line: 0,
                column: 0,
                message: None,
                field: None,
                kind: setting(None, SettingProblem::Untold { count, what }),
            };
            if what == "errors" {
                self.p.push(d);
            } else {
                self.read.warnings.push(d);
            }
        }
        self.read
    }
}

/// The state of reading one file.
struct Reader<'r, 'a, 'input> {
    p: &'r mut Parser<'a, 'input>,
    units: &'r Units,
    read: FileRead,
    /// Whether groups nested too deep were reported (once per file).
    too_deep: bool,
    /// Problems reported.
    errors: usize,
    /// Problems and warnings not reported (beyond [`MAX_REPORTED`]).
    untold: [usize; 2],
}

impl<'a, 'input> Reader<'_, 'a, 'input> {
    /// Records a warning at `node`.
    fn warn(&mut self, node: Node<'_, '_>, var: Option<&str>, problem: SettingProblem) {
        self.warn_at(node.range().start, var, problem);
    }

    /// Records a warning at byte offset `pos` of the parsed text.
    fn warn_at(&mut self, pos: usize, var: Option<&str>, problem: SettingProblem) {
        if self.read.warnings.len() >= MAX_REPORTED {
            self.untold[1] += 1;
            return;
        }
        let d = self
            .p
            .diagnostic_at(pos, &Ctx::default(), setting(var, problem));
        self.read.warnings.push(d);
    }

    /// Records a problem at byte offset `pos` of the parsed text.
    fn error_at(&mut self, pos: usize, kind: ErrorKind) {
        if self.errors >= MAX_REPORTED {
            self.untold[0] += 1;
            return;
        }
        self.errors += 1;
        let d = self.p.diagnostic_at(pos, &Ctx::default(), kind);
        self.p.push(d);
    }

    /// Warns that element `node` is not read, for `reason`.
    fn ignore(&mut self, node: Node<'_, '_>, reason: &'static str) {
        let element = node.tag_name().name().to_owned();
        self.warn(
            node,
            None,
            SettingProblem::IgnoredElement { element, reason },
        );
    }

    /// Warns about each space the repair inserted, at the attribute after it.
    fn missing_spaces(&mut self) {
        let text = self.p.document().input_text();
        for k in 0..self.p.inserted().len() {
            let name_at = self.p.inserted()[k] + 1;
            let name: String = text[name_at..]
                .chars()
                .take_while(|&c| c != '=' && !c.is_whitespace() && c != '>' && c != '/')
                .take(64)
                .collect();
            let problem = SettingProblem::MissingSpace { attribute: name };
            self.warn_at(name_at, None, problem);
        }
    }

    /// The attributes of `node` (an `element`) among `known`, looked up without regard
    /// to case; warns about the others. `None` (reported) if an attribute is given in
    /// two spellings.
    fn attributes<'n>(
        &mut self,
        node: Node<'n, '_>,
        element: &'static str,
        known: &[&'static str],
    ) -> Option<Attrs<'n>> {
        let mut attrs = Attrs::default();
        let mut spelled: Vec<&str> = Vec::new();
        let mut ok = true;
        for a in node.attributes() {
            let name = a.name();
            let at = a.range().start;
            let Some(&canonical) = known.iter().find(|k| k.eq_ignore_ascii_case(name)) else {
                let attribute = name.to_owned();
                self.warn_at(
                    at,
                    None,
                    SettingProblem::UnknownAttribute { element, attribute },
                );
                continue;
            };
            if let Some(i) = attrs.found.iter().position(|f| f.0 == canonical) {
                let problem = SettingProblem::DuplicateAttribute {
                    attribute: canonical,
                    first: spelled[i].to_owned(),
                    second: name.to_owned(),
                };
                self.error_at(at, setting(None, problem));
                ok = false;
                continue;
            }
            attrs.found.push((canonical, a.value(), at));
            spelled.push(name);
        }
        ok.then_some(attrs)
    }

    /// Reads the group `top` and the groups in it, iteratively (an explicit stack of at
    /// most [`MAX_GROUP_DEPTH`] groups), numbering settings in document order.
    fn groups(&mut self, top: Node<'a, 'input>) {
        let mut stack: Vec<(Children<'a, 'input>, bool)> = Vec::new();
        let mut path: Vec<String> = Vec::new();
        self.enter(top, &mut stack, &mut path);
        while let Some((children, _)) = stack.last_mut() {
            let Some(child) = children.next() else {
                if let Some((_, true)) = stack.pop() {
                    path.pop();
                }
                continue;
            };
            if !child.is_element() {
                continue;
            }
            if tag_is(child, "dl_setting") {
                // One more than the most the set holds shows there are too many.
                if self.read.settings.len() > MAX_SETTINGS {
                    continue;
                }
                if let Some(s) = self.setting(child, &path) {
                    self.read.settings.push(s);
                }
            } else if tag_is(child, "dl_settings") {
                if stack.len() < MAX_GROUP_DEPTH {
                    self.enter(child, &mut stack, &mut path);
                } else if !self.too_deep {
                    self.too_deep = true;
                    let kind = setting(
                        None,
                        SettingProblem::TooDeep {
                            max: MAX_GROUP_DEPTH,
                        },
                    );
                    self.error_at(child.range().start, kind);
                }
            } else {
                self.ignore(child, "is not a settings element");
            }
        }
    }

    /// Starts reading group `node`: its name joins `path`, its children `stack`.
    fn enter(
        &mut self,
        node: Node<'a, 'input>,
        stack: &mut Vec<(Children<'a, 'input>, bool)>,
        path: &mut Vec<String>,
    ) {
        let name = self
            .attributes(node, "dl_settings", GROUP_ATTRS)
            .and_then(|a| a.text("name"));
        let (mut settings, mut groups) = (false, false);
        for child in node.children() {
            settings |= tag_is(child, "dl_setting");
            groups |= tag_is(child, "dl_settings");
        }
        if settings && groups {
            self.warn(node, None, SettingProblem::MixedGroup);
        }
        let named = name.is_some();
        path.extend(name);
        stack.push((node.children(), named));
    }

    /// A `<dl_setting>` in the group `path`; `None` (reported) if it is unusable.
    fn setting(&mut self, node: Node<'_, '_>, path: &[String]) -> Option<SettingDef> {
        for child in node.children().filter(Node::is_element) {
            if !tag_is(child, "strip_button") && !tag_is(child, "key_press") {
                self.ignore(
                    child,
                    "inside a <dl_setting> (only <strip_button> and <key_press> are known there)",
                );
            }
        }
        let attrs = self.attributes(node, "dl_setting", SETTING_ATTRS)?;
        let var = self.var(node, &attrs)?;
        let bounds = self.bounds(node, &attrs, &var);
        let persistent = self.persistent(&attrs, &var);
        let (ty, type_name) = self.setting_type(&attrs, &var, persistent);
        let values: Vec<String> = match attrs.get("values") {
            Some((v, _)) if !v.is_empty() => v.split('|').map(|l| l.trim().to_owned()).collect(),
            _ => Vec::new(),
        };
        let bounds = bounds?;
        self.check_labels(node, &var, &values, &bounds);
        let (line, column) = self.p.line_col(node);
        Some(SettingDef {
            index: 0,
            file: self.p.file().to_owned(),
            line,
            column,
            group: path.join("/"),
            rust_name: names::snake_case(&rust_words(&var)),
            var,
            shortname: attrs.text("shortname"),
            min: bounds.min as f32,
            max: bounds.max as f32,
            step: bounds.step as f32,
            written_min: bounds.written[0],
            written_max: bounds.written[1],
            written_step: bounds.written[2],
            ty,
            type_name,
            values,
            unit: attrs.text("unit"),
            alt_unit: attrs.text("alt_unit"),
            alt_unit_coef: bounds.coef,
            persistent,
            handler: attrs.text("handler"),
            module: attrs.text("module"),
            param: attrs.text("param"),
        })
    }

    /// The `var` of a setting; `None` (reported) if absent or making no Rust name.
    fn var(&mut self, node: Node<'_, '_>, attrs: &Attrs<'_>) -> Option<String> {
        let Some((var, at)) = attrs.get("var") else {
            let kind = ErrorKind::MissingAttribute {
                element: "dl_setting",
                attribute: "var",
            };
            self.error_at(node.range().start, kind);
            return None;
        };
        if let Some(reason) = names::snake_name_problem(&rust_words(var)) {
            let kind = ErrorKind::UnusableName {
                what: "setting variable",
                name: var.to_owned(),
                reason,
            };
            self.error_at(at, kind);
            return None;
        }
        Some(var.to_owned())
    }

    /// Whether the setting is persistent (the attribute is present, whatever its
    /// value, as in Paparazzi); warns about a value that reads as false.
    fn persistent(&mut self, attrs: &Attrs<'_>, var: &str) -> bool {
        let Some((value, at)) = attrs.get("persistent") else {
            return false;
        };
        if ["false", "0", "no", "off"]
            .iter()
            .any(|f| f.eq_ignore_ascii_case(value))
        {
            let problem = SettingProblem::PersistentFalse {
                value: value.to_owned(),
            };
            self.warn_at(at, Some(var), problem);
        }
        true
    }

    /// The setting's type (float when absent) and its name as written; another type is
    /// read as the nearest (warning), or refused for a persistent setting.
    fn setting_type(
        &mut self,
        attrs: &Attrs<'_>,
        var: &str,
        persistent: bool,
    ) -> (SettingType, Option<String>) {
        let Some((name, at)) = attrs.get("type") else {
            return (SettingType::Float, None);
        };
        let (ty, exact) = match name {
            "bool" => (SettingType::Bool, true),
            "int8" => (SettingType::I8, true),
            "int16" => (SettingType::I16, true),
            "int32" => (SettingType::I32, true),
            "uint8" => (SettingType::U8, true),
            "uint16" => (SettingType::U16, true),
            "uint32" => (SettingType::U32, true),
            "float" => (SettingType::Float, true),
            "int64" => (SettingType::I32, false),
            "uint64" => (SettingType::U32, false),
            _ => (SettingType::Float, false),
        };
        if !exact {
            let ty_name = name.to_owned();
            if persistent {
                let problem = SettingProblem::PersistentType { ty: ty_name };
                self.error_at(at, setting(Some(var), problem));
            } else {
                let mapped = ty.name();
                let problem = SettingProblem::TypeMapped {
                    ty: ty_name,
                    mapped,
                };
                self.warn_at(at, Some(var), problem);
            }
        }
        (ty, Some(name.to_owned()))
    }

    /// Warns if the number of labels is not `max - min + 1` (in the aircraft's units,
    /// where [`SettingDesc::label`](pprz_messages::settings::SettingDesc::label) counts).
    fn check_labels(&mut self, node: Node<'_, '_>, var: &str, labels: &[String], b: &Bounds) {
        if labels.is_empty() {
            return;
        }
        let values = f64::from(b.max as f32) - f64::from(b.min as f32) + 1.0;
        if values != labels.len() as f64 {
            let problem = SettingProblem::LabelCount {
                labels: labels.len(),
                values: values.to_string(),
            };
            let at = node
                .attributes()
                .find(|a| a.name().eq_ignore_ascii_case("values"))
                .map_or(node.range().start, |a| a.range().start);
            self.warn_at(at, Some(var), problem);
        }
    }
}

/// A [`ErrorKind::Setting`] about `var`.
pub(super) fn setting(var: Option<&str>, problem: SettingProblem) -> ErrorKind {
    ErrorKind::Setting {
        var: var.map(str::to_owned),
        problem,
    }
}

/// `var` with every character that cannot be in a Rust identifier made a word
/// separator (`stabilization_gains.p.x`, `a->b[0]`), for [`names::snake_case`].
pub(super) fn rust_words(var: &str) -> String {
    var.chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

/// A setting's bounds in the aircraft's units, and as written.
pub(super) struct Bounds {
    /// Smallest value (aircraft units), a finite `f32`.
    pub(super) min: f64,
    /// Largest value (aircraft units), a finite `f32`.
    pub(super) max: f64,
    /// Step (aircraft units), a finite `f32` above 0.
    pub(super) step: f64,
    /// `min`, `max` and `step` as written (display units).
    pub(super) written: [f64; 3],
    /// Display value = value x this.
    pub(super) coef: f64,
}

impl Reader<'_, '_, '_> {
    /// A number attribute as written: finite and a finite `f32`, above 0 if
    /// `positive`; `None` (reported) otherwise.
    fn number(
        &mut self,
        (value, at): (&str, usize),
        attribute: &'static str,
        positive: bool,
    ) -> Option<f64> {
        match value.parse::<f64>() {
            Ok(x) if fits_f32(x) && (!positive || (x as f32) > 0.0) => Some(x),
            _ => {
                let expected = if positive {
                    "a finite number above 0 that fits an f32"
                } else {
                    "a finite number that fits an f32"
                };
                let kind = ErrorKind::InvalidNumber {
                    attribute,
                    value: value.to_owned(),
                    expected,
                };
                self.error_at(at, kind);
                None
            }
        }
    }

    /// A required number attribute; `None` (reported) if absent or invalid.
    fn required(
        &mut self,
        node: Node<'_, '_>,
        attrs: &Attrs<'_>,
        attribute: &'static str,
    ) -> Option<f64> {
        match attrs.get(attribute) {
            Some(v) => self.number(v, attribute, false),
            None => {
                let kind = ErrorKind::MissingAttribute {
                    element: "dl_setting",
                    attribute,
                };
                self.error_at(node.range().start, kind);
                None
            }
        }
    }

    /// The bounds and step of a setting, converted to the aircraft's units (see the
    /// [module docs](super)); `None` (reported) if one is missing or invalid.
    fn bounds(&mut self, node: Node<'_, '_>, attrs: &Attrs<'_>, var: &str) -> Option<Bounds> {
        let min = self.required(node, attrs, "min");
        let max = self.required(node, attrs, "max");
        let step = match attrs.get("step") {
            Some(v) => self.number(v, "step", true),
            None => Some(1.0),
        };
        let coef = self.coefficient(node, attrs, var);
        let (min, max, step, coef) = (min?, max?, step?, coef?);
        if min > max {
            let problem = SettingProblem::MinAboveMax {
                min: attrs
                    .get("min")
                    .map_or_else(String::new, |v| v.0.to_owned()),
                max: attrs
                    .get("max")
                    .map_or_else(String::new, |v| v.0.to_owned()),
            };
            self.error_at(node.range().start, setting(Some(var), problem));
            return None;
        }
        let (lo, hi) = if coef < 0.0 { (max, min) } else { (min, max) };
        let mut converted = [lo / coef, hi / coef, step / coef.abs()];
        let mut ok = true;
        for (x, (attribute, written)) in converted.iter_mut().zip([
            (if coef < 0.0 { "max" } else { "min" }, lo),
            (if coef < 0.0 { "min" } else { "max" }, hi),
            ("step", step),
        ]) {
            // A step that rounds to 0 is as unusable as an infinite bound.
            let bad = !fits_f32(*x) || (attribute == "step" && (*x as f32) <= 0.0);
            if bad {
                let problem = SettingProblem::ConvertedOutOfRange {
                    attribute,
                    value: attrs
                        .get(attribute)
                        .map_or_else(|| written.to_string(), |v| v.0.to_owned()),
                    coef: attrs
                        .get("alt_unit_coef")
                        .map_or_else(|| coef.to_string(), |v| v.0.to_owned()),
                };
                self.error_at(node.range().start, setting(Some(var), problem));
                ok = false;
            }
        }
        ok.then_some(Bounds {
            min: converted[0],
            max: converted[1],
            step: converted[2],
            written: [min, max, step],
            coef,
        })
    }

    /// The display coefficient: `alt_unit_coef`, else the conversion from `unit` to
    /// `alt_unit` (warning when unknown: 1), else 1; `None` (reported) if invalid.
    fn coefficient(&mut self, node: Node<'_, '_>, attrs: &Attrs<'_>, var: &str) -> Option<f64> {
        if let Some((value, at)) = attrs.get("alt_unit_coef") {
            return match value.parse::<f64>() {
                Ok(x) if fits_f32(x) && x != 0.0 && (x as f32) != 0.0 => Some(x),
                _ => {
                    let kind = ErrorKind::InvalidNumber {
                        attribute: "alt_unit_coef",
                        value: value.to_owned(),
                        expected: "a finite number other than 0 that fits an f32",
                    };
                    self.error_at(at, kind);
                    None
                }
            };
        }
        let Some(alt_unit) = attrs.text("alt_unit") else {
            return Some(1.0);
        };
        let unit = attrs.text("unit");
        match &unit {
            Some(unit) if *unit == alt_unit => return Some(1.0),
            Some(unit) => {
                if let Some(coef) = self.units.coef(unit, &alt_unit) {
                    return Some(coef);
                }
            }
            None => {}
        }
        let at = attrs.get("alt_unit").map_or(node.range().start, |v| v.1);
        self.warn_at(
            at,
            Some(var),
            SettingProblem::UnknownConversion { unit, alt_unit },
        );
        Some(1.0)
    }
}

/// Whether `x` is finite and stays finite as an `f32`.
fn fits_f32(x: f64) -> bool {
    x.is_finite() && (x as f32).is_finite()
}
