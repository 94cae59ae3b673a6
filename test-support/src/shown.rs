//! What a tool prints, checked for control characters.

/// Checks that `out` holds no control character but its line breaks, and that it quotes
/// each of `escaped` (the escaped forms a hostile input must show up as).
///
/// # Panics
/// If either does not hold: a test failure naming what was missing.
pub fn assert_escaped(out: &str, escaped: &[&str]) {
    assert!(
        !out.chars().any(|c| c.is_control() && c != '\n'),
        "raw control character in {out:?}"
    );
    for e in escaped {
        assert!(out.contains(e), "{e} not in {out:?}");
    }
}
