#!/usr/bin/env python3
"""Self-test of check_mcap.py, without the monitor.

    selftest.py [--count N] [--keep DIR]

Writes, with PyPI's `mcap` writer, a small recording as the contract describes it
(json messages, jsonschema schemas, location and link topics) with the matching
`--lines` text (numbers, arrays, escaped text, labels, units, converted values, cut
lines, unknown and malformed messages), checks that check_mcap.py accepts it, then
that it rejects altered versions of it. Exits 0 when every case behaves.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import random
import re
import struct
import subprocess
import sys
import tempfile
from decimal import Decimal

from mcap.writer import CompressionType, IndexType, Writer

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import check_mcap  # noqa: E402

# --------------------------------------------------------------------------------------
# What format.rs prints, redone here for the test data.
# --------------------------------------------------------------------------------------


def f32(x: float) -> float:
    try:
        return struct.unpack("<f", struct.pack("<f", x))[0]
    except OverflowError:
        return math.copysign(math.inf, x)


def shortest_f32(x: float) -> str:
    """The shortest decimal that reads back as the f32 `x` (scientific notation)."""
    for k in range(1, 10):
        s = "%.*e" % (k - 1, x)
        if f32(float(s)) == x:
            return s
    return repr(x)


def plain(s: str) -> str:
    """A decimal without exponent, without trailing zeros: as Rust's Display."""
    out = format(Decimal(s), "f")
    if "." in out:
        out = out.rstrip("0").rstrip(".")
    if out in ("-0", "0") and s.startswith("-"):
        return "-0"
    return out


def display(v, base: str) -> str:
    if base in ("float", "double"):
        if math.isnan(v):
            return "NaN"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return plain(shortest_f32(v) if base == "float" else repr(v))
    return str(v)


def json_number(v, base: str):
    if base in ("float", "double"):
        if not math.isfinite(v):
            return None
        # What serde_json writes for an f32: its shortest form, read back as a double.
        return float(shortest_f32(v)) if base == "float" else v
    return v


def quoted(text: str) -> str:
    return '"' + check_mcap.escape_quoted_inner(text) + '"'


def token(text: str) -> str:
    out = []
    for c in text:
        if check_mcap.is_unsafe(c) or c == "\\" or c in check_mcap._RUST_WHITESPACE or c in '=,"[]()':
            check_mcap._push_escape(out, c)
        else:
            out.append(c)
    return "".join(out)


def alt_precision(coef: float) -> int:
    c = abs(coef)
    d = math.ceil(-math.log10(c) - 1e-9)
    return min(d, 12) if d > 3 else 3


# A message set: (class, name, [(field, type, unit, alt_unit, coef, values)]).
MESSAGES = [
    (
        "telemetry",
        "ATTITUDE",
        [
            ("phi", "float", "rad", "deg", 180.0 / math.pi, []),
            ("psi", "float", "rad", "deg", 180.0 / math.pi, []),
            ("theta", "float", "rad", "deg", 180.0 / math.pi, []),
        ],
    ),
    (
        "telemetry",
        "GPS_INT",
        [
            ("lat", "int32", "1e7deg", "deg", 1e-7, []),
            ("lon", "int32", "1e7deg", "deg", 1e-7, []),
            ("alt", "int32", "mm", "m", 0.001, []),
            ("fix", "uint8", None, None, None, ["NONE", "2D", "3D"]),
            ("tow", "uint64", "ms", None, None, []),
        ],
    ),
    (
        "telemetry",
        "MIXED",
        [
            ("accel", "int16[3]", "mm/s2", "m/s2", 0.001, []),
            ("md5", "uint8[]", None, None, None, []),
            ("speeds", "int16[]", "cm/s", "m/s", 0.01, []),
            ("name", "char[8]", None, None, None, []),
            ("c", "char", None, None, None, []),
            ("d", "double", "s", None, None, []),
            ("state", "uint8", "none", None, None, ["OFF", "ON"]),
            ("big", "int64", None, None, None, []),
        ],
    ),
    ("telemetry", "INFO_MSG", [("msg", "char[]", None, None, None, [])]),
    ("telemetry", "PONG", []),
    (
        "datalink",
        "LONG",
        [("v", "double[30]", None, None, None, []), ("w", "uint8", None, None, None, [])],
    ),
    ("datalink", "LONGTEXT", [("t", "char[]", None, None, None, []), ("u", "uint8", "m", "cm", 100.0, [])]),
]

