"""Sweeps on Dask (cosim.analysis.sweep): equal to serial runs, on a real scheduler and workers, a worker
killed mid-sweep, a failing case, resumption. Short runs (0.2-0.5 s simulated) keep it fast."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from functools import partial
from pathlib import Path

import pytest
from cli_helpers import cosim, free_port, start_cosim, wait_for

pytestmark = pytest.mark.integration
ROOT = Path(__file__).parents[2]
SCENARIO = str(ROOT / "scenarios" / "helix_ctc_analytic.yaml")
BIN = Path(sys.executable).parent
_cosim = partial(cosim, timeout=240)


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def _die_with_parent() -> None:
    """In the child before exec: SIGTERM when pytest dies. A pytest killed mid-test (a CI timeout)
    runs no fixture teardown, and a scheduler or worker in its own session would run on for ever."""
    import ctypes

    ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM, 0, 0, 0)  # PR_SET_PDEATHSIG = 1 (Linux)


class DaskCluster:
    """A real Dask scheduler and worker processes (``dask scheduler``, ``dask worker``; the old ``dask-scheduler``) on localhost (random free ports)."""

    def __init__(self, n_workers: int, tmp: Path):
        self.port = free_port()
        self.address = f"tcp://127.0.0.1:{self.port}"
        self.procs: list[subprocess.Popen] = []
        self.tmp = tmp
        self.scheduler = self._start([str(BIN / "dask"), "scheduler", "--host", "127.0.0.1", "--port", str(self.port),
                                      "--dashboard-address", ":0", "--no-show"], "scheduler")
        self.workers = [self._start([str(BIN / "dask"), "worker", self.address, "--nthreads", "1", "--no-nanny",
                                     "--no-dashboard", "--local-directory", str(tmp / f"w{i}"), "--name", f"w{i}"],
                                    f"worker{i}") for i in range(n_workers)]
        from distributed import Client

        with Client(self.address, timeout="30s") as c:
            c.wait_for_workers(n_workers, timeout=60)

    def _start(self, cmd: list[str], name: str) -> subprocess.Popen:
        log = open(self.tmp / f"{name}.log", "w")
        p = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT, start_new_session=True,
                             preexec_fn=_die_with_parent)
        self.procs.append(p)
        return p

    def close(self) -> None:
        """SIGTERM, then SIGKILL to what is left after 3 s in all: a worker whose peer was killed (or whose scheduler
        ended first) spends its close waiting out connection timeouts, 15 s of the suite's teardown."""
        for p in reversed(self.procs):
            if p.poll() is None:
                p.terminate()
        deadline = time.monotonic() + 3.0
        for p in self.procs:
            try:
                p.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


@pytest.fixture
def cluster(tmp_path):
    c = DaskCluster(2, tmp_path)
    yield c
    c.close()


