"""A co-simulation component's turn in one C call (cosim.fmi.turn) against the same calls made from Python.

The C turn makes the FMI calls the Python path makes, in the same order, and ends where the Python
path raises; so every run must give the same values bit for bit, and every early end the same
error or termination. The FMUs are the C models of ``tests/cfmus`` (FMI 2 and 3, numbers of every
type, arrays, strings), so the values are checked exactly (no tolerance: same calls, same binaries).
"""

from __future__ import annotations

import ctypes

import pytest
import yaml
from cfmus import build
from endings import ENDING_CASES, ending, expected_error

from cosim.fmi import turn
from cosim.fmi import load_fmu, make_slave
from cosim.fmi.slave import CoSimulation
from cosim.observers.recorders import Probe
from cosim.run import run_scenario
from cosim.engine.scenario import parse_scenario

pytestmark = pytest.mark.integration


def _scenario(tmp_path, components: dict, connections: list[tuple[str, str]], stop: float, step: float):
    text = yaml.safe_dump({"name": "turns", "components": components,
                           "connections": [{"from": a, "to": b} for a, b in connections],
                           "time": {"stop": stop, "step": step}, "parallel": "off"}, sort_keys=False)
    return parse_scenario(text, str(tmp_path / "turns.yaml"))


def _run(scenario, signals: list[str], *, python: bool, monkeypatch, made: list | None = None):
    """The run's probed values and result, with the C turns (``python=False``; ``made`` gets, per component,
    whether it has one) or with the Python calls."""
    with monkeypatch.context() as m:
        if python:
            m.setattr(turn, "helper", lambda: None)
        elif made is not None:
            bind = CoSimulation._bind_turn

            def spy(self):
                bind(self)
                made.append(self._c_turn is not None)

            m.setattr(CoSimulation, "_bind_turn", spy)
        probe = Probe(signals)
        result = run_scenario(scenario, log=False, observers=[probe])
    return probe, result


FMI2 = (
    {"osc": "VanDerPol", "a": "Feedthrough", "b": "Feedthrough"},
    [("osc.x0", "a.Real_input"), ("a.Real_output", "b.Real_input"), ("a.Integer_output", "b.Integer_input"),
     ("a.Boolean_output", "b.Boolean_input"), ("a.Enumeration_output", "b.Enumeration_input")],
    ["osc.x0", "a.Real_output", "a.Integer_output", "a.Boolean_output", "a.Enumeration_output"],
)
FMI3 = (
    {"osc": "VanDerPol", "a": "Feedthrough", "b": "Feedthrough"},
    [("osc.x0", "a.Float64_input"), ("osc.x1", "a.Float32_input"), ("a.Float64_output", "b.Float64_input"),
     ("a.Float32_output", "b.Float32_input"), ("a.Int8_output", "b.Int8_input"), ("a.UInt64_output", "b.UInt64_input"),
     ("a.Boolean_output", "b.Boolean_input"), ("a.Float64_array_output", "b.Float64_array_input")],
    ["osc.x0", "osc.x1", "a.Float64_output", "a.Float32_output", "a.Int8_output", "a.UInt64_output",
     "a.Boolean_output", "a.Float64_array_output"],
)


@pytest.mark.parametrize("fmi, case", [(2, FMI2), (3, FMI3)], ids=["fmi2", "fmi3"])
def test_c_turns_and_python_calls_give_the_same_run(tmp_path, monkeypatch, fmi, case):
    models, connections, signals = case
    components = {name: {"path": str(build(model, fmi))} for name, model in models.items()}
    scenario = _scenario(tmp_path, components, connections, 0.5, 1e-3)
    made: list[bool] = []
    c_probe, c_result = _run(scenario, signals, python=False, monkeypatch=monkeypatch, made=made)
    assert made == [True, True, True], f"C turns made per component: {made}"
    py_probe, py_result = _run(scenario, signals, python=True, monkeypatch=monkeypatch)
    assert c_result.steps == py_result.steps == 500, f"steps {c_result.steps} vs {py_result.steps}"
    assert c_probe.t_ns == py_probe.t_ns, "sample times differ"
    for s in signals:
        c_values, py_values = c_probe.values[s], py_probe.values[s]
        assert c_values == py_values, f"{s}: C turns {c_values[:3]}... vs Python calls {py_values[:3]}..."
    assert len(set(c_probe.values["osc.x0"])) > 100, "the oscillator did not move: the test compares constants"


