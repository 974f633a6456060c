"""The scenario file's format: pydantic v2 models of its sections, and its JSON Schema for editors.

A scenario names the components (FMUs given by name or by path), their parameters, the connections, the time
grid, the algorithm, the events, logging, the comparison used by the summary and optional acceptance checks;
a domain plugged in (:mod:`cosim.engine.plugins`) adds the meaning of ``robot``, ``trajectory`` and
``model``. Unknown keys are rejected. Reading a file into these models, with the line of every value, is
:mod:`cosim.engine.scenario`; ``--set`` and the other overrides are :mod:`cosim.engine.overrides`.
"""

from __future__ import annotations

import dataclasses
import difflib
import os
import typing
from pathlib import Path
from typing import Annotated, Any, Literal, Union

from pydantic import AllowInfNan, BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator, model_validator

from .algorithm import ALGORITHMS, DEFAULT
from .grid import MAX_TIME_S, NS_PER_S, Grid, grid_error, resolution_error, seconds
from .names import expand_signal, name_problem, split_ref
from . import plugins
from .sources import SourceMap
from .structure import (Acceptance, ComponentStructure, ConnectionStructure, EventStructure, LogSettings, Observed,
                        Replay, SystemStructure, Tracking)

__all__ = ["Scenario", "Event", "Component", "Connection", "TimeGrid",
           "TrajectorySpec", "InitialState", "Logging", "Compare", "Checks", "Regression", "expand_signal",
           "trajectory_params_model", "scenario_json_schema", "NS_PER_S"]

# a list sets name[1], name[2], ... (FMI 2 structured names) or a whole FMI 3 array; nested lists
# give a matrix row by row
# a parameter's nan or infinity is let through here, to be refused naming its FMU variable and type
# (cosim.engine.system.typed_value)
_Number = Annotated[float, AllowInfNan(True)]
ParamValue = Union[bool, int, _Number, str, list[Union[bool, int, _Number, str]],
                   list[list[Union[bool, int, _Number]]]]


class _Model(BaseModel):
    # every number of a scenario (times, tolerances, rates, the watchdog) is finite: a .nan or .inf in a file, an
    # option or an archive is one error naming it, never a value the run trips over later
    model_config = ConfigDict(extra="forbid", frozen=True, allow_inf_nan=False)


