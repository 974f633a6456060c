"""Scenario files: pydantic v2 models, YAML loading with line numbers, one error list.

A scenario names the components (our FMUs by name or any FMU by path), their
parameters, the connections, the time grid, the algorithm, the initial state,
logging, the comparison used by the summary and optional acceptance checks.
Unknown keys are rejected. Every problem is reported at once as
``file:line: dotted.path: message``.
"""

from __future__ import annotations

import copy
import math
import dataclasses
import difflib
import os
import re
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, Union

import yaml
from pydantic import AllowInfNan, BaseModel, ConfigDict, Field, PrivateAttr, ValidationError, field_validator, model_validator

from ..errors import Issue, ScenarioError, file_problem
from .algorithm import ALGORITHMS, DEFAULT
from .bounded_yaml import YamlTooLarge, load_yaml
from .grid import MAX_TIME_S, NS_PER_S, Grid, grid_error
from .names import name_problem, quote, split_ref
from . import plugins

__all__ = [
    "Scenario",
    "Event",
    "parse_condition",
    "Component",
    "Connection",
    "TimeGrid",
    "TrajectorySpec",
    "InitialState",
    "Logging",
    "Compare",
    "Checks",
    "load_scenario",
    "read_scenario",
    "ScenarioFile",
    "parse_scenario",
    "scenario_from_data",
    "effective_scenario",
    "EFFECTIVE_ATTACHMENT",
    "scenario_json_schema",
    "apply_overrides",
    "dotted_overrides",
    "resolve_name",
    "Overrides",
    "WrittenNumber",
    "issue_at",
    "expand_signal",
    "NS_PER_S",
]

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
    """One FMU instance: ``fmu`` (one of our FMUs, by name) or ``path`` (any FMI 2.0/3.0 FMU)."""

    fmu: str | None = Field(None, description="name of one of our FMUs (fmus.registry)")
    path: str | None = Field(None, description="path to an .fmu file, relative to the scenario file")
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
    solver: Literal["cvode", "dop853"] = Field(
        "cvode", description="model exchange: 'cvode' (SUNDIALS BDF, as FMPy; for stiff models) or 'dop853' "
                             "(SciPy's explicit Runge-Kutta 8(5,3); restarts for free, for non-stiff models whose "
                             "inputs change at every communication step)")
    max_step: float | None = Field(
        None, gt=0, description="model exchange: largest internal step, s (default: bounded only by the "
                                "communication step; the integrator never steps past a communication point)")

    @model_validator(mode="after")
    def _one_source(self) -> "Component":
        if (self.fmu is None) == (self.path is None):
            raise ValueError("give exactly one of 'fmu' (our FMU by name) or 'path' (an .fmu file)")
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
            raise ValueError(str(exc)) from None
        if not comp or rest == "" or v.endswith("."):
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
                raise ValueError(f"{name} = {v} s is not a whole number of nanoseconds")
        if self.step_ns < 1:
            raise ValueError(f"step = {self.step} s is shorter than the grid's resolution, 1 ns")
        if self.stop_ns <= self.start_ns:
            raise ValueError(f"stop ({self.stop} s) must be after start ({self.start} s)")
        # a step that is no whole number of ns (1/30 s) is rounded to the ns, the last point still the stop time
        if grid_error(self.start_ns, self.stop_ns, self.step_ns) is not None:
            n = (self.stop_ns - self.start_ns) // self.step_ns
            raise ValueError(
                f"stop - start = {self.stop - self.start} s is not a whole number of steps of {self.step} s; "
                f"use stop = {self.start + n * self.step:g} or {self.start + (n + 1) * self.step:g}")
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
            raise ValueError(f"unknown trajectory type {kind!r}; valid: {', '.join(types) or 'none (no plugin)'}")
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
            raise ValueError(f"tolerances must be > 0: {', '.join(bad)}")
        return v


_CONDITION = re.compile(r"^\s*([^\s<>=]+)\s*([<>])\s*([^\s<>=]+)\s*$")


