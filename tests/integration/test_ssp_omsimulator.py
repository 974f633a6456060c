"""Our exported archives in OpenModelica's OMSimulator, against our own master on the same archive.

Runs only where OMSimulator is: set ``OMSIMULATOR_LIB`` to its shared library (``libOMSimulator.so`` of an
OMSimulator installed from source as docs/ssp.md says: its Python API, ``<prefix>/lib/OMSimulator``, is found
beside it); elsewhere (CI) every test here is skipped with that reason. Each run is a subprocess of its own
(OMSimulator calls ``exit`` on some failures; a deadlock ends in its time limit):

- its C API with ctypes, as its command line uses it: import, instantiate, initialize, then one
  ``oms_stepUntil`` per step, reading plant.p after each; on one thread, or on its thread pool
  (``--numProcs=2``) with no FMU call from the thread that loaded the FMUs;
- its Python API, ``OMSimulator.SSP(path).instantiate()``, stepped the same way, every parameter the archive
  binds read back from the FMUs.

Its fixed-step master (``oms-ma``, our export's annotation; ``SystemWC::doStep``) steps every FMU, then
updates the inputs along its sorted connections, direct feedthrough included: for components without state
that the step advances from its inputs, the values of our Gauss-Seidel run (a PID's integral is the
exception: see :data:`NO_INTEGRAL`). It adds the step to its time in floating point (t = 0.009000000000000001
s), so the trajectory FMU sees times a few ulps off ours: the runs agree to rounding, not bit for bit.
Its import reads no ``ssv:String``: the export leaves a String parameter at its start value out of the
.ssv (``model.fidelity: full``); one that differs is written, and OMSimulator runs without it.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np
import pytest
import yaml

from cosim.engine.overrides import apply_overrides
from cosim.engine.names import ref
from cosim.engine.scenario import load_scenario, scenario_from_data
from cosim.io.ssp.scenario import open_ssp
from cosim.io.ssp.spec import NS
from cosim.io.ssp.write import export_ssp
from cosim.observers.recorders import Probe
from cosim.run import run_scenario

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
LIB = os.environ.get("OMSIMULATOR_LIB", "")
if not LIB:
    pytestmark = [pytestmark, pytest.mark.skip(reason="OMSimulator not available: set OMSIMULATOR_LIB to "
                                                      "libOMSimulator.so (built from source, docs/ssp.md)")]
elif not Path(LIB).is_file():
    pytestmark = [pytestmark, pytest.mark.skip(reason=f"OMSIMULATOR_LIB={LIB} is not a file")]

STOP, STEP = 1.0, 1e-3
N = round(STOP / STEP)
P = ["plant.p.x", "plant.p.y", "plant.p.z"]
# OMSimulator and our Gauss-Seidel master call the FMUs with the same values, except the communication
# point, which OMSimulator accumulates in floating point: rounding only
OMS_TOL_M = 1e-12
# OMSimulator on its thread pool and on one thread: the same FMU calls with the same values
SAME_TOL = 0.0
LIMIT_S = 600  # a deadlock is a wait for ever; an honest run of 1 s of helix_ctc takes a few seconds

# OMSimulator's C API, as its command line uses it. Arguments: the library, the archive, the step, the number of
# steps, the number of its threads (``--numProcs``), the signals. The archive is imported (the FMUs' libraries
# loaded) on the main thread; everything after runs on another thread when numProcs > 1, so that no call to an
# FMU comes from the thread that loaded it: instantiation on that thread, each step on OMSimulator's own thread
# pool (SystemWC::doStep pushes each FMU's step to it), which Python did not start.
_C_RUNNER = textwrap.dedent("""
    import ctypes, json, sys, threading, zipfile
    from xml.etree import ElementTree as ET
    lib = ctypes.CDLL(sys.argv[1])
    ssp, h, n, procs = sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), int(sys.argv[5])
    lib.oms_setLoggingLevel(0)
    assert lib.oms_setCommandLineOption(f"--numProcs={procs}".encode()) == 0, "--numProcs"
    for f in ("oms_setStopTime", "oms_stepUntil"):
        getattr(lib, f).argtypes = [ctypes.c_char_p, ctypes.c_double]
    model = ctypes.c_char_p()
    assert lib.oms_importFile(ssp.encode(), ctypes.byref(model)) == 0, "oms_importFile"
    m = model.value
    with zipfile.ZipFile(ssp) as z:
        ns = "{http://ssp-standard.org/SSP1/SystemStructureDescription}"
        system = ET.fromstring(z.read("SystemStructure.ssd")).find(ns + "System").get("name")
    names = [m + b"." + system.encode() + b"." + s.encode() for s in sys.argv[6:]]
    def sample():
        t, out = ctypes.c_double(), []
        assert lib.oms_getTime(m, ctypes.byref(t)) == 0
        for name in names:
            x = ctypes.c_double()
            assert lib.oms_getReal(name, ctypes.byref(x)) == 0, name
            out.append(x.value)
        return t.value, out
    def run(rows):
        lib.oms_setStopTime(m, n * h)
        lib.oms_setResultFile(m, b"", 0)
        assert lib.oms_instantiate(m) == 0, "oms_instantiate"
        assert lib.oms_initialize(m) == 0, "oms_initialize"
        rows.append(sample())
        for k in range(1, n + 1):
            # one step each: its master steps while time < the target, and time is a float sum of steps
            assert lib.oms_stepUntil(m, (k - 0.5) * h) == 0, f"oms_stepUntil, step {k}"
            rows.append(sample())
        lib.oms_terminate(m)
        lib.oms_delete(m)
    rows, failed = [], []
    def guarded():
        try:
            run(rows)
        except AssertionError as exc:
            failed.append(str(exc))
    if procs == 1:
        guarded()
    else:
        worker = threading.Thread(target=guarded)
        worker.start()
        worker.join()
    assert not failed, failed
    print(json.dumps({"t": [r[0] for r in rows], "values": [r[1] for r in rows]}))
