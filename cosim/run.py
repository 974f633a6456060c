"""Orchestration: load, pre-flight, locate/build FMUs, instantiate, initialize, loop, summary."""

from __future__ import annotations

import time
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Iterator, Mapping, Sequence

from .engine import plugins, supervision
from .engine.assembly import assemble_structure
from .engine.execution import Execution, Observer, StopRequest
from .engine.names import safe_stem
from .engine.offload import Offload, choose
from .engine.prepare import input_files, prepare
from .engine.events import EventState, event_at, resolve_sets
from .engine.scenario import effective_scenario, load_scenario, scenario_from_data
from .engine.schema import Scenario
from .engine.structure import Acceptance, SystemStructure
from .engine.watchdog import Watchdog, hard_exit
from .errors import CosimError
from .fmi import Extractions, cleanup_extracted
from .io.checkpoint import CheckpointError, default_checkpoint_path, write_checkpoint
from .io.ssp.scenario import ArchiveFile, reopen_archive
from .io.output import OutputError, check_output, claim
from .observers.live import LiveView
from .observers.mcap_log import McapRecorder
from .observers.publish import Publisher
from .observers.realtime import RealTime
from .observers.recorders import ErrorObserver
from .observers.stats import ErrorStats

__all__ = ["RunOptions", "RunResult", "progress_bar", "run_scenario", "resumed_scenario", "resumed"]


@dataclass
class RunResult:
    """What a run produced: timings, errors against the reference, check verdicts, log path."""

    scenario: str
    steps: int
    sim_time: float  # s simulated
    wall_time: float  # s in the loop
    component_time: dict[str, float]  # s per component
    errors: list[ErrorStats] = field(default_factory=list)
    checks: dict[str, dict[str, Any]] = field(default_factory=dict)
    mcap: str | None = None
    status: str = "completed"  # completed (at the stop time) | terminated (an FMU ended it early); failures raise
    message: str = ""
    notes: list[str] = field(default_factory=list)  # e.g. which components ran ahead in a worker process
    worker_time: dict[str, float] = field(default_factory=dict)  # s per component, inside the worker process
    terminated_by: str | None = None  # the component that ended the simulation before the stop time
    events: dict[str, int] = field(default_factory=dict)  # events handled per model-exchange component
    realtime: dict[str, float] = field(default_factory=dict)  # with real-time pacing: factor, lag (cosim.observers.realtime)
    fired: list[dict] = field(default_factory=list)  # the scenario's events that fired: t, event, set
    checkpoint: str | None = None  # the checkpoint written (run --checkpoint-at)

    @property
    def real_time_factor(self) -> float:
        return self.sim_time / self.wall_time if self.wall_time > 0 else float("inf")

    @property
    def passed(self) -> bool:
        return all(c["ok"] for c in self.checks.values())

    def as_dict(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "status": self.status, "message": self.message, "steps": self.steps,
                "sim_time_s": self.sim_time, "wall_time_s": self.wall_time,
                "real_time_factor": self.real_time_factor, "component_time_s": self.component_time,
                "errors": [e.as_dict(*_SUMMARY_KEYS) for e in self.errors], "checks": self.checks, "passed": self.passed,
                "mcap": self.mcap, "notes": self.notes, "worker_time_s": self.worker_time,
                "terminated_by": self.terminated_by, "events": self.events, "realtime": self.realtime,
                "fired": self.fired, "checkpoint": self.checkpoint}


# one compared pair in the run summary (its name is the actual signal; the run's checks are ``checks``)
_SUMMARY_KEYS = ("actual", "reference", "unit", "rmse", "max_error", "t_max", "samples")


