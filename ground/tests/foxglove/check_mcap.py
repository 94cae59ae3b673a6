#!/usr/bin/env python3
"""Independent check of an MCAP recorded by `pprz-monitor --lines --mcap OUT.mcap`.

    check_mcap.py OUT.mcap LINES.txt [--messages M.xml] [--log-times any|replay|wall]

LINES.txt is the standard output of the same run (one line per decoded message, the
format of ground/src/format.rs). The MCAP is read with PyPI's `mcap` package twice:
once through its summary and chunk indexes (seeking reader), once as a plain stream
of records (non-seeking reader, which also checks the CRCs); both must give the same
messages. Then:

* every channel has a schema of encoding `jsonschema` and message encoding `json`; the
  schema is a valid Draft 2020-12 schema, named `pprz.<class>.<MESSAGE>` for the
  message topics `/ac/<id>/<class>/<MESSAGE>` (`foxglove.LocationFix` for
  `/ac/<id>/location`, `pprz.LinkStats` for `/ac/<id>/link`), and every message is
  JSON that validates against it (PyPI's `jsonschema`);
* the number of messages of each message topic equals the number of lines of that
  source, class and message (unknown and malformed messages have no topic);
* the n-th message of a topic has the values of the n-th line of that message:
  integers equal, floats equal as floats (both sides are the shortest round-trip
  decimal of the same value; NaN and infinities are null in the JSON), text equal once
  the line's escapes are undone, `<field>_alt` within half a unit of the last decimal
  the line prints of the converted value.

Prints `topics N, messages M, checked` and exits 0, or prints the mismatches (at most
20, then their count) and exits 1. Exit status 2: bad usage or unreadable lines file.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import re
import struct
import sys
import time
import xml.etree.ElementTree as ET
from collections import Counter, defaultdict
from dataclasses import dataclass, field as dc_field
from typing import Any, Optional

try:
    import jsonschema
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader, SeekingReader
except ImportError as e:  # pragma: no cover - depends on the environment
    sys.stderr.write(
        f"check_mcap.py: {e}; run ground/tests/foxglove/setup.sh and use the venv's python\n"
    )
    sys.exit(2)

MAX_REPORTED = 20
DRAFT_2020_12 = "https://json-schema.org/draft/2020-12/schema"
MCAP_MAGIC = b"\x89MCAP0\r\n"

# --------------------------------------------------------------------------------------
# The escapes of ground/src/escape.rs, undone (and redone, to compare escaped forms).
# --------------------------------------------------------------------------------------

ESC = r'\\(?:[ntr\\"]|x[0-9a-f]{2}|u\{[0-9a-f]{1,6}\})'
ESC_RE = re.compile(ESC)
SIMPLE_ESCAPES = {"n": "\n", "t": "\t", "r": "\r", "\\": "\\", '"': '"'}


_UNESCAPE_CACHE: dict = {}


def _unescape_one(m: re.Match) -> str:
    s = m.group(0)
    u = _UNESCAPE_CACHE.get(s)
    if u is None:
        c = s[1]
        if c in SIMPLE_ESCAPES:
            u = SIMPLE_ESCAPES[c]
        elif c == "x":
            u = chr(int(s[2:4], 16))
        else:
            u = chr(int(s[3:-1], 16))
        _UNESCAPE_CACHE[s] = u
    return u


def unescape(text: str) -> str:
    """Undoes escape::quoted (without its quotes) or escape::token."""
    if "\\" not in text:
        return text
    return ESC_RE.sub(_unescape_one, text)


# Rust's char::is_whitespace (Unicode White_Space).
_RUST_WHITESPACE = set(
    "\t\n\x0b\x0c\r \x85\xa0\u1680\u2000\u2001\u2002\u2003\u2004\u2005\u2006\u2007"
    "\u2008\u2009\u200a\u2028\u2029\u202f\u205f\u3000"
)


def is_unsafe(c: str) -> bool:
    """escape::is_unsafe: control characters (Cc) and invisible formatting characters."""
    o = ord(c)
    return (
        o <= 0x1F
        or 0x7F <= o <= 0x9F
        or 0x200B <= o <= 0x200F
        or 0x2028 <= o <= 0x202E
        or 0x2060 <= o <= 0x206F
        or o == 0xFEFF
        or 0xFFF9 <= o <= 0xFFFB
    )


def _push_escape(out: list, c: str) -> None:
    if c == "\n":
        out.append("\\n")
    elif c == "\t":
        out.append("\\t")
    elif c == "\r":
        out.append("\\r")
    elif c == "\\":
        out.append("\\\\")
    elif c == '"':
        out.append('\\"')
    elif ord(c) < 0x80:
        out.append("\\x%02x" % ord(c))
    else:
        out.append("\\u{%x}" % ord(c))


def _quoted_table() -> dict:
    table = {}
    for o in list(range(0x00, 0x20)) + list(range(0x7F, 0xA0)) + [
        *range(0x200B, 0x2010),
        *range(0x2028, 0x202F),
        *range(0x2060, 0x2070),
        0xFEFF,
        *range(0xFFF9, 0xFFFC),
        ord("\\"),
        ord('"'),
    ]:
        out: list = []
        _push_escape(out, chr(o))
        table[o] = out[0]
    return table


_QUOTED_TABLE = _quoted_table()


def escape_quoted_inner(text: str) -> str:
    """escape::quoted without the surrounding quotes."""
    return text.translate(_QUOTED_TABLE)


# --------------------------------------------------------------------------------------
# Parsing of the `--lines` output.
# --------------------------------------------------------------------------------------

TOKEN = r'(?:[^ =,"\[\]()\\]|' + ESC + r")+"
QUOTED = r'"(?:[^"\\]|' + ESC + r')*"'
NUMBER = r"[-+0-9A-Za-z.]+"  # digits, `.`, `-`, `NaN`, `inf`
VALUE = r"(?:" + QUOTED + r"|(?:" + NUMBER + r"(?:," + NUMBER + r")*)?)"
FIELD_RE = re.compile(
    r"(?P<name>" + TOKEN + r")=(?P<value>" + VALUE + r")"
    r"(?:\((?P<label>" + TOKEN + r")\))?"
    r"(?: \[(?P<unit>" + TOKEN + r")\])?"
    r"(?: (?P<conv>" + NUMBER + r"(?:," + NUMBER + r")*) (?P<altunit>" + TOKEN + r"))?"
    r"(?= |$)"
)
# The start of a field cut by the 2048-byte limit: its name and the beginning of a text.
PARTIAL_TEXT_RE = re.compile(
    r"(?P<name>" + TOKEN + r')="(?P<text>(?:[^"\\]|' + ESC + r')*)(?:\\[^"]*)?$'
)
QUOTED_RE = re.compile(QUOTED)
MAX_FIELDS_LEN = 2048  # format::MAX_FIELDS_LEN


@dataclass
class LineField:
    name: str
    raw_value: str  # as printed: `1,2,3`, `"text"`, `2.5`
    label: Optional[str]
    unit: Optional[str]
    conv: Optional[str]  # `43.4629172` or `0.100,0.200`
    alt_unit: Optional[str]
    partial: bool = False  # the value may be cut by the length limit
    tail_cut: bool = False  # the label, unit or converted value may be cut


@dataclass
class Line:
    lineno: int
    topic: str
    body: str


@dataclass
class ParsedLine:
    fields: list
    truncated: bool


def parse_body(body: str) -> ParsedLine:
    """The fields of a known message's line (`a=1 b=2.5 [V] ...`).

    Raises ValueError when the line does not follow the format."""
    blen = len(body.encode("utf-8"))
    truncated = body.endswith("...") and MAX_FIELDS_LEN - 3 <= blen <= MAX_FIELDS_LEN
    if truncated:
        body = body[:-3]
    fields: list = []
    pos, n = 0, len(body)
    while pos < n:
        m = FIELD_RE.match(body, pos)
        if m is None:
            rest = body[pos:]
            if not truncated:
                raise ValueError(f"cannot parse the field at column {pos + 1}: {rest[:60]!r}")
            pm = PARTIAL_TEXT_RE.match(body, pos)
            if pm is not None and pm.end() == n:
                fields.append(
                    LineField(unescape(pm.group("name")), '"' + pm.group("text"), None, None, None, None, True, True)
                )
            # Anything else cut (a name, a number, a unit): not compared.
            break
        end = m.end()
        f = LineField(
            unescape(m.group("name")),
            m.group("value"),
            m.group("label"),
            m.group("unit"),
            m.group("conv"),
            m.group("altunit"),
        )
        if truncated and end == n:
            f.partial = True
        fields.append(f)
        pos = end
        if pos < n:
            pos += 1  # the space
    if truncated and fields:
        fields[-1].tail_cut = True
    return ParsedLine(fields, truncated)


UNKNOWN_RE = re.compile(r"^\d+ class\d+ id=\d+ unknown message \(\d+ bytes\)$")


def read_lines(path: str, problems: "Problems"):
    """Groups the message lines by topic; returns (by_topic, stats)."""
    by_topic: dict = defaultdict(list)
    stats = Counter()
    with open(path, "r", encoding="utf-8", errors="strict", newline="\n") as f:
        for lineno, line in enumerate(f, 1):
            line = line.rstrip("\n")
            if line.endswith("\r"):
                line = line[:-1]
            if not line:
                stats["empty"] += 1
                continue
            parts = line.split(" ", 3)
            if len(parts) < 3 or not parts[0].isdigit():
                problems.add(f"line {lineno}: not a message line: {line[:80]!r}")
                continue
            if parts[2].startswith("id="):
                if not UNKNOWN_RE.match(line):
                    problems.add(f"line {lineno}: malformed unknown-message line: {line[:80]!r}")
                stats["unknown"] += 1
                continue
            body = parts[3] if len(parts) == 4 else ""
            if _has_error(body):
                stats["malformed"] += 1
                continue
            src, cls, name = int(parts[0]), unescape(parts[1]), unescape(parts[2])
            by_topic[f"/ac/{src}/{cls}/{name}"].append(Line(lineno, f"/ac/{src}/{cls}/{name}", body))
            stats["messages"] += 1
    return by_topic, stats


def _has_error(body: str) -> bool:
    """Whether the line ends with `<error: ...>` outside of any quoted text."""
    i = body.find("<error: ")
    if i < 0:
        return False
    if i == 0:
        return True
    # Outside text: the error follows a space, after the last complete field.
    stripped = QUOTED_RE.sub('""', body)
    return stripped.startswith("<error: ") or " <error: " in stripped


# --------------------------------------------------------------------------------------
# messages.xml (optional): field names, order, types, units and labels.
# --------------------------------------------------------------------------------------


@dataclass
class XmlField:
    name: str
    base: str  # uint8 .. double, char
    kind: str  # scalar | array | vector
    size: int
    unit: Optional[str]
    alt_unit: Optional[str]
    values: list


def parse_field_type(t: str):
    t = t.strip()
    if t == "string":
        return "char", "vector", 0
    m = re.fullmatch(r"([a-z0-9]+)\s*(?:\[\s*(\d*)\s*\])?", t)
    if m is None:
        raise ValueError(f"unknown field type {t!r}")
    base = m.group(1)
    if m.group(2) is None:
        return base, "scalar", 0
    if m.group(2) == "":
        return base, "vector", 0
    return base, "array", int(m.group(2))


def read_messages_xml(path: str) -> dict:
    """(class, MESSAGE) -> [XmlField] in order."""
    out = {}
    root = ET.parse(path).getroot()
    for cls in root.iter("msg_class"):
        cname = cls.get("name", "").strip()
        for msg in cls.iter("message"):
            fields = []
            for f in msg.iter("field"):
                base, kind, size = parse_field_type(f.get("type", ""))
                values = [v.strip() for v in f.get("values").split("|")] if f.get("values") else []
                fields.append(
                    XmlField(
                        f.get("name", "").strip(),
                        base,
                        kind,
                        size,
                        (f.get("unit") or "").strip() or None,
                        (f.get("alt_unit") or "").strip() or None,
                        values,
                    )
                )
            out[(cname, msg.get("name", "").strip())] = fields
    return out


def is_unit(u: Optional[str]) -> bool:
    if u is None:
        return False
    u = u.strip()
    return not (u == "" or u == "-" or u.lower() == "none")


INT_BASES = {"uint8", "int8", "uint16", "int16", "uint32", "int32", "uint64", "int64"}
FLOAT_BASES = {"float", "double"}

# --------------------------------------------------------------------------------------
# Comparison of one message with one line.
# --------------------------------------------------------------------------------------


class Problems:
    """Mismatches: those of the file and the counts first, then those of each topic's
    messages (only the first one of a topic whose count differs: its later messages are
    compared with shifted lines)."""

    def __init__(self, limit: int = MAX_REPORTED):
        self.limit = limit
        self.count = 0
        self.topic: Optional[str] = None  # the topic whose messages are being compared
        self.general: list = []
        self.by_topic: dict = {}
        self.count_topics: set = set()

    def add(self, text: str) -> None:
        self.count += 1
        if self.topic is None:
            if len(self.general) < self.limit:
                self.general.append(text)
            return
        lst = self.by_topic.setdefault(self.topic, [])
        if len(lst) < self.limit:
            lst.append(text)

    def add_count(self, topic: str, text: str) -> None:
        self.count_topics.add(topic)
        saved, self.topic = self.topic, None
        self.add(text)
        self.topic = saved

    def report(self) -> None:
        out = list(self.general)
        hidden = 0
        for topic, lst in self.by_topic.items():
            if topic in self.count_topics:
                out.append(lst[0] + " (first difference of a topic whose count differs)")
                hidden += len(lst) - 1
            else:
                out.extend(lst)
        for text in out[: self.limit]:
            print(f"mismatch: {text}")
        shown = min(self.limit, len(out))
        if self.count > shown:
            more = f"... and {self.count - shown} more"
            if hidden:
                more += " (most of them in topics whose counts differ)"
            print(more)


def _jtext(v: Any) -> str:
    return json.dumps(v, ensure_ascii=False, allow_nan=True)


_INT_RE = re.compile(r"-?\d+")
_FLOAT_RE = re.compile(r"-?\d+\.\d+")
NONFINITE = {"NaN": math.nan, "inf": math.inf, "-inf": -math.inf}


def line_number(tok: str):
    """A number as format.rs prints it: int, float, or None for NaN/inf (JSON null)."""
    if tok in NONFINITE:
        return None
    if tok == "-0":
        return -0.0  # a float zero with its sign (integers never print `-0`)
    if _INT_RE.fullmatch(tok):
        return int(tok)
    if _FLOAT_RE.fullmatch(tok):
        return float(tok)
    raise ValueError(f"not a number: {tok!r}")


def numbers_equal(j: Any, l: Any) -> bool:
    """JSON value `j` (int, float or None) against the line's value `l`."""
    if l is None or j is None:
        return l is None and j is None
    if isinstance(j, bool) or not isinstance(j, (int, float)):
        return False
    if isinstance(j, int) and isinstance(l, int):
        return j == l
    fj, fl = float(j), float(l)
    if fj != fl:
        return False
    if fj == 0.0 and isinstance(j, float) and isinstance(l, float):
        # -0.0 prints as `-0`; the JSON keeps its sign too.
        return math.copysign(1.0, fj) == math.copysign(1.0, fl)
    return True


