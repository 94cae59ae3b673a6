//! The machinery the XML parsers of the crate share (`messages.xml` and `units.xml` in
//! [`crate::model`], `telemetry.xml` in [`crate::telemetry`]): reading and parsing a file,
//! and a [`Parser`] that collects diagnostics with their position instead of stopping at
//! the first problem.
//!
//! Each format keeps its own element logic, as functions over a [`Parser`]; [`parse`] runs
//! the one for the root element and turns what was collected into a `Result`.

use std::collections::HashMap;
use std::io::Read as _;
use std::path::Path;

use roxmltree::{Document, Node, ParsingOptions};

use crate::error::{Diagnostic, Error, ErrorKind};
use crate::{limits, names};

/// Bytes between two checkpoints of [`Positions`]: the most a position lookup scans.
const BLOCK: usize = 512;

#[cfg(test)]
thread_local! {
    /// Bytes of text scanned to compute positions on this thread (for tests).
    pub(crate) static SCANNED: std::cell::Cell<usize> = const { std::cell::Cell::new(0) };
}

/// Counts `n` bytes scanned for positions (tests only).
fn scanned(n: usize) {
    #[cfg(test)]
    SCANNED.with(|s| s.set(s.get() + n));
    #[cfg(not(test))]
    let _ = n;
}

/// Line and column (1-based, the column counted in characters, as the XML parser
/// counts them) of byte offsets of a text, in time bounded by [`BLOCK`] per lookup after
/// one pass over the text: the text is scanned once for checkpoints every [`BLOCK`]
/// bytes, and a lookup scans from the checkpoint before the offset.
pub(crate) struct Positions<'t> {
    text: &'t [u8],
    /// At byte `k * BLOCK`: lines ended before it, characters before it, and characters
    /// before the start of its line.
    checkpoints: Vec<Checkpoint>,
}

/// The state of a [`Positions`] scan at some byte offset.
#[derive(Debug, Clone, Copy, Default)]
struct Checkpoint {
    /// `\n` before the offset.
    lines: u32,
    /// Characters before the offset.
    chars: u32,
    /// Characters before the start of the line of the offset.
    line_start: u32,
}

impl Checkpoint {
    /// The state after `bytes`.
    fn advance(mut self, bytes: &[u8]) -> Self {
        for &b in bytes {
            // Count characters at their first byte (not a UTF-8 continuation byte).
            if b & 0xC0 != 0x80 {
                self.chars = self.chars.wrapping_add(1);
            }
            if b == b'\n' {
                self.lines = self.lines.wrapping_add(1);
                self.line_start = self.chars;
            }
        }
        self
    }
}

impl<'t> Positions<'t> {
    /// The checkpoints of `text` (one pass).
    pub(crate) fn new(text: &'t str) -> Self {
        let text = text.as_bytes();
        let mut checkpoints = Vec::with_capacity(text.len() / BLOCK + 1);
        let mut state = Checkpoint::default();
        for block in text.chunks(BLOCK) {
            checkpoints.push(state);
            state = state.advance(block);
        }
        checkpoints.push(state);
        scanned(text.len());
        Self { text, checkpoints }
    }

    /// Line and column (1-based) of byte offset `pos` (the end of the text if beyond).
    pub(crate) fn line_col(&self, pos: usize) -> (u32, u32) {
        let pos = pos.min(self.text.len());
        let block = pos / BLOCK;
        let start = block * BLOCK;
        scanned(pos - start);
        let state = self.checkpoints[block].advance(&self.text[start..pos]);
        (
            state.lines.wrapping_add(1),
            state.chars.wrapping_sub(state.line_start).wrapping_add(1),
        )
    }
}

/// The message and field a diagnostic is about.
#[derive(Debug, Clone, Default)]
pub(crate) struct Ctx {
    /// Name of the message, if the diagnostic is about one.
    pub(crate) message: Option<String>,
    /// Name of the field, if the diagnostic is about one.
    pub(crate) field: Option<String>,
}

impl Ctx {
    /// About message `name` as a whole (no field).
    pub(crate) fn message(name: &str) -> Self {
        Self {
            message: Some(name.to_owned()),
            field: None,
        }
    }
}

