"""Model exchange integrated in C (cosim/fmi/me_loop.c through cosim.fmi.me_c) against the Python integrators and
FMPy.

- ``cvode`` in C calls the same SUNDIALS library as the Python path with the same FMU calls in the same order:
  the runs are the same bit for bit.
- ``dopri5`` in C is our Dormand-Prince 5(4); its Python fallback is SciPy's RK45, the same pair with another
  step-size controller: both converge to the solution, so they agree to the tolerance they were given.
- Reference FMUs (tests/cfmus: bouncing ball with state events, Van der Pol, step events) give FMPy's results
  and the bounce times of the closed form on the C path.
- A failing FMU call inside the C integration is reported as the same call made from Python is.
- Without a C compiler the Python integrators run, with the same results as above.
"""

from __future__ import annotations

import math
from ctypes import c_double
from pathlib import Path

import numpy as np
import pytest
import yaml
from cfmus import build

from cosim.cbuild import Library
from cosim.errors import FMIError
from cosim.fmi import load_fmu, make_slave, me_c
from cosim.fmi import model_exchange
from cosim.fmi.integrators import CVodeIntegrator, SciPyIntegrator
from cosim.engine.scenario import load_scenario, parse_scenario
from cosim.observers.recorders import Probe
from cosim.run import run_scenario
from fmus import registry

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
RTOL = 1e-10
EVENT_ATOL = 1e-8  # s: event times against the closed form (tests/integration/test_third_party.py)


def _python_only(m) -> None:
    """The master without the C integrators (as without a compiler): make_c_integrator finds no helper."""
    m.setattr(model_exchange, "make_c_integrator", lambda *a: None)


def _run(scenario, signals: list[str], *, python: bool, monkeypatch):
    """(probed values, result, integrator classes made) of a run on the C or the Python integrators."""
    made: list[type] = []
    with monkeypatch.context() as m:
        if python:
            _python_only(m)
        exit_init = model_exchange.ModelExchange.exit_initialization

        def spy(self):
            exit_init(self)
            made.append(type(self.integrator))

        m.setattr(model_exchange.ModelExchange, "exit_initialization", spy)
        probe = Probe(signals)
        result = run_scenario(scenario, log=False, observers=[probe], read_all=True)
    return probe, result, made


def _scenario(tmp_path: Path, model: str, fmi: int, solver: str, stop: float, step: float):
    text = yaml.safe_dump({"name": "me_c", "components": {"m": {"path": str(build(model, fmi)), "interface": "me",
                                                               "rtol": RTOL, "solver": solver}},
                           "time": {"stop": stop, "step": step}, "parallel": "off"}, sort_keys=False)
    return parse_scenario(text, str(tmp_path / "me_c.yaml"))


def bounce_times(n: int, h0: float = 1.0, g: float = 9.81, e: float = 0.7) -> list[float]:
    """Impact times of the ideal bouncing ball: t1 = sqrt(2 h0 / g), then flights of 2 e^k v1 / g."""
    t1 = math.sqrt(2 * h0 / g)
    return [t1 + sum(2 * e ** k * t1 for k in range(1, i)) for i in range(1, n + 1)]


@pytest.mark.parametrize("model, fmi, signals", [
    ("VanDerPol", 2, ["m.x0", "m.x1"]),
    ("BouncingBall", 3, ["m.h", "m.v", "m.bounces"]),
    ("Halving", 2, ["m.x", "m.count"]),
])
def test_cvode_in_c_is_the_python_cvode_bit_for_bit(tmp_path, monkeypatch, model, fmi, signals):
    scenario = _scenario(tmp_path, model, fmi, "cvode", 3.0, 0.01)
    c_probe, c_res, c_made = _run(scenario, signals, python=False, monkeypatch=monkeypatch)
    py_probe, py_res, py_made = _run(scenario, signals, python=True, monkeypatch=monkeypatch)
    assert (c_made, py_made) == ([me_c.CVode], [CVodeIntegrator]), f"integrators: C {c_made}, Python {py_made}"
    assert c_res.events == py_res.events, f"events: C {c_res.events} vs Python {py_res.events}"
    for s in signals:
        assert c_probe.values[s] == py_probe.values[s], f"{s}: C {c_probe.values[s][:3]} vs Python " \
                                                        f"{py_probe.values[s][:3]}"
    assert len(set(c_probe.values[signals[0]])) > 100, "the model did not move: the test compares constants"


