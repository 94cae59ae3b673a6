#!/usr/bin/env python3
"""An independent client of the fleet bus, on the official Zenoh Python API
(PyPI eclipse-zenoh), for the tests of pprz-gateway (ground/tests/gateway.rs).

    client.py ENDPOINT [--peer] subscribe KEYEXPR... [--seconds S]
    client.py ENDPOINT setting AC INDEX VALUE SECOND_VALUE
    client.py ENDPOINT hostile AC FLOOD
    client.py ENDPOINT queries AC INDEX N

Every session: client mode (or peer with --peer) connected to ENDPOINT only,
multicast scouting off, no listen endpoint. Output: one JSON object per line on
standard output; `{"event": "ready"}` once the gateway's first counters arrived
(so the subscriptions declared before are known to it).

subscribe: prints every sample of the key expressions (and of the gateway's
counters `pprz/gateway/*/stats`) as {"event": "sample", "key", "payload",
"attachment"} (payload as text, attachment as hex), until standard input closes
or S seconds (default 60) pass.

setting: the uplink round trip of a SETTING command and two settings queries
(see the events printed). hostile: refused commands of each kind, then FLOOD
valid commands as fast as possible. queries: N settings queries at once.
"""

import argparse
import json
import sys
import threading
import time

import zenoh

STATS = "pprz/gateway/*/stats"
REFUSED = "pprz/gateway/*/refused"

_print_lock = threading.Lock()


def emit(obj):
    """One JSON line on standard output."""
    with _print_lock:
        sys.stdout.write(json.dumps(obj) + "\n")
        sys.stdout.flush()


def open_session(endpoint, peer=False):
    """A session connected to `endpoint` only: no scouting, no listening."""
    conf = zenoh.Config()
    conf.insert_json5("mode", json.dumps("peer" if peer else "client"))
    conf.insert_json5("connect/endpoints", json.dumps([endpoint]))
    conf.insert_json5("listen/endpoints", "[]")
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    return zenoh.open(conf)


def text(zbytes):
    """A payload as text (hex when it is not UTF-8)."""
    raw = zbytes.to_bytes()
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError:
        return raw.hex()


def sample_json(sample):
    attachment = sample.attachment
    return {
        "event": "sample",
        "key": str(sample.key_expr),
        "payload": text(sample.payload),
        "attachment": attachment.to_bytes().hex() if attachment is not None else None,
    }


class Ready:
    """Set by the gateway's first counters: subscriptions declared before are known."""

    def __init__(self, session):
        self.event = threading.Event()
        self.sub = session.declare_subscriber(STATS, self._on)

    def _on(self, sample):
        if not self.event.is_set():
            self.event.set()
            emit({"event": "ready"})

    def wait(self, seconds=15):
        if not self.event.wait(seconds):
            emit({"event": "error", "message": "no counters from the gateway"})
            sys.exit(1)


def schemas(session):
    """The gateway's JSON Schemas of every message, by (class, message), as validators."""
    import jsonschema

    out = {}
    for reply in session.get("pprz/schema/**", timeout=10.0):
        if reply.ok is None:
            continue
        _, _, cls, name = str(reply.ok.key_expr).split("/")
        schema = json.loads(text(reply.ok.payload))
        jsonschema.Draft202012Validator.check_schema(schema)
        out[(cls, name)] = jsonschema.Draft202012Validator(schema)
    emit({"event": "schemas", "count": len(out)})
    return out


def checked(validators):
    """A sample handler that validates each message's JSON against its schema."""

    def on(sample):
        event = sample_json(sample)
        parts = event["key"].split("/")
        validator = validators.get((parts[2], parts[3])) if len(parts) == 4 else None
        if validator is None:
            event["schema"] = None
        else:
            errors = [e.message for e in validator.iter_errors(json.loads(event["payload"]))]
            event["schema"] = "invalid: " + "; ".join(errors) if errors else "valid"
        emit(event)

    return on


def subscribe(session, args):
    handler = checked(schemas(session)) if args.schemas else (lambda s: emit(sample_json(s)))
    subs = [session.declare_subscriber(k, handler) for k in args.keys]
    stats = session.declare_subscriber(STATS, lambda s: emit(sample_json(s)))
    ready = Ready(session)
    ready.wait()
    # Until the test closes standard input, or the time is up.
    done = threading.Event()
    threading.Thread(target=lambda: (sys.stdin.read(), done.set()), daemon=True).start()
    done.wait(args.seconds)
    del subs, stats


def reply_json(reply):
    if reply.ok is not None:
        return {"ok": json.loads(text(reply.ok.payload))}
    return {"err": text(reply.err.payload)}


def query(session, key, payload, timeout=10.0):
    """The replies of one get, as JSON."""
    replies = session.get(key, payload=payload, timeout=timeout)
    return [reply_json(r) for r in replies]


def setting(session, args):
    ac, index = args.ac, args.index
    got = threading.Condition()
    values = []

    def on_dl_value(sample):
        fields = json.loads(text(sample.payload))
        with got:
            values.append(fields)
            got.notify_all()

    sub = session.declare_subscriber(f"pprz/{ac}/telemetry/DL_VALUE", on_dl_value)
    Ready(session).wait()
    command = {"index": index, "ac_id": ac, "value": args.value}
    session.put(f"pprz/{ac}/uplink/SETTING", json.dumps(command))
    emit({"event": "put", "fields": command})

    def seen(v):
        return any(f.get("index") == index and f.get("value") == v for f in values)

    with got:
        ok = got.wait_for(lambda: seen(args.value), timeout=10)
    emit({"event": "dl_value", "seen": ok, "values": values})
    key = f"pprz/{ac}/settings/{index}"
    emit({"event": "query", "value": args.value,
          "replies": query(session, key, json.dumps({"value": args.value}))})
    emit({"event": "query", "value": args.second,
          "replies": query(session, key, json.dumps({"value": args.second}))})
    emit({"event": "read", "replies": query(session, key, None)})
    del sub


