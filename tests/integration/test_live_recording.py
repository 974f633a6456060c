"""The live view of a run with a recording component: its outputs are served like any component's, on the channel
``/<component>``, with the schema the log's channel has (each output with its unit and what it replays), and every
message served holds the value the log holds at that time, the recording's sample interpolated there. The
WebSocket client is tests/integration/test_live.py's (Foxglove protocol)."""

from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from cli_helpers import free_port
from test_live import _watch

from cosim.io.runlog import read_run

pytestmark = pytest.mark.integration

STOP_S = 3.0  # s, at real time: the client connects once the run is initialized and sees most of it
RATE_HZ = 50.0  # the recording's rate: the run (1 ms) interpolates between its samples


def test_a_live_run_serves_a_recording_components_outputs_as_the_log_holds_them(tmp_path):
    from cfmus import build

    t = np.arange(0.0, STOP_S + 0.5, 1.0 / RATE_HZ)
    q = np.column_stack([0.1 * np.sin(2.0 * t), 0.2 * np.cos(3.0 * t)])
    rows = "\n".join(",".join(repr(float(v)) for v in row) for row in np.column_stack([t, q]))
    (tmp_path / "robot.csv").write_text(f"time [s],q1 [m],q2 [mm]\n{rows}\n")
    scenario = tmp_path / "live_replay.yaml"
    scenario.write_text(yaml.safe_dump({
        "name": "live_replay",
        "components": {"m": {"path": str(build("VanDerPol", 2))},
                       "meas": {"recording": "robot.csv", "signals": {"q[1]": "q1", "q[2]": "q2"},
                                "units": {"q[2]": "m"}}},
        "time": {"stop": STOP_S, "step": 0.001}, "logging": {"signals": "all"}}))
    port, out = free_port(), tmp_path / "live.mcap"
    # --live-wait: the run starts once the viewer has subscribed, so both channels are served from their start (a
    # viewer subscribing while the run went on missed /m's first messages in 1 of 9 runs on a loaded machine)
    cmd = [sys.executable, "-m", "cosim", "run", str(scenario), "--live", str(port), "--live-wait", "60", "--realtime",
           "--out", str(out), "--quiet"]
    proc = subprocess.Popen(cmd, cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        try:
            channels, got, _ = asyncio.run(_watch(port, {"/meas", "/m"}, want=20, deadline=time.monotonic() + 90))
        except OSError as exc:  # never served: the run's own error says why
            proc.kill()
            pytest.fail(f"no live view ({exc}): {proc.communicate(timeout=30)[1].decode()[-1000:]}")
        _, err = proc.communicate(timeout=120)
    finally:
        proc.kill()
    assert proc.returncode == 0, f"exit {proc.returncode}: {err.decode()}"
    schema = json.loads(channels["/meas"]["schema"])
    for name, unit, column in (("q[1]", "m", "q1"), ("q[2]", "m", "q2")):
        prop = schema["properties"][name]
        assert prop["unit"] == unit and prop["causality"] == "output" and f"recorded {column}" in prop["description"], \
            prop
    assert len(got["/meas"]) >= 20 and len(got["/m"]) >= 20, {k: len(v) for k, v in got.items()}
    log = read_run(out)
    logged = {n: log.signal(f"meas.{n}") for n in ("q[1]", "q[2]")}
    for _, msg in got["/meas"]:
        k = int(np.searchsorted(logged["q[1]"].t_ns, round(msg["t"] * 1e9)))
        for name, col, scale in (("q[1]", 0, 1.0), ("q[2]", 1, 1e-3)):
            sig = logged[name]
            assert sig.t_ns[k] == round(msg["t"] * 1e9) and msg[name] == sig.y[k], (name, msg, sig.t_ns[k], sig.y[k])
            want = np.interp(msg["t"], t, q[:, col] * scale)  # the recording at t: linear, mm made m
            assert abs(msg[name] - want) <= 4 * np.finfo(float).eps * abs(want) + 1e-18, (name, msg, want)