class Component(_Model):
    """One FMU instance: ``fmu`` (one of our FMUs, by name) or ``path`` (any FMI 2.0/3.0 FMU); or a recording
    replayed as outputs: ``recording`` (a robot's bag, a CSV, a run log) with its ``signals``."""

    fmu: str | None = Field(None, description="name of one of our FMUs (fmus.registry)")
    path: str | None = Field(None, description="path to an .fmu file, relative to the scenario file")
    recording: str | None = Field(
        None, description="a recording replayed as outputs (a ROS 2 bag folder or .mcap/.db3, a ROS 1 .bag, a .csv, "
                          "a run log .mcap; docs/recordings.md), relative to the scenario file")
    signals: dict[str, str] = Field(
        default_factory=dict, description="recording: output name -> signal spec (q[1]: "
                                          "/joint_states.position[joint1], a CSV column, a run log's ctl.q[1])")
    interpolation: Literal["linear", "hold"] = Field(
        "linear", description="recording: between samples, 'linear' or 'hold' (the last sample at or before t)")
    offset: float = Field(0.0, description="recording: its time minus the run's, s (the output at run time t is the "
                                           "recording at t + offset; its time as time_origin says)")
    time: Literal["header", "log"] = Field(
        "header", description="recording: a bag's header stamps or its log (receive) times")
    time_origin: Literal["first", "absolute"] = Field(
        "first", description="recording: its time counts from its first message ('first': the offset is when, in "
                             "the recording, the run starts) or is its absolute stamps ('absolute': s since the "
                             "epoch in a bag; the run's t is the stamp minus the offset), as compare --time-origin")
    units: dict[str, str] = Field(
        default_factory=dict, description="recording: output name -> unit (a recorded unit converts to it; a bag's "
                                          "signal, which has none, is taken to be in it)")
    parameters: dict[str, ParamValue] = Field(
        default_factory=dict,
        description="start values by variable name; a list sets name[1], name[2], ...")
    step_multiple: int = Field(1, ge=1, description="steps every N base communication steps (multi-rate)")
    interface: Literal["auto", "cs", "me"] = Field(
        "auto", description="co-simulation or model exchange; auto prefers co-simulation")
    feedthrough: Literal["auto", "none"] = Field(
        "auto", description="override of the FMU's ModelStructure: 'none' declares that no output depends "
                            "directly on an input, for third-party FMUs that leave dependencies undeclared "
                            "(ours declare them)")
    rtol: float = Field(1e-6, gt=0, description="model exchange: the integrator's relative tolerance (absolute "
                                                "tolerance: rtol times each state's nominal value)")
    solver: Literal["cvode", "dopri5", "dop853"] = Field(
        "cvode", description="model exchange: 'cvode' (SUNDIALS BDF, as FMPy; for stiff models), 'dopri5' "
                             "(Dormand-Prince 5(4); restarts for free, for non-stiff models whose inputs change at "
                             "every communication step; in C, as cvode, where a C compiler is) or 'dop853' "
                             "(SciPy's explicit Runge-Kutta 8(5,3), Python)")
    max_step: float | None = Field(
        None, gt=0, description="model exchange: largest internal step, s (default: bounded only by the "
                                "communication step; the integrator never steps past a communication point)")

    @model_validator(mode="after")
    def _one_source(self) -> "Component":
        if sum(x is not None for x in (self.fmu, self.path, self.recording)) != 1:
            # Refused (correctness): which source is meant is a guess, or there is none
            raise ValueError("give exactly one of 'fmu' (our FMU by name), 'path' (an .fmu file) or 'recording' "
                             "(a recording replayed as outputs)")
        given = {f for f in self.model_fields_set  # a key written with its default (a log's scenario as run) is not
                 if getattr(self, f) != type(self).model_fields[f].get_default(call_default_factory=True)}
        replay = {"signals", "interpolation", "offset", "time", "time_origin", "units"} & given
        if self.recording is None and replay:
            # Refused (correctness): a recording's key on an FMU would be dropped silently
            raise ValueError(f"{', '.join(sorted(replay))}: only for a component given by 'recording'")
        if self.recording is not None:
            if not self.signals:
                # Refused (correctness): nothing to replay
                raise ValueError("a recording component needs 'signals': output name -> signal spec")
            fmu_only = {"parameters", "step_multiple", "interface", "feedthrough", "rtol", "solver",
                        "max_step"} & given
            if fmu_only:
                # Refused (correctness): an FMU's key on a recording would be dropped silently
                raise ValueError(f"{', '.join(sorted(fmu_only))}: not for a recording (it has outputs only)")
            unknown = sorted(set(self.units) - set(self.signals))
            if unknown:
                # Refused (correctness): a unit for no signal would be dropped silently
                raise ValueError(f"units: {', '.join(unknown)} not among the signals ({', '.join(self.signals)})")
        return self


