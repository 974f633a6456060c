"""Orchestration: load, pre-flight, locate/build FMUs, instantiate, initialize, loop, summary."""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping, Sequence

from .algorithm import Observer, Runtime, StopRequest, initialize, simulate
from .errors import ComponentSourceError, CosimError, Issue
from .fmu import Extractions, FMUInfo, cleanup_extracted, load_fmu, make_slave
from .observers import ErrorObserver
from .offload import Offload, choose
from .scenario import Scenario, line_for, expand_signal, load_scenario
from .stats import ErrorStats
from .watchdog import Watchdog, hard_exit

__all__ = ["RunResult", "progress_bar", "locate_fmus", "prepare", "run_scenario", "check_scenario"]


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
    status: str = "completed"  # completed | interrupted | error
    message: str = ""
    notes: list[str] = field(default_factory=list)  # e.g. which components ran ahead in a worker process
    worker_time: dict[str, float] = field(default_factory=dict)  # s per component, inside the worker process
    terminated_by: str | None = None  # the component that ended the simulation before the stop time
    events: dict[str, int] = field(default_factory=dict)  # events handled per model-exchange component
    realtime: dict[str, float] = field(default_factory=dict)  # with real-time pacing: factor, lag (cosim.realtime)

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
                "terminated_by": self.terminated_by, "events": self.events, "realtime": self.realtime}


# one compared pair in the run summary (its name is the actual signal; the run's checks are ``checks``)
_SUMMARY_KEYS = ("actual", "reference", "unit", "rmse", "max_error", "t_max", "samples")


def progress_bar():
    """The progress bar of long commands (rich; transient, so the summary replaces it)."""
    from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

    return Progress(TextColumn("[bold]{task.description}"), BarColumn(), TextColumn("{task.percentage:>3.0f}%"),
                    TimeRemainingColumn(), transient=True)


def locate_fmus(scenario: Scenario, fmu_files: Mapping[str, str | Path] | None = None) -> dict[str, FMUInfo]:
    """Each component's FMU: ``path`` relative to the scenario file, or ``fmu`` built by fmus.registry.

    ``fmu_files``: our FMUs already built, by :func:`build_key` (a sweep builds them once for every case);
    the others are built here.
    """
    base = _scenario_dir(scenario)
    lines = scenario._lines
    infos: dict[str, FMUInfo] = {}
    issues: list[Issue] = []
    built = {k: Path(p) for k, p in (fmu_files or {}).items()}
    for name, comp in scenario.components.items():
        loc = ("components", name, "fmu" if comp.fmu else "path")
        where = dict(file=scenario.source, line=line_for(loc, lines))
        try:
            if comp.path is not None:
                path = Path(comp.path)
                path = path if path.is_absolute() else base / path
                if not path.exists():
                    issues.append(Issue(f"components.{name}.path", f"FMU file not found: {path}", **where))
                    continue
            else:
                key = build_key(scenario, comp.fmu)
                if key not in built:
                    built[key] = build_ours(*key)
                path = built[key]
            infos[name] = load_fmu(path)
        except ComponentSourceError as exc:
            issues += [Issue(f"components.{name}", i.message, **where) for i in exc.issues]
    if issues:
        raise ComponentSourceError(issues)
    return infos


def input_files(scenario: Scenario) -> tuple[Path, ...]:
    """The files a run of ``scenario`` reads: its file (or archive) and the FMUs its components give by ``path``;
    no output may be written over one of them."""
    base = _scenario_dir(scenario)
    paths = [Path(c.path) if Path(c.path).is_absolute() else base / c.path
             for c in scenario.components.values() if c.path is not None]
    return tuple(Path(p) for p in (scenario.source, *paths) if p is not None and p != "<string>")


def _scenario_dir(scenario: Scenario) -> Path:
    return Path(scenario.source).parent if scenario.source and scenario.source != "<string>" else Path.cwd()


