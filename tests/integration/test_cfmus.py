"""Our own C test FMUs (tests/cfmus): valid, simulable, and physically right.

Each FMU is built (or taken from .fmu_cache/cfmus) and checked with FMPy, an
independent importer: schema/structure validation, a default run of both
interfaces, and checks that cannot be tuned (free-fall impact time,
restitution, time-event values, an ODE reference from SciPy, closed-form
linear-system output, exact feedthrough).
"""

from __future__ import annotations

import math
from contextlib import contextmanager
from ctypes import byref, c_double
from pathlib import Path

import fmpy
import numpy as np
import pytest
from fmpy import fmi2, fmi3
from fmpy.fmi1 import FMICallException
from fmpy.validation import validate_fmu

from cfmus import MODELS, build, state_space_defaults  # tests/ is on sys.path (see conftest.py)

pytestmark = pytest.mark.integration

INTERFACES = ("ModelExchange", "CoSimulation")
G, E, H0 = -9.81, 0.7, 1.0  # BouncingBall defaults
V_REST = 1e-2  # m/s, V_REST of c/models/bouncing_ball.c
# CVode at rtol 1e-10 locates a root to ~1e-12 s and integrates free fall to
# ~1e-9 relative: 1e-6 s / 1e-6 relative leave ample margin, yet catch any
# modelling error (a wrong g, a missed event, a step-end event time).
TIME_ATOL = 1e-6
RTOL_PHYSICS = 1e-6


def _model_description(path: Path):
    return fmpy.read_model_description(str(path))


@contextmanager
def _instance(model: str, fmi: int, kind, tmp_path: Path, **instantiate_args):
    """An instance of FMPy class ``kind`` (FMU2Slave, FMU3Model, ...) and the
    value references by name; the instance is freed afterwards."""
    path = build(model, fmi)
    md = _model_description(path)
    unzipped = fmpy.extract(str(path), unzipdir=str(tmp_path / "fmu"))
    fmu = kind(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=model)
    fmu.instantiate(**instantiate_args)
    try:
        yield fmu, {v.name: v.valueReference for v in md.modelVariables}
    finally:
        fmu.freeInstance()


def _start(md, name: str):
    v = next(v for v in md.modelVariables if v.name == name)
    return [float(x) for x in v.start.split()]


# --------------------------------------------------------------------------- every FMU


@pytest.mark.parametrize("model,fmi", MODELS)
def test_fmu_passes_fmpy_validation(model, fmi):
    problems = validate_fmu(str(build(model, fmi)))
    assert problems == [], f"{model} FMI {fmi}: validate_fmu found {problems}, expected none"


@pytest.mark.parametrize("interface", INTERFACES)
@pytest.mark.parametrize("model,fmi", MODELS)
def test_fmu_runs_its_default_experiment(model, fmi, interface):
    path = build(model, fmi)
    stop = _model_description(path).defaultExperiment.stopTime
    if (model, interface) == ("Horizon", "ModelExchange"):
        # FMPy's CVode, without a stop time, evaluates the right-hand side past stopTime, which Horizon refuses
        # as FMI 2.0 section 2.1.6 asks ("if the environment tries to compute past stopTime the FMU has to
        # return fmi2Error"); the master's CVode never does (CVodeSetStopTime: tests/integration/test_time_grid.py);
        # measured: SetTime(2.0080567693289813) from t = 1.968, stopTime 2
        # (whether its integrator steps past depends on its step sizes: the FMI 2 build did once, not always):
        # either it refuses that evaluation, or the run reaches stopTime like any other
        try:
            result = fmpy.simulate_fmu(str(path), fmi_type=interface)
        except RuntimeError as exc:
            assert "right-hand side routine failed" in str(exc), exc
            return
    else:
        result = fmpy.simulate_fmu(str(path), fmi_type=interface)
    assert math.isclose(result["time"][-1], float(stop)), (
        f"{model} FMI {fmi} {interface}: run ended at t = {result['time'][-1]}, expected stopTime = {stop}"
    )


def test_cache_reuses_the_built_fmu():
    first = build("VanDerPol", 2)
    stamp = first.stat().st_mtime_ns
    again = build("VanDerPol", 2)
    assert again == first and again.stat().st_mtime_ns == stamp, (
        f"second build gave {again} (mtime {again.stat().st_mtime_ns}), expected the cached {first} ({stamp})"
    )


