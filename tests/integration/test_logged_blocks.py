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
import yaml
from cfmus import build
from endings import ENDING_CASES, ending, expected_error

from cosim.engine import cloop
from cosim.engine.scenario import load_scenario, parse_scenario
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


class _Each:
    """An observer in Python after every macro step (as a caller's own): the loop in C makes a call per step."""

    def start(self, ex) -> None:
        return None

    def stepped(self, k, t_ns, active) -> None:
        return None

    def finish(self, ex, error) -> None:
        return None


def _logged(scenario, out: Path, monkeypatch, *, in_c: bool, live: bool = False, blocks: list | None = None,
            each: bool = False):
    """The result of ``scenario`` logged to ``out`` (simulation stamps: comparable logs) with its loop in C or in
    Python, and with a live view (a free port) when ``live``; ``blocks`` gets the macro steps of each block the loop in
    C ran with the log's rows copied in C; ``each``: with an observer in Python after every step."""
    blocks = [] if blocks is None else blocks
    with monkeypatch.context() as m:
        if in_c:
            run = cloop.CLoop.run

            def spy(self, k, n):
                try:
                    return run(self, k, n)
                finally:  # also the steps done before one that ended the run (raised)
                    if self.section is not None:
                        blocks.append(self.ex.k_done - k)

            m.setattr(cloop.CLoop, "run", spy)
        else:
            m.setattr(cloop, "make", lambda ex: None)
        return run_scenario(scenario, RunOptions(out=out, log=True, stamps="simulation",
                                                 live=("127.0.0.1", 0) if live else None,
                                                 observers=[_Each()] if each else ()))


def _same_log(c_log: Path, py_log: Path) -> None:
    c_channels, c_messages = _messages(c_log)
    py_channels, py_messages = _messages(py_log)
    assert c_channels == py_channels, (sorted(c_channels), sorted(py_channels))
    first = next((i for i, (a, b) in enumerate(zip(c_messages, py_messages)) if a != b), None)
    assert first is None and len(c_messages) == len(py_messages), \
        (first, c_messages[first] if first is not None else len(c_messages),
         py_messages[first] if first is not None else len(py_messages))


@pytest.mark.parametrize("layout, live, each", [("samples", False, False), ("blocks", False, False),
                                               ("samples", True, False), ("samples", False, True)],
                         ids=["samples", "blocks", "samples and a live view", "samples, a call per step"])
def test_a_logged_run_in_c_blocks_writes_the_python_loops_log(tmp_path, monkeypatch, layout, live, each):
    """helix_ctc_analytic on native FMUs for 0.457 s (a stop between two scenes): its 3D scene at 30 Hz (and the live
    view's clock, every 33 ms) ends the blocks; every channel's messages are those of the Python loop, byte for
    byte. With an observer that needs Python after every step, the loop in C makes a call per step and the publisher
    copies the rows in Python, to the same log."""
    overrides = {("fmus",): "native", ("parallel",): "off", ("time", "stop"): 0.457, ("logging", "layout"): layout}
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc_analytic.yaml", overrides)
    blocks: list[int] = []
    _logged(scenario, tmp_path / "c.mcap", monkeypatch, in_c=True, live=live, blocks=blocks, each=each)
    if each:
        assert blocks == [], f"blocks with the rows copied in C beside an observer in Python: {blocks}"
    else:
        assert sum(blocks) == 457 and max(blocks) > 30, f"blocks the loop in C ran with the rows: {blocks}"
    _logged(scenario, tmp_path / "py.mcap", monkeypatch, in_c=False, live=live, each=each)
    per_topic = defaultdict(int)
    for topic, *_ in _messages(tmp_path / "py.mcap")[1]:
        per_topic[topic] += 1
    assert per_topic["/plant"] == (458 if layout == "samples" else 15), dict(per_topic)
    _same_log(tmp_path / "c.mcap", tmp_path / "py.mcap")


NUMBERS_ONLY = ("non-finite output, numbers only", {"osc": ("VanDerPol", 2, {"mu": 1e6})}, [], 1.0, 1e-3)


@pytest.mark.parametrize("what, components, connections, stop, step", [*ENDING_CASES, NUMBERS_ONLY])
def test_a_logged_run_in_c_blocks_ends_and_logs_as_the_python_loop(tmp_path, monkeypatch, what, components,
                                                                  connections, stop, step):
    """A rejected step, an FMU's end of the simulation, a non-finite output inside a block: the same ending and the
    same log (the steps before it, the last step's samples of an FMU's end) as the Python loop."""
    comps = {name: {"path": str(build(model, fmi)), "parameters": params}
             for name, (model, fmi, params) in components.items()}
    doc = {"name": "ends", "components": comps, "connections": [{"from": a, "to": b} for a, b in connections],
           "time": {"stop": stop, "step": step}, "parallel": "off"}
    scenario = parse_scenario(yaml.safe_dump(doc, sort_keys=False), str(tmp_path / "ends.yaml"))
    blocks: list[int] = []
    c_end = ending(lambda: _logged(scenario, tmp_path / "c.mcap", monkeypatch, in_c=True, blocks=blocks))
    py_end = ending(lambda: _logged(scenario, tmp_path / "py.mcap", monkeypatch, in_c=False))
    assert c_end == py_end and (c_end[0][0] if c_end[0] else None) == expected_error(what), (c_end, py_end)
    # rows copied in C; blocks of one step where a step (0.1 s) is longer than the period of the handovers (30 Hz);
    # none where a component logs strings (Feedthrough: its values are read one by one, in Python after every step)
    if all(model != "Feedthrough" for model, _, _ in components.values()):
        assert blocks and (max(blocks) > 1 or step > 1 / 30), f"{what}: blocks the loop in C ran with rows: {blocks}"
    else:
        assert blocks == [], f"{what}: rows copied in C for a component of strings: {blocks}"
    _same_log(tmp_path / "c.mcap", tmp_path / "py.mcap")


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
    blocks: list[int] = []
    _logged(calm, tmp_path / "calm.mcap", monkeypatch, in_c=True, blocks=blocks)
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