def build_key(scenario: Scenario, name: str) -> tuple[str, bool, int]:
    """(FMU name, native, FMI version) of our FMU ``name`` in ``scenario``: the native build where the scenario asks
    for it (``fmus: native``, or ``auto`` with a C compiler on this machine) and the FMU has one, else the python
    build (FMI 2 co-simulation, or 3 for ``*_me``)."""
    if scenario.fmus == "python":
        return name, False, 2
    from fmus import registry

    if name not in registry.native_names():
        return name, False, 2
    if scenario.fmus == "auto":
        from fmus.native.build import compiler
        from fmus.native.errors import CompilerMissingError

        try:
            compiler()
        except CompilerMissingError:
            return name, False, 2
    return name, True, scenario.native_fmi


def build_ours(name: str, native: bool = False, fmi: int = 2) -> Path:
    """Our FMU ``name``, built (or taken from the cache): the python build, or with ``native`` the C build for FMI
    ``fmi``. A native build that cannot be made (no C compiler) is one line naming what is missing."""
    try:
        from fmus import registry
    except ImportError:
        raise ComponentSourceError(Issue("", f"fmu: {name}: our FMU registry (fmus.registry) is not available; "
                                             "give 'path' to an .fmu instead")) from None
    try:
        return Path(registry.build(name, native=native, fmi=fmi))
    except (KeyError, ValueError, LookupError) as exc:
        known = getattr(registry, "names", None)
        hint = f"; known: {', '.join(known())}" if callable(known) else ""
        raise ComponentSourceError(Issue("", f"unknown FMU {name!r}: {exc}{hint}")) from None


def prepare(scenario: Scenario, log_signals: str | None = None, *,
            fmu_files: Mapping[str, str | Path] | None = None):
    """Pre-flight and plan (no FMU instantiated): returns (plan, preflight report).

    With a ``trajectory:`` section, our trajectory FMUs get their parameters from it.
    ``log_signals`` overrides ``logging.signals`` (:func:`cosim.system.build_plan`);
    ``fmu_files``: our FMUs already built (:func:`locate_fmus`).
    """
    from .preflight import initial_state_values, preflight, trajectory_start_values
    from .system import build_plan

    trajectory_values = trajectory_start_values(scenario)  # our trajectory FMUs follow the scenario's section
    report = preflight(scenario)
    infos = locate_fmus(scenario, fmu_files)
    plan = build_plan(scenario, infos, log_signals)
    for name, values in trajectory_values.items():
        c = plan.names.index(name)
        plan.start_values[c] = {**values, **plan.start_values[c]}  # explicit ones are equal (checked)
    init = initial_state_values(scenario)
    if init:
        c = plan.names.index(scenario.initial_state.component)
        variables = plan.infos[c].variables
        missing = [n for n in init if n not in variables]
        if missing:
            from .errors import ScenarioError

            raise ScenarioError(Issue("initial_state", f"{scenario.initial_state.component} has no "
                                      f"{', '.join(missing)} (set initial_state.position/velocity to its start "
                                      f"parameters, or from_trajectory: false)", scenario.source))
        plan.start_values[c] = {**init, **plan.start_values[c]}  # explicit parameters win
    return plan, report


def _publishing(scenario: Scenario, mcap_path: Path | None, live: tuple[str, int] | None,
                stamps: str) -> tuple[list[Observer], Observer | None]:
    """The MCAP recorder and/or the live view on one publisher of the run's channels, in start order,
    and the recorder (None without a log)."""
    from .publish import Publisher, reference_path

    robot = None
    scene = scenario.logging.scene
    if scene is not None and scenario.robot:
        from delta.robots import get_preset

        robot = get_preset(scenario.robot)
    publisher = Publisher(robot, expand_signal(scene.position) if scene else None, scene.rate_hz if scene else 30.0,
                          stamps, reference_path(scenario) if robot is not None else None,
                          expand_signal(scenario.compare.reference) if scenario.compare is not None else None,
                          scenario.logging.layout)
    sinks: list[Observer] = []
    recorder = None
    if live is not None:  # first: a port in use fails before the log file is opened
        from .live import LiveView

        sinks.append(LiveView(publisher, live[1], live[0]))
    if mcap_path is not None:
        from .mcap_log import McapRecorder

        recorder = McapRecorder(mcap_path, publisher, scenario, scenario.source, scenario.logging.flush_interval)
        sinks.append(recorder)
    return sinks + [publisher], recorder