def _f32_hint(j: Any, l: Any) -> str:
    try:
        if isinstance(j, float) and isinstance(l, (int, float)):
            if struct.unpack("<f", struct.pack("<f", float(l)))[0] == j and j != float(l):
                return " (the JSON has the f32 value widened to f64 printed in full; expected its shortest form)"
    except (OverflowError, struct.error):
        pass
    return ""


def compare_conv(j: Any, conv: str, ctx: str, problems: Problems) -> None:
    """`<field>_alt` (number or array) against the printed converted value."""
    toks = conv.split(",")
    if isinstance(j, list):
        if len(toks) != len(j):
            problems.add(f"{ctx}_alt: MCAP has {len(j)} elements, line {len(toks)}: {_jtext(j)} vs {conv}")
            return
        vals = j
    else:
        if len(toks) != 1:
            problems.add(f"{ctx}_alt: MCAP {_jtext(j)} vs line {conv}")
            return
        vals = [j]
    for i, (v, t) in enumerate(zip(vals, toks)):
        where = f"{ctx}_alt" + (f"[{i}]" if isinstance(j, list) else "")
        if t in NONFINITE:
            if v is not None:
                problems.add(f"{where}: MCAP {_jtext(v)}, line {t} (expected null)")
            continue
        if v is None or isinstance(v, bool) or not isinstance(v, (int, float)):
            problems.add(f"{where}: MCAP {_jtext(v)}, line {t}")
            continue
        decimals = len(t.split(".", 1)[1]) if "." in t else 0
        printed = float(t)
        half = 0.5 * 10.0 ** (-decimals)
        tol = half * (1 + 1e-9) + abs(printed) * 4e-16
        if not (abs(float(v) - printed) <= tol):
            problems.add(f"{where}: MCAP {_jtext(v)} is not {t} (within {half:g})")


