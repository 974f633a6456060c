"""Parameter sweeps on Dask: a grid or random samples of dotted-name overrides, one run per case.

``python -m cosim sweep SCENARIO --grid ctl.gain.kp=1e4,4e4 --random plant.mass.payload=uniform(0,0.5) -n 8``

- Cases are the cartesian product of the ``--grid`` axes, times ``-n`` random draws (seeded)
  of the ``--random`` ones. Names are those of ``--set`` (:func:`cosim.engine.overrides.resolve_name`).
- The scenario file is read once; each case is that scenario with its overrides, validated
  (every case before anything runs) and sent to a worker as it is (a frozen Scenario, plain
  data). Our FMUs are built once, before the sweep, and reach the workers as file paths; FMU
  handles never leave the process that ran the case. Each case extracts its FMUs and removes
  them at its end, as every run does (:func:`cosim.run.run_scenario`; tens of ms a case): a
  worker ended between cases leaves nothing in the temporary directory, and a worker of a
  long-lived cluster never runs an FMU rebuilt since from an older extraction.
- Cases run on Dask: an embedded ``LocalCluster`` of single-threaded worker processes, or an
  existing cluster (``--scheduler tcp://host:8786``). A dead worker's cases are rescheduled. Each case runs
  in a child process of its worker, supervised as ``python -m cosim run`` is (:func:`run_loaded_case`): an FMU
  that segfaults, aborts or calls ``exit()`` fails its case, with the component, the time and the signal in
  its message, and the worker goes on (it died instead, and Dask retried the case on 3 more workers, each
  killed, then recorded it as ``lost: KilledWorker``, without the reason).
- Every finished case is appended (and flushed) to ``DIR/results.csv`` as it arrives; running
  the same command again skips the cases already there (``ok`` or ``failed``).
- A warm sweep (``--from-checkpoint FILE``, :func:`run_sweep`'s ``checkpoint``) starts every case from a checkpoint
  of the scenario's run (:mod:`cosim.io.checkpoint`): the case's values are set at the checkpoint's time, as
  ``run --resume FILE --set`` does (:func:`cosim.run.resumed_scenario`), so only component variables settable
  during a run can be swept (tunable parameters, inputs no connection drives; anything else is refused before a
  case runs), and a case costs only the time after the checkpoint. The checkpoint reaches the workers as its path
  and each case reads it in its own process (FMU states and handles never travel).

``results.csv``: one row per case: ``case`` (a hash of its parameter values), ``status``
(``ok``: the run completed and passed its acceptance checks; ``failed``: it raised or missed a
check, ``message`` says why), one column per swept name, then :func:`cosim.analysis.metrics.metric_names`
(``rmse_x``... ``max_error_x``... in signal units,
``rmse`` and ``max_error`` the largest over the axes, ``peak_effort`` N or N*m, ``sim_time_s``,
``steps``, ``wall_time_s`` of the case), ``checks`` (the scenario's acceptance checks:
``ok``/``FAILED``/empty), ``mcap`` (with ``--logs``) and ``message``. Floats are written with
``repr`` (they read back to the same double). A warm sweep's table has two more columns, ``start_time_s`` (the
checkpoint's time) and ``checkpoint`` (its path); its metrics cover the time after the checkpoint only.
"""

from __future__ import annotations

import asyncio
import atexit
import csv
import hashlib
import itertools
import json
import logging
import math
import multiprocessing
import os
import re
import shutil
import tempfile
import threading
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from ..engine import supervision
from ..engine.events import resolve_sets
from ..engine.assembly import assemble_scenario
from ..engine.prepare import build_key, build_ours, locate_fmus
from ..engine.overrides import dotted_overrides, parse_set_value
from ..engine.scenario import load_scenario, read_scenario
from ..engine.system import SystemPlan, build_plan
from ..errors import CosimError, ScenarioError, exit_now, file_problem, written_by_rename
from ..io.output import check_output, output_dir
from ..fmi import cleanup_extracted
from ..fmi.extract import sweep_orphans
from ..io.checkpoint import Checkpoint, file_sha256, read_checkpoint
from ..io.recover import recover_crashed
from ..observers.recorders import PeakEffort
from ..run import resumed_scenario, run_scenario
from .limits import MAX_CASES
from .metrics import metric_names, metrics

if TYPE_CHECKING:
    from ..engine.schema import Scenario

__all__ = [
    "RESULTS",
    "Case",
    "SweepError",
    "SweepSummary",
    "WarmStart",
    "make_cases",
    "parse_grid",
    "parse_random",
    "read_results",
    "run_loaded_case",
    "run_sweep",
]

RESULTS = "results.csv"
WARM_COLUMNS = ("start_time_s", "checkpoint")
"""The columns a warm sweep's table has besides a cold one's: the checkpoint's time, s, and its path."""
_RANDOM = re.compile(r"^(uniform|normal)\(\s*([^,()]+)\s*,\s*([^,()]+)\s*\)$")


class SweepError(CosimError, ValueError):
    """A bad sweep definition or output directory."""


