"""No write to freed memory when a process that ran a PythonFMU FMU exits (cosim.fmi.pythonfmu).

PythonFMU's native wrapper keeps a global ``std::shared_ptr<PyState>`` (``(anonymous
namespace)::pyState`` in PySlaveInstance.cpp). In a library still loaded at exit, ``exit``
runs the pointer's static destructor (which frees its control block) before the library's
destructor function resets the pointer, decrementing a count in the freed block: glibc then
aborts with "corrupted double-linked list" or "free(): corrupted unsorted chunks". The
master resets the state itself while the library is loaded: after ``free()`` and at
interpreter exit, before ``exit`` runs those destructors, the pointer must be empty. Checked
by reading the pointer in the loaded library (its address from ``nm``), in a fresh process
whose first PythonFMU library, as in every run, stays loaded to the end.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration
ROOT = Path(__file__).parents[2]

CHILD = textwrap.dedent(r"""
    import atexit, ctypes, json, subprocess, sys

    found = {}

    def pystate(name):
        '''The two words of the library's pyState (object and control block pointers), or None.'''
        base = None
        for line in open("/proc/self/maps"):
            parts = line.split()
            if len(parts) >= 6 and parts[5] == name and int(parts[2], 16) == 0:
                base = int(parts[0].split("-")[0], 16)
                break
        if base is None:  # not loaded (unloaded by dlclose: its destructors ran in order)
            return None
        at = found[name]
        return [ctypes.c_void_p.from_address(base + at + 8 * i).value or 0 for i in range(2)]

    result = {}
    # registered before cosim.fmi is imported, so it runs after its exit handler
    atexit.register(lambda: print(json.dumps({**result, "at_exit": pystate(lib)}), flush=True))

    from cosim.fmi import load_fmu, make_slave

    info = load_fmu(sys.argv[1])

    def started(name):
        s = make_slave(name, info)
        s.bind([info.variables["u"]], [info.variables["y"]])
        s.instantiate()
        s.setup_experiment(0.0, 1.0)
        s.set_start({})
        s.enter_initialization(0.0, 1.0)
        s.exit_initialization()
        s.step(0.0, 0.1)
        s.get_outputs()
        return s

    a = started("a")
    lib = a.fmu.dll._name
    out = subprocess.run(["nm", "-C", lib], capture_output=True, text=True, check=True).stdout
    found[lib] = next(int(l.split()[0], 16) for l in out.splitlines()
                      if l.endswith("(anonymous namespace)::pyState"))
    result["running"] = pystate(lib)
    a.terminate()
    a.free()
    result["freed"] = pystate(lib)
    b = started("b")  # instantiated again and never freed: the exit handler's case
    result["running_again"] = pystate(lib)
""")


@pytest.mark.skipif(not sys.platform.startswith("linux") or shutil.which("nm") is None,
                    reason="reads the loaded library's memory: Linux with binutils' nm")
def test_pythonfmu_state_is_released_before_the_library_destructors_run(test_fmus, tmp_path):
    script = tmp_path / "child.py"
    script.write_text(CHILD)
    r = subprocess.run([sys.executable, str(script), str(test_fmus["CosimTGain"])], capture_output=True,
                       text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    try:
        seen = json.loads(r.stdout.strip().splitlines()[-1])
    except (ValueError, IndexError):
        pytest.fail(f"no report from the child: {r.stdout}{r.stderr}")
    if seen["freed"] is None:
        pytest.skip("the library was unloaded at free (it was not the process's first PythonFMU library)")
    assert all(seen["running"]), f"the probe does not see pythonfmu's state while an instance runs: {seen}"
    assert seen["freed"] == [0, 0], f"state still held after free(): exit would write to freed memory: {seen}"
    assert all(seen["running_again"]), seen
    assert seen["at_exit"] == [0, 0], f"state still held at exit: exit would write to freed memory: {seen}"


FMPY_CHILD = textwrap.dedent(r"""
    import atexit, ctypes, json, subprocess, sys

    import fmpy
    from fmpy.fmi2 import FMU2Slave

    def pystate(name, at):
        for line in open("/proc/self/maps"):
            parts = line.split()
            if len(parts) >= 6 and parts[5] == name and int(parts[2], 16) == 0:
                base = int(parts[0].split("-")[0], 16)
                return [ctypes.c_void_p.from_address(base + at + 8 * i).value or 0 for i in range(2)]
        return None

    result = {}
    # registered before the FMU's code is imported, so it runs after the FMU's own exit handler
    atexit.register(lambda: print(json.dumps({**result, "at_exit": pystate(lib, at)}), flush=True))

    path = sys.argv[1]
    md = fmpy.read_model_description(path)
    unzipped = fmpy.extract(path)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="probe")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    fmu.doStep(0.0, 0.01)
    lib = fmu.dll._name
    out = subprocess.run(["nm", "-C", lib], capture_output=True, text=True, check=True).stdout
    at = next(int(l.split()[0], 16) for l in out.splitlines() if l.endswith("(anonymous namespace)::pyState"))
    result["running"] = pystate(lib, at)
    # not freed: the host leaves it to the end of the process, which our master never does
""")


@pytest.mark.skipif(not sys.platform.startswith("linux") or shutil.which("nm") is None,
                    reason="reads the loaded library's memory: Linux with binutils' nm")
def test_our_fmu_releases_the_state_in_any_python_host(tmp_path):
    """Our FMUs in a host that is not our master (FMPy alone, nothing of cosim imported): the FMU's own
    code (fmus.requirements, run when pythonfmu imports it) resets the state at the host's exit."""
    from fmus import registry

    script = tmp_path / "child.py"
    script.write_text(FMPY_CHILD)
    r = subprocess.run([sys.executable, str(script), str(registry.build("helix"))], capture_output=True,
                       text=True, cwd=tmp_path, timeout=120)
    assert r.returncode == 0, r.stdout + r.stderr
    seen = json.loads(r.stdout.strip().splitlines()[-1])
    assert all(seen["running"]), f"the probe does not see pythonfmu's state while the instance runs: {seen}"
    assert seen["at_exit"] == [0, 0], f"state still held at exit: exit would write to freed memory: {seen}"
