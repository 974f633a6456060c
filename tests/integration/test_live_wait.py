"""``run --live --live-wait``: the run holds before it sends anything until a viewer subscribes, so a viewer that
connects after the run started gets every message of the log; the wait is bounded, a stop signal ends it as it ends
a step, the watchdog and the supervisor do not take it for a stall."""

from __future__ import annotations

import json
import signal
import socket
import struct
import subprocess
import sys
import time
from pathlib import Path

import pytest
from cli_helpers import free_port

from cosim.cli import main

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"
pytestmark = pytest.mark.integration


def _serving(port: int, proc: subprocess.Popen, timeout: float = 60.0) -> None:
    """Return once something accepts connections on ``port`` (the run's server is up); fail if the run ended."""
    deadline = time.monotonic() + timeout
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            return
        except OSError:
            assert proc.poll() is None, f"the run ended (exit {proc.returncode}) before it served"
            assert time.monotonic() < deadline, "the live view did not start"
            time.sleep(0.05)


def _logged(path: Path, topic: str) -> list[tuple[int, bytes]]:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(m.log_time, bytes(m.data)) for _, _, m in make_reader(f).iter_messages(topics=[topic])]


def test_a_late_viewer_gets_every_message_of_the_log(tmp_path):
    """The viewer connects well after the run started (longer than the run's watchdog budget plus the supervisor's
    grace: a wait taken for a stall would have been killed), subscribes to /plant only and reads until the run
    closes it: it received exactly the log's /plant messages, the sample at t = 0 first."""
    from websockets.sync.client import connect

    port, out = free_port(), tmp_path / "waited.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(SCENARIO), "--stop-time", "0.5", "--live",
                             str(port), "--live-wait", "60", "--watchdog", "1", "--realtime", "--out", str(out)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    got: list[tuple[int, bytes]] = []
    try:
        _serving(port, proc)
        time.sleep(6.0)  # watchdog 1 s; the supervisor kills after the budget plus twice its 2 s grace
        assert proc.poll() is None, f"the waiting run ended: {proc.communicate()}"
        with connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"], max_size=None,
                     open_timeout=10) as ws:
            sub = None
            while True:
                try:
                    raw = ws.recv(timeout=30)
                except Exception:  # noqa: BLE001 - the run ended and closed the connection
                    break
                if isinstance(raw, str):
                    msg = json.loads(raw)
                    if msg["op"] == "advertise" and sub is None:
                        plant = next(ch for ch in msg["channels"] if ch["topic"] == "/plant")
                        sub = 7
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": [{"id": sub, "channelId": plant["id"]}]}))
                elif raw[0] == 0x01:
                    sub_id, log_time = struct.unpack_from("<IQ", raw, 1)
                    assert sub_id == sub
                    got.append((log_time, bytes(raw[13:])))
        stdout, err = proc.communicate(timeout=60)
    finally:
        proc.kill()
    assert proc.returncode == 0, err
    assert "the run waited" in stdout and "for its first viewer" in stdout, stdout
    logged = _logged(out, "/plant")
    assert len(logged) == 501 and json.loads(logged[0][1])["t"] == 0.0, (len(logged), logged[:1])
    assert got and json.loads(got[0][1])["t"] == 0.0, f"the viewer's first /plant sample: {got[:1]}"
    assert got == logged, f"viewer received {len(got)} /plant messages, the log holds {len(logged)}"


def test_no_viewer_within_the_bound_the_run_goes_on(tmp_path):
    port, out = free_port(), tmp_path / "alone.mcap"
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "cosim", "run", str(SCENARIO), "--stop-time", "0.2", "--live", str(port),
                        "--live-wait", "1.5", "--out", str(out)], cwd=ROOT, capture_output=True, text=True,
                       timeout=120)
    wall = time.monotonic() - t0
    assert r.returncode == 0, r.stderr
    assert "no viewer subscribed within 1.5 s (--live-wait): the run went on without one" in r.stdout, r.stdout
    assert wall >= 1.5 and len(_logged(out, "/plant")) == 201, wall


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_signal_ends_the_wait_and_the_log_is_finished(tmp_path, signum):
    from cosim.io.runlog import read_run

    port, out = free_port(), tmp_path / "stopped.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "cosim", "run", str(SCENARIO), "--stop-time", "0.5", "--live",
                             str(port), "--live-wait", "--out", str(out)],
                            cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        _serving(port, proc)
        time.sleep(0.5)
        t0 = time.monotonic()
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=30)
        stopped = time.monotonic() - t0
    finally:
        proc.kill()
    assert proc.returncode == 128 + signum, (proc.returncode, err)
    assert stopped < 5, f"{stopped:.1f} s to stop"
    assert out.exists() and not out.with_name(out.name + ".partial").exists(), sorted(tmp_path.iterdir())
    assert read_run(out).status == "interrupted"


