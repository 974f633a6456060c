"""Actuator paths: the only code that differs between a linear and a rotary delta.

Every delta has three legs; leg ``i`` joins the actuator point ``B_i(q_i)`` (a carriage
on a vertical rail, or the elbow of an arm turned by a motor) to the platform joint
``p + b_i`` by a parallelogram of length ``L``. Everything else (kinematics, dynamics,
singularities, workspace) is written once in :mod:`delta.model`, :mod:`delta.kinematics`
and :mod:`delta.dynamics` in terms of what an actuator class gives:

* the path ``B_i(q)`` and its derivatives ``B_i'``, ``B_i''``, folded with the rod to the platform
  (:meth:`Rail.leg`), and ``B_i''`` itself (:meth:`Rail.curve`, for the rods' rotational inertia),
* the closed-form leg inverse kinematics in the leg's plane (:meth:`Rail.solve`),
* the actuator's inertia and weight from the actuator-side mass lump (:meth:`Rail.inertia`, :meth:`Rail.weight`;
  the lumping itself is :func:`delta.masses.lumps`),
* units, names and the default preset of its robot kind.

The formulas take floats or numpy arrays alike: ``xp`` is :data:`SCALAR` (the ``math``
module's functions, one pose, plain floats: the per-step path of the FMUs) or
:data:`ARRAY` (numpy, many poses at once: workspace sampling and pre-flight). One
formula, two number types.
"""

from __future__ import annotations

import math

import numpy as np

from .errors import RobotError
from .masses import LinearDeltaMasses, Lumps, RotaryDeltaMasses, lumps
from .numbers import ARRAY, SCALAR
from .robots import LinearDelta, Robot, RotaryDelta

__all__ = ["SCALAR", "ARRAY", "ROUNDING", "Rail", "Arm", "Actuator", "KINDS", "actuator_for", "kind_of"]

ROUNDING = 1e-12
"""Relative slack on the real-solution tests so that exactly singular legs stay solvable."""
_RATIO_MAX2 = (1.0 + ROUNDING) ** 2
_PI = math.pi
_TWO_PI = 2.0 * math.pi


