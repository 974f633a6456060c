"""What ``--out`` may replace (issue 25): a regular file, never a device, a pipe or the run's own input."""

from __future__ import annotations

import os
import shutil
import stat
from pathlib import Path

import pytest

from cosim.cli import main

ROOT = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.integration


def _run(capsys, *argv) -> tuple[int, str]:
    rc = main([str(a) for a in argv])
    return rc, capsys.readouterr().err


def test_out_never_replaces_a_pipe(tmp_path, capsys):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    rc, err = _run(capsys, "run", ROOT / "scenarios" / "helix_ctc_analytic.yaml", "--stop-time", "0.01", "--out", fifo)
    assert rc == 2 and "is not a regular file" in err and len(err.strip().splitlines()) == 1, err
    assert stat.S_ISFIFO(os.stat(fifo).st_mode), "the pipe was replaced"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["pipe"], "files left behind"


def test_out_never_replaces_the_scenario_it_runs(tmp_path, capsys):
    scenario = tmp_path / "helix.yaml"
    shutil.copy(ROOT / "scenarios" / "helix_ctc_analytic.yaml", scenario)
    text = scenario.read_text()
    rc, err = _run(capsys, "run", scenario, "--stop-time", "0.01", "--out", scenario)
    assert rc == 2 and "own input" in err, err
    assert scenario.read_text() == text, "the scenario was replaced"


def test_json_stays_the_only_thing_on_stdout_when_the_run_prints(capfd, monkeypatch):
    """An FMU that writes to standard output (C printf: file descriptor 1; or Python's print) during the run
    must not break --json (issue 25): its text goes to standard error."""
    import json

    import cosim.run as run_module

    real = run_module.run_scenario

    def noisy(*args, **kwargs):  # what a chatty FMU does from inside the run
        os.write(1, b"FMU says hello on fd 1\n")
        print("FMU says hello through print")
        return real(*args, **kwargs)

    monkeypatch.setattr(run_module, "run_scenario", noisy)
    rc = main(["run", str(ROOT / "scenarios" / "helix_ctc_analytic.yaml"), "--stop-time", "0.01", "--no-log", "--json"])
    out, err = capfd.readouterr()
    assert rc == 0, err
    assert json.loads(out)["status"] == "completed", out
    assert "FMU says hello on fd 1" in err and "FMU says hello through print" in err, err


def test_a_relative_out_stays_where_the_run_started_when_the_working_directory_changes(tmp_path, monkeypatch):
    """An FMU that calls chdir during the run must not move a relative --out (issue 25)."""
    from cosim.engine.execution import Execution

    run_dir, elsewhere = tmp_path / "here", tmp_path / "elsewhere"
    run_dir.mkdir()
    elsewhere.mkdir()
    monkeypatch.chdir(run_dir)
    real = Execution.initialize

    def moving_initialize(ex, *args, **kwargs):  # what such an FMU does while it is instantiated
        os.chdir(elsewhere)
        return real(ex, *args, **kwargs)

    monkeypatch.setattr(Execution, "initialize", moving_initialize)
    rc = main(["run", str(ROOT / "scenarios" / "helix_ctc_analytic.yaml"), "--stop-time", "0.01",
               "--out", "rel.mcap", "--quiet"])
    assert rc == 0
    assert (run_dir / "rel.mcap").exists(), sorted(p.name for p in tmp_path.rglob("*"))
    assert not list(elsewhere.iterdir()), list(elsewhere.iterdir())


def test_no_command_writes_over_its_inputs(tmp_path, capsys):
    """The class, not one command: `ssp export -o` the scenario or one of its FMU files, `recover --out` the log
    it reads, `run --out` an FMU the run loads, each is refused and leaves the file as it was."""
    scenario = tmp_path / "helix.yaml"
    shutil.copy(ROOT / "scenarios" / "helix_ctc_analytic.yaml", scenario)
    text = scenario.read_bytes()
    rc, err = _run(capsys, "ssp", "export", scenario, "-o", scenario)
    assert rc == 2 and "own input" in err, err
    assert scenario.read_bytes() == text
    fmu_file = tmp_path / "traj.fmu"
    from fmus import registry

    shutil.copy(registry.build("helix", tmp_path / "cache"), fmu_file)
    with_path = tmp_path / "with_path.yaml"
    with_path.write_text(text.decode().replace("traj: {fmu: helix}", "traj: {path: traj.fmu}"))
    before = fmu_file.read_bytes()
    for argv in (["ssp", "export", with_path, "-o", fmu_file],
                 ["run", with_path, "--stop-time", "0.01", "--out", fmu_file]):
        rc, err = _run(capsys, *argv)
        assert rc == 2 and "own input" in err, (argv, err)
        assert fmu_file.read_bytes() == before, argv
    log = tmp_path / "run.mcap"
    assert _run(capsys, "run", scenario, "--stop-time", "0.01", "--out", log, "--quiet")[0] == 0
    rc, err = _run(capsys, "recover", log, "--out", log)
    assert rc == 2 and "own input" in err, err
