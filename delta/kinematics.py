"""Position, velocity and acceleration kinematics of linear and rotary deltas.

Both robots share one formulation (:mod:`delta.actuators` gives the only per-kind part,
the actuator path ``B_i(q_i)``). Leg ``i`` joins ``B_i(q_i)`` to the platform joint
``p + b_i`` by a parallelogram of length ``L``; its rod vector ``l_i = p + b_i - B_i(q_i)``
satisfies ``l_i . l_i = L**2``. Differentiating once and twice gives the Jacobian and the
Hessians for any actuator path.

Three layers, one set of formulas:

* the leg formulas (the actuator's ``leg``, :func:`leg_rates`, ``_proximity``) take floats or numpy
  arrays;
* the per-pose algorithms on plain floats: :func:`inverse_kinematics` (IK to second order, the
  IK FMU's step), and over ``(model, data)`` :func:`update` (forward kinematics and ``J^-1``,
  cached per ``q``: the controllers' and the analytic plant's step), :func:`set_pose`,
  :func:`rates`, :func:`proximity`; no arrays allocated;
* the batch path over (N, 3) arrays (:func:`ik_batch`, :func:`legs_batch`,
  :func:`rates_batch`, :func:`proximity_batch`): workspace sampling, pre-flight, references.

The numpy functions below them (:func:`ik`, :func:`fk`, :func:`jacobian`, ...) take a robot
preset or a :class:`~delta.model.Model` and return arrays; they call the same algorithms.

Shapes: ``p``, ``v``, ``a`` are (3,) platform position / velocity / acceleration in the base
frame, m, m/s, m/s**2; ``q``, ``qd``, ``qdd`` are (3,) joint values (m or rad). Legs are
0-based in code, 1-based in every message.
"""

from __future__ import annotations

from dataclasses import dataclass
from math import inf

import numpy as np

from .actuators import ARRAY, SCALAR
from .errors import RobotError, UnreachableError
from .model import Data, Model, as_model
from .robots import Robot

__all__ = [
    "IKResult",
    "FKResult",
    "inv3",
    "leg_rates",
    "serial_singularity",
    "solve_ik",
    "inverse_kinematics",
    "working_mode_fault",
    "update",
    "set_pose",
    "rates",
    "proximity",
    "ik_batch",
    "legs_batch",
    "rates_batch",
    "proximity_batch",
    "leg_axes",
    "actuator_points",
    "actuator_tangents",
    "platform_offsets",
    "ik",
    "joint_limit_reason",
    "JOINT_LIMIT",
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
]


# ------------------------------------------------------------------------------ leg formulas
# Each takes floats (one leg) or arrays (many poses and/or the three legs at once). A leg is the
# 8-tuple of the actuator's ``leg``: (lx, ly, lz, B'x, B'y, B'z, l . B'', l . B').

def leg_rates(leg, vx, vy, vz, ax, ay, az):  # noqa: ANN001, ANN201
    """``qd_i = J_i v`` and ``qdd_i = J_i a + v^T H_i v`` of one leg.

    ``J_i = l_i^T / (l_i . B_i')`` (thesis eq. (15); for the rotary delta it equals row i of
    ``J_theta^-1 J_p``, seed 003 eq. (12)), ``qd_i = J_i v`` (thesis eq. (16)), and, differentiating
    ``l_i . l_i = L^2`` twice, ``v^T H_i v = (|v - B_i' qd_i|^2 - (l_i . B_i'') qd_i^2) / (l_i . B_i')``
    (thesis eqs. (22)-(23) for the linear delta, where ``B_i'' = 0``; eq. (25) for ``qdd``).
    """
    lx, ly, lz, d1x, d1y, d1z, l_d2, den = leg
    jx, jy, jz = lx / den, ly / den, lz / den
    qd = jx * vx + jy * vy + jz * vz
    wx, wy, wz = vx - d1x * qd, vy - d1y * qd, vz - d1z * qd
    return qd, jx * ax + jy * ay + jz * az + (wx * wx + wy * wy + wz * wz - l_d2 * qd * qd) / den


