"""The robot's pre-flight ("before the first step", as a pilot's checks before take-off): what the delta robot
checks of a scenario before any FMU is instantiated, and the start values it gives the plan.

The reference trajectory is checked against the robot's workspace and singularity margin; the trajectory comes
from :mod:`delta.trajectories` (``helix`` -> ``Helix(**params)`` and so on). The scenario's ``trajectory:``
section is the one source of the reference: it also gives the start values of every component that is one of our
trajectory FMUs (:func:`trajectory_start_values`) and the plant's initial state (:func:`initial_state_values`),
so the pre-flight, the plant and the trajectory component cannot disagree. An identified model (``model:``)
gives the start values of our model-based components. :func:`prepare` is the robot's part of the engine's
:func:`cosim.engine.prepare.prepare` (:class:`cosim.engine.plugins.Preparation`).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from delta.actuators import kind_of
from delta.errors import DeltaError, ParameterError
from delta.model import build_model
from delta.robots import get_preset
from delta.workspace import check_trajectory
from fmus import registry
from fmus.adapters.common import check_parameters
from fmus.adapters.trajectories import ADAPTERS

from ..engine.plugins import Preparation
from ..engine.structure import SystemStructure
from ..engine.system import SystemPlan
from ..errors import Issue, PreflightError, ScenarioError
from . import sections
from .model_file import model_based, model_start_values, system_model

__all__ = ["check_positions", "sampled_positions", "preflight", "initial_state_values", "trajectory_start_values",
           "prepare"]

def check_positions(robot_name: str, times: np.ndarray, positions: np.ndarray,
                    singularity_margin: float | None) -> None:
    """Raise :class:`PreflightError` (the first offending sample and why) if any position is unreachable."""

    res = check_trajectory(get_preset(robot_name), np.asarray(positions, dtype=float), np.asarray(times, dtype=float),
                           singularity_margin)
    if not res.ok:
        raise PreflightError(res.message())


def sampled_positions(traj, times: np.ndarray) -> np.ndarray:
    """Platform positions (N, 3), m, of a trajectory at ``times`` (N,), s."""
    sample = traj.sample(times)
    p = getattr(sample, "p", sample)
    if isinstance(sample, tuple):
        p = sample[0]
    return np.asarray(p, dtype=float).reshape(len(times), 3)


def preflight(system: SystemStructure) -> str:
    """Check the system's trajectory (and the identified model's parameters against the robot's masses);
    returns a one-line report, raises PreflightError."""
    spec, robot = sections.trajectory(system), sections.robot(system)
    model = _model_report(system)
    if spec is None or robot is None:
        return "no trajectory to check" + model
    traj = sections.trajectory_object(system)
    t0, t1, _ = system.seconds()
    n = max(2, int(np.ceil((t1 - t0) / spec["check_step"])) + 1)
    times = np.linspace(t0, t1, n)
    check_positions(robot, times, sampled_positions(traj, times), spec["singularity_margin"])
    return f"trajectory reachable ({n} samples, margin {spec['singularity_margin']})" + model


def _model_report(system: SystemStructure) -> str:
    """``; model FILE (w_inertia = ..)`` for a system with an identified model, after building the robot's
    analytic model with its parameters (the mass validation of :mod:`delta.masses`)."""
    model = system_model(system)
    if model is None:
        return ""

    robot = get_preset(sections.robot(system))
    fields = {name.removeprefix("model."): value for name, value in model.parameters.items()}
    try:
        build_model(robot, kind_of(robot.kind).masses_type().with_(**fields))
    except (ParameterError, TypeError) as exc:
        raise PreflightError(f"identified model {model.path}: {exc}") from None
    shown = ", ".join(f"{k} = {v:.4g}" for k, v in fields.items())
    return f"; identified model {sections.section(system, 'model')} ({shown})"


def initial_state_values(system: SystemStructure) -> dict[str, float]:
    """Start parameters of ``initial_state.component``: position and velocity on the trajectory at t = start."""
    init = sections.initial_state(system)
    if sections.trajectory(system) is None or not init["from_trajectory"]:
        return {}
    traj = sections.trajectory_object(system)
    state = traj.evaluate(system.seconds()[0])
    p = np.asarray(getattr(state, "p", state[0] if isinstance(state, tuple) else state), dtype=float).reshape(3)
    v = getattr(state, "v", state[1] if isinstance(state, tuple) and len(state) > 1 else None)
    out = dict(zip(init["position"], map(float, p)))
    if v is not None and init["velocity"]:
        out.update(zip(init["velocity"], map(float, np.asarray(v, dtype=float).reshape(3))))
    return out


def _trajectory_adapters(system: SystemStructure) -> dict[str, type]:
    """Components that are one of our trajectory FMUs (``fmu:``, not ``path:``) -> their adapter class."""
    ours = {n: c.fmu for n, c in system.components.items() if c.fmu is not None}
    if not ours:
        return {}

    by_fmu = {a.FMU: a for a in ADAPTERS.values()}
    return {name: by_fmu[fmu] for name, fmu in ours.items() if fmu in by_fmu}


def _same(given: Any, value: Any) -> bool:
    if isinstance(value, str) or isinstance(given, (str, bool)):
        return given == value
    try:
        return float(given) == float(value)
    except (TypeError, ValueError):
        return False


def _show(value: Any) -> str:
    return repr(value) if isinstance(value, str) else str(value)


def trajectory_start_values(system: SystemStructure) -> dict[str, dict[str, Any]]:
    """Start values of our trajectory FMUs from the system's ``trajectory`` section, by component.

    Raises :class:`ScenarioError` (every issue, as ``file:line: path: message``) when such a
    component generates another trajectory type than the section's, when the FMU cannot
    represent the section's trajectory, or when the component also sets one of these
    parameters to a different value. Components given by ``path`` are left alone.
    """
    spec = sections.trajectory(system)
    adapters = _trajectory_adapters(system) if spec is not None else {}
    if not adapters:
        return {}
    traj = sections.trajectory_object(system)
    issues: list[Issue] = []

    def issue(loc: tuple, message: str) -> None:
        issues.append(system.where().issue(loc, message))

    out: dict[str, dict[str, Any]] = {}
    for name, cls in adapters.items():
        comp = system.components[name]
        if cls.TYPE != spec["type"]:

            issue(("components", name, "fmu"),
                  f"{comp.fmu} generates a {cls.TYPE} trajectory but trajectory.type is {spec['type']}; "
                  f"use fmu: {ADAPTERS[spec['type']].FMU} or change trajectory.type")
            continue
        try:
            values = cls.parameters_of(traj)
        except ValueError as exc:
            issue(("trajectory", "params"), f"{name} (fmu: {comp.fmu}) cannot generate it: {exc}")
            continue
        fields = {p.name: p.field for p in cls.PARAMS}
        for pname, given in comp.parameters.items():
            targets = [(f"{pname}[{k + 1}]", v) for k, v in enumerate(given)] if isinstance(given, list) \
                else [(pname, given)]
            for vname, val in targets:
                if vname in values and not _same(val, values[vname]):
                    field = fields[vname]
                    where = "trajectory.params" if field in spec["params"] else \
                        f"trajectory (the {type(traj).__name__} default)"
                    issue(("components", name, "parameters", pname),
                          f"{_show(val)} disagrees with {where} {field} = {_show(getattr(traj, field))}; "
                          f"set it in one place (trajectory.params)")
        out[name] = values
    if issues:
        raise ScenarioError(issues)
    return out


def prepare(system: SystemStructure) -> Preparation:
    """The robot's pre-flight of ``system`` (the trajectory's start values checked first, then the reachability
    and the identified model) and, to apply to its plan, the start values it gives: our trajectory FMUs' from the
    ``trajectory:`` section, our model-based FMUs' from the identified model, the initial state's from the
    trajectory. A component's explicit parameters win over each (equal ones for the trajectory: checked)."""
    trajectory_values = trajectory_start_values(system)
    report = preflight(system)
    return Preparation(report, lambda plan: _apply(system, plan, trajectory_values))