def compare_text(j: Any, f: LineField, ctx: str, problems: Problems, scalar_char: bool) -> None:
    if not isinstance(j, str):
        problems.add(f"{ctx}: MCAP {_jtext(j)} is not text, line {f.raw_value}")
        return
    if f.partial:
        # Cut by the line's length limit: the escaped forms must agree on what is shown.
        shown = f.raw_value[1:]
        if shown.endswith('"'):
            shown = shown[:-1]
        if not escape_quoted_inner(j[: len(shown)]).startswith(shown):
            problems.add(f"{ctx}: MCAP text {_jtext(j[:80])} does not start with the line's {shown[:80]!r}")
        return
    # escape::quoted is injective: comparing the escaped forms is comparing the texts.
    if escape_quoted_inner(j) != f.raw_value[1:-1]:
        text = unescape(f.raw_value[1:-1])
        hint = ""
        if scalar_char and len(text) == 1 and 0x80 <= ord(text) <= 0xFF:
            hint = " (format.rs reads a char byte as Latin-1: char::from(u8))"
        problems.add(f"{ctx}: MCAP {_jtext(j)} != line {f.raw_value}{hint}")


def compare_message(
    msg: dict,
    parsed: ParsedLine,
    ctx: str,
    problems: Problems,
    xml_fields: Optional[list],
) -> None:
    line_names = [f.name for f in parsed.fields]
    line_name_set = set(line_names)
    xml_by_name = {f.name: f for f in xml_fields} if xml_fields is not None else {}
    alt_keys = set()
    for f in parsed.fields:
        if f.name not in msg:
            problems.add(f"{ctx}: field {f.name} is in the line but not in the MCAP message")
            continue
        j = msg[f.name]
        fctx = f"{ctx}: {f.name}"
        xf = xml_by_name.get(f.name)
        v = f.raw_value
        if v.startswith('"'):
            compare_text(j, f, fctx, problems, scalar_char=xf is not None and xf.kind == "scalar")
        else:
            toks = v.split(",") if v else []
            is_array = isinstance(j, list)
            if xf is not None:
                is_array = xf.kind != "scalar"
                if is_array != isinstance(j, list):
                    problems.add(f"{fctx}: MCAP {_jtext(j)} but messages.xml says {xf.kind} {xf.base}")
                    continue
            if is_array:
                if not isinstance(j, list):
                    problems.add(f"{fctx}: MCAP {_jtext(j)} is not an array, line {v}")
                    continue
                if f.partial:
                    toks = toks[:-1]  # the last one may be cut
                    if len(j) < len(toks):
                        problems.add(f"{fctx}: MCAP has {len(j)} elements, the (cut) line at least {len(toks)}")
                        continue
                    j = j[: len(toks)]
                elif len(j) != len(toks):
                    problems.add(f"{fctx}: MCAP has {len(j)} elements, line {len(toks)}: {_jtext(j)[:80]} vs {v[:80]}")
                    continue
                for i, (a, t) in enumerate(zip(j, toks)):
                    try:
                        ln = line_number(t)
                    except ValueError as e:
                        problems.add(f"{fctx}[{i}]: {e}")
                        break
                    if not numbers_equal(a, ln):
                        problems.add(f"{fctx}[{i}]: MCAP {_jtext(a)} != line {t}{_f32_hint(a, ln)}")
                        break
            else:
                if f.partial:
                    continue
                if len(toks) != 1:
                    problems.add(f"{fctx}: MCAP {_jtext(j)} is a scalar, line {v}")
                    continue
                try:
                    ln = line_number(toks[0])
                except ValueError as e:
                    problems.add(f"{fctx}: {e}")
                    continue
                if not numbers_equal(j, ln):
                    problems.add(f"{fctx}: MCAP {_jtext(j)} != line {v}{_f32_hint(j, ln)}")
                    continue
                if xf is not None and xf.base in INT_BASES and not isinstance(j, int):
                    problems.add(f"{fctx}: MCAP {_jtext(j)} is not a JSON integer ({xf.base})")
                if xf is not None and xf.base in FLOAT_BASES and isinstance(j, int) and not isinstance(j, bool):
                    # 1.0f32 as `1`: allowed by JSON, and equal as a number.
                    pass
        alt_key = f.name + "_alt"
        if f.conv is not None:
            alt_keys.add(alt_key)
            if alt_key not in msg:
                problems.add(f"{fctx}: the line has the converted value {f.conv} {f.alt_unit} but the MCAP has no {alt_key}")
            elif not f.partial:
                compare_conv(msg[alt_key], f.conv, fctx, problems)
        elif alt_key in msg and alt_key not in line_names and not f.tail_cut:
            a = msg[alt_key]
            # format.rs prints no converted value for an empty array.
            if not (a == [] and msg.get(f.name) == []):
                problems.add(f"{fctx}: the MCAP has {alt_key}={_jtext(a)[:60]} but the line has no converted value")
    if not parsed.truncated:
        expected = set(line_names) | alt_keys
        extra = [k for k in msg if k not in expected and not (k.endswith("_alt") and k[:-4] in line_name_set)]
        if extra:
            problems.add(f"{ctx}: the MCAP message has keys the line does not: {', '.join(extra)}")
    raw_order = [k for k in msg if k in line_name_set]
    if raw_order != line_names[: len(raw_order)] and not parsed.truncated:
        problems.add(f"{ctx}: MCAP keys in order {raw_order}, line {line_names}")


