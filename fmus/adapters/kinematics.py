"""Inverse and forward kinematics FMUs (delta.scalar_kinematics, delta.kinematics)."""

from __future__ import annotations

from operator import itemgetter

from pythonfmu.enums import Fmi2Status

from delta.kinematics import fk, joint_limit_reason, platform_velocity
from delta.scalar_kinematics import ScalarKinematics
from delta.singularity import analyse

from .._fmi import Adapter, axis_names, joint_names, writer
from .common import declare_robot, q_units, robot_from

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
        home = (0.0, 0.0, -0.5) if kind == "linear" else (0.0, 0.0, -0.4108)
        self.inputs3(P_REF, "m", "desired platform position", home)
        self.inputs3(V_REF, "m/s", "desired platform velocity")
        self.inputs3(A_REF, "m/s2", "desired platform acceleration")
        # Each leg's IK needs the whole platform position; rates add v_ref, accelerations a_ref.
        # On vertical rails (linear delta) a vertical shift or velocity moves every carriage alike
        # and leaves the legs' geometry and relative velocities unchanged: the Jacobian, qd_ref
        # (no p_ref.z), qdd_ref (no p_ref.z, v_ref.z) and the proximity do not depend on them.
        shape = P_REF[:2] if kind == "linear" else P_REF
        shape_rate = V_REF[:2] if kind == "linear" else V_REF
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
        proximity = self.values[PROXIMITY] = self.kin.proximity(q, p)
        return proximity

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
        self.robot = robot_from(self, self.KIND)
        self.kin = ScalarKinematics(self.robot)
        self._reachable = True
        self._pending_pose = None

    def _unreachable_reason(self, p, q, leg: int) -> tuple[str | None, float | None]:
        """Why ``p_ref`` is not reachable (None if it is) and its singularity proximity (0 when unknown,
        None when not needed yet: see the class docstring), with the checks and messages of
        :func:`delta.workspace.check_point`."""
        if leg:
            return f"leg {leg} has no solution", 0.0
        limit = self.kin.limit_violation(q)
        if limit:
            return joint_limit_reason(self.robot, limit, q[limit - 1]), 0.0
        margin = self.values["singularity.margin"]
        if margin <= 0.0:
            return None, None
        proximity = self.kin.proximity(q, p)
        if proximity < margin:
            return f"too close to a singularity: proximity {proximity:.3g} < margin {margin:g}", proximity
        return None, proximity

    def refresh(self) -> None:
        x = _read_refs(self.values)
        p = x[0:3]
        q, leg = self.kin.ik(p)
        reason, proximity = self._unreachable_reason(p, q, leg)
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
        qd, qdd = self.kin.joint_rates(q, p, x[3:6], x[6:9])
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
        self.inputs3(Q, qu, "joint position", (0.0,) * 3 if kind == "rotary" else (0.35, 0.35, 0.35))
        self.inputs3(QD, qdu, "joint velocity")
        self.outputs3(P, "m", "platform position", depends=Q)
        self.outputs3(V, "m/s", "platform velocity", depends=Q + QD)
        self.output("valid", None, "true when q assembles in the working mode (else p, v hold)", depends=Q,
                    kind="boolean")
        self.output("singularity.proximity", "1", "singularity proximity of the pose (0 = singular)", depends=Q)

    def start(self) -> None:
        self.robot = robot_from(self, self.KIND)

    def refresh(self) -> None:
        q, qd = self.vec(Q), self.vec(QD)
        res = fk(self.robot, q)
        self.values["valid"] = res.ok
        if res.ok:
            self.put(P, res.p)
            self.put(V, platform_velocity(self.robot, q, res.p, qd))
            self.values["singularity.proximity"] = analyse(self.robot, q, res.p).proximity
