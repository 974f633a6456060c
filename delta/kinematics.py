"""Position, velocity and acceleration kinematics of linear and rotary deltas.

Both robots share one formulation. Leg ``i`` joins the actuator point
``B_i(q_i)`` (carriage joint or elbow) to the platform joint ``p + b_i`` by a
parallelogram of length ``L``; its rod vector ``l_i = p + b_i - B_i(q_i)``
satisfies ``l_i . l_i = L**2``. Differentiating once and twice gives the
Jacobian and the Hessians for any actuator path ``B_i(q)``:

* linear delta: ``B_i = (R e_i, -q_i)``, ``B_i' = u = (0, 0, -1)`` (thesis eqs. 4-23),
* rotary delta: ``B_i = R e_i + La (cos q_i e_i - sin q_i z)`` (seed 003 eq. 2,
  seed 004 eq. 35 with our sign convention: positive ``q`` = arm down).

Shapes: ``p``, ``v``, ``a`` are (3,) platform position / velocity /
acceleration in the base frame, m, m/s, m/s**2; ``q``, ``qd``, ``qdd`` are (3,)
joint values (m or rad). Functions whose name ends in ``_batch`` take (N, 3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .errors import RobotError, UnreachableError
from .robots import LinearDelta, Robot, RotaryDelta

_ROUNDING = 1e-12
"""Relative slack on the real-solution tests so that exactly singular legs stay solvable."""

__all__ = [
    "IKResult",
    "FKResult",
    "leg_axes",
    "actuator_points",
    "actuator_points_batch",
    "actuator_tangents",
    "actuator_tangents_batch",
    "platform_offsets",
    "ik",
    "ik_batch",
    "joint_limit_reason",
    "fk",
    "rod_vectors",
    "jacobian",
    "hessians",
    "jacobian_and_hessians",
    "joint_rates",
    "joint_velocity",
    "platform_velocity",
    "joint_acceleration",
    "platform_acceleration",
    "joint_state_from_platform",
    "platform_state_from_joints",
]

@dataclass(frozen=True)
class IKResult:
    """Result of inverse kinematics.

    ``q`` holds the joint values whenever every leg has a real solution, even if a
    joint limit is violated (``within_limits`` tells); otherwise ``q`` is None and
    ``reason`` says which leg failed.
    """

    q: np.ndarray | None
    solvable: bool
    within_limits: bool
    reason: str | None = None
    leg: int | None = None

    @property
    def ok(self) -> bool:
        return self.solvable and self.within_limits

    def require(self) -> np.ndarray:
        """Return ``q`` or raise :class:`UnreachableError` with the reason."""
        if not self.ok:
            raise UnreachableError(self.reason or "unreachable")
        assert self.q is not None
        return self.q


@dataclass(frozen=True)
class FKResult:
    """Result of forward kinematics: platform position ``p`` or the reason there is none."""

    p: np.ndarray | None
    reason: str | None = None

    @property
    def ok(self) -> bool:
        return self.p is not None

    def require(self) -> np.ndarray:
        if self.p is None:
            raise UnreachableError(self.reason or "no forward-kinematics solution")
        return self.p


def leg_axes(robot: Robot) -> np.ndarray:
    """Unit radial vectors ``e_i`` of the three legs, shape (3, 3) (row i = leg i)."""
    angles = np.asarray(robot.leg_angles, dtype=float)
    return np.stack([np.cos(angles), np.sin(angles), np.zeros(3)], axis=1)


def platform_offsets(robot: Robot) -> np.ndarray:
    """Platform joint offsets ``b_i = r e_i`` in the base frame, (3, 3), m."""
    return robot.platform_radius * leg_axes(robot)


def actuator_points_batch(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Actuator-side joint positions ``B_i(q_i)`` for (N, 3) ``q``, shape (N, 3, 3), m."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    e = leg_axes(robot)[None]
    if isinstance(robot, LinearDelta):
        out = np.repeat(robot.rail_radius * e, len(q), axis=0)
        out[:, :, 2] = -q
        return out
    la = robot.arm_length
    out = (robot.base_radius + la * np.cos(q))[:, :, None] * e
    out[:, :, 2] = -la * np.sin(q)
    return out


def actuator_tangents_batch(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives ``B_i'(q_i)``, ``B_i''(q_i)`` for (N, 3) ``q``, each (N, 3, 3)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    if isinstance(robot, LinearDelta):
        d1 = np.zeros((len(q), 3, 3))
        d1[:, :, 2] = -1.0
        return d1, np.zeros_like(d1)
    e = leg_axes(robot)[None]
    la = robot.arm_length
    d1 = (-la * np.sin(q))[:, :, None] * e
    d1[:, :, 2] = -la * np.cos(q)
    d2 = (-la * np.cos(q))[:, :, None] * e
    d2[:, :, 2] = la * np.sin(q)
    return d1, d2


def actuator_points(robot: Robot, q: np.ndarray) -> np.ndarray:
    """Actuator-side joint positions ``B_i(q_i)`` (carriage joint or elbow), (3, 3), m."""
    return actuator_points_batch(robot, np.asarray(q, dtype=float).reshape(1, 3))[0]


def actuator_tangents(robot: Robot, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and second derivatives ``B_i'(q_i)`` and ``B_i''(q_i)``, each (3, 3)."""
    d1, d2 = actuator_tangents_batch(robot, np.asarray(q, dtype=float).reshape(1, 3))
    return d1[0], d2[0]


