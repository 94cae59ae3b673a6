#!/usr/bin/env node
// Independent Foxglove WebSocket client for the tests of pprz-monitor and sitl, built on
// the protocol's official library (npm @foxglove/ws-protocol: FoxgloveClient) and `ws`.
//
//   node ws_client.mjs ws://127.0.0.1:PORT --topic T [--topic T2 ...] --count N [--timeout S]
//       Subscribes to the topics once advertised and prints one JSON line per message:
//       {"topic":..., "logTime":"<ns>", "schemaName":..., "message":{...}}
//       Exits 0 after N messages in all.
//   node ws_client.mjs URL --stall [--settle S]
//       Subscribes to every channel (and to those advertised during S seconds, 0.5 by
//       default), prints `stalled`, then stops reading the socket (the server's buffers
//       fill) and stays connected until killed.
//   node ws_client.mjs URL --vanish [--count N]
//       Subscribes to every channel, receives N messages (3 by default), then destroys
//       the TCP connection without a WebSocket close handshake and exits 0.
//   node ws_client.mjs URL --params NAME [--params NAME2 ...] [--set VALUE]
//       Gets (or sets to VALUE: a JSON value, or else a string) parameters and prints the
//       server's parameterValues reply, and any status message, as JSON lines.
//
// The advertised channels are listed on standard error as they arrive. Exit status:
// 0 done; 1 timeout (--timeout, 10 s by default); 2 a topic was not advertised in time,
// nothing to subscribe to, or the server lacks the `parameters` capability; 3 connection
// or protocol error (refused, closed by the server, wrong subprotocol, message that is not
// JSON); 64 bad usage.

import pkg from "@foxglove/ws-protocol";
import WebSocket from "ws";

const { FoxgloveClient } = pkg;

// The protocol's name: `foxglove.websocket.v1` (this package's client, as published) and
// `foxglove.sdk.v1` (the same messages, the name the Foxglove SDK servers negotiate).
const SUBPROTOCOLS = [FoxgloveClient.SUPPORTED_SUBPROTOCOL, "foxglove.sdk.v1"];

const USAGE = `usage: node ws_client.mjs ws://HOST:PORT
  (--topic T ... --count N | --stall [--settle S] | --vanish [--count N] | --params NAME ... [--set VALUE])
  [--timeout S]`;

function usage(msg) {
  process.stderr.write(`ws_client: ${msg}\n${USAGE}\n`);
  process.exit(64);
}

function parseArgs(argv) {
  const o = { url: null, topics: [], count: null, timeout: 10, stall: false, vanish: false, settle: 0.5, params: [], set: undefined };
  for (let i = 0; i < argv.length; i++) {
    const a = argv[i];
    const value = () => {
      if (i + 1 >= argv.length) usage(`${a} needs a value`);
      return argv[++i];
    };
    const number = (name, v, min) => {
      const n = Number(v);
      if (!Number.isFinite(n) || n < min) usage(`${name}: not a number >= ${min}: ${v}`);
      return n;
    };
    switch (a) {
      case "--topic": o.topics.push(value()); break;
      case "--count": o.count = number(a, value(), 1); break;
      case "--timeout": o.timeout = number(a, value(), 0.001); break;
      case "--settle": o.settle = number(a, value(), 0); break;
      case "--stall": o.stall = true; break;
      case "--vanish": o.vanish = true; break;
      case "--params": o.params.push(value()); break;
      case "--set": o.set = value(); break;
      case "-h": case "--help":
        process.stdout.write(USAGE + "\n");
        process.exit(0);
        break;
      default:
        if (a.startsWith("-") || o.url !== null) usage(`unexpected argument ${a}`);
        o.url = a;
    }
  }
  if (o.url === null) usage("no URL");
  const modes = [o.topics.length > 0, o.stall, o.vanish, o.params.length > 0].filter(Boolean).length;
  if (modes !== 1) usage("give exactly one of --topic, --stall, --vanish, --params");
  if (o.topics.length > 0 && o.count === null) usage("--topic needs --count");
  if (o.set !== undefined && o.params.length === 0) usage("--set needs --params");
  if (o.vanish && o.count === null) o.count = 3;
  return o;
}

const opts = parseArgs(process.argv.slice(2));
const mode = opts.stall ? "stall" : opts.vanish ? "vanish" : opts.params.length ? "params" : "topics";

let finished = false;
let ws;
/** Ends the process once standard output is written. */
function finish(code, msg) {
  if (finished) return;
  finished = true;
  if (msg) process.stderr.write(`ws_client: ${msg}\n`);
  clearTimeout(timer);
  try {
    if (ws && ws.readyState === WebSocket.OPEN && mode !== "vanish") ws.close();
  } catch {
    // exiting anyway
  }
  process.stdout.write("", () => process.exit(code));
}

function out(obj) {
  process.stdout.write(JSON.stringify(obj) + "\n");
}

const decoder = new TextDecoder("utf-8", { fatal: true });
const channels = new Map(); // channel id -> channel
const subscriptions = new Map(); // subscription id -> channel
const subscribedChannels = new Set();
const wanted = new Set(opts.topics);
const seenTopics = new Set();
let received = 0;
let serverInfo = null;
let stalled = false;

