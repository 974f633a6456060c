"""The analytic plant as a co-simulation FMU: the analytic model integrated between communication points."""

from __future__ import annotations

from .._names import axis_names, joint_names
from ..export2 import Adapter
from ..traced import TracedCS
from .common import declare_initial_state, declare_masses, declare_robot, hold_effort, q_units


def declare_plant_interface(fmu, kind: str) -> None:  # noqa: ANN001
    """Inputs u, outputs q, qd, p, v and the robot, mass and initial-state parameters of the analytic plant."""
    qu, qdu, _, uu = q_units(kind)
    q, qd, u = joint_names("q"), joint_names("qd"), joint_names("u")
    declare_robot(fmu, kind)
    declare_masses(fmu, kind)
    declare_initial_state(fmu, kind)
    fmu.inputs3(u, uu, "actuator effort along +q", hold_effort(kind))
    # the efforts act through the dynamics: no output depends directly on u
    fmu.outputs3(q, qu, "joint position", depends=())
    fmu.outputs3(qd, qdu, "joint velocity", depends=())
    fmu.outputs3(axis_names("p"), "m", "platform position", depends=())
    fmu.outputs3(axis_names("v"), "m/s", "platform velocity", depends=())


class AnalyticPlant(TracedCS, Adapter):
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

    What it computes is its native model's (:class:`fmus.native.models.AnalyticPlant`), which both builds evaluate
    (:mod:`fmus.traced`).
    """

    EXPERIMENT = (0.0, 1.0, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.description = f"Analytic dynamics plant of the {self.KIND} delta (co-simulation)"
        declare_plant_interface(self, self.KIND)
        self.parameter("solver.max_step", 1e-3, "s",
                       "longest Runge-Kutta step; a longer communication step is split into equal steps")
