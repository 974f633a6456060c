"""The embedded sweep's pool of forked workers (cosim.analysis.cluster.ForkPool, issue 36): its FMUs extracted once
and removed at the end, a worker killed mid-sweep fails only what it had not returned (the same call again runs
it), each case's values those of a run in this process. Short runs keep it fast."""

from __future__ import annotations

import os
import signal
import tempfile
from pathlib import Path

import pytest

from cosim.analysis.cases import Case
from cosim.analysis.cluster import ForkPool, can_fork
from cosim.analysis.sweep import _run_case, prebuild, read_results, run_sweep
from cosim.engine.overrides import dotted_overrides
from cosim.engine.scenario import read_scenario

pytestmark = [pytest.mark.integration,
              pytest.mark.skipif(not can_fork(), reason="the embedded pool forks (POSIX); elsewhere it is Dask's")]
ROOT = Path(__file__).parents[2]
SCENARIO = str(ROOT / "scenarios" / "helix_ctc_analytic.yaml")


def _extractions() -> set[str]:
    """This process's FMU extraction directories in the temporary folder."""
    return {p.name for p in Path(tempfile.gettempdir()).glob(f"cosim-fmu-{os.getpid()}-*")}


def test_pool_cases_equal_runs_here_and_leave_no_extraction(tmp_path):
    cases = [Case({"time.stop": 0.05, "ctl.gain.kp[1]": kp}) for kp in (1e4, 2e4, 3e4)]
    before = _extractions()
    summary = run_sweep(SCENARIO, cases, tmp_path / "out", workers=2)
    assert summary.ok and summary.workers == "2 local worker processes", summary.text()
    assert _extractions() == before, f"left behind: {sorted(_extractions() - before)}"
    rows = {r["case"]: r for r in read_results(tmp_path / "out")}
    source = read_scenario(SCENARIO)
    fmu_files = prebuild([source.load(dotted_overrides(cases[0].values))])
    for c in cases:  # the same case run in this process, unsupervised: every metric digit for digit
        here = _run_case(source.load(dotted_overrides(c.values, "sweep case")), fmu_files, None)
        for k in ("rmse_x", "rmse_y", "rmse_z", "max_error_x", "peak_effort", "steps"):
            assert float(rows[c.id][k]) == float(here[k]), (c.values, k, rows[c.id][k], here[k])
    assert _extractions() == before, f"left behind: {sorted(_extractions() - before)}"


@pytest.fixture
def pools(monkeypatch):
    """The sweep's pools, as they are made (a test kills their workers)."""
    made: list[ForkPool] = []
    original = ForkPool.__init__

    def init(self, workers):  # noqa: ANN001
        original(self, workers)
        made.append(self)

    monkeypatch.setattr(ForkPool, "__init__", init)
    return made


def test_every_pool_worker_killed_mid_sweep_fails_what_they_had_not_returned(tmp_path, pools):
    """SIGKILL to every worker after the first row: the sweep returns (no hang), the cases not returned are ``lost``
    naming why, and the same call again runs exactly those."""
    cases = [Case({"time.stop": 0.3, "ctl.gain.kp[1]": 1e4 + 1e3 * k}) for k in range(8)]
    killed: list[int] = []

    def kill_all(done: int, failed: int, total: int) -> None:  # noqa: ARG001
        if done >= 1 and not killed:
            for pid in pools[0].pids():
                killed.append(pid)
                os.kill(pid, signal.SIGKILL)

    out = tmp_path / "out"
    first = run_sweep(SCENARIO, cases, out, workers=2, on_progress=kill_all)
    assert killed, "no worker to kill"
    rows = read_results(out)
    assert len(rows) == len(cases), f"{len(rows)} rows for {len(cases)} cases"
    lost = [r for r in rows if r["status"] == "lost"]
    assert lost and all("WorkerLost" in r["message"] and ("killed by SIGKILL" in r["message"] or
                                                          "every sweep worker has ended" in r["message"])
                        for r in lost), [(r["status"], r["message"]) for r in rows]
    assert not first.ok and len(first.failed) == len(lost), first.text()
    again = run_sweep(SCENARIO, cases, out, workers=2)
    assert (again.ran, again.skipped) == (len(lost), len(cases) - len(lost)), again.text()
    done = {r["case"]: r["status"] for r in read_results(out)}
    assert all(done[c.id] == "ok" for c in cases), done