def test_fmi3_fmus_carry_both_binary_directories():
    import zipfile

    names = zipfile.ZipFile(build("Stair", 3)).namelist()
    for entry in ("modelDescription.xml", "binaries/x86_64-linux/Stair.so", "binaries/linux64/Stair.so"):
        assert entry in names, f"{entry} missing from the FMU, which holds {names}"


# --------------------------------------------------------------------------- BouncingBall


def _impact_rows(result):
    """(index before, index after) of the first impact: FMPy records an event twice."""
    jumps = np.flatnonzero(np.diff(result["v"]) > 0.0)
    assert len(jumps), f"no bounce found; v = {result['v']}"
    i = int(jumps[0])
    return i, i + 1


@pytest.mark.parametrize("fmi", (2, 3))
def test_bouncing_ball_me_first_impact_and_restitution(fmi):
    result = fmpy.simulate_fmu(str(build("BouncingBall", fmi)), fmi_type="ModelExchange", relative_tolerance=1e-10)
    before, after = _impact_rows(result)
    t_expected = math.sqrt(2.0 * H0 / abs(G))
    t_before, t_after = result["time"][before], result["time"][after]
    assert t_before == t_after, f"event rows at t = {t_before} and {t_after}, expected one event instant"
    assert abs(t_before - t_expected) < TIME_ATOL, (
        f"first impact at t = {t_before!r}, expected sqrt(2 h0/|g|) = {t_expected!r}"
    )
    v_impact = -math.sqrt(2.0 * abs(G) * H0)
    v_before, v_after = result["v"][before], result["v"][after]
    assert math.isclose(v_before, v_impact, rel_tol=RTOL_PHYSICS), (
        f"impact velocity {v_before!r}, expected -sqrt(2 |g| h0) = {v_impact!r}"
    )
    # v := -e v is one multiplication: exact up to the last bit
    assert math.isclose(v_after, -E * v_before, rel_tol=1e-15), (
        f"velocity after the bounce {v_after!r}, expected -e * {v_before!r} = {-E * v_before!r}"
    )
    assert result["bounces"][before] == 0 and result["bounces"][after] == 1, (
        f"bounces {result['bounces'][before]} -> {result['bounces'][after]} across the impact, expected 0 -> 1"
    )


def _bounces_to_rest() -> int:
    """Impacts until the rebound speed drops below V_REST."""
    v, k = math.sqrt(2.0 * abs(G) * H0), 0
    while v >= V_REST:
        v *= E
        k += 1
    return k


@pytest.mark.parametrize("interface", INTERFACES)
@pytest.mark.parametrize("fmi", (2, 3))
def test_bouncing_ball_comes_to_rest(fmi, interface):
    result = fmpy.simulate_fmu(str(build("BouncingBall", fmi)), fmi_type=interface, relative_tolerance=1e-10,
                               stop_time=4.0, output_interval=0.01)
    last = result[-1]
    assert last["h"] == 0.0 and last["v"] == 0.0, f"at t = 4 s h = {last['h']}, v = {last['v']}, expected rest (0, 0)"
    assert last["bounces"] == _bounces_to_rest(), f"bounces = {last['bounces']}, expected {_bounces_to_rest()}"


@pytest.mark.parametrize("fmi", (2, 3))
def test_bouncing_ball_cs_follows_the_analytic_flight(fmi):
    """Between impacts the flight is a parabola, which RK4 integrates exactly;
    the impact is located by bisection, so the CS output matches the closed
    form to round-off level."""
    result = fmpy.simulate_fmu(str(build("BouncingBall", fmi)), fmi_type="CoSimulation", stop_time=1.0,
                               output_interval=0.05)
    t1 = math.sqrt(2.0 * H0 / abs(G))
    v1 = E * math.sqrt(2.0 * abs(G) * H0)
    t2 = t1 + 2.0 * v1 / abs(G)
    for row in result:
        t = row["time"]
        if t < t1:
            h, v = H0 + 0.5 * G * t * t, G * t
        elif t1 < t < t2:
            h, v = v1 * (t - t1) + 0.5 * G * (t - t1) ** 2, v1 + G * (t - t1)
        else:
            continue
        assert abs(row["h"] - h) < 1e-9 and abs(row["v"] - v) < 1e-9, (
            f"t = {t}: (h, v) = ({row['h']!r}, {row['v']!r}), expected the closed form ({h!r}, {v!r})"
        )


