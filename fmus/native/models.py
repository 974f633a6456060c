"""What each FMU of ours computes (both builds), written as calls of the ``delta/`` formulas on symbols.

A native model is the behaviour of one FMU over the interface its adapter declares (:mod:`fmus.adapters`): an
FMU's definition (:class:`fmus.definition.FmuDefinition`) holds both classes, and makes the native model with the
robot kind and the adapter class itself; its variables are the adapter's (:mod:`fmus.native.interface`), and its
functions call the :mod:`delta` algorithms with a model compiled on symbols
(:func:`fmus.native.symbolic.symbolic_model`). Traced once (:mod:`fmus.native.generate`), they are the native
build's C and the python build's step (:mod:`fmus.traced`, run in CasADi's machine): written once. They return :class:`Result` records:
the variables they set, the new internal state, and the checks the formulas recorded, each an error
(the FMI call fails with the reason logged) or a warning (logged once when it starts failing).

The functions, as the C glue calls them (``fmus/native/c/model.h``):

* ``start``: initial internal state (and model-exchange states) from the parameters;
* ``refresh``: outputs from inputs, parameters, time and state (may update a held state);
* ``advance``: the internal state over one co-simulation substep ``h``;
* ``derivatives``: model exchange: state derivatives, and the outputs unless :attr:`NativeModel.me_outputs`
  (default: ``refresh``);
* ``accept``: model exchange: the checks of a state the importer accepted (a completed integrator step, an event, a
  communication point) and, with :attr:`NativeModel.me_outputs`, its outputs, which the integrator's trial states
  never need.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import casadi as ca

from delta.control import DEFAULT_GAINS
from delta.dynamics import platform_dynamics, platform_state, platform_step
from delta.kinematics import (BEYOND_LIMITS, END_STOP, JOINT_LIMIT, inverse_kinematics, proximity, set_pose,
                              working_mode_fault)
from delta.model import Data
from delta.trajectories import PROFILES

from .._names import axis_names, joint_names
from ..adapters import analytic_plant, plant_me
from ..adapters.common import P0, V0, mass_values, robot_values
from .symbolic import SYMBOLIC, Trace, instance, symbolic_model

__all__ = ["Check", "Result", "Symbols", "NativeModel", "Trajectory", "InverseKinematics", "ForwardKinematics",
           "Controller", "PIDController", "CTCController", "AnalyticPlant"]

P, V = tuple(axis_names("p")), tuple(axis_names("v"))
P_REF, V_REF, A_REF = (tuple(axis_names(n)) for n in ("p_ref", "v_ref", "a_ref"))
Q, QD, U = (tuple(joint_names(n)) for n in ("q", "qd", "u"))
Q_REF, QD_REF, QDD_REF = (tuple(joint_names(n)) for n in ("q_ref", "qd_ref", "qdd_ref"))
DP, DV = tuple(f"der({n})" for n in P), tuple(f"der({n})" for n in V)


@dataclass(frozen=True)
class Check:
    """A condition (an ``SX``, 1 where it holds) and what it means when it fails: ``reason``, or with ``values``
    (at most ``MODEL_MAX_DETAIL``, ``SX``) a printf format the C glue prints them into when it fails."""

    ok: Any
    reason: str
    error: bool = True
    values: tuple[Any, ...] = ()


@dataclass
class Result:
    """What one model function gives: variable values it sets, the new state (None: unchanged), checks."""

    values: dict[str, Any] = field(default_factory=dict)
    state: list[Any] | None = None
    checks: list[Check] = field(default_factory=list)


@dataclass
class Symbols:
    """The arguments of a traced function: time, step, every variable by name, the internal state."""

    t: Any
    h: Any
    v: dict[str, Any]
    s: list[Any]

    def vec(self, names) -> tuple[Any, ...]:  # noqa: ANN001
        return tuple(self.v[n] for n in names)


def _errors(trace: Trace, prefix: str = "") -> list[Check]:
    """Every recorded condition as an error: the parameters' first, then the formulas' (with ``prefix``)."""
    params, trace.parameters = trace.parameters, []
    return [Check(ok, reason) for ok, reason in params] + [Check(ok, prefix + reason) for ok, reason in trace.take()]


def _all(conditions) -> Any:  # noqa: ANN001
    out = ca.SX(1)
    for c in conditions:
        out = ca.logic_and(out, c)
    return out


class NativeModel:
    """Base: a model with no state, no substeps and no continuous states.

    ``adapter`` is the python adapter class whose interface the FMU has (:mod:`fmus.adapters`), ``kind`` the
    robot kind (None: robot-independent); both come from the FMU's definition. ``me_adapter`` (a class
    attribute) is the model-exchange adapter whose continuous states and derivatives the FMU adds, if any.
    """

    n_state = 0
    choices: dict[str, tuple[str, ...]] = {}  # String parameters: the values each may take
    max_step: str | None = None  # the parameter that bounds one advance, if any
    me_advances = False
    me_accepts = False  # model exchange checks each accepted state (:meth:`accept`)
    me_adapter: type | None = None  # its declared states and their derivatives are the FMU's continuous states
    me_outputs = False  # model exchange: :meth:`accept` gives the outputs (with me_accepts), ``derivatives`` none

    def __init__(self, kind: str | None, adapter: type) -> None:
        self.kind, self.adapter = kind, adapter

    def initial_state(self) -> list[float]:
        return [0.0] * self.n_state

    def model(self, sym: Symbols, trace: Trace):  # noqa: ANN201
        """The robot model compiled on the symbols of the ``geometry.*`` and ``mass.*`` parameters."""
        masses = mass_values(self.kind, sym.v) if all(n in sym.v for n in ("mass.rod", "model.gravity")) else None
        before = trace.take()
        model = symbolic_model(self.kind, robot_values(self.kind, sym.v), masses)
        trace.set_aside(before)  # the parameter checks are errors wherever the model is used
        return model

    def start(self, sym: Symbols, trace: Trace) -> Result:
        return Result()

    def accept(self, sym: Symbols, trace: Trace) -> Result:
        """Model exchange (with :attr:`me_accepts`): the checks of a state the importer accepted, at each completed
        integrator step and event, never of its trial states (``derivatives``); with :attr:`me_outputs` also its
        outputs, which the runtime then computes here only (at a completed step, or when one is read)."""
        return Result()

    def refresh(self, sym: Symbols, trace: Trace) -> Result:
        return Result()

    def advance(self, sym: Symbols, trace: Trace) -> Result:
        return Result()

    def derivatives(self, sym: Symbols, trace: Trace) -> Result:
        """Model exchange: as :meth:`refresh`. A model without continuous states (no :attr:`me_adapter`) has
        nothing here: its FMU never calls it (``rt_update`` refreshes), and tracing its outputs a second time
        doubled the C the compiler reads (the pick_place trajectory: about 40 % of its build)."""
        if self.me_adapter is None:
            return Result()
        return self.refresh(sym, trace)


# ----------------------------------------------------------------------------- trajectories

class Trajectory(NativeModel):
    """``p_ref, v_ref, a_ref`` at the FMU's time from the trajectory's ``evaluate_scalar`` (no inputs); a
    segmented trajectory's knots from its ``knots`` (:mod:`delta.trajectories`), traced as well."""

    def __init__(self, kind: None, adapter: type) -> None:
        super().__init__(kind, adapter)
        self.choices = {p.name: PROFILES for p in adapter.PARAMS if p.field == "profile"}

    def refresh(self, sym: Symbols, trace: Trace) -> Result:
        traj = self.adapter.from_parameters(sym.v, make=lambda **f: instance(self.adapter.CLASS, **f))
        traj.validate(SYMBOLIC)  # the checks the trajectory makes when it is made from numbers
        if hasattr(traj, "knots"):
            traj._set_segments(traj.knots(SYMBOLIC), SYMBOLIC)
        p, v, a = traj.evaluate_scalar(sym.t, SYMBOLIC)
        return Result(dict(zip(P_REF + V_REF + A_REF, (*p, *v, *a))), checks=_errors(trace))


