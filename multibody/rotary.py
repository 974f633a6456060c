"""Exudyn plant of the rotary (Clavel) delta (seed 004 prototype and any :class:`delta.robots.RotaryDelta`).

Motor i sits at ``base_radius e_i`` (leg 1 on +x), its axis ``a_i = z x e_i`` tangent to the
base circle; a positive rotation about ``a_i`` turns the arm down, so ``q[i]`` (0 = arm
horizontal, positive = down) is the rotation angle about ``a_i``.

Full fidelity
    Each upper arm is a rigid body (uniform arm of ``masses.arm`` kg over ``arm_length``,
    plus ``masses.elbow`` kg at the elbow, plus the rotor inertia ``masses.motor_inertia``
    about ``a_i``) on a revolute joint (``ObjectJointGeneric``, rotation about ``a_i`` free);
    each forearm a parallelogram of two rigid rods (solid cylinders ``masses.rod`` kg,
    radius ``masses.rod_radius``, ``masses.parallelogram_width`` apart along ``a_i``) with
    spherical joints at both ends; a rigid free-floating platform (disc, 10 mm thick).
Lumped fidelity
    The analytic (Codourey) model: the arm body carries ``elbow + 2 (1 - w) rod`` at the elbow,
    the platform is a point mass ``platform + payload + 6 w rod``, each forearm one distance
    constraint; inertial lumps use ``masses.w_inertia``, weights ``masses.w_gravity``.

Actuator effort ``u[i]``: motor torque about ``a_i`` (turning arm i down), N*m.
"""

from __future__ import annotations

import math

import numpy as np

from delta.dynamics import RotaryDeltaMasses
from delta.kinematics import actuator_points, actuator_tangents, joint_state_from_platform, leg_axes, platform_offsets
from delta.robots import RotaryDelta

from .linear import PLATFORM_THICKNESS
from .plant import DeltaPlant, JointTrajectory, RobotTypeError, SolverSettings, point_inertia, rod_inertia, tilt_angle

__all__ = ["RotaryDeltaPlant", "ARM_RADIUS"]

