"""Exudyn plant of the rotary (Clavel) delta (seed 004 prototype and any :class:`delta.robots.RotaryDelta`).

Motor i sits at ``base_radius e_i`` (leg 1 on +x), its axis ``a_i = z x e_i`` tangent to the
base circle; a positive rotation about ``a_i`` turns the arm down, so ``q[i]`` (0 = arm
horizontal, positive = down) is the rotation angle about ``a_i``.

Full fidelity
    Each upper arm is a rigid body (uniform arm of ``masses.arm`` kg over ``arm_length``,
    plus ``masses.elbow`` kg at the elbow, plus the rotor inertia ``masses.motor_inertia``
    about ``a_i``) on an ideal revolute joint about ``a_i``;
    each forearm a parallelogram of two rigid rods (solid cylinders ``masses.rod`` kg,
    radius ``masses.rod_radius``, ``masses.parallelogram_width`` apart along ``a_i``) with
    spherical joints at both ends, each rod represented by its two end nodes
    (:meth:`multibody.builder.SystemBuilder._add_rod`); a rigid free-floating platform (disc, 10 mm thick).
Lumped fidelity
    The analytic (Codourey) model: the arm body carries ``elbow + 2 (1 - w) rod`` at the elbow,
    the platform is a point mass ``platform + payload + 6 w rod``, each forearm one distance
    constraint; inertial lumps use ``masses.w_inertia``, weights ``masses.w_gravity``
    (:func:`delta.masses.lumps`).

Arms: an ideal revolute joint locks every arm motion but the rotation about ``a_i``, so an arm is modelled
exactly as a 1-DOF rotational body (``ObjectRotationalMass1D``, its moment of inertia about the motor axis)
whose coordinate is ``q[i] - q0[i]``, as the linear plant's carriages are 1-DOF masses. A free rigid body on
a generic joint (7 coordinates, 7 algebraic equations) per arm gave the same motion with 39 more unknowns in every
Newton matrix: 134 instead of 95 (full), 48 instead of 9 (lumped), and 1.5x the time per step.

Actuator effort ``u[i]``: motor torque about ``a_i`` (turning arm i down), N*m.
"""

from __future__ import annotations

import numpy as np

from delta.dynamics import RotaryDeltaMasses
from delta.kinematics import actuator_points, actuator_tangents, joint_state_from_platform, leg_axes, platform_offsets
from delta.masses import lumps
from delta.robots import RotaryDelta

from .errors import RobotTypeError
from .inertia import point_inertia, rod_inertia
from .plant import DeltaPlant, JointTrajectory
from .settings import SolverSettings

__all__ = ["RotaryDeltaPlant", "ARM_RADIUS"]

ARM_RADIUS = 0.01
"""m. Radius of the uniform arm (a solid cylinder) in its inertia; only its moment about the motor axis
enters the dynamics."""