class Connection(_Model):
    """``from: comp.var`` -> ``to: comp.var``; a prefix (``traj.p_ref``: ``.x/.y/.z``, ``[1]..[n]``) or two
    components (``from: traj, to: ik``: outputs to the inputs of the same names) wire several (cosim.engine.wiring)."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)
    src: str = Field(alias="from", description="output, as component.variable")
    dst: str = Field(alias="to", description="input, as component.variable")
    units: Literal["check", "as_is"] = Field(
        "check", description="check (default): the two variables' units must agree; as_is: the numbers pass "
                             "unconverted between different units (SSP's suppressUnitConversion)")

    @field_validator("src", "dst")
    @classmethod
    def _dotted(cls, v: str) -> str:
        try:
            comp, rest, _ = split_ref(v)
        except ValueError as exc:
            # Refused (correctness): a name we cannot split: which component is meant is a guess
            raise ValueError(str(exc)) from None
        if not comp or rest == "" or v.endswith("."):
            # Refused (correctness): a connection end we cannot read
            raise ValueError(f"expected 'component.variable', a prefix 'component.p_ref' or a component, got {v!r} "
                             "(a component name with a dot is quoted: 'a.b'.x)")
        return v


class TimeGrid(_Model):
    """Stop time and base communication step, s. Converted once to integer nanoseconds (the step rounded to the
    nanosecond when it is no whole number of them: :mod:`cosim.engine.grid`)."""

    stop: float = Field(gt=0, le=MAX_TIME_S, description="stop time, s")
    step: float = Field(gt=0, le=MAX_TIME_S, description="base communication step, s")
    start: float = Field(0.0, ge=0, le=MAX_TIME_S, description="start time, s")

    @model_validator(mode="after")
    def _grid(self) -> "TimeGrid":
        for name in ("stop", "start"):
            v = getattr(self, name)
            # a float read from YAML is within 1e-3 ns of its intended whole-nanosecond value
            if abs(v * NS_PER_S - round(v * NS_PER_S)) > 1e-3:
                # Refused (correctness): the grid counts whole nanoseconds: the time would be moved silently
                raise ValueError(f"{name} = {v} s is not a whole number of nanoseconds")
        if self.step_ns < 1:
            # Refused (correctness): no grid of whole nanoseconds has that step
            raise ValueError(f"step = {self.step} s is shorter than the grid's resolution, 1 ns")
        if self.stop_ns <= self.start_ns:
            # Refused (correctness): no time to run
            raise ValueError(f"stop ({self.stop} s) must be after start ({self.start} s)")
        # a step that is no whole number of ns (1/30 s) is rounded to the ns, the last point still the stop time
        too_short = resolution_error(self.start_ns, self.stop_ns, self.step_ns)
        if too_short is not None:
            # Refused (correctness): a double cannot tell the steps apart at that time: FMUs would get steps of 0
            raise ValueError(too_short)
        if grid_error(self.start_ns, self.stop_ns, self.step_ns) is not None:
            n = (self.stop_ns - self.start_ns) // self.step_ns
            # Refused (correctness): the last step would be cut short or the stop time moved silently
            raise ValueError(
                f"stop - start = {seconds(self.stop_ns - self.start_ns)} s is not a whole number of steps of "
                f"{seconds(self.step_ns)} s; use stop = {seconds(self.start_ns + n * self.step_ns)} or "
                f"{seconds(self.start_ns + (n + 1) * self.step_ns)}")
        return self

    @property
    def step_ns(self) -> int:
        return round(self.step * NS_PER_S)

    @property
    def stop_ns(self) -> int:
        return round(self.stop * NS_PER_S)

    @property
    def start_ns(self) -> int:
        return round(self.start * NS_PER_S)

    @property
    def n_steps(self) -> int:
        return Grid(self.start_ns, self.stop_ns, self.step_ns).n_steps


class TrajectorySpec(_Model):
    """The reference trajectory, for the pre-flight and the initial state.

    ``type`` names one of the trajectory types of the domain plugged in (:func:`cosim.engine.plugins.trajectories`;
    the delta robot's: helix, pick_and_place, point_to_point, waypoints); ``params`` are its constructor
    arguments, typed (:func:`trajectory_params_model`).
    """

    type: str = Field(description="trajectory type (cosim.engine.plugins.trajectories)")
    params: dict[str, Any] = Field(default_factory=dict)
    check_step: float = Field(0.01, gt=0, description="pre-flight sampling step, s")
    singularity_margin: float | None = Field(
        0.01, ge=0, description="minimum singularity proximity along the path (None: no check)")

    @field_validator("type", mode="after")
    @classmethod
    def _known(cls, kind: str) -> str:
        types = plugins.trajectories()
        if kind not in types:
            close = difflib.get_close_matches(kind, list(types), n=2, cutoff=0.6)
            hint = f"did you mean {' or '.join(close)}? " if close else ""
            # Refused (correctness): a trajectory we do not have
            raise ValueError(f"unknown trajectory type {kind!r}; {hint}valid: {', '.join(types) or 'none (no plugin)'}")
        return kind

    @field_validator("params", mode="after")
    @classmethod
    def _typed(cls, params: dict[str, Any], info: Any) -> dict[str, Any]:
        """The parameters as the type's model types them (YAML 1.1's ``5e-2``, a string, becomes 0.05), so
        every reader gets what the check accepted; parameters the model refuses are kept as written and
        reported, with their lines, by the scenario's checks (:func:`trajectory_params_issues`)."""
        kind = info.data.get("type")
        if kind is None:
            return params
        try:
            return trajectory_params_model(kind).model_validate(params).model_dump(exclude_unset=True)
        except ValidationError:
            return params