@pytest.mark.parametrize("fmi", [2, 3])
def test_dopri5_in_c_bounces_as_the_closed_form_and_as_scipys_rk45(tmp_path, monkeypatch, fmi):
    """State events located on the dense output: the 18 bounces of the ball in 3 s at the closed form's times, the
    same count with SciPy's RK45 (the Python fallback of the same pair), heights alike to the tolerance."""
    scenario = _scenario(tmp_path, "BouncingBall", fmi, "dopri5", 3.0, 0.01)
    signals = ["m.h", "m.bounces"]
    c_probe, c_res, c_made = _run(scenario, signals, python=False, monkeypatch=monkeypatch)
    py_probe, py_res, py_made = _run(scenario, signals, python=True, monkeypatch=monkeypatch)
    assert (c_made, py_made) == ([me_c.DOPRI5], [SciPyIntegrator]), f"integrators: C {c_made}, Python {py_made}"
    bounces = int(c_probe.values["m.bounces"][-1])
    assert bounces >= 10 and c_probe.values["m.bounces"] == py_probe.values["m.bounces"], \
        f"bounces: C {bounces}, Python {py_probe.values['m.bounces'][-1]}"
    assert c_res.events == py_res.events, f"events: C {c_res.events} vs Python {py_res.events}"
    h_c, h_py = np.array(c_probe.values["m.h"]), np.array(py_probe.values["m.h"])
    assert np.max(np.abs(h_c - h_py)) <= 1e-6, f"heights differ by {np.max(np.abs(h_c - h_py)):.3g} m"


def test_dopri5_in_c_finds_each_bounce_at_its_time(tmp_path):
    """The event times themselves, from the run's log (each event's time as the master handled it)."""
    from cosim.io.runlog import read_run

    fmu = build("BouncingBall", 2)
    text = yaml.safe_dump({"name": "me_c", "components": {"m": {"path": str(fmu), "interface": "me", "rtol": RTOL,
                                                               "solver": "dopri5"}},
                           "time": {"stop": 3.0, "step": 0.01}, "logging": {"signals": "all"}}, sort_keys=False)
    out = tmp_path / "run.mcap"
    res = run_scenario(parse_scenario(text, str(tmp_path / "s.yaml")), out=out)
    ours = [e["t"] for e in read_run(out).events]
    assert len(ours) == res.events["m"] >= 10, f"{len(ours)} events logged, {res.events} counted"
    worst = max(abs(a - b) for a, b in zip(ours, bounce_times(len(ours))))
    assert worst <= EVENT_ATOL, f"bounce times differ from the closed form by up to {worst:.3g} s"


def test_van_der_pol_in_c_gives_fmpys_result(tmp_path):
    from fmpy import simulate_fmu

    fmu = build("VanDerPol", 3)
    ref = simulate_fmu(str(fmu), fmi_type="ModelExchange", stop_time=10.0, output_interval=0.01,
                       relative_tolerance=RTOL, output=["x0", "x1"])
    for solver in ("dopri5", "cvode"):
        probe = Probe(["m.x0", "m.x1"])
        run_scenario(_scenario(tmp_path, "VanDerPol", 3, solver, 10.0, 0.01), log=False, observers=[probe],
                     read_all=True)
        t = np.array(probe.t_ns) * 1e-9
        k = np.searchsorted(ref["time"], t - 1e-9)  # FMPy's sample at each of ours
        assert len(t) >= 999 and np.allclose(ref["time"][k], t, rtol=0, atol=1e-9), "sample times differ"
        for name in ("x0", "x1"):
            ours, theirs = np.array(probe.values[f"m.{name}"]), ref[name][k]
            err = np.max(np.abs(ours - theirs)) / np.max(np.abs(theirs))
            assert err <= 1e-6, f"{solver}, {name}: relative difference {err:.3g} from FMPy"


def test_helix_ctc_me_plant_on_dopri5_in_c_is_the_cs_plant():
    """The scenario's own solver on the native FMUs: the model-exchange plant within 1e-6 m of the co-simulation
    plant (its RK4 at 1 ms) over 2 s, integrated in C."""
    signals = ["plant.p.x", "plant.p.y", "plant.p.z"]
    runs = []
    for name in ("helix_ctc_me", "helix_ctc_analytic"):
        probe = Probe(signals)
        scenario = load_scenario(ROOT / "scenarios" / f"{name}.yaml",
                                 {("time", "stop"): 2.0, ("fmus",): "native", ("parallel",): "off"})
        run_scenario(scenario, log=False, observers=[probe], read_all=True)
        runs.append(np.array([probe.values[s] for s in signals]))
    assert load_scenario(ROOT / "scenarios" / "helix_ctc_me.yaml").components["plant"].solver == "dopri5"
    dist = np.max(np.linalg.norm(runs[0] - runs[1], axis=0))
    assert runs[0].shape[1] == 2001 and dist <= 1e-6, f"ME plant {dist:.3g} m from the CS plant"


def test_helix_ctc_me_runs_alike_in_the_masters_loops():
    """Without observers of its own a run may take the master's loop in C (the C macro step as a turn: no event
    can arise in it); with a probe it takes the Python loop (the C macro step per set_step_get): the same errors."""
    scenario = load_scenario(ROOT / "scenarios" / "helix_ctc_me.yaml",
                             {("time", "stop"): 1.0, ("fmus",): "native", ("parallel",): "off"})
    quiet = run_scenario(scenario, log=False)
    probed = run_scenario(scenario, log=False, observers=[Probe(["plant.p.x"])], read_all=True)
    assert [(e.rmse, e.max_error) for e in quiet.errors] == [(e.rmse, e.max_error) for e in probed.errors], \
        f"errors: {quiet.errors} vs {probed.errors}"