def parse_condition(text: str) -> tuple[str, str, float]:
    """``"SIGNAL < VALUE"`` -> (signal, "<", value); raises ValueError saying what a condition looks like."""
    m = _CONDITION.match(text)
    value = None
    if m:
        try:
            value = float(m.group(3))
        except ValueError:
            value = None
    if m is None or value is None or not math.isfinite(value):
        raise ValueError(f"condition {text!r} is not 'SIGNAL < VALUE' or 'SIGNAL > VALUE' (SIGNAL a "
                         "component.variable, VALUE a finite number)")
    return m.group(1), m.group(2), value


def condition_issue(text: str) -> str | None:
    try:
        parse_condition(text)
    except ValueError as exc:
        return str(exc)
    return None


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
            raise ValueError("an event has either 'at' (a time) or 'when' (a condition), not both or neither")
        if self.repeat and self.when is None:
            raise ValueError("'repeat' is for a state event ('when'); a time event fires once")
        if not self.set:
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
                            "ahead in a worker process on another core; same values as serial. auto: when 2 CPUs "
                            "are available and the run has at least 2000 steps. YAML's bare on/off (booleans) "
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
    _trajectory: Any = PrivateAttr(default=None)  # built once: :meth:`trajectory_object`
    _domain: dict[str, Any] = PrivateAttr(default_factory=dict)  # :meth:`domain`
    _archive: dict[str, str] | None = PrivateAttr(default=None)  # set by cosim.io.ssp: :attr:`archive`

    def domain(self) -> dict[str, Any]:
        """What the domain plugged in (:mod:`cosim.engine.plugins`) made of this scenario, kept with it so that it
        is made once (the robot layer's identified model, read from the ``model:`` file)."""
        return self._domain

    def trajectory_object(self) -> Any:
        """The trajectory of the ``trajectory:`` section (an instance of its type's class,
        :func:`cosim.engine.plugins.trajectories`; None without the section), built once per scenario: the pre-flight, the start values of our
        trajectory FMUs, the initial state and the log's reference path all use this one."""
        spec = self.trajectory
        if spec is None:
            return None
        if self._trajectory is None:
            cls = plugins.trajectories()[spec.type]
            try:  # spec.params are typed by the scenario's model (TrajectorySpec._typed)
                self._trajectory = cls(**spec.params)
            except (TypeError, ValueError) as exc:  # pydantic's ValidationError is a ValueError
                raise ScenarioError(Issue("trajectory.params", f"{cls.__name__}: {exc}", self.source)) from None
        return self._trajectory

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
                raise ValueError(problem)
        return self


def expand_signal(spec: str | list[str]) -> list[str]:
    """``"plant.p"`` -> ``["plant.p.x", "plant.p.y", "plant.p.z"]``; a list is kept as is."""
    if isinstance(spec, list):
        return list(spec)
    return [f"{spec}.{axis}" for axis in "xyz"]


# --------------------------------------------------------------------------- YAML with lines


@dataclass
class SourceMap:
    """Where a scenario's values came from, by key path (``("components", "ctl", "parameters", "gain.kp")``).

    ``file``: the scenario file (or archive); ``lines``: the 1-based line of every key and item in it;
    ``origins``: the command-line option (``--set ctl.gain.kp[1]=2e4``) of every overridden value;
    ``written``: overridden component parameters as written where the text matters (a number given as text,
    ``--set s=1e3``, typed by the FMU variable it sets: :func:`cosim.engine.system.build_plan`).
    """

    file: str | None
    lines: dict[tuple, int] = field(default_factory=dict)
    origins: dict[tuple, str] = field(default_factory=dict)
    written: dict[tuple, Any] = field(default_factory=dict)

    def line(self, loc: tuple) -> int | None:
        """The line of ``loc`` in the file, or of its nearest enclosing key."""
        return line_for(loc, self.lines)

    def issue(self, loc: tuple, message: str) -> Issue:
        """An issue placed where the value at ``loc`` came from (:func:`issue_at`)."""
        return issue_at(loc, message, self.file, self.lines, self.origins)