@dataclass(frozen=True)
class RunOptions:
    """How to run a scenario (everything but the scenario itself): one record from the CLI, the API, SSP runs
    and sweeps to :func:`run_scenario`, so a new option is one field here, not a parameter threaded through
    every layer.

    ``out``: the log's path (default: the scenario's ``logging.out``, else ``runs/<name>.mcap``);
    ``overrides``: applied when the scenario is given as a path; ``log``: log or not (None: the scenario's
    ``logging.enabled``); ``progress``: a progress bar on long runs; ``observers``: more observers, after ours;
    ``live``: (host, port) of a Foxglove WebSocket server showing the run (:mod:`cosim.observers.live`);
    ``realtime``: pace the run at this many simulated seconds per wall second (:mod:`cosim.observers.realtime`);
    ``stamps``: log times from the run's ``"wall"``-clock start or pure ``"simulation"`` time
    (:mod:`cosim.observers.publish`); ``read_all``: read every output of every component at every step, also
    without a log (for an observer of every signal, :class:`cosim.api.SignalRecorder`); ``fmu_files``: our
    FMUs already built, by :func:`~cosim.engine.prepare.build_key` (a sweep builds them once).
    ``checkpoint_at``: write a checkpoint (:mod:`cosim.io.checkpoint`) when the run reaches this time, s (the
    first grid point at or after it), to ``checkpoint_out`` (default: beside the log, suffix ``.ckpt``);
    ``resume``: a :class:`~cosim.io.checkpoint.Checkpoint` to continue (the scenario must be the one it holds,
    :func:`resumed_scenario`), with ``resume_sets`` (``component.variable: value``) set at its time as an event;
    ``command``: the command line, written into a checkpoint; ``live_wait``: with ``live``, hold the run before it
    sends anything until a viewer subscribes, at most this many s (:mod:`cosim.observers.live`).
    """

    out: str | Path | None = None
    overrides: Mapping | None = None
    log: bool | None = None
    progress: bool = False
    observers: Sequence[Observer] = ()
    live: tuple[str, int] | None = None
    realtime: float | None = None
    stamps: str = "wall"
    read_all: bool = False
    fmu_files: Mapping[Any, str | Path] | None = None
    checkpoint_at: float | None = None
    checkpoint_out: str | Path | None = None
    resume: Any = None
    resume_sets: Mapping[str, Any] | None = None
    command: str = ""
    live_wait: float | None = None


def progress_bar():
    """The progress bar of long commands (rich; transient, so the summary replaces it)."""
    from rich.progress import (  # lazy: --help loads this module without it
        BarColumn,
        Progress,
        TextColumn,
        TimeRemainingColumn,
    )

    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                    TimeRemainingColumn(), transient=True)


def _publishing(system: SystemStructure, mcap_path: Path | None,
                options: RunOptions) -> tuple[list[Observer], Observer | None]:
    """The MCAP recorder and/or the live view on one publisher of the run's channels, in start order,
    and the recorder (None without a log)."""
    scene = plugins.scene(system)
    publisher = Publisher(scene, options.stamps,
                          list(system.tracking.reference) if system.tracking is not None else None,
                          system.log.layout, scene.rate_hz if scene is not None else 30.0)
    sinks: list[Observer] = []
    recorder = None
    if options.live is not None:  # first: a port in use fails before the log file is opened
        host, port = options.live
        sinks.append(LiveView(publisher, port, host, wait=options.live_wait))
    if mcap_path is not None:
        recorder = McapRecorder(mcap_path, publisher, system, system.source, system.log.flush_interval_s)
        sinks.append(recorder)
    return sinks + [publisher], recorder


def check_initialization(system: SystemStructure) -> tuple[Any, str]:
    """What ``check`` does: :func:`~cosim.engine.prepare.prepare`, then every component instantiated and initialized
    as a run does before t = 0 (the FMUs' own parameter checks: a gain, a mass, a geometry, a trajectory they
    refuse), then freed, no step taken. Returns (plan, pre-flight report); raises the run's own error for what it
    refuses at t = 0."""
    with Extractions() as held:
        ex, ended = None, False
        try:
            plan, report = prepare(system)
            supervised = supervision.record()  # python -m cosim check: its supervisor names a crash
            ex = assemble_structure(plan, system, supervised)
            if supervised is not None:
                supervised.describe(names=plan.names, watchdog_s=system.watchdog_s)

            def abort(err: BaseException) -> None:  # a component that never returns from its initialization
                held.release()
                cleanup_extracted()
                hard_exit(err, [])

            stop = StopRequest()
            watchdog = Watchdog(ex, system.watchdog_s, stop, abort)  # as a run's initialization is watched
            with stop, watchdog:
                try:
                    ex.initialize(start_observers=False)
                except BaseException as exc:
                    replaced = watchdog.translate(exc)
                    if replaced is not exc:
                        raise replaced from None
                    raise
            ended, failure = True, ex.end()
            if failure is not None:
                raise failure
        finally:
            if ex is not None and not ended:
                ex.end(terminate=False)
            held.release()
    return plan, report


