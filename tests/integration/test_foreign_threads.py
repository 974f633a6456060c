"""Our python FMUs called from threads Python did not start (issue 38, newcomer item 1).

FMI lets a host make every call after ``fmi2Instantiate`` from another thread, one call at a time. OSP libcosim
does: its worker threads step the FMUs. Before ``fmus._names.hold_thread_state`` the Exudyn plants deadlocked
there at their first step (Exudyn's pybind11 callback waited for the GIL that its own thread held), in libcosim
as in any C host that steps from one worker thread. Each check runs in a child process with a time limit, so a
deadlock fails the test with that name instead of hanging the suite:

- a bare C host (``tests/chost/thread_host.c``) steps each Exudyn plant from one worker thread, and from a new
  thread per call, and reads what FMPy's ``FMU2Slave`` reads stepping the same FMU in its own thread;
- OSP libcosim runs the whole helix_ctc system (traj, IK, CTC, the python Exudyn plant) from its exported SSP
  archive as our Jacobi master does.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import textwrap
from pathlib import Path

import numpy as np
import pytest

from cosim.engine.scenario import load_scenario
from cosim.io.ssp.scenario import open_ssp
from cosim.io.ssp.write import export_ssp
from cosim.observers.recorders import Probe
from cosim.run import run_scenario
from fmus import registry

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
HOST_C = ROOT / "tests" / "chost" / "thread_host.c"
PLANTS = ["linear_exudyn_plant", "rotary_exudyn_plant"]
STEPS, H = 40, 1e-3
# The same FMU code with the same inputs in the same order: only the calling thread differs.
SAME_TOL = 0.0
# A run of 0.2 s of the exported helix_ctc in libcosim and in our Jacobi master, as tests/integration/test_ssp.py
# holds for helix_ctc_analytic: the same FMU calls with the same values, equal to rounding.
LIBCOSIM_TOL_M = 1e-9
LIMIT_S = 300  # a deadlock is a wait for ever; the slowest honest child takes about 10 s on the loaded 2 cores


@pytest.fixture(scope="module")
def plants(tmp_path_factory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("plants")
    return {name: registry.build(name, out) for name in PLANTS}


@pytest.fixture(scope="module")
def host(tmp_path_factory) -> Path:
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None:
        pytest.skip("no C compiler for the bare C host")
    exe = tmp_path_factory.mktemp("host") / "thread_host"
    subprocess.run([cc, "-O1", "-Wall", "-Werror", "-o", str(exe), str(HOST_C), "-ldl", "-lpthread"], check=True)
    return exe


def _libpython() -> str:
    path = Path(sysconfig.get_config_var("LIBDIR") or "") / (sysconfig.get_config_var("LDLIBRARY") or "")
    if not sysconfig.get_config_var("Py_ENABLE_SHARED") or not path.is_file():
        pytest.skip(f"this Python has no shared libpython for a C host to load ({path})")
    return str(path)


def _outputs(fmu: Path) -> tuple[str, list[int]]:
    import fmpy

    md = fmpy.read_model_description(str(fmu))
    return md.guid, [v.valueReference for v in md.modelVariables if v.causality == "output" and v.type == "Real"]


def _fmpy(fmu: Path, vrs: list[int], extracted: Path) -> list[float]:
    import fmpy
    from fmpy.fmi2 import FMU2Slave

    md = fmpy.read_model_description(str(fmu))
    slave = FMU2Slave(guid=md.guid, unzipDirectory=str(extracted), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="host")
    slave.instantiate()
    slave.setupExperiment(startTime=0.0)
    slave.enterInitializationMode()
    slave.exitInitializationMode()
    for k in range(STEPS):
        slave.doStep(currentCommunicationPoint=k * H, communicationStepSize=H)
    values = slave.getReal(vrs)
    slave.terminate()
    slave.freeInstance()
    return values


def _child(argv: list[str], what: str, env: dict | None = None) -> str:
    try:
        done = subprocess.run(argv, capture_output=True, text=True, timeout=LIMIT_S, env=env)
    except subprocess.TimeoutExpired:
        pytest.fail(f"{what}: no answer after {LIMIT_S} s (a deadlock)")
    assert done.returncode == 0, f"{what}: exit {done.returncode}: {done.stderr[-2000:]}"
    return done.stdout


@pytest.mark.parametrize("mode", ["worker", "fresh"])
@pytest.mark.parametrize("name", PLANTS)
def test_a_c_host_steps_the_exudyn_plant_from_other_threads(plants, host, tmp_path, name, mode):
    import fmpy

    fmu = plants[name]
    guid, vrs = _outputs(fmu)
    extracted = Path(fmpy.extract(str(fmu), unzipdir=str(tmp_path / "fmu")))
    binary = extracted / "binaries" / "linux64" / f"{name}.so"
    env = {**os.environ, "LD_PRELOAD": _libpython(),
           "PYTHONPATH": os.pathsep.join(p for p in sys.path if p and Path(p).is_dir())}
    out = _child([str(host), mode, str(binary), guid, extracted.joinpath("resources").as_uri(), str(STEPS), str(H),
                  *map(str, vrs)], f"{name} in the C host ({mode} threads)", env)
    got = np.array([float(line) for line in out.split()])
    want = np.array(_fmpy(fmu, vrs, extracted))
    assert got.shape == want.shape and np.all(np.isfinite(got))
    assert np.max(np.abs(got - want)) <= SAME_TOL, f"{name} ({mode}): C host {got} vs FMPy {want}"


_LIBCOSIM = textwrap.dedent("""
    import json, sys
    from libcosimpy.CosimEnums import CosimVariableType
    from libcosimpy.CosimExecution import CosimExecution
    from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
    from libcosimpy.CosimObserver import CosimObserver

    log_output_level(CosimLogLevel.ERROR)
    ssp, n = sys.argv[1], int(sys.argv[2])
    ex = CosimExecution.from_ssp_file(ssp, step_size=1_000_000)
    obs = CosimObserver.create_last_value()
    ex.add_observer(obs)
    plant = ex.slave_index_from_instance_name("plant")
    vr = {v.name.decode(): v.reference for v in ex.slave_variables(plant)}
    refs = [vr["p.x"], vr["p.y"], vr["p.z"]]
    rows = []
    for k in range(1, n + 1):
        assert ex.simulate_until(k * 1_000_000)
        rows.append(list(obs.last_real_values(plant, refs)))
    print(json.dumps(rows))