@dataclass(frozen=True)
class Case:
    """One run: overrides by dotted name, and its id (a hash of the names and values)."""

    values: dict[str, Any]

    @property
    def id(self) -> str:
        text = json.dumps(sorted((k, repr(v)) for k, v in self.values.items()))
        return hashlib.sha256(text.encode()).hexdigest()[:12]


@dataclass(frozen=True)
class WarmStart:
    """Where a warm sweep's cases start (plain data: it travels to the workers, each case reads the checkpoint in its
    own process). ``checkpoint``: the file's absolute path; ``time``: its time, s; ``sha256``: the file's;
    ``stop_time``: the cases' end, s."""

    checkpoint: str
    time: float
    sha256: str
    stop_time: float

    def record(self) -> dict[str, Any]:
        """What ``sweep.json`` says of it (``warm_start``)."""
        return {"checkpoint": self.checkpoint, "time": self.time, "stop_time": self.stop_time, "sha256": self.sha256}

    def text(self) -> str:
        return f"warm-started from {self.checkpoint} at t = {self.time:g} s"


def _value(text: str, where: str) -> Any:

    return parse_set_value(text.strip(), where)


def _top_level_split(text: str) -> list[str]:
    """Split at commas outside brackets: ``1,[2,3],4`` -> ``["1", "[2,3]", "4"]`` (list values)."""
    parts, depth, cur = [], 0, ""
    for ch in text:
        depth += ch in "[(" and 1 or (-1 if ch in "])" else 0)
        if ch == "," and depth == 0:
            parts.append(cur)
            cur = ""
        else:
            cur += ch
    return parts + [cur]


def parse_grid(items: Sequence[str]) -> dict[str, list[Any]]:
    """``["ctl.gain.kp[1]=1e4,4e4"]`` -> ``{"ctl.gain.kp[1]": [1e4, 4e4]}`` (values as ``--set`` reads them;
    a list value in brackets, ``ctl.gain.kp=[1e4,1e4,1e4],[4e4,4e4,4e4]``, sets every element)."""
    out: dict[str, list[Any]] = {}
    for item in items:
        name, sep, values = item.partition("=")
        if not sep or not name or not values.strip():
            raise SweepError(f"--grid {item}: expected NAME=V1,V2,...")
        if name in out:
            raise SweepError(f"--grid {item}: {name} is given twice")
        out[name] = [_value(v, f"--grid {item}") for v in _top_level_split(values)]
    return out


def parse_random(items: Sequence[str]) -> dict[str, tuple[str, float, float]]:
    """``["plant.mass.payload=uniform(0,0.5)"]`` -> ``{"plant.mass.payload": ("uniform", 0.0, 0.5)}``."""
    out: dict[str, tuple[str, float, float]] = {}
    for item in items:
        name, sep, dist = item.partition("=")
        m = _RANDOM.match(dist.strip())
        if not sep or not name or m is None:
            raise SweepError(f"--random {item}: expected NAME=uniform(A,B) or NAME=normal(MU,SIGMA)")
        try:
            a, b = float(m[2]), float(m[3])
        except ValueError:
            raise SweepError(f"--random {item}: the bounds must be numbers") from None
        if not math.isfinite(b - a):  # nan, an infinity, or a span past the largest double (-1e308, 1e308)
            raise SweepError(f"--random {item}: the bounds must be finite numbers whose difference is finite")
        if m[1] == "uniform" and not a < b:
            raise SweepError(f"--random {item}: uniform(A,B) needs A < B")
        if m[1] == "normal" and not b >= 0:
            raise SweepError(f"--random {item}: normal(MU,SIGMA) needs SIGMA >= 0")
        out[name] = (m[1], a, b)
    return out


def make_cases(grid: dict[str, list[Any]], random: dict[str, tuple[str, float, float]], n: int | None,
               seed: int | None) -> list[Case]:
    """Cartesian product of ``grid``, each combined with ``n`` draws of ``random`` (numpy, ``seed``)."""

    if random and not n:
        raise SweepError("--random needs -n N (the number of draws)")
    if n and not random:
        raise SweepError("-n needs at least one --random NAME=DIST")
    if not grid and not random:
        raise SweepError("nothing to sweep: give --grid NAME=V1,V2,... and/or --random NAME=DIST -n N")
    both = set(grid) & set(random)
    if both:
        raise SweepError(f"{', '.join(sorted(both))}: both --grid and --random")
    total = math.prod(len(v) for v in grid.values()) * (n or 1)
    if total > MAX_CASES:
        raise SweepError(f"the sweep has {total:.3g} cases (at most {MAX_CASES}): fewer grid values or draws")
    rng = np.random.default_rng(seed)
    draws = [{name: float(rng.uniform(a, b) if kind == "uniform" else rng.normal(a, b))
              for name, (kind, a, b) in random.items()} for _ in range(n or 1)]
    names = list(grid)
    cases = []
    for combo in itertools.product(*(grid[k] for k in names)):
        for draw in draws:
            cases.append(Case({**dict(zip(names, combo)), **draw}))
    ids = [c.id for c in cases]
    if len(set(ids)) != len(ids):
        raise SweepError("some cases repeat the same values (a grid value given twice?)")
    return cases