def run_scenario(scenario: SystemStructure | Scenario | str | Path, options: RunOptions | None = None, /,
                 **changes: Any) -> RunResult:
    """Run a system end to end with ``options`` (a :class:`RunOptions`; keyword ``changes`` replace its
    fields: ``run_scenario(sc, log=False)``). Raises CosimError (bad input, FMU failure, a stalled component:
    StallError) or Interrupted (a KeyboardInterrupt: SIGINT, SIGTERM, SIGHUP).

    The MCAP file, when logging, is finished whatever happens, and the FMUs extracted for the
    run are removed (success, error or Ctrl-C). The log's path is claimed (checked writable, locked,
    written as X.partial) before any FMU is loaded, and the finished log renamed into place at the end
    (see :mod:`cosim.io.output`).

    ``scenario``: the system structure to run (:class:`~cosim.engine.structure.SystemStructure`: from a YAML
    scenario, an SSP archive or code), or a scenario (:class:`~cosim.engine.schema.Scenario`), or a scenario
    file's path (with ``options.overrides``): each is run as its structure.
    """
    options = replace(options or RunOptions(), **changes)
    output = None
    with Extractions() as held:  # this run's FMU extractions (other runs of the process keep theirs)
        try:
            if isinstance(scenario, (str, Path)):
                scenario = load_scenario(scenario, dict(options.overrides) if options.overrides else None)
            system = scenario.structure() if isinstance(scenario, Scenario) else scenario
            logging_on = system.log.enabled if options.log is None else options.log
            output = claim(_log_path(system, options.out), input_files(system)) if logging_on else None
            result = _run_claimed(system, output, held, options)
        except BaseException as exc:
            _name_lost_descriptors(output)
            _conclude(output, exc, held)
            raise
        _conclude(output, None, held)
    return result


def _name_lost_descriptors(output) -> None:
    """A log that could not be finished because a component closed the run's own descriptors (its lock's, the log
    writer's pipe) is said to be so, rather than as the write that failed (``Bad file descriptor``)."""
    if output is not None and output.state not in ("none", "finished") and not output.intact():
        output.state = (f"{output.target}: a component closed the run's own file descriptors (the log's lock and the "
                        "log writer's pipe among them): an FMU must close only the descriptors it opened")


def _log_path(system: SystemStructure, out: str | Path | None) -> Path:
    """``--out``, else the system's log path (``logging.out``, relative to its source's folder), else
    runs/<name>.mcap."""
    if out is not None:
        return Path(out)
    if system.log.out is not None:
        return _tidy((system.base if system.base is not None else Path(".")) / system.log.out)
    return Path("runs") / f"{safe_stem(system.name)}.mcap"


def _tidy(path: Path) -> Path:
    """``path`` without ``..`` steps (``scenarios/../runs/x.mcap`` is ``runs/x.mcap``): relative to the working
    directory when it lies below it, else absolute; resolved through the file system, so symbolic links keep
    their meaning."""
    try:
        full = path.resolve()
    except (OSError, RuntimeError):  # no working directory left, a link loop: as written
        return path
    try:
        return full.relative_to(Path.cwd().resolve())
    except (OSError, ValueError):  # outside the working directory
        return full


def _conclude(output, error: BaseException | None, held: Extractions, offload: Offload | None = None) -> None:
    """The end of every run, the watchdog's hard shutdown included: the log settled (:func:`_settle`),
    the worker process stopped (``offload``: only when the run was abandoned inside a component's
    call; otherwise its proxies stopped it), the FMUs extracted for the run removed (``held``: those
    another run of the process still uses stay)."""
    try:
        _settle(output, error)
    finally:
        if offload is not None:
            offload.close()
        held.release()


def _finish_observers(ex: Execution, error: BaseException | None, recorder, output,
                      hard: bool = False) -> BaseException | None:
    """Finish the started observers with the run's ``error``, in order; returns the error the run ends with.

    The recorder's outcome marks the log (``output.state``: ``"finished"``, or why it could not be
    finished, e.g. a full disk: kept as X.partial); its failure becomes the run's error when the run
    had none, and the observers after it see it. Another observer's CosimError is raised, except in
    the watchdog's hard shutdown (``hard``), where no failure may stop the exit.
    """
    catch = Exception if hard else CosimError
    late: BaseException | None = None  # a signal while another observer finished (the live view's wait)
    for o in ex.started:
        try:
            o.finish(ex, error)
            if o is recorder:
                output.state = "finished"
        except catch as exc:
            if o is recorder:
                output.state = str(exc)
                error = error or exc
            elif not hard:
                raise
        except BaseException as exc:  # noqa: BLE001 - KeyboardInterrupt, Interrupted: raised once the log is done
            if o is recorder:
                raise
            late = late or exc
    if late is not None:
        raise late
    return error


