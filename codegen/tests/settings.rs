//! Settings files (`settings.xml`): numbering, what is read, refused and warned about,
//! bounds in the aircraft's units, hostile inputs, and the real Paparazzi files.
//!
//! The real files are compatibility data kept outside the project (their licence
//! differs): they are found in `$PPRZ_SETTINGS_DIR`, by default `shared/paparazzi/settings`
//! next to the workspace directory; without them those tests are skipped with a printed
//! reason (a failure when `PPRZ_REQUIRE_REFERENCE` is set). Every other test file here is
//! written for these tests.

use std::path::{Path, PathBuf};

use pprz_codegen::limits::{MAX_ATTRIBUTES, MAX_ENTITY_EXPANSION, MAX_INPUT_BYTES, MAX_NODES};
use pprz_codegen::settings::{MAX_GROUP_DEPTH, MAX_SETTINGS};
use pprz_codegen::{Diagnostic, ErrorKind, Generator, SettingProblem, SettingsSet, Units};
use pprz_messages::settings::{SettingType, fnv1a};
use pprz_test_support::reference;

// ----------------------------------------------------------------------------------------
// Helpers

fn parse(files: &[(&str, &str)]) -> Result<SettingsSet, pprz_codegen::Error> {
    SettingsSet::parse(files, &Units::builtin())
}

/// A file whose `<dl_settings>` holds `body` (from line 3).
fn file(body: &str) -> String {
    format!("<settings>\n<dl_settings>\n{body}\n</dl_settings>\n</settings>\n")
}

/// The settings of `body` (see [`file`]); panics on an error.
fn ok(body: &str) -> SettingsSet {
    parse(&[("t.xml", &file(body))]).unwrap_or_else(|e| panic!("{e}"))
}

/// The diagnostics of `body` (see [`file`]), which must be refused.
fn refused(body: &str) -> Vec<Diagnostic> {
    refused_text(&file(body))
}

/// The diagnostics of `text`, which must be refused.
fn refused_text(text: &str) -> Vec<Diagnostic> {
    match parse(&[("t.xml", text)]) {
        Ok(set) => panic!("accepted: {set:?}"),
        Err(e) => e.diagnostics().to_vec(),
    }
}

/// The setting problem of a diagnostic.
fn problem(d: &Diagnostic) -> &SettingProblem {
    match &d.kind {
        ErrorKind::Setting { problem, .. } => problem,
        other => panic!("not a setting problem: {other:?}"),
    }
}

/// `(line, column, text)` of diagnostics.
fn at(ds: &[Diagnostic]) -> Vec<(u32, u32, String)> {
    ds.iter()
        .map(|d| (d.line, d.column, d.kind.to_string()))
        .collect()
}

/// The variables of a set, in index order.
fn vars(set: &SettingsSet) -> Vec<&str> {
    set.settings.iter().map(|s| s.var.as_str()).collect()
}

// ----------------------------------------------------------------------------------------
// Numbering