""")


def test_libcosim_runs_helix_ctc_with_the_python_exudyn_plant(tmp_path):
    """The whole exported system in libcosim's worker threads (it hung at the plant's first step), against our
    Jacobi master on the same archive."""
    stop = 0.2
    archive = tmp_path / "helix_ctc.ssp"
    export_ssp(load_scenario(ROOT / "scenarios" / "helix_ctc.yaml", {("time", "stop"): stop}), archive)
    n = round(stop / 1e-3)
    script = tmp_path / "libcosim_run.py"
    script.write_text(_LIBCOSIM)
    theirs = np.array(json.loads(_child([sys.executable, str(script), str(archive), str(n)],
                                        "helix_ctc in OSP libcosim")))
    names = ["plant.p.x", "plant.p.y", "plant.p.z"]
    probe = Probe(names)
    with open_ssp(archive, {("algorithm",): "jacobi"}) as scenario:
        run_scenario(scenario, log=False, observers=[probe])
    ours = np.column_stack([probe.values[s] for s in names])[1:]  # steps 1..n (libcosim's rows)
    assert theirs.shape == ours.shape == (n, 3)
    diff = np.abs(theirs - ours)
    print(f"helix_ctc, python Exudyn plant: max |libcosim - ours (jacobi)| = {diff.max():.3e} m over {n} steps")
    assert diff.max() <= LIBCOSIM_TOL_M
