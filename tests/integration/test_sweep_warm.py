"""Warm sweeps (``sweep --from-checkpoint``, issue 34): every case continues a checkpoint of the scenario's run with
its values set at the checkpoint's time. Each case equals ``run --resume CKPT --set`` of its values bit for bit, and
the case of the unchanged values equals the uninterrupted run after the checkpoint; names that cannot be set during a
run, and a checkpoint of another scenario, are refused before a case runs. helix_ctc_analytic (native FMUs), 0.3 s
with a checkpoint at 0.2 s, keeps it short."""

from __future__ import annotations

import csv
import json
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import cosim

pytestmark = pytest.mark.integration
ROOT = Path(__file__).parents[2]
SCENARIO = str(ROOT / "scenarios" / "helix_ctc_analytic.yaml")
T, STOP = 0.2, 0.3  # s: the checkpoint's time and the cases' end (100 steps of 1 ms after it)
T_NS = 200_000_000
GRID = ["--grid", "plant.mass.payload=0,0.3", "--grid", "ctl.mass.payload=0,0.3"]  # 0 kg: the FMUs' start value
METRICS = ("rmse_x", "rmse_y", "rmse_z", "max_error_x", "max_error_y", "max_error_z", "rmse", "max_error",
           "peak_effort", "steps")
_cosim = partial(cosim, timeout=240)


def _rows(out: Path) -> list[dict[str, str]]:
    with (out / "results.csv").open(newline="") as f:
        return list(csv.DictReader(f))


def _same(a: np.ndarray, b: np.ndarray) -> bool:
    """Bit for bit: the same bytes for numbers (a NaN equals the same NaN), equal values for text."""
    if a.dtype == object or b.dtype == object:
        return a.dtype == b.dtype and list(a) == list(b)
    return a.dtype == b.dtype and a.tobytes() == b.tobytes()


def _assert_same_samples(a: Path, b: Path, since_ns: int = 0) -> int:
    """Every signal of log ``a`` equals log ``b``'s bit for bit at the stamps from ``since_ns`` on (the same stamps,
    the same doubles); returns the number of samples compared."""
    from cosim.io.runlog import read_run

    la, lb = read_run(a), read_run(b)
    assert sorted(la.signals) == sorted(lb.signals), (sorted(la.signals), sorted(lb.signals))
    n = 0
    for name, sa in la.signals.items():
        sb = lb.signals[name]
        ka, kb = sa.t_ns >= since_ns, sb.t_ns >= since_ns
        ta, tb, ya, yb = sa.t_ns[ka], sb.t_ns[kb], sa.y[ka], sb.y[kb]
        assert np.array_equal(ta, tb), (name, ta, tb)
        diff = [k for k in range(len(ya)) if not _same(ya[k:k + 1], yb[k:k + 1])]
        if diff:
            k = diff[0]
            raise AssertionError(f"{name} differs at t = {ta[k] * 1e-9} s: {ya[k]!r} ({a.name}) != {yb[k]!r} "
                                 f"({b.name}); {len(diff)} of {len(ya)} samples differ")
        n += len(ya)
    return n


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    """The uninterrupted run to STOP (logged) with a checkpoint at T."""
    d = tmp_path_factory.mktemp("warm")
    r = _cosim("run", SCENARIO, "--stop-time", STOP, "--checkpoint-at", T, "--checkpoint-out", d / "c.ckpt",
               "--out", d / "full.mcap", "--quiet")
    assert r.returncode == 0 and (d / "c.ckpt").is_file(), (r.returncode, r.stdout + r.stderr)
    return d