""")

# OMSimulator's Python API (``OMSimulator.SSP(path).instantiate()``), installed beside the library
# (``<prefix>/lib/OMSimulator``, which loads ``<prefix>/lib/libOMSimulator.so``). Arguments: the library, the
# archive, the step, the number of steps, a JSON object of the parameters to read back ({component: {name:
# value}}), the signals. Its SSD reader takes a solver's settings from attributes of oms:SimulationInformation
# (ours carries the C++ reader's oms:FixedStepMaster element) and gives components without a solver of their own
# OMSimulator's default step: the step is set after instantiate(), as a user of that API does.
_PY_RUNNER = textwrap.dedent("""
    import json, os, sys
    sys.path.insert(0, os.path.dirname(sys.argv[1]))
    from OMSimulator import SSP, CRef
    ssp, h, n, params = sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), json.loads(sys.argv[5])
    archive = SSP(ssp)
    system = archive.activeVariant.system.name
    model = archive.instantiate()
    model.setResultFile("", 0)
    model.setFixedStepSize(h)
    read = {c: {name: model.getValue(CRef(system, c, name)) for name in values} for c, values in params.items()}
    model.initialize()
    signals = [CRef(system, *s.split(".", 1)) for s in sys.argv[6:]]
    rows = [(model.getTime(), [model.getValue(s) for s in signals])]
    for k in range(1, n + 1):
        model.stepUntil((k - 0.5) * h)
        rows.append((model.getTime(), [model.getValue(s) for s in signals]))
    model.terminate()
    model.delete()
    print(json.dumps({"t": [r[0] for r in rows], "values": [r[1] for r in rows], "parameters": read}))
