"""tests/stall_guard.py stops an xdist run in which no test has reported for its bound, naming the last test."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

TESTS = Path(__file__).resolve().parents[1]


def _run(tmp_path, body: str, stall_s: float):
    (tmp_path / "test_subject.py").write_text(body)
    env = {**os.environ, "PYTHONPATH": str(TESTS), "COSIM_TEST_STALL_S": str(stall_s)}
    env.pop("PYTEST_ADDOPTS", None)
    t0 = time.monotonic()
    r = subprocess.run([sys.executable, "-m", "pytest", "-q", "-n", "1", "-p", "stall_guard", "-p", "no:randomly",
                        "-p", "no:cacheprovider", "test_subject.py"], cwd=tmp_path, env=env, capture_output=True,
                       text=True, timeout=120)
    return r, time.monotonic() - t0


def test_a_run_with_no_report_for_the_bound_is_stopped_naming_the_last_test(tmp_path):
    r, wall = _run(tmp_path, "import time\n\ndef test_first():\n    pass\n\ndef test_hangs():\n    time.sleep(60)\n", 3)
    assert r.returncode == 3, (r.returncode, r.stdout, r.stderr)
    assert "suite stalled: no test reported for" in r.stderr and "test_subject.py::test_hangs" in r.stderr, r.stderr
    assert wall < 50, f"{wall:.0f} s to stop a run stalled for 3 s"


def test_a_run_that_reports_is_left_alone(tmp_path):
    """The run lasts longer than the bound (12 x 0.5 s against 5 s) but reports every half second: it is not stopped.
    The worker's start and collection count as progress, so a loaded machine's slow start is no stall (CI saw one)."""
    body = "import time, pytest\n\n@pytest.mark.parametrize('i', range(12))\ndef test_steady(i):\n    time.sleep(0.5)\n"
    r, wall = _run(tmp_path, body, 5)
    assert r.returncode == 0 and "12 passed" in r.stdout, (r.returncode, r.stdout, r.stderr)
    assert wall > 5, f"the run took {wall:.1f} s, not more than the bound: it shows nothing"
