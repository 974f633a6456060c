"""Inverse and forward kinematics FMUs on the per-pose path of :mod:`delta.kinematics`.

This module declares their interfaces; what they compute is their native models'
(:class:`fmus.native.models.InverseKinematics`, :class:`~fmus.native.models.ForwardKinematics`), which both builds
evaluate (:mod:`fmus.traced`).
"""

from __future__ import annotations

from delta.actuators import kind_of

from ..export2 import Adapter, axis_names, joint_names
from ..traced import TracedCS
from .common import declare_robot, home, home_joints, q_units

P_REF, V_REF, A_REF = axis_names("p_ref"), axis_names("v_ref"), axis_names("a_ref")
Q_REF, QD_REF, QDD_REF = joint_names("q_ref"), joint_names("qd_ref"), joint_names("qdd_ref")
P, V = axis_names("p"), axis_names("v")
Q, QD = joint_names("q"), joint_names("qd")


class InverseKinematics(TracedCS, Adapter):
    """p_ref, v_ref, a_ref -> q_ref, qd_ref, qdd_ref, reachability and singularity proximity.

    When the reference leaves the workspace ``reachable`` drops to false and the joint
    references hold their last reachable values (no NaN reaches the controller); the reason is
    logged as a warning when the reference leaves the workspace.
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


class ForwardKinematics(TracedCS, Adapter):
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