def _serial(leg, xp):  # noqa: ANN001, ANN202
    """Type 1 measure ``|l_i . B_i'| / (|l_i| |B_i'|)`` (seed 003 eq. (13)) and the unit rod."""
    lx, ly, lz, d1x, d1y, d1z, _, den = leg
    norm = xp.sqrt(lx * lx + ly * ly + lz * lz)
    return abs(den) / (norm * xp.sqrt(d1x * d1x + d1y * d1y + d1z * d1z)), (lx / norm, ly / norm, lz / norm)


def _proximity(legs, xp):  # noqa: ANN001, ANN202
    """Singularity proximity in [0, 1], 0 = singular (see :mod:`delta.singularity`):
    ``min(min_i serial_i, sigma_min / sigma_max of the unit-row J_p)``.

    The singular values come from the eigenvalues of the Gram matrix ``U U^T`` of the unit rods:
    the largest by the closed form for symmetric 3x3 matrices, the smallest from ``det(U)^2`` (the
    product of all three), which keeps its relative accuracy near a type 2 singularity.
    """
    (s0, u0), (s1, u1), (s2, u2) = (_serial(leg, xp) for leg in legs)
    serial = xp.minimum(xp.minimum(s0, s1), s2)

    def dot(a, b):  # noqa: ANN001, ANN202
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

    m00, m11, m22 = dot(u0, u0), dot(u1, u1), dot(u2, u2)
    m01, m02, m12 = dot(u0, u1), dot(u0, u2), dot(u1, u2)
    trace = m00 + m11 + m22
    mean = trace / 3.0
    a0, a1, a2 = m00 - mean, m11 - mean, m22 - mean
    off = m01 * m01 + m02 * m02 + m12 * m12
    scale = xp.sqrt((a0 * a0 + a1 * a1 + a2 * a2 + 2.0 * off) / 6.0)
    safe = scale + (scale == 0.0)  # a multiple of the identity: lam_max = mean below
    det_b = (a0 * (a1 * a2 - m12 * m12) - m01 * (m01 * a2 - m12 * m02) + m02 * (m01 * m12 - a1 * m02)) / safe**3
    r = xp.minimum(xp.maximum(0.5 * det_b, -1.0), 1.0)
    lam_max = mean + 2.0 * scale * xp.cos(xp.acos(r) / 3.0)
    det_u = u0[0] * (u1[1] * u2[2] - u1[2] * u2[1]) - u0[1] * (u1[0] * u2[2] - u1[2] * u2[0]) \
        + u0[2] * (u1[0] * u2[1] - u1[1] * u2[0])
    rest = trace - lam_max  # lam_mid + lam_min
    prod = det_u * det_u / lam_max  # lam_mid * lam_min
    lam_mid = 0.5 * (rest + xp.sqrt(xp.maximum(rest * rest - 4.0 * prod, 0.0)))
    lam_min = prod / (lam_mid + (lam_mid == 0.0)) * (lam_mid > 0.0)
    return xp.minimum(serial, xp.sqrt(lam_min / lam_max))


def inv3(a, b, c, d, e, f, g, h, i):  # noqa: ANN001, ANN201
    """Inverse of the 3x3 matrix ``[[a, b, c], [d, e, f], [g, h, i]]`` by cofactors, row-major 9-tuple,
    and its determinant (the caller checks it; the inverse is meaningless when it is 0)."""
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c00 + b * c01 + c * c02
    r = 1.0 / (det + (det == 0.0))
    return (c00 * r, (c * h - b * i) * r, (b * f - c * e) * r,
            c01 * r, (a * i - c * g) * r, (c * d - a * f) * r,
            c02 * r, (b * g - a * h) * r, (a * e - b * d) * r), det


def serial_singularity(leg: int, q=None) -> RobotError:  # noqa: ANN001
    """The error of a type 1 singularity of the 1-based ``leg`` (``l_i . B_i' = 0``), at ``q`` when known."""
    at = "" if q is None else f" at q = {tuple(q)}"
    return RobotError(f"type 1 (serial) singularity{at}: leg {leg} rod is orthogonal to its actuator motion")


# ------------------------------------------------------------------------------ one pose, floats