class InitialState(_Model):
    """Start the plant on the trajectory at t = start (position and velocity).

    The master sets ``position`` and ``velocity`` parameters of ``component``
    from the trajectory (x, y, z order). Off: the plant keeps its own start values.
    """

    from_trajectory: bool = True
    component: str = Field("plant", description="component whose start parameters are set")
    position: list[str] = Field(default_factory=lambda: ["initial.p.x", "initial.p.y", "initial.p.z"])
    velocity: list[str] = Field(default_factory=lambda: ["initial.v.x", "initial.v.y", "initial.v.z"])

    @field_validator("position", "velocity")
    @classmethod
    def _three(cls, v: list[str]) -> list[str]:
        if len(v) not in (0, 3):
            # Refused (correctness): a vector of another size: which axis is which is a guess
            raise ValueError(f"give 3 variable names (x, y, z) or none, got {len(v)}")
        return v


class SceneSpec(_Model):
    """Where the 3D drawing takes the platform position from (needs ``robot``)."""

    position: str = Field("plant.p", description="component.prefix; .x .y .z are appended")
    rate_hz: float = Field(30.0, gt=0)


class Logging(_Model):
    """MCAP recording. ``signals``: all inputs and outputs, or outputs only; ``layout``: one message per
    sample or per block of samples on the component channels (:mod:`cosim.observers.publish`)."""

    enabled: bool = True
    out: str | None = Field(None, description="MCAP path (default runs/<scenario name>.mcap)")
    signals: Literal["all", "outputs", "none"] = "all"
    flush_interval: float = Field(1.0, gt=0, description="wall-clock seconds between flushes")
    layout: Literal["samples", "blocks"] = Field(
        "samples", description="component channels' messages: 'samples', one per sample ({\"t\": s, \"<variable>\": "
                               "value}), plotted as time series by Foxglove and PlotJuggler as they are; 'blocks', "
                               "one per block of samples, every scene period ({\"t\": [...], \"<variable>\": "
                               "[...]}), a cheaper log that viewers split into per-index series. Both read back "
                               "alike (cosim compare, runlog)")
    scene: SceneSpec | None = None


class Compare(_Model):
    """Actual vs reference signals for the summary (RMSE, max error)."""

    actual: str | list[str] = Field(description="component.prefix (expands .x .y .z) or a list of names")
    reference: str | list[str]


class Checks(_Model):
    """Acceptance checks on the comparison; a failure sets exit code 1."""

    max_rmse: float | None = Field(None, gt=0, description="largest per-axis RMSE allowed, in signal units")
    max_error: float | None = Field(None, gt=0, description="largest absolute error allowed")


class Regression(_Model):
    """Tolerances for ``python -m cosim compare``, as largest absolute differences in signal units.

    ``tolerances``: a run of this scenario against its baseline log (same models; guards
    against unintended changes). ``plant_tolerances``: this scenario run on two plants
    (``compare SCENARIO --plants exudyn,analytic``; guards the models' agreement).
    Keys are signal patterns: a full name (``plant.p.x``), a prefix ending at a name
    boundary (``plant.p`` covers ``plant.p.x/.y/.z``; ``ctl.u`` covers ``ctl.u[1]``...)
    or a glob (``*.u[*]``). The most specific pattern wins.
    """

    tolerances: dict[str, float] = Field(default_factory=dict,
                                         description="run vs baseline: signal pattern -> largest |A - B|")
    plant_tolerances: dict[str, float] = Field(default_factory=dict,
                                               description="plant vs plant: signal pattern -> largest |A - B|")

    @field_validator("tolerances", "plant_tolerances")
    @classmethod
    def _positive(cls, v: dict[str, float]) -> dict[str, float]:
        bad = [k for k, x in v.items() if not x > 0]
        if bad:
            # Refused (correctness): no value passes a tolerance <= 0 (or NaN)
            raise ValueError(f"tolerances must be > 0: {', '.join(bad)}")
        return v


