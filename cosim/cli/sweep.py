"""``python -m cosim sweep|sweep-report``: a scenario run over a grid or random samples of parameters on worker
processes (:mod:`cosim.analysis.sweep`), and a figure of a sweep's metric against its parameters
(:mod:`cosim.analysis.sweep_report`)."""

from __future__ import annotations

import argparse
import json
from typing import Any, Callable

from ..analysis.limits import MAX_CASES, MAX_WORKERS
from ..errors import file_problem, number_option

__all__ = ["register"]


def register(sub: argparse._SubParsersAction) -> None:
    """The ``sweep`` and ``sweep-report`` commands."""
    p = sub.add_parser("sweep", help="run a scenario over a grid or random samples of parameters, on worker processes",
                       description="Cases: the cartesian product of --grid, each with -n draws of --random. "
                                   "Names as for --set (ctl.gain.kp[1], plant.mass.payload, "
                                   "trajectory.params.rx, time.stop). Results go to DIR/results.csv as they "
                                   "arrive; the same command again skips the finished cases. Exit 1 if a case "
                                   "failed. With --from-checkpoint, every case continues a checkpoint of the "
                                   "scenario's run (run --checkpoint-at) with its values set at the checkpoint's "
                                   "time: only component variables settable during a run (plant.mass.payload).")
    p.add_argument("scenario", help="scenario file (.yaml) or SSP 1.0 archive (.ssp)")
    p.add_argument("--grid", action="append", default=[], metavar="NAME=V1,V2,...", help="values of NAME "
                   "(repeatable: the cartesian product); NAME,NAME2=... sets both to each value (one axis)")
    p.add_argument("--random", action="append", default=[], metavar="NAME=uniform(A,B)|normal(MU,SIGMA)",
                   help="draws of NAME (repeatable; needs -n)")
    p.add_argument("-n", type=number_option(whole=True, ge=1, le=MAX_CASES), default=None, metavar="N", help="number of random draws")
    p.add_argument("--seed", type=number_option(whole=True, ge=0), default=None, help="seed of the random draws (default: fresh each time)")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="fixed override for every case (repeatable)")
    p.add_argument("--stop-time", type=number_option(), help="override time.stop for every case, s")
    p.add_argument("--from-checkpoint", metavar="FILE",
                   help="warm sweep: every case starts from this checkpoint of the scenario's run (written by run "
                        "--checkpoint-at T), its --grid/--random/--set values set at T as run --resume --set does "
                        "(tunable parameters, inputs no connection drives); a case runs only from T to the stop "
                        "time")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--workers", type=number_option(whole=True, ge=1, le=MAX_WORKERS), default=None, metavar="W",
                   help="embedded pool of W worker processes forked from this one, each running one case at a time "
                        "(default: CPU count)")
    g.add_argument("--scheduler", metavar="ADDRESS", help="run on an existing Dask cluster (tcp://host:8786)")
    p.add_argument("--out", required=True, metavar="DIR", help="directory of results.csv (and logs/)")
    p.add_argument("--logs", action="store_true", help="write each case's MCAP log to DIR/logs/<case>.mcap")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="the summary as JSON on stdout")
    p.set_defaults(handler=_cmd_sweep)

    p = sub.add_parser("sweep-report", help="figure of a sweep's metric against its parameters")
    p.add_argument("dir", metavar="DIR", help="the sweep's --out directory")
    p.add_argument("--metric", default="rmse", help="column of results.csv (default rmse: the largest per-axis "
                                                    "RMSE; rmse_x, max_error, peak_effort, wall_time_s, ...)")
    p.add_argument("--out", help="PNG path (default DIR/sweep_<metric>.png)")
    p.set_defaults(handler=_cmd_sweep_report)


def _cmd_sweep(args: argparse.Namespace) -> int:
    from ..analysis.cases import Case, SweepError, make_cases, parse_grid, parse_random
    from ..analysis.results import RESULTS
    from ..analysis.sweep import run_sweep
    from ..engine.overrides import parse_set_value

    problem = file_problem(args.scenario)
    if problem is not None:
        raise SweepError(f"{args.scenario}: {problem.replace('no such file', 'no such scenario file')}")
    fixed: dict[str, Any] = {}
    for item in args.set:
        name, sep, raw = item.partition("=")
        if not sep or not name:
            raise SweepError(f"--set {item}: expected NAME=VALUE")
        fixed[name] = parse_set_value(raw, f"--set {item}")
    warm = args.from_checkpoint is not None
    if args.stop_time is not None and not warm:  # a warm sweep's stop time is the resumed scenario's
        fixed["time.stop"] = args.stop_time
    cases = make_cases(parse_grid(args.grid), parse_random(args.random), args.n, args.seed)
    cases = [Case({**fixed, **c.values}) for c in cases]
    bar = task = None
    progress: Callable[[int, int, int], None] | None = None
    if not (args.quiet or args.json):
        from rich.progress import (
            BarColumn,
            MofNCompleteColumn,
            Progress,
            TextColumn,
            TimeElapsedColumn,
        )

        bar = Progress(TextColumn("[bold]sweep"), BarColumn(), MofNCompleteColumn(),
                       TextColumn("[green]{task.fields[ok]} ok[/] [red]{task.fields[failed]} failed[/] "
                                  "{task.fields[left]} remaining"), TimeElapsedColumn(), transient=True)
        task = bar.add_task("sweep", total=len(cases), ok=0, failed=0, left=len(cases))
        bar.start()

        def show(done: int, failed: int, total: int) -> None:
            bar.update(task, completed=done, ok=done - failed, failed=failed, left=total - done)

        progress = show
    try:
        summary = run_sweep(args.scenario, cases, args.out, workers=args.workers, scheduler=args.scheduler,
                            logs=args.logs, on_progress=progress, checkpoint=args.from_checkpoint,
                            stop_time=args.stop_time if warm else None)
    finally:
        if bar is not None:
            bar.stop()
    if args.json:
        print(json.dumps({"ok": summary.ok, "out": str(summary.out / RESULTS), "total": summary.total,
                          "ran": summary.ran, "skipped": summary.skipped, "failed": summary.failed,
                          "wall_time_s": summary.wall_time,
                          "warm_start": summary.warm.record() if summary.warm is not None else None}, indent=2))
    else:
        print(summary.text())
    return 0 if summary.ok else 1


def _cmd_sweep_report(args: argparse.Namespace) -> int:
    from ..analysis.sweep_report import report

    path = report(args.dir, args.metric, args.out)
    print(f"{args.metric} -> {path}")
    return 0