# ----------------------------------------------------------------------------- kinematics

class InverseKinematics(NativeModel):
    """As :class:`fmus.adapters.kinematics.InverseKinematics`: the joint references of ``p_ref, v_ref,
    a_ref``; an unreachable reference (no solution, a joint limit, or a singularity proximity below
    ``singularity.margin`` > 0) drops ``reachable`` and holds the last reachable references (the state).
    A type 1 singularity with ``singularity.margin`` <= 0 is an error."""

    n_state = 9  # the last reachable q_ref, qd_ref, qdd_ref

    def refresh(self, sym: Symbols, trace: Trace) -> Result:
        model = self.model(sym, trace)
        p = sym.vec(P_REF)
        q, qd, qdd, _ = inverse_kinematics(model, p, sym.vec(V_REF), sym.vec(A_REF))
        faults = trace.take()  # no solution / beyond the limits per leg, and the type 1 singularities
        solvable = [c for c, r in faults if "singularity" not in r]
        serial = [c for c, r in faults if "singularity" in r]
        margin = sym.v["singularity.margin"]
        fault = ca.logic_not(_all(solvable))
        value = proximity(set_pose(model, Data(model), q, p), SYMBOLIC)
        near = ca.logic_and(margin > 0.0, value < margin)
        reachable = ca.logic_and(ca.logic_not(fault), ca.logic_not(near))
        new = (*q, *qd, *qdd)
        held = [ca.if_else(reachable, x, s) for x, s in zip(new, sym.s)]
        checks = [Check(ok, f"p_ref is unreachable: {reason}; joint references hold their last reachable values",
                        error=False) for ok, reason in faults if "singularity" not in reason]
        checks.append(Check(ca.logic_or(fault, ca.logic_not(near)),
                            "p_ref is unreachable: too close to a singularity (proximity below singularity.margin); "
                            "joint references hold their last reachable values", error=False))
        checks += [Check(ca.logic_or(ca.logic_or(fault, margin > 0.0), ok), reason)
                   for ok, reason in zip(serial, (r for _, r in faults if "singularity" in r))]
        checks += _errors(trace)
        values = dict(zip(Q_REF + QD_REF + QDD_REF, held))
        values.update({"reachable": reachable, "singularity.proximity": ca.if_else(fault, 0.0, value)})
        return Result(values, held, checks)