# --------------------------------------------------------------------------------------
# Schemas.
# --------------------------------------------------------------------------------------

TOPIC_MSG_RE = re.compile(r"^/ac/(\d+)/([^/]+)/([^/]+)$")
TOPIC_AUX_RE = re.compile(r"^/ac/(\d+)/(location|link)$")


def _reject_constant(name: str):
    raise ValueError(f"{name} is not JSON")


def loads(data: bytes) -> Any:
    return json.loads(data.decode("utf-8"), parse_constant=_reject_constant)


@dataclass
class ChannelCheck:
    topic: str
    kind: str  # message | location | link | unexpected
    validator: Any = None
    schema: Optional[dict] = None
    ac: Optional[int] = None
    key: Optional[tuple] = None  # (class, MESSAGE)
    count: int = 0
    valid_cache: dict = dc_field(default_factory=dict)
    described: bool = False


def check_channel(schema, channel, problems: Problems, xml: Optional[dict], allowed=()) -> ChannelCheck:
    topic = channel.topic
    m = TOPIC_MSG_RE.match(topic)
    a = TOPIC_AUX_RE.match(topic)
    if any(r.fullmatch(topic) for r in allowed):
        cc = ChannelCheck(topic, "other")
        expected_name = None
    elif a:
        cc = ChannelCheck(topic, a.group(2), ac=int(a.group(1)))
        expected_name = "foxglove.LocationFix" if a.group(2) == "location" else "pprz.LinkStats"
    elif m:
        cc = ChannelCheck(topic, "message", ac=int(m.group(1)), key=(m.group(2), m.group(3)))
        expected_name = f"pprz.{m.group(2)}.{m.group(3)}"
    else:
        cc = ChannelCheck(topic, "unexpected")
        expected_name = None
        problems.add(f"{topic}: unexpected topic (not /ac/<id>/<class>/<MESSAGE>, /ac/<id>/location or /ac/<id>/link)")
    if channel.message_encoding != "json":
        problems.add(f"{topic}: message encoding {channel.message_encoding!r}, expected 'json'")
    if schema is None:
        problems.add(f"{topic}: no schema")
        return cc
    if schema.encoding != "jsonschema":
        problems.add(f"{topic}: schema encoding {schema.encoding!r}, expected 'jsonschema'")
    if expected_name is not None and schema.name != expected_name:
        problems.add(f"{topic}: schema name {schema.name!r}, expected {expected_name!r}")
    try:
        doc = loads(schema.data)
    except (ValueError, UnicodeDecodeError) as e:
        problems.add(f"{topic}: schema {schema.name!r} is not JSON: {e}")
        return cc
    if not isinstance(doc, dict):
        problems.add(f"{topic}: schema {schema.name!r} is not a JSON object")
        return cc
    if doc.get("$schema") != DRAFT_2020_12:
        problems.add(f"{topic}: schema $schema is {doc.get('$schema')!r}, expected {DRAFT_2020_12!r}")
    try:
        jsonschema.Draft202012Validator.check_schema(doc)
    except jsonschema.exceptions.SchemaError as e:
        problems.add(f"{topic}: invalid Draft 2020-12 schema: {e.message}")
        return cc
    if doc.get("type") != "object":
        problems.add(f"{topic}: schema type {doc.get('type')!r}, expected 'object'")
    cc.schema = doc
    cc.validator = jsonschema.Draft202012Validator(doc)
    if cc.kind == "message":
        if doc.get("additionalProperties") is not False:
            problems.add(f"{topic}: schema without \"additionalProperties\": false")
        props = doc.get("properties")
        if not isinstance(props, dict):
            problems.add(f"{topic}: schema without properties")
        if xml is not None:
            fields = xml.get(cc.key)
            if fields is None:
                problems.add(f"{topic}: message {cc.key[0]}.{cc.key[1]} is not in messages.xml")
            else:
                names = [f.name for f in fields]
                if doc.get("required") != names:
                    problems.add(f"{topic}: schema required {doc.get('required')}, messages.xml fields {names}")
                if isinstance(props, dict):
                    check_descriptions_xml(topic, props, fields, problems)
    return cc