# --------------------------------------------------------------------------- Stair


def _check_stair_counter(result, what: str):
    for row in result:
        t = row["time"]
        if abs(t - round(t)) < 1e-6:
            continue  # at a tick FMPy records the values before and after
        expected = 1 + math.floor(t)
        assert row["counter"] == expected, f"{what}: counter = {row['counter']} at t = {t}, expected {expected}"
        assert row["ramp"] == 0.5 * row["counter"], (
            f"{what}: ramp = {row['ramp']} at t = {t}, expected 0.5 * counter = {0.5 * row['counter']}"
        )


@pytest.mark.parametrize("fmi", (2, 3))
def test_stair_me_counts_time_events_and_terminates(fmi):
    result = fmpy.simulate_fmu(str(build("Stair", fmi)), fmi_type="ModelExchange", stop_time=12.0,
                               output_interval=0.25)
    _check_stair_counter(result, f"FMI {fmi} ME")
    for k in range(1, 11):
        at_tick = result[np.isclose(result["time"], k)]
        assert at_tick["counter"][-1] == k + 1, (
            f"after the event at t = {k} counter = {at_tick['counter'][-1]}, expected {k + 1}"
        )
    assert math.isclose(result["time"][-1], 10.5), f"ME result ends at t = {result['time'][-1]}, expected 10.5"
    assert result["counter"][-1] == 11, f"counter at termination = {result['counter'][-1]}, expected 11"


def test_stair_cs_fmi2_terminates_with_discard():
    result = fmpy.simulate_fmu(str(build("Stair", 2)), fmi_type="CoSimulation", stop_time=12.0, output_interval=0.2)
    _check_stair_counter(result, "FMI 2 CS")
    assert math.isclose(result["time"][-1], 10.5), f"CS result ends at t = {result['time'][-1]}, expected 10.5"
    assert result["counter"][-1] == 11, f"counter at termination = {result['counter'][-1]}, expected 11"


def test_stair_cs_fmi3_terminates_with_early_return():
    path = str(build("Stair", 3))
    result = fmpy.simulate_fmu(path, fmi_type="CoSimulation", stop_time=12.0, output_interval=0.2,
                               early_return_allowed=True)
    _check_stair_counter(result, "FMI 3 CS")
    assert math.isclose(result["time"][-1], 10.5), f"CS result ends at t = {result['time'][-1]}, expected 10.5"
    # without early return the FMU cannot stop inside the step: fmi3Discard + terminateSimulation
    with pytest.raises(FMICallException) as info:
        fmpy.simulate_fmu(path, fmi_type="CoSimulation", stop_time=12.0, output_interval=0.2)
    assert info.value.status == fmi3.fmi3Discard, f"status {info.value.status}, expected fmi3Discard"


def test_stair_fmi2_rejects_a_step_crossing_t_reject(tmp_path):
    messages = []

    def logger(env, name, status, category, message):
        messages.append(message.decode())

    callbacks = fmi2.fmi2CallbackFunctions()
    callbacks.logger = fmi2.fmi2CallbackLoggerTYPE(logger)
    callbacks.allocateMemory = fmi2.fmi2CallbackAllocateMemoryTYPE(fmpy.calloc)
    callbacks.freeMemory = fmi2.fmi2CallbackFreeMemoryTYPE(fmpy.free)
    with _instance("Stair", 2, fmi2.FMU2Slave, tmp_path, callbacks=callbacks) as (fmu, vr):
        fmu.setReal([vr["t_reject"]], [2.5])
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 1.0)
        fmu.doStep(1.0, 1.0)
        with pytest.raises(FMICallException) as info:
            fmu.doStep(2.0, 1.0)
        assert info.value.status == fmi2.fmi2Discard, f"status {info.value.status}, expected fmi2Discard"
        terminated = fmu.getBooleanStatus(fmi2.fmi2Terminated)
        last = fmu.getRealStatus(fmi2.fmi2LastSuccessfulTime)
        assert not terminated, f"fmi2Terminated = {terminated}, expected False for a rejected step"
        assert last == 2.0, f"fmi2LastSuccessfulTime = {last}, expected the step start 2.0"
        assert any("step rejected at t = 2.5" in m for m in messages), (
            f"logged {messages}, expected a 'step rejected at t = 2.5' message"
        )
        counter = fmu.getInteger([vr["counter"]])[0]
        assert counter == 3, f"counter = {counter} after the rejected step, expected 3 (state of t = 2)"
        fmu.terminate()