""")
PY_API = Path(LIB).parent / "OMSimulator" / "__init__.py" if LIB else None


def _run(ssp: Path, signals: list[str], step: float, n: int, procs: int = 1) -> tuple[dict, list[str]]:
    """Run ``ssp`` in OMSimulator's C API on ``procs`` threads: (the samples, the error and warning lines it
    logged)."""
    data, lines = _subprocess([_C_RUNNER, LIB, str(ssp), repr(step), str(n), str(procs), *signals], ssp)
    return data, _complaints(lines)


def _subprocess(args: list[str], ssp: Path) -> tuple[dict, list[str]]:
    """Run a runner: (its samples, every line it printed)."""
    proc = subprocess.run([sys.executable, "-c", *args], check=False, capture_output=True, text=True,
                          timeout=LIMIT_S, cwd=ssp.parent)
    lines = (proc.stdout + proc.stderr).splitlines()
    data = [json.loads(line) for line in lines if line.startswith('{"t"')]
    assert proc.returncode == 0 and data, (f"OMSimulator failed (exit code {proc.returncode}):\n"
                                           f"{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}")
    return data[0], lines


def _complaints(lines: list[str]) -> list[str]:
    return [line for line in lines if line.startswith(("error:", "warning:"))]


def omsimulator(ssp: Path, signals: list[str], step: float = STEP, n: int = N,
                procs: int = 1) -> tuple[np.ndarray, np.ndarray]:
    """Run ``ssp`` in OMSimulator's C API; (times s, signals as an (n + 1, len(signals)) array), from t = 0. It
    must log no error or warning."""
    data, complaints = _run(ssp, signals, step, n, procs)
    assert not complaints, "OMSimulator complained:\n" + "\n".join(complaints)
    return np.array(data["t"]), np.array(data["values"])


def _bound_parameters(ssp: Path) -> dict[str, dict[str, float | int | bool]]:
    """{component: {parameter: value}} of the archive's .ssv files (Real, Integer, Boolean)."""
    out: dict[str, dict] = {}
    with zipfile.ZipFile(ssp) as z:
        ssd = ET.fromstring(z.read("SystemStructure.ssd"))
        for comp in ssd.iterfind("ssd:System/ssd:Elements/ssd:Component", NS):
            for b in comp.iterfind("ssd:ParameterBindings/ssd:ParameterBinding", NS):
                for p in ET.fromstring(z.read(b.get("source"))).iterfind("ssv:Parameters/ssv:Parameter", NS):
                    typed = p[0]
                    kind, text = typed.tag.rsplit("}", 1)[1], typed.get("value")
                    value = {"Real": float, "Integer": int, "Boolean": lambda v: v == "true"}.get(kind, str)(text)
                    out.setdefault(comp.get("name"), {})[p.get("name")] = value
    return out


def omsimulator_python(ssp: Path, signals: list[str], step: float = STEP,
                       n: int = N) -> tuple[np.ndarray, np.ndarray, dict, dict]:
    """Run ``ssp`` through OMSimulator's Python API: (times s, signals, the parameters the archive binds, the values
    the API reads back from the instantiated FMUs). It must raise nothing and log no error or warning."""
    if PY_API is None or not PY_API.is_file():
        pytest.skip(f"OMSimulator's Python API is not beside {LIB} (install OMSimulator: docs/ssp.md)")
    params = _bound_parameters(ssp)
    data, lines = _subprocess([_PY_RUNNER, LIB, str(ssp), repr(step), str(n), json.dumps(params), *signals], ssp)
    complaints = _complaints(lines)
    assert not complaints, "OMSimulator complained:\n" + "\n".join(complaints)
    return np.array(data["t"]), np.array(data["values"]), params, data["parameters"]


def ours(ssp: Path, overrides: dict | None = None, signals: list[str] = P) -> tuple[np.ndarray, np.ndarray]:
    """Our master on the archive (its own algorithm, Gauss-Seidel), no log: (times s, ``signals``, plant.p)."""
    probe = Probe(signals)
    with open_ssp(ssp, overrides) as sc:
        run_scenario(sc, log=False, observers=[probe])
    return np.array(probe.t_ns) * 1e-9, np.column_stack([probe.values[s] for s in signals])


def _difference(ssp: Path, t_oms: np.ndarray, p_oms: np.ndarray, how: str, overrides: dict | None = None,
                signals: list[str] = P) -> float:
    """The largest |p(OMSimulator) - p(ours)| over the run, printed; the time grids and the start must agree.
    ``signals``: plant.p as our master names it."""
    t_us, p_us = ours(ssp, overrides, signals)
    assert len(t_oms) == len(t_us), (len(t_oms), len(t_us))
    assert np.abs(t_oms - t_us).max() < 1e-12, "time grids differ"
    diff = np.abs(p_oms - p_us)
    k = np.unravel_index(np.argmax(diff), diff.shape)
    print(f"{ssp.name} ({how}): max |OMSimulator - ours (gauss_seidel)| = {diff.max():.3e} m over {len(t_us)} "
          f"samples (worst at t = {t_us[k[0]]:g} s, {P[k[1]]}); p({t_us[-1]:g} s) = {p_oms[-1].tolist()}")
    assert diff[0].max() == 0.0, f"start values differ: OMSimulator {p_oms[0]}, ours {p_us[0]}"
    return float(diff.max())