def _failed(exc: Exception, t0: float) -> dict[str, Any]:
    msg = str(exc) if isinstance(exc, CosimError) else f"{type(exc).__name__}: {exc}"
    return {"status": "failed", "message": " ".join(msg.split()),  # one line in the table
            "checks": "", "mcap": "", "wall_time_s": time.perf_counter() - t0}


def run_loaded_case(scenario: Scenario, fmu_files: dict[tuple[str, bool, int], str],
                    mcap: str | None = None, warm: WarmStart | None = None,
                    sets: dict[str, Any] | None = None) -> dict[str, Any]:
    """Run one case, a loaded :class:`~cosim.engine.scenario.Scenario` (in a Dask worker, or here); never
    raises for a failing case, and a case whose FMU crashes its process is a failed case, not the end of the worker.

    ``fmu_files``: our FMUs by :func:`cosim.engine.prepare.build_key`, built beforehand. The run is serial in its
    process (``parallel: off``: the sweep already uses the cores), a child forked for the case and supervised as
    ``python -m cosim run`` is (:func:`cosim.engine.supervision.contained`): a segfault, an ``abort()`` or an
    ``exit()`` inside an FMU, or a component that cannot be stopped, ends the child only, and the row's message names
    the component, the phase, the time and how it died (the case's log, with ``mcap``, is recovered up to the crash).
    ``COSIM_SUPERVISE=0`` (or a system without ``fork``) runs it in this process. Returns the row of
    ``results.csv`` without the parameter columns: status, message, metrics, checks, mcap.

    ``warm``: a warm case, ``scenario`` being the checkpoint's (:func:`cosim.run.resumed_scenario`): the checkpoint
    read here, its state restored, ``sets`` (``component.variable: value``) set at its time.
    """
    if not hasattr(os, "fork") or os.environ.get("COSIM_SUPERVISE", "1") == "0":
        return _run_case(scenario, fmu_files, mcap, warm, sets)
    t0 = time.perf_counter()
    row, why, rec = supervision.contained(lambda: _run_case(scenario, fmu_files, mcap, warm, sets))
    if why is None:
        return row
    sweep_orphans()  # the FMUs the dead child extracted
    log, _ = recover_crashed(rec.info())
    return {**_failed(CosimError(why), t0), "mcap": log or ""}


def _run_case(scenario: Scenario, fmu_files: dict[tuple[str, bool, int], str], mcap: str | None,
              warm: WarmStart | None = None, sets: dict[str, Any] | None = None) -> dict[str, Any]:
    """:func:`run_loaded_case` in this process."""
    t0 = time.perf_counter()
    row: dict[str, Any] = {"status": "failed", "message": "", "checks": "", "mcap": ""}
    try:
        sc = scenario.model_copy(update={"parallel": "off"})  # a valid value: nothing to validate again
        peak = PeakEffort()
        resume = {}
        if warm is not None:  # read here: FMU states are restored in the process that runs the case
            resume = {"resume": read_checkpoint(warm.checkpoint), "resume_sets": dict(sets or {})}
        res = run_scenario(sc, out=mcap, log=mcap is not None, progress=False, observers=[peak],
                           fmu_files=fmu_files, **resume)
        row.update(metrics(sc, res, peak.peak))
        row["status"] = "ok"  # completed, or ended early by an FMU (the message says which and when)
        row["message"] = res.message
        if res.checks:
            row["checks"] = "ok" if res.passed else "FAILED"
        if res.checks and not res.passed and row["status"] == "ok":  # ran to the end but missed its acceptance
            row["status"] = "failed"
            row["message"] = "acceptance check failed: " + ", ".join(
                f"{name} {c['value']:.4g} > {c['limit']:g}" for name, c in res.checks.items() if not c["ok"])
        row["mcap"] = res.mcap or ""
    except Exception as exc:  # a failing case is a result, never the end of the sweep
        row.update(_failed(exc, t0))
    return row


@dataclass
class SweepSummary:
    """What a sweep did: cases in the table, this time's runs, failures ("case (values)" -> message)."""

    out: Path
    total: int
    ran: int
    skipped: int
    failed: dict[str, str] = field(default_factory=dict)
    wall_time: float = 0.0
    workers: str = ""
    warm: WarmStart | None = None

    @property
    def ok(self) -> bool:
        return not self.failed

    def text(self) -> str:
        lines = [f"sweep: {self.total} cases, {self.total - len(self.failed)} ok, {len(self.failed)} failed "
                 f"({self.ran} run now in {self.wall_time:.1f} s on {self.workers}, {self.skipped} already done"
                 f"{'; ' + self.warm.text() if self.warm is not None else ''}) -> {self.out / RESULTS}"]
        for cid, msg in list(self.failed.items())[:10]:
            lines.append(f"  FAILED {cid}: {msg}")
        if len(self.failed) > 10:
            lines.append(f"  ... and {len(self.failed) - 10} more (status column of {self.out / RESULTS})")
        return "\n".join(lines)