def inverse_kinematics(model: Model, p, v=None, a=None, limits: bool = True):  # noqa: ANN001, ANN201
    """Inverse kinematics to second order, the IK FMU's step: ``(q, qd, qdd, 0)`` for the platform
    position, velocity and acceleration ``p, v, a`` in the working mode (platform below the carriages;
    elbows out), with ``qd``, ``qdd`` from :func:`leg_rates` (``v`` None: positions only, ``qd`` and
    ``qdd`` None; ``a`` None: zero); or ``(None, None, None, leg)`` when the 1-based ``leg`` has no real
    solution; or, with ``limits``, ``(q, None, None, -leg)`` when ``q[leg - 1]`` is beyond the joint
    limits. Raises :class:`RobotError` at a type 1 singularity (rates only)."""
    x, y, z = p
    if v is not None:
        vx, vy, vz = v
        ax, ay, az = _ZERO if a is None else a
    actuator, xp = model.actuator, model.xp
    lo, hi = (model.q_min, model.q_max) if limits else (-inf, inf)
    solve, leg_at, check, both, symbolic = actuator.solve, actuator.leg, xp.check, xp.both, xp.symbolic
    q, qd, qdd = [], [], []
    limit = 0
    try:
        for c, s, ox, oy in model.legs:
            qi, ok = solve(x, y, z, c, s, ox, oy, xp)
            if not check(ok, NO_SOLUTION[len(q)]):
                return None, None, None, len(q) + 1
            q.append(qi)
            if limits and not check(both(lo <= qi, qi <= hi), BEYOND_LIMITS[len(q) - 1]):
                limit = limit or -len(q)
            if limit or v is None:
                continue
            leg = leg_at(qi, c, s, ox, oy, x, y, z, xp)
            if symbolic:  # numbers raise ZeroDivisionError below instead
                check(leg[7] != 0.0, SERIAL[len(q) - 1])
            qdi, qddi = leg_rates(leg, vx, vy, vz, ax, ay, az)
            qd.append(qdi)
            qdd.append(qddi)
    except ZeroDivisionError:  # l_i . B_i' = 0
        raise serial_singularity(len(q)) from None
    if limit or v is None:
        return q, None, None, limit
    return q, qd, qdd, 0


_ZERO = (0.0, 0.0, 0.0)
NO_SOLUTION = tuple(f"leg {i} has no solution" for i in (1, 2, 3))
"""Reasons of the per-leg checks, as generated code reports them (``fmus.native``)."""
BEYOND_LIMITS = tuple(f"leg {i} is beyond its joint limits" for i in (1, 2, 3))
END_STOP = "the actuator was driven into its end stop (the plant stops here rather than pass through it)"
"""Why a plant stops when a step ends with a joint beyond its limits (:func:`inverse_kinematics` with ``limits``):
every plant, the Exudyn one (:mod:`multibody`), the analytic one and its native build, stops so."""
SERIAL = tuple(f"type 1 (serial) singularity: leg {i} rod is orthogonal to its actuator motion" for i in (1, 2, 3))
PARALLEL = "type 2 (parallel) singularity: J is singular"
WRONG_MODE = "the joints would be assembled outside the working mode"
_COLLINEAR = "sphere centres are collinear (degenerate configuration)"
_APART = "the three rods cannot meet (legs too far apart)"


def solve_ik(model: Model, p) -> tuple[list[float] | None, int]:  # noqa: ANN001
    """Joint values for platform position ``p``: ``(q, 0)``, or ``(None, leg)`` with the 1-based first
    leg that has no real solution. Joint limits are not checked here."""
    q, _, _, fault = inverse_kinematics(model, p, limits=False)
    return (None, fault) if fault else (q, 0)


def _legs(model: Model, q, x: float, y: float, z: float) -> list[tuple[float, ...]]:  # noqa: ANN001
    leg_at, xp = model.actuator.leg, model.xp
    return [leg_at(qi, c, s, ox, oy, x, y, z, xp) for qi, (c, s, ox, oy) in zip(q, model.legs)]


def set_pose(model: Model, data: Data, q, p) -> Data:  # noqa: ANN001
    """Fill ``data`` with the legs of the pose ``(q, p)`` (from IK: no forward kinematics)."""
    x, y, z = p
    data.model, data.q, data.p, data.jinv = model, None, (x, y, z), None  # q unset: the FK cache stays cold
    data.legs = _legs(model, q, x, y, z)
    return data