class Rail:
    """Linear delta: a carriage on a vertical rail at planar radius ``R`` (thesis ``U_A``).

    ``q`` is the carriage travel downward from the rail top: ``B_i = (R e_i, -q_i)``,
    ``B_i' = (0, 0, -1)``, ``B_i'' = 0`` (thesis eqs. (4)-(9)).
    """

    kind = "linear"
    robot_type = LinearDelta
    masses_type = LinearDeltaMasses
    preset = "linear_delta_thesis"
    units = ("m", "m/s", "m/s2", "N")  # q, qd, qdd, effort
    joint_range = "carriage stroke"
    wrong_mode = "platform above its carriage"
    home = (0.1, 0.0, -0.45)  # m, start of the default helix
    vertical_invariant = True
    guide_style = ((0.6, 0.6, 0.6, 1.0), 0.01)  # RGBA and width of the drawn rails
    """A vertical platform shift moves every carriage alike: the legs' shape does not depend on p_z."""

    def __init__(self, robot: LinearDelta) -> None:
        self.radius = robot.rail_radius
        self.offset = robot.platform_radius - robot.rail_radius  # radial, platform joint - rail
        self.rod = robot.rod_length
        self._rod2 = robot.rod_length ** 2
        self._slack = -ROUNDING * self._rod2
        self.q_scale = robot.rod_length  # m: the size a joint error is measured against

    def leg(self, q, c, s, ox, oy, x, y, z, xp):  # noqa: ANN001, ANN201
        """Leg i at joint value ``q`` and platform position ``(x, y, z)``: the rod ``l_i = p + b_i - B_i``,
        ``B_i'`` and the products ``l_i . B_i''``, ``l_i . B_i'`` (see :func:`delta.kinematics.leg_rates`).
        ``(c, s)`` is ``e_i``, ``(ox, oy)`` is ``b_i - R e_i``. ``B_i = (R e_i, -q_i)``, ``B_i' = (0, 0, -1)``,
        ``B_i'' = 0``."""
        lz = z + q
        return x + ox, y + oy, lz, 0.0, 0.0, -1.0, 0.0, -lz

    def curve(self, q, c, s, xp):  # noqa: ANN001, ANN201
        """``B_i''``: a rail is straight."""
        return 0.0, 0.0, 0.0

    def solve(self, x, y, z, c, s, ox, oy, xp):  # noqa: ANN001, ANN201
        """Leg IK for the platform position ``(x, y, z)``, leg direction ``e_i = (c, s)``: thesis eq. (9),
        ``q_i = -(z + sqrt(L^2 - lx^2 - ly^2))`` with ``(lx, ly) = (x, y) + (ox, oy)`` the horizontal part of
        ``p + b_i - R e_i`` (the platform below the carriage). Returns ``(q, solvable)``; a rod exactly
        horizontal is a (singular) solution."""
        lx, ly = x + ox, y + oy
        h2 = self._rod2 - lx * lx - ly * ly
        return -(z + xp.sqrt(h2 * (h2 > 0.0))), h2 >= self._slack  # h2 < 0 by rounding: sqrt(0)

    def inertia(self, masses: LinearDeltaMasses, lumped: Lumps | None = None) -> float:
        """``D``, kg: the carriage lump moving with ``q`` (``actuator_inertial`` of ``lumped``, by default
        :func:`delta.masses.lumps` of ``masses``)."""
        return (lumps(masses, self.kind) if lumped is None else lumped).actuator_inertial

    def weight(self, masses: LinearDeltaMasses, lumped: Lumps | None = None) -> float:
        """Weight of the carriage lump, N; ``q`` points down, so ``dV_i/dq_i = -weight``."""
        return (lumps(masses, self.kind) if lumped is None else lumped).actuator_weight_mass * masses.gravity

    def gravity(self, q, weight: float, xp):  # noqa: ANN001, ANN201
        """``dV_i/dq_i`` of the actuator-side lump (the same at every ``q``)."""
        return -weight

    def potential(self, q, weight: float, xp):  # noqa: ANN001, ANN201
        """``V_i(q_i)``, zero at ``q = 0`` (the carriage height is ``-q``)."""
        return -weight * q

    Q_PRINTF = ("%.4f m", 1.0)
    """A joint value as people read it: (printf format, factor from SI); the native FMUs print it so in C."""

    @classmethod
    def format_q(cls, value: float) -> str:
        fmt, factor = cls.Q_PRINTF
        return fmt % (value * factor)

    @staticmethod
    def shown(q) -> tuple[list[float], str]:  # noqa: ANN001
        """Joint values as people read them: carriage travels in m."""
        return [float(x) for x in q], "m"

    @staticmethod
    def workspace_centre(robot: LinearDelta) -> tuple[float, float, float]:
        """A point on the axis in the middle of the reachable heights (default cylinder centre), m."""
        return 0.0, 0.0, -0.5 * (robot.q_min + robot.q_max) - 0.8 * robot.rod_length

    @staticmethod
    def guides(robot: LinearDelta, anchors: np.ndarray, joints: np.ndarray) -> list[np.ndarray]:
        """Fixed segments to draw: each rail from its top stroke limit to its bottom one (pairs of points)."""
        top, bottom = anchors.copy(), anchors.copy()
        top[:, 2], bottom[:, 2] = -robot.q_min, -robot.q_max
        return [x for pair in zip(top, bottom) for x in pair]

    @staticmethod
    def leg_angles(q: np.ndarray, rods: np.ndarray, e: np.ndarray) -> tuple[None, None]:
        """Seed 003's leg angles apply to arms only."""
        return None, None

    def bounds(self, robot: LinearDelta) -> tuple[np.ndarray, np.ndarray]:
        """An axis-aligned box that contains the whole workspace, m."""
        reach = robot.rail_radius - robot.platform_radius + robot.rod_length
        return np.array([-reach, -reach, -robot.q_max - robot.rod_length]), np.array([reach, reach, -robot.q_min])


