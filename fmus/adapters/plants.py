"""Plant FMUs: the analytic model integrated between communication points, and the Exudyn plant."""

from __future__ import annotations

from math import isfinite

from delta.dynamics import integrate
from delta.errors import DeltaError, ParameterError, UnreachableError
from delta.kinematics import END_STOP, inverse_kinematics, joint_limit_reason
from delta.model import build_model

from ..export2 import Adapter, axis_names, joint_names, writer
from .common import (
    P0,
    V0,
    declare_initial_state,
    declare_masses,
    declare_robot,
    hold_effort,
    initial_joint_state,
    masses_from,
    q_units,
    robot_from,
)

Q, QD, U = joint_names("q"), joint_names("qd"), joint_names("u")
P, V = axis_names("p"), axis_names("v")
REACTION = joint_names("reaction")
_WRITE_STATE = writer(Q, QD, P, V)  # (values, q, qd, p, v): AnalyticPlant.refresh
_WRITE_EXUDYN_OUTPUTS = writer(Q, QD, P, V, REACTION)  # (values, q, qd, p, v, reaction): ExudynPlant._show


def declare_plant_interface(fmu: Adapter, kind: str) -> None:
    """Inputs u, outputs q, qd, p, v and the initial-state parameters shared by the plants."""
    qu, qdu, _, uu = q_units(kind)
    declare_robot(fmu, kind)
    declare_masses(fmu, kind)
    declare_initial_state(fmu, kind)
    fmu.inputs3(U, uu, "actuator effort along +q", hold_effort(kind))
    # the efforts act through the dynamics: no output depends directly on u
    fmu.outputs3(Q, qu, "joint position", depends=())
    fmu.outputs3(QD, qdu, "joint velocity", depends=())
    fmu.outputs3(P, "m", "platform position", depends=())
    fmu.outputs3(V, "m/s", "platform velocity", depends=())


