"""The analytic plant as an FMI 3.0 model-exchange FMU: states p, v (the platform), derivatives from the platform
dynamics of the co-simulation plant; the joints q, qd are outputs."""

from __future__ import annotations

from .._names import axis_names, joint_names
from ..export3 import AdapterME
from ..traced import TracedME
from .common import declare_initial_state, declare_masses, declare_robot, hold_effort, q_units

Q, QD, U = joint_names("q"), joint_names("qd"), joint_names("u")
P, V = axis_names("p"), axis_names("v")
DP, DV = [f"der({n})" for n in P], [f"der({n})" for n in V]


class AnalyticPlantME(TracedME, AdapterME):
    """dp/dt = v, dv/dt = platform_dynamics(p, v, u); the importing tool integrates.

    The same equations as the co-simulation plant (:class:`fmus.adapters.analytic_plant.AnalyticPlant`), which integrates
    them itself with RK4: the virtual-work dynamics in platform coordinates (:func:`delta.dynamics.platform_dynamics`,
    a 3x3 system with no forward kinematics, no ``J^-1`` and no mass matrix), about half the work of the
    joint-space form ``M(q) qdd = u - C qd - G`` per evaluation. The joints are outputs, by inverse kinematics of
    the states: read at communication points, never at the integrator's trial states."""

    EXPERIMENT = (0.0, 1.0, 1e-3)
    LINEAR = frozenset(zip(DP, V))  # dp/dt = v

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        kind = self.KIND
        qu, qdu, _, uu = q_units(kind)
        self.description = f"Analytic dynamics plant of the {kind} delta (model exchange)"
        declare_robot(self, kind)
        declare_masses(self, kind)
        declare_initial_state(self, kind)
        for i in range(3):
            self.input(U[i], uu, f"actuator effort along +q (leg {i + 1})", hold_effort(kind)[i])
        for i, a in enumerate("xyz"):
            self.state(P[i], DP[i], "m", "m/s", f"platform position ({a})", depends=(V[i],))
        for i, a in enumerate("xyz"):  # the platform dynamics: every state and effort
            self.state(V[i], DV[i], "m/s", "m/s2", f"platform velocity ({a})", depends=(*P, *V, *U))
        for i in range(3):  # inverse kinematics: no direct feedthrough of u
            self.output(Q[i], qu, f"joint position (leg {i + 1})", depends=P)
        for i in range(3):
            self.output(QD[i], qdu, f"joint velocity (leg {i + 1})", depends=(*P, *V))