class Event(_Model):
    """A change during the run (``events:`` items): values set at a time, or when a signal crosses a value.

    ``at``: a time event, s (on the time grid or between two points: the macro step is cut there).
    ``when``: a state event, ``"SIGNAL < VALUE"`` or ``"SIGNAL > VALUE"`` (``component.variable``): it fires once,
    when the signal crosses the value in that direction (``repeat: true``: at every such crossing), located
    inside the macro step to ``tolerance`` seconds by restoring every component's state and stepping again.
    ``set``: ``component.variable: value``; an input no connection drives or a tunable parameter.
    """

    at: float | None = Field(None, ge=0, le=MAX_TIME_S, description="time of a time event, s")
    when: str | None = Field(None, description='condition of a state event: "SIGNAL < VALUE" or "SIGNAL > VALUE"')
    set: dict[str, ParamValue] = Field(description="component.variable: value, set when the event fires")
    repeat: bool = Field(False, description="a state event fires at every crossing (default: once)")
    tolerance: float = Field(1e-6, gt=0, le=1.0, description="a state event is located to within this time, s")

    @model_validator(mode="after")
    def _one_kind(self) -> "Event":
        if (self.at is None) == (self.when is None):
            # Refused (correctness): when the event fires is a guess, or never
            raise ValueError("an event has either 'at' (a time) or 'when' (a condition), not both or neither")
        if self.repeat and self.when is None:
            # Refused (correctness): a time event fires once: 'repeat' would be dropped silently
            raise ValueError("'repeat' is for a state event ('when'); a time event fires once")
        if not self.set:
            # Refused (correctness): an event that sets nothing
            raise ValueError("'set' names at least one component.variable")
        return self