def _compare(ssp: Path, procs: int = 1) -> float:
    t_oms, p_oms = omsimulator(ssp, P, procs=procs)
    assert len(t_oms) == N + 1, len(t_oms)
    return _difference(ssp, t_oms, p_oms, f"C API, {procs} thread(s)")


@pytest.mark.parametrize("fmus", ["native", "python"])
def test_omsimulator_runs_helix_ctc_analytic_as_our_master(tmp_path, fmus):
    """The native build's InitialUnknowns once lacked their dependencies: OMSimulator then saw a loop at
    initialization (plant.q -> ctl.u -> plant.u) and stopped ("Solution of algebraic loop 0 not within
    precision")."""
    ssp = tmp_path / f"helix_ctc_analytic_{fmus}.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc_analytic.yaml",
                             {("time", "stop"): STOP, ("fmus",): fmus}), ssp)
    assert _compare(ssp) <= OMS_TOL_M


def test_omsimulator_runs_helix_ctc_with_the_exudyn_plant(tmp_path):
    """The Exudyn plant (a python FMI 2 co-simulation FMU) with ``model.fidelity: full``, its String
    parameter's start value: the export leaves it out of the .ssv, so OMSimulator 3.0, which reads no
    ``ssv:String``, imports the archive without an error."""
    pytest.importorskip("exudyn")
    ssp = tmp_path / "helix_ctc.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("time", "stop"): STOP}), ssp)
    assert _compare(ssp) <= OMS_TOL_M


def test_omsimulator_skips_a_string_parameter_with_an_error(tmp_path):
    """What is left: a String parameter that differs from its start (``model.fidelity=lumped``) is written
    as ``ssv:String``, as SSP 1.0 says; OMSimulator 3.0 logs an error for it and runs the FMU with its start
    value ("full"). When this fails, OMSimulator reads ssv:String: update docs/ssp.md."""
    pytest.importorskip("exudyn")
    ssp = tmp_path / "helix_ctc_lumped.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc.yaml",
                             apply_overrides(["plant.model.fidelity=lumped"], stop_time=0.01)), ssp)
    with zipfile.ZipFile(ssp) as z:
        assert b"<ssv:String " in z.read("resources/plant.ssv")
    _, complaints = _run(ssp, P, STEP, 10)
    assert any("Unknown ParameterBinding-type" in line for line in complaints), complaints


def test_omsimulator_steps_the_exudyn_plant_from_its_own_threads(tmp_path):
    """No deadlock in any host: with ``--numProcs=2`` OMSimulator steps each FMU on its thread pool, and our
    runner instantiates and initializes them on a thread other than the one that loaded them, so no call to the
    python Exudyn plant comes from its loading thread (FMI 2.0 allows it, one call at a time). The run is the
    single-threaded one exactly (the same calls with the same values; only the calling thread differs) and ours
    to rounding. A deadlock ends in the time limit with this test's name."""
    pytest.importorskip("exudyn")
    ssp = tmp_path / "helix_ctc.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("time", "stop"): STOP}), ssp)
    t_one, p_one = omsimulator(ssp, P)
    data, lines = _subprocess([_C_RUNNER, LIB, str(ssp), repr(STEP), str(N), "2", *P], ssp)
    assert not _complaints(lines), _complaints(lines)
    assert any("Initialized thread pool" in line and "with 2 threads" in line for line in lines), lines[:20]
    t_pool, p_pool = np.array(data["t"]), np.array(data["values"])
    assert np.array_equal(t_one, t_pool), "time grids differ"
    assert np.abs(p_pool - p_one).max() <= SAME_TOL, (
        f"threads changed the run: max |pool - one thread| = {np.abs(p_pool - p_one).max():.3e} m")
    assert _difference(ssp, t_pool, p_pool, "C API, 2 threads") <= OMS_TOL_M