class ForwardKinematics(NativeModel):
    """As :class:`fmus.adapters.kinematics.ForwardKinematics`: ``p, v`` and the singularity proximity of ``q, qd``;
    ``valid`` drops (and ``p, v``, the proximity hold their last valid values) when the rods cannot meet or ``q``
    would be assembled outside the working mode. A type 1 or 2 singularity is an error."""

    n_state = 7  # the last valid p, v and proximity

    def refresh(self, sym: Symbols, trace: Trace) -> Result:
        data = Data(model := self.model(sym, trace))
        q = sym.vec(Q)
        p, v = platform_state(model, data, q, sym.vec(QD))
        assembled = trace.take()  # the spheres meet, then J^-1 exists (singularities)
        working_mode_fault(model, q, p)
        mode = trace.take()  # each leg solves at p, and the solution is q's
        meet = _all(c for c, r in assembled if "singularity" not in r)
        valid = ca.logic_and(meet, _all(c for c, _ in mode))
        value = proximity(data, SYMBOLIC)
        held = [ca.if_else(valid, x, s) for x, s in zip((*p, *v, value), sym.s)]
        checks = [Check(ca.logic_or(ca.logic_not(meet), c), r) for c, r in assembled if "singularity" in r]
        checks += [Check(c, f"q is not a valid assembly: {r}; p and v hold their last valid values", error=False)
                   for c, r in assembled + mode if "singularity" not in r]
        checks += _errors(trace)
        values = dict(zip(P + V + ("singularity.proximity",), held))
        values["valid"] = valid
        return Result(values, held, checks)


# ----------------------------------------------------------------------------- controllers

