"""Native C FMUs: checked by FMPy (validation, simulate_fmu, its source-FMU build), equal to the python
build on every shipped scenario, faults reported through the FMI logger, and a clear line without a C
compiler.

Equality (issue 23), sample by sample on every signal: positions (m, rad: ``p``, ``q`` and their
references) to ATOL_POSITION = 1e-12; every other signal (efforts, velocities, accelerations) to
RTOL = 1e-12 relative to its largest magnitude (at least 1). The native code evaluates the same
formulas in CasADi's operation order; the differences are rounding (measured: at most 2.2e-12 N on
10 N efforts, 3e-15 m on positions).

With the Exudyn plant in the loop, velocities and efforts follow the plant's own response to rounding:
its Newton iterations stop at a tolerance, so a change in the last bit of an input moves its velocities
by ~1e-11 m/s and the efforts by ~3e-9 relative (``test_exudyn_plant_amplifies_rounding`` measures it on
the python build alone, with a gain changed by one ulp). There, velocities and efforts are compared to
RTOL_EXUDYN = 1e-8 relative; positions still to 1e-12 m.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np
import pytest

from cosim import api
from fmus import registry

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.integration

ATOL_POSITION = 1e-12
RTOL = 1e-12
RTOL_EXUDYN = 1e-8
NATIVE = registry.native_names()
_POSITION = re.compile(r"\.(p|p_ref)\.[xyz]$|\.(q|q_ref)\[\d\]$")


@pytest.fixture(scope="module")
def cache(tmp_path_factory):
    return tmp_path_factory.mktemp("native_cache")


@pytest.mark.parametrize("fmi", [2, 3])
def test_every_native_fmu_validates_and_runs_in_fmpy(fmi, cache):
    """fmpy.validation finds nothing, and FMPy's own master runs each FMU in both interfaces."""
    from fmpy import simulate_fmu
    from fmpy.validation import validate_fmu

    for name in NATIVE:
        path = registry.build(name, cache, native=True, fmi=fmi)
        assert validate_fmu(str(path)) == [], f"{name} FMI {fmi}: {validate_fmu(str(path))}"
        for interface in ("CoSimulation", "ModelExchange"):
            result = simulate_fmu(str(path), fmi_type=interface, stop_time=0.2, output_interval=0.05)
            values = np.array(result.tolist(), dtype=float)
            assert np.all(np.isfinite(values)), f"{name} FMI {fmi} {interface}: non-finite output"


def test_native_fmu_carries_its_sources_and_compiles_from_them(cache, tmp_path):
    """A tool on another platform compiles the FMU from sources/ (FMPy's source-FMU build with CMake)."""
    import zipfile

    from fmpy import simulate_fmu
    from fmpy.build import build_platform_binary

    for fmi in (2, 3):
        path = registry.build("linear_ctc", cache, native=True, fmi=fmi)
        unzipped = tmp_path / f"fmi{fmi}"
        with zipfile.ZipFile(path) as zf:
            names = zf.namelist()
            zf.extractall(unzipped)
        assert "sources/model_functions.c" in names and "sources/model.c" in names, names
        assert not any(n.endswith(".py") for n in names), "a native FMU carries no Python"
        binaries = unzipped / "binaries"
        for so in binaries.rglob("*.so"):
            so.unlink()
        (tmp_path / f"build{fmi}").mkdir()
        build_platform_binary(unzipped, tmp_path / f"build{fmi}")
        assert list(binaries.rglob("linear_ctc.so")), f"FMI {fmi}: no binary compiled from the sources"
        result = simulate_fmu(str(unzipped), fmi_type="CoSimulation", stop_time=0.1)
        assert np.isfinite(result["u[1]"][-1])


