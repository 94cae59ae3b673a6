//! Turning `messages.xml` names into Rust identifiers.

/// Rust keywords (strict and reserved, all editions) that cannot be field names.
const KEYWORDS: &[&str] = &[
    "abstract", "as", "async", "await", "become", "box", "break", "const", "continue", "crate",
    "do", "dyn", "else", "enum", "extern", "false", "final", "fn", "for", "gen", "if", "impl",
    "in", "let", "loop", "macro", "match", "mod", "move", "mut", "override", "priv", "pub", "ref",
    "return", "self", "static", "struct", "super", "trait", "true", "try", "type", "typeof",
    "union", "unsafe", "unsized", "use", "virtual", "where", "while", "yield",
];

/// Primitive types: an item of this name (a class module) would shadow the type in the
/// generated code around it.
const PRIMITIVES: &[&str] = &[
    "bool", "char", "str", "u8", "u16", "u32", "u64", "u128", "usize", "i8", "i16", "i32", "i64",
    "i128", "isize", "f32", "f64",
];

/// Crates named by a bare path (`core::...`): a module of this name would shadow them for
/// code next to the generated items.
const CRATES: &[&str] = &["core", "std", "alloc"];

/// Whether `name` is `[A-Za-z_][A-Za-z0-9_]*`.
pub fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    matches!(chars.next(), Some(c) if c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Whether `path` can name a crate or module in the generated code (the crate path
/// options, e.g. [`Generator::runtime_crate`](crate::Generator::runtime_crate)): an
/// optional leading `::`, then identifiers (ASCII letters, digits and `_`, not
/// starting with a digit, not a keyword) separated by `::`; without the leading `::`,
/// the first may be `crate`, `self` or `super`, and `super` may follow `self` or
/// `super` at the start.
///
/// ```
/// use pprz_codegen::is_rust_path;
/// for ok in ["pprz_messages", "::my_crate::rt", "crate::rt", "super::super::m"] {
///     assert!(is_rust_path(ok), "{ok}");
/// }
/// for bad in ["", "a b", "a\nb", "a::", "::", "1x", "::crate", "a::self", "a::fn"] {
///     assert!(!is_rust_path(bad), "{bad:?}");
/// }
/// ```
pub fn is_rust_path(path: &str) -> bool {
    let (absolute, rest) = match path.strip_prefix("::") {
        Some(rest) => (true, rest),
        None => (false, path),
    };
    // Whether `self` or `super` may come: only at the start of a relative path.
    let mut at_start = !absolute;
    let mut first = true;
    for segment in rest.split("::") {
        let ok = match segment {
            "crate" | "self" => first && at_start,
            "super" => at_start,
            "_" | "Self" => false,
            _ => is_identifier(segment) && !KEYWORDS.contains(&segment),
        };
        if !ok {
            return false;
        }
        at_start = at_start && matches!(segment, "self" | "super");
        first = false;
    }
    true
}

/// Splits a name into words at `_` and at lower-to-upper case changes
/// (`GPS_INT` -> `GPS`, `INT`; `asAirsFilt` -> `as`, `Airs`, `Filt`).
fn words(name: &str) -> Vec<String> {
    let mut words = Vec::new();
    let mut current = String::new();
    let mut prev_lower_or_digit = false;
    for c in name.chars() {
        if c == '_' || c == '-' || c == ' ' || c == '.' {
            if !current.is_empty() {
                words.push(std::mem::take(&mut current));
            }
            prev_lower_or_digit = false;
            continue;
        }
        if c.is_ascii_uppercase() && prev_lower_or_digit && !current.is_empty() {
            words.push(std::mem::take(&mut current));
        }
        prev_lower_or_digit = c.is_ascii_lowercase() || c.is_ascii_digit();
        current.push(c);
    }
    if !current.is_empty() {
        words.push(current);
    }
    words
}

/// `GPS_INT` -> `GpsInt`, `DL_VALUE` -> `DlValue`.
pub fn camel_case(name: &str) -> String {
    words(name)
        .iter()
        .map(|w| {
            let mut chars = w.chars();
            match chars.next() {
                Some(first) => {
                    first.to_ascii_uppercase().to_string() + &chars.as_str().to_ascii_lowercase()
                }
                None => String::new(),
            }
        })
        .collect()
}

/// `utm_east` -> `utm_east`, `asAirsFilt` -> `as_airs_filt`, `type` -> `type_`.
pub fn snake_case(name: &str) -> String {
    let ident = words(name)
        .iter()
        .map(|w| w.to_ascii_lowercase())
        .collect::<Vec<_>>()
        .join("_");
    escape_keyword(ident)
}

/// `telemetry` -> `telemetry`; a module name from a class (or process) name: as
/// [`snake_case`], and a primitive type or crate name gets a trailing `_` (`u8` -> `u8_`,
/// `core` -> `core_`) so the module does not shadow it.
pub fn module_name(name: &str) -> String {
    let ident = snake_case(name);
    if PRIMITIVES.contains(&ident.as_str()) || CRATES.contains(&ident.as_str()) {
        ident + "_"
    } else {
        ident
    }
}

/// Why the Rust type (or enum variant) name made from `name` by [`camel_case`] cannot be
/// used, if it cannot: nothing left, a leading digit, or the keyword `Self`.
pub fn type_name_problem(name: &str) -> Option<String> {
    let ty = camel_case(name);
    if ty.is_empty() {
        Some("it has no letter or digit to make a Rust name from".to_owned())
    } else if ty.starts_with(|c: char| c.is_ascii_digit()) {
        Some(format!(
            "its Rust name `{ty}` would start with a digit (the `_` before it is dropped)"
        ))
    } else if ty == "Self" {
        Some("its Rust name `Self` is a keyword".to_owned())
    } else {
        None
    }
}

/// Why the Rust field or module name made from `name` by [`snake_case`] cannot be used,
/// if it cannot: nothing left (`_`, `__`). Keywords and leading digits are escaped.
pub fn snake_name_problem(name: &str) -> Option<String> {
    words(name)
        .is_empty()
        .then(|| "it has no letter or digit to make a Rust name from".to_owned())
}

/// An enum variant from a `values` label: `NO_FIX` -> `NoFix`, `2D` -> `V2D`,
/// `-1` -> `Minus1`, `v3` -> `V3`. `None` if nothing usable remains.
pub fn variant_name(label: &str) -> Option<String> {
    let trimmed = label.trim();
    let (prefix, rest) = match trimmed.strip_prefix('-') {
        Some(rest) => ("Minus", rest),
        None => ("", trimmed),
    };
    let cleaned: String = rest
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let camel = format!("{prefix}{}", camel_case(&cleaned));
    if camel.is_empty() {
        return None;
    }
    if camel.starts_with(|c: char| c.is_ascii_digit()) {
        Some(format!("V{camel}"))
    } else {
        Some(camel)
    }
}

/// Name of the enum generated for a field's `values`: the message's type name followed by
/// the field's (`GPS`, `mode` -> `GpsMode`).
pub fn values_enum(message: &str, field: &str) -> String {
    format!("{}{}", camel_case(message), camel_case(field))
}

fn escape_keyword(ident: String) -> String {
    if KEYWORDS.contains(&ident.as_str()) || ident.is_empty() {
        ident + "_"
    } else if ident.starts_with(|c: char| c.is_ascii_digit()) {
        format!("_{ident}")
    } else {
        ident
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn converts_names() {
        assert_eq!(camel_case("GPS_INT"), "GpsInt");
        assert_eq!(camel_case("DL_VALUE"), "DlValue");
        assert_eq!(camel_case("I2C_ERRORS"), "I2CErrors");
        assert_eq!(snake_case("asAirsFilt"), "as_airs_filt");
        assert_eq!(snake_case("Hx"), "hx");
        assert_eq!(snake_case("YprU1"), "ypr_u1");
        assert_eq!(snake_case("type"), "type_");
        assert_eq!(snake_case("self"), "self_");
        assert_eq!(snake_case("utm_east"), "utm_east");
        assert_eq!(variant_name("NO_FIX").as_deref(), Some("NoFix"));
        assert_eq!(variant_name("2D").as_deref(), Some("V2D"));
        assert_eq!(variant_name("-1").as_deref(), Some("Minus1"));
        assert_eq!(variant_name("1").as_deref(), Some("V1"));
        assert_eq!(variant_name("v3").as_deref(), Some("V3"));
        assert_eq!(variant_name("--"), Some("Minus".into()));
        assert_eq!(variant_name(""), None);
        assert!(is_identifier("GPS_INT") && is_identifier("_x"));
        assert!(!is_identifier("1GPS") && !is_identifier("GPS INT") && !is_identifier(""));
    }

    #[test]
    fn escapes_or_refuses_unusable_names() {
        assert_eq!(module_name("u8"), "u8_");
        assert_eq!(module_name("core"), "core_");
        assert_eq!(module_name("crate"), "crate_");
        assert_eq!(module_name("SELF"), "self_");
        assert_eq!(module_name("telemetry"), "telemetry");
        assert_eq!(snake_case("u8"), "u8");
        assert_eq!(snake_case("_1st"), "_1st");
        for bad in ["_", "__", "SELF", "self", "Self", "_1ST", "_2"] {
            assert!(type_name_problem(bad).is_some(), "{bad}");
        }
        for ok in ["RESULT", "OPTION", "ANY_MESSAGE", "Set", "X_1"] {
            assert_eq!(type_name_problem(ok), None, "{ok}");
        }
        assert!(snake_name_problem("_").is_some() && snake_name_problem("___").is_some());
        assert_eq!(snake_name_problem("_1"), None);
        assert_eq!(snake_name_problem("self"), None);
    }

    #[test]
    fn rust_paths() {
        for ok in [
            "pprz_messages",
            "::pprz_messages",
            "::my_crate::rt",
            "crate",
            "crate::rt",
            "self::m",
            "super",
            "super::super::m",
            "self::super::m",
            "_x::Y9",
        ] {
            assert!(is_rust_path(ok), "{ok}");
        }
        for bad in [
            "",
            "::",
            "a b",
            "a\nb",
            "a::",
            "::a::",
            "1x",
            "a::1x",
            "a:::b",
            "a:b",
            "::crate",
            "::self",
            "a::crate",
            "a::super",
            "crate::super",
            "crate::crate",
            "fn",
            "a::type",
            "Self",
            "_",
            "r#type",
            "a\u{1b}",
            "é",
        ] {
            assert!(!is_rust_path(bad), "{bad:?}");
        }
    }
}
