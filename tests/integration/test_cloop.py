"""The master's loop in C (cosim.engine.cloop) against its loop in Python, on the C models of ``tests/cfmus``.

The loop in C makes the same FMI calls in the same order, copies the same bytes and sums the tracking errors in the
same double arithmetic: every value of a run must be the same bit for bit (no tolerance), every early end the same
error or termination, and the stop request, the progress and the record the watchdog reads must work as in the
Python loop.
"""

from __future__ import annotations

import signal

import pytest
import yaml
from cfmus import build
from endings import ENDING_CASES, ending, expected_error

from cosim.engine import cloop
from cosim.engine.scenario import parse_scenario
from cosim.errors import Interrupted
from cosim.run import RunOptions, run_scenario

pytestmark = pytest.mark.integration

EVERY = 7  # macro steps between two snapshots: the loop in C runs blocks of 7


class Snapshots:
    """Every component's input and output bytes every :data:`EVERY` macro steps, taken by the execution's hooks.
    An error-sums observer without pairs (``error_sums``): the loop in C may run with it."""

    error_sums = True

    def __init__(self) -> None:
        self.pairs, self.sq, self.mx, self.t_mx, self.n = [], [], [], [], 0
        self.taken: list[tuple[int, list[bytes]]] = []

    def start(self, ex) -> None:
        self.ex = ex
        for k in range(EVERY, ex.n_steps + 1, EVERY):
            ex.hooks.setdefault(k, []).append(self.take)
        self.take(0)

    def take(self, k: int) -> None:
        self.taken.append((k, [bytes(b.values) for s in self.ex.slaves for b in (*s.in_bufs, *s.out_bufs)]))

    def stepped(self, k, t_ns, active) -> None:
        self.n += 1

    def finish(self, ex, error) -> None:
        return None


def _scenario(tmp_path, components: dict, connections: list[tuple[str, str]], stop: float, step: float,
              algorithm: str = "gauss_seidel", compare: tuple[str, str] | None = None):
    doc = {"name": "loops", "components": components, "connections": [{"from": a, "to": b} for a, b in connections],
           "time": {"stop": stop, "step": step}, "parallel": "off", "algorithm": algorithm}
    if compare is not None:
        doc["compare"] = {"actual": [compare[0]], "reference": [compare[1]]}
    return parse_scenario(yaml.safe_dump(doc, sort_keys=False), str(tmp_path / "loops.yaml"))


class Steps:
    """An observer in Python (not error sums): the loop in C makes one call per macro step and calls it after each."""

    def __init__(self) -> None:
        self.seen: list[tuple[int, int, list[int]]] = []

    def start(self, ex) -> None:
        return None

    def stepped(self, k, t_ns, active) -> None:
        self.seen.append((k, t_ns, list(active)))

    def finish(self, ex, error) -> None:
        return None


def _run(scenario, monkeypatch, *, in_c: bool, each: bool = False):
    """(snapshots, result, blocks the loop in C ran) of a run with its loop in C or in Python; ``each``: with an
    observer in Python too (then ``blocks`` counts the blocks of single macro steps)."""
    blocks: list[int] = []
    with monkeypatch.context() as m:
        if in_c:
            run, block = cloop.CLoop.run, cloop.CLoop._block

            def spy(self, k, n):
                blocks.append(n)
                return run(self, k, n)

            def spy_each(self, k, n):
                blocks.append(n)
                return block(self, k, n)

            m.setattr(cloop.CLoop, "_block" if each else "run", spy_each if each else spy)
        else:
            m.setattr(cloop, "make", lambda ex: None)
        snaps = Snapshots()
        observers = [snaps, Steps()] if each else [snaps]
        result = run_scenario(scenario, RunOptions(log=False, observers=observers))
    if each:
        snaps.steps = observers[1].seen
    return snaps, result, blocks


FMI2 = ({"osc": "VanDerPol", "a": "Feedthrough", "b": "Feedthrough"},
        [("osc.x0", "a.Real_input"), ("a.Real_output", "b.Real_input"), ("a.Integer_output", "b.Integer_input"),
         ("a.Boolean_output", "b.Boolean_input"), ("a.Enumeration_output", "b.Enumeration_input")])
FMI3 = ({"osc": "VanDerPol", "a": "Feedthrough", "b": "Feedthrough"},
        [("osc.x0", "a.Float64_input"), ("a.Float64_output", "b.Float64_input"),
         ("a.Float32_output", "b.Float32_input"), ("a.Int8_output", "b.Int8_input"),
         ("a.UInt64_output", "b.UInt64_input"), ("a.Boolean_output", "b.Boolean_input"),
         ("a.Float64_array_output", "b.Float64_array_input")])