def check_scenario(path: str | Path, overrides: dict | None = None) -> tuple[Scenario, Any, str]:
    """Validate the scenario, resolve its FMUs and wiring and run the pre-flight."""
    scenario = load_scenario(path, overrides)
    plan, report = prepare(scenario)
    return scenario, plan, report


def check_initialization(scenario: Scenario) -> tuple[Any, str]:
    """What ``check`` does: :func:`prepare`, then every component instantiated and initialized as a run does before
    t = 0 (the FMUs' own parameter checks: a gain, a mass, a geometry, a trajectory they refuse), then freed, no
    step taken. Returns (plan, pre-flight report); raises the run's own error for what it refuses at t = 0."""
    with Extractions() as held:
        slaves = []
        try:
            plan, report = prepare(scenario)
            comps = scenario.components
            for i, n in enumerate(plan.names):
                slaves.append(make_slave(n, plan.infos[i], comps[n].interface, comps[n].rtol, comps[n].solver,
                                         comps[n].max_step))
                slaves[-1].bind(plan.inputs[i], plan.outputs[i])
            rt = Runtime(plan, slaves, scenario.time.start_ns, scenario.time.stop_ns, scenario.time.step_ns,
                         [comps[n].step_multiple for n in plan.names], scenario.algorithm)
            initialize(rt)
            for s in slaves:
                s.terminate()
        finally:
            for s in slaves:
                s.free()
            held.release()
    return plan, report


def run_scenario(scenario: Scenario | str | Path, out: str | Path | None = None, overrides: dict | None = None,
                 log: bool | None = None, progress: bool = False, extra_observers: Sequence[Observer] = (),
                 live: tuple[str, int] | None = None, realtime: float | None = None, stamps: str = "wall", *,
                 read_all: bool = False, fmu_files: Mapping[str, str | Path] | None = None) -> RunResult:
    """Run a scenario end to end. Raises CosimError (bad input, FMU failure, a stalled component:
    StallError) or Interrupted (a KeyboardInterrupt: SIGINT, SIGTERM).

    The MCAP file, when logging, is finished whatever happens, and the FMUs extracted for the
    run are removed (success, error or Ctrl-C). ``live``: (host, port) of a Foxglove WebSocket
    server showing the run (:mod:`cosim.live`); ``realtime``: pace the run at this many simulated
    seconds per wall second (:mod:`cosim.realtime`); ``stamps``: log times from the run's
    ``"wall"``-clock start or pure ``"simulation"`` time (:mod:`cosim.publish`).
    ``read_all``: read every output of every component at every step, also without a log (for
    an observer of every signal, :class:`cosim.api.SignalRecorder`); ``fmu_files``: our FMUs
    already built, by name (:func:`locate_fmus`).

    The log's path is claimed (checked writable, locked, written as X.partial) before any FMU is
    loaded, and the finished log renamed into place at the end (see :mod:`cosim.output`).
    """
    from .output import claim

    output = None
    with Extractions() as held:  # this run's FMU extractions (other runs of the process keep theirs)
        try:
            if not isinstance(scenario, Scenario):
                scenario = load_scenario(scenario, overrides)
            logging_on = scenario.logging.enabled if log is None else log
            output = claim(_log_path(scenario, out), input_files(scenario)) if logging_on else None
            result = _run_claimed(scenario, output, held, progress, extra_observers, live, realtime, stamps,
                                  read_all, fmu_files)
        except BaseException as exc:
            _conclude(output, exc, held)
            raise
        _conclude(output, None, held)
    return result