def _me_slave(path: Path):
    slave = make_slave("m", load_fmu(path), "me", rtol=RTOL, solver="dopri5")
    slave.instantiate()
    slave.enter_initialization(0.0, 1.0)
    slave.bind([], [])
    slave.exit_initialization()
    return slave


def _failure(path: Path, x: list[float], python: bool, monkeypatch) -> tuple:
    """The error (type, component, function, time, text) of a step from t = 0.5 s at states ``x``."""
    with monkeypatch.context() as m:
        if python:
            _python_only(m)
        slave = _me_slave(path)
    assert isinstance(slave.integrator, SciPyIntegrator if python else me_c.DOPRI5), type(slave.integrator)
    try:
        slave.set_time(0.5)
        slave.set_x((c_double * len(x))(*x))
        slave.restart()
        with pytest.raises(FMIError) as info:
            slave.step(0.5, 0.01)
    finally:
        slave.free()
    err = info.value
    return type(err).__name__, err.component, err.function, err.time, str(err)


@pytest.mark.parametrize("what, path, x, function", [
    ("error status", lambda: registry.build("linear_analytic_plant_me", native=True, fmi=2),
     [0.0, 0.9, 0.9, 0.0, 0.0, 0.0], "fmi2GetContinuousStates"),  # the restart reads the states: they fail there
    ("non-finite derivatives", lambda: build("VanDerPol", 3), [1e200, 1e200], "fmi3GetContinuousStateDerivatives"),
])
def test_a_failing_call_in_c_raises_as_the_python_calls_raise(monkeypatch, what, path, x, function):
    fmu = path()
    c_error = _failure(fmu, x, python=False, monkeypatch=monkeypatch)
    py_error = _failure(fmu, x, python=True, monkeypatch=monkeypatch)
    assert c_error == py_error, f"{what}: C {c_error} vs Python {py_error}"
    assert c_error[2] == function and c_error[3] == 0.5, f"{what}: {c_error}, expected {function} at t = 0.5 s"


def test_without_a_compiler_the_python_integrators_run(tmp_path, monkeypatch):
    """No compiler: the helper is not built (unavailable() says why, no library left in the cache) and the run
    takes the Python integrators, with the same bounces."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setenv("CC", str(tmp_path / "no-such-cc"))
    monkeypatch.setattr(me_c, "_LIBRARY", Library(me_c._LIBRARY.source))
    probe, res, made = _run(_scenario(tmp_path, "BouncingBall", 2, "dopri5", 3.0, 0.01), ["m.bounces"],
                            python=False, monkeypatch=monkeypatch)
    assert made == [SciPyIntegrator], f"integrators made: {made}"
    assert "no C compiler" in (me_c.unavailable() or ""), me_c.unavailable()
    assert not list((tmp_path / "cache").rglob("*.so")), "a failed build left a library in the cache"
    assert res.status == "completed" and probe.values["m.bounces"][-1] >= 10, (res.status, probe.values["m.bounces"][-1])


def test_only_a_step_where_no_event_can_arise_is_offered_to_the_loop_in_c():
    """c_turn: the native plant (no indicators, a completedIntegratorStep that never asks for event mode) gets a
    turn; the bouncing ball (event indicators) and Halving (step events from completedIntegratorStep) do not."""
    plant = _me_slave(registry.build("linear_analytic_plant_me", native=True, fmi=3))
    ball, halving = _me_slave(build("BouncingBall", 3)), _me_slave(build("Halving", 2))
    try:
        assert plant.c_turn() is not None and plant._c_step is not None
        assert ball._c_step is not None and ball.c_turn() is None, "event indicators: the Python loop's"
        assert halving._needs_completed and halving._c_step is not None and halving.c_turn() is None, \
            "a completedIntegratorStep that may ask for event mode: the Python loop's"
    finally:
        for s in (plant, ball, halving):
            s.free()


@pytest.mark.parametrize("model, fmi, stop, exact", [("Stair", 3, 8.0, ["m.counter", "m.ramp"]),
                                                     ("Halving", 2, 5.0, ["m.count"])])
def test_time_and_step_events_in_c_as_in_python(tmp_path, monkeypatch, model, fmi, stop, exact):
    """Time events (nextEventTime) and step events (completedIntegratorStep) on the C dopri5: the same events and the
    same discrete outputs as on SciPy's RK45 from Python."""
    scenario = _scenario(tmp_path, model, fmi, "dopri5", stop, 0.01)
    c_probe, c_res, c_made = _run(scenario, exact, python=False, monkeypatch=monkeypatch)
    py_probe, py_res, py_made = _run(scenario, exact, python=True, monkeypatch=monkeypatch)
    assert (c_made, py_made) == ([me_c.DOPRI5], [SciPyIntegrator]), f"integrators: C {c_made}, Python {py_made}"
    assert c_res.events == py_res.events and c_res.events["m"] >= 5, f"events: C {c_res.events}, Python {py_res.events}"
    for s in exact:
        assert c_probe.values[s] == py_probe.values[s], f"{s}: C and Python differ"