/// A parsed XML document and the diagnostics collected about it so far.
pub(crate) struct Parser<'a, 'input> {
    file: &'a str,
    doc: &'a Document<'input>,
    positions: Positions<'input>,
    /// Offsets, in the parsed text, of the bytes a [`Repaired`] text inserted (sorted);
    /// empty when the text was parsed as written.
    inserted: Vec<usize>,
    diagnostics: Vec<Diagnostic>,
}

impl<'a, 'input> Parser<'a, 'input> {
    /// A parser of `doc`, which `file` names in diagnostics, with no diagnostics yet;
    /// `positions` are those of the text as written, and `inserted` the offsets in the
    /// parsed text of the bytes a repair inserted into it.
    fn new(
        file: &'a str,
        doc: &'a Document<'input>,
        positions: Positions<'input>,
        inserted: Vec<usize>,
    ) -> Self {
        Self {
            file,
            doc,
            positions,
            inserted,
            diagnostics: Vec::new(),
        }
    }

    /// The name of the file in diagnostics.
    pub(crate) fn file(&self) -> &'a str {
        self.file
    }

    /// The document being parsed.
    pub(crate) fn document(&self) -> &'a Document<'input> {
        self.doc
    }

    /// The root element if its tag is `tag`; otherwise reports it as unexpected where
    /// `expected` was.
    pub(crate) fn root(&mut self, tag: &str, expected: &'static str) -> Option<Node<'a, 'input>> {
        let root = self.doc.root_element();
        if root.has_tag_name(tag) {
            Some(root)
        } else {
            self.unexpected(root, &Ctx::default(), expected);
            None
        }
    }

    /// Line and column (1-based) where `node` starts.
    pub(crate) fn line_col(&self, node: Node<'_, '_>) -> (u32, u32) {
        self.line_col_at(node.range().start)
    }

    /// Line and column (1-based), in the text as written, of byte offset `pos` of the
    /// parsed text (which differs when a repair inserted bytes).
    pub(crate) fn line_col_at(&self, pos: usize) -> (u32, u32) {
        let before = self.inserted.partition_point(|&at| at < pos);
        self.positions.line_col(pos - before)
    }

    /// Offsets, in the parsed text, of the bytes a repair inserted (sorted).
    pub(crate) fn inserted(&self) -> &[usize] {
        &self.inserted
    }

    /// A diagnostic at byte offset `pos` of the parsed text, about the message and field
    /// of `ctx`, without recording it (a warning, or a problem reported later).
    pub(crate) fn diagnostic_at(&self, pos: usize, ctx: &Ctx, kind: ErrorKind) -> Diagnostic {
        let (line, column) = self.line_col_at(pos);
        Diagnostic {
            file: self.file.to_owned(),
            line,
            column,
            message: ctx.message.clone(),
            field: ctx.field.clone(),
            kind,
        }
    }

    /// Records `diagnostic` as a problem.
    pub(crate) fn push(&mut self, diagnostic: Diagnostic) {
        self.diagnostics.push(diagnostic);
    }

    /// Records a problem at `node`, about the message and field of `ctx`.
    pub(crate) fn report(&mut self, node: Node<'_, '_>, ctx: &Ctx, kind: ErrorKind) {
        let d = self.diagnostic_at(node.range().start, ctx, kind);
        self.diagnostics.push(d);
    }

    /// The trimmed value of `attribute` of `node` (an `element`); reports it if absent.
    pub(crate) fn required<'n>(
        &mut self,
        node: Node<'n, '_>,
        element: &'static str,
        attribute: &'static str,
        ctx: &Ctx,
    ) -> Option<&'n str> {
        let value = node.attribute(attribute).map(str::trim);
        if value.is_none() {
            self.report(
                node,
                ctx,
                ErrorKind::MissingAttribute { element, attribute },
            );
        }
        value
    }

    /// The `name` attribute of `node` (an `element`); reports it if absent or not an
    /// identifier.
    pub(crate) fn name(
        &mut self,
        node: Node<'_, '_>,
        element: &'static str,
        ctx: &Ctx,
    ) -> Option<String> {
        let name = self.required(node, element, "name", ctx)?;
        if names::is_identifier(name) {
            Some(name.to_owned())
        } else {
            self.report(node, ctx, ErrorKind::InvalidName(name.to_owned()));
            None
        }
    }

    /// Reports `name` (of a `what`, at `node`) as unusable in Rust for `problem`, if
    /// any; whether it was reported.
    pub(crate) fn unusable(
        &mut self,
        node: Node<'_, '_>,
        ctx: &Ctx,
        what: &'static str,
        name: &str,
        problem: Option<String>,
    ) -> bool {
        let Some(reason) = problem else {
            return false;
        };
        self.report(
            node,
            ctx,
            ErrorKind::UnusableName {
                what,
                name: name.to_owned(),
                reason,
            },
        );
        true
    }

    /// Reports `node` as an element not allowed where `expected` is.
    pub(crate) fn unexpected(&mut self, node: Node<'_, '_>, ctx: &Ctx, expected: &'static str) {
        self.report(
            node,
            ctx,
            ErrorKind::UnexpectedElement {
                found: node.tag_name().name().to_owned(),
                expected,
            },
        );
    }

    /// `value` (of `attribute` of `node`) as a finite number for which `ok` holds;
    /// otherwise reports it as an invalid number where `expected` was.
    pub(crate) fn number(
        &mut self,
        node: Node<'_, '_>,
        ctx: &Ctx,
        attribute: &'static str,
        value: &str,
        ok: impl Fn(f64) -> bool,
        expected: &'static str,
    ) -> Option<f64> {
        match value.parse::<f64>() {
            Ok(x) if x.is_finite() && ok(x) => Some(x),
            _ => {
                self.report(
                    node,
                    ctx,
                    ErrorKind::InvalidNumber {
                        attribute,
                        value: value.to_owned(),
                        expected,
                    },
                );
                None
            }
        }
    }

    /// Parses the `<tag>` element children of `node` with `parse`, in file order,
    /// keeping what it returns; reports any other element child as unexpected where
    /// `expected` was.
    pub(crate) fn children<'n, 'i, T>(
        &mut self,
        node: Node<'n, 'i>,
        tag: &str,
        ctx: &Ctx,
        expected: &'static str,
        mut parse: impl FnMut(&mut Self, Node<'n, 'i>) -> Option<T>,
    ) -> Vec<T> {
        let mut parsed = Vec::new();
        for child in node.children().filter(Node::is_element) {
            if !child.has_tag_name(tag) {
                self.unexpected(child, ctx, expected);
            } else if let Some(value) = parse(self, child) {
                parsed.push(value);
            }
        }
        parsed
    }

    /// `value` if no problem was reported, otherwise every problem reported.
    pub(crate) fn finish<T>(self, value: T) -> Result<T, Error> {
        if self.diagnostics.is_empty() {
            Ok(value)
        } else {
            Err(Error::new(self.diagnostics))
        }
    }
}

