"""Parameter sweeps: a grid or random samples of dotted-name overrides, one run per case.

``python -m cosim sweep SCENARIO --grid ctl.gain.kp=1e4,4e4 --random plant.mass.payload=uniform(0,0.5) -n 8``

- Cases are the cartesian product of the ``--grid`` axes, times ``-n`` random draws (seeded)
  of the ``--random`` ones. Names are those of ``--set`` (:func:`cosim.engine.overrides.resolve_name`).
- The scenario file is read once; each case is that scenario with its overrides, validated
  (every case before anything runs) and sent to a worker as it is (a frozen Scenario, plain
  data). Our FMUs are built once, before the sweep, and reach the workers as file paths; FMU
  handles never leave the process that ran the case. On the embedded pool the first case's FMUs are extracted
  once, before the workers fork, and removed when the sweep ends (a case of other FMUs extracts its own); on a
  Dask cluster each case extracts its FMUs and removes them at its end, as every run does
  (:func:`cosim.run.run_scenario`; tens of ms a case): a worker ended between cases leaves nothing in the
  temporary directory, and a worker of a long-lived cluster never runs an FMU rebuilt since from an older
  extraction.
- Cases run on an embedded pool of worker processes forked from this process once it is prepared (the cases
  validated, the FMUs built, checked and extracted once: :func:`extract_for_cases`), or on an existing Dask cluster
  (``--scheduler tcp://host:8786``), where a dead worker's cases are rescheduled (:mod:`cosim.analysis.cluster`
  says why the embedded one is not Dask's). Each case runs
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

import atexit
import csv
import json
import logging
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

from ..engine import supervision
from ..engine.assembly import assemble_structure
from ..engine.events import resolve_sets
from ..engine.overrides import dotted_overrides
from ..engine.prepare import build_key, build_ours, locate_fmus
from ..engine.system import SystemPlan, build_plan
from ..errors import CosimError, ScenarioError, exit_now, written_by_rename
from ..fmi import Extractions, FMUInfo, cleanup_extracted, make_slave
from ..fmi.extract import sweep_orphans
from ..fmi.slave import drop_preloaded, preload
from ..io.checkpoint import Checkpoint, file_sha256, read_checkpoint
from ..io.output import exclusive, output_dir
from ..io.recover import recover_crashed
from ..io.ssp.scenario import ArchiveFile, read_source
from ..observers.recorders import PeakEffort
from ..run import resumed_scenario, run_scenario
from .cases import Case, SweepError
from .cluster import ForkPool, SweepCluster
from .metrics import metric_names, metrics
from .results import RESULTS, cell, read_meta, read_results, started, table_columns

if TYPE_CHECKING:
    from ..engine.schema import Scenario

__all__ = ["SweepSummary", "WarmStart", "dask_setup", "dask_teardown", "drop_preloaded", "extract_for_cases",
           "prebuild", "run_loaded_case", "run_sweep"]


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
    partial = rec.info().get("partial")
    if log is None and partial and Path(partial).exists():  # not recoverable here: the row names what is left
        log = partial
    return {**_failed(CosimError(why), t0), "mcap": log or ""}


def _run_case(scenario: Scenario, fmu_files: dict[tuple[str, bool, int], str], mcap: str | None,
              warm: WarmStart | None = None, sets: dict[str, Any] | None = None) -> dict[str, Any]:
    """:func:`run_loaded_case` in this process."""
    t0 = time.perf_counter()
    row: dict[str, Any] = {"status": "failed", "message": "", "checks": "", "mcap": ""}
    try:
        system = scenario.structure()  # the case runs serially (the pool keeps the CPUs busy), and its log says so
        sc = replace(system, parallel="off",
                     document={**system.document, "parallel": "off"} if system.document is not None else None)
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
        if mcap is not None and Path(mcap).exists():  # a stalled or failed run finished its log: the row names it
            row["mcap"] = mcap
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


def prebuild(scenarios: Iterable[Any]) -> dict[tuple[str, bool, int], str]:
    """Build each of our FMUs the cases use, once; :func:`cosim.engine.prepare.build_key` -> absolute path."""

    keys = sorted({build_key(sc.structure(), c.fmu) for sc in scenarios for c in sc.components.values()
                   if c.fmu is not None})
    return {k: str(Path(build_ours(*k)).resolve()) for k in keys}


def _check_names(scenarios: list[Any], fmu_files: dict[tuple[str, bool, int], str]) -> None:
    """Resolve every case's parameter names and values against the FMUs (no instantiation), so a
    misspelt name stops the sweep before it starts (ScenarioError / WiringError, exit 2)."""

    infos = None
    for sc in scenarios:
        if infos is None or set(infos) != set(sc.components):
            infos = locate_fmus(sc.structure(), fmu_files)
        build_plan(sc.structure(), infos)


def _warm_scenario(source: Any, checkpoint: str | Path, stop_time: float | None,
                   params: list[str]) -> tuple[Checkpoint, Scenario]:
    """The checkpoint read and its scenario to ``stop_time`` (``source``'s scenario, the file named, must be the one
    it holds: CheckpointError); a swept name that is a scenario key, not a component's variable, refused
    (SweepError)."""
    ck = read_checkpoint(checkpoint)  # of an archive's run: its FMUs moved into the sweep's unpacking of it
    sc = resumed_scenario(ck, stop_time, source.load(), source if isinstance(source, ArchiveFile) else None)
    for name in params:
        comp, dot, _ = name.partition(".")
        if not dot or comp not in sc.components:
            # Refused (correctness): a warm case cannot change the run's setup: the value would be dropped
            raise SweepError(f"{name}: a scenario key, not a variable of a component ({', '.join(sc.components)}); a "
                             f"warm sweep continues the checkpoint's run as it was from t = {ck.time:g} s and sets "
                             "only component variables settable during a run (tunable parameters, inputs no "
                             "connection drives)")
    return ck, sc


def _warm_system(scenario: Scenario, ck: Checkpoint, fmu_files: dict[tuple[str, bool, int], str]) -> SystemPlan:
    """The warm cases' system, checked against the checkpoint before any case runs (the same components on the same
    FMU files, time grid and algorithm, a stop time after it: :meth:`Checkpoint.check_system`; no FMU
    instantiated). A checkpoint holds its exchanged values by variable, so a case with or without a log takes it."""
    infos = locate_fmus(scenario.structure(), fmu_files)
    plan = build_plan(scenario.structure(), infos, "none")
    ck.check_system(assemble_structure(plan, scenario.structure()), scenario.name)  # buffers, no instance
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
            # Refused (correctness): a value not settable during a run would be dropped
            raise SweepError(f"{why} (a warm sweep sets each case's values at the checkpoint's time, t = {t:g} s, "
                             "as an event)") from None


def run_sweep(scenario: str | Path, cases: list[Case], out: str | Path, *, workers: int | None = None,
              scheduler: str | None = None, logs: bool = False,
              on_progress: Callable[[int, int, int], None] | None = None,
              checkpoint: str | Path | None = None, stop_time: float | None = None) -> SweepSummary:
    """Run ``cases`` of ``scenario`` on worker processes, appending each result to ``out/results.csv``.

    Cases already in the table are skipped. ``workers``: size of the embedded pool of forked workers
    (default: the CPU count); ``scheduler``: address of an existing Dask cluster instead.
    ``on_progress(done, failed, total)`` after each case. Raises :class:`ScenarioError` for a bad
    override name or value (checked for every case before anything runs).

    ``checkpoint``: a warm sweep: every case continues this checkpoint of ``scenario``'s run
    (:mod:`cosim.io.checkpoint`) to ``stop_time`` (s; default: the checkpoint's run's), its values
    (``component.variable``: tunable parameters, inputs no connection drives) set at the checkpoint's
    time; anything else, a checkpoint of another scenario or FMU build, or a stop time not after the
    checkpoint raises before anything runs (SweepError, CheckpointError).
    """

    t_start = time.perf_counter()
    out = output_dir(out)
    path = str(Path(scenario).resolve())
    # read once, every case derived from it (an SSP archive unpacked for the whole sweep: the workers fork from here)
    with exclusive(out, "a sweep"), read_source(path) as source:  # two sweeps appending to one table corrupted it
        return _run_sweep(path, source, cases, out, t_start, workers=workers, scheduler=scheduler, logs=logs,
                          on_progress=on_progress, checkpoint=checkpoint, stop_time=stop_time)


def _run_sweep(scenario: str, source: Any, cases: list[Case], out: Path, t_start: float, *, workers: int | None,
               scheduler: str | None, logs: bool, on_progress: Callable[[int, int, int], None] | None,
               checkpoint: str | Path | None, stop_time: float | None) -> SweepSummary:
    """:func:`run_sweep` in its folder ``out``, held."""
    params = list(dict.fromkeys(k for c in cases for k in c.values))
    ck, warm, loaded = _loaded(source, cases, params, checkpoint, stop_time)
    columns = table_columns(params, metric_names(loaded[0]), warm is not None)
    finished, failed = _finished(out, columns, params, warm, scenario)
    todo = [(c, sc) for c, sc in zip(cases, loaded) if c.id not in finished]
    meta: dict[str, Any] = {"scenario": scenario, "parameters": params, "cases": len(cases)}
    if warm is not None:
        meta["warm_start"] = warm.record()
    with written_by_rename(out / "sweep.json") as tmp:
        tmp.write_text(json.dumps(meta, indent=2), encoding="utf-8")
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
        output_dir(out / "logs")  # a file in its place: one line, not a FileExistsError
    held = Extractions()
    try:
        if cluster.forks:  # the workers fork from here: every case's child finds the FMUs extracted
            extract_for_cases(held, todo[0][1], fmu_files)
        with cluster as (client, label):
            _run_cases(client, todo, fmu_files, out, columns, params, warm, logs,
                       lambda n_done: on_progress(n_done, len(failed), len(cases)) if on_progress else None,
                       len(finished), failed)
            summary.workers = label
    finally:
        cluster.close()
        held.release()
        drop_preloaded()
    summary.wall_time = time.perf_counter() - t_start
    return summary


def extract_for_cases(held: Extractions, scenario: Scenario, fmu_files: dict[tuple[str, bool, int], str]) -> None:
    """Extract ``scenario``'s FMUs here, held by ``held`` until ``held.release()`` (the sweep's end), and load our
    compiled FMUs' libraries (:func:`cosim.fmi.slave.preload`): the forked workers and their cases' children share
    these directories and each child takes the loaded libraries (a case holds the extractions too, so its end removes
    nothing; a case of other FMUs extracts and loads its own, as any run). Extracting and removing each FMU for every
    case cost 30 ms a case or more, binding fmpy's functions about 3 ms an FMU. :func:`drop_preloaded` after."""
    with held:
        for name, info in locate_fmus(scenario.structure(), fmu_files).items():
            if not isinstance(info, FMUInfo):  # a recording replayed as a component: nothing to extract
                continue
            comp = scenario.components[name]
            try:
                info.unzipdir  # noqa: B018 - extracted on first use
                if comp.fmu is not None and not (info.md.generationTool or "").startswith("PythonFMU"):
                    preload(make_slave(name, info, comp.interface))  # ours, C: its library runs nothing at load
            except (CosimError, OSError):  # an archive that does not extract, a library that does not load: each
                continue  # case says so itself