def read_results(out: str | Path) -> list[dict[str, str]]:
    """The rows of ``out/results.csv`` (strings, as written)."""
    path = Path(out) / RESULTS
    if not os.path.lexists(path):
        return []
    problem = file_problem(path)  # a directory, or a FIFO read for ever
    if problem is not None:
        raise SweepError(f"{path}: {problem}; use another --out")
    try:
        with path.open(newline="", encoding="utf-8") as f:
            rows = list(csv.DictReader(f))
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise SweepError(f"{path}: not a sweep's results table ({exc}); use another --out") from None
    if rows and (None in rows[0] or not {"case", "status"} <= set(rows[0])):
        raise SweepError(f"{path}: not a sweep's results table (no case and status columns); use another --out")
    return rows


def prebuild(scenarios: Iterable[Any]) -> dict[tuple[str, bool, int], str]:
    """Build each of our FMUs the cases use, once; :func:`cosim.engine.prepare.build_key` -> absolute path."""

    keys = sorted({build_key(sc, c.fmu) for sc in scenarios for c in sc.components.values() if c.fmu is not None})
    return {k: str(Path(build_ours(*k)).resolve()) for k in keys}


def _check_names(scenarios: list[Any], fmu_files: dict[tuple[str, bool, int], str]) -> None:
    """Resolve every case's parameter names and values against the FMUs (no instantiation), so a
    misspelt name stops the sweep before it starts (ScenarioError / WiringError, exit 2)."""

    infos = None
    for sc in scenarios:
        if infos is None or set(infos) != set(sc.components):
            infos = locate_fmus(sc, fmu_files)
        build_plan(sc, infos)


def _columns(params: list[str], metric_names: list[str], warm: bool = False) -> list[str]:
    return ["case", "status", *params, *metric_names, *(WARM_COLUMNS if warm else ()), "checks", "mcap", "message"]


def _warm_scenario(scenario: str, checkpoint: str | Path, stop_time: float | None,
                   params: list[str]) -> tuple[Checkpoint, Scenario]:
    """The checkpoint read and its scenario to ``stop_time`` (``scenario``, the file named, must be the one it holds:
    CheckpointError); a swept name that is a scenario key, not a component's variable, refused (SweepError)."""
    ck = read_checkpoint(checkpoint)
    sc = resumed_scenario(ck, stop_time, load_scenario(scenario))
    for name in params:
        comp, dot, _ = name.partition(".")
        if not dot or comp not in sc.components:
            raise SweepError(f"{name}: a scenario key, not a variable of a component ({', '.join(sc.components)}); a "
                             f"warm sweep continues the checkpoint's run as it was from t = {ck.time:g} s and sets "
                             "only component variables settable during a run (tunable parameters, inputs no "
                             "connection drives)")
    return ck, sc


def _warm_system(scenario: Scenario, ck: Checkpoint, fmu_files: dict[tuple[str, bool, int], str]) -> SystemPlan:
    """The warm cases' system, checked against the checkpoint before any case runs (the same components on the same
    FMU files, time grid and algorithm, a stop time after it: :meth:`Checkpoint.check_system`; no FMU
    instantiated). A checkpoint holds its exchanged values by variable, so a case with or without a log takes it."""
    infos = locate_fmus(scenario, fmu_files)
    plan = build_plan(scenario, infos, "none")
    ck.check_system(assemble_scenario(plan, scenario), scenario.name)  # buffers, no instance
    return plan


def _check_sets(cases: list[Case], plan: SystemPlan, t: float) -> None:
    """Every warm case's values resolved as the run resolves a resumed run's ``--set`` (:func:`resolve_sets`): a
    name not settable during a run (a fixed parameter, a connected input, an output) or a bad value stops the sweep
    before it starts, one line naming the name and why."""
    for c in cases:
        try:
            resolve_sets(dict(c.values), plan, "sweep")
        except ScenarioError as exc:
            why = exc.issues[0].message if exc.issues else str(exc)
            raise SweepError(f"{why} (a warm sweep sets each case's values at the checkpoint's time, t = {t:g} s, "
                             "as an event)") from None


def _meta(out: Path) -> dict[str, Any]:
    """``out/sweep.json`` as written by an earlier sweep; {} when it is missing or unreadable."""
    path = out / "sweep.json"
    if not os.path.lexists(path) or file_problem(path) is not None:
        return {}
    try:
        meta = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError, RecursionError):
        return {}
    return meta if isinstance(meta, dict) else {}


def _started(record: Any) -> str:
    """The start a ``sweep.json``'s ``warm_start`` record names, in words."""
    if isinstance(record, dict) and {"checkpoint", "time", "stop_time"} <= set(record):
        return f"warm-started from {record['checkpoint']} at t = {record['time']} s to {record['stop_time']} s"
    return "its sweep.json names no warm start"


