"""``python -m cosim run|check|schema|recover``: a scenario's run (YAML, SSP archive, a run's log or a checkpoint),
its checks before t = 0, the scenario schema, and an unfinished log made whole."""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import shlex
import sys
from pathlib import Path

from ..errors import CosimError, number_option
from .common import EXIT_CHECK_FAILED, EXIT_OK, NUMBER, emit

__all__ = ["LIVE_WAIT_S", "register"]

LIVE_WAIT_S = 60.0
"""s ``run --live-wait`` waits at most for a viewer when no SECONDS are given; then the run goes on without one."""


def register(sub: argparse._SubParsersAction) -> None:
    """The ``run``, ``check``, ``schema`` and ``recover`` commands; run and check are supervised (they load FMUs:
    the supervisor names a crash inside one)."""
    p = sub.add_parser("run", help="run a co-simulation scenario (YAML or SSP archive) and log it to MCAP")
    p.add_argument("scenario", nargs="?", help="scenario file (.yaml) or SSP 1.0 archive (.ssp)")
    p.add_argument("--from-log", metavar="LOG", help="instead of a scenario file: run again the scenario a run's "
                                                     ".mcap log records, as it ran (every override applied)")
    p.add_argument("--out", help="MCAP output path (default: the scenario's logging.out or runs/<name>.mcap; with "
                                 "--from-log LOG, LOG's name with .rerun.mcap; with --resume FILE, FILE's with "
                                 ".resumed.mcap)")
    p.add_argument("--stop-time", type=NUMBER, help="override time.stop, s")
    p.add_argument("--step", type=NUMBER, help="override time.step (the base communication step), s")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name (repeatable): a component parameter (ctl.gain.kp[1]=4e4), the trajectory (trajectory.params.rx=0.05), the time grid (time.stop=0.5), any scenario key")
    p.add_argument("--no-log", action="store_true", help="do not write an MCAP file")
    p.add_argument("--parallel", choices=("auto", "on", "off"),
                   help="override the scenario's parallel: run the feed-forward components (e.g. trajectory, IK) "
                        "ahead in a worker process (same values as serial)")
    p.add_argument("--live", nargs="?", const="8765", default=None, metavar="PORT",
                   help="serve the run over the Foxglove WebSocket protocol on PORT or HOST:PORT (default 8765, "
                        "localhost): the log's channels and 3D scene while it runs; the log is still written")
    p.add_argument("--live-wait", nargs="?", const=LIVE_WAIT_S, type=number_option(gt=0), metavar="SECONDS",
                   help="with --live: start stepping once a viewer has subscribed, so it misses nothing; at most "
                        f"SECONDS (default {LIVE_WAIT_S:g}), then the run goes on without one")
    p.add_argument("--realtime", nargs="?", const="1", default=None, metavar="FACTOR",
                   help="pace simulated time to the wall clock, FACTOR simulated s per wall s (default 1); "
                        "the summary gives the achieved factor and the lag")
    p.add_argument("--sim-stamps", action="store_true",
                   help="log times in pure simulation time (default: from the run's wall-clock start, so viewers "
                        "show the real date; the message field t is simulation time either way)")
    p.add_argument("--watchdog", type=number_option(ge=0), metavar="SECONDS",
                   help="override watchdog_s: wall-clock seconds a step may take before the run stops naming the "
                        "stalled component (0: no limit)")
    p.add_argument("--checkpoint-at", type=number_option(ge=0), metavar="T",
                   help="write a checkpoint (every component's state, the scenario as run) when the run reaches "
                        "simulation time T, s (the first grid point at or after it)")
    p.add_argument("--checkpoint-out", metavar="FILE",
                   help="the checkpoint's path (default: beside the log, suffix .ckpt)")
    p.add_argument("--resume", metavar="FILE",
                   help="continue the run a checkpoint holds from its time (to its stop time unless --stop-time); "
                        "--set NAME=VALUE then sets component.variable at that time, as an event; a scenario file "
                        "given too must be the checkpoint's")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary")
    p.add_argument("--json", action="store_true", help="summary as JSON on stdout")
    p.set_defaults(handler=_cmd_run, supervised=True)

    p = sub.add_parser("check", help="validate a scenario (YAML or SSP) and run the pre-flight only")
    p.add_argument("scenario")
    p.add_argument("--set", action="append", default=[], metavar="NAME=VALUE",
                   help="override by dotted name (repeatable): a component parameter (ctl.gain.kp[1]=4e4), the trajectory (trajectory.params.rx=0.05), the time grid (time.stop=0.5), any scenario key")
    p.add_argument("--stop-time", type=NUMBER, help="override time.stop, s")
    p.add_argument("--step", type=NUMBER, help="override time.step, s")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_check, supervised=True)

    p = sub.add_parser("schema", help="print the scenario JSON Schema (for editors)")
    p.set_defaults(handler=_cmd_schema)

    p = sub.add_parser("recover", help="rewrite an unfinished MCAP log into a valid, indexed one")
    p.add_argument("file")
    p.add_argument("--out", help="output path (default: FILE with .recovered.mcap)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(handler=_cmd_recover)


def _summary_text(res) -> str:
    lines = [f"{res.scenario}: {res.status}{(' - ' + res.message) if res.message else ''}",
             f"  {res.steps} steps, {res.sim_time:.4g} s simulated in {res.wall_time:.3f} s wall "
             f"(real-time factor {res.real_time_factor:.3g})"]
    total = sum(res.component_time.values()) or 1.0
    share = ", ".join(f"{n} {100 * t / res.wall_time if res.wall_time else 0:.0f}%"
                      for n, t in sorted(res.component_time.items(), key=lambda kv: -kv[1]))
    lines.append(f"  time share: {share}, master {100 * max(0.0, 1 - total / res.wall_time) if res.wall_time else 0:.0f}%")
    lines += [f"  {note}" for note in res.notes]
    if res.events:
        lines.append("  model-exchange events: " + ", ".join(f"{n} {k}" for n, k in res.events.items()))
    if res.worker_time:
        lines.append("  in the worker process (overlapped with the master): "
                     + ", ".join(f"{n} {t:.3f} s" for n, t in res.worker_time.items()))
    for e in res.errors:
        lines.append(f"  {e.actual} vs {e.reference}: RMSE {e.rmse:.4g}, max error {e.max_error:.4g}")
    for name, c in res.checks.items():
        lines.append(f"  check {name}: {c['value']:.4g} {'<=' if c['ok'] else '>'} {c['limit']:g} "
                     f"{'ok' if c['ok'] else 'FAILED'}")
    if res.mcap:
        lines.append(f"  log: {res.mcap}")
    return "\n".join(lines)


def _open_system(args: argparse.Namespace, overrides: dict):
    """The system structure of a YAML scenario, of an SSP archive or of a run's log, for a ``with`` block (an archive
    is unpacked for the block only)."""
    from contextlib import nullcontext

    from ..engine.scenario import load_scenario
    from ..io.ssp.spec import is_ssp

    if args.step is not None:
        overrides.put(("time", "step"), args.step, f"--step {args.step:g}")
    from_log = getattr(args, "from_log", None)
    if (from_log is None) == (args.scenario is None):
        raise CosimError("run takes a scenario file or --from-log LOG, not both" if from_log else
                         "run needs a scenario file (or --from-log LOG: a run's log)")
    if from_log is not None:
        from ..io.runlog import open_from_log

        return open_from_log(from_log, overrides)
    if is_ssp(args.scenario):
        from ..io.ssp.scenario import open_ssp

        return open_ssp(args.scenario, overrides)
    return nullcontext(load_scenario(args.scenario, overrides).structure())


@contextlib.contextmanager
def _stdout_kept_for_json(on: bool):
    """With ``--json``, what the run's FMUs (and worker processes) write to standard output goes to standard error
    until the run is over, so the JSON on stdout stays the only thing there (issue 25: an FMU printing broke it)."""
    if not on:
        yield
        return
    sys.stdout.flush()
    saved = os.dup(1)
    os.dup2(2, 1)
    try:
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        sys.stdout.flush()
        os.dup2(saved, 1)
        os.close(saved)


def _cmd_run(args: argparse.Namespace) -> int:
    from ..engine.overrides import apply_overrides
    from ..run import run_scenario

    overrides = apply_overrides(args.set, args.stop_time)
    if args.parallel:
        overrides.put(("parallel",), args.parallel, f"--parallel {args.parallel}")
    if args.watchdog is not None:
        overrides.put(("watchdog_s",), args.watchdog if args.watchdog > 0 else None, f"--watchdog {args.watchdog:g}")
    live = realtime = None
    if args.live is not None:
        from ..observers.live import parse_address

        live = parse_address(args.live)
    elif args.live_wait is not None:
        raise CosimError("--live-wait waits for a viewer of the live view: it needs --live [PORT]")
    if args.realtime is not None:
        from ..observers.realtime import parse_factor

        realtime = parse_factor(args.realtime)
    command = " ".join(["python -m cosim", *(shlex.quote(a) for a in sys.argv[1:])])
    if args.from_log is not None and args.out is None:  # beside the log, never over it (its scenario's default)
        args.out = str(Path(args.from_log).with_name(Path(args.from_log).stem + ".rerun.mcap"))
    if args.resume is not None:
        with _stdout_kept_for_json(args.json):
            res = _resume_run(args, live, realtime, command)
    else:
        with _stdout_kept_for_json(args.json), _open_system(args, overrides) as system:
            res = run_scenario(system, out=args.out, log=False if args.no_log else None,
                               progress=not (args.quiet or args.json), live=live, realtime=realtime,
                               stamps="simulation" if args.sim_stamps else "wall", checkpoint_at=args.checkpoint_at,
                               checkpoint_out=args.checkpoint_out, command=command, live_wait=args.live_wait)
    if args.json:
        print(json.dumps(res.as_dict(), indent=2))
    elif not args.quiet:
        print(_summary_text(res))
    return EXIT_OK if res.passed else EXIT_CHECK_FAILED


def _resume_run(args: argparse.Namespace, live, realtime, command: str):
    """``run --resume FILE``: the checkpoint's scenario (``--stop-time`` moves its end; a scenario file given too
    must be the checkpoint's), its state restored, ``--set`` values set at its time."""
    from ..engine.overrides import parse_set_value
    from ..io.checkpoint import read_checkpoint
    from ..io.ssp.scenario import read_source
    from ..run import resumed, run_scenario

    if args.from_log is not None:
        raise CosimError("run takes --resume FILE or --from-log LOG, not both")
    for option, value in (("--step", args.step), ("--parallel", args.parallel), ("--watchdog", args.watchdog)):
        if value is not None:
            raise CosimError(f"{option} cannot change a resumed run: it continues the checkpoint's run as it was")
    checkpoint = read_checkpoint(args.resume)
    sets = {}
    for item in args.set:
        name, sep, raw = item.partition("=")
        if not sep or not name.strip():
            raise CosimError(f"--set {item}: expected component.variable=VALUE")
        sets[name.strip()] = parse_set_value(raw, f"--set {item}")
    out = args.out if args.out is not None else Path(checkpoint.path).with_suffix(".resumed.mcap")
    with contextlib.ExitStack() as stack:
        named = None
        if args.scenario is not None:  # must be the one the checkpoint holds
            named = stack.enter_context(read_source(args.scenario)).load()
        scenario = stack.enter_context(resumed(checkpoint, args.stop_time, named))
        return run_scenario(scenario, out=out, log=False if args.no_log else None,
                            progress=not (args.quiet or args.json), live=live, realtime=realtime,
                            stamps="simulation" if args.sim_stamps else "wall", resume=checkpoint, resume_sets=sets,
                            checkpoint_at=args.checkpoint_at, checkpoint_out=args.checkpoint_out, command=command,
                            live_wait=args.live_wait)


def _cmd_check(args: argparse.Namespace) -> int:
    from ..engine.offload import choose
    from ..engine.overrides import apply_overrides
    from ..run import check_initialization

    with _open_system(args, apply_overrides(args.set, args.stop_time)) as system:
        plan, report = check_initialization(system)  # the checks a run makes before t = 0, FMUs' own included
    order = " -> ".join(plan.names[c] for c in plan.order)
    from ..observers.mcap_log import McapRecorder

    n_steps = system.n_steps()  # a logged run of these steps writes through a writer process (cosim.observers.mcap_log)
    _, parallel = choose(plan, system.parallel, n_steps,
                         system.log.enabled and McapRecorder.writes_in_a_process(n_steps))
    payload = {"scenario": system.name, "ok": True, "preflight": report, "order": [plan.names[c] for c in plan.order],
               "connections": len(plan.links), "parallel": parallel}
    emit(args, payload, f"{system.name}: ok\n  pre-flight: {report}\n  order: {order}\n"
                         f"  {len(plan.links)} connections" + (f"\n  {parallel}" if parallel else ""))
    return EXIT_OK


def _cmd_schema(args: argparse.Namespace) -> int:
    from ..engine.schema import scenario_json_schema

    print(json.dumps(scenario_json_schema(), indent=2))
    return EXIT_OK


def _cmd_recover(args: argparse.Namespace) -> int:
    from ..io.recover import recover

    rep = recover(args.file, args.out)
    emit(args, rep.as_dict(), f"recovered {rep.messages} messages on {rep.channels} channels "
                               f"({rep.attachments} attachments, {rep.metadata} metadata) -> {rep.out}")
    return EXIT_OK