def test_sweep_metrics_equal_serial_runs_to_the_last_digit(tmp_path):
    out = tmp_path / "sweep"
    grid = ["--grid", "ctl.gain.kp[1]=1e4,4e4", "--grid", "trajectory.params.rx=0.05,0.1"]
    r = _cosim("sweep", SCENARIO, *grid, "--stop-time", "0.2", "--workers", "2", "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stdout + r.stderr
    rows = _rows(out)
    assert len(rows) == 4 and all(x["status"] == "ok" for x in rows), rows
    for row in rows[:2]:  # two serial runs against their sweep cases: every metric digit for digit
        serial = _cosim("run", SCENARIO, "--no-log", "--json", "--stop-time", "0.2",
                        "--set", f"ctl.gain.kp[1]={row['ctl.gain.kp[1]']}",
                        "--set", f"trajectory.params.rx={row['trajectory.params.rx']}")
        assert serial.returncode == 0, serial.stderr
        errors = json.loads(serial.stdout)["errors"]
        for e, axis in zip(errors, "xyz"):
            for metric in ("rmse", "max_error"):
                assert float(row[f"{metric}_{axis}"]) == e[metric], (row, axis, metric, e[metric])
    # the same command again runs nothing and keeps the table
    again = _cosim("sweep", SCENARIO, *grid, "--stop-time", "0.2", "--workers", "2", "--out", str(out), "--json")
    assert again.returncode == 0, again.stderr
    summary = json.loads(again.stdout)
    assert (summary["ran"], summary["skipped"]) == (0, 4), summary
    assert _rows(out) == rows, "the re-run changed the table"


def test_a_sweep_of_an_ssp_archive_gives_its_scenarios_rows(tmp_path):
    """The archive exported from a scenario sweeps as the scenario does: the same metrics for the same cases (the
    archive unpacked once for the whole sweep, nothing of it left after), warm starts included."""
    archive = tmp_path / "helix.ssp"
    assert _cosim("ssp", "export", SCENARIO, "-o", str(archive)).returncode == 0
    grid = ["--grid", "ctl.gain.kp[1]=1e4,4e4", "--stop-time", "0.05", "--workers", "2", "--quiet"]
    rows = []
    for source, out in ((SCENARIO, tmp_path / "yaml"), (str(archive), tmp_path / "ssp")):
        r = _cosim("sweep", source, *grid, "--out", str(out), env={**os.environ, "TMPDIR": str(tmp_path)})
        assert r.returncode == 0, r.stdout + r.stderr
        rows.append(sorted(({k: v for k, v in x.items() if k.startswith(("rmse", "max_error", "ctl.", "status"))}
                            for x in _rows(out)), key=lambda x: float(x["ctl.gain.kp[1]"])))  # in arrival order
    assert rows[0] == rows[1] and len(rows[0]) == 2, rows
    assert not list(tmp_path.glob("cosim-ssp-*")), "the unpacked archive is left in TMPDIR"


def test_sweep_on_an_existing_dask_cluster(cluster, tmp_path):
    out = tmp_path / "sweep"
    r = _cosim("sweep", SCENARIO, "--random", "trajectory.params.rx=uniform(0.04,0.1)", "-n", "3", "--seed", "7",
               "--stop-time", "0.2", "--scheduler", cluster.address, "--out", str(out), "--quiet")
    assert r.returncode == 0, r.stdout + r.stderr
    assert "on tcp://127.0.0.1" in r.stdout and "(2 workers)" in r.stdout, r.stdout
    rows = _rows(out)
    assert len(rows) == 3 and all(x["status"] == "ok" for x in rows), rows


def test_a_worker_killed_mid_sweep_loses_no_case(cluster, tmp_path):
    out = tmp_path / "sweep"
    n = 8
    sweep = start_cosim("sweep", SCENARIO,
                        "--grid", "ctl.gain.kp[1]=" + ",".join(f"{1e4 + 1e3 * k:g}" for k in range(n)),
                        "--stop-time", "0.5", "--scheduler", cluster.address, "--out", str(out), "--quiet")
    try:
        wait_for(lambda: (out / "results.csv").exists() and len(_rows(out)) >= 1, 120, "the first case")
        victim = cluster.workers[0]
        os.killpg(victim.pid, signal.SIGKILL)
        victim.wait(10)
        stdout, stderr = sweep.communicate(timeout=240)
    finally:
        if sweep.poll() is None:
            sweep.kill()
    assert sweep.returncode == 0, stdout + stderr
    rows = _rows(out)
    assert victim.returncode == -signal.SIGKILL, victim.returncode
    assert len(rows) == n and len({x["case"] for x in rows}) == n, [(x["case"], x["status"]) for x in rows]
    assert all(x["status"] == "ok" for x in rows), [(x["case"], x["status"], x["message"]) for x in rows]


def test_a_case_outside_the_workspace_fails_alone(tmp_path):
    out = tmp_path / "sweep"
    r = _cosim("sweep", SCENARIO, "--grid", "trajectory.params.rx=0.05,0.1,0.8", "--stop-time", "0.2",
               "--workers", "2", "--out", str(out))
    assert r.returncode == 1, r.stdout + r.stderr
    rows = {float(x["trajectory.params.rx"]): x for x in _rows(out)}
    assert rows[0.8]["status"] == "failed" and "out of workspace" in rows[0.8]["message"], rows[0.8]
    assert rows[0.05]["status"] == rows[0.1]["status"] == "ok", rows
    assert "3 cases, 2 ok, 1 failed" in r.stdout, r.stdout
    assert f"FAILED {rows[0.8]['case']} (time.stop=0.2, trajectory.params.rx=0.8): out of workspace" in r.stdout, \
        r.stdout


def test_sweep_report_plots_one_and_two_parameters(tmp_path):
    from cosim.analysis.sweep_report import report

    out = tmp_path / "sweep"
    out.mkdir()
    cols = "case,status,a,b,rmse,checks,mcap,message\n"
    rows = "".join(f"c{i}{j},ok,{i},{j},{i * 0.1 + j},,,\n" for i in range(3) for j in range(2))
    (out / "results.csv").write_text(cols + rows)
    (out / "sweep.json").write_text(json.dumps({"scenario": "x.yaml", "parameters": ["a", "b"]}))
    assert report(out, "rmse").stat().st_size > 1000
    r = _cosim("sweep-report", str(out), "--metric", "nope")
    assert r.returncode == 2 and r.stderr.count("\n") == 1 and "valid: rmse" in r.stderr, r.stderr


def test_bad_sweep_input_is_one_line_exit_2(tmp_path):
    for args in (["--grid", "ctl.gain.kpp[1]=1,2"], ["--random", "x=gauss(1,2)", "-n", "2"], ["--grid", "time.stop"]):
        r = _cosim("sweep", SCENARIO, *args, "--out", str(tmp_path / "o"))
        assert r.returncode == 2 and r.stderr.count("\n") == 1, (args, r.stderr)


@pytest.mark.parametrize("option", [["--set", "ctl.gain.kp[1]=[1"], ["--grid", "ctl.gain.kp[1]=[1,2"]])
def test_a_value_that_is_not_yaml_is_one_line_naming_the_option(tmp_path, option):
    """Before anything runs: exit 2, the option as given and YAML's reason, no traceback."""
    r = _cosim("sweep", SCENARIO, *option, "--out", str(tmp_path / "s"))
    assert r.returncode == 2, r.stderr
    assert f"error: {option[0]} {option[1]}: invalid value: " in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_sweep_report_without_its_sweep_json_says_so(tmp_path):
    (tmp_path / "results.csv").write_text("case,status,rmse\nabc,ok,1e-6\n")
    r = _cosim("sweep-report", str(tmp_path))
    assert r.returncode != 0 and "sweep.json: missing or without parameters" in r.stderr, r.stderr


CRASH = """
name: crash
components:
  src: {{path: "{crash}", parameters: {{mode: 0, at: 0.005}}}}
  g: {{path: "{gain}"}}
connections:
  - {{from: src.y, to: g.u}}
time: {{stop: 0.01, step: 0.001}}
"""


def test_a_case_whose_fmu_crashes_its_process_is_a_failed_case_with_the_reason(tmp_path, test_fmus):
    """A segfault or an exit() inside a case's FMU ends that case's process only (a child of the Dask worker): the
    case is failed, its message names the component, the time and how it died, its log is recovered up to the crash,
    the other case runs, exit 1. (The worker died instead: the case was retried on 4 workers, each killed, and
    recorded as 'lost: KilledWorker', without the reason.)"""
    scenario = tmp_path / "crash.yaml"
    scenario.write_text(CRASH.format(crash=test_fmus["CosimTCrash"], gain=test_fmus["CosimTGain"]))
    out, tmp = tmp_path / "sweep", tmp_path / "tmp"
    tmp.mkdir()
    r = _cosim("sweep", scenario, "--grid", "src.mode=0,1,3", "--workers", "2", "--logs", "--out", out, "--quiet",
               env={**os.environ, "TMPDIR": str(tmp)})
    assert r.returncode == 1, r.stdout + r.stderr
    assert "Traceback" not in r.stderr and "KilledWorker" not in r.stdout + r.stderr, r.stdout + r.stderr
    rows = {x["src.mode"]: x for x in _rows(out)}
    how = {"1": "crashed (SIGSEGV)", "3": "exited with status 3"}
    assert rows["0"]["status"] == "ok" and rows["0"]["steps"] == "10", rows["0"]
    for mode, reason in how.items():
        row = rows[mode]
        assert row["status"] == "failed", row
        assert row["message"].startswith(f"component 'src' in its step at t = 0.004 s {reason}"), row
        assert f"FAILED {row['case']} (src.mode={mode}): component 'src' in its step" in r.stdout, r.stdout
        from cosim.io.runlog import read_run

        read_run(row["mcap"])  # recovered: readable (10 steps write in the case's process: nothing flushed yet)
    assert sorted(p.name for p in (out / "logs").iterdir()) == sorted(x["case"] + ".mcap" for x in rows.values())
    assert not list(tmp.glob("cosim-*")), list(tmp.glob("cosim-*"))  # extracted FMUs removed


def test_run_loaded_case_contains_a_crash_in_the_calling_process(test_fmus, tmp_path):
    """The Python API of a case (what each Dask worker calls): an abort() inside the FMU is a failed row, and the
    caller goes on."""
    from cosim.analysis.sweep import run_loaded_case
    from cosim.engine.scenario import load_scenario

    scenario = tmp_path / "crash.yaml"
    scenario.write_text(CRASH.format(crash=test_fmus["CosimTCrash"], gain=test_fmus["CosimTGain"]))
    row = run_loaded_case(load_scenario(scenario, {("components", "src", "parameters", "mode"): 2}), {})
    assert row["status"] == "failed" and row["message"] == "component 'src' in its step at t = 0.004 s crashed " \
        "(SIGABRT)", row
    assert run_loaded_case(load_scenario(scenario), {})["status"] == "ok"


def test_a_case_whose_fmu_holds_the_python_lock_is_killed_and_named(test_fmus, tmp_path):
    """A case whose FMU blocks in C with the Python lock held (the case's own watchdog thread cannot run): its
    supervised process is killed after the watchdog's budget and a grace, the row is failed naming the component,
    its call and the time, and the caller goes on."""
    import time

    from cosim.analysis.sweep import run_loaded_case
    from cosim.engine.scenario import load_scenario

    scenario = tmp_path / "held.yaml"
    scenario.write_text(CRASH.format(crash=test_fmus["CosimTCrash"], gain=test_fmus["CosimTGain"]))
    t0 = time.monotonic()
    row = run_loaded_case(load_scenario(scenario, {("components", "src", "parameters", "mode"): 4,
                                                   ("components", "src", "parameters", "hold"): 60,
                                                   ("watchdog_s",): 1.0}), {})
    assert row["status"] == "failed", row
    assert row["message"].startswith("component 'src' in its step at t = 0.004 s made no progress for ") and \
        "could not be stopped from inside: killed" in row["message"], row
    assert time.monotonic() - t0 < 30, f"{time.monotonic() - t0:.1f} s for a case stalled 60 s"
    assert run_loaded_case(load_scenario(scenario), {})["status"] == "ok"