const timer = setTimeout(() => {
  if (mode === "topics") {
    const missing = [...wanted].filter((t) => !seenTopics.has(t));
    if (missing.length > 0) {
      finish(2, `not advertised within ${opts.timeout} s: ${missing.join(", ")}; advertised: ${advertisedList()}`);
      return;
    }
  }
  if ((mode === "stall" || mode === "vanish") && subscribedChannels.size === 0) {
    finish(2, `nothing advertised within ${opts.timeout} s`);
    return;
  }
  if (mode === "stall") return; // stays until killed
  finish(1, `timeout after ${opts.timeout} s: ${received} messages` + (opts.count ? ` of ${opts.count}` : ""));
}, opts.timeout * 1000);

function advertisedList() {
  const topics = [...new Set([...channels.values()].map((c) => c.topic))].sort();
  return topics.length ? topics.join(" ") : "(none)";
}

try {
  ws = new WebSocket(opts.url, SUBPROTOCOLS);
} catch (e) {
  finish(3, `cannot connect to ${opts.url}: ${e.message}`);
}
const client = new FoxgloveClient({ ws });

function subscribe(channel) {
  if (subscribedChannels.has(channel.id) || stalled) return;
  subscribedChannels.add(channel.id);
  const sub = client.subscribe(channel.id);
  subscriptions.set(sub, channel);
}

client.on("open", () => {
  if (!SUBPROTOCOLS.includes(ws.protocol)) {
    finish(3, `server chose subprotocol ${JSON.stringify(ws.protocol)}, not one of ${SUBPROTOCOLS.join(", ")}`);
  }
});

client.on("error", (e) => {
  finish(3, `error: ${e && e.message ? e.message : e}`);
});

client.on("close", (event) => {
  if (finished) return;
  if (stalled) {
    process.stderr.write("ws_client: connection closed by the server while stalled\n");
    return; // stays until killed
  }
  const why = event && (event.code || event.reason) ? ` (code ${event.code}${event.reason ? `, ${event.reason}` : ""})` : "";
  finish(3, `connection closed by the server${why} after ${received} messages`);
});

client.on("serverInfo", (info) => {
  serverInfo = info;
  process.stderr.write(`ws_client: server ${JSON.stringify(info.name)}, capabilities ${JSON.stringify(info.capabilities)}\n`);
  if (mode === "params") {
    if (!info.capabilities.includes("parameters")) {
      finish(2, `the server has no "parameters" capability`);
      return;
    }
    if (opts.set === undefined) {
      client.getParameters(opts.params, "ws_client-get");
    } else {
      let value;
      try {
        value = JSON.parse(opts.set);
      } catch {
        value = opts.set;
      }
      client.setParameters(opts.params.map((name) => ({ name, value })), "ws_client-set");
    }
  }
});

client.on("status", (s) => {
  process.stderr.write(`ws_client: status ${JSON.stringify(s)}\n`);
  if (mode === "params") out(s);
});

client.on("parameterValues", (p) => {
  if (mode !== "params") return;
  out({ op: "parameterValues", id: p.id, parameters: p.parameters });
  if (p.id === "ws_client-get" || p.id === "ws_client-set") finish(0);
});

let settleTimer = null;
client.on("advertise", (list) => {
  for (const c of list) {
    channels.set(c.id, c);
    seenTopics.add(c.topic);
    process.stderr.write(`ws_client: advertised ${c.topic} ${c.schemaName} (${c.encoding}, ${c.schemaEncoding ?? "?"})\n`);
    if (mode === "topics" ? wanted.has(c.topic) : mode === "stall" || mode === "vanish") subscribe(c);
  }
  if (mode === "stall" && settleTimer === null && subscribedChannels.size > 0) {
    settleTimer = setTimeout(stall, opts.settle * 1000);
  }
});

client.on("unadvertise", (ids) => {
  for (const id of ids) {
    channels.delete(id);
    subscribedChannels.delete(id);
    for (const [sub, c] of subscriptions) if (c.id === id) subscriptions.delete(sub);
  }
});

function stall() {
  stalled = true;
  ws.pause(); // stops reading the TCP socket: the kernel's and the server's buffers fill
  setInterval(() => {}, 1 << 30); // stays until killed, whatever the server does
  process.stdout.write("stalled\n");
  process.stderr.write(`ws_client: stalled with ${subscribedChannels.size} subscriptions\n`);
}

client.on("message", (m) => {
  if (finished || stalled) return;
  const channel = subscriptions.get(m.subscriptionId);
  if (channel === undefined) {
    finish(3, `message for unknown subscription ${m.subscriptionId}`);
    return;
  }
  received += 1;
  if (mode === "vanish") {
    if (received >= opts.count) {
      finished = true;
      clearTimeout(timer);
      ws.terminate(); // destroys the socket: no close frame
      process.stderr.write(`ws_client: vanished after ${received} messages\n`);
      process.stdout.write("", () => process.exit(0));
    }
    return;
  }
  if (mode !== "topics") return;
  const bytes = new Uint8Array(m.data.buffer, m.data.byteOffset, m.data.byteLength);
  let message;
  if (channel.encoding === "json") {
    try {
      message = JSON.parse(decoder.decode(bytes));
    } catch (e) {
      finish(3, `${channel.topic}: message is not JSON: ${e.message}`);
      return;
    }
  } else {
    finish(3, `${channel.topic}: message encoding ${channel.encoding}, expected json`);
    return;
  }
  out({ topic: channel.topic, logTime: m.timestamp.toString(), schemaName: channel.schemaName, message });
  if (received >= opts.count) finish(0);
});

// `ws` reports a refused connection as an error before `open`.
ws.on("error", (e) => finish(3, `cannot connect to ${opts.url}: ${e.message}`));
ws.on("unexpected-response", (_req, res) => finish(3, `HTTP ${res.statusCode} from ${opts.url}`));