def test_warm_cases_equal_resumed_runs_bit_for_bit(run_dir, tmp_path):
    out = tmp_path / "sweep"
    ckpt = run_dir / "c.ckpt"
    r = _cosim("sweep", SCENARIO, "--from-checkpoint", ckpt, *GRID, "--stop-time", STOP, "--workers", "2", "--logs",
               "--out", out, "--json")
    # exit 1: an unmodelled payload misses the scenario's 1 um acceptance check (a result, not an error)
    assert r.returncode in (0, 1), (r.returncode, r.stdout + r.stderr)
    summary = json.loads(r.stdout)
    assert summary["warm_start"]["checkpoint"] == str(ckpt.resolve()) and summary["warm_start"]["time"] == T, \
        (summary["warm_start"], str(ckpt.resolve()), T)
    meta = json.loads((out / "sweep.json").read_text())
    assert meta["warm_start"] == summary["warm_start"], (meta["warm_start"], summary["warm_start"])
    rows = _rows(out)
    assert len(rows) == 4, (len(rows), 4)
    for row in rows:
        assert row["status"] == "ok" or row["message"].startswith("acceptance check failed"), \
            (row["status"], row["message"])
        assert (float(row["start_time_s"]), row["checkpoint"]) == (T, str(ckpt.resolve())), \
            ((row["start_time_s"], row["checkpoint"]), (T, str(ckpt.resolve())))
        assert row["steps"] == "100", (row["steps"], "100: the time after the checkpoint only")
        sets = [a for k in ("plant.mass.payload", "ctl.mass.payload") for a in ("--set", f"{k}={row[k]}")]
        resumed = tmp_path / f"resumed_{row['case']}.mcap"
        rr = _cosim("run", "--resume", ckpt, *sets, "--out", resumed, "--json")
        assert rr.returncode in (0, 1), (rr.returncode, "0 or 1 (its acceptance check)", rr.stderr)
        errors = json.loads(rr.stdout)["errors"]
        for e, axis in zip(errors, "xyz"):
            for metric in ("rmse", "max_error"):
                assert float(row[f"{metric}_{axis}"]) == e[metric], (row["case"], axis, metric,
                                                                     row[f"{metric}_{axis}"], e[metric])
        n = _assert_same_samples(Path(row["mcap"]), resumed)
        assert n > 0, (n, "samples compared")
    unchanged = next(x for x in rows if float(x["plant.mass.payload"]) == float(x["ctl.mass.payload"]) == 0.0)
    n = _assert_same_samples(Path(unchanged["mcap"]), run_dir / "full.mcap", since_ns=T_NS)
    assert n > 0, (n, "samples compared")

    # the same cases without logs (a case then reads every output, as the logged run that wrote the checkpoint):
    # the same metrics, digit for digit
    bare = tmp_path / "bare"
    r = _cosim("sweep", SCENARIO, "--from-checkpoint", ckpt, *GRID, "--stop-time", STOP, "--workers", "2",
               "--out", bare, "--quiet")
    assert r.returncode in (0, 1), (r.returncode, r.stdout + r.stderr)
    logged = {x["case"]: x for x in rows}
    for row in _rows(bare):
        for metric in METRICS:
            assert row[metric] == logged[row["case"]][metric], (row["case"], metric, row[metric],
                                                                logged[row["case"]][metric])

    # the same command again runs nothing; sweep-report draws it
    again = _cosim("sweep", SCENARIO, "--from-checkpoint", ckpt, *GRID, "--stop-time", STOP, "--out", bare, "--json")
    summary = json.loads(again.stdout)
    assert (summary["ran"], summary["skipped"]) == (0, 4), ((summary["ran"], summary["skipped"]), (0, 4))
    rep = _cosim("sweep-report", bare)
    assert rep.returncode == 0 and (bare / "sweep_rmse.png").stat().st_size > 1000, (rep.returncode, rep.stderr)


@pytest.mark.parametrize("grid, why", [
    ("plant.mass.platform=1,2", "a fixed parameter of plant"),
    ("ctl.q[1]=0,1", "this input is driven by a connection"),
    ("time.step=0.001,0.002", "a scenario key, not a variable of a component"),
])
def test_a_name_not_settable_during_a_run_is_refused_in_one_line(run_dir, tmp_path, grid, why):
    out = tmp_path / "sweep"
    r = _cosim("sweep", SCENARIO, "--from-checkpoint", run_dir / "c.ckpt", "--grid", grid, "--stop-time", STOP,
               "--workers", "1", "--out", out)
    name = grid.split("=")[0]
    assert (r.returncode, r.stderr.count("\n")) == (2, 1), ((r.returncode, r.stderr.count("\n")), (2, 1), r.stderr)
    assert r.stderr.startswith(f"error: {name}: ") and why in r.stderr, (r.stderr, name, why)
    assert not (out / "results.csv").exists(), (sorted(p.name for p in out.iterdir()), "no results.csv")


def test_a_checkpoint_of_another_scenario_is_refused(run_dir, tmp_path):
    other = str(ROOT / "scenarios" / "helix_ctc.yaml")
    r = _cosim("sweep", other, "--from-checkpoint", run_dir / "c.ckpt", "--grid", "plant.mass.payload=0,0.1",
               "--out", tmp_path / "sweep")
    assert (r.returncode, r.stderr.count("\n")) == (2, 1), ((r.returncode, r.stderr.count("\n")), (2, 1), r.stderr)
    assert "a checkpoint of another scenario" in r.stderr, (r.stderr, "a checkpoint of another scenario")