def test_one_pool_worker_killed_loses_only_its_case(tmp_path, pools):
    """SIGKILL to a worker running a case: that case alone is ``lost`` (naming the worker and the signal), the other
    worker runs every other case (a standard library pool broke whole: every case not returned was lost)."""
    cases = [Case({"time.stop": 0.3, "ctl.gain.kp[1]": 1e4 + 1e3 * k}) for k in range(8)]
    killed: list[int] = []

    def kill_one(done: int, failed: int, total: int) -> None:  # noqa: ARG001
        if done >= 1 and not killed:
            busy = [w for w in pools[0]._workers if w.running is not None]
            if busy:
                killed.append(busy[0].child.pid)
                os.kill(busy[0].child.pid, signal.SIGKILL)

    out = tmp_path / "out"
    run_sweep(SCENARIO, cases, out, workers=2, on_progress=kill_one)
    assert killed, "no busy worker to kill"
    rows = read_results(out)
    assert len(rows) == len(cases), f"{len(rows)} rows for {len(cases)} cases"
    lost = [r for r in rows if r["status"] == "lost"]
    assert len(lost) <= 1 and all(r["status"] in ("ok", "lost") for r in rows), [(r["status"], r["message"]) for r in rows]
    assert all(f"(pid {killed[0]}) ended before it returned the case (killed by SIGKILL)" in r["message"]
               for r in lost), lost


def test_a_case_takes_the_libraries_loaded_ahead_and_gives_the_same_values():
    """extract_for_cases loads each of our native FMUs' libraries once (cosim.fmi.slave.preload); a run takes them
    instead of loading its own, with the values of a run that loads its own, and drop_preloaded lets go of the rest."""
    from cosim.analysis.sweep import drop_preloaded, extract_for_cases
    from cosim.fmi import Extractions
    from cosim.fmi import slave

    source = read_scenario(SCENARIO)
    sc = source.load(dotted_overrides({"time.stop": 0.05, "fmus": "native"}, "sweep case"))
    fmu_files = prebuild([sc])
    fresh = _run_case(sc, fmu_files, None)
    assert fresh["status"] == "ok", fresh["message"]
    held = Extractions()
    try:
        extract_for_cases(held, sc, fmu_files)
        loaded = {key[1].rsplit("/", 1)[-1]: len(objs) for key, objs in slave._PRELOADED.items()}
        assert sorted(loaded.values()) == [1] * len(sc.components), f"one loaded library per component: {loaded}"
        taken = _run_case(sc, fmu_files, None)
        assert all(not objs for objs in slave._PRELOADED.values()), "the run did not take every loaded library"
    finally:
        held.release()
        drop_preloaded()
    assert not slave._PRELOADED, "drop_preloaded kept some"
    for k in ("rmse_x", "rmse_y", "rmse_z", "max_error_x", "peak_effort", "steps"):
        assert taken[k] == fresh[k], (k, taken[k], fresh[k])


INTERRUPTED = """
import os, signal, sys, threading, time
from cosim.analysis.cases import Case
from cosim.analysis.sweep import run_sweep
signal.signal(signal.SIGINT, signal.default_int_handler)  # a shell's background job starts with SIGINT ignored
cases = [Case({"time.stop": 2.0, "ctl.gain.kp[1]": 1e4 + 1e3 * k}) for k in range(12)]
first = []

def progress(done, failed, total):
    if done >= 1 and not first:  # after the first row: Ctrl-C, as a terminal sends it to the sweep's process
        first.append(time.monotonic())
        threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()

try:
    run_sweep(sys.argv[1], cases, sys.argv[2], workers=2, on_progress=progress)
except KeyboardInterrupt:
    print(f"interrupted after {time.monotonic() - first[0]:.2f} s", flush=True)
    sys.exit(130)
print("not interrupted", flush=True)
"""


def test_ctrl_c_stops_the_pool_sweep_and_leaves_no_worker(tmp_path):
    """Ctrl-C after the first row: the sweep's process raises KeyboardInterrupt (the cases not started cancelled, the
    running ones let finish unwritten), its pool's workers end with it, and the table holds only whole rows of the
    cases that finished; the same sweep again runs the rest."""
    import subprocess
    import sys

    script = tmp_path / "interrupted.py"
    script.write_text(INTERRUPTED)
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, str(script), SCENARIO, str(out)], capture_output=True, text=True,
                          timeout=120, env=env, cwd=ROOT)
    assert proc.returncode == 130 and "interrupted after" in proc.stdout, (proc.returncode, proc.stdout, proc.stderr)
    took = float(proc.stdout.split("interrupted after ")[1].split()[0])
    assert took < ForkPool.CLOSE_WAIT_S / 2, f"{took} s from Ctrl-C to the end: the workers were waited out, not ended"
    rows = read_results(out)
    assert 1 <= len(rows) < 12 and all(r["status"] == "ok" for r in rows), [(r["case"], r["status"]) for r in rows]
    orphans = subprocess.run(["pgrep", "-f", str(script)], capture_output=True, text=True).stdout.split()
    assert not orphans, f"processes of the interrupted sweep left: {orphans}"
    cases = [Case({"time.stop": 2.0, "ctl.gain.kp[1]": 1e4 + 1e3 * k}) for k in range(12)]
    again = run_sweep(SCENARIO, cases, out, workers=2)
    assert again.ok and (again.ran, again.skipped) == (12 - len(rows), len(rows)), again.text()
