"""Portable FMUs: each FMU records what its host Python must provide (resources/requirements.json)
and, when instantiated by another tool (fmpy here), fails through the FMI logger with one message
naming what is missing."""

from __future__ import annotations

import json
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

from fmus import registry
from fmus.requirements import FILE, project_requirements

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
# one FMU of each kind of dependency set: numpy only (FMI 2 CS and FMI 3 ME; the analytic plant too, since
# it integrates with delta.dynamics' own RK4 instead of SciPy's DOP853), numpy + exudyn
NAMES = ["helix", "linear_analytic_plant", "linear_exudyn_plant", "linear_analytic_plant_me"]
EXPECTED = {"helix": {"numpy", "casadi"}, "linear_analytic_plant": {"numpy", "casadi"},  # casadi: the traced step
            "linear_exudyn_plant": {"numpy", "exudyn"}, "linear_analytic_plant_me": {"numpy", "casadi"}}

# Instantiate an FMU with fmpy in a fresh interpreter (as a host tool would: the FMU's module is
# imported for the first time) and print whether it worked and what reached the FMI logger.
_INSTANTIATE = r"""
import json, sys
import fmpy
path = sys.argv[1]
for hidden in sys.argv[2:]:  # as if not installed: importing it raises ModuleNotFoundError
    sys.modules[hidden] = None
md = fmpy.read_model_description(path)
messages = []
unzipped = fmpy.extract(path)
if md.fmiVersion.startswith("2"):
    from fmpy.fmi2 import (FMU2Slave, calloc, free, fmi2CallbackAllocateMemoryTYPE, fmi2CallbackFreeMemoryTYPE,
                           fmi2CallbackFunctions, fmi2CallbackLoggerTYPE)
    def logger(env, name, status, category, message):
        messages.append({"status": status, "message": message.decode() if message else ""})
    cb = fmi2CallbackFunctions()
    cb.logger = fmi2CallbackLoggerTYPE(logger)
    cb.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    cb.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="probe")
    kwargs = {"callbacks": cb, "loggingOn": True}
else:
    from fmpy.fmi3 import FMU3Model
    def logger(env, status, category, message):
        messages.append({"status": status, "message": message.decode() if message else ""})
    fmu = FMU3Model(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.modelExchange.modelIdentifier,
                    instanceName="probe")
    kwargs = {"logMessage": logger, "loggingOn": True}
try:
    fmu.instantiate(**kwargs)
    ok = True
    fmu.terminate()
    fmu.freeInstance()
except Exception:
    ok = False
print(json.dumps({"instantiated": ok, "messages": messages, "python": sys.executable}))
"""


def _instantiate(path: Path, *hide: str) -> dict:
    res = subprocess.run([sys.executable, "-c", _INSTANTIATE, str(path), *hide], capture_output=True, text=True,
                         cwd=ROOT, timeout=120)
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout.strip().splitlines()[-1])


def _record(path: Path) -> dict:
    with zipfile.ZipFile(path) as z:
        return json.loads(z.read(f"resources/{FILE}"))


def _with_record(src: Path, dst: Path, record: dict) -> Path:
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == f"resources/{FILE}":
                data = json.dumps(record).encode()
            zout.writestr(item, data)
    return dst


@pytest.mark.parametrize("name", NAMES)
def test_fmu_records_python_and_packages_with_versions(name):
    rec = _record(registry.build(name))
    python, specs = project_requirements(ROOT)
    assert rec["python"] == python == ">=3.11", rec
    got = {p["distribution"]: p for p in rec["packages"]}
    assert set(got) == EXPECTED[name], f"{name}: records {sorted(got)}, imports {sorted(EXPECTED[name])}"
    for dist, p in got.items():
        assert p["specifier"] == specs[dist] and p["built_with"], f"{name}: {p} (pyproject: {specs[dist]})"
    assert not {"pythonfmu", "pythonfmu3"} & set(got), "the exporter ships inside the FMU: not a host requirement"


@pytest.mark.parametrize("name", ["helix", "linear_analytic_plant_me"])
def test_missing_package_fails_instantiation_with_one_logged_message(name, tmp_path):
    good = registry.build(name)
    rec = _record(good)
    ok = _instantiate(good)
    assert ok["instantiated"], f"{name}: the FMU as built should instantiate: {ok['messages']}"
    bad_rec = {**rec, "packages": rec["packages"] + [
        {"module": "no_such_package_xyz", "distribution": "no-such-package-xyz", "specifier": ">=1.0"}]}
    res = _instantiate(_with_record(good, tmp_path / f"{name}.fmu", bad_rec))
    print(res["messages"])
    assert not res["instantiated"], f"{name}: instantiated although a package is missing"
    expected = f"FMU {name} needs no-such-package-xyz>=1.0, not installed in {res['python']}"
    hits = [m for m in res["messages"] if expected in m["message"]]
    assert len(hits) == 1, f"expected one logged message containing {expected!r}, got {res['messages']}"


def test_every_unmet_requirement_is_named_in_the_one_message(tmp_path):
    good = registry.build("helix")
    rec = _record(good)
    numpy_rec = next(p for p in rec["packages"] if p["module"] == "numpy")
    bad_rec = {**rec, "python": ">=99", "packages": [
        {**numpy_rec, "specifier": ">=999"},  # numpy, too old for this requirement
        {"module": "no_such_package_xyz", "distribution": "no-such-package-xyz", "specifier": ""}]}
    res = _instantiate(_with_record(good, tmp_path / "helix.fmu", bad_rec))
    assert not res["instantiated"]
    text = [m["message"] for m in res["messages"] if "FMU helix needs" in m["message"]]
    assert len(text) == 1, res["messages"]
    import numpy

    for part in (f"needs Python >=99, not {'.'.join(map(str, sys.version_info[:3]))}",
                 f"needs numpy>=999, found {numpy.__version__} in {res['python']}",
                 f"needs no-such-package-xyz, not installed in {res['python']}"):
        assert part in text[0], f"{part!r} not in {text[0]!r}"


def test_exudyn_plant_as_built_names_exudyn_when_the_host_lacks_it():
    """The unmodified FMU in a host without exudyn: the message names it (not an ImportError deep inside)."""
    res = _instantiate(registry.build("linear_exudyn_plant"), "exudyn")
    assert not res["instantiated"]
    expected = f"FMU linear_exudyn_plant needs exudyn>=1.9, not installed in {res['python']}"
    assert [m["message"] for m in res["messages"] if expected in m["message"]], res["messages"]