def test_a_component_exchanging_strings_keeps_the_python_calls(tmp_path, monkeypatch):
    """Strings go through fmpy: that component's turn stays in Python, the others' are C, the run the same."""
    components = {"osc": {"path": str(build("VanDerPol", 2))}, "a": {"path": str(build("Feedthrough", 2))},
                  "b": {"path": str(build("Feedthrough", 2))}}
    connections = [("osc.x0", "a.Real_input"), ("a.Real_output", "b.Real_input"), ("a.String_output", "b.String_input")]
    scenario = _scenario(tmp_path, components, connections, 0.2, 1e-3)
    made: list[bool] = []
    c_probe, _ = _run(scenario, ["a.Real_output", "a.String_output"], python=False, monkeypatch=monkeypatch, made=made)
    assert made == [True, False, False], f"C turns made per component (a and b exchange a string): {made}"
    py_probe, _ = _run(scenario, ["a.Real_output", "a.String_output"], python=True, monkeypatch=monkeypatch)
    assert c_probe.values == py_probe.values, f"{c_probe.values} vs {py_probe.values}"


def _ending(tmp_path, monkeypatch, components, connections, stop, step, python: bool):
    """(error text, None) or (None, result summary) of a run that ends early."""
    scenario = _scenario(tmp_path, components, connections, stop, step)
    return ending(lambda: _run(scenario, [], python=python, monkeypatch=monkeypatch)[1])


@pytest.mark.parametrize("what, components, connections, stop, step", ENDING_CASES)
def test_a_turn_ends_as_the_python_calls_end(tmp_path, monkeypatch, what, components, connections, stop, step):
    comps = {name: {"path": str(build(model, fmi)), "parameters": params}
             for name, (model, fmi, params) in components.items()}
    c_end = _ending(tmp_path, monkeypatch, comps, connections, stop, step, python=False)
    py_end = _ending(tmp_path, monkeypatch, comps, connections, stop, step, python=True)
    assert c_end == py_end, f"{what}: C turn {c_end} vs Python calls {py_end}"
    error, result = c_end
    assert (error[0] if error else None) == expected_error(what), f"{what}: ended as {c_end}"
    if what == "non-finite output":
        assert error[1] == "osc" and "non-finite output x0" in error[3], error


def test_the_turn_says_which_call_failed():
    """cosim_turn's contract, on an FMU that rejects an unknown value reference: the phase, the call's
    index among its kind and its status come back; the calls before it were made, none after."""
    slave = make_slave("osc", load_fmu(build("VanDerPol", 2)))
    variables = slave.info.variables
    slave.bind([], [variables["x0"], variables["x1"]])
    slave.instantiate()
    slave.enter_initialization(0.0, 1.0)
    slave.exit_initialization()
    try:
        dll = slave.fmu.dll
        address = {n: ctypes.cast(getattr(dll, n), ctypes.c_void_p).value for n in ("fmi2GetReal", "fmi2DoStep")}
        good_vrs = (ctypes.c_uint32 * 1)(variables["x0"].vr)
        bad_vrs = (ctypes.c_uint32 * 1)(4242)
        values = (ctypes.c_double * 1)(-1.0)

        def get(vrs):
            return turn.Exchange(address["fmi2GetReal"], ctypes.addressof(vrs), 1, ctypes.addressof(values), 1)

        t, h = ctypes.c_double(0.0), ctypes.c_double(1e-3)
        call, u = turn.make_turn(2, slave._c, address["fmi2DoStep"], t, h, [], [get(good_vrs), get(bad_vrs)], [],
                                 None, lambda f: slave._prototype(f, None))
        ended = call()
        assert (ended, u.index, u.status) == (turn.GET, 1, 3), \
            f"(phase, index, status) = {(ended, u.index, u.status)}, expected GET of the second buffer, fmi2Error"
        assert values[0] == pytest.approx(2.0, abs=1e-2), f"the first get read x0 = {values[0]} after one step from 2"
        assert "unknown value reference 4242" in slave._last_log(), slave._last_log()
    finally:
        slave.terminate()
        slave.free()


def test_no_compiler_is_a_reason_not_a_failure(tmp_path, monkeypatch):
    """Without a compiler the helper cannot be built: _build says so (helper() then returns None and the
    master makes the calls from Python)."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # an empty cache: it must compile
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    with pytest.raises(RuntimeError, match="no C compiler"):
        turn._build()
    assert not list(tmp_path.rglob("*.so")), "a failed build left a library in the cache"