def _apply(system: SystemStructure, plan: SystemPlan, trajectory_values: dict[str, dict[str, Any]]) -> None:
    for name, values in trajectory_values.items():
        c = plan.names.index(name)
        plan.start_values[c] = {**values, **plan.start_values[c]}  # explicit ones are equal (checked)
    model = system_model(system)
    if model is not None:  # the identified model: start values of our model-based components, explicit ones win
        for c, name in enumerate(plan.names):
            comp = system.components[name]
            if comp.fmu is not None and model_based(registry.get(comp.fmu)):
                values = model_start_values(model, plan.infos[c].variables)
                plan.start_values[c] = {**values, **plan.start_values[c]}
    init = initial_state_values(system)
    if init:
        target = sections.initial_state(system)["component"]
        c = plan.names.index(target)
        variables = plan.infos[c].variables
        missing = [n for n in init if n not in variables]
        if missing:
            raise ScenarioError(Issue("initial_state", f"{target} has no "
                                      f"{', '.join(missing)} (set initial_state.position/velocity to its start "
                                      f"parameters, or from_trajectory: false)", system.source))
        plan.start_values[c] = {**init, **plan.start_values[c]}  # explicit parameters win
    _check_parameters(system, plan)


_LAW_PARAMETERS = {"kp": "gain.kp", "ki": "gain.ki", "kd": "gain.kd", "u_max": "limit.u_max"}
"""The control laws' gains and limit (:mod:`delta.control`) by our controller FMUs' parameters."""