def _initial_dependencies(md, fmi: int) -> dict[str, set[str]]:
    """InitialUnknown name -> the names its ``dependencies`` list (None: the attribute is missing)."""
    if fmi == 2:
        names = [v.get("name") for v in md.iter("ScalarVariable")]
        return {names[int(u.get("index")) - 1]: None if u.get("dependencies") is None
                else {names[int(i) - 1] for i in u.get("dependencies").split()}
                for u in md.iterfind("ModelStructure/InitialUnknowns/Unknown")}
    names = {v.get("valueReference"): v.get("name") for v in md.find("ModelVariables")}
    return {names[u.get("valueReference")]: None if u.get("dependencies") is None
            else {names[i] for i in u.get("dependencies").split()}
            for u in md.iterfind("ModelStructure/InitialUnknown")}


def test_initial_unknowns_declare_their_dependencies_as_in_the_python_build(cache):
    """One declaration (the adapter's ``depends``) and one rule (:func:`fmus._names.initial_knowns`) for
    both builds: every InitialUnknown of a native FMU (FMI 2 and 3) lists its dependencies, and each
    output's list names the same variables as in the python build. An InitialUnknown without the list
    depends on every input: an importer then sees a loop at initialization through every feedback
    connection (OMSimulator 3.0 did on helix_ctc_analytic: plant.q -> ctl.u -> plant.u)."""
    import zipfile
    from xml.etree import ElementTree as ET

    from fmus.native.interface import interface, model_description

    for name in NATIVE:
        with zipfile.ZipFile(registry.build(name, cache)) as zf:
            python = _initial_dependencies(ET.fromstring(zf.read("modelDescription.xml")), 2)
        itf = interface(name, registry.get(name).native_model())
        for fmi in (2, 3):
            native = _initial_dependencies(ET.fromstring(model_description(itf, fmi, "token", [])), fmi)
            bare = sorted(n for n, deps in native.items() if deps is None)
            assert not bare, f"{name} FMI {fmi}: InitialUnknowns without dependencies: {bare}"
            for output, deps in python.items():
                assert native[output] == deps, f"{name} FMI {fmi} {output}: native {native[output]} vs python {deps}"


def _signals(name: str, build: str, stop: float | None):
    overrides = {"fmus": build, "parallel": "off"}
    if stop is not None:
        overrides["time.stop"] = stop
    res = api.run(ROOT / "scenarios" / f"{name}.yaml", overrides)
    assert res.status == "completed", (name, build, res.status)
    return res


SCENARIOS = sorted(p.stem for p in (ROOT / "scenarios").glob("*.yaml"))
EXUDYN_STOP = 2.0
"""s of a scenario with an Exudyn plant (which dominates its run, and has no native build to compare): enough to
exercise every component; every other scenario runs whole."""


def _exudyn(name: str) -> bool:
    from cosim.engine.scenario import load_scenario

    return any("exudyn" in (c.fmu or "") for c in load_scenario(ROOT / "scenarios" / f"{name}.yaml").components.values())


def _worst(a: np.ndarray, b: np.ndarray, signal: str, rtol: float) -> tuple[float, float]:
    """(difference, its tolerance) of one signal: absolute for positions, relative for the rest."""
    diff = float(np.max(np.abs(a - b)))
    if _POSITION.search(signal):
        return diff, ATOL_POSITION
    return diff / max(1.0, float(np.max(np.abs(a)))), rtol


@pytest.mark.parametrize("name", SCENARIOS)
def test_native_build_reproduces_the_python_build(name):
    """Every shipped scenario, every signal, sample by sample: native against python."""
    exudyn = _exudyn(name)
    stop = EXUDYN_STOP if exudyn else None
    python, native = _signals(name, "python", stop), _signals(name, "native", stop)
    assert np.array_equal(python.time, native.time)
    assert set(python.signals) == set(native.signals)
    rtol = RTOL_EXUDYN if exudyn else RTOL
    for signal, a in python.signals.items():
        diff, tol = _worst(a, native.signals[signal], signal, rtol)
        assert diff <= tol, f"{name} {signal}: native vs python differ by {diff:.3g} (tolerance {tol:g})"