def update(model: Model, data: Data, q) -> Data:  # noqa: ANN001
    """Forward kinematics of ``q`` into ``data``: ``p``, the legs and ``J^-1`` (cached: no work when
    ``q`` is the pose ``data`` holds for ``model``; another model's pose is computed again).

    ``p`` is the lower intersection of the three spheres of radius ``L`` about ``B_i(q_i) - b_i``
    (no working-mode check: :func:`fk` does it). Raises :class:`UnreachableError` when the spheres do
    not meet or their centres are collinear, :class:`RobotError` at a type 1 or 2 singularity.
    """
    q0, q1, q2 = q
    key = (q0, q1, q2)
    if data.q == key and data.model is model:
        return data
    p, reason = _trilaterate(model, key)
    if p is None:
        raise UnreachableError(f"forward kinematics at q = {key}: {reason}")
    legs = _legs(model, key, *p)
    data.model, data.q, data.p, data.legs = model, None, p, legs
    data.jinv = _jinv(legs, key, model.xp)
    data.q = key
    return data


def _trilaterate(model: Model, q) -> tuple[tuple[float, float, float] | None, str]:  # noqa: ANN001
    """Lower intersection of the spheres of radius ``L`` about the centres ``B_i(q_i) - b_i`` (the rods
    at ``p = 0``, negated), or the reason there is none."""
    (l1x, l1y, l1z, *_), (l2x, l2y, l2z, *_), (l3x, l3y, l3z, *_) = _legs(model, q, 0.0, 0.0, 0.0)
    ax, ay, az = l1x - l2x, l1y - l2y, l1z - l2z  # second centre minus the first
    bx, by, bz = l1x - l3x, l1y - l3y, l1z - l3z  # third centre minus the first
    nx, ny, nz = ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx
    nn = nx * nx + ny * ny + nz * nz
    aa, bb = ax * ax + ay * ay + az * az, bx * bx + by * by + bz * bz
    xp = model.xp
    if not xp.check(nn > 1e-24 * xp.maximum(xp.maximum(aa, bb), 1e-300) ** 2, _COLLINEAR):
        return None, _COLLINEAR
    sx, sy, sz = aa * bx - bb * ax, aa * by - bb * ay, aa * bz - bb * az
    k = 0.5 / nn  # circumcentre of the centres' triangle, relative to the first: (s x n) / (2 |n|^2)
    ox, oy, oz = (sy * nz - sz * ny) * k, (sz * nx - sx * nz) * k, (sx * ny - sy * nx) * k
    h2 = model.rod * model.rod - (ox * ox + oy * oy + oz * oz)
    if not xp.check(h2 >= 0.0, _APART):
        return None, _APART
    down = xp.sqrt(h2 / nn)
    down = xp.where(nz > 0.0, -down, down)
    return (ox + down * nx - l1x, oy + down * ny - l1y, oz + down * nz - l1z), ""


def _jinv(legs, q, xp) -> tuple[float, ...]:  # noqa: ANN001
    """``J^-1`` from the legs: ``J = diag(1 / (l_i . B_i')) L`` with rows ``l_i^T`` (thesis eq. (15)), so
    ``J^-1 = L^-1 diag(l_i . B_i')``."""
    (ax, ay, az, _, _, _, _, da), (bx, by, bz, _, _, _, _, db), (cx, cy, cz, _, _, _, _, dc) = legs
    for leg, den in enumerate((da, db, dc)):
        if not xp.check(den != 0.0, SERIAL[leg]):
            raise serial_singularity(leg + 1, q)
    (i00, i01, i02, i10, i11, i12, i20, i21, i22), det = inv3(ax, ay, az, bx, by, bz, cx, cy, cz)
    if not xp.check(det != 0.0, PARALLEL):
        raise RobotError(f"type 2 (parallel) singularity at q = {tuple(q)}: J is singular")
    return i00 * da, i01 * db, i02 * dc, i10 * da, i11 * db, i12 * dc, i20 * da, i21 * db, i22 * dc