def _law_issue(system: SystemStructure, name: str, definition: Any, start_values: dict[str, Any],
               step_multiple: int) -> Issue | None:
    """The controller's gains, limit and period as the FMU will start (its start values under the scenario's, at the
    period the run gives it) checked as its law (the adapter's ``LAW_CLASS``, :mod:`delta.control`) checks them:
    what the law refuses (a gain <= 0), named as the scenario names it, or None."""
    adapter = definition.declared()
    values = dict(adapter.values)
    try:
        values.update({n: float(v) for n, v in start_values.items() if n in values})
    except (TypeError, ValueError):  # a value of the wrong type: the plan's typing says so, by its name
        return None
    gains = {g: [values[f"gain.{g}[{i}]"] for i in (1, 2, 3)] for g in ("kp", "ki", "kd") if f"gain.{g}[1]" in values}
    try:
        adapter.LAW_CLASS.check(system.step_ns * step_multiple / 1e9, u_max=values["limit.u_max"] or None, **gains)
    except ParameterError as exc:
        field = (exc.name or "").rsplit(".", 1)[-1]
        parameter = _LAW_PARAMETERS.get(field)
        if parameter is None:
            return system.where().issue(("components", name), str(exc))
        written = system.components[name].parameters  # as the scenario or --set wrote them (a list: one key)
        given = next((n for n in written if n == parameter or n.startswith(parameter + "[")), parameter)
        return system.where().issue(("components", name, "parameters", given),
                                    f"{name}.{parameter}{str(exc)[len(exc.name):]}")
    return None


def _check_parameters(system: SystemStructure, plan: SystemPlan) -> None:
    """Our FMUs' robot and mass parameters as they will start (the FMU's own start values, under the scenario's,
    the identified model's and the trajectory's), checked by the function the FMUs check them with at
    initialization (:func:`fmus.adapters.common.check_parameters`): a negative payload is refused here, placed
    where the scenario or ``--set`` gave it and named as the scenario names it (``plant.mass.payload``), before any
    FMU is instantiated."""
    issues: list[Issue] = []
    for c, name in enumerate(plan.names):
        comp = system.components[name]
        definition = registry.get(comp.fmu) if comp.fmu is not None and comp.fmu in registry.names() else None
        kind = definition.kind if definition is not None else None
        if kind is None:
            continue
        given = {n: v.start for n, v in plan.infos[c].variables.items()
                 if n.startswith(("geometry.", "mass.", "model."))}
        given.update((n, v) for n, v in plan.start_values[c].items() if n in given)
        values = {}
        for n, v in given.items():  # numbers only: model.fidelity is a String; a value of the wrong type is
            try:                    # the plan's typing's to refuse (a mass left out is not checked here)
                values[n] = float(v)
            except (TypeError, ValueError):
                pass
        try:
            check_parameters(kind, values)
        except DeltaError as exc:
            parameter = exc.name or ""
            issues.append(system.where().issue(("components", name, "parameters", parameter),
                                               f"{name}.{exc}"))
            continue
        if definition.role == "controller":
            issue = _law_issue(system, name, definition, plan.start_values[c], comp.step_multiple)
            if issue is not None:
                issues.append(issue)
    if issues:
        # Refused (correctness): an FMU of ours would refuse the value at its initialization
        raise ScenarioError(issues)