class Scenario(_Model):
    """A co-simulation scenario."""

    model_config = ConfigDict(extra="forbid", frozen=True, title="cosim scenario")
    name: str = "scenario"
    description: str = ""
    robot: str | None = Field(None, description="robot preset (cosim.engine.plugins.robots), for the pre-flight and "
                                                "the scene")
    components: dict[str, Component]
    connections: list[Connection] = Field(default_factory=list)
    time: TimeGrid
    algorithm: Literal[tuple(ALGORITHMS)] = Field(  # type: ignore[valid-type]  # the registered algorithms
        DEFAULT, description="master algorithm: " + ", ".join(ALGORITHMS) + " (cosim.engine.algorithm)")
    fmus: Literal["auto", "python", "native"] = Field(
        "auto", description="build of our FMUs (components given by 'fmu:'): 'native' (C generated from the same "
                            "formulas, no Python in the FMU; needs a C compiler; the Exudyn plants have no native "
                            "build and stay python), 'python' (pythonfmu), or 'auto': native when a C compiler is "
                            "found, else python (the two give the same results)")
    native_fmi: Literal[2, 3] = Field(2, description="FMI version of the native FMUs (both have co-simulation and "
                                                     "model exchange)")
    parallel: Union[Literal["auto", "on", "off"], bool] = Field(
        "auto", description="run the feed-forward components (inputs only from each other, e.g. trajectory -> IK) "
                            "ahead in a worker process on another core; same values as serial. auto: when they hold a "
                            "PythonFMU, a CPU no other process keeps busy is free for the worker and the run has at "
                            "least 2000 steps. YAML's bare on/off (booleans) "
                            "are accepted")
    watchdog_s: float | None = Field(
        60.0, gt=0, description="wall-clock seconds a macro step (or the initialization) may take before the run "
                                "stops naming the stalled component and time; null: no limit (Ctrl-C and SIGTERM "
                                "still end a stalled run, after 2 s)")
    trajectory: TrajectorySpec | None = None
    model: str | None = Field(
        None, description="identified model file (YAML, written by `python -m cosim validate-model --out`), "
                          "relative to the scenario file: its parameters (model.w_inertia, model.w_gravity, model.w_rotation) are "
                          "the start values of every model-based component of ours (controllers, analytic "
                          "plants); a component's own parameters win")
    parameters: Union[str, list[str], None] = Field(
        None, description="files of values (YAML, `name: value` by the names --set takes: plant.mass.payload, "
                          "trajectory.params.rx, components.meas.offset; written by `python -m cosim calibrate "
                          "--out`), relative to the scenario file: set over the scenario's own values and under "
                          "--set; of several, a later file's value wins")
    initial_state: InitialState = Field(default_factory=InitialState)
    logging: Logging = Field(default_factory=Logging)
    compare: Compare | None = None
    checks: Checks | None = None
    regression: Regression = Field(default_factory=Regression)
    events: list[Event] = Field(default_factory=list, description="values set during the run: at a time, or when a "
                                                                   "signal crosses a value (cosim.engine.events)")
    # set by the loader, not part of the file format
    source: str | None = Field(None, exclude=True, json_schema_extra={"readOnly": True})
    # where the values came from (set by the loader): :attr:`sources`
    _sources: "SourceMap | None" = PrivateAttr(default=None)
    _structure: Any = PrivateAttr(default=None)  # made once: :meth:`structure`
    _archive: dict[str, str] | None = PrivateAttr(default=None)  # set by cosim.io.ssp: :attr:`archive`

    def structure(self) -> SystemStructure:
        """This scenario as the engine runs it (:class:`cosim.engine.structure.SystemStructure`), made once: its
        components, connections, time grid, algorithm, events, what is logged and what its observers read."""
        if self._structure is None:
            comps = {n: ComponentStructure(c.fmu, c.path, dict(c.parameters), c.step_multiple, c.interface,
                                           c.feedthrough, c.rtol, c.solver, c.max_step, _replay(c))
                     for n, c in self.components.items()}
            observed = []
            if self.compare is not None:
                observed.append(Observed(tuple(expand_signal(self.compare.actual)
                                               + expand_signal(self.compare.reference)), ("compare",)))
            if self.logging.scene is not None:
                observed.append(Observed(tuple(expand_signal(self.logging.scene.position)), ("logging", "scene")))
            from_file = self.source is not None and self.source != "<string>"
            t = self.time
            self._structure = SystemStructure(
                self.name, comps, tuple(ConnectionStructure(c.src, c.dst, c.units) for c in self.connections),
                t.start_ns, t.stop_ns, t.step_ns, self.algorithm,
                tuple(EventStructure(dict(e.set), e.at, e.when, e.repeat, e.tolerance) for e in self.events),
                self.logging.signals if self.logging.enabled else "none", tuple(observed), self.sources,
                Path(self.source).parent if from_file else None, (self.source or "").lower().endswith(".ssp"),
                self._domain_sections(), self.source, watchdog_s=self.watchdog_s, parallel=self.parallel,
                tracking=None if self.compare is None else Tracking(tuple(expand_signal(self.compare.actual)),
                                                                    tuple(expand_signal(self.compare.reference))),
                acceptance=None if self.checks is None else Acceptance(self.checks.max_rmse, self.checks.max_error),
                log=LogSettings(self.logging.enabled, self.logging.out, self.logging.flush_interval,
                                self.logging.layout),
                document=self.as_run(), ssp=dict(self._archive) if self._archive is not None else None)
        return self._structure

    def with_archive(self, archive: dict[str, str]) -> None:
        """Record the SSP archive this scenario was read from (:mod:`cosim.io.ssp`: ``file``, ``sha256``,
        ``unpacked``): :attr:`archive`, and its structure's."""
        self._archive = dict(archive)
        self._structure = None  # made again with it

    def as_run(self) -> dict[str, Any]:
        """This scenario as it runs, every override applied, as a scenario mapping (JSON, valid YAML): every key with
        its value, defaults included; the values of its ``parameters:`` files applied (the key itself emptied, so
        that the mapping runs the same without them); the paths of FMU files and of the identified model absolute (a
        run writes its log's path in it: :meth:`~cosim.engine.structure.SystemStructure.recorded`); a component
        parameter overridden by a number written as text (``1e3``) as that text, as a file gives it."""
        data = self.model_dump(mode="json", by_alias=True)
        base = Path(self.source).parent if self.source and self.source != "<string>" else Path.cwd()
        for comp in data["components"].values():
            if comp.get("path") is not None:
                comp["path"] = os.path.normpath((base / comp["path"]).absolute())
        if data.get("model") is not None:  # relative to the scenario file, as an FMU's path: absolute in the log
            data["model"] = os.path.normpath((base / data["model"]).absolute())
        data["parameters"] = None  # the files' values are applied above: the log runs again without the files
        for path, text in self.sources.written.items():  # ("components", name, "parameters", variable)
            data["components"][path[1]]["parameters"][path[3]] = text
        return data

    def _domain_sections(self) -> dict[str, Any]:
        """The sections only the domain reads (:attr:`SystemStructure.domain`), as plain values."""
        def plain(section: BaseModel | None) -> dict[str, Any] | None:
            return None if section is None else section.model_dump(mode="python")

        return {"robot": self.robot, "fmus": self.fmus, "native_fmi": self.native_fmi,
                "trajectory": plain(self.trajectory), "model": self.model,
                "initial_state": plain(self.initial_state), "scene": plain(self.logging.scene)}

    @property
    def archive(self) -> dict[str, str] | None:
        """The SSP archive the scenario was read from (set by :mod:`cosim.io.ssp`), None for a YAML scenario:
        ``file`` (its absolute path), ``sha256`` (of its bytes) and ``unpacked`` (the temporary folder its FMUs were
        unpacked to, where the component paths point). A run's log records it, so that ``run --from-log`` unpacks
        the same archive again."""
        return self._archive

    @property
    def sources(self) -> "SourceMap":
        """Where each value came from (file and line, or the command-line option): the one way issues are placed."""
        if self._sources is None:
            self._sources = SourceMap(self.source)
        return self._sources

    @field_validator("parallel", mode="after")
    @classmethod
    def _parallel_word(cls, v: str | bool) -> str:
        return ("on" if v else "off") if isinstance(v, bool) else v  # YAML 1.1 reads bare on/off as booleans

    @model_validator(mode="after")
    def _names(self) -> "Scenario":
        for name in self.components:
            problem = name_problem(name)
            if problem:
                # Refused (correctness): an empty name, or control characters a message would show garbled
                raise ValueError(problem)
        return self


