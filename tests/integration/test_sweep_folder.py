"""A sweep's folder (issue 38, items 19, 21 and 22): a table of another sweep with the same columns is refused (its
rows were appended under the other's header), two sweeps into one folder at once are refused (they corrupted
``results.csv``), a ``logs`` that is a file is one line (it was an internal error), and a stalled case's row names
its log."""

from __future__ import annotations

import csv
import shutil
import time
from pathlib import Path

import pytest
from cli_helpers import cosim, start_cosim

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
SCENARIO = """
name: {name}
components:
  src: {{path: "{crash}", parameters: {{mode: 0, at: 0.005, hold: 60}}}}
  g: {{path: "{gain}"}}
connections:
  - {{from: src.y, to: g.u}}
time: {{stop: {stop}, step: 0.001}}
{extra}
"""


def _scenario(folder: Path, test_fmus, name: str, stop: float = 0.01, extra: str = "") -> Path:
    path = folder / f"{name}.yaml"
    path.write_text(SCENARIO.format(name=name, crash=test_fmus["CosimTCrash"], gain=test_fmus["CosimTGain"],
                                    stop=stop, extra=extra))
    return path


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def _one_line(r, *parts: str) -> str:
    assert r.returncode == 2 and "Traceback" not in r.stderr, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and all(p in lines[0] for p in parts), r.stderr
    return lines[0]


def test_a_folder_holding_another_scenarios_sweep_is_refused(tmp_path, test_fmus):
    first, second = _scenario(tmp_path, test_fmus, "first"), _scenario(tmp_path, test_fmus, "second")
    out = tmp_path / "sweep"
    assert cosim("sweep", first, "--grid", "src.at=0.005", "--out", out, "--quiet").returncode == 0
    before = (out / "results.csv").read_bytes()
    _one_line(cosim("sweep", second, "--grid", "src.at=0.006", "--out", out, "--quiet"),
              f"{out / 'results.csv'} holds another sweep (of {first.resolve()}); use another --out")
    assert (out / "results.csv").read_bytes() == before


def test_two_sweeps_into_one_folder_at_once_are_refused(tmp_path, test_fmus):
    slow = _scenario(tmp_path, test_fmus, "slow")
    out = tmp_path / "sweep"
    proc = start_cosim("sweep", slow, "--grid", "src.mode=7", "--out", out, "--quiet")  # a case busy for 60 s
    try:
        deadline = time.monotonic() + 60
        while time.monotonic() < deadline and not (out / ".lock").exists():
            time.sleep(0.05)
        assert (out / ".lock").exists(), "the first sweep never held its folder"
        line = _one_line(cosim("sweep", slow, "--grid", "src.at=0.006", "--out", out, "--quiet"),
                         f"{out}: another command (pid ", "is writing a sweep there")
        assert "sweep" in line
    finally:
        proc.kill()  # SIGKILL: its forked workers must end with it (they held its pipes, communicate() waited)
        proc.communicate(timeout=60)


def test_a_logs_folder_that_is_a_file_is_one_line(tmp_path, test_fmus):
    out = tmp_path / "sweep"
    out.mkdir()
    (out / "logs").write_text("not a folder")
    _one_line(cosim("sweep", _scenario(tmp_path, test_fmus, "s"), "--grid", "src.at=0.005", "--logs", "--out", out,
                    "--quiet"), "logs: is a file, not a folder")


def test_a_stalled_cases_row_names_its_log(tmp_path, test_fmus):
    """The case's FMU busy-loops in Python, its watchdog ends the run as stalled: the row's mcap is the case's log."""
    from cosim.io.runlog import read_run

    stalled = _scenario(tmp_path, test_fmus, "stalled", stop=0.02, extra="watchdog_s: 1.0")
    out = tmp_path / "sweep"
    r = cosim("sweep", stalled, "--grid", "src.mode=7", "--logs", "--out", out, "--quiet", timeout=240)
    assert r.returncode == 1, r.stdout + r.stderr
    (row,) = _rows(out)
    assert row["status"] == "failed" and row["mcap"], row
    assert Path(row["mcap"]).is_file() and Path(row["mcap"]).parent == (out / "logs").resolve(), row
    read_run(row["mcap"])
    shutil.rmtree(out)