class Controller(NativeModel):
    """``u`` from the law's ``output_scalar`` on the inputs, the gains and ``limit.u_max`` (0 = no saturation)
    as parameters: the law (``LAW_CLASS``), whether it takes the robot model (``MODEL_BASED``) and its gains (those
    of :data:`delta.control.DEFAULT_GAINS` under ``LAW``) are the adapter's (:mod:`fmus.adapters.controllers`)."""

    FIXED: dict[str, Any] = {}  # law attributes the FMU does not expose

    def law(self, sym: Symbols, trace: Trace, h: Any, **state: Any):  # noqa: ANN201
        u_max = sym.v["limit.u_max"]
        bound = ca.if_else(u_max != 0.0, u_max, ca.inf)  # 0 = no saturation
        fields = {g: sym.vec(joint_names(f"gain.{g}")) for g in DEFAULT_GAINS[self.kind][self.adapter.LAW]}
        fields.update(h=h, u_max=(bound, bound, bound), **self.FIXED, **state)
        if self.adapter.MODEL_BASED:
            fields.update(model=(model := self.model(sym, trace)), data=Data(model))
        before = trace.take()
        law = self.adapter.LAW_CLASS.traced(SYMBOLIC, **fields)
        trace.set_aside(before)
        return law

    def inputs(self, sym: Symbols) -> tuple[tuple[Any, ...], ...]:
        return tuple(sym.vec(n) for n in (Q, QD, Q_REF, QD_REF, QDD_REF))

    def refresh(self, sym: Symbols, trace: Trace) -> Result:
        u = self.law(sym, trace, sym.h).output_scalar(*self.inputs(sym))
        return Result(dict(zip(U, u)), checks=_errors(trace))


class CTCController(Controller):
    FIXED = {"feedforward": True}


class PIDController(Controller):
    """PID: the state is the integral and the period of the last step (the output's integral update uses it;
    before the first step the default step). The integral is kept when the step size
    changes: it is a sum of ``e h`` whatever each ``h``."""

    n_state = 4  # integral[3], h of the last step
    me_advances = True  # in model exchange the integral advances at each completed integrator step

    def initial_state(self) -> list[float]:
        return [0.0, 0.0, 0.0, self.adapter.EXPERIMENT[2]]  # the default experiment's step

    def law(self, sym: Symbols, trace: Trace, h: Any, **state: Any):  # noqa: ANN201
        law = super().law(sym, trace, h, **state)
        law.i_max = law.u_max
        return law

    def refresh(self, sym: Symbols, trace: Trace) -> Result:
        u = self.law(sym, trace, sym.s[3], integral=list(sym.s[:3])).output_scalar(*self.inputs(sym))
        return Result(dict(zip(U, u)), checks=_errors(trace))

    def advance(self, sym: Symbols, trace: Trace) -> Result:
        _, integral = self.law(sym, trace, sym.h, integral=list(sym.s[:3]))._evaluate(*self.inputs(sym))
        return Result(state=[*integral, sym.h], checks=_errors(trace))


# ----------------------------------------------------------------------------- analytic plant

WORKSPACE = "the platform left the workspace: "


def _end_stops(model, leg: int, q) -> list[Check]:
    """Joint ``leg`` (0-based) within its range, below and above, each failing with the reason
    :func:`delta.kinematics.joint_limit_reason` gives (``END_STOP: leg 3 joint limit: q = 0.5803 m > q_max = 0.5800
    m``): the joint value and the limit printed as the actuator shows them (:attr:`delta.actuators.Rail.Q_PRINTF`)."""
    fmt, factor = model.actuator.Q_PRINTF
    return [Check(ok, f"{END_STOP}: " + JOINT_LIMIT[above].format(leg=leg + 1, q=fmt, limit=fmt),
                  values=(q[leg] * factor, limit * factor))
            for above, (ok, limit) in enumerate(((ca.logic_not(q[leg] < model.q_min), model.q_min),  # NaN holds:
                                                 (ca.logic_not(q[leg] > model.q_max), model.q_max)))]  # named apart


