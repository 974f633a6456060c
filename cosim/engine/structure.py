"""The system structure: what a front end parses a system into and what the engine builds its plan from.

Tool-neutral and file-neutral, as libcosim's ``system_structure`` between its parsers and its execution: the
components with their FMU sources and start values, the connections, the time grid, the algorithm, the events,
what is logged and what the observers read, and the sections only a domain reads (:attr:`SystemStructure.domain`:
the robot's, for the plugin of :mod:`cosim.engine.plugins`; the engine never looks inside). A YAML scenario (:meth:`cosim.engine.schema.Scenario.structure`)
and an SSP archive (read into the same scenario, :mod:`cosim.io.ssp`) both meet here; the plan
(:func:`cosim.engine.system.build_plan`), the events (:func:`cosim.engine.events.resolve_events`) and the
execution (:func:`cosim.engine.assembly.assemble_structure`) take it. Where each value came from (file and
line, or the option that set it) travels with it (:attr:`SystemStructure.sources`), so every problem the engine
finds is placed there.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

from .grid import Grid
from .sources import SourceMap

__all__ = ["DOCUMENT_ATTACHMENT", "Acceptance", "ComponentStructure", "ConnectionStructure", "EventStructure", "LogSettings", "Observed", "Replay",
           "SystemStructure", "Tracking"]


DOCUMENT_ATTACHMENT = "effective/scenario.json"
"""The name of a run log's attachment holding its system's :attr:`SystemStructure.document` (the scenario as run),
which ``run --from-log`` runs again."""


@dataclass(frozen=True)
class Replay:
    """A component that replays a recording as outputs (``recording: FILE``): ``file`` (relative to
    :attr:`SystemStructure.base`), ``signals`` ((output name, signal spec) pairs, in order), ``interpolation``
    ('linear' or 'hold'), ``offset_s`` (the recording's time minus the run's), ``time`` (a bag's 'header' stamps or
    'log' times), ``units`` ((output name, unit) pairs), ``time_origin`` ('first': the recording's time counts from
    its first message; 'absolute': from its stamps, as ``compare --time-origin absolute``). The domain that reads
    recordings makes it a component (:func:`cosim.engine.plugins.recording_source`)."""

    file: str
    signals: tuple[tuple[str, str], ...]
    interpolation: str = "linear"
    offset_s: float = 0.0
    time: str = "header"
    units: tuple[tuple[str, str], ...] = ()
    time_origin: str = "first"


@dataclass(frozen=True)
class ComponentStructure:
    """One FMU instance: its FMU given by ``path`` (a file, relative to :attr:`SystemStructure.base`) or by
    ``fmu`` (a name the domain's FMU source resolves, :func:`cosim.engine.plugins.fmu_source`); its start values
    by variable name as written (a list sets ``name[1]``, ``name[2]``, ... or a whole array); how it is driven.
    Or no FMU: a recording replayed as outputs (``replay``; ``fmu`` and ``path`` None)."""

    fmu: str | None
    path: str | None
    parameters: Mapping[str, Any]
    step_multiple: int = 1
    interface: str = "auto"  # "cs", "me", or "auto" (the FMU's)
    feedthrough: str = "auto"  # "none": no output depends directly on an input, whatever the FMU declares
    rtol: float = 1e-6  # model exchange: the integrator's relative tolerance
    solver: str = "cvode"  # model exchange: the integrator
    max_step: float | None = None  # model exchange: the integrator's largest internal step, s
    replay: Replay | None = None  # a recording replayed as outputs, instead of an FMU


@dataclass(frozen=True)
class ConnectionStructure:
    """An output (``src``, ``component.variable`` or a prefix of several) driving an input (``dst``); ``units``:
    ``check`` (refuse differing units) or ``as_is``."""

    src: str
    dst: str
    units: str = "check"


@dataclass(frozen=True)
class EventStructure:
    """Values ``set`` (``component.variable`` -> value) at time ``at`` s, or when the signal of ``when``
    (``signal < value`` or ``signal > value``) crosses, every time with ``repeat``, located to ``tolerance`` s."""

    set: Mapping[str, Any]
    at: float | None = None
    when: str | None = None
    repeat: bool = False
    tolerance: float = 1e-6


@dataclass(frozen=True)
class Observed:
    """Signals an observer reads besides the connections (the compared pair, a scene's position), and where in the
    source they were named (the location an unknown one is reported at)."""

    signals: tuple[str, ...]
    loc: tuple


@dataclass(frozen=True)
class Tracking:
    """The signals a run compares, pair by pair: ``actual[i]`` against ``reference[i]`` (the tracking error its
    summary, its checks and its log's reference path report)."""

    actual: tuple[str, ...]
    reference: tuple[str, ...]


@dataclass(frozen=True)
class Acceptance:
    """A run's acceptance check on its tracking errors: the largest per-pair RMSE and absolute error allowed (None:
    not checked)."""

    max_rmse: float | None = None
    max_error: float | None = None


@dataclass(frozen=True)
class LogSettings:
    """How a run logs: ``enabled`` by default; ``out``, the log's path relative to :attr:`SystemStructure.base` (None:
    ``runs/<name>.mcap``); ``flush_interval_s``, wall-clock seconds between flushes; ``layout``, one message per
    sample (``samples``) or per block of samples (``blocks``). What is logged: :attr:`SystemStructure.log_signals`."""

    enabled: bool = True
    out: str | None = None
    flush_interval_s: float = 1.0
    layout: str = "samples"


@dataclass(frozen=True)
class SystemStructure:
    """A system as the engine runs it (see the module's docstring)."""

    name: str
    components: Mapping[str, ComponentStructure]
    connections: tuple[ConnectionStructure, ...]
    start_ns: int
    stop_ns: int
    step_ns: int
    algorithm: str
    events: tuple[EventStructure, ...] = ()
    log_signals: str = "outputs"  # what is logged: "outputs", "all" (inputs too) or "none"
    observed: tuple[Observed, ...] = ()
    sources: SourceMap | None = None
    base: Path | None = None  # the folder relative FMU paths are resolved against (None: the working folder)
    archive: bool = False  # read from an SSP archive: advice names options, not YAML keys
    domain: Mapping[str, Any] = field(default_factory=dict)
    """The sections of the source the engine does not read, as plain values (numbers, strings, lists, mappings) the
    front end validated: what the domain plugged in reads (:func:`cosim.engine.plugins.prepare`, ``scene``, an FMU
    source's ``key``). A YAML scenario's: ``robot``, ``fmus``, ``native_fmi``, ``trajectory``, ``model``,
    ``initial_state``, ``scene`` (:meth:`cosim.engine.schema.Scenario.structure`)."""
    source: str | None = None  # the file the structure was read from (None: made in code)
    watchdog_s: float | None = 60.0  # wall-clock s a macro step (or the initialization) may take; None: no limit
    parallel: str = "auto"  # the feed-forward components ahead in a worker process: "auto", "on" or "off"
    tracking: Tracking | None = None
    acceptance: Acceptance | None = None
    log: LogSettings = LogSettings()
    document: Mapping[str, Any] | None = None
    """The source as a run records it, for ``run --from-log`` and checkpoints to make the same system again (a YAML
    scenario's: every key with every override applied, :meth:`cosim.engine.schema.Scenario.as_run`); None: made in
    code, nothing to record."""
    ssp: Mapping[str, str] | None = None
    """The SSP archive the system was read from (``file``: its absolute path, ``sha256``, ``unpacked``: the folder its
    FMUs were unpacked to); a log records it so that ``run --from-log`` unpacks the same archive again."""
    made: dict[str, Any] = field(default_factory=dict, compare=False, repr=False)
    """What a domain made of :attr:`domain` once per structure (a trajectory object, an identified model read from its
    file), kept here so that every part of a run uses the same one."""

    def where(self) -> SourceMap:
        """Where each value came from (an empty map when the structure was made in code)."""
        return self.sources if self.sources is not None else SourceMap(None)

    def folder(self) -> Path:
        return self.base if self.base is not None else Path.cwd()

    def recorded(self, log: str | Path | None = None) -> dict[str, Any] | None:
        """:attr:`document` as a run records it, with the run's ``log`` (absolute) as its ``logging.out``; None
        for a system made in code."""
        if self.document is None:
            return None
        data = dict(self.document)
        if log is not None:
            data["logging"] = {**(data.get("logging") or {}), "out": os.path.normpath(Path(log).absolute())}
        return data

    def n_steps(self) -> int:
        """The base steps of the run's time grid (:class:`cosim.engine.grid.Grid`)."""
        return Grid(self.start_ns, self.stop_ns, self.step_ns).n_steps

    def seconds(self) -> tuple[float, float, float]:
        """(start, stop, step) in seconds: each the double nearest its decimal value (an integer count of
        nanoseconds divided by 1e9 is rounded once, as the decimal text was when it was read)."""
        return self.start_ns / 1e9, self.stop_ns / 1e9, self.step_ns / 1e9