def _cell(v: Any) -> str:
    if isinstance(v, float):
        return repr(v)
    if isinstance(v, (list, dict)):
        return json.dumps(v)
    return "" if v is None else str(v)


def run_sweep(scenario: str | Path, cases: list[Case], out: str | Path, *, workers: int | None = None,
              scheduler: str | None = None, logs: bool = False,
              on_progress: Callable[[int, int, int], None] | None = None,
              checkpoint: str | Path | None = None, stop_time: float | None = None) -> SweepSummary:
    """Run ``cases`` of ``scenario`` on Dask, appending each result to ``out/results.csv``.

    Cases already in the table are skipped. ``workers``: size of the embedded ``LocalCluster``
    (default: the CPU count); ``scheduler``: address of an existing cluster instead.
    ``on_progress(done, failed, total)`` after each case. Raises :class:`ScenarioError` for a bad
    override name or value (checked for every case before anything runs).

    ``checkpoint``: a warm sweep: every case continues this checkpoint of ``scenario``'s run
    (:mod:`cosim.io.checkpoint`) to ``stop_time`` (s; default: the checkpoint's run's), its values
    (``component.variable``: tunable parameters, inputs no connection drives) set at the checkpoint's
    time; anything else, a checkpoint of another scenario or FMU build, or a stop time not after the
    checkpoint raises before anything runs (SweepError, CheckpointError).
    """

    t_start = time.perf_counter()
    scenario = str(Path(scenario).resolve())
    out = Path(out)
    params = list(dict.fromkeys(k for c in cases for k in c.values))
    ck = warm = None
    if checkpoint is None:
        if stop_time is not None:
            raise SweepError("stop_time is a warm sweep's (with checkpoint=); a case from t = 0 takes time.stop "
                             "among its values")
        source = read_scenario(scenario)  # read once: every case is derived from it
        loaded = [source.load(dotted_overrides(c.values, "sweep case")) for c in cases]
    else:
        ck, warm_scenario = _warm_scenario(scenario, checkpoint, stop_time, params)
        warm = WarmStart(str(Path(ck.path).resolve()), ck.time, file_sha256(ck.path), warm_scenario.time.stop)
        loaded = [warm_scenario] * len(cases)  # one scenario: a case's values are set during its run
    columns = _columns(params, metric_names(loaded[0]), warm is not None)
    output_dir(out)
    table = out / RESULTS
    done_rows = read_results(out)
    if done_rows and list(done_rows[0]) != columns:
        raise SweepError(f"{table} holds another sweep (columns {', '.join(done_rows[0])}); use another --out")
    if done_rows and warm is not None:
        before = _meta(out).get("warm_start")
        if before != warm.record():
            raise SweepError(f"{table} holds another sweep ({_started(before)}, not {warm.text()} to "
                             f"{warm.stop_time:g} s); use another --out")
    finished = {r["case"]: r for r in done_rows if r["status"] in ("ok", "failed")}
    failed = {f"{cid} ({', '.join(f'{k}={r[k]}' for k in params)})": r["message"] or "acceptance check failed"
              for cid, r in finished.items() if r["status"] == "failed" or r["checks"] == "FAILED"}
    todo = [(c, sc) for c, sc in zip(cases, loaded) if c.id not in finished]
    meta: dict[str, Any] = {"scenario": scenario, "parameters": params, "cases": len(cases)}
    if warm is not None:
        meta["warm_start"] = warm.record()
    with written_by_rename(out / "sweep.json") as tmp:
        tmp.write_text(json.dumps(meta, indent=2))
    summary = SweepSummary(out, len(cases), len(todo), len(cases) - len(todo), failed, warm=warm)
    if on_progress is not None:
        on_progress(len(finished), len(failed), len(cases))
    if not todo:
        summary.wall_time = time.perf_counter() - t_start
        summary.workers = "no workers"
        return summary
    cluster = SweepCluster(workers, scheduler).start()  # its workers start while the FMUs are built and checked
    try:
        if warm is None:
            fmu_files = prebuild(loaded)
            _check_names(loaded, fmu_files)
        else:
            fmu_files = prebuild(loaded[:1])
            plan = _warm_system(loaded[0], ck, fmu_files)
            _check_sets(cases, plan, ck.time)
            warm = summary.warm = WarmStart(warm.checkpoint, warm.time, warm.sha256, warm.stop_time)
    except BaseException:
        cluster.close()
        raise
    if logs:
        (out / "logs").mkdir(exist_ok=True)
    new = not table.exists() or table.stat().st_size == 0
    with cluster as (client, label), table.open("a", newline="") as f:
        from distributed import as_completed  # lazy: --help loads this module without it

        writer = csv.writer(f)
        if new:
            writer.writerow(columns)
            f.flush()
        futures = {}
        for c, sc in todo:
            mcap = str((out / "logs" / f"{c.id}.mcap").resolve()) if logs else None
            fut = client.submit(run_loaded_case, sc, fmu_files, mcap, warm, c.values if warm is not None else None,
                                key=f"case-{c.id}", pure=False)
            futures[fut] = c
        n_done = len(finished)
        for fut in as_completed(futures):
            c = futures[fut]
            try:
                row = fut.result()
            except Exception as exc:  # the task itself was lost (e.g. every worker it ran on died)
                row = {"status": "lost", "message": f"{type(exc).__name__}: {exc}"}
            row = {"case": c.id, **{k: c.values.get(k) for k in params}, **row}
            if warm is not None:
                row.update(start_time_s=warm.time, checkpoint=warm.checkpoint)
            writer.writerow([_cell(row.get(k)) for k in columns])
            f.flush()
            n_done += 1
            if row["status"] != "ok":
                who = f"{c.id} ({', '.join(f'{k}={_cell(v)}' for k, v in c.values.items())})"
                failed[who] = row["message"] if row["status"] == "failed" else f"{row['status']}: {row['message']}"
            if on_progress is not None:
                on_progress(n_done, len(failed), len(cases))
        summary.workers = label
    summary.wall_time = time.perf_counter() - t_start
    return summary


