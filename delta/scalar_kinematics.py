"""Plain-float kinematics of one pose: the hot path of the FMUs, controllers and analytic models.

:mod:`delta.kinematics` works on numpy arrays and batches; for one pose per call its
array overhead dominates (hundreds of microseconds per IK + Jacobian + Hessian). This
module evaluates the same formulas on Python floats for a single pose, a few
microseconds per call. Both follow one formulation: leg ``i`` joins the actuator point
``B_i(q_i)`` to the platform joint ``p + b_i`` by a rod of length ``L``,
``l_i = p + b_i - B_i(q_i)``, ``|l_i| = L``. They agree within 1e-12
(``tests/unit/test_scalar_kinematics.py``).

Vectors are 3-tuples of floats in the base frame (SI units); legs are 0-based here,
1-based in every message.
"""

from __future__ import annotations

from math import acos, atan2, cos, hypot, pi, sin, sqrt

from .errors import RobotError, UnreachableError
from .robots import LinearDelta, Robot

__all__ = ["Vec", "dot", "inv3", "ScalarKinematics"]

Vec = tuple[float, float, float]

_ROUNDING = 1e-12
"""Relative slack on the real-solution tests (the value of :mod:`delta.kinematics`)."""
_TWO_PI = 2.0 * pi


def dot(a: Vec, b: Vec) -> float:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def inv3(m) -> list[list[float]]:  # noqa: ANN001 - any 3x3 nested sequence
    """Inverse of a 3x3 matrix (nested lists) by cofactors; raises ZeroDivisionError when singular."""
    (a, b, c), (d, e, f), (g, h, i) = m
    c00, c01, c02 = e * i - f * h, f * g - d * i, d * h - e * g
    det = a * c00 + b * c01 + c * c02
    if det == 0.0:
        raise ZeroDivisionError("singular 3x3 matrix")
    r = 1.0 / det
    return [
        [c00 * r, (c * h - b * i) * r, (b * f - c * e) * r],
        [c01 * r, (a * i - c * g) * r, (c * d - a * f) * r],
        [c02 * r, (b * g - a * h) * r, (a * e - b * d) * r],
    ]