def _log_path(scenario: Scenario, out: str | Path | None) -> Path:
    """``--out``, else the scenario's ``logging.out`` (relative to the scenario file), else runs/<name>.mcap."""
    if out is not None:
        return Path(out)
    if scenario.logging.out is not None:
        base = Path(scenario.source).parent if scenario.source and scenario.source != "<string>" else Path(".")
        return base / scenario.logging.out
    return Path("runs") / f"{safe_stem(scenario.name)}.mcap"


def safe_stem(name: str) -> str:
    """``name`` as a file name in a folder of ours: letters, digits, ``.``, ``_`` and ``-`` kept, any other character
    ``_``, no leading dot (an SSP's system named ``../../x`` must not put its log outside ``runs/``)."""
    stem = "".join(c if c.isalnum() or c in "._-" else "_" for c in name).lstrip(".")
    return stem or "run"


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


def _finish_observers(started: Sequence[Observer], rt: Runtime, error: BaseException | None, recorder,
                      output, hard: bool = False) -> BaseException | None:
    """Finish the started observers with the run's ``error``, in order; returns the error the run ends with.

    The recorder's outcome marks the log (``output.state``: ``"finished"``, or why it could not be
    finished, e.g. a full disk: kept as X.partial); its failure becomes the run's error when the run
    had none, and the observers after it see it. Another observer's CosimError is raised, except in
    the watchdog's hard shutdown (``hard``), where no failure may stop the exit.
    """
    catch = Exception if hard else CosimError
    late: BaseException | None = None  # a signal while another observer finished (the live view's wait)
    for o in started:
        try:
            o.finish(rt, error)
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
        from .output import OutputError

        raise OutputError(f"{state}; the log written so far is kept in {output.partial}: recover it with "
                          f"`python -m cosim recover {output.partial}`") from None