MESSAGES_XML_HEAD = '<?xml version="1.0"?>\n<protocol>\n'


def messages_xml() -> str:
    out = [MESSAGES_XML_HEAD]
    classes = {}
    for cls, name, fields in MESSAGES:
        classes.setdefault(cls, []).append((name, fields))
    for ci, (cls, msgs) in enumerate(classes.items(), 1):
        out.append(f'  <msg_class name="{cls}" id="{ci}">\n')
        for mi, (name, fields) in enumerate(msgs, 1):
            out.append(f'    <message name="{name}" id="{mi}">\n')
            for f, ty, unit, alt, coef, values in fields:
                attrs = f'name="{f}" type="{ty}"'
                if unit:
                    attrs += f' unit="{unit}"'
                if alt:
                    attrs += f' alt_unit="{alt}" alt_unit_coef="{coef!r}"'
                if values:
                    attrs += f' values="{"|".join(values)}"'
                out.append(f"      <field {attrs}/>\n")
            out.append("    </message>\n")
        out.append("  </msg_class>\n")
    out.append("</protocol>\n")
    return "".join(out)


def base_of(ty: str):
    b, kind, size = check_mcap.parse_field_type(ty)
    return b, kind, size


def schema_for(cls: str, name: str, fields) -> dict:
    props = {}
    for f, ty, unit, alt, coef, values in fields:
        b, kind, size = base_of(ty)
        desc = []
        if unit:
            desc.append(f"unit: {unit}")
        if values:
            desc.append(", ".join(f"{i}={v}" for i, v in enumerate(values)))
        if b == "char":
            p = {"type": "string"}
        else:
            jt = "number" if b in ("float", "double") else "integer"
            item = {"type": [jt, "null"]} if jt == "number" else {"type": jt}
            if kind == "scalar":
                p = dict(item)
            elif kind == "array":
                p = {"type": "array", "items": item, "minItems": size, "maxItems": size}
            else:
                p = {"type": "array", "items": item, "maxItems": 255}
        p["description"] = "; ".join(desc) or f
        props[f] = p
        if alt and coef and b != "char":
            a = {"type": ["number", "null"]} if kind == "scalar" else {"type": "array", "items": {"type": ["number", "null"]}}
            a["description"] = f"{f} in {alt}"
            props[f + "_alt"] = a
    return {
        "$schema": check_mcap.DRAFT_2020_12,
        "title": f"{cls}.{name}",
        "description": f"{name} message",
        "type": "object",
        "properties": props,
        "required": [f[0] for f in fields],
        "additionalProperties": False,
    }


LOCATION_SCHEMA = {
    "$schema": check_mcap.DRAFT_2020_12,
    "title": "foxglove.LocationFix",
    "type": "object",
    "properties": {
        "timestamp": {
            "type": "object",
            "properties": {"sec": {"type": "integer"}, "nsec": {"type": "integer"}},
            "required": ["sec", "nsec"],
        },
        "frame_id": {"type": "string"},
        "latitude": {"type": "number"},
        "longitude": {"type": "number"},
        "altitude": {"type": "number"},
        "position_covariance": {"type": "array", "items": {"type": "number"}, "minItems": 9, "maxItems": 9},
        "position_covariance_type": {"type": "integer"},
    },
}
LINK_SCHEMA = {
    "$schema": check_mcap.DRAFT_2020_12,
    "title": "pprz.LinkStats",
    "type": "object",
    "properties": {"received": {"type": "integer"}, "lost": {"type": "integer"}},
    "required": ["received", "lost"],
}

HOSTILE = [
    "ok",
    "hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;t\x07",
    'quote " back\\slash = , [x] (y)',
    "\u202eevil\u200b\ufeff\x85 é ünïcødé \ufffd",
    "x <error: not really> y",
    "",
    "a\x00b",
]


