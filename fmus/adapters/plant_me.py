"""The analytic plant as an FMI 3.0 model-exchange FMU: states q, qd, derivatives from the forward dynamics."""

from __future__ import annotations

from delta.dynamics import forward_dynamics, platform_state
from delta.errors import UnreachableError
from delta.kinematics import END_STOP, joint_limit_reason
from delta.model import Data, build_model

from .._names import axis_names, joint_names
from ..export3 import AdapterME
from .common import (
    declare_initial_state,
    declare_masses,
    declare_robot,
    hold_effort,
    initial_joint_state,
    masses_from,
    q_units,
    robot_from,
)

Q, QD, QDD, U = joint_names("q"), joint_names("qd"), joint_names("qdd"), joint_names("u")
DQ, DQD = [f"der(q[{i}])" for i in (1, 2, 3)], [f"der(qd[{i}])" for i in (1, 2, 3)]
P, V = axis_names("p"), axis_names("v")


class AnalyticPlantME(AdapterME):
    """dq/dt = qd, dqd/dt = forward_dynamics(q, qd, u); the importing tool integrates."""

    EXPERIMENT = (0.0, 1.0, 1e-3)
    LINEAR = frozenset(zip(DQ, QD))  # dq/dt = qd

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        kind = self.KIND
        qu, qdu, qddu, uu = q_units(kind)
        self.description = f"Analytic dynamics plant of the {kind} delta (model exchange)"
        declare_robot(self, kind)
        declare_masses(self, kind)
        declare_initial_state(self, kind)
        for i in range(3):
            self.input(U[i], uu, f"actuator effort along +q (leg {i + 1})", hold_effort(kind)[i])
        for i in range(3):
            self.state(Q[i], DQ[i], qu, qdu, f"joint position (leg {i + 1})", depends=(QD[i],))
        for i in range(3):  # M(q)^-1 (u - C(q, qd) qd - G(q)): every state and effort
            self.state(QD[i], DQD[i], qdu, qddu, f"joint velocity (leg {i + 1})", depends=(*Q, *QD, *U))
        for n, a in zip(P, "xyz"):  # forward kinematics: no direct feedthrough of u
            self.output(n, "m", f"platform position ({a})", depends=Q)
        for n, a in zip(V, "xyz"):
            self.output(n, "m/s", f"platform velocity ({a})", depends=(*Q, *QD))

    def start(self) -> None:
        self.model = build_model(robot_from(self, self.KIND), masses_from(self, self.KIND))
        self.data = Data(self.model)
        q, qd = initial_joint_state(self, self.model)
        self.put(Q, q)
        self.put(QD, qd)

    def retune(self, names: tuple[str, ...]) -> None:
        """The payload changed: the model of the new masses; the states are the importer's."""
        self.model = build_model(robot_from(self, self.KIND), masses_from(self, self.KIND))

    def derivatives(self) -> None:
        qd = self.vec3(QD)
        self.put(DQ, qd)
        self.put(DQD, forward_dynamics(self.model, self.data, self.vec3(Q), qd, self.vec3(U)))

    def outputs(self) -> None:
        """p, v from the states; the end stops as the co-simulation plant's (:mod:`fmus.adapters.plants`): here,
        on the states the importer accepted (the outputs are read at communication points, never at the
        integrator's trial states, which only ``derivatives`` sees; pythonfmu3 does not pass
        ``completedIntegratorStep`` on to Python)."""
        q = self.vec3(Q)
        model = self.model
        for i, qi in enumerate(q):
            if qi < model.q_min or qi > model.q_max:  # not NaN: the master names a NaN output itself
                raise UnreachableError(f"{self.modelName} at t = {self.time:.6f} s: {END_STOP}: "
                                       f"{joint_limit_reason(model, i + 1, qi)}")
        p, v = platform_state(model, self.data, q, self.vec3(QD))
        self.put(P, p)
        self.put(V, v)