def test_exudyn_plant_amplifies_rounding():
    """The python build against itself with one gain changed in its last bit: on the Exudyn plant the efforts
    move by more than RTOL (so native-vs-python cannot be held to it there) but stay within RTOL_EXUDYN."""
    base = _signals("helix_ctc", "python", 1.0)
    nudged = api.run(ROOT / "scenarios" / "helix_ctc.yaml",
                     {"fmus": "python", "parallel": "off", "time.stop": 1.0, "ctl.gain.kp[1]": float(np.nextafter(22500.0, 1e9))})
    diff, _ = _worst(base.signals["ctl.u[1]"], nudged.signals["ctl.u[1]"], "ctl.u[1]", RTOL)
    assert RTOL < diff <= RTOL_EXUDYN, f"effort change for a 1-ulp gain change: {diff:.3g} relative"


def test_native_run_is_native_where_it_can_be(tmp_path):
    """fmus: native builds the C FMUs; the Exudyn plant stays python (it has no native build)."""
    from cosim.engine.prepare import build_key

    scenario = api.load(ROOT / "scenarios" / "helix_ctc.yaml", {"fmus": "native"})
    keys = {n: build_key(scenario.structure(), c.fmu) for n, c in scenario.components.items()}
    assert keys["plant"][1] is False, keys
    assert all(keys[n][1] for n in ("traj", "ik", "ctl")), keys


def test_unreachable_reference_is_held_and_logged_once(cache):
    """The IK holds its last reachable references and says why once, through the FMI logger."""
    from fmpy import simulate_fmu

    path = registry.build("linear_ik", cache, native=True, fmi=2)
    messages: list[str] = []

    def logger(*args):  # noqa: ANN002 - FMI 2 passes 5 arguments, FMI 3 four; the message is the last
        messages.append(args[-1].decode())

    inputs = np.array([(0.0, 0.1, 0.0, -0.45), (0.1, 3.0, 0.0, -0.45), (0.2, 3.0, 0.0, -0.45)],
                      dtype=[("time", float), ("p_ref.x", float), ("p_ref.y", float), ("p_ref.z", float)])
    result = simulate_fmu(str(path), stop_time=0.3, output_interval=0.01, input=inputs, logger=logger,
                          debug_logging=True, output=["q_ref[1]", "reachable"])
    reach = result["reachable"]
    assert reach[0] and not reach[-1], reach
    held = result["q_ref[1]"][reach == 0]
    assert np.all(held == result["q_ref[1]"][np.argmin(reach) - 1]), "references must hold their last values"
    unreachable = [m for m in messages if "unreachable" in m]
    assert len(unreachable) == 1 and "leg" in unreachable[0], messages


@pytest.mark.parametrize("fmi", [2, 3])
def test_non_finite_effort_discards_the_step_with_its_reason(fmi, cache):
    """A NaN effort is a discarded step (no NaN output), with the reason through the FMI logger."""
    from fmpy import simulate_fmu

    path = registry.build("linear_analytic_plant", cache, native=True, fmi=fmi)
    messages: list[str] = []

    def logger(*args):  # noqa: ANN002 - FMI 2 passes 5 arguments, FMI 3 four; the message is the last
        messages.append(args[-1].decode())

    inputs = np.array([(0.0, 0.0, 0.0, 0.0), (0.05, float("nan"), 0.0, 0.0)],
                      dtype=[("time", float), ("u[1]", float), ("u[2]", float), ("u[3]", float)])
    try:  # FMPy ends an FMI 2 run at a discarded step, and raises for FMI 3
        result = simulate_fmu(str(path), stop_time=0.1, input=inputs, logger=logger, debug_logging=True)
    except Exception as exc:  # noqa: BLE001 - FMPy raises a bare Exception
        assert "Discard" in str(exc) or "discard" in str(exc), exc
    else:
        assert result["time"][-1] < 0.1, "the run must stop at the discarded step"
        assert np.all(np.isfinite(np.array(result.tolist(), dtype=float))), "no NaN may reach an output"
    assert any("non-finite effort" in m for m in messages), messages


