"""File systems that refuse: a cache folder on a read-only file system (a mount the user cannot write, which no
permission bit lets root pass) and a full temporary folder (``TMPDIR`` on a 64 kB file system, where FMUs are built
and extracted): ``cosim run`` and ``fmus build`` end on one line per component naming the folder, the system's
reason and the remedy, exit 2, no traceback (a full TMPDIR was an internal error). The mounts are made in a user and
mount namespace of the test's own (``unshare -rm``), so the test needs no privilege; where the system does not
allow such namespaces it skips."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]


def _mounted(options: str, folder: Path, env: dict[str, str], *argv: str) -> subprocess.CompletedProcess:
    """``argv`` run with a tmpfs mounted at ``folder`` with ``options``, in namespaces of its own."""
    script = f'mount -t tmpfs -o {options} tmpfs "{folder}" && exec "$@"'
    return subprocess.run(["unshare", "-rm", "sh", "-c", script, "sh", *argv], capture_output=True, text=True,
                          env={**os.environ, **env}, cwd=ROOT, timeout=300)


def _read_only(folder: Path, *argv: str) -> subprocess.CompletedProcess:
    """``argv`` run with the cache at ``folder``, a read-only tmpfs."""
    return _mounted("ro", folder, {"DELTA_COSIM_CACHE": str(folder / "cache")}, *argv)


def _full_tmp(folder: Path, cache: Path, *argv: str) -> subprocess.CompletedProcess:
    """``argv`` run with ``TMPDIR`` at ``folder``, a 64 kB tmpfs, and the FMU cache at ``cache``."""
    return _mounted("size=64k", folder, {"TMPDIR": str(folder), "DELTA_COSIM_CACHE": str(cache)}, *argv)


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


@pytest.mark.parametrize("build", ["--native", "--python"])
def test_a_full_temporary_folder_ends_a_build_on_one_line(folder, tmp_path, build):
    got = _full_tmp(folder, tmp_path / "cache", sys.executable, "-m", "cosim", "fmus", "build", "linear_ctc",
                    *([build] if build == "--native" else []), "--force")
    assert got.returncode == 2, (got.returncode, got.stderr)
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1, got.stderr
    assert lines[0].startswith(f"error: cannot build FMU linear_ctc in the temporary folder {folder}/"), lines[0]
    assert "No space left on device" in lines[0] and "TMPDIR" in lines[0], lines[0]


def test_a_full_temporary_folder_ends_a_run_on_one_line_naming_the_fmu(folder, tmp_path):
    cache = tmp_path / "cache"
    env = {**os.environ, "DELTA_COSIM_CACHE": str(cache)}
    warm = subprocess.run([sys.executable, "-m", "cosim", "fmus", "build", "helix", "--native"], capture_output=True,
                          text=True, env=env, cwd=ROOT, timeout=600)
    assert warm.returncode == 0, warm.stderr
    scenario = tmp_path / "one.yaml"
    scenario.write_text("name: one\ncomponents:\n  traj: {fmu: helix}\ntime: {stop: 0.01, step: 0.001}\n")
    got = _full_tmp(folder, cache, sys.executable, "-m", "cosim", "run", str(scenario), "--no-log")
    assert got.returncode == 2, (got.returncode, got.stderr)
    assert "Traceback" not in got.stderr and "internal error" not in got.stderr, got.stderr
    lines = got.stderr.strip().splitlines()
    assert len(lines) == 1 and "helix.fmu: cannot extract it into " + str(folder) in lines[0], got.stderr
    assert "No space left on device" in lines[0] and "TMPDIR" in lines[0], lines[0]