def _description(props: dict, name: str) -> str:
    p = props.get(name)
    if not isinstance(p, dict):
        return ""
    d = p.get("description")
    return d if isinstance(d, str) else ""


def check_descriptions_xml(topic: str, props: dict, fields: list, problems: Problems) -> None:
    for f in fields:
        if f.name not in props:
            problems.add(f"{topic}: schema has no property {f.name}")
            continue
        d = _description(props, f.name)
        if is_unit(f.unit) and f.unit not in d:
            problems.add(f"{topic}: the description of {f.name} ({d!r}) does not name its unit {f.unit!r}")
        for i, label in enumerate(f.values):
            if f"{i}={label}" not in d:
                problems.add(f"{topic}: the description of {f.name} ({d!r}) does not list {i}={label}")
        alt = f.name + "_alt"
        if alt in props and is_unit(f.alt_unit) and f.alt_unit not in _description(props, alt):
            problems.add(f"{topic}: the description of {alt} ({_description(props, alt)!r}) does not name {f.alt_unit!r}")


def check_descriptions_line(cc: ChannelCheck, parsed: ParsedLine, problems: Problems) -> None:
    """Once per topic: the line's unit and alt unit appear in the schema's descriptions."""
    props = cc.schema.get("properties") if cc.schema else None
    if not isinstance(props, dict):
        return
    required = cc.schema.get("required")
    if not parsed.truncated and required != [f.name for f in parsed.fields]:
        problems.add(f"{cc.topic}: schema required {required}, line fields {[f.name for f in parsed.fields]}")
    for f in parsed.fields:
        if f.partial:
            continue
        d = _description(props, f.name)
        if f.unit is not None and unescape(f.unit) not in d:
            problems.add(f"{cc.topic}: the description of {f.name} ({d!r}) does not name its unit {unescape(f.unit)!r}")
        if f.label is not None and "=" + unescape(f.label) not in d:
            problems.add(f"{cc.topic}: the description of {f.name} ({d!r}) does not list the label {unescape(f.label)!r}")
        if f.conv is not None:
            au = unescape(f.alt_unit)
            if f.name + "_alt" not in props:
                problems.add(f"{cc.topic}: the schema has no property {f.name}_alt")
            elif au not in _description(props, f.name + "_alt") and au not in d:
                problems.add(f"{cc.topic}: no description names the alt unit {au!r} of {f.name}")