# Dask settings of the embedded cluster's workers. Each case is one long task in the worker's
# single thread; the worker's own threads take the GIL from it. Dask's statistical profiler
# samples the task's stack every 10 ms (with it the workers spent 9-12 % CPU on top of the cases'
# own, without it 1-2 %; measured with 8 cases on 2 workers), and the event-loop tick (20 ms),
# memory monitor (100 ms) and system monitor (500 ms) wake it more often than a sweep needs.
WORKER_CONFIG = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.worker.memory.monitor-interval": "1s",
    "distributed.admin.system-monitor.interval": "2s",
}


class SweepCluster:
    """A Dask client: on ``scheduler`` (an existing cluster) or on an embedded LocalCluster.

    :meth:`start` starts the embedded cluster in a thread (the caller builds the FMUs meanwhile);
    ``with`` waits for it and yields ``(client, label)``; :meth:`close` if ``with`` is never entered.
    """

    CONNECT_TIMEOUT = 10.0
    """s, for an existing scheduler to accept a connection, answer Dask's handshake and say it is a scheduler."""

    def __init__(self, workers: int | None, scheduler: str | None):
        self.workers, self.scheduler = workers, scheduler
        self.cluster = self.client = self._thread = None
        self._error: BaseException | None = None
        self._scratch: str | None = None  # the embedded workers' folder, removed with the cluster

    def start(self) -> "SweepCluster":

        logging.getLogger("distributed").setLevel(logging.ERROR)  # the process's: the cluster's and the client's
        if self.scheduler is None:
            self._thread = threading.Thread(target=self._start_local, name="sweep-cluster-start", daemon=True)
            self._thread.start()
        else:
            self._probe()
        return self

    def _probe(self) -> None:
        """Check that ``scheduler`` is a Dask scheduler, within :attr:`CONNECT_TIMEOUT`, before anything is built:
        Dask's client waits for ever on a silent listener, and reads an HTTP answer as a frame of 3 EiB."""

        from distributed.comm import connect  # lazy: --help loads this module without it

        address, timeout = self.scheduler, self.CONNECT_TIMEOUT

        async def identity() -> dict:
            comm = await connect(address, timeout=timeout)
            try:
                await comm.write({"op": "identity", "reply": True})
                return await comm.read()
            finally:
                comm.abort()

        try:  # connect() retries a refused connection for ``timeout``, then its handshake waits for ever: bounded
            answer = asyncio.run(asyncio.wait_for(identity(), timeout + 1.0))
        except TimeoutError:
            raise SweepError(f"--scheduler {address}: no answer from {address} within {timeout:g} s (it accepted "
                             f"the connection: is it a Dask scheduler?)") from None
        except ValueError as exc:  # parse_address: not an address of a comm Dask knows
            raise SweepError(f"--scheduler {address}: not a scheduler address ({exc}); expected tcp://HOST:PORT") \
                from None
        except OSError as exc:  # distributed's CommClosedError too: refused, or closed during the handshake
            if str(exc).startswith("Timed out trying to connect"):
                raise SweepError(f"--scheduler {address}: cannot connect to {address} within {timeout:g} s "
                                 f"({_comm_reason(exc.__cause__ or exc)})") from None
            raise SweepError(f"--scheduler {address}: {address} is not a Dask scheduler (it closed the connection "
                             f"in Dask's handshake: {_comm_reason(exc)})") from None
        except Exception:  # noqa: BLE001 - an answer in another protocol: a frame of 3 EiB, undecodable, ...
            raise SweepError(f"--scheduler {address}: {address} is not a Dask scheduler (its answer is not "
                             f"Dask's protocol)") from None
        if not isinstance(answer, dict) or answer.get("type") != "Scheduler":
            kind = answer.get("type") if isinstance(answer, dict) else None
            raise SweepError(f"--scheduler {address}: {address} is not a Dask scheduler"
                             + (f" (a Dask {kind})" if kind else ""))

    def _start_local(self) -> None:
        try:

            import dask  # lazy: --help loads this module without it
            from distributed import LocalCluster  # lazy: --help loads this module without it

            n = self.workers or os.cpu_count() or 1
            self._scratch = tempfile.mkdtemp(prefix="cosim-sweep-")  # not dask-scratch-space, left in the temp folder
            config = {**WORKER_CONFIG, "temporary-directory": self._scratch}  # the scheduler's and workers' folders
            with dask.config.set(config):  # the nannies hand this configuration to their workers
                self.cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                            dashboard_address=None, silence_logs=logging.ERROR,
                                            preload=[__name__],  # dask_setup below
                                            scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})  # not 8787
        except BaseException as exc:  # noqa: BLE001 - raised in the caller's thread by __enter__
            self._error = exc

    def __enter__(self):
        from distributed import Client  # lazy: --help loads this module without it

        if self._thread is None:  # not started yet (an embedded cluster starts here; an existing one needs nothing)
            self.start()
        if self.scheduler is not None:
            try:
                self.client = Client(self.scheduler, timeout="10s")
            except OSError as exc:
                raise SweepError(f"--scheduler {self.scheduler}: cannot connect: {exc}") from None
            n = len(self.client.scheduler_info().get("workers", {}))
            return self.client, f"{self.scheduler} ({n} workers)"
        try:
            self._thread.join()
            if self._error is not None:
                raise self._error
            self.client = Client(self.cluster)
        except BaseException:
            self.close()
            raise
        n = len(self.cluster.workers)
        return self.client, f"{n} local worker process{'es' if n > 1 else ''}"

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._thread is not None:
            self._thread.join()
        if self.client is not None:
            self.client.close()
        if self.cluster is not None:
            self.cluster.close()
        if self._scratch is not None:

            shutil.rmtree(self._scratch, ignore_errors=True)