def _rod_length(robot: Robot) -> float:
    return robot.rod_length if isinstance(robot, LinearDelta) else robot.forearm_length


def ik_batch(robot: Robot, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Vectorised inverse kinematics.

    Parameters
    ----------
    p : (N, 3) array, m

    Returns
    -------
    q : (N, 3) array
        Joint values; NaN where the leg has no real solution.
    solvable : (N, 3) bool array
    """
    p = np.atleast_2d(np.asarray(p, dtype=float))
    e = leg_axes(robot)
    big_l = _rod_length(robot)
    x_loc = p @ e.T  # radial coordinate of p in each leg's plane, (N, 3)
    y_loc = p[:, 0:1] * (-e[:, 1]) + p[:, 1:2] * e[:, 0]  # tangential coordinate
    z = p[:, 2:3]
    if isinstance(robot, LinearDelta):
        # thesis eq. (9): d_i = lambda_iz +- sqrt(l^2 - lambda_ix^2 - lambda_iy^2), with the
        # branch that keeps the platform below the carriage; q is measured downward.
        dx = x_loc + robot.platform_radius - robot.rail_radius
        h2 = big_l**2 - dx**2 - y_loc**2
        solvable = h2 >= -_ROUNDING * big_l**2  # a rod exactly horizontal is a (singular) solution
        q = -(z + np.sqrt(np.where(solvable, np.maximum(h2, 0.0), np.nan)))
        return q, solvable
    # Rotary leg in its own plane: dx cos q - z sin q = K (derived from |l|^2 = Lb^2;
    # seed 003 eq. (8) is garbled in the text, so it is re-derived here).
    la = robot.arm_length
    dx = x_loc + robot.platform_radius - robot.base_radius
    k = (dx**2 + y_loc**2 + z**2 + la**2 - big_l**2) / (2.0 * la)
    rho = np.hypot(dx, z)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = k / rho
    solvable = np.abs(c) <= 1.0 + _ROUNDING  # a stretched or folded leg is a (singular) solution
    # Elbow-out branch: the arm points away from the base centre (the delta's working mode).
    q = -np.arctan2(z, dx) - np.arccos(np.where(solvable, np.clip(c, -1.0, 1.0), np.nan))
    q = (q + np.pi) % (2.0 * np.pi) - np.pi
    return q, solvable


def _fmt_q(robot: Robot, value: float) -> str:
    if isinstance(robot, LinearDelta):
        return f"{value:.4f} m"
    return f"{np.degrees(value):.2f} deg"


def joint_limit_reason(robot: Robot, leg: int, value: float) -> str:
    """``leg 2 joint limit: q = ... < q_min = ...`` for joint ``leg`` (1-based) at ``value``."""
    if value < robot.q_min:
        return f"leg {leg} joint limit: q = {_fmt_q(robot, value)} < q_min = {_fmt_q(robot, robot.q_min)}"
    return f"leg {leg} joint limit: q = {_fmt_q(robot, value)} > q_max = {_fmt_q(robot, robot.q_max)}"


def ik(robot: Robot, p: np.ndarray) -> IKResult:
    """Inverse kinematics of one platform position ``p`` (3,), m."""
    p = np.asarray(p, dtype=float).reshape(3)
    q, solvable = ik_batch(robot, p[None, :])
    q, solvable = q[0], solvable[0]
    if not solvable.all():
        leg = int(np.argmin(solvable)) + 1
        return IKResult(None, False, False, f"leg {leg} has no solution (rod cannot reach the platform joint)", leg)
    for i in range(3):
        if q[i] < robot.q_min or q[i] > robot.q_max:
            return IKResult(q, True, False, joint_limit_reason(robot, i + 1, q[i]), i + 1)
    return IKResult(q, True, True)


def _trilaterate_low(centres: np.ndarray, radius: float) -> tuple[np.ndarray | None, str | None]:
    """Lower intersection point of three spheres of equal ``radius``, closed form."""
    c1 = centres[0]
    a = centres[1] - c1
    b = centres[2] - c1
    n = np.cross(a, b)
    nn = float(n @ n)
    scale = max(float(a @ a), float(b @ b), 1e-300)
    if nn <= 1e-24 * scale**2:
        return None, "sphere centres are collinear (degenerate configuration)"
    # Circumcentre of the triangle (c1, c2, c3) relative to c1.
    o = np.cross(float(a @ a) * b - float(b @ b) * a, n) / (2.0 * nn)
    h2 = radius**2 - float(o @ o)
    if h2 < 0.0:
        return None, "the three rods cannot meet (legs too far apart)"
    n_hat = n / np.sqrt(nn)
    if n_hat[2] > 0.0:
        n_hat = -n_hat
    return c1 + o + np.sqrt(h2) * n_hat, None


def fk(robot: Robot, q: np.ndarray) -> FKResult:
    """Closed-form forward kinematics (three-sphere intersection), lower branch.

    The platform position is the point, below the plane of the three sphere
    centres ``B_i(q_i) - b_i``, at rod length from each of them. The answer must
    belong to the working mode that :func:`ik` solves for (linear: platform below
    every carriage; rotary: elbows out); a ``q`` whose assembly needs another
    branch is reported as such instead of returning a pose IK would not give back.
    """
    q = np.asarray(q, dtype=float).reshape(3)
    centres = actuator_points(robot, q) - platform_offsets(robot)
    p, reason = _trilaterate_low(centres, _rod_length(robot))
    if p is None:
        return FKResult(None, reason)
    q_back, solvable = ik_batch(robot, p[None, :])
    mismatch = np.abs(q_back[0] - q)
    scale = _rod_length(robot) if isinstance(robot, LinearDelta) else 1.0
    if not solvable.all() or np.any(mismatch > 1e-6 * scale):
        leg = int(np.nanargmax(np.where(solvable[0], mismatch, np.inf))) + 1
        return FKResult(None, f"leg {leg} would be assembled outside the working mode "
                              f"({'platform above its carriage' if isinstance(robot, LinearDelta) else 'elbow in'})")
    return FKResult(p, None)


def rod_vectors(robot: Robot, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Rod vectors ``l_i = p + b_i - B_i(q_i)`` (row i), (3, 3), m."""
    return np.asarray(p, dtype=float)[None, :] + platform_offsets(robot) - actuator_points(robot, q)


def _jacobian_parts(robot: Robot, q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    rods = rod_vectors(robot, q, p)
    d1, d2 = actuator_tangents(robot, q)
    denom = np.einsum("ij,ij->i", rods, d1)  # l_i . B_i'
    return rods, d1, d2, denom


def _jacobian_from_parts(rods: np.ndarray, denom: np.ndarray) -> np.ndarray:
    if np.any(denom == 0.0):
        leg = int(np.argmin(np.abs(denom))) + 1
        raise RobotError(f"type 1 (serial) singularity: leg {leg} rod is orthogonal to its actuator motion")
    return rods / denom[:, None]


def jacobian(robot: Robot, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Task Jacobian ``J`` with ``qd = J v``, (3, 3).

    Row i is ``l_i^T / (l_i . B_i')`` (thesis eq. (15) for the linear delta, where
    ``B_i' = u_i``; for the rotary delta it equals ``J_theta^-1 J_p`` of seed 003 eq. (12)).
    """
    rods, _, _, denom = _jacobian_parts(robot, q, p)
    return _jacobian_from_parts(rods, denom)


def jacobian_and_hessians(robot: Robot, q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``J`` (3, 3) and the Hessians ``H_i`` (3, 3, 3) with ``qdd_i = J_i a + v^T H_i v`` (thesis eq. (22)).

    ``H_i = [(I - B_i' J_i)^T (I - B_i' J_i) - (l_i . B_i'') J_i^T J_i] / (l_i . B_i')``;
    for the linear delta ``B_i'' = 0`` and this is thesis eq. (23) (there ``l_i`` is
    the unit rod vector and the factor ``1 / L`` appears explicitly).
    """
    rods, d1, d2, denom = _jacobian_parts(robot, q, p)
    jac = _jacobian_from_parts(rods, denom)
    out = np.empty((3, 3, 3))
    eye = np.eye(3)
    for i in range(3):
        m = eye - np.outer(d1[i], jac[i])
        out[i] = (m.T @ m - float(rods[i] @ d2[i]) * np.outer(jac[i], jac[i])) / denom[i]
    return jac, out


def hessians(robot: Robot, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Hessians ``H_i`` (3, 3, 3), see :func:`jacobian_and_hessians`."""
    return jacobian_and_hessians(robot, q, p)[1]


def joint_velocity(robot: Robot, q: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``qd = J v`` (thesis eq. (16))."""
    return jacobian(robot, q, p) @ np.asarray(v, dtype=float)


def platform_velocity(robot: Robot, q: np.ndarray, p: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """``v = J^-1 qd`` (thesis eq. (31))."""
    return np.linalg.solve(jacobian(robot, q, p), np.asarray(qd, dtype=float))


def joint_rates(robot: Robot, q: np.ndarray, p: np.ndarray, v: np.ndarray,
                a: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``qd = J v`` and ``qdd = J a + [v^T H_i v]`` (thesis eqs. (16), (22)) from one evaluation
    of ``J`` and ``H``; ``qdd`` is zero when ``a`` is None."""
    v = np.asarray(v, dtype=float)
    if a is None:
        return jacobian(robot, q, p) @ v, np.zeros(3)
    jac, hess = jacobian_and_hessians(robot, q, p)
    return jac @ v, jac @ np.asarray(a, dtype=float) + np.einsum("j,ijk,k->i", v, hess, v)


def joint_acceleration(robot: Robot, q: np.ndarray, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``qdd = J a + [v^T H_i v]`` (thesis eqs. (22), (25))."""
    return joint_rates(robot, q, p, v, a)[1]


def platform_acceleration(robot: Robot, q: np.ndarray, p: np.ndarray, v: np.ndarray, qdd: np.ndarray) -> np.ndarray:
    """``a = J^-1 (qdd - [v^T H_i v])`` (thesis eq. (37))."""
    jac, hess = jacobian_and_hessians(robot, q, p)
    v = np.asarray(v, dtype=float)
    return np.linalg.solve(jac, np.asarray(qdd, dtype=float) - np.einsum("j,ijk,k->i", v, hess, v))


def joint_state_from_platform(
    robot: Robot, p: np.ndarray, v: np.ndarray, a: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint position, velocity, acceleration for a platform state; raises if unreachable."""
    q = ik(robot, p).require()
    qd, qdd = joint_rates(robot, q, p, v, a)
    return q, qd, qdd


def platform_state_from_joints(robot: Robot, q: np.ndarray, qd: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Platform position and velocity for a joint state; raises if FK has no solution."""
    p = fk(robot, q).require()
    return p, platform_velocity(robot, q, p, qd)