def check_location(msg: dict, cc: ChannelCheck, ctx: str, problems: Problems) -> None:
    if msg.get("frame_id") != f"ac{cc.ac}":
        problems.add(f"{ctx}: frame_id {_jtext(msg.get('frame_id'))}, expected \"ac{cc.ac}\"")
    lat, lon = msg.get("latitude"), msg.get("longitude")
    if not (isinstance(lat, (int, float)) and -90.0 <= lat <= 90.0):
        problems.add(f"{ctx}: latitude {_jtext(lat)}")
    if not (isinstance(lon, (int, float)) and -180.0 <= lon <= 180.0):
        problems.add(f"{ctx}: longitude {_jtext(lon)}")
    cov = msg.get("position_covariance")
    if not (isinstance(cov, list) and len(cov) == 9):
        problems.add(f"{ctx}: position_covariance {_jtext(cov)} is not 9 numbers")
    ts = msg.get("timestamp")
    if not (
        isinstance(ts, dict)
        and isinstance(ts.get("sec"), int)
        and isinstance(ts.get("nsec"), int)
        and 0 <= ts["nsec"] < 1_000_000_000
    ):
        problems.add(f"{ctx}: timestamp {_jtext(ts)}")


# --------------------------------------------------------------------------------------
# Reading the MCAP.
# --------------------------------------------------------------------------------------


