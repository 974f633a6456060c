"""Runs in threads of one process (the Python API, a threaded Dask worker) and FMUs rebuilt in place.

Each run holds the FMU extractions it uses and removes them at its end unless another running
run still holds them; library loading is serialised and does not move the process's working
directory (fmpy's chdir); a worker forked while another thread holds the extraction lock does not
wait for it. A file rebuilt at the same path is read again and extracted apart from the old build.
"""

from __future__ import annotations

import multiprocessing.context
import os
import shutil
import tempfile
import threading
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from cosim.fmi import extract
from cosim.fmi import Extractions, load_fmu
from cosim.run import run_scenario
from cosim.engine.scenario import load_scenario

pytestmark = pytest.mark.integration

# a feedback loop behind a source: with parallel on, src and ref run ahead in the offload worker
LOOP = """
name: loop
components:
  src: {path: "{CosimTSource}"}
  ref: {path: "{CosimTSum}"}
  sum: {path: "{CosimTSum}"}
  ctl: {path: "{CosimTGain}", parameters: {k: -5.0}}
  plant: {path: "{CosimTIntegrator}", parameters: {x0: 0.5}}
connections:
  - {from: src.y, to: ref.a}
  - {from: ref.y, to: sum.a}
  - {from: ctl.y, to: sum.b}
  - {from: sum.y, to: plant.u}
  - {from: plant.x, to: ctl.u}
time: {stop: 0.5, step: 0.001}
parallel: "off"
watchdog_s: 20
compare: {actual: [plant.x], reference: [src.y]}
"""


def _extractions() -> set[str]:
    return {p.name for p in Path(tempfile.gettempdir()).glob(f"cosim-fmu-{os.getpid()}-*")}


def _rebuild(path: Path, source: Path) -> None:
    """``path`` replaced by another FMU, as a build in place does, with a later mtime whatever the clock."""
    shutil.copy(source, path)
    st = path.stat()
    os.utime(path, ns=(st.st_atime_ns, st.st_mtime_ns + 1_000_000_000))


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
    assert os.getcwd() == cwd  # as it was (test_the_working_directory_stays_while_libraries_load looks closer)
    assert _extractions() == before  # every run removed what it extracted, none removed another's early


def test_an_fmu_rebuilt_in_place_is_read_again(test_fmus, tmp_path):
    path = tmp_path / "component.fmu"
    shutil.copy(test_fmus["CosimTGain"], path)
    assert "k" in load_fmu(path).variables
    _rebuild(path, test_fmus["CosimTSource"])
    rebuilt = load_fmu(path)
    assert "k" not in rebuilt.variables and rebuilt.md.modelName == "CosimTSource"


def test_the_working_directory_stays_while_libraries_load(write_scenario):
    """Another thread sees the process's working directory unchanged while runs load their FMUs."""
    path = write_scenario(LOOP)
    cwd, seen, done = os.getcwd(), set(), threading.Event()

    def watch() -> None:
        while not done.is_set():
            seen.add(os.getcwd())

    watcher = threading.Thread(target=watch)
    watcher.start()
    try:
        for _ in range(5):  # each run extracts afresh (the last one removed its own) and loads from there
            _fingerprint(path, 0.01)
    finally:
        done.set()
        watcher.join()
    assert seen == {cwd}


def test_a_worker_forked_while_another_thread_holds_the_lock_runs(write_scenario, monkeypatch):
    """The offload worker is forked while another thread holds the extraction lock (as a run extracting
    a large FMU does): the child must not inherit a lock held by a thread it does not have."""
    path = write_scenario(LOOP.replace('parallel: "off"', 'parallel: "on"'))
    grabbed, release = threading.Event(), threading.Event()

    def hold() -> None:
        with extract._LOCK:
            grabbed.set()
            release.wait(10)

    fork = multiprocessing.context.ForkProcess._Popen

    def popen(process):  # noqa: ANN001, ANN202
        threading.Thread(target=hold).start()
        grabbed.wait(10)
        try:
            return fork(process)
        finally:
            threading.Timer(0.5, release.set).start()

    monkeypatch.setattr(multiprocessing.context.ForkProcess, "_Popen", staticmethod(popen))
    res = run_scenario(load_scenario(path), log=False)
    assert grabbed.is_set(), "the worker was not forked (nothing offloaded?)"
    assert res.steps == 500 and res.worker_time, res


def test_an_fmu_rebuilt_while_a_run_holds_it_is_extracted_apart(test_fmus, tmp_path):
    """A run still holds the old build's extraction; a new run gets the new build's files, not the old."""
    path = tmp_path / "component.fmu"
    shutil.copy(test_fmus["CosimTGain"], path)
    with Extractions() as held:
        old = load_fmu(path).unzipdir
        _rebuild(path, test_fmus["CosimTSource"])
        with Extractions() as other:
            new = load_fmu(path).unzipdir
            assert new != old and (new / "modelDescription.xml").read_text() != (old / "modelDescription.xml").read_text()
            assert "CosimTSource" in (new / "modelDescription.xml").read_text()
            other.release()
        assert old.is_dir() and not new.exists()  # each build removed by its own holder
        held.release()
    assert not old.exists()
