//! The checks across settings and files: their number, the Rust names of their
//! variables, and the storage keys of the persistent ones.

use std::collections::HashMap;

use super::read::setting;
use super::{MAX_SETTINGS, SettingDef};
use crate::error::{Diagnostic, ErrorKind, SettingProblem};

/// A problem at setting `s`.
fn at(s: &SettingDef, kind: ErrorKind) -> Diagnostic {
    Diagnostic {
        file: s.file.clone(),
        line: s.line,
        column: s.column,
        message: None,
        field: None,
        kind,
    }
}

/// Checks the settings, in index order, together: at most [`MAX_SETTINGS`]; one Rust
/// name per variable; one storage key per persistent variable.
pub(super) fn all(settings: &[SettingDef], errors: &mut Vec<Diagnostic>) {
    if let Some(s) = settings.get(MAX_SETTINGS) {
        let problem = SettingProblem::TooManySettings { max: MAX_SETTINGS };
        errors.push(at(s, setting(Some(&s.var), problem)));
    }
    let mut rust: HashMap<&str, &SettingDef> = HashMap::new();
    let mut keys: HashMap<u32, &SettingDef> = HashMap::new();
    for s in settings {
        let first = *rust.entry(&s.rust_name).or_insert(s);
        if first.var != s.var {
            let problem = SettingProblem::NameClash {
                rust: s.rust_name.clone(),
                other: first.var.clone(),
                other_at: first.location(),
            };
            errors.push(at(s, setting(Some(&s.var), problem)));
        }
        if !s.persistent {
            continue;
        }
        let key = s.key();
        let first = *keys.entry(key).or_insert(s);
        if first.var != s.var {
            let problem = SettingProblem::KeyCollision {
                key,
                other: first.var.clone(),
                other_at: first.location(),
            };
            errors.push(at(s, setting(Some(&s.var), problem)));
        }
    }
}