/// First occurrences of names and ids, to report duplicates.
#[derive(Default)]
pub(crate) struct Seen {
    first: HashMap<(&'static str, String), u32>,
}

impl Seen {
    /// Records `value` (a `what`, first seen on `line`); if it was already seen, reports
    /// it at `node` with the line of its first occurrence and returns `false`.
    pub(crate) fn check(
        &mut self,
        p: &mut Parser<'_, '_>,
        node: Node<'_, '_>,
        ctx: &Ctx,
        what: &'static str,
        value: String,
        line: u32,
    ) -> bool {
        match self.first.get(&(what, value.clone())) {
            Some(&first_line) => {
                p.report(
                    node,
                    ctx,
                    ErrorKind::Duplicate {
                        what,
                        value,
                        first_line,
                    },
                );
                false
            }
            None => {
                self.first.insert((what, value), line);
                true
            }
        }
    }
}

/// A diagnostic about `file` at line and column `at`, about no message.
fn at(file: &str, (line, column): (u32, u32), kind: ErrorKind) -> Error {
    Error::new(vec![Diagnostic {
        file: file.to_owned(),
        line,
        column,
        message: None,
        field: None,
        kind,
    }])
}

/// Parses `text` (named `file` in diagnostics) as XML and runs `run` on a [`Parser`] of
/// it; the value `run` returns if it reported no problem, otherwise every problem.
///
/// The text is first checked against the [`limits`], and positions are computed from
/// checkpoints made in one pass (see [`Positions`]), so parsing takes time linear in the
/// size of the text.
///
/// # Errors
/// A text beyond the limits, malformed XML, or the problems `run` reported.
pub(crate) fn parse<T>(
    file: &str,
    text: &str,
    run: impl FnOnce(&mut Parser<'_, '_>) -> T,
) -> Result<T, Error> {
    parse_repaired(file, text, |_| None, run)
}

/// A text with bytes inserted before parsing, so that the XML parser accepts what a more
/// lenient reader accepts (a space between two attributes).
pub(crate) struct Repaired {
    /// The text to parse.
    pub(crate) text: String,
    /// Offsets in the text as written before which one byte was inserted, sorted: the
    /// `k`-th inserted byte is at offset `at[k] + k` of [`text`](Self::text).
    pub(crate) at: Vec<usize>,
}

/// [`parse`], parsing the text `repair` returns, if it returns one, instead of `text`;
/// positions in diagnostics (of the XML parser too) are those of `text` as written.
/// `repair` runs after the [`limits`] are checked.
///
/// # Errors
/// As [`parse`].
pub(crate) fn parse_repaired<T>(
    file: &str,
    text: &str,
    repair: impl FnOnce(&str) -> Option<Repaired>,
    run: impl FnOnce(&mut Parser<'_, '_>) -> T,
) -> Result<T, Error> {
    let size = text.len() as u64;
    if size > limits::MAX_INPUT_BYTES {
        return Err(too_large(file, size));
    }
    let positions = Positions::new(text);
    limits::check(text).map_err(|(pos, kind)| at(file, positions.line_col(pos), kind))?;
    let repaired = repair(text).filter(|r| !r.at.is_empty());
    let (parsed, original_at) = match &repaired {
        Some(r) => (r.text.as_str(), r.at.as_slice()),
        None => (text, &[][..]),
    };
    let doc = parse_xml(file, parsed, |row, col| {
        written_line_col(&positions, original_at, row, col)
    })?;
    let inserted = original_at
        .iter()
        .enumerate()
        .map(|(k, &o)| o + k)
        .collect();
    let mut p = Parser::new(file, &doc, positions, inserted);
    let value = run(&mut p);
    p.finish(value)
}

/// The line and column in the text as written of line `row`, column `col` of the text
/// parsed, into which one byte was inserted before each offset of `at` (sorted). An
/// inserted byte never is a line break, so only the column changes.
fn written_line_col(positions: &Positions<'_>, at: &[usize], row: u32, col: u32) -> (u32, u32) {
    let (mut shift, mut line_before, mut on_line) = (0, 0, 0);
    for &o in at {
        let (line, column) = positions.line_col(o);
        on_line = if line == line_before { on_line + 1 } else { 0 };
        line_before = line;
        // The inserted byte's column in the parsed text.
        if line == row && column + on_line < col {
            shift += 1;
        }
    }
    (row, col - shift)
}

/// An input of `size` bytes, more than [`limits::MAX_INPUT_BYTES`].
fn too_large(file: &str, size: u64) -> Error {
    Error::single(
        file,
        ErrorKind::InputTooLarge {
            size,
            max: limits::MAX_INPUT_BYTES,
        },
    )
}

/// Reads the file at `path` and parses it with `parse` (given the file's name for
/// diagnostics and its text).
///
/// # Errors
/// An unreadable file, or what `parse` returns.
pub(crate) fn parse_file<T>(
    path: &Path,
    parse: impl FnOnce(&str, &str) -> Result<T, Error>,
) -> Result<T, Error> {
    let (name, text) = read_file(path)?;
    parse(&name, &text)
}

/// Reads a file, returning its name for diagnostics and its text; a file larger than
/// [`limits::MAX_INPUT_BYTES`] is refused from its size, without reading it.
fn read_file(path: &Path) -> Result<(String, String), Error> {
    let name = path.display().to_string();
    let io = |e: std::io::Error| Error::single(&name, ErrorKind::Io(e.to_string()));
    let file = std::fs::File::open(path).map_err(io)?;
    let size = file.metadata().map_err(io)?.len();
    if size > limits::MAX_INPUT_BYTES {
        return Err(too_large(&name, size));
    }
    // The size may change while reading: read one byte more than allowed at most.
    let mut text = String::new();
    file.take(limits::MAX_INPUT_BYTES + 1)
        .read_to_string(&mut text)
        .map_err(io)?;
    if text.len() as u64 > limits::MAX_INPUT_BYTES {
        return Err(too_large(&name, text.len() as u64));
    }
    Ok((name, text))
}

/// Parses XML, allowing the `<!DOCTYPE ...>` line Paparazzi files carry (its entities
/// were checked against the [`limits`]), with at most [`limits::MAX_NODES`] nodes; a
/// syntax error is reported at its position in `file` (`written` maps a line and column
/// of the text parsed to the text as written).
fn parse_xml<'t>(
    file: &str,
    text: &'t str,
    written: impl Fn(u32, u32) -> (u32, u32),
) -> Result<Document<'t>, Error> {
    Document::parse_with_options(
        text,
        ParsingOptions {
            allow_dtd: true,
            nodes_limit: limits::MAX_NODES,
            ..ParsingOptions::default()
        },
    )
    .map_err(|e| {
        if let roxmltree::Error::NodesLimitReached = e {
            return Error::single(
                file,
                ErrorKind::TooManyNodes {
                    max: limits::MAX_NODES,
                },
            );
        }
        let pos = e.pos();
        let (row, col) = written(pos.row, pos.col);
        // The parser's message ends with the position in the text it parsed.
        let message = e.to_string();
        let message = match message.strip_suffix(&format!(" at {}:{}", pos.row, pos.col)) {
            Some(rest) if (row, col) != (pos.row, pos.col) => format!("{rest} at {row}:{col}"),
            _ => message,
        };
        at(file, (row, col), ErrorKind::Xml(message))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A valid `messages.xml` of `classes` classes of `messages` messages of 8 fields.
    fn protocol(classes: u8, messages: u8) -> String {
        let mut xml = String::from("<?xml version=\"1.0\"?>\n<protocol>\n");
        for c in 1..=classes {
            xml.push_str(&format!("  <msg_class name=\"class_{c}\" id=\"{c}\">\n"));
            for m in 0..messages {
                xml.push_str(&format!(
                    "    <message name=\"MSG_{m}\" id=\"{m}\">\n      <description>Généré: é</description>\n"
                ));
                for f in 0..8 {
                    xml.push_str(&format!(
                        "      <field name=\"f{f}\" type=\"uint16\" unit=\"m\">field {f}</field>\n"
                    ));
                }
                xml.push_str("    </message>\n");
            }
            xml.push_str("  </msg_class>\n");
        }
        xml.push_str("</protocol>\n");
        xml
    }

    #[test]
    fn positions_are_those_of_the_xml_parser() {
        // Multi-byte characters, a long line crossing several checkpoints, empty lines.
        let mut text = String::from("<a>\n\n  <b>é€𝄞</b>\n");
        text.push_str(&"xé".repeat(3 * BLOCK));
        text.push_str("\n<c/>\n</a>");
        let doc = Document::parse(&text).unwrap();
        let positions = Positions::new(&text);
        let offsets = (0..=text.len()).filter(|&i| text.is_char_boundary(i));
        for pos in offsets.chain([text.len() + 10]) {
            let expected = doc.text_pos_at(pos);
            assert_eq!(
                positions.line_col(pos),
                (expected.row, expected.col),
                "offset {pos}"
            );
        }
    }

    /// Bytes scanned for positions while parsing `text`.
    fn scanned_by_parse(text: &str) -> usize {
        SCANNED.with(|s| s.set(0));
        let p = crate::Protocol::parse("large.xml", text).expect("valid");
        assert!(p.message_count() > 0);
        SCANNED.with(std::cell::Cell::get)
    }

    #[test]
    fn positions_take_linear_work() {
        // The positions of every class, message and field are computed: a scan from the
        // start of the text for each (as before) grows with the square of the size.
        let small = protocol(2, 100);
        let large = protocol(8, 100);
        let (s, l) = (scanned_by_parse(&small), scanned_by_parse(&large));
        let elements = 8 * 100 * 9;
        assert!(
            l <= large.len() + elements * BLOCK,
            "{l} bytes scanned for a text of {}",
            large.len()
        );
        // Four times the text: about four times the work (a square would be 16 times).
        assert!(
            l <= 5 * s,
            "{s} bytes scanned, then {l} for 4 times the text"
        );
    }
}
