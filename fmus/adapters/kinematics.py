"""Inverse and forward kinematics FMUs on the per-pose path of :mod:`delta.kinematics`."""

from __future__ import annotations

from operator import itemgetter

from pythonfmu.enums import Fmi2Status

from delta.actuators import kind_of
from delta.dynamics import platform_state
from delta.errors import RobotError, UnreachableError
from delta.kinematics import (
    inverse_kinematics,
    joint_limit_reason,
    proximity,
    set_pose,
    solve_ik,
    working_mode_fault,
)
from delta.model import Data, build_model

from ..export2 import Adapter, axis_names, joint_names, writer
from .common import declare_robot, home, home_joints, q_units, robot_from

P_REF, V_REF, A_REF = axis_names("p_ref"), axis_names("v_ref"), axis_names("a_ref")
Q_REF, QD_REF, QDD_REF = joint_names("q_ref"), joint_names("qd_ref"), joint_names("qdd_ref")
_read_refs = itemgetter(*P_REF, *V_REF, *A_REF)  # values -> p_ref, v_ref, a_ref as one tuple
_WRITE_JOINT_REFS = writer(Q_REF, QD_REF, QDD_REF)  # (values, q, qd, qdd): refresh's store
P, V = axis_names("p"), axis_names("v")
Q, QD = joint_names("q"), joint_names("qd")
PROXIMITY = "singularity.proximity"