#[test]
fn settings_are_numbered_in_document_order_across_groups_and_files() {
    let a = file(
        r#"<dl_settings name="A">
  <dl_setting var="a0" min="0" max="1"/>
  <dl_settings name="inner"><dl_setting var="a1" min="0" max="1"/></dl_settings>
  <dl_settings><dl_settings name="deep"><dl_setting var="a2" min="0" max="1"/></dl_settings></dl_settings>
</dl_settings>
<dl_settings name="B"><dl_setting var="b0" min="0" max="1"/></dl_settings>"#,
    );
    let b = file(r#"<dl_settings name="C"><dl_setting var="a0" min="0" max="5"/></dl_settings>"#);
    let set = parse(&[("a.xml", &a), ("b.xml", &b)]).unwrap();
    assert_eq!(vars(&set), ["a0", "a1", "a2", "b0", "a0"]);
    let indices: Vec<u8> = set.settings.iter().map(|s| s.index).collect();
    assert_eq!(indices, [0, 1, 2, 3, 4]);
    let groups: Vec<&str> = set.settings.iter().map(|s| s.group.as_str()).collect();
    assert_eq!(groups, ["A", "A/inner", "A/deep", "B", "C"]);
    assert_eq!(
        (
            set.files[1].name.as_str(),
            set.files[1].first,
            set.files[1].count
        ),
        ("b.xml", 4, 1)
    );
    assert_eq!(
        (set.settings[4].file.as_str(), set.settings[4].line),
        ("b.xml", 3)
    );
    // The same variable twice: one binding, two indices (Paparazzi allows it).
    let v = set.variables();
    assert_eq!(v.len(), 4);
    assert_eq!((v[0].var, v[0].indices.clone()), ("a0", vec![0, 4]));
    // The other order numbers the other way.
    let set = parse(&[("b.xml", &b), ("a.xml", &a)]).unwrap();
    assert_eq!(vars(&set), ["a0", "a0", "a1", "a2", "b0"]);
}

#[test]
fn at_most_256_settings() {
    let body = |n: usize| {
        (0..n)
            .map(|i| format!("<dl_setting var=\"v{i}\" min=\"0\" max=\"1\"/>\n"))
            .collect::<String>()
    };
    let set = ok(&body(MAX_SETTINGS));
    assert_eq!(set.get(255).unwrap().var, "v255");
    let ds = refused(&body(MAX_SETTINGS + 1));
    assert_eq!(ds.len(), 1);
    assert_eq!(
        problem(&ds[0]),
        &SettingProblem::TooManySettings { max: MAX_SETTINGS }
    );
    assert_eq!((ds[0].line, ds[0].column), (3 + 256, 1));
    assert_eq!(
        ds[0].to_string(),
        "t.xml:259:1: setting `v256`: more than 256 settings: a setting's index is one byte"
    );
    // Across files too.
    let half = file(&body(200));
    let ds = parse(&[("a.xml", &half), ("b.xml", &half)]).unwrap_err();
    assert_eq!(ds.diagnostics()[0].file, "b.xml");
    assert_eq!(ds.diagnostics()[0].line, 3 + 56);
}

// ----------------------------------------------------------------------------------------
// What is read

#[test]
fn attributes_are_read() {
    let set = ok(
        r#"<dl_setting var="nav.mode" min="0" max="2" step="1" shortname="Mode"
   type="uint8" values="A | B|C" unit="enum" handler="SetMode" module="nav/nav" param="NAV_MODE"
   widget="combo" header="nav" auto="x">
  <strip_button name="A" value="0"/><key_press key="a" value="0"/>
</dl_setting>"#,
    );
    let s = &set.settings[0];
    assert_eq!(
        (s.var.as_str(), s.rust_name.as_str()),
        ("nav.mode", "nav_mode")
    );
    assert_eq!(s.index_const(), "NAV_MODE");
    assert_eq!((s.min, s.max, s.step), (0.0, 2.0, 1.0));
    assert_eq!(s.shortname.as_deref(), Some("Mode"));
    assert_eq!(s.name(), "Mode");
    assert_eq!(
        (s.ty, s.type_name.as_deref()),
        (SettingType::U8, Some("uint8"))
    );
    assert_eq!(s.values, ["A", "B", "C"]);
    assert_eq!(s.unit.as_deref(), Some("enum"));
    assert_eq!(s.handler.as_deref(), Some("SetMode"));
    assert_eq!(s.module.as_deref(), Some("nav/nav"));
    assert_eq!(s.param.as_deref(), Some("NAV_MODE"));
    assert!(!s.persistent);
    assert_eq!((s.line, s.column), (3, 1));
    assert!(set.warnings.is_empty(), "{:?}", set.warnings);
}

#[test]
fn defaults_step_1_float_not_persistent() {
    let set = ok(r#"<dl_setting var="x" min="-1.5" max="2.5"/>"#);
    let s = &set.settings[0];
    assert_eq!((s.min, s.max, s.step), (-1.5, 2.5, 1.0));
    assert_eq!((s.ty, s.type_name.as_deref()), (SettingType::Float, None));
    assert_eq!(s.alt_unit_coef, 1.0);
    assert!(!s.persistent && s.values.is_empty() && s.shortname.is_none());
    assert!(set.warnings.is_empty());
}

#[test]
fn types_are_paparazzis_others_map_to_the_nearest() {
    let types = [
        ("bool", SettingType::Bool),
        ("int8", SettingType::I8),
        ("int16", SettingType::I16),
        ("int32", SettingType::I32),
        ("uint8", SettingType::U8),
        ("uint16", SettingType::U16),
        ("uint32", SettingType::U32),
        ("float", SettingType::Float),
    ];
    for (name, ty) in types {
        let set = ok(&format!(
            r#"<dl_setting var="x" min="0" max="1" type="{name}" persistent="true"/>"#
        ));
        assert_eq!(set.settings[0].ty, ty, "{name}");
        assert!(set.warnings.is_empty(), "{name}");
    }
    let mapped = [
        ("int64", SettingType::I32),
        ("uint64", SettingType::U32),
        ("double", SettingType::Float),
        ("fun", SettingType::Float),
        ("char", SettingType::Float),
    ];
    for (name, ty) in mapped {
        let set = ok(&format!(
            r#"<dl_setting var="x" min="0" max="1" type="{name}"/>"#
        ));
        assert_eq!(set.settings[0].ty, ty, "{name}");
        assert_eq!(
            problem(&set.warnings[0]),
            &SettingProblem::TypeMapped {
                ty: name.into(),
                mapped: ty.name()
            }
        );
        assert_eq!((set.warnings[0].line, set.warnings[0].column), (3, 37));
        // Persistent: refused, it could not be stored as declared.
        let ds = refused(&format!(
            r#"<dl_setting var="x" min="0" max="1" type="{name}" persistent="true"/>"#
        ));
        assert_eq!(
            problem(&ds[0]),
            &SettingProblem::PersistentType { ty: name.into() }
        );
        assert!(
            ds[0].to_string().starts_with(&format!(
                "t.xml:3:37: setting `x`: type `{name}` cannot be stored"
            )),
            "{}",
            ds[0]
        );
    }
}

#[test]
fn persistent_is_any_value_of_the_attribute() {
    let set = ok(r#"<dl_setting var="a" min="0" max="1" persistent="true"/>
<dl_setting var="b" min="0" max="1" persistent="false"/>
<dl_setting var="c" min="0" max="1" persistent="0"/>
<dl_setting var="d" min="0" max="1" persistent=""/>
<dl_setting var="e" min="0" max="1"/>"#);
    let flags: Vec<bool> = set.settings.iter().map(|s| s.persistent).collect();
    assert_eq!(flags, [true, true, true, true, false]);
    assert_eq!(set.persistent_count(), 4);
    let w = at(&set.warnings);
    assert_eq!(w.len(), 2, "{w:?}");
    assert_eq!((w[0].0, w[0].1), (4, 37));
    assert!(
        w[0].2.starts_with(
            "setting `b`: persistent=\"false\" makes the setting persistent, as in Paparazzi"
        ),
        "{}",
        w[0].2
    );
    assert_eq!(
        problem(&set.warnings[1]),
        &SettingProblem::PersistentFalse { value: "0".into() }
    );
    assert_eq!(set.settings[0].key(), fnv1a(b"a"));
}

#[test]
fn labels_are_checked_against_the_range() {
    let set = ok(r#"<dl_setting var="ok" min="0" max="1" values="OFF|ON"/>
<dl_setting var="many" min="0" max="2" values="A|B|C|D|E|F"/>
<dl_setting var="few" min="1" max="4" values="A|B"/>"#);
    assert_eq!(set.settings[1].values.len(), 6);
    let w = at(&set.warnings);
    assert_eq!(
        w,
        [
            (
                4,
                40,
                "setting `many`: 6 `values` labels for 3 values (max - min + 1): the labels name min, min + 1, ... in order".to_owned()
            ),
            (
                5,
                39,
                "setting `few`: 2 `values` labels for 4 values (max - min + 1): the labels name min, min + 1, ... in order".to_owned()
            ),
        ]
    );
}

#[test]
fn names_and_tags_are_matched_without_case() {
    let set = parse(&[(
        "t.xml",
        r#"<SETTINGS TARGET="ap"><Dl_Settings><DL_SETTINGS NAME="G">
<dl_setting VAR="a" MIN="-1" Max="1" STEP="0.5" ShortName="A" ALT_UNIT="deg" UNIT="rad"/>
</DL_SETTINGS></Dl_Settings></SETTINGS>"#,
    )])
    .unwrap();
    let s = &set.settings[0];
    assert_eq!((s.var.as_str(), s.group.as_str()), ("a", "G"));
    assert_eq!(s.shortname.as_deref(), Some("A"));
    assert_eq!(set.files[0].target.as_deref(), Some("ap"));
    assert_eq!(s.alt_unit.as_deref(), Some("deg"));
    assert!(set.warnings.is_empty(), "{:?}", set.warnings);
    // Two spellings of one attribute: refused.
    let ds = refused(r#"<dl_setting var="a" VAR="b" min="0" max="1"/>"#);
    assert_eq!(
        at(&ds),
        [(
            3,
            21,
            "attribute `var` is given twice, as `var` and `VAR` (names are matched without regard to case)".to_owned()
        )]
    );
}

#[test]
fn a_missing_space_between_attributes_is_accepted_with_a_warning() {
    // Two on one line, one on the next: each at its column in the file as written.
    let text = "<settings>\n<dl_settings>\n<dl_setting var=\"a\"min=\"0\" max=\"1\"handler=\"H\"/>\n  <dl_setting var='b' min='0'max='1'/>\n</dl_settings>\n</settings>\n";
    let set = parse(&[("t.xml", text)]).unwrap();
    assert_eq!(vars(&set), ["a", "b"]);
    assert_eq!(set.settings[0].handler.as_deref(), Some("H"));
    assert_eq!((set.settings[1].line, set.settings[1].column), (4, 3));
    assert_eq!(
        at(&set.warnings),
        [
            (
                3,
                20,
                "no space before attribute `min`: accepted, as Paparazzi accepts it".to_owned()
            ),
            (
                3,
                35,
                "no space before attribute `handler`: accepted, as Paparazzi accepts it".to_owned()
            ),
            (
                4,
                30,
                "no space before attribute `max`: accepted, as Paparazzi accepts it".to_owned()
            ),
        ]
    );
    assert_eq!(&text.lines().nth(2).unwrap()[19..22], "min");
    // Errors after a repair are at their column in the file as written too.
    let text = "<settings>\n<dl_settings>\n<dl_setting var=\"a\"min=\"0\" max=\"x\"/><bad\n</dl_settings>\n</settings>\n";
    let ds = refused_text(text);
    let (line, column, message) = &at(&ds)[0];
    assert_eq!((*line, *column), (4, 1), "{message}");
    assert!(message.ends_with(" at 4:1"), "{message}");
    let text = "<settings>\n<dl_settings>\n<dl_setting var=\"a\"min=\"0\" max=\"1\" x=\"1\"y=\"2\" ==/>\n</dl_settings>\n</settings>\n";
    let ds = refused_text(text);
    assert_eq!((ds[0].line, ds[0].column), (3, 47), "{}", ds[0]);
    assert!(ds[0].to_string().ends_with(" at 3:47"), "{}", ds[0]);
}

#[test]
fn unknown_attributes_and_elements_are_ignored_with_a_warning() {
    let text = r#"<settings target="ap" colour="red">
<dl_setting var="outside" min="0" max="1"/>
<rc_settings/>
<dl_settings flavour="x">
<dl_setting var="a" min="0" max="1" colour="blue"><strip_button/><other/></dl_setting>
<note/>
</dl_settings>
<dl_settings name="second"><dl_setting var="b" min="0" max="1"/></dl_settings>
<extra/>
</settings>"#;
    let set = parse(&[("t.xml", text)]).unwrap();
    assert_eq!(vars(&set), ["a", "b"]);
    assert_eq!(
        at(&set.warnings),
        [
            (1, 23, "<settings> attribute `colour` is not known: ignored".to_owned()),
            (
                2,
                1,
                "<dl_setting> directly under <settings> (Paparazzi reads settings inside <dl_settings> only): ignored".to_owned()
            ),
            (4, 14, "<dl_settings> attribute `flavour` is not known: ignored".to_owned()),
            (
                5,
                66,
                "<other> inside a <dl_setting> (only <strip_button> and <key_press> are known there): ignored".to_owned()
            ),
            (5, 37, "<dl_setting> attribute `colour` is not known: ignored".to_owned()),
            (6, 1, "<note> is not a settings element: ignored".to_owned()),
            (
                8,
                1,
                "a second <dl_settings> under <settings>: Paparazzi reads only the first; read here too, in document order".to_owned()
            ),
            (9, 1, "<extra> is not a settings element: ignored".to_owned()),
        ]
    );
}

#[test]
fn a_group_mixing_settings_and_groups_is_read_in_document_order() {
    let set = ok(r#"<dl_settings name="M">
<dl_setting var="a" min="0" max="1"/>
<dl_settings name="N"><dl_setting var="b" min="0" max="1"/></dl_settings>
<dl_setting var="c" min="0" max="1"/>
</dl_settings>"#);
    assert_eq!(vars(&set), ["a", "b", "c"]);
    assert_eq!(set.warnings.len(), 1);
    assert_eq!(problem(&set.warnings[0]), &SettingProblem::MixedGroup);
    assert_eq!((set.warnings[0].line, set.warnings[0].column), (3, 1));
}

// ----------------------------------------------------------------------------------------
// Bounds and units

#[test]
fn bounds_in_display_units_are_converted_to_the_aircrafts() {
    let set = ok(
        r#"<dl_setting var="phi" min="-90" max="90" step="0.5" unit="rad" alt_unit="deg"/>
<dl_setting var="pos" min="-10" max="10" step="1" unit="1/2^8m" alt_unit="m" alt_unit_coef="0.00390625"/>
<dl_setting var="inv" min="-2" max="4" step="0.5" alt_unit_coef="-2"/>
<dl_setting var="same" min="1" max="2" unit="m" alt_unit="m"/>
<dl_setting var="cm" min="0" max="250" unit="m" alt_unit="cm"/>"#,
    );
    let deg = 180.0 / std::f64::consts::PI;
    let phi = &set.settings[0];
    assert_eq!(
        (phi.min, phi.max, phi.step),
        (
            (-90.0 / deg) as f32,
            (90.0 / deg) as f32,
            (0.5 / deg) as f32
        )
    );
    assert_eq!(
        (phi.written_min, phi.written_max, phi.written_step),
        (-90.0, 90.0, 0.5)
    );
    assert_eq!(phi.alt_unit_coef, deg);
    let pos = &set.settings[1];
    assert_eq!((pos.min, pos.max, pos.step), (-2560.0, 2560.0, 256.0));
    // A negative coefficient swaps the bounds.
    let inv = &set.settings[2];
    assert_eq!((inv.min, inv.max, inv.step), (-2.0, 1.0, 0.25));
    assert_eq!(
        (set.settings[3].min, set.settings[3].alt_unit_coef),
        (1.0, 1.0)
    );
    assert_eq!((set.settings[4].min, set.settings[4].max), (0.0, 2.5));
    assert!(set.warnings.is_empty(), "{:?}", set.warnings);
}

#[test]
fn an_unknown_conversion_keeps_the_bounds_with_a_warning() {
    let set = ok(
        r#"<dl_setting var="a" min="0" max="10" unit="furlong" alt_unit="m"/>
<dl_setting var="b" min="0" max="10" alt_unit="m"/>"#,
    );
    assert_eq!(
        (set.settings[0].max, set.settings[0].alt_unit_coef),
        (10.0, 1.0)
    );
    assert_eq!(
        at(&set.warnings),
        [
            (
                3,
                53,
                "setting `a`: alt_unit `m` without alt_unit_coef, and no known conversion from `furlong`: coefficient 1 (bounds taken as written)".to_owned()
            ),
            (
                4,
                38,
                "setting `b`: alt_unit `m` without alt_unit_coef nor unit: coefficient 1 (bounds taken as written)".to_owned()
            ),
        ]
    );
    // A units.xml given to the generator supplies it.
    let units =
        std::env::temp_dir().join(format!("pprz-settings-units-{}.xml", std::process::id()));
    std::fs::write(
        &units,
        r#"<units><unit from="furlong" to="m" coef="201.168"/></units>"#,
    )
    .unwrap();
    let set = Generator::for_settings(Vec::<PathBuf>::new())
        .settings_from_str(
            "t.xml",
            &file(r#"<dl_setting var="a" min="0" max="201.168" unit="furlong" alt_unit="m"/>"#),
        )
        .units(&units)
        .settings_set()
        .unwrap();
    let _ = std::fs::remove_file(&units);
    assert_eq!(set.settings[0].max, 1.0);
    assert!(set.warnings.is_empty());
}

#[test]
fn bad_numbers_are_refused_where_they_are() {
    for (attrs, attribute, value, column) in [
        (r#"min="x" max="1""#, "min", "x", 21),
        (r#"min="0" max="inf""#, "max", "inf", 29),
        (r#"min="NaN" max="1""#, "min", "NaN", 21),
        (r#"min="0" max="1e39""#, "max", "1e39", 29),
        (r#"min="0" max="1" step="0""#, "step", "0", 37),
        (r#"min="0" max="1" step="-1""#, "step", "-1", 37),
        (
            r#"min="0" max="1" alt_unit_coef="0""#,
            "alt_unit_coef",
            "0",
            37,
        ),
        (
            r#"min="0" max="1" alt_unit_coef="1e-50""#,
            "alt_unit_coef",
            "1e-50",
            37,
        ),
    ] {
        let ds = refused(&format!(r#"<dl_setting var="a" {attrs}/>"#));
        assert_eq!(ds.len(), 1, "{attrs}: {ds:?}");
        let ErrorKind::InvalidNumber {
            attribute: a,
            value: v,
            ..
        } = &ds[0].kind
        else {
            panic!("{attrs}: {:?}", ds[0]);
        };
        assert_eq!((*a, v.as_str()), (attribute, value), "{attrs}");
        assert_eq!((ds[0].line, ds[0].column), (3, column), "{attrs}");
    }
    let ds = refused(r#"<dl_setting var="a" min="0" max="1" step="1e-50"/>"#);
    assert_eq!(
        ds[0].kind.to_string(),
        "attribute `step` = `1e-50` is not a finite number above 0 that fits an f32"
    );
}

#[test]
fn bounds_must_be_ordered_and_stay_finite_once_converted() {
    let ds = refused(r#"<dl_setting var="a" min="2" max="1"/>"#);
    assert_eq!(
        at(&ds),
        [(3, 1, "setting `a`: min 2 is above max 1".to_owned())]
    );
    // min = max is a setting with one value (Paparazzi has some).
    assert_eq!(
        ok(r#"<dl_setting var="a" min="0" max="0"/>"#).settings[0].max,
        0.0
    );
    let ds = refused(
        r#"<dl_setting var="a" min="-3e38" max="3e38" step="1e-30" alt_unit_coef="1e-3"/>"#,
    );
    let kinds: Vec<&SettingProblem> = ds.iter().map(problem).collect();
    assert_eq!(kinds.len(), 2, "{ds:?}");
    assert!(matches!(
        kinds[0],
        SettingProblem::ConvertedOutOfRange {
            attribute: "min",
            ..
        }
    ));
    assert_eq!(
        ds[1].kind.to_string(),
        "setting `a`: `max` = 3e38 divided by the display coefficient 1e-3 does not fit an f32"
    );
}

#[test]
fn missing_required_attributes_are_refused() {
    let ds = refused(
        r#"<dl_setting min="0" max="1"/>
  <dl_setting var="b" max="1"/>
<dl_setting var="c"/>"#,
    );
    assert_eq!(
        at(&ds),
        [
            (
                3,
                1,
                "<dl_setting> is missing the required attribute `var`".to_owned()
            ),
            (
                4,
                3,
                "<dl_setting> is missing the required attribute `min`".to_owned()
            ),
            (
                5,
                1,
                "<dl_setting> is missing the required attribute `min`".to_owned()
            ),
            (
                5,
                1,
                "<dl_setting> is missing the required attribute `max`".to_owned()
            ),
        ]
    );
}

#[test]
fn variables_must_make_distinct_rust_names() {
    // The same variable twice is one variable; another that makes its name is refused.
    let ds = refused(
        r#"<dl_setting var="a.b" min="0" max="1"/>
<dl_setting var="a.b" min="0" max="2"/>
<dl_setting var="a_b" min="0" max="1"/>"#,
    );
    assert_eq!(
        at(&ds),
        [(
            5,
            1,
            "setting `a_b`: makes the Rust name `a_b`, as `a.b` does (t.xml:3:1)".to_owned()
        )]
    );
    let ds = refused(r#"<dl_setting var="..." min="0" max="1"/>"#);
    assert_eq!(
        at(&ds),
        [(
            3,
            13,
            "setting variable name `...` cannot be used: it has no letter or digit to make a Rust name from".to_owned()
        )]
    );
    // Across files, and for names that differ by case or separators.
    let a = file(r#"<dl_setting var="fooBar" min="0" max="1"/>"#);
    let b = file(r#"<dl_setting var="foo__bar" min="0" max="1"/>"#);
    let err = parse(&[("a.xml", &a), ("b.xml", &b)]).unwrap_err();
    assert_eq!(
        err.to_string(),
        "error: b.xml:3:1: setting `foo__bar`: makes the Rust name `foo_bar`, as `fooBar` does (a.xml:3:1)"
    );
    // Keywords and leading digits are escaped, not refused.
    let set =
        ok(r#"<dl_setting var="type" min="0" max="1"/><dl_setting var="2nd" min="0" max="1"/>"#);
    let rust: Vec<&str> = set.settings.iter().map(|s| s.rust_name.as_str()).collect();
    assert_eq!(rust, ["type_", "_2nd"]);
}

#[test]
fn two_persistent_variables_with_one_storage_key_are_refused() {
    // FNV-1a 32 collides for these two names.
    assert_eq!(fnv1a(b"v332789"), fnv1a(b"v529192"));
    let both = r#"<dl_setting var="v332789" min="0" max="1" persistent="true"/>
<dl_setting var="v529192" min="0" max="1" persistent="true"/>"#;
    let ds = refused(both);
    assert_eq!(
        at(&ds),
        [(
            4,
            1,
            "setting `v529192`: storage key 0xa7f1170b (FNV-1a of the variable) is also that of the persistent `v332789` (t.xml:3:1): rename one".to_owned()
        )]
    );
    // Only one is stored: no conflict. The same variable twice: one key.
    ok(
        r#"<dl_setting var="v332789" min="0" max="1" persistent="true"/>
<dl_setting var="v529192" min="0" max="1"/>
<dl_setting var="v332789" min="0" max="1" persistent="true"/>"#,
    );
}

#[test]
fn the_root_must_be_settings_and_the_xml_well_formed() {
    let ds = refused_text("<protocol/>");
    assert_eq!(
        at(&ds),
        [(
            1,
            1,
            "unexpected element <protocol>, expected <settings> as the root element".to_owned()
        )]
    );
    let ds = refused_text(
        "<settings>\n<dl_settings>\n<dl_setting var=\"a\" min=\"0\" max=\"1\">\n</settings>",
    );
    assert!(matches!(ds[0].kind, ErrorKind::Xml(_)), "{ds:?}");
    assert_eq!(ds[0].line, 4);
}

#[test]
fn every_file_is_checked_and_every_problem_reported() {
    let bad = file(r#"<dl_setting var="a" min="2" max="1"/>"#);
    let good = file(r#"<dl_setting var="b" min="0" max="1"/>"#);
    let err = parse(&[("bad1.xml", &bad), ("good.xml", &good), ("bad2.xml", &bad)]).unwrap_err();
    let files: Vec<&str> = err.diagnostics().iter().map(|d| d.file.as_str()).collect();
    assert_eq!(files, ["bad1.xml", "bad2.xml"]);
}

// ----------------------------------------------------------------------------------------
// Hostile inputs: refused with a typed error, or read in bounded time and memory.

#[test]
fn deep_nesting_is_refused_without_recursion() {
    let depth = 200_000;
    let text = format!(
        "<settings>{}<dl_setting var=\"a\" min=\"0\" max=\"1\"/>{}</settings>",
        "<dl_settings>".repeat(depth),
        "</dl_settings>".repeat(depth)
    );
    let ds = refused_text(&text);
    assert_eq!(ds.len(), 1);
    assert_eq!(
        problem(&ds[0]),
        &SettingProblem::TooDeep {
            max: MAX_GROUP_DEPTH
        }
    );
    // The deepest accepted.
    let text = format!(
        "<settings>{}<dl_setting var=\"a\" min=\"0\" max=\"1\"/>{}</settings>",
        "<dl_settings name=\"g\">".repeat(MAX_GROUP_DEPTH),
        "</dl_settings>".repeat(MAX_GROUP_DEPTH)
    );
    let set = parse(&[("t.xml", &text)]).unwrap();
    assert_eq!(set.settings[0].group.split('/').count(), MAX_GROUP_DEPTH);
    // Deep elements that are not read cost nothing more.
    let text = file(&format!(
        "<dl_setting var=\"a\" min=\"0\" max=\"1\"><strip_button>{}{}</strip_button></dl_setting>",
        "<x>".repeat(depth),
        "</x>".repeat(depth)
    ));
    assert_eq!(vars(&parse(&[("t.xml", &text)]).unwrap()), ["a"]);
}

#[test]
fn inputs_beyond_the_limits_are_refused() {
    let first = |text: &str| refused_text(text)[0].kind.clone();
    let big = format!(
        "<settings>{}</settings>",
        " ".repeat(MAX_INPUT_BYTES as usize)
    );
    assert!(matches!(first(&big), ErrorKind::InputTooLarge { .. }));
    drop(big);
    let attrs: String = (0..=MAX_ATTRIBUTES)
        .map(|i| format!(" a{i}=\"1\""))
        .collect();
    assert_eq!(
        first(&file(&format!("<dl_setting{attrs}/>"))),
        ErrorKind::TooManyAttributes {
            max: MAX_ATTRIBUTES
        }
    );
    let entity = format!(
        "<!DOCTYPE settings [<!ENTITY big \"{}\">]>\n{}",
        "x".repeat(100_000),
        file(&format!(
            "<dl_setting var=\"a\" min=\"0\" max=\"1\" shortname=\"{}\"/>",
            "&big;".repeat(20)
        ))
    );
    assert_eq!(
        first(&entity),
        ErrorKind::EntityExpansionTooLarge {
            max: MAX_ENTITY_EXPANSION
        }
    );
    let nested = "<!DOCTYPE settings [<!ENTITY a \"x\"><!ENTITY b \"&a;&a;\">]><settings/>";
    assert!(matches!(first(nested), ErrorKind::NestedEntity { .. }));
    let nodes = file(&"<x/>".repeat(MAX_NODES as usize));
    assert_eq!(first(&nodes), ErrorKind::TooManyNodes { max: MAX_NODES });
}

#[test]
fn floods_of_problems_are_counted_not_kept() {
    // 100,000 settings: one error, whatever follows the 257th is not read.
    let many: String = (0..100_000)
        .map(|i| format!("<dl_setting var=\"v{i}\" min=\"0\" max=\"1\" junk=\"\"/>\n"))
        .collect();
    let ds = refused(&many);
    assert_eq!(ds.len(), 1, "{:?}", &ds[..3.min(ds.len())]);
    assert_eq!(
        problem(&ds[0]),
        &SettingProblem::TooManySettings { max: MAX_SETTINGS }
    );
    // 100,000 invalid settings: 1000 errors, then their count.
    let bad = "<dl_setting/>\n".repeat(100_000);
    let ds = refused(&bad);
    assert_eq!(ds.len(), 1001);
    assert_eq!(
        ds[1000].to_string(),
        "t.xml: 99000 more errors in this file are not shown"
    );
    // 12,000 unknown attributes: 1000 warnings, then their count.
    let attrs: String = (0..60).map(|k| format!(" x{k}=\"\"")).collect();
    let noisy: String = (0..200)
        .map(|i| format!("<dl_setting var=\"v{i}\" min=\"0\" max=\"1\"{attrs}/>\n"))
        .collect();
    let set = ok(&noisy);
    assert_eq!(set.len(), 200);
    assert_eq!(set.warnings.len(), 1001);
    assert_eq!(
        set.warnings[1000].to_string(),
        "t.xml: 11000 more warnings in this file are not shown"
    );
}

#[test]
fn huge_attributes_and_many_repairs_are_read() {
    let long = "s".repeat(8 << 20);
    let set = ok(&format!(
        "<dl_setting var=\"a\" min=\"0\" max=\"1\" shortname=\"{long}\" values=\"{}\"/>",
        "L|".repeat(1 << 20)
    ));
    assert_eq!(
        set.settings[0].shortname.as_deref().map(str::len),
        Some(8 << 20)
    );
    assert_eq!(set.settings[0].values.len(), (1 << 20) + 1);
    assert_eq!(set.warnings.len(), 1); // the label count
    // A missing space before each of many attributes of many settings.
    let body: String = (0..MAX_SETTINGS)
        .map(|i| {
            let junk: String = (0..MAX_ATTRIBUTES - 4)
                .map(|k| format!("x{k}=\"1\""))
                .collect();
            format!("<dl_setting var=\"v{i}\"min=\"0\"max=\"1\"{junk}/>\n")
        })
        .collect();
    let set = ok(&body);
    assert_eq!(set.len(), MAX_SETTINGS);
    // Each missing space, then each unknown attribute: the first 1000 are reported.
    let spaces = MAX_SETTINGS * (MAX_ATTRIBUTES - 2);
    let unknown = MAX_SETTINGS * (MAX_ATTRIBUTES - 4);
    assert_eq!(set.warnings.len(), 1001);
    assert!(
        set.warnings[..1000]
            .iter()
            .all(|w| matches!(problem(w), SettingProblem::MissingSpace { .. }))
    );
    assert_eq!(
        problem(&set.warnings[1000]),
        &SettingProblem::Untold {
            count: spaces + unknown - 1000,
            what: "warnings"
        }
    );
}

// ----------------------------------------------------------------------------------------
// Generated code

#[test]
fn generated_code_names_every_setting_and_variable() {
    let code = Generator::for_settings(Vec::<PathBuf>::new())
        .settings_from_str(
            "g.xml",
            &file(r#"<dl_setting var="a.b" min="0" max="1"/><dl_setting var="c" min="0" max="1"/><dl_setting var="a.b" min="0" max="2"/>"#),
        )
        .runtime_crate("crate::rt")
        .telemetry_crate("::my_tm")
        .embassy_sync_crate("::my_sync")
        .generate_settings()
        .unwrap()
        .code;
    assert!(code.starts_with("// Generated by pprz-codegen "), "{code}");
    assert!(code.contains("pub const COUNT: usize = 3;"));
    assert!(
        code.contains("pub static SETTINGS: [crate::rt::settings::SettingDesc<'static>; 3] = [")
    );
    assert!(code.contains(
        "    pub const A_B: u8 = 0;\n    #[doc = \" `c`: setting 1.\"]\n    pub const C: u8 = 1;\n}"
    ));
    assert!(code.contains("    pub a_b: ::my_tm::settings::Binding<'a>,"));
    assert!(code.contains(
        "pub fn register<'a, M: ::my_sync::blocking_mutex::raw::RawMutex, const K: usize>("
    ));
    assert!(code.contains(
        "    table.add_desc(&SETTINGS[1], bindings.c)?;\n    table.add_desc(&SETTINGS[2], bindings.a_b)?;\n"
    ));
    let err = Generator::for_settings(Vec::<PathBuf>::new())
        .generate_settings()
        .unwrap_err();
    assert_eq!(
        err.to_string(),
        "error: settings.xml: no settings file given (see `Generator::settings`)"
    );
    // A generator of settings only has no messages.
    assert!(Generator::for_settings(["x.xml"]).protocol().is_err());
}

#[test]
fn files_are_read_from_disk_in_the_order_given() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/settings");
    let three = dir.join("three.xml");
    let set = SettingsSet::from_files(
        &[three.clone(), dir.join("empty.xml"), three],
        &Units::builtin(),
    )
    .unwrap();
    assert_eq!(
        vars(&set),
        [
            "gain",
            "trim.roll",
            "ap_mode",
            "gain",
            "trim.roll",
            "ap_mode"
        ]
    );
    assert_eq!((set.files[2].first, set.files[2].count), (3, 3));
    assert!(set.files[2].name.ends_with("three.xml"));
    // `Gain` of edge.xml makes the Rust name of `gain`.
    let err = SettingsSet::from_files(
        &[dir.join("three.xml"), dir.join("edge.xml")],
        &Units::builtin(),
    )
    .unwrap_err();
    assert!(
        err.to_string()
            .contains("setting `Gain`: makes the Rust name `gain`, as `gain` does"),
        "{err}"
    );
    let edge = SettingsSet::from_files(&[dir.join("edge.xml")], &Units::builtin()).unwrap();
    assert_eq!(edge.files[0].target.as_deref(), Some("ap|nps"));
    let err = SettingsSet::from_files(&[dir.join("absent.xml")], &Units::builtin()).unwrap_err();
    assert!(matches!(err.diagnostics()[0].kind, ErrorKind::Io(_)));
}

// ----------------------------------------------------------------------------------------
// The real Paparazzi files

/// Environment variable naming the directory of the real Paparazzi settings files.
const DIR_VAR: &str = "PPRZ_SETTINGS_DIR";

/// The real settings files (every `.xml` under the directory, sorted by path), or `None`
/// (skipped, the reason printed) when the directory is absent.
fn real_files(who: &str) -> Option<Vec<PathBuf>> {
    let dir = std::env::var_os(DIR_VAR).map_or_else(
        || {
            // `shared/paparazzi/settings` in the directory that holds the workspace.
            let workspace = Path::new(env!("CARGO_MANIFEST_DIR")).parent().unwrap();
            workspace
                .parent()
                .unwrap()
                .join("shared")
                .join("paparazzi")
                .join("settings")
        },
        PathBuf::from,
    );
    let mut files = Vec::new();
    let mut dirs = vec![dir.clone()];
    while let Some(d) = dirs.pop() {
        let Ok(entries) = std::fs::read_dir(&d) else {
            continue;
        };
        for e in entries.flatten() {
            let path = e.path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|x| x == "xml") {
                files.push(path);
            }
        }
    }
    files.sort();
    if files.is_empty() {
        let reason = format!(
            "Paparazzi settings files not found: no .xml under {} (set {DIR_VAR} to the directory that holds them)",
            dir.display()
        );
        reference::skip_test(who, &reason);
        return None;
    }
    Some(files)
}

/// Paparazzi's numbering computed independently of the generator: the `var` of every
/// `<dl_setting` tag of the text, in document order, found by a plain scan (comments
/// skipped; an attribute's name is the run of name characters before its `=`, so a
/// missing space does not matter; names compared without case).
fn scan_vars(text: &str) -> Vec<String> {
    let mut vars = Vec::new();
    let mut rest = text;
    while let Some(open) = rest.find('<') {
        rest = &rest[open..];
        if rest.starts_with("<!--") {
            rest = rest.find("-->").map_or("", |end| &rest[end + 3..]);
            continue;
        }
        let tag_end = tag_end(rest);
        let tag = &rest[..tag_end];
        rest = &rest[tag_end..];
        let name_len = tag[1..]
            .find(|c: char| c.is_whitespace() || c == '/' || c == '>')
            .unwrap_or(tag.len() - 1);
        if tag[1..1 + name_len].eq_ignore_ascii_case("dl_setting") {
            vars.push(attribute(tag, "var").unwrap_or_default());
        }
    }
    vars
}

/// Length of the tag at the start of `text`, up to its `>` outside quotes.
fn tag_end(text: &str) -> usize {
    let mut quote = None;
    for (i, c) in text.char_indices() {
        match quote {
            Some(q) if c == q => quote = None,
            Some(_) => {}
            None if c == '"' || c == '\'' => quote = Some(c),
            None if c == '>' => return i + 1,
            None => {}
        }
    }
    text.len()
}

/// The value of attribute `name` (any case) of a tag.
fn attribute(tag: &str, name: &str) -> Option<String> {
    let bytes = tag.as_bytes();
    let mut i = 0;
    while let Some(eq) = tag[i..].find('=') {
        let eq = i + eq;
        let mut start = eq;
        while start > 0 && (bytes[start - 1].is_ascii_alphanumeric() || bytes[start - 1] == b'_') {
            start -= 1;
        }
        let after = tag[eq + 1..].trim_start();
        let quote = after.chars().next()?;
        let value = &after[1..];
        let end = value.find(quote)?;
        if tag[start..eq].eq_ignore_ascii_case(name) {
            return Some(value[..end].trim().to_owned());
        }
        i = tag.len() - value.len() + end + 1;
    }
    None
}

/// Line and column (1-based, in characters) of every attribute name that directly
/// follows a closing quote in a tag: the places Paparazzi's reader accepts without a
/// space (computed independently of the generator).
fn scan_missing_spaces(text: &str) -> Vec<(u32, u32)> {
    let mut found = Vec::new();
    for (l, line) in text.lines().enumerate() {
        let chars: Vec<char> = line.chars().collect();
        let mut quote = None;
        for (c, &ch) in chars.iter().enumerate() {
            match quote {
                Some(q) if ch == q => {
                    quote = None;
                    if chars.get(c + 1).is_some_and(|n| n.is_ascii_alphabetic()) {
                        found.push((l as u32 + 1, c as u32 + 2));
                    }
                }
                Some(_) => {}
                None if (ch == '"' || ch == '\'') && c > 0 && chars[c - 1] == '=' => {
                    quote = Some(ch);
                }
                None => {}
            }
        }
    }
    found
}

#[test]
fn the_real_files_are_numbered_as_paparazzi_numbers_them() {
    let Some(files) = real_files("the_real_files_are_numbered_as_paparazzi_numbers_them") else {
        return;
    };
    let mut all_expected = Vec::new();
    for path in &files {
        let text = std::fs::read_to_string(path).unwrap();
        let expected = scan_vars(&text);
        assert!(!expected.is_empty(), "{}", path.display());
        let set =
            SettingsSet::from_files(&[path], &Units::builtin()).unwrap_or_else(|e| panic!("{e}"));
        for (i, (s, var)) in set.settings.iter().zip(&expected).enumerate() {
            assert_eq!(
                (usize::from(s.index), &s.var),
                (i, var),
                "{}",
                path.display()
            );
        }
        assert_eq!(set.len(), expected.len(), "{}", path.display());
        // The missing spaces, each warned about at its place.
        let warned: Vec<(u32, u32)> = set
            .warnings
            .iter()
            .filter(|w| matches!(problem(w), SettingProblem::MissingSpace { .. }))
            .map(|w| (w.line, w.column))
            .collect();
        assert_eq!(warned, scan_missing_spaces(&text), "{}", path.display());
        all_expected.extend(expected);
    }
    // All of them, in the fixed order, numbered one after the other.
    let set = SettingsSet::from_files(&files, &Units::builtin()).unwrap();
    assert_eq!(vars(&set), all_expected);
    assert_eq!(set.files.len(), files.len());
    assert!(set.len() <= MAX_SETTINGS);
    // The generated code has an index constant for each variable's first setting.
    let code = Generator::for_settings(&files)
        .generate_settings()
        .unwrap()
        .code;
    for v in set.variables() {
        let first = set.get(v.indices[0]).unwrap();
        let line = format!("pub const {}: u8 = {};", first.index_const(), first.index);
        assert!(code.contains(&line), "{line}");
    }
}

#[test]
fn the_malformed_real_file_is_accepted_with_a_warning_at_its_place() {
    let Some(files) = real_files("the_malformed_real_file_is_accepted_with_a_warning_at_its_place")
    else {
        return;
    };
    let Some(path) = files
        .iter()
        .find(|p| p.ends_with("control/stabilization_att_int.xml"))
    else {
        reference::skip_test(
            "the_malformed_real_file_is_accepted_with_a_warning_at_its_place",
            "control/stabilization_att_int.xml is not among the real settings files",
        );
        return;
    };
    let set = SettingsSet::from_files(&[path], &Units::builtin()).unwrap();
    let name = path.display().to_string();
    let warnings: Vec<String> = set.warnings.iter().map(ToString::to_string).collect();
    assert_eq!(
        warnings,
        [format!(
            "{name}:9:176: no space before attribute `param`: accepted, as Paparazzi accepts it"
        )]
    );
    let s = &set.settings[2];
    assert_eq!(
        (s.var.as_str(), s.handler.as_deref(), s.param.as_deref()),
        (
            "stabilization_gains.i.x",
            Some("SetKiPhi"),
            Some("STABILIZATION_ATTITUDE_PHI_IGAIN")
        )
    );
}

#[test]
fn the_real_files_bounds_are_in_the_aircrafts_units() {
    let Some(files) = real_files("the_real_files_bounds_are_in_the_aircrafts_units") else {
        return;
    };
    let set = SettingsSet::from_files(&files, &Units::builtin()).unwrap();
    let mut converted = 0;
    for s in &set.settings {
        let coef = s.alt_unit_coef;
        let (lo, hi) = if coef < 0.0 {
            (s.written_max, s.written_min)
        } else {
            (s.written_min, s.written_max)
        };
        assert_eq!(
            (s.min, s.max),
            ((lo / coef) as f32, (hi / coef) as f32),
            "{}",
            s.var
        );
        if s.unit.as_deref() == Some("rad") && s.alt_unit.as_deref() == Some("deg") {
            assert_eq!(coef, 180.0 / std::f64::consts::PI, "{}", s.var);
            converted += 1;
        }
    }
    if files
        .iter()
        .any(|p| p.ends_with("estimation/body_to_imu.xml"))
    {
        assert!(converted >= 3, "{converted}");
    }
}
