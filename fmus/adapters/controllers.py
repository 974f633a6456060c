"""Joint-space controller FMUs: PD, PID, PD+ and CTC (delta.control) at the communication step.

Inputs are the measured joint state ``q``, ``qd`` and the references ``q_ref``,
``qd_ref``, ``qdd_ref``; the output is the actuator effort ``u``. The control law is
evaluated once per communication step on the inputs at the start of the step and
held over it (a discrete controller at sample period ``h`` = the step size), like
the thesis's MATLAB controller driving ADAMS. The gains start at the tuned defaults
of :data:`delta.control.DEFAULT_GAINS`.
"""

from __future__ import annotations

from operator import itemgetter

from delta.control import CTC, DEFAULT_GAINS, PD, PID, PDPlus
from delta.model import build_model

from ..export2 import Adapter, joint_names, writer
from .common import declare_masses, declare_robot, home_joints, masses_from, q_units, robot_from

Q, QD = joint_names("q"), joint_names("qd")
Q_REF, QD_REF, QDD_REF = joint_names("q_ref"), joint_names("qd_ref"), joint_names("qdd_ref")
U = joint_names("u")
_read_inputs = itemgetter(*Q, *QD, *Q_REF, *QD_REF, *QDD_REF)  # values -> the 15 inputs, in _inputs order
_WRITE_U = writer(U)


class _Controller(Adapter):
    """Shared interface; subclasses set ``LAW`` (key of DEFAULT_GAINS) and ``GAINS`` (gain names and units)."""

    EXPERIMENT = (0.0, 1.0, 1e-3)
    LAW = ""
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

    def make_law(self, h: float):  # pragma: no cover - overridden
        raise NotImplementedError

    def start(self) -> None:
        self.law = None
        self.u_max = self.values["limit.u_max"] or None

    def gains(self, name: str):
        return self.vec(joint_names(f"gain.{name}"))

    def _inputs(self):
        """(q, qd, q_ref, qd_ref, qdd_ref), each a tuple of three floats."""
        x = _read_inputs(self.values)
        return x[0:3], x[3:6], x[6:9], x[9:12], x[12:15]

    def advance(self, t: float, h: float) -> None:
        """One control period ends: commit the law's state (the PID integral) for the inputs
        that held during the step; the effort applied over the step was already output.

        The law's period follows the step size, its state is kept: the PID integral is a sum of ``e h``, so a
        step of another length adds ``e h`` of that length to it. (A master's step sizes differ by an ulp from
        step to step when each lands exactly on its communication point.)"""
        if self.law is None or not h > 0.0:  # a period <= 0 is refused as the law's parameter
            self.law = self.make_law(h)
        self.law.h = h
        if self.law.stateful:  # stateless laws: the effort output before the step is all there is
            self.law.step(*self._inputs())

    def retune(self, names: tuple[str, ...]) -> None:
        """Gains, the saturation or (model-based laws) the payload changed: the law of the new values, with the
        period and the state (a PID's integral) of the current one."""
        self.u_max = self.values["limit.u_max"] or None
        if self.law is not None:
            law = self.make_law(self.law.h)
            if law.stateful:
                law.integral = list(self.law.integral)
            self.law = law

    def internal_state(self) -> dict:
        """The law's period and (PID) integral; no law yet (none is made before the first output or step)."""
        law = self.law
        if law is None:
            return {"law": False}
        return {"law": True, "h": law.h, "integral": list(law.integral) if law.stateful else []}

    def restore_internal(self, state: dict) -> None:
        """The law is made again only if there is none: one of the current parameters is the state's."""
        if not state["law"]:
            self.law = None
            return
        if self.law is None:
            self.law = self.make_law(state["h"])
        self.law.h = state["h"]
        if self.law.stateful:
            self.law.integral = list(state["integral"])

    def refresh(self) -> None:
        # Direct feedthrough without side effects: the master sets the step's inputs,
        # reads u, then calls doStep, which commits the state (see advance). The law's
        # period is the communication step, known at the first doStep; before it the
        # DefaultExperiment's step is assumed (it only scales the PID integral update).
        if self.law is None:
            self.law = self.make_law(self.EXPERIMENT[2])
        _WRITE_U(self.values, self.law.output_scalar(*self._inputs()))


class PDController(_Controller):
    """PD (thesis eq. (39)): u = Kp (q_ref - q) + Kd (qd_ref - qd)."""

    LAW = "pd"

    def make_law(self, h: float):
        return PD(self.gains("kp"), self.gains("kd"), h, u_max=self.u_max)


class PIDController(_Controller):
    """PID (thesis eq. (40)) with conditional-integration anti-windup and saturation."""

    LAW = "pid"

    def make_law(self, h: float):
        return PID(self.gains("kp"), self.gains("ki"), self.gains("kd"), h, u_max=self.u_max)


class PDPlusController(_Controller):
    """PD with gravity compensation G(q) from the analytic model."""

    LAW = "pdplus"
    MODEL_BASED = True

    def feedthrough(self, i: int) -> tuple[str, ...]:
        """The PD terms of leg i plus G(q), which couples the legs through the platform."""
        return (*Q, QD[i], Q_REF[i], QD_REF[i])

    def make_law(self, h: float):
        model = build_model(robot_from(self, self.KIND), masses_from(self, self.KIND))
        return PDPlus(model, self.gains("kp"), self.gains("kd"), h, u_max=self.u_max)


class CTCController(_Controller):
    """Computed torque (thesis eq. (50)): u = M (qdd_ref + Kd e_dot + Kp e) + C qd + G (Kp in 1/s^2, Kd in 1/s)."""

    LAW = "ctc"
    MODEL_BASED = True

    def feedthrough(self, i: int) -> tuple[str, ...]:
        """Every input: M(q) couples the legs' outer-loop terms, C(q, qd) qd and G(q) every joint."""
        return (*Q, *QD, *Q_REF, *QD_REF, *QDD_REF)

    def gain_unit(self, name: str, uu: str, qu: str) -> tuple[str, str]:
        return ({"kp": "1/s2", "kd": "1/s"}[name],
                {"kp": "outer-loop stiffness (natural frequency squared)", "kd": "outer-loop damping"}[name])

    def make_law(self, h: float):
        model = build_model(robot_from(self, self.KIND), masses_from(self, self.KIND))
        return CTC(model, self.gains("kp"), self.gains("kd"), h, u_max=self.u_max)