def _collect_lines(node: yaml.Node, path: tuple, lines: dict[tuple, int]) -> None:
    """Record the 1-based line of every key and item, by key path."""
    lines.setdefault(path, node.start_mark.line + 1)
    if isinstance(node, yaml.MappingNode):
        for k, v in node.value:
            key = k.value if isinstance(k, yaml.ScalarNode) else str(k)
            lines[path + (key,)] = k.start_mark.line + 1
            _collect_lines(v, path + (key,), lines)
    elif isinstance(node, yaml.SequenceNode):
        for i, v in enumerate(node.value):
            _collect_lines(v, path + (i,), lines)


def _format_loc(loc: tuple) -> str:
    out = ""
    for part in loc:
        if isinstance(part, int):
            out += f"[{part}]"
        else:
            out += ("." if out else "") + str(part)
    return out


def line_for(loc: tuple, lines: dict[tuple, int]) -> int | None:
    for n in range(len(loc), -1, -1):
        if loc[:n] in lines:
            return lines[loc[:n]]
    return None


def issue_at(loc: tuple, message: str, file: str | None, lines: dict[tuple, int],
             origins: dict[tuple, str] | None = None) -> Issue:
    """An issue placed where the value came from: the command-line option that set it
    (``--set ctl.gain.kp[1]=abc: ...``), else ``file:line`` of the scenario.

    A location that contains an overridden value (``time`` holding ``--stop-time``) is placed
    in the file and names the option too.
    """
    origins = origins or {}
    for path, origin in origins.items():
        if loc[:len(path)] == path:
            return Issue("", message, origin)
    inside = [o for p, o in origins.items() if p[:len(loc)] == loc]
    tail = f" (with {', '.join(inside)})" if inside else ""
    return Issue(_format_loc(loc), message + tail, file, line_for(loc, lines))


_ALIASES = {"src": "from", "dst": "to"}
_UNION_TAG = re.compile(r"^(bool|int|float|str|list\[.*\]|union\[.*\])$")
_PARAM_MSG = "expected a number, a boolean, a string, a list of them, or a list of lists (rows of a matrix)"


@dataclass(frozen=True)
class ScenarioFile:
    """A scenario file read and parsed once (not validated): its data and the line of every key path.

    :meth:`load` validates it with overrides as :func:`load_scenario` does, so variants of one
    file (a sweep's cases) do not read and parse it again.
    """

    file: str
    data: dict[str, Any]
    lines: dict[tuple, int]

    def load(self, overrides: dict[tuple, Any] | None = None) -> Scenario:
        """The scenario with ``overrides`` applied (:func:`scenario_from_data`); raises :class:`ScenarioError`."""
        return scenario_from_data(self.data, self.file, overrides, self.lines)


def _parse_yaml(text: str, file: str) -> ScenarioFile:
    try:
        data, root = load_yaml(text)
    except YamlTooLarge as exc:
        raise ScenarioError(Issue("", str(exc), file, 1)) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        problem = " ".join(str(getattr(exc, "problem", None) or exc).split())  # one line, whatever YAML says
        line = mark.line + 1 if mark else None
        if isinstance(exc, yaml.reader.ReaderError):  # a character YAML refuses (NUL, a control character)
            line = text[:exc.position].count("\n") + 1
            code = exc.character if isinstance(exc.character, int) else ord(exc.character)
            problem = f"the character U+{code:04X} at offset {exc.position} is not allowed in YAML"
        raise ScenarioError(Issue("", f"invalid YAML: {problem}", file, line)) from None
    lines: dict[tuple, int] = {}
    if root is not None:
        _collect_lines(root, (), lines)
    if data is None:  # an empty file, or only comments: one line, not every key it lacks
        raise ScenarioError(Issue("", "the file holds no scenario (it is empty, or only comments)", file, 1))
    if not isinstance(data, dict):
        raise ScenarioError(Issue("", "a scenario is a mapping (components, connections, time, ...)", file, 1))
    return ScenarioFile(file, data, lines)