HOSTILE = [
    # (key, payload, reason the gateway must give)
    ("pprz/{ac}/uplink/SETTING", "{not json", "bad_fields"),
    ("pprz/{ac}/uplink/NO_SUCH_MESSAGE", "{}", "unknown_message"),
    ("pprz/{ac}/uplink/GPS_INT", "{}", "unknown_message"),
    ("pprz/{ac}/uplink/SETTING", '{"index": "two", "value": "high"}', "bad_fields"),
    ("pprz/{ac}/uplink/SETTING", '{"index": 2, "value": 1e999}', "bad_fields"),
    ("pprz/{ac}/uplink/SETTING", '[1, 2, 3]', "bad_fields"),
    ("pprz/{ac}/uplink/SETTING", '{"index": 2, "ac_id": {other}, "value": 1.0}', "other_aircraft"),
    ("pprz/seven/uplink/SETTING", '{"index": 2, "value": 1.0}', "bad_key"),
    ("pprz/300/uplink/SETTING", '{"index": 2, "value": 1.0}', "bad_key"),
    ("pprz/{ac}/uplink/SETTING", "\udcff", "bad_fields"),
]


def hostile(session, args):
    ac = args.ac
    got = threading.Condition()
    refused = []

    def on_refused(sample):
        with got:
            refused.append(json.loads(text(sample.payload)))
            got.notify_all()

    sub = session.declare_subscriber(REFUSED, on_refused)
    Ready(session).wait()
    for key, payload, reason in HOSTILE:
        key = key.format(ac=ac)
        payload = payload.replace("{other}", str(ac + 1))
        raw = payload.encode("utf-8", "surrogateescape")
        with got:
            start = len(refused)
        session.put(key, raw)
        with got:
            ok = got.wait_for(lambda: len(refused) > start, timeout=10)
            answer = refused[start] if ok else None
        emit({"event": "refused", "key": key, "want": reason, "answer": answer})
    # The flood: valid commands as fast as the session takes them (blocking, so that
    # every one reaches the gateway).
    body = json.dumps({"index": 3, "value": 2.0})
    start = time.monotonic()
    for _ in range(args.flood):
        session.put(f"pprz/{ac}/uplink/SETTING", body,
                    congestion_control=zenoh.CongestionControl.BLOCK)
    seconds = time.monotonic() - start
    # A read query after the flood: the gateway takes requests in order, so its answer
    # means every command before it was taken, refused or dropped (counted). A query
    # dropped because the queue was full gets no answer: try again.
    tries = 0
    while tries < 20:
        tries += 1
        replies = query(session, f"pprz/{ac}/settings/3", None, timeout=2.0)
        if replies:
            break
    emit({"event": "flood", "n": args.flood, "seconds": seconds, "read_tries": tries,
          "answered": bool(replies)})
    time.sleep(0.2)
    with got:
        reasons = {}
        for r in refused:
            reasons[r.get("reason")] = reasons.get(r.get("reason"), 0) + 1
    emit({"event": "refusals", "reasons": reasons})
    del sub


def queries(session, args):
    """N settings queries at once, each setting a value the aircraft is not asked to
    answer; their replies grouped (ok, or the error text)."""
    Ready(session).wait()
    key = f"pprz/{args.ac}/settings/{args.index}"
    handlers = [session.get(key, payload=json.dumps({"value": 10 + i}), timeout=10)
                for i in range(args.n)]
    outcome = {}
    for h in handlers:
        for r in h:
            j = reply_json(r)
            label = "ok" if "ok" in j else j["err"]
            if label.startswith("no DL_VALUE"):
                label = "no DL_VALUE"
            outcome[label] = outcome.get(label, 0) + 1
    emit({"event": "queries", "outcome": outcome})


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("endpoint")
    p.add_argument("--peer", action="store_true", help="a peer session, not a client")
    sub = p.add_subparsers(dest="command", required=True)
    s = sub.add_parser("subscribe")
    s.add_argument("keys", nargs="+")
    s.add_argument("--seconds", type=float, default=60.0)
    s.add_argument(
        "--schemas",
        action="store_true",
        help="validate each message's JSON against the schema the gateway serves",
    )
    s = sub.add_parser("setting")
    s.add_argument("ac", type=int)
    s.add_argument("index", type=int)
    s.add_argument("value", type=float)
    s.add_argument("second", type=float)
    s = sub.add_parser("hostile")
    s.add_argument("ac", type=int)
    s.add_argument("flood", type=int)
    s = sub.add_parser("queries")
    s.add_argument("ac", type=int)
    s.add_argument("index", type=int)
    s.add_argument("n", type=int)
    args = p.parse_args()
    session = open_session(args.endpoint, args.peer)
    try:
        {"subscribe": subscribe, "setting": setting, "hostile": hostile,
         "queries": queries}[args.command](
            session, args)
    finally:
        session.close()
    emit({"event": "end"})


if __name__ == "__main__":
    main()
