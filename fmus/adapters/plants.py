"""Plant FMUs: the analytic model integrated between communication points, and the Exudyn plant."""

from __future__ import annotations

import numpy as np
from scipy.integrate import solve_ivp

from delta.dynamics import analytic_model

from .._fmi import Adapter, axis_names, joint_names, writer
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


class _TooManyEvaluations(Exception):
    pass


class AnalyticPlant(Adapter):
    """Analytic virtual-work dynamics (delta.dynamics) integrated by DOP853 over each communication step,
    with the effort u held constant over the step (zero-order hold).

    A step needing more than :attr:`MAX_EVALUATIONS` evaluations of the dynamics fails (fmi2Discard,
    the reason logged) instead of crawling on: an absurd effort (``u_max = 1e300``) makes the
    model so stiff that DOP853's steps shrink to ~1e-12 s and never reach the step's end.
    """

    EXPERIMENT = (0.0, 1.0, 1e-3)
    MAX_EVALUATIONS = 20000
    """Per communication step: a 1 ms step of the helix takes 12 to ~100; 20000 take ~0.5 s."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = f"Analytic dynamics plant of the {self.KIND} delta (co-simulation)"
        declare_plant_interface(self, self.KIND)
        self.parameter("solver.rtol", 1e-10, "1", "relative tolerance of the DOP853 integrator")
        self.parameter("solver.atol", 1e-12, "1", "absolute tolerance of the DOP853 integrator")

    def start(self) -> None:
        robot = robot_from(self, self.KIND)
        self.model = analytic_model(robot, masses_from(self, self.KIND))
        self.state = initial_joint_state(self, robot)

    def _rhs(self, t: float, x: np.ndarray, u: np.ndarray) -> np.ndarray:
        self._evaluations += 1
        if self._evaluations > self.MAX_EVALUATIONS:
            raise _TooManyEvaluations
        return np.concatenate([x[3:], self.model.forward_dynamics(x[:3], x[3:], u)])

    def advance(self, t: float, h: float) -> None:
        """DOP853 over [t, t + h] (adaptive: any h > 0); a non-finite effort or state fails the step."""
        u = self.vec(U)
        if not np.all(np.isfinite(u)):
            raise ValueError(f"non-finite effort u = {u.tolist()}")
        self._evaluations = 0
        try:
            sol = solve_ivp(self._rhs, (t, t + h), self.state, method="DOP853", args=(u,),
                            rtol=self.values["solver.rtol"], atol=self.values["solver.atol"])
        except _TooManyEvaluations:
            raise RuntimeError(f"{self.modelName} at t = {t:.6f} s: DOP853 needed more than {self.MAX_EVALUATIONS} "
                               f"evaluations of the dynamics for a step of {h:g} s (stiff or diverging; effort "
                               f"u = {u.tolist()})") from None
        if not sol.success or not np.all(np.isfinite(sol.y[:, -1])):
            raise RuntimeError(f"{self.modelName} at t = {t:.6f} s: integration failed: {sol.message}")
        self.state = sol.y[:, -1]

    def refresh(self) -> None:
        q, qd = self.state[:3], self.state[3:]
        self.put(Q, q)
        self.put(QD, qd)
        p, v = self.model.platform_state(q, qd)
        self.put(P, p)
        self.put(V, v)


class ExudynPlant(Adapter):
    """Exudyn multibody plant (multibody.make_plant), ``model.fidelity`` = "full" or "lumped".

    Any communication step h > 0 is accepted (:meth:`multibody.DeltaPlant.step`): a step longer
    than ``solver.max_step`` is integrated in equal steps no longer than it, and a remainder below
    the plant's resolution (1 ns, :class:`multibody.SolverSettings` ``min_step``), such as the
    1e-13 s last step of a tool that adds float steps, is absorbed: the FMU's time advances, the
    outputs keep the state at most 1 ns old, and the next step integrates that interval with its
    own. A step the solver cannot take returns fmi2Discard with the solver's message logged.
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
