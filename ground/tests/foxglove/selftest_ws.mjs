#!/usr/bin/env node
// Self-test of ws_client.mjs against a small server built on @foxglove/ws-protocol's
// FoxgloveServer (no pprz code involved). `node selftest_ws.mjs` exits 0 when every
// mode of the client behaves as documented.

import { spawn } from "node:child_process";
import { fileURLToPath } from "node:url";
import path from "node:path";
import net from "node:net";

import pkg from "@foxglove/ws-protocol";
import { WebSocketServer } from "ws";

const { FoxgloveServer } = pkg;
const HERE = path.dirname(fileURLToPath(import.meta.url));
const CLIENT = path.join(HERE, "ws_client.mjs");

const SCHEMA = JSON.stringify({
  $schema: "https://json-schema.org/draft/2020-12/schema",
  type: "object",
  properties: { phi: { type: "number" }, psi: { type: "number" }, theta: { type: "number" } },
});

/** A Foxglove server on 127.0.0.1:<free port> publishing ATTITUDE every 5 ms. */
async function startServer({ capabilities = [], onConnection } = {}) {
  const fox = new FoxgloveServer({ name: "selftest", capabilities });
  const wss = new WebSocketServer({
    host: "127.0.0.1",
    port: 0,
    handleProtocols: (protocols) => fox.handleProtocols(protocols),
  });
  await new Promise((resolve) => wss.on("listening", resolve));
  const state = { fox, wss, sockets: [], subscribed: new Set(), params: new Map([["/ac/7/settings/2", 1.5]]) };
  wss.on("connection", (conn, req) => {
    state.sockets.push(conn);
    fox.handleConnection(conn, `${req.socket.remoteAddress}:${req.socket.remotePort}`);
    if (onConnection) onConnection(conn, state);
  });
  fox.on("subscribe", (id) => state.subscribed.add(id));
  fox.on("unsubscribe", (id) => state.subscribed.delete(id));
  fox.on("getParameters", ({ parameterNames, id }, conn) => {
    const names = parameterNames.length ? parameterNames : [...state.params.keys()];
    fox.publishParameterValues(
      names.filter((n) => state.params.has(n)).map((name) => ({ name, value: state.params.get(name) })),
      id,
      conn,
    );
  });
  fox.on("setParameters", ({ parameters, id }, conn) => {
    for (const p of parameters) state.params.set(p.name, p.value);
    if (id !== undefined) {
      fox.publishParameterValues(parameters.map((p) => ({ name: p.name, value: state.params.get(p.name) })), id, conn);
    }
  });
  state.attitude = fox.addChannel({
    topic: "/ac/7/telemetry/ATTITUDE",
    encoding: "json",
    schemaName: "pprz.telemetry.ATTITUDE",
    schema: SCHEMA,
    schemaEncoding: "jsonschema",
  });
  state.silent = fox.addChannel({
    topic: "/ac/7/telemetry/SILENT",
    encoding: "json",
    schemaName: "pprz.telemetry.SILENT",
    schema: "{}",
    schemaEncoding: "jsonschema",
  });
  let n = 0;
  const enc = new TextEncoder();
  state.interval = setInterval(() => {
    n += 1;
    fox.sendMessage(state.attitude, BigInt(n) * 100_000n + 18_000_000_000_000_000_000n, enc.encode(JSON.stringify({ phi: n * 0.5, psi: -0.25, theta: n })));
  }, 5);
  state.url = `ws://127.0.0.1:${wss.address().port}`;
  state.stop = () =>
    new Promise((resolve) => {
      clearInterval(state.interval);
      if (state.flood) clearInterval(state.flood);
      for (const s of state.sockets) s.terminate();
      wss.close(() => resolve());
    });
  return state;
}

/** Runs the client; resolves {code, stdout, stderr}. `onStdout` sees stdout as it comes. */
function runClient(args, { onStdout, killAfter } = {}) {
  return new Promise((resolve) => {
    const child = spawn(process.execPath, [CLIENT, ...args], { stdio: ["ignore", "pipe", "pipe"] });
    let stdout = "";
    let stderr = "";
    child.stdout.on("data", (d) => {
      stdout += d;
      if (onStdout) onStdout(stdout, child);
    });
    child.stderr.on("data", (d) => (stderr += d));
    const guard = setTimeout(() => child.kill("SIGKILL"), killAfter ?? 20000);
    child.on("close", (code, signal) => {
      clearTimeout(guard);
      resolve({ code, signal, stdout, stderr });
    });
  });
}