def _comm_reason(exc: BaseException) -> str:
    """distributed's comm error without its ``in <TCP ...>:`` prefix (``ConnectionRefusedError: [Errno 111] ...``);
    an error without text (a connect attempt that timed out on a loaded machine) by its kind."""
    text = re.sub(r"^in <[^>]*>: ", "", str(exc)).strip()
    return text or f"{type(exc).__name__}: the last attempt gave no reason"


# Worker preload (``LocalCluster(preload=["cosim.analysis.sweep"])``, or
# ``dask worker --preload cosim.analysis.sweep``).
_TORN_DOWN = False


def dask_setup(worker) -> None:  # noqa: ARG001 - Dask's preload hook
    """Import what a case needs while the worker starts (not in its first case), and arrange a
    quick exit for a nanny's worker process once the worker has closed (:func:`_exit_now`)."""

    if multiprocessing.parent_process() is not None:
        atexit.register(_exit_now)
    # this module imports what a case needs (the run, the FMU access layer) when the worker loads it


def dask_teardown(worker) -> None:  # noqa: ARG001 - Dask's preload hook
    global _TORN_DOWN
    _TORN_DOWN = True


def _exit_now() -> None:
    """At exit of a nanny's worker process whose worker closed normally: remove the extracted FMUs,
    flush, and leave with ``os._exit(0)`` (as ``python -m cosim`` does, :mod:`cosim.__main__`): the
    interpreter's finalization and the shared libraries' destructors sometimes abort there
    ("free(): corrupted unsorted chunks") after every result was delivered."""


    if not _TORN_DOWN:
        return
    try:
        cleanup_extracted()
        logging.shutdown()
    finally:
        exit_now(0)