def rates(data: Data, v, a=None) -> tuple[tuple[float, float, float], tuple[float, float, float]]:  # noqa: ANN001
    """``qd = J v`` and ``qdd = J a + [v^T H_i v]`` at the pose in ``data`` (``qdd`` = 0 when ``a`` is None).
    Raises :class:`RobotError` at a type 1 singularity."""
    vx, vy, vz = v
    ax, ay, az = (0.0, 0.0, 0.0) if a is None else a
    out = []
    for i, leg in enumerate(data.legs):
        if leg[7] == 0.0:
            raise serial_singularity(i + 1)
        out.append(leg_rates(leg, vx, vy, vz, ax, ay, az))
    (qd0, qdd0), (qd1, qdd1), (qd2, qdd2) = out
    return (qd0, qd1, qd2), ((qdd0, qdd1, qdd2) if a is not None else (0.0, 0.0, 0.0))


def proximity(data: Data, xp=SCALAR) -> float:  # noqa: ANN001
    """Singularity proximity of the pose in ``data`` (``_proximity``), 0 = singular (``xp``: the model's)."""
    value = _proximity(data.legs, xp)
    return value if xp.symbolic else float(value)


# ------------------------------------------------------------------------------ batch (N, 3)

def ik_batch(robot: Robot | Model, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse kinematics of (N, 3) positions: ``q`` (N, 3), NaN where a leg has no real solution,
    and ``solvable`` (N, 3) bool."""
    model = as_model(robot)
    p = np.atleast_2d(np.asarray(p, dtype=float))
    with np.errstate(invalid="ignore", divide="ignore"):
        q, ok = model.actuator.solve(p[:, 0:1], p[:, 1:2], p[:, 2:3], model.ex_arr, model.ey_arr,
                                     model.ox_arr, model.oy_arr, ARRAY)
    ok = np.broadcast_to(ok, q.shape)
    return np.where(ok, q, np.nan), ok


def legs_batch(model: Model, q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, ...]:
    """The 8 leg components of the actuator's ``leg`` for (N, 3) ``q`` and ``p``, each (N, 3) (column = leg)."""
    q = np.atleast_2d(np.asarray(q, dtype=float))
    p = np.atleast_2d(np.asarray(p, dtype=float))
    legs = model.actuator.leg(q, model.ex_arr, model.ey_arr, model.ox_arr, model.oy_arr,
                              p[:, 0:1], p[:, 1:2], p[:, 2:3], ARRAY)
    return tuple(np.broadcast_to(c, q.shape) for c in legs)


def rates_batch(model: Model, q: np.ndarray, p: np.ndarray, v: np.ndarray, a: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """``qd = J v``, ``qdd = J a + [v^T H_i v]`` for (N, 3) poses and platform rates."""
    v = np.atleast_2d(np.asarray(v, dtype=float))
    a = np.atleast_2d(np.asarray(a, dtype=float))
    return leg_rates(legs_batch(model, q, p), v[:, 0:1], v[:, 1:2], v[:, 2:3], a[:, 0:1], a[:, 1:2], a[:, 2:3])


def proximity_batch(robot: Robot | Model, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Singularity proximity (N,) of (N, 3) poses; 0 = singular."""
    legs = legs_batch(as_model(robot), q, p)
    per_leg = [tuple(c[:, i] for c in legs) for i in range(3)]
    with np.errstate(invalid="ignore", divide="ignore"):
        return _proximity(per_leg, ARRAY)


# ------------------------------------------------------------------------------ numpy API

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


def leg_axes(robot: Robot | Model) -> np.ndarray:
    """Unit radial vectors ``e_i`` of the three legs, shape (3, 3) (row i = leg i)."""
    model = as_model(robot)
    return np.stack([model.ex_arr, model.ey_arr, np.zeros(3)], axis=1)


def platform_offsets(robot: Robot | Model) -> np.ndarray:
    """Platform joint offsets ``b_i = r e_i`` in the base frame, (3, 3), m."""
    model = as_model(robot)
    return model.robot.platform_radius * np.stack([model.ex_arr, model.ey_arr, np.zeros(3)], axis=1)


def actuator_points(robot: Robot | Model, q: np.ndarray) -> np.ndarray:
    """Actuator-side joint positions ``B_i(q_i)`` (carriage joint or elbow), (3, 3), m: ``b_i - l_i`` at ``p = 0``."""
    legs = legs_batch(as_model(robot), np.asarray(q, dtype=float).reshape(1, 3), np.zeros((1, 3)))
    return platform_offsets(robot) - np.stack([c[0] for c in legs[0:3]], axis=1)


def actuator_tangents(robot: Robot | Model, q: np.ndarray) -> np.ndarray:
    """Actuator tangents ``B_i'(q_i)`` (row i), (3, 3)."""
    legs = legs_batch(as_model(robot), np.asarray(q, dtype=float).reshape(1, 3), np.zeros((1, 3)))
    return np.stack([c[0] for c in legs[3:6]], axis=1)


JOINT_LIMIT = ("leg {leg} joint limit: q = {q} < q_min = {limit}", "leg {leg} joint limit: q = {q} > q_max = {limit}")
"""A joint beyond its range, below and above: ``q`` and ``limit`` as the actuator shows a joint value
(:meth:`format_q`; the native FMUs put its printf format there and print it in C)."""


def joint_limit_reason(robot: Robot | Model, leg: int, value: float) -> str:
    """``leg 2 joint limit: q = ... < q_min = ...`` for joint ``leg`` (1-based) at ``value``."""
    model = as_model(robot)
    fmt = model.actuator.format_q
    above = not value < model.q_min
    return JOINT_LIMIT[above].format(leg=leg, q=fmt(value), limit=fmt(model.q_max if above else model.q_min))


def ik(robot: Robot | Model, p: np.ndarray) -> IKResult:
    """Inverse kinematics of one platform position ``p`` (3,), m."""
    model = as_model(robot)
    q, _, _, fault = inverse_kinematics(model, np.asarray(p, dtype=float).reshape(3).tolist())
    if fault > 0:
        return IKResult(None, False, False, f"leg {fault} has no solution (rod cannot reach the platform joint)", fault)
    if fault < 0:
        return IKResult(np.array(q), True, False, joint_limit_reason(model, -fault, q[-fault - 1]), -fault)
    return IKResult(np.array(q), True, True)


def working_mode_fault(model: Model, q, p) -> str | None:  # noqa: ANN001
    """Why the assembly ``(q, p)`` is not the one :func:`ik` solves for (linear: platform below every
    carriage; rotary: elbows out), or None when it is."""
    q_back, leg = solve_ik(model, p)
    if q_back is not None:
        xp, tol = model.xp, 1e-6 * model.actuator.q_scale
        d0, d1, d2 = (abs(a - b) for a, b in zip(q_back, q))
        if xp.check(xp.both(xp.both(d0 <= tol, d1 <= tol), d2 <= tol), WRONG_MODE):
            return None
        leg = int(np.argmax(np.abs(np.array(q_back) - np.asarray(q, dtype=float)))) + 1
    return f"leg {leg} would be assembled outside the working mode ({model.actuator.wrong_mode})"


def fk(robot: Robot | Model, q: np.ndarray) -> FKResult:
    """Closed-form forward kinematics (three-sphere intersection, :func:`update`), lower branch.

    The answer must belong to the working mode that :func:`ik` solves for; a ``q`` whose assembly
    needs another branch is reported as such (:func:`working_mode_fault`) instead of returning a
    pose IK would not give back.
    """
    model = as_model(robot)
    q = np.asarray(q, dtype=float).reshape(3).tolist()
    p, reason = _trilaterate(model, q)
    if p is None:
        return FKResult(None, reason)
    reason = working_mode_fault(model, q, p)
    return FKResult(None, reason) if reason else FKResult(np.array(p), None)


def _posed(robot: Robot | Model, q: np.ndarray, p: np.ndarray) -> Data:
    """A :class:`Data` of the model of ``robot`` at the pose ``(q, p)`` (arrays or sequences)."""
    model = as_model(robot)
    return set_pose(model, Data(model), np.asarray(q, dtype=float).tolist(), np.asarray(p, dtype=float).tolist())


def rod_vectors(robot: Robot | Model, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Rod vectors ``l_i = p + b_i - B_i(q_i)`` (row i), (3, 3), m."""
    data = _posed(robot, q, p)
    return np.array([leg[0:3] for leg in data.legs])


def jacobian(robot: Robot | Model, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Task Jacobian ``J`` with ``qd = J v``, (3, 3).

    Row i is ``l_i^T / (l_i . B_i')`` (thesis eq. (15) for the linear delta, where
    ``B_i' = u_i``; for the rotary delta it equals ``J_theta^-1 J_p`` of seed 003 eq. (12)).
    """
    data = _posed(robot, q, p)
    legs = np.array(data.legs)
    if np.any(legs[:, 7] == 0.0):
        leg = int(np.argmin(np.abs(legs[:, 7]))) + 1
        raise serial_singularity(leg)
    return legs[:, 0:3] / legs[:, 7:8]


def jacobian_and_hessians(robot: Robot | Model, q: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``J`` (3, 3) and the Hessians ``H_i`` (3, 3, 3) with ``qdd_i = J_i a + v^T H_i v`` (thesis eq. (22)).

    ``H_i`` is the matrix of the quadratic form in :func:`leg_rates` (recovered by polarisation:
    ``H[j, k] = (Q(e_j + e_k) - Q(e_j) - Q(e_k)) / 2``), so the formula lives in one place.
    """
    data = _posed(robot, q, p)
    eye = np.eye(3)
    jac = np.column_stack([rates(data, e)[0] for e in eye])

    def quad(v: np.ndarray) -> np.ndarray:
        return np.array(rates(data, v, (0.0, 0.0, 0.0))[1])

    diag = [quad(e) for e in eye]
    hess = np.empty((3, 3, 3))
    for j in range(3):
        hess[:, j, j] = diag[j]
        for k in range(j + 1, 3):
            hess[:, j, k] = hess[:, k, j] = 0.5 * (quad(eye[j] + eye[k]) - diag[j] - diag[k])
    return jac, hess


def hessians(robot: Robot | Model, q: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Hessians ``H_i`` (3, 3, 3), see :func:`jacobian_and_hessians`."""
    return jacobian_and_hessians(robot, q, p)[1]


def joint_rates(robot: Robot | Model, q: np.ndarray, p: np.ndarray, v: np.ndarray,
                a: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``qd = J v`` and ``qdd = J a + [v^T H_i v]`` (thesis eqs. (16), (22)); ``qdd`` is zero when ``a`` is None."""
    data = _posed(robot, q, p)
    qd, qdd = rates(data, np.asarray(v, dtype=float).tolist(), None if a is None else np.asarray(a, dtype=float).tolist())
    return np.array(qd), np.array(qdd)


def joint_velocity(robot: Robot | Model, q: np.ndarray, p: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``qd = J v`` (thesis eq. (16))."""
    return joint_rates(robot, q, p, v)[0]


def joint_acceleration(robot: Robot | Model, q: np.ndarray, p: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
    """``qdd = J a + [v^T H_i v]`` (thesis eqs. (22), (25))."""
    return joint_rates(robot, q, p, v, a)[1]


def platform_velocity(robot: Robot | Model, q: np.ndarray, p: np.ndarray, qd: np.ndarray) -> np.ndarray:
    """``v = J^-1 qd`` (thesis eq. (31))."""
    return np.linalg.solve(jacobian(robot, q, p), np.asarray(qd, dtype=float))


def platform_acceleration(robot: Robot | Model, q: np.ndarray, p: np.ndarray, v: np.ndarray,
                          qdd: np.ndarray) -> np.ndarray:
    """``a = J^-1 (qdd - [v^T H_i v])`` (thesis eq. (37))."""
    quad = joint_rates(robot, q, p, v, np.zeros(3))[1]
    return np.linalg.solve(jacobian(robot, q, p), np.asarray(qdd, dtype=float) - quad)


def joint_state_from_platform(
    robot: Robot | Model, p: np.ndarray, v: np.ndarray, a: np.ndarray | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Joint position, velocity, acceleration for a platform state; raises if unreachable."""
    q = ik(robot, p).require()
    qd, qdd = joint_rates(robot, q, p, v, a)
    return q, qd, qdd


