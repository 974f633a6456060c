"""Paths and names survive any locale (issue 38, item 20): under ``LC_ALL=C`` with Python's UTF-8 mode off a
non-ASCII file name reaches Python as surrogate escapes of its bytes (the log's metadata refused them: an internal
error, the lock left behind), and on an ASCII stdout a completed run's summary could not be printed (exit 2 after
the work was done). Each command here ends as it does under a UTF-8 locale, its outputs named as given."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from cli_helpers import cosim

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
ANALYTIC = str(ROOT / "scenarios" / "helix_ctc_analytic.yaml")
LOCALES = {
    "C locale, UTF-8 mode off": {"LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONIOENCODING": ""},
    "ASCII stdout": {"PYTHONIOENCODING": "ascii"},
    "both": {"LC_ALL": "C", "PYTHONUTF8": "0", "PYTHONIOENCODING": "ascii"},
}


@pytest.mark.parametrize("locale", list(LOCALES))
def test_a_non_ascii_path_runs_and_reads_back_under_any_locale(tmp_path, locale):
    env = {**os.environ, **LOCALES[locale]}
    folder = tmp_path / "mesures_été"
    log = folder / "délta.mcap"
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.02", "--out", str(log), env=env)
    assert r.returncode == 0 and "internal error" not in r.stderr, (r.returncode, r.stderr)
    assert "log: " in r.stdout, r.stdout  # the summary printed (escaped where the stream cannot carry it)
    assert sorted(p.name for p in folder.iterdir()) == ["délta.mcap"], "a lock or partial file was left"
    for command in (("table", str(log)), ("report", str(log)), ("run", "--from-log", str(log), "--stop-time", "0.01",
                                                                 "--out", str(folder / "à_nouveau.mcap"))):
        r = cosim(*command, env=env)
        assert r.returncode == 0 and "internal error" not in r.stderr, (command[0], r.returncode, r.stderr)
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.02", "--out", str(log), "--json", env=env)
    assert r.returncode == 0, r.stderr