def _replay(c: Component) -> Replay | None:
    """A recording component's source, as the structure holds it (None: an FMU)."""
    if c.recording is None:
        return None
    return Replay(c.recording, tuple(c.signals.items()), c.interpolation, c.offset, c.time, tuple(c.units.items()),
                  c.time_origin)




def trajectory_params_model(kind: str) -> type[BaseModel]:
    """The typed parameters of trajectory type ``kind``: the constructor arguments of its class
    (:func:`cosim.engine.plugins.trajectories`), with their types and defaults (unknown keys refused)."""


    if kind in _PARAM_MODELS:
        return _PARAM_MODELS[kind]
    from pydantic import create_model  # lazy: --help loads this module without it

    cls = plugins.trajectories()[kind]
    hints = typing.get_type_hints(cls)
    fields: dict[str, Any] = {}
    for f in dataclasses.fields(cls):
        if not f.init:
            continue
        default = ... if f.default is dataclasses.MISSING else f.default
        fields[f.name] = (hints[f.name], Field(default))
    model = create_model(f"{cls.__name__}Params", __config__=ConfigDict(extra="forbid", title=f"{kind} parameters"),
                         __doc__=f"Parameters of the {kind} trajectory ({cls.__module__}.{cls.__name__}), SI units.",
                         **fields)
    _PARAM_MODELS[kind] = model
    return model


_PARAM_MODELS: dict[str, type[BaseModel]] = {}




def scenario_json_schema() -> dict:
    """JSON Schema of the scenario format, for editors (yaml-language-server)."""

    schema = Scenario.model_json_schema(by_alias=True)
    schema.get("properties", {}).pop("source", None)
    spec = schema["$defs"]["TrajectorySpec"]
    branches = []
    spec["properties"]["type"]["enum"] = list(plugins.trajectories())
    for kind in plugins.trajectories():  # params typed per trajectory type: editors complete and check them
        model = trajectory_params_model(kind).model_json_schema()
        schema["$defs"].update(model.pop("$defs", {}))
        schema["$defs"][model["title"].replace(" ", "_")] = model
        branches.append({"if": {"properties": {"type": {"const": kind}}, "required": ["type"]},
                         "then": {"properties": {"params": {"$ref": f"#/$defs/{model['title'].replace(' ', '_')}"}}}})
    spec["allOf"] = branches
    schema["$schema"] = "https://json-schema.org/draft/2020-12/schema"
    return schema