class AnalyticPlant(NativeModel):
    """As :class:`fmus.adapters.analytic_plant.AnalyticPlant` (co-simulation: RK4 in platform coordinates, the state
    ``p, v``, substeps of at most ``solver.max_step``) and :class:`fmus.adapters.plant_me.AnalyticPlantME`
    (model exchange: the same platform dynamics, states ``p, v``, the joints ``q, qd`` as outputs) in one model: both
    FMUs of the analytic plant, whichever adapter their definition holds, have the co-simulation adapter's variables
    and the model-exchange adapter's continuous states."""

    n_state = 6
    max_step = "solver.max_step"
    me_adapter = plant_me.AnalyticPlantME
    me_accepts = True  # the end stops, on accepted states (derivatives see the integrator's trial states)
    me_outputs = True  # q, qd of accepted states only, not at each of the integrator's evaluations

    def __init__(self, kind: str | None, adapter: type) -> None:
        super().__init__(kind, analytic_plant.AnalyticPlant)

    def start(self, sym: Symbols, trace: Trace) -> Result:
        model = self.model(sym, trace)
        p0, v0 = sym.vec(P0), sym.vec(V0)
        q, qd, _, _ = inverse_kinematics(model, p0, v0)
        checks = _errors(trace, "initial platform state: ")
        max_step = sym.v["solver.max_step"]
        checks.append(Check(ca.logic_and(max_step > 0.0, SYMBOLIC.isfinite(max_step)),
                            "solver.max_step must be a time > 0 s"))
        return Result(dict(zip(Q + QD + P + V, (*q, *qd, *p0, *v0))), [*p0, *v0], checks)

    def _joints(self, model, p, v, trace: Trace) -> tuple[Any, Any, list[Check]]:  # noqa: ANN001
        """``q, qd`` of the platform state ``p, v`` (at a step's end or an accepted state, never an RK stage or a
        trial state), and their checks: a leg with no solution (the platform left the workspace), a joint past
        its range (an end stop, printed as :func:`delta.kinematics.joint_limit_reason` prints it)."""
        q, qd, _, _ = inverse_kinematics(model, p, v)
        checks = []
        for c in _errors(trace, WORKSPACE):
            beyond = c.reason.removeprefix(WORKSPACE)
            checks += _end_stops(model, BEYOND_LIMITS.index(beyond), q) if beyond in BEYOND_LIMITS else [c]
        return q, qd, checks

    def refresh(self, sym: Symbols, trace: Trace) -> Result:
        model = self.model(sym, trace)
        p, v = sym.s[:3], sym.s[3:]
        checks = [Check(_all(SYMBOLIC.isfinite(x) for x in sym.s), "the state diverged (not finite)")]
        q, qd, joints = self._joints(model, p, v, trace)
        return Result(dict(zip(Q + QD + P + V, (*q, *qd, *p, *v))), checks=checks + joints)

    def accept(self, sym: Symbols, trace: Trace) -> Result:
        q, qd, checks = self._joints(self.model(sym, trace), sym.vec(P), sym.vec(V), trace)
        return Result(dict(zip(Q + QD, (*q, *qd))), checks=checks)

    def advance(self, sym: Symbols, trace: Trace) -> Result:
        model = self.model(sym, trace)
        u = sym.vec(U)
        checks = [Check(_all(SYMBOLIC.isfinite(x) for x in u), "non-finite effort u")]
        p, v = platform_step(model, sym.s[:3], sym.s[3:], u, sym.h)
        checks += [Check(c.ok, (WORKSPACE + c.reason) if "no solution" in c.reason else c.reason)
                   for c in _errors(trace)]
        return Result(state=[*p, *v], checks=checks)

    def derivatives(self, sym: Symbols, trace: Trace) -> Result:
        model = self.model(sym, trace)
        v = sym.vec(V)
        a = platform_dynamics(model, sym.vec(P), v, sym.vec(U))
        checks = [Check(c.ok, (WORKSPACE + c.reason) if "no solution" in c.reason else c.reason)
                  for c in _errors(trace)]
        return Result(dict(zip(DP + DV, (*v, *a))), checks=checks)