@pytest.mark.parametrize("each", [False, True], ids=["blocks", "each step"])
@pytest.mark.parametrize("algorithm", ["gauss_seidel", "jacobi"])
@pytest.mark.parametrize("fmi, case", [(2, FMI2), (3, FMI3)], ids=["fmi2", "fmi3"])
def test_the_loop_in_c_gives_the_python_loops_run(tmp_path, monkeypatch, fmi, case, algorithm, each):
    models, connections = case
    components = {name: {"path": str(build(model, fmi))} for name, model in models.items()}
    scenario = _scenario(tmp_path, components, connections, 0.5, 1e-3, algorithm, compare=("osc.x0", "osc.x1"))
    c_snaps, c_res, blocks = _run(scenario, monkeypatch, in_c=True, each=each)
    assert blocks and sum(blocks) == 500 and max(blocks) == EVERY, f"blocks of the loop in C: {blocks[:5]}..."
    py_snaps, py_res, _ = _run(scenario, monkeypatch, in_c=False, each=each)
    if each:
        assert c_snaps.steps == py_snaps.steps and len(c_snaps.steps) == 500, "the observer saw other steps"
    assert c_res.steps == py_res.steps == 500, f"steps {c_res.steps} vs {py_res.steps}"
    assert len(c_snaps.taken) == len(py_snaps.taken) == 1 + 500 // EVERY, (len(c_snaps.taken), len(py_snaps.taken))
    for (k, c_bytes), (k_py, py_bytes) in zip(c_snaps.taken, py_snaps.taken):
        assert k == k_py and c_bytes == py_bytes, f"after macro step {k}: the buffers differ"
    assert c_snaps.taken[1][1] != c_snaps.taken[-1][1], "nothing moved: the test compares constants"
    c_err, py_err = c_res.errors[0], py_res.errors[0]
    assert (c_err.rmse, c_err.max_error, c_err.t_max, c_err.samples) == \
        (py_err.rmse, py_err.max_error, py_err.t_max, py_err.samples), f"tracking: C {c_err} vs Python {py_err}"
    assert c_err.max_error > 0, f"the tracked error is zero: the test compares nothing ({c_err})"
    assert c_snaps.n == py_snaps.n == 500, f"observer steps: C {c_snaps.n}, Python {py_snaps.n}"
    assert set(c_res.component_time) == set(models) and all(v > 0 for v in c_res.component_time.values()), \
        c_res.component_time


def test_a_link_that_converts_keeps_the_python_loop(tmp_path, monkeypatch):
    """A Float64 output into a Float32 input converts through Python: the run takes the Python loop, unchanged."""
    components = {name: {"path": str(build(model, 3))} for name, model in FMI3[0].items()}
    scenario = _scenario(tmp_path, components, [*FMI3[1], ("osc.x1", "a.Float32_input")], 0.1, 1e-3)
    c_snaps, _, blocks = _run(scenario, monkeypatch, in_c=True)
    assert blocks == [], f"the loop in C ran blocks {blocks[:5]}... over a converting link"
    py_snaps, _, _ = _run(scenario, monkeypatch, in_c=False)
    assert c_snaps.taken == py_snaps.taken, "the same loop gave different values"


def _ending(tmp_path, monkeypatch, components, connections, stop, step, in_c: bool, each: bool):
    scenario = _scenario(tmp_path, components, connections, stop, step)
    return ending(lambda: _run(scenario, monkeypatch, in_c=in_c, each=each)[1])


@pytest.mark.parametrize("what, components, connections, stop, step", ENDING_CASES)
@pytest.mark.parametrize("each", [False, True], ids=["blocks", "each step"])
def test_the_loop_in_c_ends_as_the_python_loop_ends(tmp_path, monkeypatch, what, components, connections, stop, step,
                                                    each):
    comps = {name: {"path": str(build(model, fmi)), "parameters": params}
             for name, (model, fmi, params) in components.items()}
    c_end = _ending(tmp_path, monkeypatch, comps, connections, stop, step, in_c=True, each=each)
    py_end = _ending(tmp_path, monkeypatch, comps, connections, stop, step, in_c=False, each=each)
    assert c_end == py_end, f"{what}: loop in C {c_end} vs loop in Python {py_end}"
    assert (c_end[0][0] if c_end[0] else None) == expected_error(what), f"{what}: ended as {c_end}"


def test_a_stop_request_is_answered_at_the_end_of_a_block(tmp_path, monkeypatch):
    """Progress every 100 steps ends the blocks there; a stop requested in the report of step 300 ends the run
    there, with the steps done recorded where the watchdog and the supervisor read them."""
    from cosim.engine.execution import Execution

    scenario = _scenario(tmp_path, {"osc": {"path": str(build("VanDerPol", 2))}}, [], 2.0, 1e-3)
    simulate_until, seen = Execution.simulate_until, {}

    def with_progress(self, t_ns=None, stop=None, progress=None, progress_every=0):
        def report(k):
            seen.setdefault("reports", []).append(k)
            seen["record"] = self.current[3]
            if k == 300:
                stop.request(signal.SIGTERM)
        return simulate_until(self, t_ns, stop, report, 100)

    monkeypatch.setattr(Execution, "simulate_until", with_progress)
    with pytest.raises(Interrupted):
        _run(scenario, monkeypatch, in_c=True)
    assert seen["reports"] == [100, 200, 300], seen
    assert seen["record"] == 300.0, f"steps done in the record: {seen['record']}"


CRASH = """
name: held
components:
  src: {path: "{CosimTCrash}", parameters: {mode: 4, at: 0.5, hold: 60}}
  g: {path: "{CosimTGain}"}
connections:
  - {from: src.y, to: g.u}
time: {stop: 3.0, step: 0.001}
parallel: off
watchdog_s: 1.0
"""


def test_a_component_stuck_in_the_loop_in_c_is_named_at_its_step(write_scenario, tmp_path):
    """Without a log the run takes the loop in C (two PythonFMU components, called with the Python lock held); the
    FMU holding that lock in C at t = 0.5 s is named, with its step's time, from the record the loop in C writes."""
    import os
    import subprocess
    import sys
    from pathlib import Path

    root = Path(__file__).resolve().parents[2]
    path = write_scenario(CRASH)
    env = {**os.environ, "PYTHONPATH": str(root)}
    r = subprocess.run([sys.executable, "-m", "cosim", "run", str(path), "--no-log", "--quiet"], capture_output=True,
                       text=True, env=env, cwd=root, timeout=60)
    assert r.returncode == 2 and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    first = r.stderr.strip().splitlines()[0]
    assert first.startswith("error: ") and "component 'src' in its step at t = 0.499 s made no progress" in first, \
        r.stderr