def _settle(output, error: BaseException | None) -> None:
    """A finished log (also one marked error or interrupted) takes its final name; a log never
    started leaves nothing; a log that could not be finished stays as X.partial, and the error says so."""
    if output is None:
        return
    state = output.state
    if state == "finished":
        output.commit()
    elif state == "none":
        output.discard()
    else:
        output.release()

        raise OutputError(f"{state}; the log written so far is kept in {output.partial}: recover it with "
                          f"`python -m cosim recover {output.partial}`") from None


def _checkpointing(ex: Execution, system: SystemStructure, options: RunOptions, output) -> tuple[Any, dict | None]:
    """(macro step, hook) writing ``--checkpoint-at``'s checkpoint after the macro step reaching that time, and a
    record of what it wrote (``path``, ``bytes``, ``t``); (None, None) without the option. Raises CheckpointError for a time outside the run
    or an FMU that cannot serialize its state (before any step)."""
    if options.checkpoint_at is None:
        return None, None
    missing = [n for n, s in zip(ex.plan.names, ex.slaves) if not getattr(s, "can_serialize_state", False)]
    if missing:  # known from the model descriptions: refused before any step
        raise CheckpointError(f"--checkpoint-at: no checkpoint of this system can be written: the state of "
                              f"{', '.join(missing)} cannot be serialized (no canSerializeFMUstate in its FMU)")
    t = float(options.checkpoint_at)
    t_ns = round(t * 1e9)
    first = ex.t_ns(options.resume.k_done) if options.resume is not None else ex.start_ns
    if not first < t_ns <= ex.stop_ns:
        raise CheckpointError(f"--checkpoint-at {t:g} s is outside the run ({first * 1e-9:g} s, "
                              f"{ex.stop_ns * 1e-9:g} s]")
    k_at = -(-(t_ns - ex.start_ns) // ex.step_ns)  # the first grid point at or after t
    k_at = min(k_at, ex.n_steps)
    while ex.t_ns(k_at) < t_ns:  # a grid whose last step is shorter
        k_at += 1
    target = Path(options.checkpoint_out) if options.checkpoint_out is not None else default_checkpoint_path(
        output.target if output is not None else None, safe_stem(system.name))
    if system.document is None:
        raise CheckpointError("--checkpoint-at: this system was made in code: a checkpoint holds the scenario it "
                              "continues, and there is none to record")
    inputs = (*input_files(system), options.resume.path if options.resume is not None else None,
              output.target if output is not None else None)
    check_output(target, inputs)
    record: dict = {}

    def hook(k_done: int) -> None:
        size = write_checkpoint(target, ex, system.recorded(output.target if output is not None else None),
                                options.command, system.ssp)
        record.update(path=str(target), bytes=size, t=ex.t_ns(k_done) * 1e-9)

    return (k_at, hook), record


def _resume_event(ex: Execution, options: RunOptions) -> Any:
    """A resumed run's ``--set`` values as an event at the checkpoint's time (resolved before the run starts)."""
    if options.resume is None or not options.resume_sets:
        return None
    changes = resolve_sets(dict(options.resume_sets), ex.plan)
    return event_at(changes, dict(options.resume_sets), options.resume.t_ns)


def _resume(ex: Execution, system: SystemStructure, checkpoint, event) -> None:
    """Continue from ``checkpoint``: the system checked against it, its state restored, the events' progress taken
    over, the resumed run's ``--set`` fired at its time."""
    checkpoint.check_system(ex, system.name)
    state = checkpoint.restore_into(ex)
    ex.free_state(state)
    if event is not None and ex.events is None:
        ex.events = EventState([])
    if ex.events is not None:
        ex.events.resume(checkpoint.header.get("events"), checkpoint.t_ns)
    if event is not None:
        ex.fire(event, checkpoint.time)


def resumed_scenario(checkpoint, stop_time: float | None = None, scenario: Scenario | None = None,
                     archive: ArchiveFile | None = None) -> Scenario:
    """The scenario a checkpoint holds (as it ran), to ``stop_time`` (default: its own); ``scenario``: the one the
    user named, which must be that one (else CheckpointError: a checkpoint of another scenario).

    A checkpoint of a run read from an SSP archive (:attr:`~cosim.io.checkpoint.Checkpoint.archive`) needs that
    archive unpacked: ``archive`` (the same file, unpacked: :func:`resumed` does it), into which the recorded FMU
    paths are moved."""
    data = dict(checkpoint.scenario)
    ours = checkpoint.archive
    if ours is not None:
        if archive is None:
            # Refused (correctness): the run's FMUs were unpacked for it only: they are gone
            raise CheckpointError(f"{checkpoint.path} is a checkpoint of a run of the SSP archive {ours['file']}: "
                                  "its FMUs are unpacked again from the archive to resume it (cosim.run.resumed)")
        if archive.archive["sha256"] != ours["sha256"]:
            # Refused (correctness): the archive's FMUs and values may not be those the state was saved with
            raise CheckpointError(f"{checkpoint.path} is a checkpoint of a run of the SSP archive {ours['file']} "
                                  f"(SHA-256 {ours['sha256'][:16]}...); {archive.file} is another file "
                                  f"({archive.archive['sha256'][:16]}...)")
        data = archive.adopt(data, ours["unpacked"])
    if scenario is not None:
        mine = effective_scenario(scenario)
        if ours is not None and scenario.archive is not None:  # the named archive's FMUs, where the data's are now
            mine = archive.adopt(mine, scenario.archive["unpacked"])
        theirs = {k: v for k, v in data.items() if k not in ("logging", "time")}
        if {k: v for k, v in mine.items() if k not in ("logging", "time")} != theirs or \
                {k: v for k, v in mine["time"].items() if k != "stop"} != \
                {k: v for k, v in data["time"].items() if k != "stop"}:
            raise CheckpointError(f"{checkpoint.path} is a checkpoint of scenario {data.get('name')!r} as it ran "
                                  f"then; {scenario.source} differs from it: a checkpoint of another scenario")
    if stop_time is not None:
        data["time"] = {**data["time"], "stop": stop_time}
    else:
        data["time"] = {**data["time"], "stop": checkpoint.header["grid"]["stop_ns"] * 1e-9}
    data.get("logging", {}).pop("out", None)  # the resumed run's log is its own (--out, or the default)
    if ours is not None:
        return replace(archive, file=str(checkpoint.path), data=data).load()
    return scenario_from_data(data, str(checkpoint.path))


@contextmanager
def resumed(checkpoint, stop_time: float | None = None, scenario: Scenario | None = None) -> Iterator[Scenario]:
    """:func:`resumed_scenario` for a ``with`` block: a checkpoint of a run read from an SSP archive has the archive
    unpacked again for the block (checked to be the file the run was made from: its SHA-256), as ``run --from-log``
    does (:func:`cosim.io.ssp.scenario.reopen_archive`); ``scenario``, if named, is compared as the run read it."""
    if checkpoint.archive is None:
        yield resumed_scenario(checkpoint, stop_time, scenario)
        return
    with reopen_archive(checkpoint.archive, {}, str(checkpoint.path)) as archive:
        yield resumed_scenario(checkpoint, stop_time, scenario, archive)


def _run_claimed(system: SystemStructure, output, held: Extractions, options: RunOptions) -> RunResult:
    """A run whose log (``output``) is claimed: prepared, assembled, observed, stepped, summarised."""
    logging_on = output is not None
    published = logging_on or options.live is not None  # the log's and the live view's signals: logging.signals
    plan, _ = prepare(system, None if published else ("all" if options.read_all else "none"),
                      fmu_files=options.fmu_files)
    supervised = supervision.record()  # python -m cosim run: the record its supervisor process reads
    ex = assemble_structure(plan, system, supervised)
    if supervised is not None:
        supervised.describe(names=plan.names, watchdog_s=system.watchdog_s, start_s=ex.grid.time(0),
                            step_s=(ex.grid.time(ex.n_steps) - ex.grid.time(0)) / max(1, ex.n_steps),
                            partial=str(output.partial) if output is not None else None,
                            target=str(output.target) if output is not None else None)
    ex.set_events(plan.events)
    checkpoint_hook, checkpoint_path = _checkpointing(ex, system, options, output)
    writer_process = logging_on and McapRecorder.writes_in_a_process(ex.n_steps)  # a writer process takes a CPU
    ahead, note = choose(plan, system.parallel, ex.n_steps, writer_process)
    if ahead and (options.resume is not None or checkpoint_hook is not None):
        # a component in a worker process cannot save its state (events: choose runs them serial already)
        ahead, note = [], (f"parallel: {system.parallel}: serial run (a checkpoint saves every component's state "
                           "in this process)")
    resume_event = _resume_event(ex, options)
    tracking, recorder, pacing = _observe(ex, system, output, options, published)
    loop = _Loop(ex, system, options, output, held, recorder)
    loop.run(ahead, supervised, checkpoint_hook, resume_event)
    result = RunResult(system.name, ex.k_done - loop.k_start, (loop.t_end_ns - ex.t_ns(loop.k_start)) * 1e-9,
                       loop.wall, dict(zip(plan.names, ex.comp_time)),
                       mcap=str(output.target) if output is not None else None,
                       notes=([note] if note else []) + loop.notes,
                       worker_time=loop.offload.worker_time if loop.offload else {})
    _summarise(result, ex, options, checkpoint_path, pacing)
    if tracking is not None:
        result.errors = tracking.result()
        result.checks = acceptance(result.errors, system.acceptance)
    return result


def _observe(ex: Execution, system: SystemStructure, output, options: RunOptions, published: bool):
    """The run's observers, in order: the tracking error, the log and the live view, the caller's, the real-time
    pacing (last: every other observer has seen the step before it waits). Returns (tracking, recorder, pacing),
    each None when absent."""
    tracking = recorder = pacing = None
    if system.tracking is not None:
        tracking = ErrorObserver(list(system.tracking.actual), list(system.tracking.reference))
        ex.add_observer(tracking)
    if published:  # the log and the live view: the same channels (cosim.observers.publish)
        sinks, recorder = _publishing(system, output.partial if output is not None else None, options)
        for o in sinks:
            ex.add_observer(o)
    for o in options.observers:
        ex.add_observer(o)
    if options.realtime is not None:
        pacing = RealTime(options.realtime)
        ex.add_observer(pacing)
    return tracking, recorder, pacing


class _Loop:
    """The stepping of an assembled run: the feed-forward components offloaded, the watchdog, the initialization
    (or the checkpoint's state), the progress bar, the loop, then every component freed and the observers
    finished whatever happened. ``wall``: the loop's wall-clock seconds; ``t_end_ns``, ``k_start``: where it
    ended and started."""

    def __init__(self, ex: Execution, system: SystemStructure, options: RunOptions, output, held: Extractions,
                 recorder) -> None:
        self.ex, self.system, self.options, self.output, self.held, self.recorder = \
            ex, system, options, output, held, recorder
        self.offload: Offload | None = None
        self.notes: list[str] = []  # what the run's summary says of the loop
        self.wall = 0.0
        self.k_start = options.resume.k_done if options.resume is not None else 0

    def abort(self, err: BaseException) -> None:
        """The watchdog's hard shutdown, from its thread: the main thread is stuck inside a component's
        call and cannot unwind. The end of the run without it (the stuck component is never freed),
        then say why and leave the process."""
        _finish_observers(self.ex, err, self.recorder, self.output, hard=True)
        lines = []
        try:
            _conclude(self.output, err, self.held, self.offload)
        except CosimError as exc:
            lines.append(f"error: {exc}")
        cleanup_extracted()  # the process leaves without its exit handlers: other runs' extractions too
        hard_exit(err, lines)

    def run(self, ahead: list[int], supervised, checkpoint_hook, resume_event) -> None:
        ex, options = self.ex, self.options
        error: BaseException | None = None
        t_wall = time.perf_counter()
        t_loop_end: float | None = None
        bar = None
        stop = StopRequest()
        for o in ex.observers:  # --live-wait: a stop signal ends the live view's wait for a viewer
            if isinstance(o, LiveView):
                o.stop_request = stop
        try:
            if ahead:  # proxies take the feed-forward components' places, on the same buffers
                self.offload = Offload(ex, ahead, [ex.slaves[c] for c in ahead])
                for c, proxy in zip(ahead, self.offload.proxies):
                    ex.replace_slave(c, proxy)
            watchdog = Watchdog(ex, self.system.watchdog_s, stop, self.abort)  # after the worker's fork
            with stop, watchdog:
                try:
                    ex.initialize(start_observers=options.resume is None)
                    if options.resume is not None:  # the checkpoint's state, its --set at its time, then the log
                        _resume(ex, self.system, options.resume, resume_event)
                        ex.start_observers()
                    if checkpoint_hook is not None:
                        ex.hooks.setdefault(checkpoint_hook[0], []).append(checkpoint_hook[1])
                    if supervised is not None and self.recorder is not None:
                        supervised.describe(writer_pid=self.recorder.writer_pid)
                    t_wall = time.perf_counter()
                    cb, every = None, 0
                    if options.progress and ex.n_steps >= 1000:
                        bar = progress_bar()
                        bar.start()
                        task = bar.add_task(self.system.name, total=ex.n_steps)
                        every = max(1, ex.n_steps // 200)
                        cb = lambda k: bar.update(task, completed=k)  # noqa: E731
                    ex.simulate_until(None, stop, cb, every)
                    t_loop_end = time.perf_counter()  # the loop's wall time, without the shutdown below
                except BaseException as exc:
                    replaced = watchdog.translate(exc)  # the watchdog's error, when it stopped the run
                    if replaced is not exc:
                        raise replaced from None
                    raise
        except BaseException as exc:  # finish the log on every failure, signals included, then re-raise
            error = exc
            raise
        finally:
            self.wall = (t_loop_end if t_loop_end is not None else time.perf_counter()) - t_wall
            if bar is not None:
                bar.stop()
            ended = ex.end(terminate=error is None)  # every component freed, whatever happened
            error = error or ended
            error = _finish_observers(ex, error, self.recorder, self.output)
        if error is not None:  # a failure at the end (fmi2Terminate, the worker's report) fails the run too
            raise error
        if watchdog.lost:  # the results stand; the run was not guarded from then on
            self.notes.append("a component closed the master's own file descriptors during the run (the watchdog's "
                              "pipe): stop signals and the stall check were not watched from then on; an FMU must "
                              "close only the descriptors it opened")
        self.t_end_ns = ex.t_end_ns if ex.t_end_ns is not None else ex.t_ns(ex.k_done)


def _summarise(result: RunResult, ex: Execution, options: RunOptions, checkpoint_path: dict | None, pacing) -> None:
    """What the summary says besides the figures: events fired and located, the resume, the checkpoint, the
    observers' summaries, the real-time figures, an FMU's end of the simulation."""
    result.events = {n: s.events for n, s in zip(ex.plan.names, ex.slaves) if s.model_exchange}
    if ex.events is not None:
        result.fired = [{"t": e.t, "event": e.event, "set": e.set} for e in ex.events.fired]
        late = [s.index for s in ex.events.timed[ex.events.next_timed:]]
        if late and ex.terminated is None:
            result.notes.append(f"events {', '.join(map(str, late))} come after the stop time: not fired")
        result.notes += ex.events.warnings
        if ex.events.located:
            result.notes.append(f"{ex.events.located} state event(s) located by {ex.events.restarts} re-step(s)")
    if options.resume is not None:
        result.notes.append(f"resumed from {options.resume.path} at t = {options.resume.time:g} s")
    if checkpoint_path is not None:
        result.checkpoint = checkpoint_path.get("path")
        if result.checkpoint is None:
            result.notes.append("no checkpoint written: the run ended before its time")
        else:
            result.notes.append(f"checkpoint at t = {checkpoint_path['t']:g} s: {result.checkpoint} "
                                f"({checkpoint_path['bytes']} bytes)")
    result.notes += [o.summary() for o in ex.observers if hasattr(o, "summary")]  # live view, real time
    if pacing is not None:
        result.realtime = pacing.figures()
    if ex.terminated is not None:  # an FMU ended the simulation: a normal end, said in the summary
        result.status = "terminated"
        result.message = str(ex.terminated)
        result.terminated_by = ex.terminated.component


def acceptance(errors: list, checks: Acceptance | None) -> dict[str, dict[str, Any]]:
    """The system's acceptance checks (a scenario's ``checks:``) on the tracking ``errors``: each limit, the worst
    value, ok."""
    out: dict[str, dict[str, Any]] = {}
    if checks is None:
        return out
    worst_rmse = max(e.rmse for e in errors)
    worst_max = max(e.max_error for e in errors)
    if checks.max_rmse is not None:
        out["max_rmse"] = {"limit": checks.max_rmse, "value": worst_rmse, "ok": worst_rmse <= checks.max_rmse}
    if checks.max_error is not None:
        out["max_error"] = {"limit": checks.max_error, "value": worst_max, "ok": worst_max <= checks.max_error}
    return out