def test_live_wait_needs_live(capsys):
    assert main(["run", str(SCENARIO), "--stop-time", "0.01", "--no-log", "--live-wait", "5"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == "error: --live-wait waits for a viewer of the live view: it needs --live [PORT]", err


def test_the_bound_holds_against_a_viewer_that_subscribes_again_and_again():
    """A viewer that subscribes anew every 0.05 s never lets 0.2 s of quiet pass: the wait still ends at its bound."""
    import threading
    import types

    import numpy as np

    from cosim.observers.live import LiveView

    view = object.__new__(LiveView)
    view.wait, view.stop_request, view._subscribed, view._offset = 0.5, None, None, 0
    view.viewed, view.waited = False, None
    view.server = types.SimpleNamespace(broadcast_time=lambda t: None)
    rt = types.SimpleNamespace(current=np.zeros(5), now_ns=0)
    done = threading.Event()

    def churn():
        while not done.is_set():
            view._subscribed = time.monotonic()
            done.wait(0.05)

    thread = threading.Thread(target=churn)
    thread.start()
    try:
        t0 = time.monotonic()
        view._wait_for_viewer(rt)
        took = time.monotonic() - t0
    finally:
        done.set()
        thread.join()
    assert 0.5 <= took < 5.0 and view.viewed, (took, view.viewed)


def _draining(delivered_over_time, due, end_in=5.0, connected=1):
    """LiveView._drain against a relay whose ``delivered`` count follows ``delivered_over_time`` (a function of the
    seconds since the start, run in a thread), with ``connected`` viewers: the seconds it waited."""
    import threading
    import types

    from cosim.observers.live import LiveView

    view = object.__new__(LiveView)
    relay = types.SimpleNamespace(delivered=0, connected=lambda: connected)
    view._relay = relay
    done = threading.Event()
    t0 = time.monotonic()

    def pass_on():
        while not done.is_set():
            relay.delivered = delivered_over_time(time.monotonic() - t0)
            done.wait(0.005)

    thread = threading.Thread(target=pass_on)
    thread.start()
    try:
        view._drain(due, t0 + end_in)
        return time.monotonic() - t0, relay.delivered
    finally:
        done.set()
        thread.join()


def test_the_end_waits_for_what_the_server_still_holds_for_its_viewers():
    """The server's stop sends its Close ahead of the messages its queues still hold (foxglove-sdk's poller), so the
    run's end first waits until the relay has passed on every message due: here the last 20 of 501 come 0.3 s late."""
    took, delivered = _draining(lambda s: 481 if s < 0.3 else 501, due=501)
    assert delivered >= 501 and 0.3 <= took < 0.3 + 2.0, (took, delivered)


def test_the_end_waits_no_longer_once_nothing_passes():
    """Messages a viewer's lossy backlog dropped never come: the wait ends DRAIN_QUIET_S after the last one passed,
    however many were due, and at the bound at the latest (a viewer reading slowly forever)."""
    from cosim.observers.live import DRAIN_QUIET_S

    took, _ = _draining(lambda s: min(int(s * 1000), 300), due=501)  # 300 by 0.3 s, then nothing
    assert 0.3 + DRAIN_QUIET_S - 0.05 <= took < 0.3 + DRAIN_QUIET_S + 2.0, took
    took, _ = _draining(lambda s: int(s * 1000), due=10**9, end_in=1.0)  # always passing, never all
    assert 1.0 <= took < 1.0 + 2.0, took
    took, _ = _draining(lambda s: 0, due=501, connected=0)  # the viewers have gone: nothing more can pass
    assert took < DRAIN_QUIET_S, took
    took, _ = _draining(lambda s: 0, due=0)
    assert took < DRAIN_QUIET_S, took
