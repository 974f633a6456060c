"""The live view keeps the WebSocket protocol: a viewer's Close is answered with a Close echoing its code (RFC 6455
section 5.5.1), during the run and at its end, while everything else a viewer sees comes from foxglove-sdk's server
unchanged (cosim.observers.relay)."""

from __future__ import annotations

import base64
import json
import os
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_helpers import free_port

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
pytestmark = pytest.mark.integration
CLOSE_TIMEOUT = 3.0  # s the client waits for the answer to its Close


def _connect(port: int, deadline: float):
    from websockets.sync.client import connect

    while True:
        try:
            # max_queue=None: the client reads on while it closes (with a full queue it stops reading, and no server's
            # answer reaches it: websockets' own server streaming to it ends in 1006 alike)
            return connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None, max_queue=None,
                           open_timeout=5, close_timeout=CLOSE_TIMEOUT)
        except (OSError, TimeoutError, Exception):  # noqa: BLE001 - the run's server is not up yet
            if time.monotonic() > deadline:
                raise
            time.sleep(0.05)


def _subscribe_and_read(ws, n: int) -> int:
    """Subscribe to every channel advertised; read ``n`` binary messages; returns how many were read."""
    got = 0
    while got < n:
        raw = ws.recv(timeout=20)
        if isinstance(raw, str):
            msg = json.loads(raw)
            if msg["op"] == "advertise":
                ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                    {"id": k + 1, "channelId": ch["id"]} for k, ch in enumerate(msg["channels"])]}))
        else:
            got += 1
    return got


def test_a_viewer_closing_gets_its_close_answered(tmp_path):
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(SCENARIO), "--stop-time", "3", "--live",
                             str(port), "--realtime", "--out", str(tmp_path / "run.mcap"), "--quiet"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        results = []
        for code, reason in ((1000, ""), (4001, "bye"), (1001, "going away")):
            ws = _connect(port, deadline)
            assert ws.subprotocol == "foxglove.sdk.v1"
            assert _subscribe_and_read(ws, 200) == 200  # in the middle of the server's stream
            t0 = time.monotonic()
            ws.close(code, reason)
            results.append((code, ws.close_code, ws.protocol.close_rcvd, time.monotonic() - t0))
        end = _connect(port, deadline)  # stays to the end of the run: the server's own Close, passed on
        _subscribe_and_read(end, 10)
        while True:
            try:
                end.recv(timeout=30)
            except Exception:  # noqa: BLE001 - the run ended and closed the connection
                break
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    for code, got, rcvd, took in results:
        assert got == code and rcvd is not None and rcvd.code == code, (code, got, rcvd)
        assert took < 1.0, f"close {code} answered after {took:.2f} s"
    assert end.protocol.close_rcvd is not None, "the run's end came without a Close frame"
    assert end.close_code == end.protocol.close_rcvd.code, (end.close_code, end.protocol.close_rcvd)


def test_a_close_cut_in_single_bytes_is_answered_and_probes_pass(tmp_path):
    """A raw client: the upgrade, then a masked Close (4002) sent a byte at a time; the answer is one Close frame
    with 4002, then the end of the connection. A plain HTTP GET gets the server's own answer (none: it drops it)."""
    port = free_port()
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(SCENARIO), "--stop-time", "2", "--live",
                             str(port), "--realtime", "--no-log", "--quiet"],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 60
        _connect(port, deadline).close()  # up
        s = socket.create_connection(("127.0.0.1", port), timeout=10)
        key = base64.b64encode(os.urandom(16)).decode()
        s.sendall((f"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
                   f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n"
                   f"Sec-WebSocket-Protocol: foxglove.sdk.v1\r\n\r\n").encode())
        head = b""
        while b"\r\n\r\n" not in head:
            head += s.recv(1)
        assert head.startswith(b"HTTP/1.1 101"), head
        mask = os.urandom(4)
        payload = struct.pack("!H", 4002) + b"x"
        frame = bytes([0x88, 0x80 | len(payload)]) + mask + bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        for b in frame:
            s.sendall(bytes([b]))
            time.sleep(0.01)
        rest = b""
        while True:
            chunk = s.recv(65536)
            if not chunk:
                break
            rest += chunk
        s.close()
        with socket.create_connection(("127.0.0.1", port), timeout=10) as plain:
            plain.sendall(b"GET / HTTP/1.1\r\nHost: x\r\n\r\n")
            answer = plain.recv(4096)
        _, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    frames, pos = [], 0  # the server's frames, then the answer: it must be the last, and whole
    while pos < len(rest):
        opcode, n = rest[pos] & 0x0F, rest[pos + 1] & 0x7F
        at = pos + 2
        if n == 126:
            n, at = struct.unpack_from("!H", rest, at)[0], at + 2
        elif n == 127:
            n, at = struct.unpack_from("!Q", rest, at)[0], at + 8
        frames.append((opcode, rest[at:at + n]))
        pos = at + n
    assert pos == len(rest), "a frame cut short"
    assert frames and frames[-1] == (0x8, struct.pack("!H", 4002)), frames[-1:]
    assert answer == b"", answer[:80]  # foxglove-sdk drops a plain GET unanswered; the relay passes that on


