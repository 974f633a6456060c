"""A model-exchange FMU's right-hand side in one C call (cosim.fmi.turn's cosim_rhs) against the same calls
made from Python.

The C right-hand side makes the FMI calls the Python path makes (set time, set continuous states, get
derivatives), in the same order with the same values, and ends where the Python path raises; so every
run must give the same values bit for bit, and every failing call the same error. The FMUs are the C
models of ``tests/cfmus`` (state events, FMI 2 and 3), the native plant of ``helix_ctc_me`` and its
python build (pythonfmu3: its calls keep the GIL); values are checked exactly (no tolerance: same calls,
same binaries).
"""

from __future__ import annotations

import ctypes
from ctypes import c_double
from pathlib import Path

import pytest
import yaml
from cfmus import build

from cosim.fmi import turn
from cosim.errors import FMIError
from cosim.fmi import load_fmu, make_slave
from cosim.fmi.model_exchange import ModelExchange
from cosim.observers.recorders import Probe
from cosim.run import run_scenario
from cosim.engine.scenario import load_scenario, parse_scenario
from fmus import registry

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]


def _run(scenario, signals: list[str], *, python: bool, monkeypatch):
    """(probed values, result, per model-exchange component whether it got a C right-hand side) of a run with
    the C right-hand side (``python=False``) or with the Python calls."""
    made: list[bool] = []
    with monkeypatch.context() as m:
        if python:
            m.setattr(turn, "rhs_helper", lambda: None)
        bind = ModelExchange._bind_rhs

        def spy(self):
            bind(self)
            made.append(self._c_rhs is not None)

        m.setattr(ModelExchange, "_bind_rhs", spy)
        probe = Probe(signals)
        result = run_scenario(scenario, log=False, observers=[probe], read_all=True)
    return probe, result, made


def _assert_same_runs(c_run, py_run, signals: list[str]) -> None:
    (c_probe, c_result, c_made), (py_probe, py_result, py_made) = c_run, py_run
    assert c_made and all(c_made), f"C right-hand sides made per ME component: {c_made}"
    assert py_made and not any(py_made), f"the Python run made C right-hand sides: {py_made}"
    assert (c_result.steps, c_result.events) == (py_result.steps, py_result.events), \
        f"steps, events: C {c_result.steps}, {c_result.events} vs Python {py_result.steps}, {py_result.events}"
    assert c_probe.t_ns == py_probe.t_ns, "sample times differ"
    for s in signals:
        c_values, py_values = c_probe.values[s], py_probe.values[s]
        assert c_values == py_values, f"{s}: C right-hand side {c_values[:3]}... vs Python calls {py_values[:3]}..."


@pytest.mark.parametrize("model, fmi, solver, signals", [
    ("VanDerPol", 2, "cvode", ["m.x0", "m.x1"]),
    ("VanDerPol", 3, "dop853", ["m.x0", "m.x1"]),
    ("BouncingBall", 2, "dop853", ["m.h", "m.v", "m.bounces"]),
    ("BouncingBall", 3, "cvode", ["m.h", "m.v", "m.bounces"]),
])
def test_c_and_python_right_hand_sides_give_the_same_run(tmp_path, monkeypatch, model, fmi, solver, signals):
    text = yaml.safe_dump({"name": "rhs", "components": {"m": {"path": str(build(model, fmi)), "interface": "me",
                                                               "rtol": 1e-8, "solver": solver}},
                           "time": {"stop": 2.0, "step": 1e-2}, "parallel": "off"}, sort_keys=False)
    scenario = parse_scenario(text, str(tmp_path / "rhs.yaml"))
    c_run = _run(scenario, signals, python=False, monkeypatch=monkeypatch)
    py_run = _run(scenario, signals, python=True, monkeypatch=monkeypatch)
    _assert_same_runs(c_run, py_run, signals)
    assert len(set(c_run[0].values[signals[0]])) > 100, "the model did not move: the test compares constants"
    if model == "BouncingBall":
        assert c_run[1].events["m"] >= 2, f"no bounces to compare: {c_run[1].events}"


@pytest.mark.parametrize("fmus, solver", [("native", "dop853"), ("native", "cvode"), ("python", "dop853")])
def test_helix_ctc_me_is_the_same_run_with_either_right_hand_side(monkeypatch, fmus, solver):
    """The plant of the ME scenario, fed by the controller at every step, on its native build (FMI 3, GIL
    released) and its python build (pythonfmu3, GIL kept)."""
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc_me.yaml",
                             {("time", "stop"): 0.05, ("fmus",): fmus, ("parallel",): "off",
                              ("components", "plant", "solver"): solver})
    signals = ["plant.p.x", "plant.p.z", "plant.qd[1]", "ctl.u[2]"]
    c_run = _run(scenario, signals, python=False, monkeypatch=monkeypatch)
    py_run = _run(scenario, signals, python=True, monkeypatch=monkeypatch)
    assert c_run[1].steps == 50, f"{c_run[1].steps} steps, expected 50"
    _assert_same_runs(c_run, py_run, signals)


