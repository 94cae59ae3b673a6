#!/usr/bin/env python3
"""Peak memory of pprz-monitor --foxglove under hostile WebSocket clients (loopback only).

    ws_flood.py MONITOR MESSAGES_XML {idle,fragment} COUNT [--aircraft N] [-- EXTRA ARGS]

Starts MONITOR --stdin --foxglove 127.0.0.1:0, feeds it one zero-filled frame of every
message of MESSAGES_XML from each of N aircraft (so every topic exists), then opens COUNT
clients that complete the WebSocket handshake and either stay idle (reading nothing) or
send one text message in fragments of 1 MiB, up to 80 MiB, until the server closes.
Prints the monitor's VmHWM before and after, the clients accepted and refused.
Standard library only.
"""
import argparse, base64, os, re, socket, struct, subprocess, sys, threading, time
import xml.etree.ElementTree as ET

SIZES = {"char": 1, "uint8": 1, "int8": 1, "uint16": 2, "int16": 2, "uint32": 4,
         "int32": 4, "float": 4, "uint64": 8, "int64": 8, "double": 8}

def frames(xml, aircraft):
    out = bytearray()
    for cls in ET.parse(xml).getroot():
        if cls.get("name") != "telemetry":
            continue
        for msg in cls:
            payload = bytearray()
            for f in msg.findall("field"):
                m = re.fullmatch(r"(\w+)(\[(\d*)\])?", f.get("type"))
                base, arr, n = m.group(1), m.group(2), m.group(3)
                if arr and not n:
                    payload.append(0)  # variable array: length 0
                else:
                    payload += bytes(SIZES[base] * (int(n) if n else 1))
            for ac in range(1, aircraft + 1):
                data = bytes([ac, 0, int(cls.get("id")), int(msg.get("id"))]) + payload
                if len(data) + 4 > 255:
                    continue
                body = bytes([len(data) + 4]) + data
                a = b = 0
                for x in body:
                    a = (a + x) & 0xFF
                    b = (b + a) & 0xFF
                out += b"\x99" + body + bytes([a, b])
    return bytes(out)

def hwm(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(("VmHWM", "VmRSS")):
                yield line.split()[0] + " " + str(int(line.split()[1]) // 1024) + " MB"

def handshake(port):
    s = socket.create_connection(("127.0.0.1", port), timeout=10)
    key = base64.b64encode(os.urandom(16)).decode()
    s.sendall((f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nUpgrade: websocket\r\n"
               f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
               "Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
    return s

def frame(opcode, fin, payload):
    mask = os.urandom(4)
    n = len(payload)
    head = bytes([(0x80 if fin else 0) | opcode])
    if n < 126:
        head += bytes([0x80 | n])
    elif n < 65536:
        head += bytes([0x80 | 126]) + struct.pack(">H", n)
    else:
        head += bytes([0x80 | 127]) + struct.pack(">Q", n)
    # A zero payload masked is the mask repeated.
    return head + mask + (mask * (n // 4 + 1))[:n]

def fragment(s, results, i):
    chunk = frame(1, False, b"\0" * (1 << 20))
    cont = bytes([0x00]) + chunk[1:]
    sent = 0
    try:
        s.settimeout(60)
        s.sendall(chunk)
        sent = 1
        while sent < 80:
            s.sendall(cont)
            sent += 1
    except OSError:
        pass
    results[i] = sent

def main():
    p = argparse.ArgumentParser()
    p.add_argument("monitor"); p.add_argument("messages")
    p.add_argument("mode", choices=["idle", "fragment"]); p.add_argument("count", type=int)
    p.add_argument("--aircraft", type=int, default=1)
    p.add_argument("extra", nargs="*")
    a = p.parse_args()
    mon = subprocess.Popen([a.monitor, "--messages", a.messages, "--stdin", "--lines",
                            "--foxglove", "127.0.0.1:0", *a.extra],
                           stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    port = None
    for line in mon.stderr:
        m = re.search(rb"serving ws://127.0.0.1:(\d+)", line)
        if m:
            port = int(m.group(1)); break
    tail = []
    reader = threading.Thread(target=lambda: tail.append(mon.stderr.read()), daemon=True)
    reader.start()
    mon.stdin.write(frames(a.messages, a.aircraft)); mon.stdin.flush()
    time.sleep(2)
    print("before:", ", ".join(hwm(mon.pid)))
    socks, refused = [], 0
    for _ in range(a.count):
        try:
            socks.append(handshake(port))
        except OSError:
            refused += 1
    if a.mode == "fragment":
        results = [0] * len(socks)
        ts = [threading.Thread(target=fragment, args=(s, results, i)) for i, s in enumerate(socks)]
        for t in ts: t.start()
        for t in ts: t.join(120)
        print("MiB sent per client before the server closed or 80 reached:", results)
    time.sleep(3)
    print(f"clients opened {len(socks)}, refused at connect {refused}")
    print("after:", ", ".join(hwm(mon.pid)))
    for s in socks: s.close()
    mon.stdin.close()
    mon.wait(30)
    reader.join(10)
    for line in b"".join(tail).decode(errors="replace").splitlines():
        if line.startswith("foxglove:"):
            print(line)

main()