def test_stair_fmi3_rejected_step_can_be_retried_shorter(tmp_path):
    messages = []

    def log(env, status, category, message):
        messages.append(message.decode())

    with _instance("Stair", 3, fmi3.FMU3Slave, tmp_path, logMessage=log) as (fmu, vr):
        fmu.setFloat64([vr["t_reject"]], [2.5])
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        flags = [fmi3.fmi3Boolean() for _ in range(3)]  # event, terminate, early return
        last = c_double()

        def do_step(t, h):  # the raw call: FMPy's doStep raises on fmi3Discard and hides the outputs
            return fmu.dll.fmi3DoStep(fmu.component, t, h, True, *(byref(f) for f in flags), byref(last))

        assert do_step(0.0, 2.0) == fmi3.fmi3OK, "the step from 0 to 2 should be accepted"
        status = do_step(2.0, 1.0)
        assert status == fmi3.fmi3Discard, f"status {status}, expected fmi3Discard for the step across t_reject"
        assert not flags[1].value and last.value == 2.0, (
            f"terminateSimulation = {flags[1].value}, lastSuccessfulTime = {last.value}; expected False, 2.0"
        )
        assert any("step rejected at t = 2.5" in m for m in messages), f"logged {messages}"
        assert do_step(2.0, 0.5) == fmi3.fmi3OK, "the shorter step up to t_reject should be accepted"
        assert do_step(2.5, 1.0) == fmi3.fmi3OK, "a step starting at t_reject should be accepted"
        counter = fmu.getInt32([vr["counter"]])[0]
        assert counter == 4, f"counter = {counter} at t = 3.5, expected 4"
        fmu.terminate()


# --------------------------------------------------------------------------- VanDerPol


@pytest.fixture(scope="module")
def van_der_pol_reference():
    from scipy.integrate import solve_ivp

    t = np.linspace(0.0, 20.0, 201)

    def f(_, x, mu=1.0):
        return [x[1], mu * (1.0 - x[0] ** 2) * x[1] - x[0]]

    sol = solve_ivp(f, (0.0, 20.0), [2.0, 0.0], method="Radau", t_eval=t, rtol=1e-12, atol=1e-12)
    return t, sol.y


@pytest.mark.parametrize("interface", INTERFACES)
@pytest.mark.parametrize("fmi", (2, 3))
def test_van_der_pol_matches_scipy(fmi, interface, van_der_pol_reference):
    """ME at rtol 1e-10 and CS (RK4, 1 ms) both reproduce a Radau reference
    at rtol 1e-12 to 1e-6 over 20 s (about three periods)."""
    t, ref = van_der_pol_reference
    result = fmpy.simulate_fmu(str(build("VanDerPol", fmi)), fmi_type=interface, relative_tolerance=1e-10,
                               output_interval=0.1)
    for k, name in enumerate(("x0", "x1")):
        ours = np.interp(t, result["time"], result[name])
        err = np.max(np.abs(ours - ref[k]))
        i = int(np.argmax(np.abs(ours - ref[k])))
        assert err < 1e-6, f"{name} at t = {t[i]}: FMU {ours[i]!r}, SciPy Radau {ref[k][i]!r} (|diff| = {err:.2e})"


# --------------------------------------------------------------------------- StateSpace


@pytest.mark.parametrize("interface", INTERFACES)
def test_state_space_initial_output(interface):
    path = build("StateSpace", 3)
    md = _model_description(path)
    A, B, C, D = (np.array(_start(md, n)).reshape(3, 3) for n in "ABCD")
    x0, u, offset = (np.array(_start(md, n)) for n in ("x0", "u", "offset"))
    result = fmpy.simulate_fmu(str(path), fmi_type=interface)
    y0 = C @ x0 + D @ u + offset
    assert np.allclose(result["y"][0], y0, rtol=0, atol=1e-14), (
        f"y(0) = {result['y'][0]}, expected C x0 + D u + offset = {y0}"
    )