def _me_slave(path: Path):
    slave = make_slave("m", load_fmu(path), "me")
    slave.instantiate()
    slave.enter_initialization(0.0, 1.0)
    slave.bind([], [])
    slave.exit_initialization()
    return slave


def _failure(path: Path, x: list[float], before, python: bool, monkeypatch) -> tuple:
    """The error (type, component, function, time, text) of one right-hand side at t = 0.5 s and ``x``, after
    ``before(slave)`` put the FMU where a call fails."""
    with monkeypatch.context() as m:
        if python:
            m.setattr(turn, "rhs_helper", lambda: None)
        slave = _me_slave(path)
    assert (slave._c_rhs is None) == python, f"C right-hand side made: {slave._c_rhs is not None}"
    try:
        before(slave)
        with pytest.raises(FMIError) as info:
            slave.rhs(0.5, (c_double * len(x))(*x), (c_double * len(x))())
    finally:
        slave.free()
    err = info.value
    return type(err).__name__, err.component, err.function, err.time, str(err)


def _nothing(slave) -> None:
    return None


FAILURES = [
    ("set time, terminated", lambda: build("VanDerPol", 2), [1.0, 1.0], lambda s: s.terminate(), "fmi2SetTime"),
    ("set time, FMI 3 event mode", lambda: build("VanDerPol", 3), [1.0, 1.0], lambda s: s._enter_event_mode(),
     "fmi3SetTime"),
    ("set states, event mode", lambda: build("VanDerPol", 2), [1.0, 1.0], lambda s: s._enter_event_mode(),
     "fmi2SetContinuousStates"),
    ("derivatives, error status", lambda: registry.build("linear_analytic_plant_me", native=True, fmi=2),
     [0.0, 0.9, 0.9, 0.0, 0.0, 0.0], _nothing, "fmi2GetDerivatives"),
    ("derivatives, error logged", lambda: registry.build("linear_analytic_plant_me", native=False, fmi=3),
     [0.0, 0.9, 0.9, 0.0, 0.0, 0.0], _nothing, "fmi3GetContinuousStateDerivatives"),
    ("non-finite derivatives", lambda: build("VanDerPol", 3), [1e200, 1e200], _nothing,
     "fmi3GetContinuousStateDerivatives"),
]


@pytest.mark.parametrize("what, path, x, before, function", FAILURES, ids=[f[0] for f in FAILURES])
def test_a_failing_call_raises_as_the_python_calls_raise(monkeypatch, what, path, x, before, function):
    fmu = path()
    c_error = _failure(fmu, x, before, python=False, monkeypatch=monkeypatch)
    py_error = _failure(fmu, x, before, python=True, monkeypatch=monkeypatch)
    assert c_error == py_error, f"{what}: C right-hand side {c_error} vs Python calls {py_error}"
    assert c_error[2] == function and c_error[3] == 0.5, f"{what}: {c_error}, expected {function} at t = 0.5 s"
    if what == "non-finite derivatives":
        assert "non-finite der(x1) = -inf" in c_error[4], c_error


def test_the_right_hand_side_says_which_call_failed():
    """cosim_rhs's contract, on an FMU in event mode (FMI 2: fmi2SetTime allowed, fmi2SetContinuousStates not):
    the phase and the call's status come back; the call before it was made, none after."""
    slave = _me_slave(build("VanDerPol", 2))
    try:
        slave._enter_event_mode()
        dll = slave.fmu.dll
        address = {n: ctypes.cast(getattr(dll, n), ctypes.c_void_p).value
                   for n in ("fmi2SetTime", "fmi2SetContinuousStates", "fmi2GetDerivatives")}
        t = c_double(0.25)
        call, r = turn.make_rhs(slave._c, address["fmi2SetTime"], address["fmi2SetContinuousStates"],
                                address["fmi2GetDerivatives"], 2, t, lambda f: slave._prototype(f, None))
        x, dx = (c_double * 2)(1.0, 1.0), (c_double * 2)(-7.0, -7.0)
        ended = call(x, dx)
        assert (ended, r.status) == (turn.STATES, 3), \
            f"(phase, status) = {(ended, r.status)}, expected STATES, fmi2Error"
        assert list(dx) == [-7.0, -7.0], f"dx = {list(dx)}: fmi2GetDerivatives was called after the failure"
        assert "must not be called in EventMode" in slave._last_log(), slave._last_log()
        slave._enter_continuous_mode()
        assert call(x, dx) == 0, f"ended with {r.status} in continuous-time mode"
        assert list(dx) == [1.0, -1.0], f"dx = {list(dx)} at x = (1, 1), mu = 1: expected (x1, mu (1 - x0^2) x1 - x0)"
    finally:
        slave.free()