_SAME_STREAM = r'''
import json, sys, threading, time
import foxglove
from foxglove.websocket import Capability
from websockets.sync.client import connect
from cosim.observers.relay import Relay

ctx = foxglove.Context()
server = foxglove.start_server(port=0, context=ctx, capabilities=[Capability.Time])
relay = Relay("127.0.0.1", 0)
relay.start(("127.0.0.1", server.port))
schema = foxglove.Schema(name="x", encoding="jsonschema", data=b'{"type": "object"}')
channels = [foxglove.Channel(f"/c{i}", schema=schema, message_encoding="json", context=ctx) for i in range(3)]
seen = {}

def viewer(name, port, ready, go):
    with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None, max_queue=None) as ws:
        got = [ws.subprotocol, ws.response.headers.get("Sec-WebSocket-Protocol")]
        while True:
            raw = ws.recv(timeout=10)
            got.append(raw)
            if isinstance(raw, str) and json.loads(raw)["op"] == "advertise":
                ids = sorted(ch["id"] for ch in json.loads(raw)["channels"])
                ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": i, "channelId": i} for i in ids]}))
                break
        ready.set()
        go.wait(10)
        while len(got) < 2 + 2 + 3 * 200 + 1:
            got.append(ws.recv(timeout=10))
    seen[name] = got

events = {n: (threading.Event(), threading.Event()) for n in ("direct", "relayed")}
threads = [threading.Thread(target=viewer, args=(n, p, *events[n])) for n, p in
           (("direct", server.port), ("relayed", relay.port))]
for t in threads:
    t.start()
for ready, _ in events.values():
    ready.wait(10)
time.sleep(0.5)  # both subscriptions registered
for _, go in events.values():
    go.set()
for k in range(200):
    for ch in channels:
        ch.log(json.dumps({"k": k}).encode(), log_time=k)
server.broadcast_time(12345)
for t in threads:
    t.join(30)
relay.stop()
server.stop()
print(json.dumps({n: [m if isinstance(m, str) or m is None else m.hex() for m in v] for n, v in seen.items()}))
'''


def test_a_relayed_viewer_sees_what_a_direct_one_sees():
    """Two viewers of one server, one direct, one through the relay: the same subprotocol, and the same messages,
    byte for byte (serverInfo, advertise, 600 messages, a time broadcast; the server interleaves its data and control
    messages as its queues come, so each is compared in its own order). In a process of its own: the SDK's threads
    stay out of the test process."""
    r = subprocess.run([sys.executable, "-c", _SAME_STREAM], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    seen = json.loads(r.stdout.strip().splitlines()[-1])
    assert seen["direct"][:2] == ["foxglove.sdk.v1", "foxglove.sdk.v1"]
    assert len(seen["direct"]) == 2 + 2 + 600 + 1

    def planes(got: list) -> tuple[list, list]:  # the server's data and control planes: each in order, not interleaved
        data = [m for m in got if m.startswith("01")]
        return data, [m for m in got if not m.startswith("01")]

    direct, relayed = planes(seen["direct"]), planes(seen["relayed"])
    assert len(direct[0]) == 600 and relayed[0] == direct[0], "the relayed messages differ"
    assert relayed[1] == direct[1], (relayed[1], direct[1])  # subprotocol, serverInfo, advertise, time
