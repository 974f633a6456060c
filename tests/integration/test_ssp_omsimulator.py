"""Our exported archives in OpenModelica's OMSimulator, against our own master on the same archive.

Runs only where OMSimulator is: set ``OMSIMULATOR_LIB`` to its shared library (``libOMSimulator.so``,
built from source as docs/ssp.md says); elsewhere (CI) every test here is skipped with that reason.
OMSimulator is driven through its C API with ctypes, in a subprocess of its own (it calls ``exit`` on
some failures): import, instantiate, initialize, then one ``oms_stepUntil`` per 1 ms step, reading
plant.p after each. Its fixed-step master (``oms-ma``, our export's annotation; ``SystemWC::doStep``)
steps every FMU, then updates the inputs along its sorted connections, direct feedthrough included: the
same values as our Gauss-Seidel run. It adds the step to its time in floating point (t = 0.009000000000000001 s), so the
trajectory FMU sees times a few ulps off ours: the runs agree to rounding, not bit for bit (measured
6.5e-15 m with the native FMUs, 2.4e-15 m with the Exudyn plant, over the first second).
Its import reads no ``ssv:String``: the export leaves a String parameter at its start value out of the
.ssv (``model.fidelity: full``); one that differs is written, and OMSimulator runs without it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.engine.overrides import apply_overrides
from cosim.engine.scenario import load_scenario
from cosim.io.ssp.scenario import open_ssp
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

_RUNNER = textwrap.dedent("""
    import ctypes, json, sys, zipfile
    from xml.etree import ElementTree as ET
    lib = ctypes.CDLL(sys.argv[1])
    ssp, h, n = sys.argv[2], float(sys.argv[3]), int(sys.argv[4])
    lib.oms_setLoggingLevel(0)
    for f in ("oms_setStopTime", "oms_stepUntil"):
        getattr(lib, f).argtypes = [ctypes.c_char_p, ctypes.c_double]
    model = ctypes.c_char_p()
    assert lib.oms_importFile(ssp.encode(), ctypes.byref(model)) == 0, "oms_importFile"
    m = model.value
    lib.oms_setStopTime(m, n * h)
    lib.oms_setResultFile(m, b"", 0)
    assert lib.oms_instantiate(m) == 0, "oms_instantiate"
    assert lib.oms_initialize(m) == 0, "oms_initialize"
    with zipfile.ZipFile(ssp) as z:
        ns = "{http://ssp-standard.org/SSP1/SystemStructureDescription}"
        system = ET.fromstring(z.read("SystemStructure.ssd")).find(ns + "System").get("name")
    names = [m + b"." + system.encode() + b"." + s.encode() for s in sys.argv[5:]]
    def sample():
        t, out = ctypes.c_double(), []
        assert lib.oms_getTime(m, ctypes.byref(t)) == 0
        for name in names:
            x = ctypes.c_double()
            assert lib.oms_getReal(name, ctypes.byref(x)) == 0, name
            out.append(x.value)
        return t.value, out
    rows = [sample()]
    for k in range(1, n + 1):
        # one step each: its master steps while time < the target, and time is a float sum of steps
        assert lib.oms_stepUntil(m, (k - 0.5) * h) == 0, f"oms_stepUntil, step {k}"
        rows.append(sample())
    lib.oms_terminate(m)
    lib.oms_delete(m)
    print(json.dumps({"t": [r[0] for r in rows], "values": [r[1] for r in rows]}))
""")


def _run(ssp: Path, signals: list[str], step: float, n: int) -> tuple[dict, list[str]]:
    """Run ``ssp`` in OMSimulator: (the samples, the error and warning lines OMSimulator logged)."""
    proc = subprocess.run([sys.executable, "-c", _RUNNER, LIB, str(ssp), repr(step), str(n), *signals],
                          check=False, capture_output=True, text=True, timeout=600, cwd=ssp.parent)
    lines = (proc.stdout + proc.stderr).splitlines()
    data = [json.loads(line) for line in lines if line.startswith('{"t"')]
    assert proc.returncode == 0 and data, f"OMSimulator failed:\n{proc.stdout[-3000:]}\n{proc.stderr[-3000:]}"
    return data[0], [line for line in lines if line.startswith(("error:", "warning:"))]


def omsimulator(ssp: Path, signals: list[str], step: float = STEP, n: int = N) -> tuple[np.ndarray, np.ndarray]:
    """Run ``ssp`` in OMSimulator; (times s, signals as an (n + 1, len(signals)) array), from t = 0. It must
    log no error or warning."""
    data, complaints = _run(ssp, signals, step, n)
    assert not complaints, "OMSimulator complained:\n" + "\n".join(complaints)
    return np.array(data["t"]), np.array(data["values"])


def ours(ssp: Path) -> tuple[np.ndarray, np.ndarray]:
    """Our master on the archive (its own algorithm, Gauss-Seidel), no log: (times s, plant.p)."""
    probe = Probe(P)
    with open_ssp(ssp) as sc:
        run_scenario(sc, log=False, observers=[probe])
    return np.array(probe.t_ns) * 1e-9, np.column_stack([probe.values[s] for s in P])


def _compare(ssp: Path) -> float:
    t_oms, p_oms = omsimulator(ssp, P)
    t_us, p_us = ours(ssp)
    assert len(t_oms) == len(t_us) == N + 1, (len(t_oms), len(t_us))
    assert np.abs(t_oms - t_us).max() < 1e-12, "time grids differ"
    diff = np.abs(p_oms - p_us)
    k = np.unravel_index(np.argmax(diff), diff.shape)
    print(f"{ssp.name}: max |OMSimulator - ours (gauss_seidel)| = {diff.max():.3e} m over {len(t_us)} samples "
          f"(worst at t = {t_us[k[0]]:g} s, {P[k[1]]}); p(1 s) = {p_oms[-1].tolist()}")
    assert diff[0].max() == 0.0, f"start values differ: OMSimulator {p_oms[0]}, ours {p_us[0]}"
    return float(diff.max())


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