def random_value(rng: random.Random, b: str):
    if b == "float":
        r = rng.random()
        if r < 0.03:
            return rng.choice([math.nan, math.inf, -math.inf, -0.0, 0.0, 1.0, 1e-7, 3.4028234663852886e38])
        return f32(rng.uniform(-4, 4) * 10 ** rng.randint(-3, 3))
    if b == "double":
        if rng.random() < 0.05:
            return rng.choice([math.nan, -0.0, 1e300, 5e-324, 0.1])
        return rng.uniform(-1e6, 1e6)
    lo, hi = {
        "uint8": (0, 255),
        "int8": (-128, 127),
        "uint16": (0, 65535),
        "int16": (-32768, 32767),
        "uint32": (0, 2**32 - 1),
        "int32": (-(2**31), 2**31 - 1),
        "uint64": (0, 2**64 - 1),
        "int64": (-(2**63), 2**63 - 1),
    }[b]
    return rng.randint(lo, hi)


def make_message(rng: random.Random, cls: str, name: str, fields):
    """(json dict, line body) of one message."""
    obj = {}
    parts = []
    for f, ty, unit, alt, coef, values in fields:
        b, kind, size = base_of(ty)
        if b == "char":
            if kind == "scalar":
                ch = chr(rng.choice([0x41, 0x1B, 0x22, 0x5C, 0x20, 0x3D, 0xE9, 0x00]))
                obj[f] = ch
                s = f"{token(f)}={quoted(ch)}"
            else:
                if name == "LONGTEXT":
                    text = "".join(rng.choice("ab \n\"\\é\x1b=") for _ in range(rng.randint(1500, 2100)))
                else:
                    text = rng.choice(HOSTILE)
                if kind == "array":
                    text = text[:size]
                text = text.rstrip("\x00")
                obj[f] = text
                s = f"{token(f)}={quoted(text)}"
        else:
            if kind == "scalar":
                vals = [random_value(rng, b)]
            elif kind == "array":
                vals = [random_value(rng, b) for _ in range(size)]
            else:
                vals = [random_value(rng, b) for _ in range(rng.choice([0, 0, 1, 5, 16]))]
            jvals = [json_number(v, b) for v in vals]
            text_vals = ",".join(display(v, b) for v in vals)
            obj[f] = jvals[0] if kind == "scalar" else jvals
            s = f"{token(f)}={text_vals}"
            if values and kind == "scalar" and 0 <= vals[0] < len(values):
                s += f"({token(values[vals[0]])})"
        if check_mcap.is_unit(unit):
            s += f" [{token(unit)}]"
        if alt and coef and b != "char":
            prec = alt_precision(coef)
            conv = []
            jalt = []
            for v in vals:
                x = float(v) * coef  # as f64, like FieldDescriptor::to_alt_unit
                conv.append(fmt_fixed(x, prec))
                jalt.append(x if math.isfinite(x) else None)
            obj[f + "_alt"] = jalt[0] if kind == "scalar" else jalt
            if conv:
                s += f" {','.join(conv)} {token(alt)}"
        parts.append(s)
    body = " ".join(parts)
    if len(body.encode()) > check_mcap.MAX_FIELDS_LEN:
        b = body.encode()
        end = check_mcap.MAX_FIELDS_LEN - 3
        while end > 0 and (b[end] & 0xC0) == 0x80:
            end -= 1
        body = b[:end].decode() + "..."
    return obj, body


def fmt_fixed(x: float, prec: int) -> str:
    if math.isnan(x):
        return "NaN"
    if math.isinf(x):
        return "inf" if x > 0 else "-inf"
    # Rust rounds the exact binary value, like Decimal does.
    return format(Decimal(x), f".{prec}f")


# --------------------------------------------------------------------------------------
# The recording and its variants.
# --------------------------------------------------------------------------------------