class RotaryDeltaPlant(DeltaPlant):
    """Exudyn plant of a rotary delta; parameters as :class:`multibody.linear.LinearDeltaPlant`.

    Default start: ``p0 = (0, 0, robot.home_z)`` (all arms horizontal), at rest.
    """

    kind = "rotary"

    def __init__(self, robot: RotaryDelta, masses: RotaryDeltaMasses | None = None, fidelity: str = "full",
                 settings: SolverSettings | None = None, p0=None, v0=(0.0, 0.0, 0.0), t0: float = 0.0,
                 prescribed: JointTrajectory | None = None, h_nominal: float = 1e-3) -> None:
        if not isinstance(robot, RotaryDelta):
            raise RobotTypeError(f"RotaryDeltaPlant needs a RotaryDelta robot, got {type(robot).__name__}")
        if p0 is None:
            p0 = (0.0, 0.0, robot.home_z)
        super().__init__(robot, masses or RotaryDeltaMasses(), fidelity, settings, prescribed, p0, v0, t0, h_nominal)

    def _build(self, p0: np.ndarray, v0: np.ndarray, t0: float) -> None:
        from exudyn.itemInterface import (
            CoordinateConstraint,
            DistanceConstraint,
            LoadCoordinate,
            MarkerBodyPosition,
            MarkerNodeCoordinate,
            Node1D,
            NodePointGround,
            ObjectGround,
            ObjectRotationalMass1D,
        )

        robot, m, mbs = self.robot, self.masses, self.mbs
        full = self.fidelity == "full"
        q0, qd0, _ = joint_state_from_platform(robot, p0, v0)
        self._q0 = q0
        e = leg_axes(robot)
        z = np.array([0.0, 0.0, 1.0])
        self._axes = np.cross(z[None, :], e)  # a_i = z x e_i
        b = platform_offsets(robot)
        elbows = actuator_points(robot, q0)
        d_elbow = actuator_tangents(robot, q0)
        la, length = robot.arm_length, robot.forearm_length
        lumped = lumps(m, self.kind)  # the rods' shares (lumped fidelity; in the full one the rods are bodies)
        self._ground = mbs.AddObject(ObjectGround())

        self._add_platform(p0, v0)

        elbow_mass = lumped.actuator_alone if full else lumped.actuator_inertial
        elbow_weight = lumped.actuator_alone if full else lumped.actuator_weight_mass
        self._arms = []
        ground_node = mbs.AddNode(NodePointGround(referenceCoordinates=[0.0, 0.0, 0.0]))
        ground_coord = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=ground_node, coordinate=0))
        for i in range(3):
            a = self._axes[i]
            origin = robot.base_radius * e[i]
            d = (elbows[i] - origin) / la  # arm direction
            total = m.arm + elbow_mass
            com = origin + (m.arm * la / 2.0 + elbow_mass * la) / total * d
            inertia = (rod_inertia(m.arm, ARM_RADIUS, la, d) + point_inertia(m.arm, origin + 0.5 * la * d - com)
                       + point_inertia(elbow_mass, elbows[i] - com) + m.motor_inertia * np.outer(a, a))
            # moment of inertia about the motor axis (through the motor): the arm's only motion
            axial = float(a @ (inertia + point_inertia(total, com - origin)) @ a)
            # the arm turns about a_i through the motor: a 1-DOF rotational body whose coordinate is q[i] - q0[i],
            # local axes (e_i, -z, a_i) at the reset pose (positive rotation about local z = a_i turns the arm down)
            frame = np.column_stack([e[i], -z, a])
            node = mbs.AddNode(Node1D(referenceCoordinates=[0.0], initialCoordinates=[0.0],
                                      initialVelocities=[float(qd0[i])]))
            arm = mbs.AddObject(ObjectRotationalMass1D(inertia=axial, nodeNumber=node,
                                                       referencePosition=[float(x) for x in origin],
                                                       referenceRotation=frame.tolist()))
            self._arms.append(arm)
            self._joint_nodes.append(node)
            self._bodies.append((arm, 0.0, np.diag([0.0, 0.0, axial])))  # energy: w (local) = (0, 0, qd[i])

            def local(point, frame=frame, origin=origin):
                return frame.T @ (np.asarray(point, dtype=float) - origin)

            self._add_weight(arm, local(origin + 0.5 * la * d), m.arm)
            self._add_weight(arm, local(elbows[i]), elbow_weight)
            coord = mbs.AddMarker(MarkerNodeCoordinate(nodeNumber=node, coordinate=0))
            if self.prescribed is None:
                load = mbs.AddLoad(LoadCoordinate(markerNumber=coord, load=0.0))
                self._effort_values.append(self._symbolic_load(load, "loadUserFunction", 0.0))
            else:
                self._drives.append(mbs.AddObject(CoordinateConstraint(
                    markerNumbers=[ground_coord, coord], offsetUserFunction=self._offset(i),
                    offsetUserFunction_t=self._offset_t(i))))
            omega = qd0[i] * a
            vel_e = d_elbow[i] * qd0[i]
            if full:
                for side in (-0.5, 0.5):
                    pa = elbows[i] + side * m.parallelogram_width * a
                    self._add_rod(arm, pa, p0 + b[i] + side * m.parallelogram_width * a,
                                  vel_e + np.cross(omega, pa - elbows[i]), v0)
            else:
                elbow_marker = mbs.AddMarker(MarkerBodyPosition(bodyNumber=arm, localPosition=list(local(elbows[i]))))
                pm = mbs.AddMarker(MarkerBodyPosition(bodyNumber=self._platform, localPosition=list(b[i])))
                mbs.AddObject(DistanceConstraint(markerNumbers=[elbow_marker, pm], distance=length))

    # prescribed-motion offsets (relative to the reset pose) ---------------------------
    def _offset(self, i: int):
        def offset(mbs, t, item, l_offset):
            return float(self.prescribed(t)[0][i] - self._q0[i])  # node coordinate = rotation from q0
        return offset

    def _offset_t(self, i: int):
        def offset_t(mbs, t, item, l_offset):
            return float(self.prescribed(t)[1][i])
        return offset_t
