"""Runs in threads of one process (the Python API, a threaded Dask worker) and FMUs rebuilt in place.

Each run holds the FMU extractions it uses and removes them at its end unless another running
run still holds them; library loading (where fmpy changes the working directory) is serialised.
A file rebuilt at the same path is read again, not served from the description cache.
"""

from __future__ import annotations

import os
import shutil
import tempfile
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from cosim.fmu import load_fmu
from cosim.run import run_scenario
from cosim.scenario import load_scenario

pytestmark = pytest.mark.integration

LOOP = """
name: loop
components:
  src: {path: "{CosimTSource}"}
  ctl: {path: "{CosimTGain}", parameters: {k: -5.0}}
  plant: {path: "{CosimTIntegrator}", parameters: {x0: 0.5}}
connections:
  - {from: src.y, to: ctl.u}
  - {from: ctl.y, to: plant.u}
time: {stop: 0.5, step: 0.001}
parallel: "off"
compare: {actual: [plant.x], reference: [src.y]}
"""


def _extractions() -> set[str]:
    return {p.name for p in Path(tempfile.gettempdir()).glob(f"cosim-fmu-{os.getpid()}-*")}


def _fingerprint(path: Path, stop: float) -> tuple:
    res = run_scenario(load_scenario(path, {("time", "stop"): stop}), log=False)
    return res.steps, [(e.rmse, e.max_error) for e in res.errors]


def test_runs_in_threads_give_their_serial_results_and_leave_no_extraction(write_scenario):
    path = write_scenario(LOOP)
    stops = [0.2, 0.5, 0.3, 0.5, 0.1, 0.4]
    serial = {s: _fingerprint(path, s) for s in set(stops)}
    before, cwd = _extractions(), os.getcwd()
    with ThreadPoolExecutor(2) as pool:
        threaded = list(pool.map(lambda s: _fingerprint(path, s), stops))
    assert threaded == [serial[s] for s in stops]
    assert os.getcwd() == cwd  # fmpy's chdir around each library load did not leak
    assert _extractions() == before  # every run removed what it extracted, none removed another's early


def test_an_fmu_rebuilt_in_place_is_read_again(test_fmus, tmp_path):
    fmu = tmp_path / "component.fmu"
    shutil.copy(test_fmus["CosimTGain"], fmu)
    assert "k" in load_fmu(fmu).variables
    shutil.copy(test_fmus["CosimTSource"], fmu)
    st = fmu.stat()
    os.utime(fmu, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))  # a later build, whatever the clock
    rebuilt = load_fmu(fmu)
    assert "k" not in rebuilt.variables and rebuilt.md.modelName == "CosimTSource"