def parse_scenario(text: str, file: str = "<string>", overrides: dict[tuple, Any] | None = None) -> Scenario:
    """Parse and validate scenario YAML; raise :class:`ScenarioError` with every issue."""
    return _parse_yaml(text, file).load(overrides)


def scenario_from_data(data: dict[str, Any], file: str = "<string>", overrides: dict[tuple, Any] | None = None,
                       lines: dict[tuple, int] | None = None) -> Scenario:
    """Validate scenario data (the mapping a YAML file holds, or one built from an SSP file).

    ``overrides`` are applied first; ``lines`` (key path -> line) place the issues in ``file``.
    Raises :class:`ScenarioError` with every issue.
    """

    lines = lines if lines is not None else {}
    origins = dict(getattr(overrides, "origins", {}))
    written: dict[tuple, Any] = {}
    data = copy.deepcopy(data)  # the overrides must not change the caller's mapping
    for path, value in (overrides or {}).items():
        if path[0] == DOTTED:  # a dotted name (--set NAME=VALUE, the Python API): resolved against this data
            origin = origins.get(path, f"--set {path[1]}")
            path = resolve_name(path[1], data, origin)
            origins[path] = origin
        components = data.get("components") or {}
        if path[0] == "components" and len(path) == 1:  # the whole mapping replaced by an option's value
            raise ScenarioError(Issue("", "name a component's parameter (NAME.PARAM=VALUE), not all of components",
                                      origins.get(path, "--set components")))
        if path[0] == "components" and path[1] not in components:
            close = difflib.get_close_matches(path[1], list(components), n=3)
            hint = f"did you mean {', '.join(close)}? " if close else ""
            raise ScenarioError(Issue("", f"unknown component {path[1]!r} in {file}; {hint}components: "
                                      f"{', '.join(components)}", origins.get(path, "--set")))
        if path[0] == "components" and len(path) == 4 and path[2] == "parameters":
            if _has_written(value):
                written[path] = _as_written(value)
            else:  # a later override of the same parameter, written otherwise, replaces the text
                written.pop(path, None)
        node = data
        for key in path[:-1]:
            node = node[key] if isinstance(node, list) else node.setdefault(key, {})
        node[path[-1]] = value
    data["source"] = file
    try:
        scenario = Scenario.model_validate(data)
    except ValidationError as exc:
        by_loc: dict[tuple, list[str]] = {}
        for err in exc.errors():
            # drop pydantic's union-member tags (".int", ".list[...]") from the location
            loc = tuple(_ALIASES.get(p, p) if isinstance(p, str) else p for p in err["loc"]
                        if not (isinstance(p, str) and _UNION_TAG.match(p)))
            msg = err["msg"].removeprefix("Value error, ")
            if err["type"] == "extra_forbidden":
                msg = "unknown key"
            by_loc.setdefault(loc, []).append(msg)
        issues = [issue_at(loc, msgs[0] if len(msgs) == 1 else _PARAM_MSG, file, lines, origins)
                  for loc, msgs in by_loc.items()]
        raise ScenarioError(issues) from None
    issues = [issue_at(loc, msg, file, lines, origins) for loc, msg in _semantic_issues(scenario)]
    if issues:
        raise ScenarioError(issues)
    scenario._sources = SourceMap(file, lines, origins, written)
    return scenario