class AnalyticPlant(Adapter):
    """Analytic virtual-work dynamics (:mod:`delta.dynamics`) integrated with the classical fixed-step
    Runge-Kutta method in platform coordinates (:func:`delta.dynamics.integrate`) under the effort u
    held over the step (zero-order hold).

    A communication step ``h`` is split into ``ceil(h / solver.max_step)`` equal RK4 steps, so any
    ``h > 0`` is accepted. Within a step the effort is constant and the robot's own motion is slow
    (the helix turns at 0.5 Hz): on 10 s of the helix under CTC, 1 ms steps stay within 2e-14 m of a
    16-substep reference (RK3: 1.1e-11 m, the midpoint rule: 1.7e-8 m, which already changes the
    tracking RMSE by 16 %). A state that leaves the workspace or the joint range (the end stops, as the Exudyn
    plant), meets a singularity or stops being finite (an absurd effort) fails the step (fmi2Discard) with the
    reason logged. ``mass.payload`` (tunable) takes effect at the next step, the motion kept.
    """

    EXPERIMENT = (0.0, 1.0, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = f"Analytic dynamics plant of the {self.KIND} delta (co-simulation)"
        declare_plant_interface(self, self.KIND)
        self.parameter("solver.max_step", 1e-3, "s",
                       "longest Runge-Kutta step; a longer communication step is split into equal steps")

    def start(self) -> None:
        self.model = build_model(robot_from(self, self.KIND), masses_from(self, self.KIND))
        max_step = self.values["solver.max_step"]
        if not (max_step > 0.0 and isfinite(max_step)):
            raise ParameterError(f"solver.max_step must be a time > 0 s, got {max_step!r}")
        self.q, self.qd = initial_joint_state(self, self.model)  # raises if the initial state is unreachable
        self.p, self.v = self.vec3(P0), self.vec3(V0)

    def advance(self, t: float, h: float) -> None:
        try:
            p, v = integrate(self.model, self.p, self.v, self.vec3(U), h, self.values["solver.max_step"])
            q, qd, _, fault = inverse_kinematics(self.model, p, v)  # at the step's end (no RK stage): the limits too
            if fault > 0:
                raise UnreachableError(f"the platform left the workspace at p = ({p[0]:.6g}, {p[1]:.6g}, "
                                       f"{p[2]:.6g}) m: leg {fault} has no solution")
            if fault < 0:  # as the Exudyn plant (multibody.DeltaPlant.step): a joint past its range stops the plant
                raise UnreachableError(f"{END_STOP}: {joint_limit_reason(self.model, -fault, q[-fault - 1])}")
        except DeltaError as exc:
            raise type(exc)(f"{self.modelName} at t = {t:.6f} s: {exc}") from None
        self.p, self.v, self.q, self.qd = p, v, q, qd

    def refresh(self) -> None:
        _WRITE_STATE(self.values, self.q, self.qd, self.p, self.v)

    def retune(self, names: tuple[str, ...]) -> None:
        """The payload changed: the model of the new masses, the motion (p, v, q, qd) kept."""
        self.model = build_model(robot_from(self, self.KIND), masses_from(self, self.KIND))

    def internal_state(self) -> dict:
        """The integrated platform state and its joints (the outputs hold them only until the next step's refresh)."""
        return {"q": list(self.q), "qd": list(self.qd), "p": list(self.p), "v": list(self.v)}

    def restore_internal(self, state: dict) -> None:
        self.q, self.qd, self.p, self.v = (tuple(state[k]) for k in ("q", "qd", "p", "v"))


class ExudynPlant(Adapter):
    """Exudyn multibody plant (multibody.make_plant), ``model.fidelity`` = "full" or "lumped".

    Any communication step h > 0 is accepted (:meth:`multibody.DeltaPlant.step`): a step longer
    than ``solver.max_step`` is integrated in equal steps no longer than it, and a remainder below
    the plant's resolution (1 ns, :class:`multibody.SolverSettings` ``min_step``), such as the
    1e-13 s last step of a tool that adds float steps, is absorbed: the FMU's time advances, the
    outputs keep the state at most 1 ns old, and the next step integrates that interval with its
    own. A step the solver cannot take returns fmi2Discard with the solver's message logged.

    ``mass.payload`` (tunable) changes the platform's mass and weight in the running system; the FMU state holds
    the whole multibody and solver state (:meth:`multibody.DeltaPlant.get_state`), and setting one rebuilds the
    system only when a fixed parameter differs.
    """

    EXPERIMENT = (0.0, 0.5, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        kind = self.KIND
        qu, qdu, _, uu = q_units(kind)
        self.description = f"Exudyn multibody plant of the {kind} delta (full rigid legs or lumped point masses)"
        declare_robot(self, kind)
        declare_masses(self, kind)
        self.parameter("model.fidelity", "full", None, "multibody fidelity: full (rigid rods) or lumped (point masses)")
        self.parameter("solver.max_step", 1e-3, "s",
                       "longest integrator step; a longer communication step is split into equal steps")
        declare_initial_state(self, kind)
        self.inputs3(U, uu, "actuator effort along +q", hold_effort(kind))
        # the efforts act through the dynamics, and reaction is the effort held over the last step:
        # no output depends directly on u
        self.outputs3(Q, qu, "joint position", depends=())
        self.outputs3(QD, qdu, "joint velocity", depends=())
        self.outputs3(P, "m", "platform position", depends=())
        self.outputs3(V, "m/s", "platform velocity", depends=())
        self.outputs3(REACTION, uu, "actuator effort applied during the last step", depends=())

    def start(self) -> None:
        from multibody import SolverSettings, make_plant

        self.plant = make_plant(robot_from(self, self.KIND), masses_from(self, self.KIND),
                                fidelity=self.values["model.fidelity"],
                                settings=SolverSettings(max_step=self.values["solver.max_step"]))
        self._show(self.plant.reset(self.vec(P0), self.vec(V0), t0=self.time))

    def _show(self, out) -> None:
        _WRITE_EXUDYN_OUTPUTS(self.values, out.q.tolist(), out.qd.tolist(), out.p.tolist(), out.v.tolist(),
                              out.reaction.tolist())

    def advance(self, t: float, h: float) -> None:
        self._show(self.plant.step(t, h, self.vec3(U)))

    def retune(self, names: tuple[str, ...]) -> None:
        """The payload changed: the platform carries it from the next step on, in the running system
        (:meth:`multibody.DeltaPlant.set_payload`)."""
        self.plant.set_payload(self.values["mass.payload"])

    def internal_state(self) -> dict:
        """The whole multibody and solver state (:meth:`multibody.DeltaPlant.get_state`)."""
        return self.plant.get_state()

    def restore_internal(self, state: dict) -> None:
        self.plant.set_state(state)