class InverseKinematics(Adapter):
    """p_ref, v_ref, a_ref -> q_ref, qd_ref, qdd_ref, reachability and singularity proximity.

    When the reference leaves the workspace ``reachable`` drops to false and the joint
    references hold their last reachable values (no NaN reaches the controller).

    ``singularity.proximity`` is computed when it is read: a refresh that does not need it
    (reachable pose, ``singularity.margin <= 0``, which no proximity in [0, 1] is below)
    keeps the pose and leaves it pending; reading the output (fmi2GetReal, its getter, the
    FMU state) computes it for that pose, so every value read is the one an eager refresh
    would have stored.
    """

    EXPERIMENT = (0.0, 1.0, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        kind = self.KIND
        qu, qdu, qddu, _ = q_units(kind)
        self.description = f"Inverse kinematics of the {kind} delta"
        declare_robot(self, kind)
        self.parameter("singularity.margin", 0.0, "1",
                       "minimum singularity proximity for a reachable point (0 = only exact singularities)",
                       tunable=True)
        self.inputs3(P_REF, "m", "desired platform position", home(kind))
        self.inputs3(V_REF, "m/s", "desired platform velocity")
        self.inputs3(A_REF, "m/s2", "desired platform acceleration")
        # Each leg's IK needs the whole platform position; rates add v_ref, accelerations a_ref.
        # On vertical rails (linear delta) a vertical shift or velocity moves every carriage alike
        # and leaves the legs' geometry and relative velocities unchanged: the Jacobian, qd_ref
        # (no p_ref.z), qdd_ref (no p_ref.z, v_ref.z) and the proximity do not depend on them.
        vertical_invariant = kind_of(kind).vertical_invariant
        shape = P_REF[:2] if vertical_invariant else P_REF
        shape_rate = V_REF[:2] if vertical_invariant else V_REF
        self.outputs3(Q_REF, qu, "desired joint position", depends=P_REF)
        self.outputs3(QD_REF, qdu, "desired joint velocity", depends=shape + V_REF)
        self.outputs3(QDD_REF, qddu, "desired joint acceleration", depends=shape + shape_rate + A_REF)
        self.output("reachable", None, "true when p_ref is reachable within joint limits and singularity margin",
                    depends=P_REF, kind="boolean")
        self.output("singularity.proximity", "1", "singularity proximity of the pose p_ref (0 = singular)",
                    depends=shape)
        self._proximity_vr = next(v.value_reference for v in self.vars.values() if v.name == PROXIMITY)
        self._pending_pose = None

    def _getter(self, name: str, is_output: bool):
        get = super()._getter(name, is_output)
        if name != PROXIMITY:
            return get

        def get_proximity():
            value = get()  # refreshes if an input changed
            return self._settle_proximity() if self._pending_pose is not None else value
        return get_proximity

    def _settle_proximity(self) -> float:
        """Compute the pending proximity of the last refreshed pose and store it."""
        q, p = self._pending_pose
        self._pending_pose = None
        value = self.values[PROXIMITY] = proximity(set_pose(self.model, self.data, q, p))
        return value

    def _get_plan(self, vrs):
        """fmi2GetReal plans that include the proximity settle it after the refresh, before reading."""
        plan = super()._get_plan(vrs)
        if plan is None or self._proximity_vr not in vrs:
            return plan
        reads_outputs, read = plan

        def read_settled(values):
            if self._pending_pose is not None:
                self._settle_proximity()
            return read(values)
        return reads_outputs, read_settled

    def start(self) -> None:
        self.model = build_model(robot_from(self, self.KIND))
        self.data = Data(self.model)
        self._reachable = True
        self._pending_pose = None

    def internal_state(self) -> dict:
        """Whether the last reference was reachable (the warning is logged once, when it leaves the workspace)
        and the pose whose proximity is pending (see the class docstring)."""
        pending = self._pending_pose
        return {"reachable": self._reachable,
                "pending": None if pending is None else [list(pending[0]), list(pending[1])]}

    def restore_internal(self, state: dict) -> None:
        self._reachable = state["reachable"]
        pending = state["pending"]
        self._pending_pose = None if pending is None else (tuple(pending[0]), tuple(pending[1]))

    def _unreachable_reason(self, p, q, fault: int) -> tuple[str | None, float | None]:
        """Why ``p_ref`` is not reachable (None if it is) and its singularity proximity (0 when unknown,
        None when not needed yet: see the class docstring), with the checks and messages of
        :func:`delta.workspace.check_point`; ``fault`` as :func:`delta.kinematics.inverse_kinematics` gives it."""
        if fault > 0:
            return f"leg {fault} has no solution", 0.0
        if fault < 0:
            return joint_limit_reason(self.model, -fault, q[-fault - 1]), 0.0
        margin = self.values["singularity.margin"]
        if margin <= 0.0:
            return None, None
        value = proximity(set_pose(self.model, self.data, q, p))
        if value < margin:
            return f"too close to a singularity: proximity {value:.3g} < margin {margin:g}", value
        return None, value

    def refresh(self) -> None:
        x = _read_refs(self.values)
        p = x[0:3]
        try:
            q, qd, qdd, fault = inverse_kinematics(self.model, p, x[3:6], x[6:9])
        except RobotError:  # a type 1 singularity: unreachable under any margin > 0, an error without one
            if self.values["singularity.margin"] <= 0.0:
                raise
            (q, fault), qd = solve_ik(self.model, p), None
        reason, proximity = self._unreachable_reason(p, q, fault)
        values = self.values
        values["reachable"] = reason is None
        if proximity is None:
            self._pending_pose = (q, p)
        else:
            self._pending_pose = None
            values[PROXIMITY] = proximity
        if reason is not None:
            if self._reachable:  # say why once, when the reference leaves the workspace
                self.log(f"t = {self.time:.6g} s: p_ref = ({p[0]:.4f}, {p[1]:.4f}, {p[2]:.4f}) m is unreachable: "
                         f"{reason}; joint references hold their last reachable values", Fmi2Status.warning)
            self._reachable = False
            return
        self._reachable = True
        _WRITE_JOINT_REFS(values, q, qd, qdd)


class ForwardKinematics(Adapter):
    """q, qd -> p, v, plus a validity flag and the singularity proximity of the pose."""

    EXPERIMENT = (0.0, 1.0, 1e-3)

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        kind = self.KIND
        qu, qdu, _, _ = q_units(kind)
        self.description = f"Forward kinematics of the {kind} delta"
        declare_robot(self, kind)
        self.inputs3(Q, qu, "joint position", home_joints(kind))
        self.inputs3(QD, qdu, "joint velocity")
        self.outputs3(P, "m", "platform position", depends=Q)
        self.outputs3(V, "m/s", "platform velocity", depends=Q + QD)
        self.output("valid", None, "true when q assembles in the working mode (else p, v hold)", depends=Q,
                    kind="boolean")
        self.output("singularity.proximity", "1", "singularity proximity of the pose (0 = singular)", depends=Q)

    def start(self) -> None:
        self.model = build_model(robot_from(self, self.KIND))
        self.data = Data(self.model)

    def refresh(self) -> None:
        q, qd = self.vec3(Q), self.vec3(QD)
        try:  # the forward kinematics once: p, legs and J^-1 for the velocity and the proximity
            p, v = platform_state(self.model, self.data, q, qd)
            valid = working_mode_fault(self.model, q, p) is None  # the assembly IK solves for
        except UnreachableError:  # the rods cannot meet
            valid = False
        self.values["valid"] = valid
        if valid:
            self.put(P, p)
            self.put(V, v)
            self.values["singularity.proximity"] = proximity(self.data)