def test_native_without_compiler_is_one_line(monkeypatch, tmp_path):
    """No C compiler: one line naming what is missing and how to get it; the python build still works."""
    from fmus.native.errors import CompilerMissingError

    monkeypatch.setenv("CC", "no-such-compiler-xyz")
    with pytest.raises(CompilerMissingError) as exc:
        registry.build("linear_ctc", tmp_path, native=True)
    text = str(exc.value)
    assert "\n" not in text and "no-such-compiler-xyz" in text and "gcc" in text, text
    assert registry.build("linear_ctc", tmp_path).exists()


@pytest.mark.parametrize("fmi", [2, 3])
def test_string_parameter_takes_its_declared_values(fmi, cache):
    """A native String parameter (the time scaling) is set by its text; another text is an error naming both."""
    from fmpy import simulate_fmu

    path = str(registry.build("point_to_point", cache, native=True, fmi=fmi))
    quintic = simulate_fmu(path, stop_time=1.0, output_interval=0.01)
    cubic = simulate_fmu(path, stop_time=1.0, output_interval=0.01, start_values={"move.profile": "cubic"})
    assert np.max(np.abs(quintic["a_ref.x"] - cubic["a_ref.x"])) > 0.01, "the profile must change the motion"
    messages: list[str] = []
    with pytest.raises(Exception):  # noqa: B017 - FMPy raises a bare Exception for the failed call
        simulate_fmu(path, stop_time=1.0, start_values={"move.profile": "linear"},
                     logger=lambda *args: messages.append(args[-1].decode()), debug_logging=True)
    assert any('"linear"' in m and '"cubic"' in m and '"quintic"' in m for m in messages), messages


def test_pid_keeps_its_integral_when_the_step_size_changes_by_an_ulp(cache):
    """A master on an exact time grid gives step sizes that differ by an ulp from step to step
    (cosim.engine.grid): the PID integral is kept through them, in the python and the native build alike.

    linear_pid is stepped through FMPy with a constant error e on leg 1 and steps alternating h and the
    next double above it; after each step u[1] must be kp e + ki (e sum(h) + e h_last) (the output adds the
    coming step's e h with the last step's size), to RTOL, and the two builds must agree to RTOL."""
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    e, h, n = 1e-4, 1e-3, 50  # 5e-6 m s of integral: far from the anti-windup bound and the effort limit
    outputs = {}
    for native in (False, True):
        path = registry.build("linear_pid", cache, native=native, fmi=2)
        md = read_model_description(str(path))
        vrs = {v.name: v.valueReference for v in md.modelVariables}
        start = {v.name: float(v.start) for v in md.modelVariables if v.start is not None and v.type == "Real"}
        kp, ki = start["gain.kp[1]"], start["gain.ki[1]"]
        fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(str(path)),
                        modelIdentifier=md.coSimulation.modelIdentifier, instanceName=f"pid_{native}")
        fmu.instantiate()
        fmu.setupExperiment(startTime=0.0)
        fmu.enterInitializationMode()
        fmu.setReal([vrs["q[1]"], vrs["qd[1]"], vrs["q_ref[1]"], vrs["qd_ref[1]"]], [0.0, 0.0, e, 0.0])
        fmu.exitInitializationMode()
        t, total, got, want = 0.0, 0.0, [], []
        for k in range(n):
            hk = h if k % 2 == 0 else math.nextafter(h, 1.0)
            fmu.doStep(t, hk)
            t, total = t + hk, total + hk
            got.append(fmu.getReal([vrs["u[1]"]])[0])
            want.append(kp * e + ki * (e * total + e * hk))
        fmu.terminate()
        fmu.freeInstance()
        got, want = np.array(got), np.array(want)
        assert np.allclose(got, want, rtol=RTOL, atol=0.0), \
            f"native={native}: u[1] {got[:4]} ... expected {want[:4]} ... (worst {np.max(np.abs(got - want))})"
        assert got[-1] - got[0] > 0.5 * ki * e * (n - 1) * h, f"native={native}: the integral did not grow: {got}"
        outputs[native] = got
    worst = np.max(np.abs(outputs[True] - outputs[False]))
    assert worst <= RTOL * np.max(np.abs(outputs[False])), f"python and native differ by {worst}"