def _loaded(source: Any, cases: list[Case], params: list[str], checkpoint: str | Path | None,
            stop_time: float | None) -> tuple[Checkpoint | None, WarmStart | None, list[Scenario]]:
    """(the checkpoint, the warm start, each case's scenario): a cold sweep's cases each the scenario with their
    values (``source``, the file read once: :func:`cosim.io.ssp.scenario.read_source`), a warm sweep's the checkpoint's scenario (a case's
    values are set during its run)."""
    if checkpoint is None:
        if stop_time is not None:
            # Refused (correctness): a stop time without a checkpoint would be dropped silently
            raise SweepError("stop_time is a warm sweep's (with checkpoint=); a case from t = 0 takes time.stop "
                             "among its values")
        return None, None, [source.load(dotted_overrides(c.values, "sweep case")) for c in cases]
    ck, warm_scenario = _warm_scenario(source, checkpoint, stop_time, params)
    warm = WarmStart(str(Path(ck.path).resolve()), ck.time, file_sha256(ck.path), warm_scenario.time.stop)
    return ck, warm, [warm_scenario] * len(cases)


def _finished(out: Path, columns: list[str], params: list[str], warm: WarmStart | None,
              scenario: str) -> tuple[dict[str, dict[str, str]], dict[str, str]]:
    """The cases ``out``'s table holds already (case -> row) and those of them that failed ("case (values)" ->
    message); a table of another sweep (other columns, or the same columns of another scenario, whose rows were
    appended under its header) is refused."""
    table = out / RESULTS
    done_rows = read_results(out)
    if done_rows and list(done_rows[0]) != columns:
        # Refused (correctness): two sweeps' rows in one table: results would mix
        raise SweepError(f"{table} holds another sweep (columns {', '.join(done_rows[0])}); use another --out")
    before = read_meta(out).get("scenario") if done_rows else None
    if before is not None and before != scenario:
        # Refused (correctness): two sweeps' rows in one table: results would mix
        raise SweepError(f"{table} holds another sweep (of {before}); use another --out")
    if done_rows and warm is not None:
        before = read_meta(out).get("warm_start")
        if before != warm.record():
            # Refused (correctness): two sweeps' rows in one table: results would mix
            raise SweepError(f"{table} holds another sweep ({started(before)}, not {warm.text()} to "
                             f"{warm.stop_time:g} s); use another --out")
    finished = {r["case"]: r for r in done_rows if r["status"] in ("ok", "failed")}
    failed = {f"{cid} ({', '.join(f'{k}={r[k]}' for k in params)})": r["message"] or "acceptance check failed"
              for cid, r in finished.items() if r["status"] == "failed" or r["checks"] == "FAILED"}
    return finished, failed