def test_omsimulator_python_api_sets_every_parameter_of_helix_ctc(tmp_path):
    """OMSimulator's Python API addresses every parameter the archive binds, ``model.w_inertia`` of ``ctl``
    included (once refused as "Unknown signal model.root.ctl.w_inertia", then a segmentation fault): it reads
    each back from the instantiated FMU, unchanged, and runs the system as our master does."""
    pytest.importorskip("exudyn")
    ssp = tmp_path / "helix_ctc.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("time", "stop"): STOP}), ssp)
    t, p, bound, read = omsimulator_python(ssp, P)
    assert any(name.startswith("model.") for name in bound["ctl"]), bound
    assert read == bound, f"read back {read}, the archive binds {bound}"
    assert _difference(ssp, t, p, "Python API") <= OMS_TOL_M


def test_undeclared_parameters_are_what_the_python_api_cannot_address(tmp_path):
    """The check above can fail: the same archive with its parameter connectors removed (as the export wrote it
    before) stops in OMSimulator's Python API on the first name it mangles."""
    pytest.importorskip("exudyn")
    ssp = tmp_path / "helix_ctc.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("time", "stop"): 0.01}), ssp)
    bare = tmp_path / "undeclared" / "helix_ctc.ssp"
    bare.parent.mkdir()
    with zipfile.ZipFile(ssp) as zin, zipfile.ZipFile(bare, "w") as zout:
        for item in zin.namelist():
            data = zin.read(item)
            if item == "SystemStructure.ssd":  # as text: OMSimulator reads the prefixes as written
                data, removed = re.subn(rb'<ssd:Connector [^>]*kind="parameter".*?</ssd:Connector>\s*', b"", data,
                                        flags=re.S)
                assert removed, "no parameter connector in the export"
            zout.writestr(item, data)
    with pytest.raises(AssertionError, match="model.root.ctl.w_inertia"):
        omsimulator_python(bare, P, n=10)


SCENARIOS = sorted(p.name for p in (ROOT / "scenarios").glob("*.yaml"))
SWEEP_STOP = 0.2  # s: every system imported, instantiated, initialized and run 200 steps in both APIs
# OMSimulator's oms-ma steps every FMU with the inputs of the step's start, then sets the inputs along the
# connections; our Gauss-Seidel master sets a component's inputs from those stepped before it. For a law without
# state the two give the same values; a PID's integral (a forward Euler sum of e h, added at each step) sums
# e(t_j) h there and e(t_j+1) h here: the runs differ by that, and agree to rounding with the integral gain 0.
NO_INTEGRAL = [f"ctl.gain.ki[{i}]=0" for i in (1, 2, 3)]


def _both_apis(ssp: Path, n: int, step: float) -> tuple[np.ndarray, np.ndarray]:
    """``ssp`` in OMSimulator's C API and in its Python API: the same run exactly (one master), every parameter
    the archive binds read back unchanged; (times s, plant.p)."""
    t_c, p_c = omsimulator(ssp, P, step, n)
    t_py, p_py, bound, read = omsimulator_python(ssp, P, step, n)
    assert read == bound, f"read back {read}, the archive binds {bound}"
    assert np.array_equal(t_py, t_c) and np.array_equal(p_py, p_c), (
        f"the Python API ran otherwise: max |Python - C| = {np.abs(p_py - p_c).max():.3e} m")
    return t_c, p_c