ARM_RADIUS = 0.01
"""m. Gives the arm an axial inertia so its mass matrix is regular; the revolute joint locks
that rotation, so it never enters the dynamics."""


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
            DistanceConstraint,
            LoadTorqueVector,
            MarkerBodyPosition,
            MarkerBodyRigid,
            ObjectGround,
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
        w_i, w_g = m.w_inertia, m.w_gravity
        self._ground = mbs.AddObject(ObjectGround())

        platform_mass = m.platform + m.payload + (0.0 if full else 6.0 * w_i * m.rod)
        platform_weight = m.platform + m.payload + (0.0 if full else 6.0 * w_g * m.rod)
        if full:
            r = robot.platform_radius
            j_plat = np.diag([platform_mass * (3 * r**2 + PLATFORM_THICKNESS**2) / 12.0] * 2
                             + [platform_mass * r**2 / 2.0])
            self._platform = self._add_body(platform_mass, j_plat, p0, v0)
        else:
            self._platform = self._add_body(platform_mass, None, p0, v0)
        self._add_weight(self._platform, (0.0, 0.0, 0.0), platform_weight)

        elbow_mass = m.elbow if full else m.elbow + 2.0 * (1.0 - w_i) * m.rod
        elbow_weight = m.elbow if full else m.elbow + 2.0 * (1.0 - w_g) * m.rod
        self._arms, self._drives = [], []
        self._com_from_motor, self._elbow_local = np.zeros((3, 3)), np.zeros((3, 3))  # per arm, base axes, m
        self._effort_values = []  # symbolic vector variables returned by the motor loads
        self._e = e
        self._origins = robot.base_radius * e
        for i in range(3):
            a = self._axes[i]
            origin = self._origins[i]
            d = (elbows[i] - origin) / la  # arm direction
            total = m.arm + elbow_mass
            com = origin + (m.arm * la / 2.0 + elbow_mass * la) / total * d
            inertia = (rod_inertia(m.arm, ARM_RADIUS, la, d) + point_inertia(m.arm, origin + 0.5 * la * d - com)
                       + point_inertia(elbow_mass, elbows[i] - com) + m.motor_inertia * np.outer(a, a))
            omega = qd0[i] * a
            arm = self._add_body(total, inertia, com, np.cross(omega, com - origin), omega)
            self._arms.append(arm)
            self._com_from_motor[i], self._elbow_local[i] = com - origin, elbows[i] - com
            self._add_weight(arm, origin + 0.5 * la * d - com, m.arm)
            self._add_weight(arm, elbows[i] - com, elbow_weight)
            elbow_marker = mbs.AddMarker(MarkerBodyPosition(bodyNumber=arm, localPosition=list(elbows[i] - com)))
            axes_frame = np.column_stack([e[i], -z, a])  # joint z = motor axis
            if self.prescribed is None:
                joint = mbs.CreateGenericJoint(itemNumbers=[self._ground, arm], position=list(origin),
                                               rotationMatrixAxes=axes_frame, constrainedAxes=[1, 1, 1, 1, 1, 0],
                                               useGlobalFrame=True, show=False)
                rigid = mbs.AddMarker(MarkerBodyRigid(bodyNumber=arm, localPosition=[0.0, 0.0, 0.0]))
                load = mbs.AddLoad(LoadTorqueVector(markerNumber=rigid, loadVector=[0.0] * 3))
                self._effort_values.append(self._symbolic_load(load, "loadVectorUserFunction", [0.0] * 3))
            else:
                joint = mbs.CreateGenericJoint(itemNumbers=[self._ground, arm], position=list(origin),
                                               rotationMatrixAxes=axes_frame, constrainedAxes=[1] * 6,
                                               useGlobalFrame=True, show=False,
                                               offsetUserFunction=self._offset(i), offsetUserFunction_t=self._offset_t(i))
            self._drives.append(joint)
            vel_e = d_elbow[i] * qd0[i]
            if full:
                for side in (-0.5, 0.5):
                    pa = elbows[i] + side * m.parallelogram_width * a
                    self._add_rod(arm, pa, p0 + b[i] + side * m.parallelogram_width * a,
                                  vel_e + np.cross(omega, pa - elbows[i]), v0)
            else:
                pm = mbs.AddMarker(MarkerBodyPosition(bodyNumber=self._platform, localPosition=list(b[i])))
                mbs.AddObject(DistanceConstraint(markerNumbers=[elbow_marker, pm], distance=length))

    def _offset(self, i: int):
        def offset(mbs, t, item, params):
            return [0.0, 0.0, 0.0, 0.0, 0.0, float(self.prescribed(t)[0][i] - self._q0[i])]
        return offset

    def _offset_t(self, i: int):
        def offset_t(mbs, t, item, params):
            return [0.0, 0.0, 0.0, 0.0, 0.0, float(self.prescribed(t)[1][i])]
        return offset_t

    def _apply_effort(self, u: list[float]) -> None:
        for value, ui, (a0, a1, a2) in zip(self._effort_values, u, self._axes_list):
            value.SetVector([ui * a0, ui * a1, ui * a2])

    def _after_assemble(self) -> None:
        system_data = self.mbs.systemData
        first = [int(system_data.GetNodeLTGODE2(self.mbs.GetObject(arm)["nodeNumber"])[0]) for arm in self._arms]
        self._arm_index = np.array(first)[:, None] + np.arange(7)  # (3, 7): each arm node's position, Euler parameters
        self._axes_list = self._axes.tolist()
        self._arm_geometry = list(zip(self._com_from_motor.tolist(), self._elbow_local.tolist(), self._e.tolist(),
                                      self._axes_list))

    def _read_joints(self, coords: np.ndarray, coords_t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        # From the arm nodes' coordinates (displacements from the reset pose, whose rotation is the identity), as
        # Exudyn's own outputs compute them: the elbow at com + R r (R = I + 2 e0 [e]x + 2 [e]x^2 from the Euler
        # parameters (e0, e)) gives the arm angle in the plane of leg i, and the angular velocity
        # w = 2 (e0 de - de0 e + e x de) (base frame) the speed about a_i. Scalar arithmetic: numpy's overhead
        # on 3-vectors (np.cross ~20 us a call) would cost more than Exudyn's six output calls it replaces.
        q, qd = [], []
        for x, x_t, ((cx, cy, cz), (rx, ry, rz), (ex, ey, ez), (ax, ay, az)) in zip(
                coords[self._arm_index].tolist(), coords_t[self._arm_index].tolist(), self._arm_geometry):
            dx, dy, dz, e0, e1, e2, e3 = x
            e0 += 1.0  # reference Euler parameters (1, 0, 0, 0)
            d0, d1, d2, d3 = x_t[3:]
            sx, sy, sz = e2 * rz - e3 * ry, e3 * rx - e1 * rz, e1 * ry - e2 * rx  # e x r
            px = cx + dx + rx + 2.0 * (e0 * sx + e2 * sz - e3 * sy)  # elbow - motor = com + R r - origin
            py = cy + dy + ry + 2.0 * (e0 * sy + e3 * sx - e1 * sz)
            pz = cz + dz + rz + 2.0 * (e0 * sz + e1 * sy - e2 * sx)
            q.append(math.atan2(-pz, px * ex + py * ey + pz * ez))
            wx = e0 * d1 - d0 * e1 + e2 * d3 - e3 * d2  # w / 2
            wy = e0 * d2 - d0 * e2 + e3 * d1 - e1 * d3
            wz = e0 * d3 - d0 * e3 + e1 * d2 - e2 * d1
            qd.append(2.0 * (wx * ax + wy * ay + wz * az))
        return np.array(q), np.array(qd)

    def _read_prescribed_reaction(self) -> np.ndarray:
        import exudyn as exu

        tz = [self.mbs.GetObjectOutput(j, exu.OutputVariableType.TorqueLocal)[2] for j in self._drives]
        return _DRIVE_SIGN * np.array(tz, dtype=float)

    def platform_tilt(self) -> float:
        import exudyn as exu

        if self.fidelity != "full":
            return 0.0
        rot = self.mbs.GetObjectOutputBody(self._platform, exu.OutputVariableType.RotationMatrix, [0.0, 0.0, 0.0])
        return tilt_angle(rot)


_DRIVE_SIGN = 1.0