def _run_cases(client: Any, todo: list[tuple[Case, Scenario]], fmu_files: dict[tuple[str, bool, int], str],
               out: Path, columns: list[str], params: list[str], warm: WarmStart | None, logs: bool,
               progress: Callable[[int], None], n_done: int, failed: dict[str, str]) -> None:
    """Submit ``todo`` to the cluster and append each row to ``out``'s table as it arrives (flushed); a case that
    did not pass goes into ``failed``; ``progress(cases done)`` after each."""
    if isinstance(client, ForkPool):
        as_completed = client.as_completed
    else:
        from distributed import as_completed  # lazy: --help loads this module without it

    table = out / RESULTS
    new = not table.exists() or table.stat().st_size == 0
    with table.open("a", newline="") as f:
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
        for fut in as_completed(futures):
            c = futures[fut]
            try:
                row = fut.result()
            except Exception as exc:  # the task itself was lost (e.g. every worker it ran on died)
                row = {"status": "lost", "message": f"{type(exc).__name__}: {exc}"}
            row = {"case": c.id, **{k: c.values.get(k) for k in params}, **row}
            if warm is not None:
                row.update(start_time_s=warm.time, checkpoint=warm.checkpoint)
            writer.writerow([cell(row.get(k)) for k in columns])
            f.flush()
            n_done += 1
            if row["status"] != "ok":
                who = f"{c.id} ({', '.join(f'{k}={cell(v)}' for k, v in c.values.items())})"
                failed[who] = row["message"] if row["status"] == "failed" else f"{row['status']}: {row['message']}"
            progress(n_done)


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