def _run_claimed(scenario: Scenario, output, held: Extractions, progress: bool, extra_observers: Sequence[Observer],
                 live: tuple[str, int] | None, realtime: float | None, stamps: str, read_all: bool,
                 fmu_files: Mapping[str, str | Path] | None) -> RunResult:
    logging_on = output is not None
    published = logging_on or live is not None  # the log's and the live view's signals: logging.signals
    plan, _ = prepare(scenario, None if published else ("all" if read_all else "none"), fmu_files=fmu_files)
    comps = scenario.components
    slaves = [make_slave(n, plan.infos[i], comps[n].interface, comps[n].rtol, comps[n].solver, comps[n].max_step)
              for i, n in enumerate(plan.names)]
    for c, s in enumerate(slaves):
        s.bind(plan.inputs[c], plan.outputs[c])
    rt = Runtime(plan, slaves, scenario.time.start_ns, scenario.time.stop_ns, scenario.time.step_ns,
                 [scenario.components[n].step_multiple for n in plan.names], scenario.algorithm)
    writer_process = False  # the log written by a writer process (as McapRecorder decides): it takes a CPU
    if logging_on:
        from .mcap_log import McapRecorder

        writer_process = rt.n_steps >= McapRecorder.PROCESS_MIN_STEPS
    ahead, note = choose(plan, scenario.parallel, rt.n_steps, writer_process)
    offload: Offload | None = None
    observers: list[Observer] = []
    tracking = None
    if scenario.compare is not None:
        tracking = ErrorObserver(expand_signal(scenario.compare.actual), expand_signal(scenario.compare.reference))
        observers.append(tracking)
    mcap_path = output.target if output is not None else None
    recorder = None
    if published:  # the log and the live view: the same channels (cosim.publish)
        sinks, recorder = _publishing(scenario, output.partial if output is not None else None, live, stamps)
        observers += sinks
    pacing = None
    if realtime is not None:
        from .realtime import RealTime

        pacing = RealTime(realtime)
    observers += list(extra_observers)
    if pacing is not None:  # last: every other observer has seen the step before it waits
        observers.append(pacing)
    started: list[Observer] = []
    error: BaseException | None = None
    t_wall = time.perf_counter()
    t_loop_end: float | None = None
    bar = None
    stop = StopRequest()

    def abort(err: BaseException) -> None:
        """The watchdog's hard shutdown, from its thread: the main thread is stuck inside a component's
        call and cannot unwind. The end of the run without it (the stuck component is never freed),
        then say why and leave the process."""
        _finish_observers(started, rt, err, recorder, output, hard=True)
        lines = []
        try:
            _conclude(output, err, held, offload)
        except CosimError as exc:
            lines.append(f"error: {exc}")
        cleanup_extracted()  # the process leaves without its exit handlers: other runs' extractions too
        hard_exit(err, lines)

    try:
        if ahead:  # proxies take the feed-forward components' places, on the same buffers
            offload = Offload(plan, ahead, [slaves[c] for c in ahead], rt.multiples, rt.start_ns, rt.stop_ns,
                              rt.step_ns, rt.algorithm)
            for c, proxy in zip(ahead, offload.proxies):
                slaves[c] = proxy
        watchdog = Watchdog(rt, scenario.watchdog_s, stop, abort)  # after the worker's fork: a thread of its own
        with stop, watchdog:
            try:
                initialize(rt)
                for o in observers:
                    o.start(rt)
                    started.append(o)
                t_wall = time.perf_counter()
                cb, every = None, 0
                if progress and rt.n_steps >= 1000:
                    bar = progress_bar()
                    bar.start()
                    task = bar.add_task(scenario.name, total=rt.n_steps)
                    every = max(1, rt.n_steps // 200)
                    cb = lambda k: bar.update(task, completed=k)  # noqa: E731
                simulate(rt, observers, stop, cb, every)
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
        wall = (t_loop_end if t_loop_end is not None else time.perf_counter()) - t_wall
        if bar is not None:
            bar.stop()
        for s in slaves:
            try:
                if error is None:
                    s.terminate()
            except CosimError as exc:
                error = error or exc
            finally:
                s.free()
        error = _finish_observers(started, rt, error, recorder, output)
    if error is not None:  # a failure at the end (fmi2Terminate, the worker's report) fails the run too
        raise error
    t_end_ns = rt.t_end_ns if rt.t_end_ns is not None else rt.t_ns(rt.k_done)
    result = RunResult(scenario.name, rt.k_done, (t_end_ns - rt.start_ns) * 1e-9, wall,
                       dict(zip(plan.names, rt.comp_time)), mcap=str(mcap_path) if mcap_path else None,
                       notes=[note] if note else [], worker_time=offload.worker_time if offload else {})
    result.events = {n: s.events for n, s in zip(plan.names, slaves) if getattr(s, "model_exchange", False)}
    result.notes += [o.summary() for o in observers if hasattr(o, "summary")]  # live view, real time
    if pacing is not None:
        result.realtime = pacing.figures()
    if rt.terminated is not None:  # an FMU ended the simulation: a normal end, said in the summary
        result.message = str(rt.terminated)
        result.terminated_by = rt.terminated.component
    if tracking is not None:
        result.errors = tracking.result()
        if scenario.checks is not None:
            worst_rmse = max(e.rmse for e in result.errors)
            worst_max = max(e.max_error for e in result.errors)
            if scenario.checks.max_rmse is not None:
                result.checks["max_rmse"] = {"limit": scenario.checks.max_rmse, "value": worst_rmse,
                                             "ok": worst_rmse <= scenario.checks.max_rmse}
            if scenario.checks.max_error is not None:
                result.checks["max_error"] = {"limit": scenario.checks.max_error, "value": worst_max,
                                              "ok": worst_max <= scenario.checks.max_error}
    return result