class Arm:
    """Rotary delta: an arm of length ``La`` turned by a motor whose axis is tangent to the base
    circle of radius ``R``; ``q`` is the arm angle, 0 = horizontal outward, positive = down.

    ``B_i = R e_i + La (cos q_i e_i - sin q_i z)`` (seed 003 eq. (2), seed 004 eq. (35) with
    our sign convention).
    """

    kind = "rotary"
    robot_type = RotaryDelta
    masses_type = RotaryDeltaMasses
    preset = "rotary_delta_prototype"
    units = ("rad", "rad/s", "rad/s2", "N.m")
    joint_range = "arm range"
    wrong_mode = "elbow in"
    home = (0.0, 0.0, -0.4108)  # m, arms near horizontal on the prototype
    vertical_invariant = False
    guide_style = ((0.2, 0.4, 0.9, 1.0), 0.015)  # RGBA and width of the drawn arms

    def __init__(self, robot: RotaryDelta) -> None:
        self.radius = robot.base_radius
        self.offset = robot.platform_radius - robot.base_radius  # radial, platform joint - motor axis
        self.arm = robot.arm_length
        self.rod = robot.forearm_length
        self.q_scale = 1.0  # rad
        self._k0 = robot.arm_length ** 2 - robot.forearm_length ** 2
        self._half_inv_arm = 0.5 / robot.arm_length

    def leg(self, q, c, s, ox, oy, x, y, z, xp):  # noqa: ANN001, ANN201
        """As :meth:`Rail.leg`, with ``B_i = R e_i + La (cos q_i e_i - sin q_i z)``,
        ``B_i' = -La (sin q_i e_i + cos q_i z)`` and ``B_i'' = -La (cos q_i e_i - sin q_i z)``."""
        la = self.arm
        lc, ls = la * xp.cos(q), la * xp.sin(q)
        lx, ly, lz = x + ox - lc * c, y + oy - lc * s, z + ls
        radial = lx * c + ly * s
        return lx, ly, lz, -ls * c, -ls * s, -lc, ls * lz - lc * radial, -ls * radial - lc * lz

    def curve(self, q, c, s, xp):  # noqa: ANN001, ANN201
        """``B_i'' = -La (cos q_i e_i - sin q_i z)``: the elbow's centripetal direction."""
        lc = self.arm * xp.cos(q)
        return -lc * c, -lc * s, self.arm * xp.sin(q)

    def solve(self, x, y, z, c, s, ox, oy, xp):  # noqa: ANN001, ANN201
        """Leg IK in the leg plane, with ``dx``, ``dy`` the radial and tangential parts of
        ``p + b_i - R e_i``: ``dx cos q - z sin q = K``, ``K = (dx^2 + dy^2 + z^2 + La^2 - L^2) / (2 La)``
        from ``|l_i| = L`` (seed 003 eq. (8) is garbled in the text, so it is re-derived here); the
        elbow-out branch, wrapped to [-pi, pi). A stretched or folded leg is a (singular) solution."""
        dx, dy = x * c + y * s + self.offset, y * c - x * s
        rho2 = dx * dx + z * z
        k = (rho2 + dy * dy + self._k0) * self._half_inv_arm
        rho = xp.sqrt(rho2)
        ratio = k / (rho + (rho == 0.0))
        clipped = ratio - (ratio > 1.0) * (ratio - 1.0) - (ratio < -1.0) * (ratio + 1.0)  # to [-1, 1]
        q = -xp.atan2(z, dx) - xp.acos(clipped)
        return q + _TWO_PI * (q < -_PI), xp.both(rho > 0.0, ratio * ratio <= _RATIO_MAX2)  # to [-pi, pi)

    def inertia(self, masses: RotaryDeltaMasses, lumped: Lumps | None = None) -> float:
        """``I = motor_inertia + arm La^2/3 + m_e La^2`` about the motor axis, kg m^2, with ``m_e`` the elbow's lump
        (``actuator_inertial`` of ``lumped``, by default :func:`delta.masses.lumps` of ``masses``)."""
        la, elbow = self.arm, (lumps(masses, self.kind) if lumped is None else lumped).actuator_inertial
        return masses.motor_inertia + masses.arm * la * la / 3.0 + elbow * la * la

    def weight(self, masses: RotaryDeltaMasses, lumped: Lumps | None = None) -> float:
        """Gravity moment of the arm (centre of mass at ``La/2``) and the elbow's lump at ``La``, N m."""
        la, elbow = self.arm, (lumps(masses, self.kind) if lumped is None else lumped).actuator_weight_mass
        return (masses.arm * la / 2.0 + elbow * la) * masses.gravity

    def gravity(self, q, weight: float, xp):  # noqa: ANN001, ANN201
        return -weight * xp.cos(q)

    def potential(self, q, weight: float, xp):  # noqa: ANN001, ANN201
        return -weight * xp.sin(q)  # the lumps sit r sin q below the motor axis

    Q_PRINTF = ("%.2f deg", 180.0 / math.pi)  # the factor of math.degrees: the same double
    """A joint value as people read it: (printf format, factor from SI); the native FMUs print it so in C."""

    @classmethod
    def format_q(cls, value: float) -> str:
        fmt, factor = cls.Q_PRINTF
        return fmt % (value * factor)

    @staticmethod
    def shown(q) -> tuple[list[float], str]:  # noqa: ANN001
        """Joint values as people read them: arm angles in degrees."""
        return [math.degrees(float(x)) for x in q], "deg"

    @staticmethod
    def workspace_centre(robot: RotaryDelta) -> tuple[float, float, float]:
        """The platform position with all arms horizontal (default cylinder centre), m."""
        return 0.0, 0.0, robot.home_z

    @staticmethod
    def guides(robot: RotaryDelta, anchors: np.ndarray, joints: np.ndarray) -> list[np.ndarray]:
        """Segments to draw: each upper arm from its motor axis to its elbow (pairs of points)."""
        return [x for pair in zip(anchors, joints) for x in pair]

    @staticmethod
    def leg_angles(q: np.ndarray, rods: np.ndarray, e: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Seed 003's ``theta_2i`` (arm to forearm projection in the leg plane) and ``theta_3i`` (forearm
        to motor axis), rad, for joint values ``q`` (3,), rods (3, 3) and leg axes ``e`` (3, 3)."""
        t = np.stack([-e[:, 1], e[:, 0], np.zeros(3)], axis=1)
        unit = rods / np.linalg.norm(rods, axis=1, keepdims=True)
        theta3 = np.arccos(np.clip(np.einsum("ij,ij->i", unit, t), -1.0, 1.0))
        radial = np.einsum("ij,ij->i", unit, e)
        vertical = unit[:, 2]
        # the arm direction in the leg plane is (cos q, -sin q) in (radial, vertical) coordinates
        cross = np.cos(q) * vertical + np.sin(q) * radial
        dot = np.cos(q) * radial - np.sin(q) * vertical
        return np.arctan2(cross, dot), theta3

    def bounds(self, robot: RotaryDelta) -> tuple[np.ndarray, np.ndarray]:
        reach = robot.base_radius + robot.arm_length + robot.forearm_length - robot.platform_radius
        height = robot.arm_length + robot.forearm_length
        return np.array([-reach, -reach, -height]), np.array([reach, reach, height])


Actuator = Rail | Arm

KINDS: dict[str, type[Rail] | type[Arm]] = {cls.kind: cls for cls in (Rail, Arm)}
"""Robot kind -> its actuator path (with the kind's robot and mass types, units and default preset)."""


def kind_of(kind: str) -> type[Rail] | type[Arm]:
    """The actuator class of a robot kind; the error lists the valid kinds."""
    try:
        return KINDS[kind]
    except KeyError:
        raise RobotError(f"unknown robot kind {kind!r}; valid kinds: {', '.join(KINDS)}") from None


def actuator_for(robot: Robot) -> Actuator:
    """The actuator path of ``robot`` (by its ``kind``)."""
    return kind_of(robot.kind)(robot)