def report(out: str | Path, metric: str = "rmse", fig: str | Path | None = None) -> Path:
    """A figure of ``metric`` over the swept parameters of ``out/results.csv``: a line against one
    parameter (several lines when a second one has few values), a heatmap against two (a scatter
    for random draws). Failed cases are left out (and counted in the title). Returns the PNG path."""
    import matplotlib  # lazy: --help loads this module without it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # lazy: --help loads this module without it

    rows = read_results(out)
    if not rows:
        raise SweepError(f"{Path(out) / RESULTS}: no results")
    meta_path = Path(out) / "sweep.json"
    meta = {}
    if os.path.lexists(meta_path):
        problem = file_problem(meta_path)
        if problem is not None:
            raise SweepError(f"{meta_path}: {problem}")
        try:
            meta = json.loads(meta_path.read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, ValueError, RecursionError) as exc:
            raise SweepError(f"{meta_path}: not the sweep's JSON ({str(exc)[:120]})") from None
    params = meta.get("parameters") if isinstance(meta, dict) else None
    if not params or not isinstance(params, list) or not all(isinstance(p, str) and p in rows[0] for p in params):
        raise SweepError(f"{meta_path}: missing or without parameters (the columns of results.csv "
                         "it swept); it is written by the sweep next to results.csv")
    if metric not in rows[0]:
        valid = [c for c in rows[0] if c not in ("case", "status", "checks", "mcap", "message", *WARM_COLUMNS,
                                                 *params)]
        raise SweepError(f"--metric {metric}: not a column; valid: {', '.join(valid)}")
    ok = [r for r in rows if r["status"] == "ok"]
    n_bad = len(rows) - len(ok)
    swept = [p for p in params if len({r[p] for r in rows}) > 1] or params[:1]
    fig_path = Path(fig) if fig is not None else Path(out) / f"sweep_{metric}.png"
    check_output(fig_path, (Path(out) / RESULTS,))  # a regular file or nothing, never a FIFO, a device or the table
    try:
        y = np.array([float(r[metric]) for r in ok])
    except (TypeError, ValueError):
        bad = next(r for r in ok if not _is_number(r[metric]))
        raise SweepError(f"{Path(out) / RESULTS}: case {bad['case']}: {metric} = {bad[metric]!r} is not a "
                         "number") from None
    f, ax = plt.subplots(figsize=(6.4, 4.6), layout="constrained")

    def axis(name: str) -> tuple[np.ndarray, list[str]]:
        """Numbers, or the positions of list values (``[1e4, 1e4, 1e4]``) ordered by their first element."""
        cells = [r[name] for r in ok]
        try:
            return np.array([float(c) for c in cells]), []
        except ValueError:
            labels = sorted(set(cells), key=_first_element)
            return np.array([labels.index(c) for c in cells], dtype=float), [_short(c) for c in labels]

    if len(swept) == 1:
        x, labels = axis(swept[0])
        order = np.argsort(x)
        ax.plot(x[order], y[order], "o-")
        if labels:
            ax.set_xticks(range(len(labels)), labels)
        ax.set_xlabel(swept[0])
        ax.set_ylabel(metric)
    else:
        a, b = swept[:2]
        (xa, la), (xb, lb) = axis(a), axis(b)
        ua, ub = np.unique(xa), np.unique(xb)
        if len(ua) * len(ub) == len(ok):  # a full grid: heatmap
            grid = np.full((len(ub), len(ua)), np.nan)
            for va, vb, v in zip(xa, xb, y):
                grid[np.searchsorted(ub, vb), np.searchsorted(ua, va)] = v
            finite = grid[np.isfinite(grid)]
            log = finite.size and finite.min() > 0 and finite.max() > 100 * finite.min()
            from matplotlib.colors import LogNorm  # lazy: --help loads this module without it

            im = ax.imshow(grid, origin="lower", aspect="auto", cmap="viridis", norm=LogNorm() if log else None)
            ax.set_xticks(range(len(ua)), la or [f"{v:g}" for v in ua])
            ax.set_yticks(range(len(ub)), lb or [f"{v:g}" for v in ub])
            for i in range(len(ub)):
                for j in range(len(ua)):
                    if not math.isnan(grid[i, j]):
                        ax.text(j, i, f"{grid[i, j]:.3g}", ha="center", va="center", color="w", fontsize=8)
        else:
            im = ax.scatter(xa, xb, c=y, cmap="viridis")
        f.colorbar(im, ax=ax, label=metric)
        ax.set_xlabel(a)
        ax.set_ylabel(b)
    scenario = Path(meta.get("scenario", "")).stem
    warm = meta.get("warm_start")
    start = ""
    if isinstance(warm, dict) and _is_number(warm.get("time")):  # a warm sweep: its metrics are those after the start
        start = f"\nwarm-started at t = {float(warm['time']):g} s from {Path(str(warm.get('checkpoint', ''))).name}"
    ax.set_title(f"{scenario}: {metric}, {len(ok)} cases" + (f" ({n_bad} failed, not shown)" if n_bad else "") + start,
                 fontsize="medium" if start else None)
    try:
        with written_by_rename(fig_path) as tmp:
            f.savefig(tmp, dpi=120, format="png")
    except OSError as exc:
        raise SweepError(f"{fig_path}: cannot write the figure: {exc.strerror or exc}") from None
    finally:
        plt.close(f)
    return fig_path


def _is_number(cell: Any) -> bool:
    try:
        float(cell)
    except (TypeError, ValueError):
        return False
    return True


def _first_element(cell: str) -> tuple:
    """The order of list values (``[1e4, 1e4, 1e4]``) by their first element; other text after them, as text."""
    try:
        first = json.loads(cell)[0] if cell.startswith("[") else None
        return (0, float(first), "") if first is not None else (1, 0.0, cell)
    except (ValueError, TypeError, IndexError, KeyError, RecursionError):
        return (1, 0.0, cell)


def _short(cell: str) -> str:
    """A list value as a tick label: ``[2500.0, 2500.0, 2500.0]`` -> ``2500 (x3)``."""
    try:
        values = json.loads(cell)
    except (ValueError, RecursionError):
        return cell
    if isinstance(values, list) and values and len(set(map(str, values))) == 1:
        return f"{values[0]:g} (x{len(values)})" if isinstance(values[0], (int, float)) else cell
    return cell