class Recording:
    """Messages as (topic, log_time, json bytes) and lines, altered before writing."""

    def __init__(self, count: int, seed: int = 1):
        rng = random.Random(seed)
        self.schemas = {}  # topic -> (name, encoding, data bytes, message_encoding)
        self.messages = []  # [topic, log_time, data bytes]
        self.lines = []
        t = 0
        for i in range(count):
            cls, name, fields = rng.choice(MESSAGES)
            src = rng.choice([7, 7, 7, 12, 0])
            topic = f"/ac/{src}/{cls}/{name}"
            obj, body = make_message(rng, cls, name, fields)
            t += rng.randint(0, 3) * 100_000  # 100 µs ticks
            if topic not in self.schemas:
                self.schemas[topic] = [
                    f"pprz.{cls}.{name}",
                    "jsonschema",
                    json.dumps(schema_for(cls, name, fields)).encode(),
                    "json",
                ]
            self.messages.append([topic, t, json.dumps(obj, allow_nan=False).encode()])
            self.lines.append(f"{src} {token(cls)} {token(name)} {body}" if body else f"{src} {cls} {name}")
            if i % 97 == 5:
                self.lines.append(f"{src} class9 id=42 unknown message (3 bytes)")
            if i % 89 == 7:
                self.lines.append(f"{src} telemetry GPS_INT lat=1 [1e7deg] 0.0000001 deg <error: payload truncated: needs at least 8 bytes, got 4>")
            if name == "GPS_INT" and obj["fix"] == 2:
                loc = f"/ac/{src}/location"
                self.schemas.setdefault(loc, ["foxglove.LocationFix", "jsonschema", json.dumps(LOCATION_SCHEMA).encode(), "json"])
                fix = {
                    "timestamp": {"sec": t // 10**9, "nsec": t % 10**9},
                    "frame_id": f"ac{src}",
                    "latitude": max(-90.0, min(90.0, obj["lat_alt"])),
                    "longitude": max(-180.0, min(180.0, obj["lon_alt"])),
                    "altitude": obj["alt_alt"],
                    "position_covariance": [0.0] * 9,
                    "position_covariance_type": 0,
                }
                self.messages.append([loc, t, json.dumps(fix).encode()])
            if i % 500 == 0:
                link = f"/ac/{src}/link"
                self.schemas.setdefault(link, ["pprz.LinkStats", "jsonschema", json.dumps(LINK_SCHEMA).encode(), "json"])
                self.messages.append([link, t, json.dumps({"received": i, "lost": 0}).encode()])

    def write(self, path: str, lines_path: str, summary: bool = True, truncate: int = 0, split: str = "") -> None:
        with open(path, "wb") as out:
            kw = {}
            if not summary:
                kw = dict(
                    index_types=IndexType.NONE,
                    repeat_channels=False,
                    repeat_schemas=False,
                    use_statistics=False,
                    use_summary_offsets=False,
                )
            w = Writer(out, chunk_size=64 * 1024, compression=CompressionType.ZSTD, **kw)
            w.start(profile="", library="pprz selftest")
            channels = {}
            for topic, (name, enc, data, menc) in self.schemas.items():
                sid = w.register_schema(name, enc, data) if name is not None else 0
                channels[topic] = w.register_channel(topic, menc, sid)
            second = None
            for seq, (topic, t, data) in enumerate(self.messages):
                channel = channels[topic]
                if topic == split:
                    # From the 3rd message on, a second channel of the same topic.
                    if second is None:
                        second = (channel, 0)
                    if second[1] >= 2:
                        if not isinstance(second[0], tuple):
                            name, enc, sdata, menc = self.schemas[topic]
                            second = ((w.register_channel(topic, menc, w.register_schema(name, enc, sdata)),), second[1])
                        channel = second[0][0]
                    second = (second[0], second[1] + 1)
                w.add_message(channel, log_time=t, data=data, publish_time=t, sequence=seq)
            w.finish()
        if truncate:
            with open(path, "r+b") as f:
                f.seek(0, 2)
                f.truncate(f.tell() - truncate)
        with open(lines_path, "w", encoding="utf-8", newline="\n") as f:
            f.write("".join(l + "\n" for l in self.lines))

    def find(self, topic_part: str, n: int = 0) -> int:
        """Index of the n-th message whose topic contains `topic_part`."""
        seen = 0
        for i, m in enumerate(self.messages):
            if topic_part in m[0]:
                if seen == n:
                    return i
                seen += 1
        raise KeyError(topic_part)

    def edit(self, i: int, fn) -> None:
        obj = json.loads(self.messages[i][2])
        fn(obj)
        self.messages[i][2] = json.dumps(obj).encode()


def run_check(mcap: str, lines: str, *extra: str):
    p = subprocess.run(
        [sys.executable, os.path.join(HERE, "check_mcap.py"), mcap, lines, *extra],
        capture_output=True,
        text=True,
        timeout=600,
    )
    return p.returncode, p.stdout + p.stderr


def parser_cases() -> list:
    """The lines of format.rs's own tests, parsed."""
    failures = []

    def expect(cond, what):
        if not cond:
            failures.append(what)

    p = check_mcap.parse_body(
        r'msg="hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;t\x07" name="ab" c="\x1b"'
    )
    expect([f.name for f in p.fields] == ["msg", "name", "c"], f"hostile names {p.fields}")
    expect(
        check_mcap.unescape(p.fields[0].raw_value[1:-1]) == "hi\n7 telemetry ALIVE md5sum=FORGED\x1b[2J\x1b]0;t\x07",
        "hostile text",
    )
    p = check_mcap.parse_body(
        "lat=434629172 [1e7deg] 43.4629172 deg values=1,2,165 att=0.5,-1 [rad] 28.648,-57.296 deg n=-1"
    )
    got = [(f.name, f.raw_value, f.unit, f.conv, f.alt_unit) for f in p.fields]
    expect(
        got
        == [
            ("lat", "434629172", "1e7deg", "43.4629172", "deg"),
            ("values", "1,2,165", None, None, None),
            ("att", "0.5,-1", "rad", "28.648,-57.296", "deg"),
            ("n", "-1", None, None, None),
        ],
        f"units {got}",
    )
    p = check_mcap.parse_body(r"f\x1b\x3d=0(A\x20B\x07) [m\n7\x20telemetry\x20FORGED] 0.000 \x1b\x5b2J")
    f = p.fields[0]
    expect(
        (f.name, f.raw_value, check_mcap.unescape(f.label), check_mcap.unescape(f.unit), f.conv, check_mcap.unescape(f.alt_unit))
        == ("f\x1b=", "0", "A B\x07", "m\n7 telemetry FORGED", "0.000", "\x1b[2J"),
        f"escaped tokens {f}",
    )
    p = check_mcap.parse_body("east=10000 [cm] 100.000 m state=1(ON) empty= x=NaN [m] NaN m")
    got = [(f.name, f.raw_value, f.label, f.conv) for f in p.fields]
    expect(
        got == [("east", "10000", None, "100.000"), ("state", "1", "ON", None), ("empty", "", None, None), ("x", "NaN", None, "NaN")],
        f"labels {got}",
    )
    for bad in ["a=1 junk", 'a="unterminated', "a=1 [m"]:
        try:
            check_mcap.parse_body(bad)
            failures.append(f"accepted {bad!r}")
        except ValueError:
            pass
    expect(check_mcap._has_error("a=1 <error: payload truncated>"), "error detected")
    expect(not check_mcap._has_error('msg="x <error: y>"'), "error in text ignored")
    for s in ["a\x1b\u202e\\\"é\x85\u2028 ", "\x00\x7f\ufffd"]:
        expect(check_mcap.unescape(check_mcap.escape_quoted_inner(s)) == s, f"escape round trip {s!r}")
    expect(check_mcap.unescape(token("a b=c,d\"[e](f)")) == "a b=c,d\"[e](f)", "token round trip")
    expect(token("a b=c,d\"[e](f)") == r'a\x20b\x3dc\x2cd\"\x5be\x5d\x28f\x29', "token as escape.rs")
    expect(token("\u00a0") == r"\u{a0}", "nbsp token")
    return failures


# --------------------------------------------------------------------------------------
# With the real monitor: its --lines output against the MCAP the contract describes.
# --------------------------------------------------------------------------------------

PACK = {
    "uint8": "B", "int8": "b", "uint16": "H", "int16": "h", "uint32": "I", "int32": "i",
    "uint64": "Q", "int64": "q", "float": "f", "double": "d",
}


def wire_message(rng: random.Random, fields):
    """(payload, json object, line body) of one message, its values drawn at random."""
    payload = bytearray()
    obj = {}
    parts = []
    for f, ty, unit, alt, coef, values in fields:
        b, kind, size = base_of(ty)
        if b == "char":
            if kind == "scalar":
                byte = rng.choice([0x41, 0x1B, 0x22, 0x5C, 0x20, 0x3D, 0xE9, 0x00, 0x85])
                payload.append(byte)
                ch = chr(byte)  # format.rs: char::from(u8)
                obj[f] = ch
                parts.append(f"{token(f)}={quoted(ch)}")
            else:
                raw = rng.choice(HOSTILE).encode("utf-8")
                if rng.random() < 0.2:
                    raw += bytes([0xFF, 0xC3])  # invalid UTF-8
                if kind == "array":
                    raw = raw[:size].ljust(size, b"\0")
                else:
                    raw = raw[:200]
                    payload.append(len(raw))
                payload += raw
                text = raw.decode("utf-8", "replace").rstrip("\x00")
                obj[f] = text
                parts.append(f"{token(f)}={quoted(text)}")
            if check_mcap.is_unit(unit):
                parts[-1] += f" [{token(unit)}]"
            continue
        if kind == "scalar":
            vals = [random_value(rng, b)]
        elif kind == "array":
            vals = [random_value(rng, b) for _ in range(size)]
        else:
            vals = [random_value(rng, b) for _ in range(rng.choice([0, 1, 5, 16]))]
            payload.append(len(vals))
        if b == "double" and rng.random() < 0.3:
            vals = [rng.choice([1e300, -1e300, 5e-324]) for _ in vals]
        for v in vals:
            payload += struct.pack("<" + PACK[b], v)
        jvals = [json_number(v, b) for v in vals]
        obj[f] = jvals[0] if kind == "scalar" else jvals
        s = f"{token(f)}={','.join(display(v, b) for v in vals)}"
        if values and kind == "scalar" and 0 <= vals[0] < len(values):
            s += f"({token(values[vals[0]])})"
        if check_mcap.is_unit(unit):
            s += f" [{token(unit)}]"
        if alt and coef:
            prec = alt_precision(coef)
            xs = [float(v) * coef for v in vals]
            obj[f + "_alt"] = [x if math.isfinite(x) else None for x in xs]
            if kind == "scalar":
                obj[f + "_alt"] = obj[f + "_alt"][0]
            if xs:
                s += f" {','.join(fmt_fixed(x, prec) for x in xs)} {token(alt)}"
        parts.append(s)
    body = " ".join(parts)
    if len(body.encode()) > check_mcap.MAX_FIELDS_LEN:
        b8 = body.encode()
        end = check_mcap.MAX_FIELDS_LEN - 3
        while end > 0 and (b8[end] & 0xC0) == 0x80:
            end -= 1
        body = b8[:end].decode() + "..."
    return bytes(payload), obj, body


def pprz2_frame(source: int, class_id: int, msg_id: int, payload: bytes) -> bytes:
    data = bytes([source, 0, class_id, msg_id]) + payload
    length = len(data) + 4
    assert length <= 255
    ck_a = ck_b = 0
    for byte in bytes([length]) + data:
        ck_a = (ck_a + byte) & 0xFF
        ck_b = (ck_b + ck_a) & 0xFF
    return bytes([0x99, length]) + data + bytes([ck_a, ck_b])


def with_monitor(monitor: str, d: str, xml_path: str, count: int) -> list:
    """Frames of random messages through the real `pprz-monitor --lines`; the MCAP the
    contract describes is written here. check_mcap.py must accept the pair, and the
    lines must be those this test expects (its reading of format.rs)."""
    failures = []
    rng = random.Random(7)
    ids = {}
    classes = {}
    for cls, name, fields in MESSAGES:
        cid = classes.setdefault(cls, len(classes) + 1)
        ids[(cls, name)] = (cid, sum(1 for c, _n, _f in MESSAGES[: MESSAGES.index((cls, name, fields))] if c == cls) + 1)
    rec = Recording(0)
    frames = bytearray()
    expected = []
    for i in range(count):
        cls, name, fields = rng.choice(MESSAGES)
        cid, mid = ids[(cls, name)]
        src = rng.choice([7, 12])
        payload, obj, body = wire_message(rng, fields)
        if len(payload) > 247:
            continue
        frames += pprz2_frame(src, cid, mid, payload)
        topic = f"/ac/{src}/{cls}/{name}"
        if topic not in rec.schemas:
            rec.schemas[topic] = [f"pprz.{cls}.{name}", "jsonschema", json.dumps(schema_for(cls, name, fields)).encode(), "json"]
        rec.messages.append([topic, i * 1000, json.dumps(obj, allow_nan=False).encode()])
        expected.append(f"{src} {token(cls)} {token(name)} {body}" if body else f"{src} {cls} {name}")
    frames += pprz2_frame(7, 1, 200, b"\x01\x02")  # unknown
    expected.append("7 class1 id=200 unknown message (2 bytes)")
    bin_path = os.path.join(d, "monitor-input.pprz2")
    with open(bin_path, "wb") as f:
        f.write(frames)
    p = subprocess.run(
        [monitor, "--messages", xml_path, "--file", bin_path, "--transport", "pprz2", "--lines"],
        capture_output=True,
        timeout=600,
    )
    got = p.stdout.decode("utf-8").split("\n")
    if got and got[-1] == "":
        got.pop()
    if p.returncode != 0 or len(got) != len(expected):
        failures.append(f"monitor: exit {p.returncode}, {len(got)} lines for {len(expected)} frames: {p.stderr.decode()[-500:]}")
        return failures
    diffs = [(k, e, g) for k, (e, g) in enumerate(zip(expected, got)) if e != g]
    for k, e, g in diffs[:5]:
        print(f"FAIL line {k + 1} differs from this test's reading of format.rs:\n  expected {e[:300]}\n  monitor  {g[:300]}")
    if diffs:
        failures.append(f"monitor: {len(diffs)} lines differ")
    rec.lines = got
    mc, ln = os.path.join(d, "monitor.mcap"), os.path.join(d, "monitor.txt")
    rec.write(mc, ln)
    code, out = run_check(mc, ln, "--messages", xml_path)
    print(f"{'ok  ' if code == 0 else 'FAIL'} real monitor lines ({len(got)}) against the contract's MCAP: exit {code}")
    print("     " + out.strip()[-3000:].replace("\n", "\n     "))
    if code != 0:
        failures.append("monitor: check_mcap.py rejects the real lines")
    return failures


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, default=3000)
    ap.add_argument("--keep", help="write the files to this directory and keep them")
    ap.add_argument(
        "--monitor",
        help="a pprz-monitor binary: also check its real --lines output (of random frames) "
        "against the MCAP the contract describes",
    )
    args = ap.parse_args()

    failures = parser_cases()
    tmp_ctx = tempfile.TemporaryDirectory(prefix="pprz-fox-selftest-")
    d = args.keep or tmp_ctx.name
    os.makedirs(d, exist_ok=True)
    xml_path = os.path.join(d, "messages.xml")
    with open(xml_path, "w") as f:
        f.write(messages_xml())

    def case(name: str, expect_ok: bool, expect_text: str = "", alter=None, write_kw=None, extra=(), lines_fn=None):
        rec = Recording(args.count)
        if alter:
            alter(rec)
        if lines_fn:
            lines_fn(rec)
        mc, ln = os.path.join(d, f"{name}.mcap"), os.path.join(d, f"{name}.txt")
        rec.write(mc, ln, **(write_kw or {}))
        code, out = run_check(mc, ln, "--messages", xml_path, *extra)
        ok = (code == 0) == expect_ok and (code in (0, 1)) and expect_text in out
        if expect_ok and "checked" not in out:
            ok = False
        print(f"{'ok  ' if ok else 'FAIL'} {name}: exit {code}" + ("" if ok else "\n" + out[-3000:]))
        if not ok:
            failures.append(name)
        return out

    out = case("good", True)
    print("     " + out.strip().replace("\n", "\n     "))
    case("good-replay-times", True, extra=("--log-times", "replay"))
    case("wall-times-expected", False, "not a reception time", extra=("--log-times", "wall"))
    case("one-message-missing", False, "messages in the MCAP", alter=lambda r: r.messages.pop(r.find("ATTITUDE", 3)))
    case("one-line-missing", False, "lines", lines_fn=lambda r: r.lines.pop(next(i for i, l in enumerate(r.lines) if " ATTITUDE " in l)))

    def wrong_value(r):
        r.edit(r.find("GPS_INT", 2), lambda o: o.update(lat=o["lat"] + 1))

    case("integer-off-by-one", False, "lat", alter=wrong_value)

    def widened(r):
        i = r.find("/ac/7/telemetry/ATTITUDE", 1)
        r.edit(i, lambda o: o.update(phi=(struct.unpack("<f", struct.pack("<f", 0.1))[0])))
        # and the line says 0.1 for that message
        n = 0
        for k, l in enumerate(r.lines):
            if l.startswith("7 telemetry ATTITUDE "):
                if n == 1:
                    r.lines[k] = re.sub(r"phi=\S+ \[rad\] \S+ deg", "phi=0.1 [rad] 5.730 deg", l)
                    break
                n += 1

    case("f32-widened", False, "widened", alter=widened)

    def alt_off(r):
        r.edit(r.find("GPS_INT", 0), lambda o: o.update(alt_alt=o["alt_alt"] + 0.0006))

    case("alt-off-by-more-than-half-unit", False, "alt_alt", alter=alt_off)

    def alt_within(r):
        r.edit(r.find("GPS_INT", 0), lambda o: o.update(alt_alt=o["alt_alt"] + 0.0004))

    case("alt-off-by-less-than-half-unit", True, alter=alt_within)

    def text_changed(r):
        i = next(k for k, m in enumerate(r.messages) if "INFO_MSG" in m[0] and b"FORGED" in m[2])
        r.edit(i, lambda o: o.update(msg=o["msg"].replace("\x1b", "\\x1b")))

    case("text-escaped-twice", False, "msg", alter=text_changed)

    def long_text_changed(r):
        i = r.find("LONGTEXT", 0)
        r.edit(i, lambda o: o.update(t="X" + o["t"][1:]))

    case("cut-text-differs", False, "does not start with", alter=long_text_changed)

    def long_text_tail_changed(r):
        i = r.find("LONGTEXT", 0)
        r.edit(i, lambda o: o.update(t=o["t"][:-1] + "Z"))

    # Text past the 2048-byte cut of the line cannot be compared (the line lost it).
    case("text-after-the-cut", True, alter=long_text_tail_changed)

    def no_schema(r):
        r.schemas["/ac/7/telemetry/ATTITUDE"][0] = None

    case("missing-schema", False, "no schema", alter=no_schema)

    def bad_encoding(r):
        r.schemas["/ac/7/telemetry/GPS_INT"][1] = "protobuf"

    case("schema-encoding", False, "schema encoding", alter=bad_encoding)

    def bad_msg_encoding(r):
        r.schemas["/ac/7/telemetry/GPS_INT"][3] = "cbor"

    case("message-encoding", False, "message encoding", alter=bad_msg_encoding)

    def bad_name(r):
        r.schemas["/ac/7/telemetry/GPS_INT"][0] = "GPS_INT"

    case("schema-name", False, "schema name", alter=bad_name)

    def extra_key(r):
        r.edit(r.find("ATTITUDE", 0), lambda o: o.update(extra=1))

    case("does-not-validate", False, "does not validate", alter=extra_key)

    def nan_literal(r):
        i = r.find("ATTITUDE", 0)
        r.messages[i][2] = r.messages[i][2].replace(b'"phi": ', b'"phi": NaN, "x": ', 1)

    case("nan-literal", False, "not JSON", alter=nan_literal)

    def swapped(r):
        a, b = r.find("/ac/7/telemetry/GPS_INT", 0), r.find("/ac/7/telemetry/GPS_INT", 1)
        r.messages[a][2], r.messages[b][2] = r.messages[b][2], r.messages[a][2]

    case("order-swapped", False, "GPS_INT", alter=swapped)

    def wrong_frame(r):
        r.edit(r.find("location", 0), lambda o: o.update(frame_id="map"))

    case("location-frame", False, "frame_id", alter=wrong_frame)

    def unexpected_topic(r):
        other = {"$schema": check_mcap.DRAFT_2020_12, "type": "object"}
        r.schemas["/other"] = ["x", "jsonschema", json.dumps(other).encode(), "json"]
        r.messages.append(["/other", 0, b"{}"])

    case("unexpected-topic", False, "unexpected topic", alter=unexpected_topic)
    case("allowed-topic", True, alter=unexpected_topic, extra=("--allow-topic", "/oth.*"))
    case("topic-on-two-channels", True, write_kw={"split": "/ac/7/telemetry/GPS_INT"})
    case("topic-on-two-channels-swapped", False, "GPS_INT", alter=swapped, write_kw={"split": "/ac/7/telemetry/GPS_INT"})
    case("no-summary", False, "no summary", write_kw={"summary": False})
    case("truncated-file", False, "", write_kw={"truncate": 40})

    if args.monitor:
        failures += with_monitor(args.monitor, d, xml_path, args.count)

    if failures:
        print(f"selftest FAILED: {', '.join(failures)}")
        return 1
    print("selftest passed")
    return 0


if __name__ == "__main__":
    sys.exit(main())
