"""The suite's fork server (tests/forkserver.py) runs a command as a new interpreter does: the same output, exit
status, environment, working folder, command line and temporary folder, a signal's death and a timeout reported
as :mod:`subprocess` reports them. The comparisons are against ``python -m cosim`` started by :mod:`subprocess`."""

from __future__ import annotations

import os
import subprocess

import pytest
from cli_helpers import ROOT, _command, cosim

pytestmark = pytest.mark.integration

SCENARIO = ROOT / "scenarios" / "helix_ctc_analytic.yaml"


def _fresh(*args):
    """The command in a new interpreter, as ``cli_helpers.cosim`` runs one that is not forked."""
    return subprocess.run(_command(args), cwd=ROOT, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args", [
    ("--version",),
    ("check", SCENARIO),
    ("check", "no_such.yaml"),
    ("run", SCENARIO, "--no-log", "--stop-time", "0.005", "--set", "ctl.gain.kp=5e4"),
    ("run", SCENARIO, "--no-log", "--stop-time", "0.005", "--json"),
    ("table", "--bogus"),
], ids=["version", "check", "missing", "set-error", "json", "usage"])
def test_a_forked_command_says_and_exits_what_a_new_interpreter_does(args):
    forked, fresh = cosim(*args), _fresh(*args)
    assert forked.returncode == fresh.returncode, (forked.returncode, fresh.returncode, forked.stderr, fresh.stderr)
    assert forked.stderr == fresh.stderr, (forked.stderr, fresh.stderr)
    if "--json" in args:  # wall-clock figures differ from run to run
        import json

        a, b = json.loads(forked.stdout), json.loads(fresh.stdout)
        assert a.keys() == b.keys() and a["errors"] == b["errors"] and a["status"] == b["status"], (a, b)
    elif args[0] != "run":
        assert forked.stdout == fresh.stdout, (forked.stdout, fresh.stdout)


def test_environment_folder_command_line_and_temporary_folder_are_the_commands(tmp_path):
    """A run from another folder, with TMPDIR of its own: its log lands relative to that folder, records the
    command line it was given (sys.orig_argv), and the extraction folders it made in TMPDIR are gone."""
    from cosim.io.runlog import read_run

    tmp = tmp_path / "tmp"
    tmp.mkdir()
    work = tmp_path / "work"
    work.mkdir()
    r = cosim("run", SCENARIO, "--stop-time", "0.005", "--out", "here.mcap", "--quiet", cwd=work,
              env={**os.environ, "TMPDIR": str(tmp)})
    assert r.returncode == 0, r.stderr
    log = read_run(work / "here.mcap")
    import json

    argv = json.loads(log.metadata["command"]["argv"])
    assert argv[-6:] == [str(SCENARIO), "--stop-time", "0.005", "--out", "here.mcap", "--quiet"], argv
    assert argv[1:3] == ["-m", "cosim"], argv
    assert not any(tmp.iterdir()), sorted(p.name for p in tmp.iterdir())


def test_a_timeout_kills_the_command_and_raises_as_subprocess_does():
    with pytest.raises(subprocess.TimeoutExpired):
        cosim("run", SCENARIO, "--no-log", "--realtime", "--stop-time", "30", timeout=2)
    r = cosim("--version")  # the server serves the next command
    assert r.returncode == 0, r.stderr


def test_a_startup_variable_starts_a_new_interpreter():
    """LC_ALL and PYTHON* are read when an interpreter starts: with one of them changed the command is not forked
    (its stdout encoding is the new interpreter's: ASCII here)."""
    from cli_helpers import _forkable

    env = {**os.environ, "PYTHONIOENCODING": "ascii"}
    assert not _forkable(env) and _forkable(dict(os.environ)) and _forkable(None)
    assert not _forkable({**os.environ, "LC_ALL": "C" if os.environ.get("LC_ALL") != "C" else "POSIX"})
    r = cosim("--version", env=env)
    assert r.returncode == 0, r.stderr
