"""The Exudyn plant FMU: the multibody model (:mod:`multibody`) in the role of ADAMS."""

from __future__ import annotations

from ..export2 import Adapter, axis_names, joint_names, writer
from .common import (
    P0,
    V0,
    declare_initial_state,
    declare_masses,
    declare_robot,
    hold_effort,
    masses_from,
    q_units,
    robot_from,
)

Q, QD, U = joint_names("q"), joint_names("qd"), joint_names("u")
P, V = axis_names("p"), axis_names("v")
REACTION = joint_names("reaction")
_WRITE_EXUDYN_OUTPUTS = writer(Q, QD, P, V, REACTION)  # (values, q, qd, p, v, reaction): ExudynPlant._show


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
