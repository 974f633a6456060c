"""A component that closes every descriptor above 2 of the process it runs in (the master's log pipe, the lock of
its log, the watchdog's pipe), as a careless daemonising library can: the run ends on one line naming the log and
the cause, the log written so far is kept and recoverable, nothing is left behind; without a log the results
stand and the summary says the run was no longer guarded."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from cosim.io.runlog import read_run

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = """
name: closer
components:
  src: {path: "{CosimTCrash}", parameters: {mode: 11, at: 0.05, hold: 60}}
  g: {path: "{CosimTGain}"}
connections:
  - {from: src.y, to: g.u}
time: {stop: 0.2, step: 0.001}
parallel: off
"""


def _run(path: Path, tmp: Path, *extra: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "TMPDIR": str(tmp), "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "cosim", "run", str(path), *extra], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=300)


def test_a_component_closing_the_masters_descriptors_ends_the_logged_run_named(write_scenario, tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    out = tmp_path / "runs" / "closer.mcap"
    out.parent.mkdir()
    got = _run(write_scenario(SCENARIO), tmp, "--out", str(out), "--quiet")
    assert got.returncode == 2, (got.returncode, got.stderr)
    assert "Traceback" not in got.stderr and "internal error" not in got.stderr, got.stderr
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {out}: a component closed the run's own file "
                                                    "descriptors"), got.stderr
    partial = out.with_name(out.name + ".partial")
    assert f"python -m cosim recover {partial}" in lines[0], lines[0]
    assert sorted(p.name for p in out.parent.iterdir()) == [partial.name]  # no lock left
    recovered = tmp_path / "recovered.mcap"
    rec = subprocess.run([sys.executable, "-m", "cosim", "recover", str(partial), "--out", str(recovered)],
                         capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert rec.returncode == 0, rec.stderr
    t = read_run(recovered).signal("g.y").t
    assert len(t) > 0 and t[-1] <= 0.2 + 1e-9, t[-5:]
    assert not list(tmp.glob("cosim-*")), list(tmp.glob("cosim-*"))  # extracted FMUs removed


def test_without_a_log_the_results_stand_and_the_summary_says_the_run_was_unguarded(write_scenario, tmp_path):
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    got = _run(write_scenario(SCENARIO), tmp, "--no-log")
    assert got.returncode == 0, (got.returncode, got.stderr)
    assert "a component closed the master's own file descriptors" in got.stdout + got.stderr, (got.stdout,
                                                                                             got.stderr)
    assert "Traceback" not in got.stderr, got.stderr
    assert not list(tmp.glob("cosim-*")), list(tmp.glob("cosim-*"))