class ScalarKinematics:
    """Kinematics of one robot on plain floats.

    Attributes
    ----------
    robot : Robot
    linear : bool
        True for a linear delta (``q`` = carriage travel, m), False for a rotary delta (arm angle, rad).
    e : tuple of 3 (cos, sin)
        Leg directions in the base plane.
    b : tuple of 3 Vec
        Platform joint offsets ``b_i``, m.
    rod : float
        Rod length ``L`` (linear ``rod_length``, rotary ``forearm_length``), m.
    """

    __slots__ = ("robot", "linear", "e", "b", "rod", "q_min", "q_max", "_radius", "_la", "_anchor", "_dx0")

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self.linear = isinstance(robot, LinearDelta)
        self.e = tuple((cos(a), sin(a)) for a in robot.leg_angles)
        r = robot.platform_radius
        self.b = tuple((r * c, r * s, 0.0) for c, s in self.e)
        if self.linear:
            self.rod = robot.rod_length
            self._radius = robot.rail_radius
            self._la = 0.0
        else:
            self.rod = robot.forearm_length
            self._radius = robot.base_radius
            self._la = robot.arm_length
        self._anchor = tuple((self._radius * c, self._radius * s) for c, s in self.e)
        self._dx0 = r - self._radius  # radial offset platform joint - actuator axis
        self.q_min = robot.q_min
        self.q_max = robot.q_max

    # ------------------------------------------------------------------ actuator path
    def actuator(self, i: int, qi: float) -> tuple[Vec, Vec, Vec]:
        """``B_i(q_i)``, ``B_i'`` and ``B_i''`` of leg ``i`` (0-based).

        Linear: ``B_i = (R e_i, -q_i)``; rotary: ``B_i = R e_i + La (cos q_i e_i - sin q_i z)``.
        """
        if self.linear:
            x, y = self._anchor[i]
            return (x, y, -qi), (0.0, 0.0, -1.0), (0.0, 0.0, 0.0)
        ex, ey = self.e[i]
        la, cq, sq = self._la, cos(qi), sin(qi)
        r = self._radius + la * cq
        return (r * ex, r * ey, -la * sq), (-la * sq * ex, -la * sq * ey, -la * cq), (-la * cq * ex, -la * cq * ey, la * sq)

    # ------------------------------------------------------------------ inverse kinematics
    def ik(self, p: Vec) -> tuple[Vec | None, int]:
        """Joint values for platform position ``p``, m, in the working mode of :func:`delta.kinematics.ik`.

        Returns ``(q, 0)``, or ``(None, leg)`` with the 1-based first leg that has no real
        solution. Joint limits are not checked here (see :meth:`limit_violation`).
        """
        x, y, z = p
        big_l = self.rod
        out = [0.0, 0.0, 0.0]
        for i in range(3):
            c, s = self.e[i]
            dx = x * c + y * s + self._dx0  # radial coordinate in the leg plane
            dy = y * c - x * s  # tangential coordinate
            if self.linear:
                # thesis eq. (9), the branch with the platform below the carriage; q downward
                h2 = big_l * big_l - dx * dx - dy * dy
                if not h2 >= -_ROUNDING * big_l * big_l:
                    return None, i + 1
                out[i] = -(z + sqrt(h2 if h2 > 0.0 else 0.0))
            else:
                # dx cos q - z sin q = K in the leg plane; elbow-out branch (see delta.kinematics.ik_batch)
                la = self._la
                k = (dx * dx + dy * dy + z * z + la * la - big_l * big_l) / (2.0 * la)
                rho = hypot(dx, z)
                if rho == 0.0:
                    return None, i + 1
                ratio = k / rho
                if not abs(ratio) <= 1.0 + _ROUNDING:
                    return None, i + 1
                ratio = 1.0 if ratio > 1.0 else (-1.0 if ratio < -1.0 else ratio)
                qi = -atan2(z, dx) - acos(ratio)
                out[i] = (qi + pi) % _TWO_PI - pi
        return (out[0], out[1], out[2]), 0

    def limit_violation(self, q: Vec) -> int:
        """1-based first leg whose joint value is outside ``[q_min, q_max]``, 0 when none."""
        lo, hi = self.q_min, self.q_max
        for i in range(3):
            if q[i] < lo or q[i] > hi:
                return i + 1
        return 0

    # ------------------------------------------------------------------ forward kinematics
    def fk(self, q: Vec) -> tuple[Vec, list[Vec], list[Vec], list[Vec]]:
        """Lower three-sphere intersection: ``p`` and, per leg, ``B_i``, ``B_i'``, ``B_i''``.

        No working-mode check (:func:`delta.kinematics.fk` does it); raises
        :class:`UnreachableError` when the spheres do not meet or their centres are collinear.
        """
        pts, d1s, d2s, centres = [], [], [], []
        for i in range(3):
            bpt, d1, d2 = self.actuator(i, q[i])
            b = self.b[i]
            pts.append(bpt)
            d1s.append(d1)
            d2s.append(d2)
            centres.append((bpt[0] - b[0], bpt[1] - b[1], bpt[2] - b[2]))
        c1, c2, c3 = centres
        a = (c2[0] - c1[0], c2[1] - c1[1], c2[2] - c1[2])
        b = (c3[0] - c1[0], c3[1] - c1[1], c3[2] - c1[2])
        n = (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])
        nn = dot(n, n)
        qt = (q[0], q[1], q[2])
        if nn == 0.0:
            raise UnreachableError(f"forward kinematics at q = {qt}: sphere centres are collinear")
        aa, bb = dot(a, a), dot(b, b)
        s = (aa * b[0] - bb * a[0], aa * b[1] - bb * a[1], aa * b[2] - bb * a[2])
        k = 0.5 / nn
        o = ((s[1] * n[2] - s[2] * n[1]) * k, (s[2] * n[0] - s[0] * n[2]) * k, (s[0] * n[1] - s[1] * n[0]) * k)
        h2 = self.rod * self.rod - dot(o, o)
        if h2 < 0.0:
            raise UnreachableError(f"forward kinematics at q = {qt}: the three rods cannot meet")
        scale = sqrt(h2 / nn)
        if n[2] > 0.0:
            scale = -scale
        p = (c1[0] + o[0] + scale * n[0], c1[1] + o[1] + scale * n[1], c1[2] + o[2] + scale * n[2])
        return p, pts, d1s, d2s

    # ------------------------------------------------------------------ differential kinematics
    def _leg(self, i: int, qi: float, p: Vec) -> tuple[float, float, float, float, float, float, float]:
        """Rod ``l_i = p + b_i - B_i(q_i)``, ``B_i'`` and ``l_i . B_i''`` of leg ``i``, unpacked."""
        bx, by, _ = self.b[i]
        if self.linear:
            x, y = self._anchor[i]
            return p[0] + bx - x, p[1] + by - y, p[2] + qi, 0.0, 0.0, -1.0, 0.0
        ex, ey = self.e[i]
        la, cq, sq = self._la, cos(qi), sin(qi)
        r = self._radius + la * cq
        lx, ly, lz = p[0] + bx - r * ex, p[1] + by - r * ey, p[2] + la * sq
        return lx, ly, lz, -la * sq * ex, -la * sq * ey, -la * cq, la * (sq * lz - cq * (lx * ex + ly * ey))

    def joint_rates(self, q: Vec, p: Vec, v: Vec, a: Vec | None = None) -> tuple[Vec, Vec]:
        """``qd = J v`` (thesis eq. (16)) and ``qdd = J a + [v^T H_i v]`` (thesis eqs. (22), (25)).

        Row i of ``J`` is ``l_i^T / (l_i . B_i')`` (thesis eq. (15)) and, with ``J_i v = qd_i``,
        ``v^T H_i v = (|v - B_i' qd_i|^2 - (l_i . B_i'') qd_i^2) / (l_i . B_i')`` (thesis eq. (23),
        generalised to the rotary arm). ``qdd`` is zero when ``a`` is None. Raises
        :class:`RobotError` at a type 1 singularity.
        """
        vx, vy, vz = v
        qd = [0.0, 0.0, 0.0]
        qdd = [0.0, 0.0, 0.0]
        for i in range(3):
            lx, ly, lz, d1x, d1y, d1z, l_d2 = self._leg(i, q[i], p)
            den = lx * d1x + ly * d1y + lz * d1z
            if den == 0.0:
                raise RobotError(f"type 1 (serial) singularity: leg {i + 1} rod is orthogonal to its actuator motion")
            jx, jy, jz = lx / den, ly / den, lz / den
            qdi = jx * vx + jy * vy + jz * vz
            qd[i] = qdi
            if a is not None:
                wx, wy, wz = vx - d1x * qdi, vy - d1y * qdi, vz - d1z * qdi
                qdd[i] = jx * a[0] + jy * a[1] + jz * a[2] + (wx * wx + wy * wy + wz * wz - l_d2 * qdi * qdi) / den
        return (qd[0], qd[1], qd[2]), (qdd[0], qdd[1], qdd[2])

    def proximity(self, q: Vec, p: Vec) -> float:
        """Singularity proximity in [0, 1] (0 = singular), as :func:`delta.singularity.proximity_batch`:
        ``min(min_i |l_i . B_i'| / (|l_i| |B_i'|), sigma_min / sigma_max of the unit-row J_p)``.

        The singular values come from the eigenvalues of the Gram matrix ``U U^T`` of the
        unit rods ``u_i``: the largest by the closed form for symmetric 3x3 matrices, the
        smallest from ``det(U)^2`` (the product of all three), which keeps its relative
        accuracy near a type 2 singularity.
        """
        units = []
        serial = 1.0
        for i in range(3):
            lx, ly, lz, d1x, d1y, d1z, _ = self._leg(i, q[i], p)
            norm = sqrt(lx * lx + ly * ly + lz * lz)
            measure = abs(lx * d1x + ly * d1y + lz * d1z) / (norm * sqrt(d1x * d1x + d1y * d1y + d1z * d1z))
            if measure < serial:
                serial = measure
            units.append((lx / norm, ly / norm, lz / norm))
        u0, u1, u2 = units
        m00, m11, m22 = dot(u0, u0), dot(u1, u1), dot(u2, u2)
        m01, m02, m12 = dot(u0, u1), dot(u0, u2), dot(u1, u2)
        trace = m00 + m11 + m22
        off = m01 * m01 + m02 * m02 + m12 * m12
        if off == 0.0:
            lam_max = max(m00, m11, m22)
        else:
            mean = trace / 3.0
            a0, a1, a2 = m00 - mean, m11 - mean, m22 - mean
            scale = sqrt((a0 * a0 + a1 * a1 + a2 * a2 + 2.0 * off) / 6.0)
            det_b = (a0 * (a1 * a2 - m12 * m12) - m01 * (m01 * a2 - m12 * m02) + m02 * (m01 * m12 - a1 * m02)) / scale**3
            r = 0.5 * det_b
            r = 1.0 if r > 1.0 else (-1.0 if r < -1.0 else r)
            lam_max = mean + 2.0 * scale * cos(acos(r) / 3.0)
        det_u = u0[0] * (u1[1] * u2[2] - u1[2] * u2[1]) - u0[1] * (u1[0] * u2[2] - u1[2] * u2[0]) \
            + u0[2] * (u1[0] * u2[1] - u1[1] * u2[0])
        rest = trace - lam_max  # lam_mid + lam_min
        prod = det_u * det_u / lam_max  # lam_mid * lam_min
        disc = rest * rest - 4.0 * prod
        lam_mid = 0.5 * (rest + sqrt(disc if disc > 0.0 else 0.0))
        lam_min = prod / lam_mid if lam_mid > 0.0 else 0.0
        parallel = sqrt(lam_min / lam_max)
        return serial if serial < parallel else parallel
