"""A logged run whose loop in C copies each step's log row (cosim.engine.cloop.Blocks, the publisher's joint rows)
against the same run with its loop in Python: the same log, message by message, and a crash inside a block keeps
every step completed before it.

The loop in C enters Python once per block (a scene due, the rows full); every macro step's row is still copied
(in C, into the memory a forked writer shares), so the log must hold exactly the messages the Python loop logs: the
same channels, the same bytes at the same log times, in the same order.
"""

from __future__ import annotations

import os
import subprocess
import sys
from collections import defaultdict
from pathlib import Path

import pytest

from cosim.engine import cloop
from cosim.engine.scenario import load_scenario
from cosim.io.runlog import read_run
from cosim.observers.log_writer import writer_forks
from cosim.run import RunOptions, run_scenario

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]


def _messages(path: Path) -> tuple[dict, list]:
    """(per topic: schema name, schema, channel metadata; every message as (topic, log time, publish time, data) in
    the file's order)."""
    from mcap.reader import make_reader

    channels, messages = {}, []
    with open(path, "rb") as f:
        for schema, channel, m in make_reader(f).iter_messages(log_time_order=False):
            channels[channel.topic] = (schema.name, schema.data, dict(channel.metadata))
            messages.append((channel.topic, m.log_time, m.publish_time, m.data))
    return channels, messages


def _logged(scenario, out: Path, monkeypatch, *, in_c: bool, live: bool = False) -> list[int]:
    """Run ``scenario`` logged to ``out`` (simulation stamps: comparable logs) with its loop in C or in Python, and
    with a live view (a free port) when ``live``; the macro steps of each block the loop in C ran with the log's rows
    copied in C."""
    blocks: list[int] = []
    with monkeypatch.context() as m:
        if in_c:
            run = cloop.CLoop.run

            def spy(self, k, n):
                done = run(self, k, n)
                if self.section is not None:
                    blocks.append(done)
                return done

            m.setattr(cloop.CLoop, "run", spy)
        else:
            m.setattr(cloop, "make", lambda ex: None)
        result = run_scenario(scenario, RunOptions(out=out, log=True, stamps="simulation",
                                                   live=("127.0.0.1", 0) if live else None))
    assert result.status == "completed", (result.status, result.message)
    return blocks


@pytest.mark.parametrize("layout, live", [("samples", False), ("blocks", False), ("samples", True)],
                         ids=["samples", "blocks", "samples and a live view"])
def test_a_logged_run_in_c_blocks_writes_the_python_loops_log(tmp_path, monkeypatch, layout, live):
    """helix_ctc_analytic on native FMUs for 0.457 s (a stop between two scenes): its 3D scene at 30 Hz (and the live
    view's clock, every 33 ms) ends the blocks; every channel's messages are those of the Python loop, byte for
    byte."""
    overrides = {("fmus",): "native", ("parallel",): "off", ("time", "stop"): 0.457, ("logging", "layout"): layout}
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc_analytic.yaml", overrides)
    blocks = _logged(scenario, tmp_path / "c.mcap", monkeypatch, in_c=True, live=live)
    assert sum(blocks) == 457 and max(blocks) > 30, f"blocks the loop in C ran with the rows: {blocks}"
    _logged(scenario, tmp_path / "py.mcap", monkeypatch, in_c=False, live=live)
    c_channels, c_messages = _messages(tmp_path / "c.mcap")
    py_channels, py_messages = _messages(tmp_path / "py.mcap")
    assert c_channels == py_channels, (sorted(c_channels), sorted(py_channels))
    per_topic = defaultdict(int)
    for topic, *_ in py_messages:
        per_topic[topic] += 1
    assert per_topic["/plant"] == (458 if layout == "samples" else 15), dict(per_topic)
    first = next((i for i, (a, b) in enumerate(zip(c_messages, py_messages)) if a != b), None)
    assert first is None and len(c_messages) == len(py_messages), \
        (first, c_messages[first] if first is not None else len(c_messages),
         py_messages[first] if first is not None else len(py_messages))


CRASH = """
name: crash_in_block
components:
  src: {{path: "{{CosimTCrash}}", parameters: {{mode: {mode}, at: 0.4, hold: 60}}}}
  g: {{path: "{{CosimTGain}}"}}
connections:
  - {{from: src.y, to: g.u}}
time: {{stop: 0.5, step: 0.001}}
parallel: off
"""


def test_a_crash_inside_a_block_keeps_every_step_before_it(write_scenario, tmp_path, monkeypatch):
    """Blocks of 34 macro steps (the publisher hands its rows over at 30 Hz: after the steps ending at 34, 68, ...,
    374, 408 ms): the source segfaults in step 399, the 26th of the block from step 374, whose rows only the loop in C
    copied, into the memory the forked writer shares. The same scenario without the crash runs those blocks in C;
    with it, the recovered log has every step up to the crash."""
    if not writer_forks():
        pytest.skip("the writer cannot be forked here: short runs log in the master")
    calm = load_scenario(write_scenario(CRASH.format(mode=0), "calm.yaml"))
    blocks = _logged(calm, tmp_path / "calm.mcap", monkeypatch, in_c=True)
    # every step in C with its row copied there; blocks of 34 steps, fewer where the call's wall budget ran out (a
    # loaded machine), which hands no rows over: those since the step ending at 374 ms lie in the shared memory alone
    assert sum(blocks) == 500 and max(blocks) > 1, f"blocks with the rows copied in C: {blocks}"
    path = write_scenario(CRASH.format(mode=1))
    out = tmp_path / "logs" / "crash.mcap"
    out.parent.mkdir()
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-m", "cosim", "run", str(path), "--out", str(out), "--quiet"],
                          capture_output=True, text=True, env=env, cwd=ROOT, timeout=120)
    assert proc.returncode == 2 and "t = 0.399 s crashed (SIGSEGV)" in proc.stderr, (proc.returncode, proc.stderr)
    run = read_run(out)
    for name in ("g.y", "src.y"):
        got = run.signal(name).t_ns.tolist()
        assert got == [k * 1_000_000 for k in range(400)], (name, len(got), got[-3:])