def _semantic_issues(s: Scenario) -> list[tuple[tuple, str]]:
    """Cross-field checks pydantic cannot see: names that must exist, sections that need a robot."""

    out: list[tuple[tuple, str]] = []
    names = list(s.components)

    def comp_of(ref: str, loc: tuple) -> None:
        try:
            comp = split_ref(ref)[0]
        except ValueError as exc:
            out.append((loc, str(exc)))
            return
        if comp not in s.components:
            close = difflib.get_close_matches(comp, names, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else f"; components: {', '.join(names)}"
            out.append((loc, f"unknown component {comp!r}{hint}"))

    for i, c in enumerate(s.connections):
        comp_of(c.src, ("connections", i, "from"))
        comp_of(c.dst, ("connections", i, "to"))
    seen: dict[str, int] = {}
    for i, c in enumerate(s.connections):
        if c.dst in seen:
            out.append((("connections", i, "to"), f"input {c.dst} is already driven by connections[{seen[c.dst]}]"))
        seen.setdefault(c.dst, i)
    if s.trajectory is not None:
        out += [(("trajectory", "params") + loc, msg) for loc, msg in trajectory_params_issues(s.trajectory)]
    if s.robot is not None:
        robots = plugins.robots()
        if s.robot not in robots:
            close = difflib.get_close_matches(s.robot, robots, n=3) or robots
            out.append((("robot",), f"unknown robot preset {s.robot!r}; valid: {', '.join(close) or 'none (no plugin)'}"))
    if s.model is not None and s.robot is None:
        out.append((("model",), "an identified model needs 'robot' (the preset it was identified for)"))
    if s.trajectory is not None and s.initial_state.from_trajectory and s.initial_state.position:
        if s.initial_state.component not in s.components:
            out.append((("initial_state", "component"), f"unknown component {s.initial_state.component!r}"))
    if s.logging.scene is not None:
        comp_of(s.logging.scene.position, ("logging", "scene", "position"))
    if s.compare is not None:
        act, ref = expand_signal(s.compare.actual), expand_signal(s.compare.reference)
        if len(act) != len(ref):
            out.append((("compare",), f"actual has {len(act)} signals, reference {len(ref)}"))
        for key, sigs in (("actual", act), ("reference", ref)):
            for sig in sigs:
                comp_of(sig, ("compare", key))
    if s.checks is not None and s.compare is None:
        out.append((("checks",), "acceptance checks need a 'compare' section"))
    for i, e in enumerate(s.events):
        if e.at is not None and e.at < s.time.start:  # after the stop time it is simply not reached (--stop-time)
            out.append((("events", i, "at"), f"{e.at:g} s is before the run's start, {s.time.start:g} s"))
        if e.when is not None:
            problem = condition_issue(e.when)
            if problem:
                out.append((("events", i, "when"), problem))
            else:
                comp_of(parse_condition(e.when)[0], ("events", i, "when"))
        for name in e.set:
            comp_of(name, ("events", i, "set", name))
    return out + plugins.scenario_issues(s)


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


def trajectory_params_issues(spec: TrajectorySpec) -> list[tuple[tuple, str]]:
    """``trajectory.params`` checked against the type's parameters: (location under params, message)."""

    model = trajectory_params_model(spec.type)
    valid = list(model.model_fields)
    try:
        model.model_validate(spec.params)
    except ValidationError as exc:
        out = []
        for err in exc.errors():
            loc = tuple(err["loc"])
            if err["type"] == "extra_forbidden":
                close = difflib.get_close_matches(str(loc[0]), valid, n=3, cutoff=0.5)
                hint = f"did you mean {', '.join(close)}? " if close else ""
                out.append((loc[:1], f"{spec.type} has no parameter {loc[0]!r}; {hint}valid: {', '.join(valid)}"))
            else:
                out.append((loc, err["msg"].removeprefix("Value error, ")))
        return out
    return []


MAX_SCENARIO_BYTES = 16 * 2 ** 20
"""Bytes a scenario file may hold (the shipped ones hold a few kB; :data:`~cosim.engine.bounded_yaml.MAX_YAML_NODES`
bounds what it expands to)."""


def load_scenario(path: str | Path, overrides: dict[tuple, Any] | None = None) -> Scenario:
    """Load a scenario file. ``overrides`` maps key paths to values (``--set``, ``--stop-time``)."""
    return read_scenario(path).load(overrides)


def read_scenario(path: str | Path) -> ScenarioFile:
    """Read and parse a scenario file, not yet validated (:meth:`ScenarioFile.load`); raises
    :class:`ScenarioError` for a file that cannot be read, is not UTF-8 or not YAML."""
    path = Path(path)
    problem = file_problem(path)
    if problem is None:
        try:
            with open(path, "rb") as f:
                raw = f.read(MAX_SCENARIO_BYTES + 1)
        except OSError as exc:
            problem = exc.strerror or str(exc)
    if problem is not None:
        raise ScenarioError(Issue("", f"cannot read scenario: {problem}", str(path))) from None
    if len(raw) > MAX_SCENARIO_BYTES:
        raise ScenarioError(Issue("", f"the file is larger than {MAX_SCENARIO_BYTES // 2 ** 20} MiB, more than any "
                                      "scenario holds (cosim.engine.scenario.MAX_SCENARIO_BYTES): refused", str(path)))
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw[:exc.start].count(b"\n") + 1
        raise ScenarioError(Issue("", f"not UTF-8 text (byte 0x{raw[exc.start]:02x} at offset {exc.start}); "
                                      f"save the scenario as UTF-8", str(path), line)) from None
    return _parse_yaml(text, str(path))


EFFECTIVE_ATTACHMENT = "effective/scenario.json"
"""The log's attachment of the scenario as run (:func:`effective_scenario`), which ``run --from-log`` runs again."""


def effective_scenario(scenario: Scenario, log: str | Path | None = None) -> dict[str, Any]:
    """``scenario`` as it runs, every override applied, as a scenario mapping (JSON, valid YAML): every key with its
    value, defaults included; the paths of FMU files and of the identified model absolute, ``logging.out`` the run's ``log`` (absolute) when
    given; a component parameter overridden by a number written as text (``1e3``) as that text, as a file gives it."""

    data = Scenario.model_dump(scenario, mode="json", by_alias=True)
    base = Path(scenario.source).parent if scenario.source and scenario.source != "<string>" else Path.cwd()
    for comp in data["components"].values():
        if comp.get("path") is not None:
            comp["path"] = os.path.normpath((base / comp["path"]).absolute())
    if data.get("model") is not None:  # relative to the scenario file, as an FMU's path: absolute in the log
        data["model"] = os.path.normpath((base / data["model"]).absolute())
    if log is not None:
        data["logging"]["out"] = os.path.normpath(Path(log).absolute())
    for path, text in scenario.sources.written.items():  # ("components", name, "parameters", variable)
        data["components"][path[1]]["parameters"][path[3]] = text
    return data


class Overrides(dict):
    """Loader overrides (key path -> value) that remember the option each came from, so an
    issue with an overridden value cites the option (``--set ctl.gain.kp[1]=abc``), not a
    scenario line the user never wrote."""

    def __init__(self) -> None:
        super().__init__()
        self.origins: dict[tuple, str] = {}

    def put(self, path: tuple, value: Any, origin: str) -> None:
        self[path] = value
        self.origins[path] = origin


def parse_set_value(raw: str, origin: str = "--set") -> Any:
    """A ``--set`` value as YAML reads it, with numbers YAML 1.1 leaves as strings (``1e12``) as numbers
    that keep their text (:class:`WrittenNumber`); YAML that does not parse is a :class:`ScenarioError`
    citing ``origin`` (the option as given)."""
    try:
        return _numbers(load_yaml(raw)[0])
    except yaml.YAMLError as exc:
        raise ScenarioError(Issue("", f"invalid value: {getattr(exc, 'problem', None) or exc}", origin)) from None


class WrittenNumber(float):
    """A number written as text that YAML 1.1 reads as a string (``1e3``, ``-2.5E-4``), with that text.

    It is the number everywhere (the scenario holds a float, a sweep's case id and table show it);
    a component parameter given so is typed by its FMU variable from the text
    (:func:`cosim.engine.system.typed_value`): a Real or an Integer takes the number, a String the text as
    written (``"1e3"``, not ``"1000.0"``).
    """

    __slots__ = ("text",)

    def __new__(cls, text: str) -> "WrittenNumber":
        number = super().__new__(cls, text)
        number.text = text
        return number

    def __reduce__(self):
        return WrittenNumber, (self.text,)


def _numbers(value: Any) -> Any:
    """YAML 1.1 strings that are numbers (``1e12``) as :class:`WrittenNumber`, also inside lists."""
    if isinstance(value, list):
        return [_numbers(v) for v in value]
    if isinstance(value, str):
        try:
            return WrittenNumber(value)
        except ValueError:
            return value
    return value


def _has_written(value: Any) -> bool:
    if isinstance(value, list):
        return any(_has_written(v) for v in value)
    return isinstance(value, WrittenNumber)


def _as_written(value: Any) -> Any:
    """``value`` with each :class:`WrittenNumber` as its text, also inside lists."""
    if isinstance(value, list):
        return [_as_written(v) for v in value]
    return value.text if isinstance(value, WrittenNumber) else value


DOTTED = "<dotted name>"
"""Head of an override key path ``(DOTTED, "ctl.gain.kp[1]")``: a dotted name that
:func:`scenario_from_data` resolves (:func:`resolve_name`) against the scenario it loads."""


def _model_of(annotation: Any) -> type[BaseModel] | None:
    """The pydantic model inside an annotation (``X``, ``X | None``), if any."""

    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return annotation
    for arg in typing.get_args(annotation):
        found = _model_of(arg)
        if found is not None:
            return found
    return None


def _is_mapping(annotation: Any) -> tuple[bool, Any]:
    """(is a dict, its value annotation)."""

    if typing.get_origin(annotation) is dict:
        return True, typing.get_args(annotation)[1]
    for arg in typing.get_args(annotation):
        if typing.get_origin(arg) is dict:
            return True, typing.get_args(arg)[1]
    return False, None


def _unknown_name(name: str, prefix: str, wrong: str, candidates: list[str], origin: str) -> ScenarioError:

    close = difflib.get_close_matches(wrong, candidates, n=3, cutoff=0.5)
    hint = f"did you mean {', '.join(prefix + quote(c) for c in close)}? " if close else ""
    return ScenarioError(Issue("", f"unknown name {prefix + quote(wrong)!r}; {hint}valid here: "
                                   f"{', '.join(prefix + quote(c) for c in candidates)}", origin))


def _split(text: str, origin: str) -> tuple[str, str | None]:
    try:
        head, rest, _ = split_ref(text)
    except ValueError as exc:
        raise ScenarioError(Issue("", str(exc), origin)) from None
    return head, rest


_LIST_ITEM = re.compile(r"^([A-Za-z_]\w*)\[(\d+)\]$")


def _dotted(path: tuple) -> str:
    """A key path as a dotted name: ``("events", 0, "at")`` -> ``events[0].at``."""
    out = ""
    for p in path:
        out += f"[{p}]" if isinstance(p, int) else (("." if out else "") + quote(str(p)))
    return out


def _list_model(annotation: Any) -> type[BaseModel] | None:
    """The model of the items of a ``list[Model]`` field (``events``), else None."""
    if typing.get_origin(annotation) is list:
        args = typing.get_args(annotation)
        return _model_of(args[0]) if args else None
    return None


def resolve_name(name: str, data: dict[str, Any], origin: str = "--set") -> tuple:
    """The key path a dotted override name addresses in scenario ``data``.

    ``COMP.PARAM`` (``ctl.gain.kp[1]``, ``plant.mass.payload``) is a component parameter;
    otherwise the name walks the scenario's sections: ``time.stop``, ``trajectory.params.rx``,
    ``algorithm``, ``logging.enabled``, ``components.ctl.parameters.gain.kp[1]``, ``events[0].at`` (an item of a
    list of sections, numbered from 0; it must exist). A mapping
    (parameters, ``trajectory.params``) takes the rest of the name as one key. A component name
    with a dot is quoted (``'Ship.Engine'.rpm``, ``components.'Ship.Engine'.step_multiple``;
    :mod:`cosim.engine.names`). An unknown name raises :class:`ScenarioError`, one line citing
    ``origin``, with the close matches.
    """
    components = data.get("components") or {}
    head, rest = _split(name, origin)
    if head in components:
        if not rest:
            raise ScenarioError(Issue("", f"{name!r} is a component: name one of its parameters, "
                                          f"{quote(head)}.PARAM", origin))
        return ("components", head, "parameters", rest)
    model: type[BaseModel] = Scenario
    remaining: str | None = name
    path: tuple = ()
    while remaining is not None:
        fields = {(f.alias or n): f for n, f in model.model_fields.items() if n != "source"}
        prefix = _dotted(path) + "." if path else ""
        key, remaining = _split(remaining, origin)
        item = _LIST_ITEM.match(key)
        if item is not None and item.group(1) in fields and _list_model(fields[item.group(1)].annotation):
            # one item of a list of sections (events[0].at): 0-based, as the log numbers events
            base, index = item.group(1), int(item.group(2))
            node = data
            for k in path:
                node = node.get(k, {}) if isinstance(node, dict) else {}
            items = node.get(base) if isinstance(node, dict) else None
            if not isinstance(items, list) or index >= len(items):
                count = len(items) if isinstance(items, list) else 0
                raise ScenarioError(Issue("", f"{name!r}: {prefix}{base} has {count} item(s), numbered from 0",
                                          origin))
            path += (base, index)
            model = _list_model(fields[base].annotation)
            if remaining is None:
                return path
            continue
        if key not in fields:
            top = list(components) + list(fields) if not path else list(fields)
            raise _unknown_name(name, prefix, key, top, origin)
        path += (key,)
        ann = fields[key].annotation
        is_map, value_ann = _is_mapping(ann)
        sub = _model_of(value_ann) if is_map else _model_of(ann)
        if is_map and sub is not None:  # components: one key, then its model
            if remaining is None:
                return path
            key, remaining = _split(remaining, origin)
            path += (key,)
            model = sub
        elif is_map:  # parameters, trajectory.params, tolerances: the rest is one key
            return path + (remaining,) if remaining is not None else path
        elif sub is not None:
            model = sub
        elif remaining is not None:
            raise ScenarioError(Issue("", f"{'.'.join(map(str, path))} is a value, it has no "
                                          f"{remaining!r}", origin))
    return path


def dotted_overrides(values: dict[str, Any], origin: str = "override") -> Overrides:
    """Loader overrides from ``{dotted name: value}`` (:func:`resolve_name`), e.g.
    ``{"trajectory.params.rx": 0.05, "time.stop": 0.5, "ctl.gain.kp[1]": 4e4}``."""
    out = Overrides()
    for name, value in values.items():
        if not isinstance(name, str) or not name or name.startswith(".") or name.endswith("."):
            raise ScenarioError(Issue("", f"expected a dotted name (component.parameter, time.stop, "
                                          f"trajectory.params.NAME), got {name!r}", origin))
        out.put((DOTTED, name), value, f"{origin} {name}={value!r}")
    return out


def apply_overrides(sets: list[str], stop_time: float | None = None) -> Overrides:
    """Turn ``--set NAME=value`` (dotted names, :func:`resolve_name`) and ``--stop-time`` into loader overrides."""
    out = Overrides()
    for item in sets:
        try:  # a quoted component name may hold '=': the key ends at the first '=' after it
            end = split_ref(item)[2] if item.startswith("'") else 0
        except ValueError as exc:
            raise ScenarioError(Issue("", str(exc), f"--set {item}")) from None
        at = item.find("=", end)
        key = item[:at] if at >= 0 else item
        if at < 0 or not key or key.startswith(".") or key.endswith("."):
            raise ScenarioError(Issue("", f"expected NAME=value (component.parameter, time.stop, "
                                          f"trajectory.params.NAME, ...), got {item!r}", "--set"))
        value = parse_set_value(item[at + 1:], f"--set {item}")
        out.put((DOTTED, key), value, f"--set {item}")
    if stop_time is not None:
        out.put(("time", "stop"), stop_time, f"--stop-time {stop_time:g}")
    return out


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

