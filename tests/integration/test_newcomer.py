"""What a newcomer meets first (issue 38): commands whose defaults work, results that say what they checked."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from cli_helpers import cosim

pytestmark = pytest.mark.integration

ROOT = Path(__file__).resolve().parents[2]
ANALYTIC = str(ROOT / "scenarios" / "helix_ctc_analytic.yaml")


@pytest.fixture(scope="module")
def first_log(tmp_path_factory) -> Path:
    """A run whose log is where its scenario's default would put a rerun: runs/<name>.mcap of the folder it ran in."""
    d = tmp_path_factory.mktemp("newcomer")
    (d / "runs").mkdir()
    log = d / "runs" / "helix_ctc_analytic.mcap"
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.05", "--out", str(log), "--quiet", cwd=d)
    assert r.returncode == 0, r.stderr
    return log


def test_run_from_log_writes_beside_the_log_by_default(first_log):
    before = first_log.read_bytes()
    r = cosim("run", "--from-log", str(first_log), "--quiet", cwd=first_log.parent.parent)
    assert r.returncode == 0, f"exit {r.returncode}: {r.stderr}"
    again = first_log.with_name("helix_ctc_analytic.rerun.mcap")
    assert again.is_file(), f"no {again}: {sorted(p.name for p in first_log.parent.iterdir())}"
    assert first_log.read_bytes() == before, "the first log was replaced"


def test_compare_checked_only_with_nothing_checked_is_an_error(first_log):
    r = cosim("compare", str(first_log), str(first_log), "--checked-only")
    assert r.returncode == 2, f"exit {r.returncode}, expected 2: {r.stdout}{r.stderr}"
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "nothing was checked" in lines[0], r.stderr
    r = cosim("compare", str(first_log), str(first_log))
    assert r.returncode == 0, r.stderr
    assert "nothing checked: no signal has a tolerance" in r.stdout, r.stdout
    assert "ok: 0 signals" not in r.stdout, r.stdout
    r = cosim("compare", str(first_log), str(first_log), "--checked-only", "--tol", "plant=1e-12")
    assert r.returncode == 0 and "signals checked against a tolerance" in r.stdout, r.stdout + r.stderr


@pytest.mark.parametrize("group, commands", [("fmus", ["build", "list", "info"]),
                                             ("robot", ["presets", "ik", "fk", "workspace", "singularity"]),
                                             ("ssp", ["export"])])
def test_a_command_groups_help_lists_every_command(group, commands):
    r = cosim(group, "--help")
    assert r.returncode == 0, r.stderr
    listed = [ln.split()[0] for ln in r.stdout.splitlines() if ln.startswith("    ") and ln.split()]
    assert all(c in listed for c in commands), f"{group} --help lists {listed}, expected {commands}"
    r = cosim(group)
    assert r.returncode == 2 and "COMMAND" in r.stderr, f"exit {r.returncode}: {r.stderr}"


def test_a_vector_parameter_set_as_one_value_says_how_to_set_it(tmp_path):
    r = cosim("check", ANALYTIC, "--set", "fmus=native", "--set", "ctl.gain.kp=5e4")
    assert r.returncode == 2, r.stderr
    assert "gain.kp[1] .. gain.kp[3] are its 3 elements" in r.stderr and "ctl.gain.kp=[5e4,5e4,5e4]" in r.stderr, r.stderr


def test_an_unknown_fmu_name_gets_a_close_match_and_the_list_once():
    r = cosim("check", ANALYTIC, "--set", "components.ctl.fmu=linear_ctk")
    assert r.returncode == 2, r.stderr
    assert "did you mean linear_ctc" in r.stderr, r.stderr
    assert r.stderr.count("rotary_exudyn_plant") == 1, f"the list is printed {r.stderr.count('rotary_exudyn_plant')} times"


def test_a_deleted_working_folder_is_one_line_not_an_internal_error(tmp_path):
    gone = tmp_path / "gone"
    gone.mkdir()
    r = cosim("run", ANALYTIC, "--no-log", "--stop-time", "0.01", cwd=gone, preexec_fn=lambda: os.rmdir(gone))
    assert r.returncode == 2 and "internal error" not in r.stderr, r.stderr
    assert r.stderr.strip() == ("error: the working folder no longer exists (deleted or moved after this shell "
                                "entered it): cd to an existing folder and run again"), r.stderr


def test_runs_from_any_folder_share_the_users_cache_and_print_tidy_paths(first_log, tmp_path):
    """The first log's run (in another folder) built or found the FMUs in the user's cache: a run from here builds
    nothing into this folder, and a scenario's ``../runs`` log path is printed without the ``..``."""
    here = tmp_path / "elsewhere"
    here.mkdir()
    r = cosim("run", ANALYTIC, "--set", "fmus=native", "--stop-time", "0.02", "--no-log", cwd=here)
    assert r.returncode == 0, r.stderr
    assert list(here.iterdir()) == [], f"written into the working folder: {sorted(p.name for p in here.iterdir())}"
    r = cosim("run", "helix_ctc_analytic.yaml", "--set", "fmus=native", "--stop-time", "0.02", "--quiet",
              "--json", cwd=ROOT / "scenarios")
    assert r.returncode == 0, r.stderr
    assert "/../" not in r.stdout and '"log": "../runs/' not in r.stdout, r.stdout


def test_fmus_build_out_leaves_only_fmus(tmp_path):
    out = tmp_path / "fmus"
    r = cosim("fmus", "build", "helix", "linear_ik", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in out.iterdir()) == ["helix.fmu", "linear_ik.fmu"]