@pytest.mark.parametrize("name", SCENARIOS)
def test_omsimulator_runs_every_scenario_in_both_apis(tmp_path, name):
    """Every scenario of scenarios/, exported, runs in OMSimulator's C API and in its Python API without an error
    or a warning, as our Gauss-Seidel master runs the archive, to rounding. Where it cannot be the same run, the
    difference is named: SSP 1.0 carries no events (the export says so; they travel in our annotation only),
    so our master runs without them; OMSimulator's SSP import ignores ``implementation="ModelExchange"``
    (``System::importFromSnapshot`` makes every FMU of its fixed-step system a co-simulation component), so
    our master runs those components' co-simulation interface; a PID is compared without its integral
    (:data:`NO_INTEGRAL`), its run with it printed."""
    scenario = load_scenario(ROOT / "scenarios" / name, {("time", "stop"): SWEEP_STOP})
    if any("exudyn" in str(c.fmu) for c in scenario.components.values()):
        pytest.importorskip("exudyn")
    theirs: dict[tuple, object] = {("components", c, "interface"): "cs"
                                   for c, comp in scenario.components.items() if comp.interface == "me"}
    if scenario.events:
        theirs[("events",)] = []
    n = round(SWEEP_STOP / scenario.time.step)
    ssp = tmp_path / f"{scenario.name}.ssp"
    export_ssp(scenario, ssp)
    with open_ssp(ssp) as sc:  # our master runs the archive with the scenario's interfaces (our annotation)
        interfaces = {c: comp.interface for c, comp in sc.components.items()}
    assert interfaces == {c: comp.interface for c, comp in scenario.components.items()}, interfaces
    t, p = _both_apis(ssp, n, scenario.time.step)
    if not any(str(c.fmu).endswith("_pid") for c in scenario.components.values()):
        assert _difference(ssp, t, p, "both APIs", theirs) <= OMS_TOL_M
        return
    _difference(ssp, t, p, "both APIs, the PID's integral summed otherwise", theirs)
    ssp = tmp_path / "no_integral" / f"{scenario.name}.ssp"
    ssp.parent.mkdir()
    export_ssp(load_scenario(ROOT / "scenarios" / name, apply_overrides(NO_INTEGRAL, stop_time=SWEEP_STOP)), ssp)
    t, p = _both_apis(ssp, n, scenario.time.step)
    assert _difference(ssp, t, p, "both APIs, ki = 0", theirs) <= OMS_TOL_M


# names OMSimulator cannot take as they are: not identifiers (a digit first, a space, a dot), its model's and its
# root system's names, and "model", the first part of the controller's model.w_inertia
AWKWARD = {"traj": "2nd traj", "ik": "root", "ctl": "model", "plant": "DP plant.1"}


def test_omsimulator_runs_components_named_as_no_ssp_tool_can_address(tmp_path):
    """Component names SSP allows and OMSimulator cannot address go into the archive as identifiers (``model``
    stays clear of its ``model.w_inertia``), which our import maps back; both OMSimulator APIs run the system
    as our master does, every parameter read back."""
    data = yaml.safe_load((ROOT / "scenarios" / "helix_ctc_analytic.yaml").read_text(encoding="utf-8"))
    data["components"] = {AWKWARD[k]: v for k, v in data["components"].items()}
    # parameters of the component named "model" whose names begin "model.": the controller's model split as
    # helix_ctc's identified one, so a value that did not arrive changes the run
    data["components"]["model"]["parameters"] = {"model.w_inertia": 0.5, "model.w_gravity": 0.5}
    for c in data["connections"]:
        for end in ("from", "to"):
            comp, var = c[end].split(".", 1)
            c[end] = ref(AWKWARD[comp], var)
    data["compare"] = {"actual": ref(AWKWARD["plant"], "p"), "reference": ref(AWKWARD["traj"], "p_ref")}
    data["initial_state"] = {"component": AWKWARD["plant"]}
    data["logging"] = {"signals": "all"}
    data["name"] = "helix ctc.awkward"
    ssp = tmp_path / "awkward.ssp"
    export_ssp(scenario_from_data(data, str(ROOT / "scenarios" / "helix_ctc_analytic.yaml"),
                                  {("time", "stop"): STOP}), ssp)
    with zipfile.ZipFile(ssp) as z:
        ssd = ET.fromstring(z.read("SystemStructure.ssd"))
    names = [c.get("name") for c in ssd.iterfind("ssd:System/ssd:Elements/ssd:Component", NS)]
    assert names == ["c2nd_traj", "root", "model_", "DP_plant_1"], names
    with open_ssp(ssp) as sc:
        assert list(sc.components) == list(AWKWARD.values()), list(sc.components)
    plant = "DP_plant_1"
    signals = [f"{plant}.{s.split('.', 1)[1]}" for s in P]
    t_c, p_c = omsimulator(ssp, signals)
    t_py, p_py, bound, read = omsimulator_python(ssp, signals)
    assert "model.w_inertia" in bound["model_"], bound
    assert read == bound, f"read back {read}, the archive binds {bound}"
    theirs = [ref(AWKWARD["plant"], s.split(".", 1)[1]) for s in P]
    assert _difference(ssp, t_c, p_c, "C API", signals=theirs) <= OMS_TOL_M
    assert _difference(ssp, t_py, p_py, "Python API", signals=theirs) <= OMS_TOL_M