def test_state_space_me_matches_matrix_exponential():
    from scipy.linalg import expm

    path = build("StateSpace", 3)
    md = _model_description(path)
    A, B, C, D = (np.array(_start(md, n)).reshape(3, 3) for n in "ABCD")
    x0, u, offset = (np.array(_start(md, n)) for n in ("x0", "u", "offset"))
    result = fmpy.simulate_fmu(str(path), fmi_type="ModelExchange", relative_tolerance=1e-10, stop_time=5.0)
    x_eq = -np.linalg.solve(A, B @ u)  # constant input: x(t) = x_eq + e^{At} (x0 - x_eq)
    for row in result[::50]:
        x = x_eq + expm(A * row["time"]) @ (x0 - x_eq)
        y = C @ x + D @ u + offset
        assert np.allclose(row["y"], y, rtol=0, atol=1e-7), f"t = {row['time']}: y = {row['y']}, expected {y}"


def test_state_space_structural_parameters_resize_arrays(tmp_path):
    messages = []

    def log(env, status, category, message):
        messages.append(message.decode())

    with _instance("StateSpace", 3, fmi3.FMU3Model, tmp_path, logMessage=log) as (fmu, vr):
        fmu.enterConfigurationMode()
        fmu.setUInt64([vr["n"]], [2])
        fmu.exitConfigurationMode()
        fmu.setFloat64([vr["x0"]], [0.5, -1.5])  # x0 now has 2 elements
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        n_states = fmu.getNumberOfContinuousStates()
        assert n_states == 2, f"{n_states} continuous states, expected n = 2"
        d = state_space_defaults(m=3, n=2, r=3)
        y = np.array(d["C"]) @ [0.5, -1.5] + np.array(d["D"]) @ d["u"] + d["offset"]
        got = fmu.getFloat64([vr["y"]], nValues=3)
        assert np.allclose(got, y, rtol=0, atol=1e-14), f"y = {got}, expected C x0 + D u + offset = {y}"
        with pytest.raises(FMICallException):
            fmu.getFloat64([vr["A"]], nValues=9)  # A is 2 x 2 now
        assert any("nValues = 9" in m and "have 4 values" in m for m in messages), (
            f"logged {messages}, expected a message on the wrong nValues (9 given, 4 needed)"
        )
        fmu.terminate()


# --------------------------------------------------------------------------- Feedthrough

FMI3_INPUTS = {
    "Float32_input": 3.25,
    "Float64_input": -1.125,
    "Int8_input": -128,
    "UInt8_input": 255,
    "Int16_input": -32768,
    "UInt16_input": 65535,
    "Int32_input": -(2**31),
    "UInt32_input": 2**32 - 1,
    "Int64_input": -(2**63),
    "UInt64_input": 2**64 - 1,
    "Boolean_input": True,
    "Enumeration_input": 3,
    "Float64_array_input": [4.0, -5.0, 6.5],
}
FMI2_INPUTS = {"Real_input": -1.125, "Integer_input": -(2**31), "Boolean_input": True, "Enumeration_input": 3}


@pytest.mark.parametrize("interface", INTERFACES)
@pytest.mark.parametrize("fmi", (2, 3))
def test_feedthrough_outputs_equal_start_inputs(fmi, interface):
    inputs = FMI3_INPUTS if fmi == 3 else FMI2_INPUTS
    result = fmpy.simulate_fmu(str(build("Feedthrough", fmi)), fmi_type=interface, start_values=inputs)
    for name, value in inputs.items():
        out = name.replace("_input", "_output")
        got = result[out][-1]
        assert np.array_equal(got, value), f"{out} = {got!r} at t = {result['time'][-1]}, expected the input {value!r}"


@pytest.mark.parametrize("interface", INTERFACES)
@pytest.mark.parametrize("fmi", (2, 3))
def test_feedthrough_follows_an_input_signal(fmi, interface):
    name = "Float64" if fmi == 3 else "Real"
    signal = np.array([(0.0, 0.0), (2.0, 4.0)], dtype=[("time", np.float64), (f"{name}_input", np.float64)])
    result = fmpy.simulate_fmu(str(build("Feedthrough", fmi)), fmi_type=interface, input=signal,
                               output_interval=0.1)
    # the ramp u = 2 t is applied at the start of each step / at each output point
    times = result["time"][1:] if interface == "CoSimulation" else result["time"]
    got = result[f"{name}_output"][1:] if interface == "CoSimulation" else result[f"{name}_output"]
    applied = 2.0 * (times - 0.1) if interface == "CoSimulation" else 2.0 * times
    assert np.allclose(got, applied, rtol=0, atol=1e-12), f"{name}_output = {got}, expected the input {applied}"


