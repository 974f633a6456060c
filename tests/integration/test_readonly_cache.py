"""A cache folder on a read-only file system (a mount the user cannot write, which no permission bit lets root
pass): ``cosim run`` and ``fmus build`` end on one line per component naming the folder, the system's reason and
the remedy, exit 2, no traceback. The read-only mount is made in a user and mount namespace of the test's own
(``unshare -rm``), so the test needs no privilege; where the system does not allow such namespaces it skips."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]


def _read_only(folder: Path, *argv: str) -> subprocess.CompletedProcess:
    """``argv`` run with the cache at ``folder``, a read-only tmpfs mounted there in namespaces of its own."""
    script = f'mount -t tmpfs -o ro tmpfs "{folder}" && exec "$@"'
    env = {**os.environ, "DELTA_COSIM_CACHE": str(folder / "cache")}
    return subprocess.run(["unshare", "-rm", "sh", "-c", script, "sh", *argv], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=300)


@pytest.fixture
def folder(tmp_path) -> Path:
    if shutil.which("unshare") is None:
        pytest.skip("no unshare(1) on this system")
    folder = tmp_path / "ro"
    folder.mkdir()
    probe = _read_only(folder, "sh", "-c", f'touch "{folder}/x"')
    if "Read-only file system" not in probe.stderr:
        pytest.skip(f"no read-only mount in a user namespace here: {probe.stderr.strip()[:200]}")
    return folder


def test_a_read_only_cache_is_one_line_per_component_naming_it(folder):
    got = _read_only(folder, sys.executable, "-m", "cosim", "run", "scenarios/helix_ctc_analytic.yaml", "--no-log",
                     "--stop-time", "0.01")
    assert got.returncode == 2, (got.returncode, got.stderr)
    assert "Traceback" not in got.stderr and "internal error" not in got.stderr, got.stderr
    lines = got.stderr.strip().splitlines()
    assert lines[0] == "error:", got.stderr
    assert len(lines) == 5, got.stderr  # traj, ik, ctl, plant
    for line, component in zip(lines[1:], ["traj", "ik", "ctl", "plant"]):
        assert f"components.{component}: cannot use {folder}/cache/" in line, line
        assert "Read-only file system" in line and "DELTA_COSIM_CACHE=FOLDER" in line, line


def test_fmus_build_into_a_read_only_cache_is_one_line(folder):
    got = _read_only(folder, sys.executable, "-m", "cosim", "fmus", "build", "linear_ctc", "--native")
    assert got.returncode == 2, (got.returncode, got.stderr)
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: cannot use {folder}/cache/"), got.stderr
    assert "Read-only file system" in lines[0] and "--out" in lines[0], got.stderr