const failures = [];
function check(name, cond, detail) {
  process.stdout.write(`${cond ? "ok  " : "FAIL"} ${name}\n`);
  if (!cond) {
    failures.push(name);
    if (detail) process.stdout.write(`${detail}\n`);
  }
}
const show = (r) => `exit ${r.code} ${r.signal ?? ""}\nstdout: ${r.stdout.slice(0, 1500)}\nstderr: ${r.stderr.slice(0, 1500)}`;

async function main() {
  // 1. Messages of a topic, as JSON lines.
  {
    const s = await startServer();
    const r = await runClient([s.url, "--topic", "/ac/7/telemetry/ATTITUDE", "--count", "5", "--timeout", "10"]);
    const lines = r.stdout.trim().split("\n").filter(Boolean);
    let parsed = [];
    try {
      parsed = lines.map((l) => JSON.parse(l));
    } catch {
      parsed = [];
    }
    const good =
      r.code === 0 &&
      parsed.length === 5 &&
      parsed.every(
        (p) =>
          p.topic === "/ac/7/telemetry/ATTITUDE" &&
          p.schemaName === "pprz.telemetry.ATTITUDE" &&
          typeof p.logTime === "string" &&
          /^\d+$/.test(p.logTime) &&
          BigInt(p.logTime) > 18_000_000_000_000_000_000n &&
          p.message.psi === -0.25 &&
          typeof p.message.phi === "number",
      ) &&
      r.stderr.includes("advertised /ac/7/telemetry/ATTITUDE");
    check("topic: 5 JSON lines with topic, logTime (u64 as text), schemaName, message", good, show(r));
    await s.stop();
  }
  // 2. A topic that is never advertised: exit 2, with the advertised list.
  {
    const s = await startServer();
    const r = await runClient([s.url, "--topic", "/ac/9/telemetry/NOPE", "--count", "1", "--timeout", "1"]);
    check("missing topic: exit 2 and the advertised topics on stderr", r.code === 2 && r.stderr.includes("/ac/9/telemetry/NOPE") && r.stderr.includes("advertised: /ac/7/telemetry/ATTITUDE /ac/7/telemetry/SILENT"), show(r));
    await s.stop();
  }
  // 3. Advertised but silent: exit 1 on timeout.
  {
    const s = await startServer();
    const r = await runClient([s.url, "--topic", "/ac/7/telemetry/SILENT", "--count", "1", "--timeout", "1"]);
    check("silent topic: exit 1 (timeout)", r.code === 1 && r.stdout === "", show(r));
    await s.stop();
  }
  // 4. Two topics, count over both; a channel advertised after the client connected.
  {
    const s = await startServer({
      onConnection: (_conn, st) => {
        setTimeout(() => {
          const id = st.fox.addChannel({ topic: "/ac/7/location", encoding: "json", schemaName: "foxglove.LocationFix", schema: "{}", schemaEncoding: "jsonschema" });
          setTimeout(() => st.fox.sendMessage(id, 5n, new TextEncoder().encode('{"latitude":43.5}')), 100);
        }, 200);
      },
    });
    const r = await runClient([s.url, "--topic", "/ac/7/location", "--topic", "/ac/7/telemetry/ATTITUDE", "--count", "200", "--timeout", "10"]);
    const parsed = r.stdout.trim().split("\n").map((l) => JSON.parse(l));
    check(
      "late channel: subscribed when advertised, counted with the others",
      r.code === 0 && parsed.length === 200 && parsed.some((p) => p.topic === "/ac/7/location" && p.logTime === "5" && p.message.latitude === 43.5),
      show(r),
    );
    await s.stop();
  }
  // 5. Not JSON: exit 3.
  {
    const s = await startServer({
      onConnection: (_conn, st) => {
        setTimeout(() => {
          const id = st.fox.addChannel({ topic: "/bad", encoding: "json", schemaName: "x", schema: "{}", schemaEncoding: "jsonschema" });
          setTimeout(() => st.fox.sendMessage(id, 1n, new TextEncoder().encode("{nope")), 100);
        }, 100);
      },
    });
    const r = await runClient([s.url, "--topic", "/bad", "--count", "1", "--timeout", "5"]);
    check("invalid JSON: exit 3", r.code === 3 && r.stderr.includes("not JSON"), show(r));
    await s.stop();
  }
  // 6. Stall: subscribes to everything, then stops reading; the server's buffer grows.
  {
    let serverConn = null;
    const s = await startServer({ onConnection: (conn) => (serverConn = conn) });
    const big = new TextEncoder().encode(JSON.stringify({ phi: 1, pad: "x".repeat(60000) }));
    let maxBuffered = 0;
    let subscribedAtStall = 0;
    const r = await runClient([s.url, "--stall", "--settle", "0.3", "--timeout", "10"], {
      killAfter: 30000,
      onStdout: (text, child) => {
        if (!text.includes("stalled") || s.flood) return;
        subscribedAtStall = s.subscribed.size;
        const t0 = Date.now();
        s.flood = setInterval(() => {
          for (let i = 0; i < 20; i++) s.fox.sendMessage(s.attitude, 1n, big);
          maxBuffered = Math.max(maxBuffered, serverConn ? serverConn.bufferedAmount : 0);
          if (maxBuffered > 4 * 1024 * 1024 || Date.now() - t0 > 15000) {
            clearInterval(s.flood);
            child.kill("SIGTERM");
          }
        }, 10);
      },
    });
    check(
      `stall: prints "stalled" after subscribing to every channel, then the server's buffer grows (${(maxBuffered / 1048576).toFixed(1)} MiB)`,
      r.stdout === "stalled\n" && subscribedAtStall === 2 && maxBuffered > 4 * 1024 * 1024 && r.signal === "SIGTERM",
      show(r),
    );
    await s.stop();
  }
  // 7. Vanish: a few messages, then the TCP connection is gone without a close frame.
  {
    let closeCode = null;
    const s = await startServer({ onConnection: (conn) => conn.on("close", (code) => (closeCode = code)) });
    const r = await runClient([s.url, "--vanish", "--count", "3", "--timeout", "10"]);
    await new Promise((res) => setTimeout(res, 300));
    check(`vanish: exit 0, the server sees an abnormal close (code ${closeCode})`, r.code === 0 && closeCode === 1006, show(r));
    await s.stop();
  }
  // 8. Parameters: get, then set.
  {
    const s = await startServer({ capabilities: ["parameters"] });
    const g = await runClient([s.url, "--params", "/ac/7/settings/2", "--timeout", "5"]);
    let gj = null;
    try {
      gj = JSON.parse(g.stdout.trim());
    } catch {
      gj = null;
    }
    check("params get: the parameterValues reply as a JSON line", g.code === 0 && gj && gj.op === "parameterValues" && gj.parameters[0].name === "/ac/7/settings/2" && gj.parameters[0].value === 1.5, show(g));
    const st = await runClient([s.url, "--params", "/ac/7/settings/2", "--set", "2.25", "--timeout", "5"]);
    let sj = null;
    try {
      sj = JSON.parse(st.stdout.trim());
    } catch {
      sj = null;
    }
    check("params set: the value is sent as a number and the reply printed", st.code === 0 && sj && sj.parameters[0].value === 2.25 && s.params.get("/ac/7/settings/2") === 2.25, show(st));
    await s.stop();
  }
  // 9. Parameters on a server without the capability: exit 2.
  {
    const s = await startServer();
    const r = await runClient([s.url, "--params", "/ac/7/settings/2", "--timeout", "3"]);
    check("params without the capability: exit 2", r.code === 2 && r.stderr.includes("parameters"), show(r));
    await s.stop();
  }
  // 10. Connection refused, server closing, usage.
  {
    const port = await new Promise((resolve) => {
      const srv = net.createServer();
      srv.listen(0, "127.0.0.1", () => {
        const p = srv.address().port;
        srv.close(() => resolve(p));
      });
    });
    const r = await runClient([`ws://127.0.0.1:${port}`, "--topic", "/x", "--count", "1", "--timeout", "3"]);
    check("connection refused: exit 3", r.code === 3, show(r));
    const s = await startServer({ onConnection: (conn) => setTimeout(() => conn.close(1001, "going away"), 300) });
    const c = await runClient([s.url, "--topic", "/ac/7/telemetry/SILENT", "--count", "1", "--timeout", "5"]);
    check("closed by the server: exit 3", c.code === 3 && c.stderr.includes("closed by the server"), show(c));
    await s.stop();
    const u = await runClient(["--count", "1"]);
    check("usage: exit 64", u.code === 64, show(u));
  }
  // 11. A server that does not speak foxglove.websocket.v1.
  {
    const wss = new WebSocketServer({ host: "127.0.0.1", port: 0, handleProtocols: () => false });
    await new Promise((resolve) => wss.on("listening", resolve));
    const r = await runClient([`ws://127.0.0.1:${wss.address().port}`, "--topic", "/x", "--count", "1", "--timeout", "3"]);
    check("no subprotocol: exit 3", r.code === 3, show(r));
    for (const c of wss.clients) c.terminate();
    await new Promise((resolve) => wss.close(resolve));
  }

  if (failures.length) {
    process.stdout.write(`selftest_ws FAILED: ${failures.join("; ")}\n`);
    process.exit(1);
  }
  process.stdout.write("selftest_ws passed\n");
  process.exit(0);
}

main().catch((e) => {
  process.stdout.write(`selftest_ws crashed: ${e.stack}\n`);
  process.exit(1);
});