def indexed_pass(path: str, problems: Problems):
    """Reads through the summary and chunk indexes; returns {topic: (count, digest)}."""
    out: dict = {}
    with open(path, "rb") as f:
        data_tail = None
        try:
            f.seek(-len(MCAP_MAGIC), 2)
            data_tail = f.read()
        except OSError:
            pass
        if data_tail != MCAP_MAGIC:
            problems.add(f"{path}: does not end with the MCAP magic (not finished?)")
            return None, None
        f.seek(0)
        reader = SeekingReader(f, validate_crcs=True)
        reader.get_header()
        summary = reader.get_summary()
        if summary is None:
            problems.add(f"{path}: no summary section (footer summary_start is 0)")
            return None, None
        if summary.statistics is None:
            problems.add(f"{path}: the summary has no statistics record")
        if summary.statistics is not None and summary.statistics.chunk_count and not summary.chunk_indexes:
            problems.add(f"{path}: {summary.statistics.chunk_count} chunks but no chunk index in the summary")
        digests: dict = {}
        for _schema, channel, message in reader.iter_messages(log_time_order=False):
            d = digests.get(channel.topic)
            if d is None:
                d = digests[channel.topic] = [channel.topic, 0, hashlib.sha256()]
            d[1] += 1
            d[2].update(message.log_time.to_bytes(8, "little"))
            d[2].update(message.data)
        for topic, count, h in digests.values():
            out[topic] = (count, h.hexdigest())
        return out, summary


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("mcap")
    ap.add_argument("lines")
    ap.add_argument("--messages", help="messages.xml of the run (checks the schemas against it)")
    ap.add_argument(
        "--log-times",
        choices=["any", "replay", "wall"],
        default="any",
        help="replay: log times are a PPRZLOG's (below one year); wall: ns since the epoch, after 2020",
    )
    ap.add_argument(
        "--allow-topic",
        action="append",
        default=[],
        metavar="REGEX",
        help="also accept topics matching this (whole-topic) regular expression: json and "
        "jsonschema checked, not compared with the lines",
    )
    ap.add_argument("--max-reported", type=int, default=MAX_REPORTED)
    args = ap.parse_args(argv)
    try:
        allowed = [re.compile(r) for r in args.allow_topic]
    except re.error as e:
        print(f"check_mcap.py: --allow-topic: {e}", file=sys.stderr)
        return 2

    problems = Problems(args.max_reported)
    xml = None
    if args.messages:
        try:
            xml = read_messages_xml(args.messages)
        except (OSError, ET.ParseError, ValueError) as e:
            print(f"check_mcap.py: cannot read {args.messages}: {e}", file=sys.stderr)
            return 2
    try:
        lines_by_topic, line_stats = read_lines(args.lines, problems)
    except (OSError, UnicodeDecodeError) as e:
        print(f"check_mcap.py: cannot read {args.lines}: {e}", file=sys.stderr)
        return 2

    try:
        indexed, summary = indexed_pass(args.mcap, problems)
    except (McapError, OSError, ValueError, KeyError, EOFError, struct.error) as e:
        problems.add(f"{args.mcap}: unreadable through its summary: {type(e).__name__}: {e}")
        indexed, summary = None, None

    channels: dict = {}
    by_topic: dict = {}  # topic -> [messages so far, digest]
    total = 0
    now_ns = time.time_ns()
    try:
        with open(args.mcap, "rb") as f:
            reader = NonSeekingReader(f, validate_crcs=True)
            for schema, channel, message in reader.iter_messages(log_time_order=False):
                cc = channels.get(channel.id)
                problems.topic = channel.topic
                if cc is None:
                    cc = channels[channel.id] = check_channel(schema, channel, problems, xml, allowed)
                cc.count += 1
                total += 1
                # Per topic (a topic could have several channels): its n-th message.
                ts = by_topic.get(cc.topic)
                if ts is None:
                    ts = by_topic[cc.topic] = [0, hashlib.sha256()]
                n = ts[0]
                ts[0] += 1
                ts[1].update(message.log_time.to_bytes(8, "little"))
                ts[1].update(message.data)
                ctx = f"{cc.topic} #{n + 1}"
                lt = message.log_time
                if args.log_times == "replay" and lt >= 365 * 86400 * 10**9:
                    problems.add(f"{ctx}: log time {lt} ns is not a replay time (below a year)")
                elif args.log_times == "wall" and not (1_577_836_800 * 10**9 <= lt <= now_ns + 86400 * 10**9):
                    problems.add(f"{ctx}: log time {lt} ns is not a reception time since the epoch")
                try:
                    msg = loads(message.data)
                except (ValueError, UnicodeDecodeError) as e:
                    problems.add(f"{ctx}: not JSON: {e}")
                    continue
                if cc.validator is not None:
                    ok = cc.valid_cache.get(message.data)
                    if ok is None:
                        ok = cc.validator.is_valid(msg)
                        if len(cc.valid_cache) < 4096:
                            cc.valid_cache[message.data] = ok
                    if not ok:
                        err = jsonschema.exceptions.best_match(cc.validator.iter_errors(msg))
                        path = "/".join(str(p) for p in err.absolute_path)
                        problems.add(f"{ctx}: does not validate against {schema.name}: {path}: {err.message}")
                if cc.kind == "location":
                    if isinstance(msg, dict):
                        check_location(msg, cc, ctx, problems)
                    continue
                if cc.kind != "message":
                    continue
                lines = lines_by_topic.get(cc.topic, ())
                if n >= len(lines):
                    continue  # counted below
                line = lines[n]
                try:
                    parsed = parse_body(line.body)
                except ValueError as e:
                    problems.add(f"line {line.lineno}: {e}")
                    continue
                if not cc.described:
                    cc.described = True
                    check_descriptions_line(cc, parsed, problems)
                if not isinstance(msg, dict):
                    problems.add(f"{ctx}: not a JSON object")
                    continue
                xml_fields = xml.get(cc.key) if xml is not None else None
                compare_message(msg, parsed, f"{ctx} (line {line.lineno})", problems, xml_fields)
    except (McapError, OSError, ValueError, KeyError, EOFError, struct.error) as e:
        problems.topic = None
        problems.add(f"{args.mcap}: unreadable as a stream: {type(e).__name__}: {e}")

    problems.topic = None
    # Channels without any message are checked too.
    if summary is not None:
        for cid, ch in sorted(summary.channels.items()):
            if cid not in channels:
                sch = summary.schemas.get(ch.schema_id) if ch.schema_id else None
                channels[cid] = check_channel(sch, ch, problems, xml, allowed)

    # Counts per topic: MCAP against lines.
    mcap_counts = Counter()
    for cc in channels.values():
        mcap_counts[cc.topic] += cc.count
    message_topics = {cc.topic for cc in channels.values() if cc.kind == "message"}
    for topic in sorted(set(lines_by_topic) | message_topics):
        nl, nm = len(lines_by_topic.get(topic, ())), mcap_counts.get(topic, 0)
        if nl != nm:
            problems.add_count(topic, f"{topic}: {nm} messages in the MCAP, {nl} lines")

    # The indexed reading and the summary agree with the stream.
    if indexed is not None:
        stream = {t: (c, h.hexdigest()) for t, (c, h) in by_topic.items()}
        for topic in sorted(set(stream) | set(indexed)):
            s, i = stream.get(topic, (0, None)), indexed.get(topic, (0, None))
            if s[0] != i[0]:
                problems.add(f"{topic}: {s[0]} messages read as a stream, {i[0]} through the indexes")
            elif s[1] != i[1] and s[0]:
                problems.add(f"{topic}: the messages read through the indexes differ from the stream's")
        stats = summary.statistics if summary is not None else None
        if stats is not None:
            if stats.message_count != total:
                problems.add(f"{args.mcap}: statistics say {stats.message_count} messages, the file has {total}")
            by_id = {cid: cc.count for cid, cc in channels.items()}
            for cid, c in stats.channel_message_counts.items():
                if by_id.get(cid, 0) != c:
                    problems.add(f"{args.mcap}: statistics say {c} messages on channel {cid}, the file has {by_id.get(cid, 0)}")

    if problems.count:
        problems.report()
        print(f"FAILED: {problems.count} mismatches")
        return 1
    kinds = Counter(cc.kind for cc in channels.values())
    aux = Counter()
    for cc in channels.values():
        aux[cc.kind] += cc.count
    print(f"topics {len(set(cc.topic for cc in channels.values()))}, messages {total}, checked")
    print(
        f"  lines {line_stats['messages']} (unknown {line_stats['unknown']}, malformed {line_stats['malformed']}),"
        f" message topics {kinds['message']}, location {aux['location']}, link {aux['link']}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