def test_feedthrough_fmi3_strings_and_binaries(tmp_path):
    with _instance("Feedthrough", 3, fmi3.FMU3Slave, tmp_path) as (fmu, vr):
        fmu.setString([vr["String_input"]], ["grüße, FMI"])
        fmu.setBinary([vr["Binary_input"]], [b"\x00\xffbinary\x00"])
        fmu.enterInitializationMode(startTime=0.0)
        fmu.exitInitializationMode()
        fmu.doStep(0.0, 0.5)
        s = fmu.getString([vr["String_output"]])[0]
        b = fmu.getBinary([vr["Binary_output"]])[0]
        p = fmu.getString([vr["String_parameter"]])[0]
        assert s == "grüße, FMI", f"String_output = {s!r}, expected the input 'grüße, FMI'"
        assert b == b"\x00\xffbinary\x00", f"Binary_output = {b!r}, expected the input b'\\x00\\xffbinary\\x00'"
        assert p == "parameter", f"String_parameter = {p!r}, expected its start 'parameter'"
        fmu.terminate()


def test_feedthrough_fmi2_string(tmp_path):
    with _instance("Feedthrough", 2, fmi2.FMU2Model, tmp_path) as (fmu, vr):
        fmu.setString([vr["String_input"]], ["hello"])
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.exitInitializationMode()
        s = fmu.getString([vr["String_output"]])[0].decode()  # FMPy's FMI 2 getString gives bytes
        assert s == "hello", f"String_output = {s!r}, expected the input 'hello'"
        fmu.terminate()


# --------------------------------------------------------------------------- Clocked


def test_clocked_declares_an_input_clock():
    md = _model_description(build("Clocked", 3))
    clocks = [(v.name, v.causality) for v in md.modelVariables if v.type == "Clock"]
    assert clocks == [("tick", "input")], f"Clock variables {clocks}, expected [('tick', 'input')]"


# --------------------------------------------------------------------------- builder


def test_failed_compile_raises_with_gcc_stderr(monkeypatch):
    import dataclasses

    import cfmus

    broken = dataclasses.replace(cfmus.MODEL_SPECS[("Stair", 2)], name="Broken", source="no_such_model.c")
    monkeypatch.setitem(cfmus.MODEL_SPECS, ("Broken", 2), broken)
    with pytest.raises(cfmus.BuildError) as info:
        build("Broken", 2)
    assert "no_such_model.c" in str(info.value), f"error message {info.value}, expected gcc's complaint"
    leftovers = [p.name for p in cfmus.CACHE_DIR.iterdir() if p.name.startswith((".build-Broken", "Broken"))]
    assert leftovers == [], f"the failed build left {leftovers} in {cfmus.CACHE_DIR}"


def test_an_fmu_logs_to_a_live_logger_after_a_simulation_with_its_own_logger(capsys, tmp_path):
    """fmpy's C logging proxy keeps one logger per process; ``simulate_fmu(logger=f)`` leaves it at a thunk freed on
    return (see ``fmu_helpers.repoint_fmpy_logger``, which the suite calls after every test). Re-pointed, an FMU that
    fmpy instantiates with its default callbacks logs to fmpy's default logger again: here an ``fmi2SetTime`` before
    initialization, refused with its reason."""
    from fmpy import extract, read_model_description

    from fmu_helpers import repoint_fmpy_logger

    path = str(build("VanDerPol", 2))
    seen: list[bytes] = []
    fmpy.simulate_fmu(path, stop_time=0.01, logger=lambda *args: seen.append(args[-1]))
    repoint_fmpy_logger()
    md = read_model_description(path)
    fmu = fmi2.FMU2Model(guid=md.guid, unzipDirectory=extract(path, str(tmp_path / "x")),
                         modelIdentifier=md.modelExchange.modelIdentifier, instanceName="vdp")
    fmu.instantiate()
    try:
        capsys.readouterr()
        with pytest.raises(FMICallException):
            fmu.setTime(0.5)  # in Instantiated mode: the FMU logs why through fmpy's proxy
        assert "must not be called in Instantiated" in capsys.readouterr().out
    finally:
        fmu.freeInstance()
