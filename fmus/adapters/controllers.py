"""Joint-space controller FMUs: PD, PID, PD+ and CTC (delta.control) at the communication step.

Inputs are the measured joint state ``q``, ``qd`` and the references ``q_ref``,
``qd_ref``, ``qdd_ref``; the output is the actuator effort ``u``. The control law is
evaluated once per communication step on the inputs at the start of the step and
held over it (a discrete controller at sample period ``h`` = the step size), like
the thesis's MATLAB controller driving ADAMS. The gains start at the tuned defaults
of :data:`delta.control.DEFAULT_GAINS`.

This module declares each controller's interface; what it computes is its native model's
(:class:`fmus.native.models.Controller` and subclasses: the law's ``output_scalar`` on the inputs), which both
builds evaluate (:mod:`fmus.traced`).
"""

from __future__ import annotations

from delta.control import CTC, DEFAULT_GAINS, PD, PID, PDPlus

from ..export2 import Adapter, joint_names
from ..traced import TracedCS
from .common import declare_masses, declare_robot, home_joints, q_units

Q, QD = joint_names("q"), joint_names("qd")
Q_REF, QD_REF, QDD_REF = joint_names("q_ref"), joint_names("qd_ref"), joint_names("qdd_ref")
U = joint_names("u")


class _Controller(TracedCS, Adapter):
    """Shared interface; subclasses set ``LAW`` (key of DEFAULT_GAINS), ``LAW_CLASS`` (the law of
    :mod:`delta.control`) and ``GAINS`` (gain names and units)."""

    EXPERIMENT = (0.0, 1.0, 1e-3)
    LAW = ""
    LAW_CLASS: type = PD
    MODEL_BASED = False

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        kind = self.KIND
        qu, qdu, qddu, uu = q_units(kind)
        self.description = f"{self.LAW.upper()} joint-space controller of the {kind} delta"
        gains = DEFAULT_GAINS[kind][self.LAW]
        for name, value in gains.items():
            unit, text = self.gain_unit(name, uu, qu)
            self.parameters3(joint_names(f"gain.{name}"), (value,) * 3, unit, text, tunable=True)
        self.parameter("limit.u_max", DEFAULT_GAINS[kind]["u_max"]["u_max"], uu,
                       "actuator saturation |u[i]| <= u_max (0 = none)", tunable=True)
        if self.MODEL_BASED:
            declare_robot(self, kind)
            declare_masses(self, kind)
        q0 = home_joints(kind)
        self.inputs3(Q, qu, "measured joint position", q0)
        self.inputs3(QD, qdu, "measured joint velocity")
        self.inputs3(Q_REF, qu, "desired joint position", q0)
        self.inputs3(QD_REF, qdu, "desired joint velocity")
        self.inputs3(QDD_REF, qddu, "desired joint acceleration")
        self.outputs3(U, uu, "actuator effort along +q", depends=self.feedthrough)

    def feedthrough(self, i: int) -> tuple[str, ...]:
        """Inputs that ``u[i + 1]`` depends on directly: PD and PID act leg by leg."""
        return Q[i], QD[i], Q_REF[i], QD_REF[i]

    def gain_unit(self, name: str, uu: str, qu: str) -> tuple[str, str]:
        unit = {"kp": f"{uu}/{qu}", "kd": f"{uu}.s/{qu}", "ki": f"{uu}/({qu}.s)"}[name]
        what = {"kp": "proportional", "kd": "derivative", "ki": "integral"}[name]
        return unit, f"{what} gain"


class PDController(_Controller):
    """PD (thesis eq. (39)): u = Kp (q_ref - q) + Kd (qd_ref - qd)."""

    LAW, LAW_CLASS = "pd", PD


class PIDController(_Controller):
    """PID (thesis eq. (40)) with conditional-integration anti-windup and saturation."""

    LAW, LAW_CLASS = "pid", PID


class PDPlusController(_Controller):
    """PD with gravity compensation G(q) from the analytic model."""

    LAW, LAW_CLASS = "pdplus", PDPlus
    MODEL_BASED = True

    def feedthrough(self, i: int) -> tuple[str, ...]:
        """The PD terms of leg i plus G(q), which couples the legs through the platform."""
        return (*Q, QD[i], Q_REF[i], QD_REF[i])


class CTCController(_Controller):
    """Computed torque (thesis eq. (50)): u = M (qdd_ref + Kd e_dot + Kp e) + C qd + G (Kp in 1/s^2, Kd in 1/s)."""

    LAW, LAW_CLASS = "ctc", CTC
    MODEL_BASED = True

    def feedthrough(self, i: int) -> tuple[str, ...]:
        """Every input: M(q) couples the legs' outer-loop terms, C(q, qd) qd and G(q) every joint."""
        return (*Q, *QD, *Q_REF, *QD_REF, *QDD_REF)

    def gain_unit(self, name: str, uu: str, qu: str) -> tuple[str, str]:
        return ({"kp": "1/s2", "kd": "1/s"}[name],
                {"kp": "outer-loop stiffness (natural frequency squared)", "kd": "outer-loop damping"}[name])
